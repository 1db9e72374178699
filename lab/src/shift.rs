//! `excavator-ctl experiment shift`: a long shift of the planned session under faults, in-process on
//! virtual time (the [`crate::harness`] of `demo`: the embedded simulator and the controller node on
//! one in-process bus), with faults injected at random times drawn from the seed, against a
//! fault-free shift of the same seed run beside it (its own thread).
//!
//! # Faults ([`FaultKind`])
//!
//! The shift after a fault-free warm-up is cut into equal slots, one fault per slot, the kinds in
//! turn in an order shuffled per round; each fault starts at a random time of its slot and lasts a
//! random time of its kind's range, leaving at least [`RECOVERY_ROOM_S`] of its slot to recover.
//!
//! - sensor dropout: the gateway's sensor frames (angles, rates, valve pressures and flows, pump
//!   pressures, odometry) are withheld from the controller;
//! - garbage: a foreign node sends random frames (random 29- and 11-bit ids, the protocol's ids from
//!   the gateway's, the controller's and other addresses, random lengths and bytes), ~200 frames/s;
//! - flood: a foreign node sends 6000 frames/s of one unknown id (the in-process bus has no
//!   arbitration: the flood costs receive work, not bus time);
//! - bus-off: an error frame reporting bus-off, then every frame lost, then a `restarted` error frame;
//! - gateway fault: the gateway's clock steps back 1 s (it latches `CLOCK_FAULT`, valves neutral);
//! - e-stop: the operator's e-stop ([`controller::io::operator`]), the operator's reset after a hold;
//! - controller restart: the controller is killed (no shutdown frames) and after a downtime a fresh
//!   [`ControllerNode`] goes on from the saved state as `run --resume` does ([`onboard::resume`],
//!   [`controller::session::session_state`]): the checkpoint of every completed action is saved to the
//!   state file, synchronously (the shift is reproducible for its seed).
//!
//! A fault is **detected** when the part that must notice it does ([`FaultKind::detection`]) and
//! **recovered** when, after its end, the controller is armed again with the gateway confirming it and
//! no fault active (motion is possible again). A fault that stopped motion waits for the operator
//! once its cause has cleared (the controller's safety layer, "Stops that stay stopped"): the
//! simulated operator resumes it (`resume`, a `reset` where the stop latches) [`OPERATOR_RESPONSE_S`]
//! after the controller starts waiting, counted. The shift's controller runs the default safety
//! policy (no automatic re-arm after a transient fault).
//!
//! # Unsafe outputs
//!
//! After every 1 ms physics step the valve commands the gateway applied to the plant are checked:
//! a non-zero command is an unsafe output when
//! - the gateway is not in an armed mode, or
//! - an e-stop was requested more than [`GATEWAY_WATCHDOG_S`] ago and not yet reset, or
//! - the last heartbeat that reached the gateway in its current session (the controller alive, the
//!   bus on, the controller's session the gateway's) is more than [`GATEWAY_WATCHDOG_S`] old, or
//! - the controller's newest sensor frames (withheld in a dropout, lost in a bus-off) are older
//!   than the safety rule's `sensor_max_age_s` plus two control periods (the rule is checked once a
//!   period and its neutral command goes out in the next).
//!
//! # Work for a long shift
//!
//! The extended-operation bench lasts about 1.6 simulated hours of the planned session (seed 1: 192
//! digs and 12 track backs). When the planner ends its session (the bench removed), the shift goes on
//! on a fresh bench: the simulator's terrain back to the bench file's and the machine placed at its
//! start (trucked to the next bench of the same shape), and a new session (a fresh controller, no
//! saved state), as an operator would start `run` there. Both shifts do so.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context as _;
use clap::Args;
use firmware_bridge::CanFrame;
use firmware_bridge::dbc::MESSAGES;
use firmware_bridge::id::{CONTROLLER_ADDRESS, GATEWAY_ADDRESS, J1939Id};
use firmware_bridge::messages::{GatewayFaults, GatewayMode, Message};
use firmware_bridge::secoc::SessionKey;
use firmware_bridge::transport::{FaultInjection, InProcessNode, TimestampedFrame};
use planner::autodig::AutodigMaps;
use planner::kinematics::MachinePose;
use planner::terrain::TerrainGrid;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use vcan_sim::SimConfig;
use vcan_sim::node::MachineNode;

use controller::io::operator::{self, Command};
use controller::io::run::LoopMonitor;
use controller::session::driver::SessionDriver;
use controller::session::session_state::SessionIdentity;
use controller::session::snapshot::Strategy;
use controller::session::state_file::StateFileError;
use controller::step::safety::{Fault, GATEWAY_WATCHDOG_S};
use controller::{ControllerConfig, ControllerNode};

use crate::demo::{self, DemoArgs};
use crate::harness::{Harness, HarnessOptions, PERIOD_S, SimScans};
use onboard::resume::{RunRecords, RunState};

/// Fault-free time at the start of a shift, s (the first scan, plan and arming).
pub const WARM_UP_S: f64 = 20.0;
/// Time each fault's slot keeps after the fault's end for its recovery, s.
pub const RECOVERY_ROOM_S: f64 = 25.0;
/// The simulated operator's reaction to a controller waiting for them (the page and `ctl status`
/// show it), s: noticing the stop, checking the machine and pressing resume.
pub const OPERATOR_RESPONSE_S: f64 = 5.0;
/// Garbage frames per control period.
const GARBAGE_PER_PERIOD: usize = 2;
/// Flood frames per control period (6000 frames/s, over the loop monitor's overload threshold).
const FLOOD_PER_PERIOD: usize = 60;
/// The flood's id: priority 6, an unknown PGN, from address 0x55.
const FLOOD_ID: u32 = 0x18FF_AA55;
/// Unsafe outputs kept in the report as examples.
const UNSAFE_EXAMPLES: usize = 10;
/// Longest shift, hours.
const MAX_HOURS: f64 = 24.0;

/// Arguments of `experiment shift`.
#[derive(Debug, Clone, Args)]
pub struct ShiftArgs {
    /// Simulated shift length, hours (at most 24).
    #[arg(long, default_value_t = 8.0, value_name = "H")]
    pub hours: f64,
    /// Seed of the simulator and of the fault schedule.
    #[arg(long, default_value_t = 1, value_name = "N")]
    pub seed: u64,
    /// Faults injected per hour (at least one of each kind in any shift).
    #[arg(long, default_value_t = 12.0, value_name = "N")]
    pub faults_per_hour: f64,
    /// The least share of the fault-free shift's actions the shift under faults must complete (0
    /// checks only the unsafe outputs, detection and recovery).
    #[arg(long, default_value_t = ACTIONS_TARGET, value_name = "F")]
    pub actions_target: f64,
    /// Output folder (`shift.md`, `shift.json`, the faulted shift's `session_state.json`).
    #[arg(long, default_value = "out/shift", value_name = "DIR")]
    pub out: PathBuf,
}

/// What is injected.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FaultKind {
    /// Sensor frames withheld from the controller.
    SensorDropout,
    /// Random frames from a foreign node.
    Garbage,
    /// A flood of frames from a foreign node.
    Flood,
    /// Bus-off: every frame lost.
    BusOff,
    /// The gateway's clock steps back (it latches `CLOCK_FAULT`).
    GatewayFault,
    /// The operator's e-stop, then the operator's reset.
    EStop,
    /// The controller killed, then restarted from the saved state.
    ControllerRestart,
}

impl FaultKind {
    /// Every kind, in the report's order.
    pub const ALL: [Self; 7] = [
        Self::SensorDropout,
        Self::Garbage,
        Self::Flood,
        Self::BusOff,
        Self::GatewayFault,
        Self::EStop,
        Self::ControllerRestart,
    ];

    /// The name in the report.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::SensorDropout => "sensor dropout",
            Self::Garbage => "garbage frames",
            Self::Flood => "flood",
            Self::BusOff => "bus-off",
            Self::GatewayFault => "gateway fault",
            Self::EStop => "e-stop + reset",
            Self::ControllerRestart => "controller restart",
        }
    }

    /// Duration range `[min, max)`, s (0: an instant).
    #[must_use]
    pub fn duration_s(self) -> (f64, f64) {
        match self {
            Self::SensorDropout => (0.2, 3.0),
            Self::Garbage | Self::Flood => (2.0, 10.0),
            Self::BusOff => (0.1, 2.0),
            Self::GatewayFault => (0.0, 0.0),
            Self::EStop => (5.0, 15.0),
            Self::ControllerRestart => (1.0, 10.0),
        }
    }

    /// Whether the machine must stop for it (the table's time to neutral valves): not for foreign
    /// frames, which the controller may ride through.
    #[must_use]
    pub fn stops_motion(self) -> bool {
        !matches!(self, Self::Garbage | Self::Flood)
    }

    /// What counts as detected (the report's legend).
    #[must_use]
    pub fn detection(self) -> &'static str {
        match self {
            Self::SensorDropout => "the controller's safety layer finds the sensor data stale",
            Self::Garbage => "the controller counts the frames as foreign or faulty",
            Self::Flood => "the controller's loop monitor reports a receive overload",
            Self::BusOff => "the controller gets the bus-off report or finds its sensors stale",
            Self::GatewayFault => {
                "the controller sees the gateway's fault (status or safety fault)"
            }
            Self::EStop => "the gateway latches E_STOP",
            Self::ControllerRestart => {
                "the gateway closes the dead controller's session (watchdog), valves neutral"
            }
        }
    }
}

/// One fault of the schedule.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ScheduledFault {
    /// What.
    pub kind: FaultKind,
    /// Start, shift time, s.
    pub start_s: f64,
    /// End (the reset, the restart, the bus back on; the start for an instant), shift time, s.
    pub end_s: f64,
}

/// The faults of a shift of `shift_s` for `seed` (module docs).
///
/// # Errors
/// A rate or length that leaves a slot too short for the longest fault and its recovery.
pub fn schedule(
    seed: u64,
    shift_s: f64,
    faults_per_hour: f64,
) -> anyhow::Result<Vec<ScheduledFault>> {
    anyhow::ensure!(
        faults_per_hour.is_finite() && faults_per_hour > 0.0,
        "--faults-per-hour {faults_per_hour}: a positive number"
    );
    let n = ((faults_per_hour * shift_s / 3600.0).round() as usize).max(FaultKind::ALL.len());
    let slot_s = (shift_s - WARM_UP_S) / n as f64;
    let longest = FaultKind::ALL
        .iter()
        .map(|k| k.duration_s().1)
        .fold(0.0, f64::max);
    anyhow::ensure!(
        slot_s >= longest + RECOVERY_ROOM_S + 1.0,
        "{n} faults in {:.0} s leave {slot_s:.1} s each; a fault needs up to {:.0} s (its longest \
         {longest:.0} s and {RECOVERY_ROOM_S:.0} s to recover): fewer --faults-per-hour or a longer \
         shift",
        shift_s,
        longest + RECOVERY_ROOM_S + 1.0
    );
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x5348_4946_5446_4155);
    let mut kinds = Vec::with_capacity(n);
    while kinds.len() < n {
        let mut round = FaultKind::ALL;
        for i in (1..round.len()).rev() {
            round.swap(i, rng.random_range(0..=i));
        }
        kinds.extend(round);
    }
    kinds.truncate(n);
    Ok(kinds
        .into_iter()
        .enumerate()
        .map(|(i, kind)| {
            let slot = WARM_UP_S + slot_s * i as f64;
            let (lo, hi) = kind.duration_s();
            let duration_s = if hi > lo {
                rng.random_range(lo..hi)
            } else {
                lo
            };
            let latest = slot_s - duration_s - RECOVERY_ROOM_S;
            let start_s = slot + rng.random_range(0.0..latest);
            ScheduledFault {
                kind,
                start_s,
                end_s: start_s + duration_s,
            }
        })
        .collect())
}

/// What happened to one injected fault.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FaultOutcome {
    /// The fault.
    pub fault: ScheduledFault,
    /// Time from its start to its detection, s.
    pub detect_s: Option<f64>,
    /// Time from its end to the recovery, s.
    pub recover_s: Option<f64>,
    /// Time from its start to all valve outputs neutral at the gateway, s (first time they are).
    pub neutral_s: Option<f64>,
}

/// Per kind: counts and times.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FaultRow {
    /// The kind.
    pub kind: FaultKind,
    /// Injected.
    pub count: usize,
    /// Detected.
    pub detected: usize,
    /// Recovered.
    pub recovered: usize,
    /// Median and worst time to detect, s.
    pub detect_median_s: Option<f64>,
    /// Worst time to detect, s.
    pub detect_worst_s: Option<f64>,
    /// Median time to recover, s.
    pub recover_median_s: Option<f64>,
    /// Worst time to recover, s.
    pub recover_worst_s: Option<f64>,
    /// Worst time from the fault's start to neutral valves, s.
    pub neutral_worst_s: Option<f64>,
}

/// A non-neutral valve output the rules forbid (module docs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct UnsafeOutput {
    /// Shift time, s.
    pub time_s: f64,
    /// The rule broken.
    pub rule: UnsafeRule,
    /// The applied valve commands.
    pub valve_commands: [f64; 6],
    /// The gateway's mode (`Debug` name).
    pub gateway_mode: String,
}

/// The rules of [`UnsafeOutput`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum UnsafeRule {
    /// The gateway is not armed.
    NotArmed,
    /// E-stopped for longer than the watchdog.
    EStopped,
    /// No valid heartbeat for longer than the watchdog.
    NoHeartbeat,
    /// The controller's sensor data stale beyond its rule.
    StaleSensors,
}

/// The totals of one shift.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct ShiftTotals {
    /// Digs, cleanups and track backs completed.
    pub actions: usize,
    /// Digs and cleanups completed.
    pub digs: usize,
    /// Track backs completed.
    pub backups: usize,
    /// Benches started.
    pub benches: u32,
    /// Weight dug (the controller's weighing), N.
    pub weight_n: f64,
    /// Safety faults the controller reported (repeats included).
    pub controller_faults: u64,
    /// Operator actions (resume, or reset where the stop latches) the controller waited for after a
    /// fault stopped motion (beyond the e-stops' scheduled resets).
    pub operator_resets: u64,
    /// Simulated time, s.
    pub sim_time_s: f64,
    /// Wall time, s.
    pub wall_time_s: f64,
}

/// The report of `experiment shift` (`shift.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ShiftReport {
    /// Shift length, hours.
    pub hours: f64,
    /// The seed.
    pub seed: u64,
    /// Faults per hour asked for.
    pub faults_per_hour: f64,
    /// The least share of the fault-free shift's actions asked for.
    pub actions_target: f64,
    /// The fault-free shift.
    pub reference: ShiftTotals,
    /// The shift under faults.
    pub faulted: ShiftTotals,
    /// Actions of the faulted shift over the fault-free one's.
    pub actions_ratio: f64,
    /// Physics steps with an unsafe output.
    pub unsafe_outputs: u64,
    /// The first of them.
    pub unsafe_examples: Vec<UnsafeOutput>,
    /// Per kind.
    pub faults: Vec<FaultRow>,
    /// Every fault.
    pub fault_log: Vec<FaultOutcome>,
    /// Resident memory of the process at the end of the warm-up (both shifts set up and running),
    /// KiB (`None` off Linux).
    pub rss_start_kib: Option<u64>,
    /// ... at the end.
    pub rss_end_kib: Option<u64>,
    /// ... at every simulated hour of the faulted shift `(hour, KiB)`.
    pub rss_hourly_kib: Vec<(u32, u64)>,
    /// Wall time of the whole command, s.
    pub wall_time_s: f64,
    /// CPU time of the process (both shifts), s (`None` off Linux): the wall time on a machine of
    /// its own with a core per shift is about half of it.
    pub cpu_time_s: Option<f64>,
}

/// The default least share of the fault-free shift's actions.
pub const ACTIONS_TARGET: f64 = 0.9;

impl ShiftReport {
    /// The targets missed: unsafe outputs, a fault not detected or not recovered, too few actions.
    #[must_use]
    pub fn missed_targets(&self) -> Vec<String> {
        let mut missed = Vec::new();
        if self.unsafe_outputs > 0 {
            missed.push(format!("{} unsafe outputs", self.unsafe_outputs));
        }
        for r in &self.faults {
            if r.detected < r.count || r.recovered < r.count {
                missed.push(format!(
                    "{}: {} of {} detected, {} recovered",
                    r.kind.name(),
                    r.detected,
                    r.count,
                    r.recovered
                ));
            }
        }
        if self.actions_ratio < self.actions_target {
            missed.push(format!(
                "{:.1} % of the fault-free shift's actions (target {:.0} %)",
                100.0 * self.actions_ratio,
                100.0 * self.actions_target
            ));
        }
        missed
    }

    /// The report as markdown (`shift.md`, printed).
    #[must_use]
    pub fn markdown(&self) -> String {
        use std::fmt::Write as _;
        let mut m = String::new();
        let secs = |v: Option<f64>| v.map_or("-".to_owned(), |s| format!("{s:.2}"));
        let kib =
            |v: Option<u64>| v.map_or("-".to_owned(), |k| format!("{:.1} MiB", k as f64 / 1024.0));
        let (r, f) = (&self.reference, &self.faulted);
        // Writing into a String cannot fail.
        let _ = writeln!(
            m,
            "# Shift under faults\n\n{:.2} h simulated, seed {}, {} faults ({:.1}/h); wall time {:.0} s \
             (CPU {} s, both shifts, one thread each).\n",
            self.hours,
            self.seed,
            self.fault_log.len(),
            self.faults_per_hour,
            self.wall_time_s,
            self.cpu_time_s
                .map_or("-".to_owned(), |c| format!("{c:.0}"))
        );
        let _ = writeln!(
            m,
            "**Unsafe outputs: {}** (physics steps with a non-neutral valve output at the gateway while \
             it is not armed, e-stopped, more than {:.0} ms after the last valid heartbeat, or with the \
             controller's sensors stale beyond its rule).\n",
            self.unsafe_outputs,
            1e3 * GATEWAY_WATCHDOG_S
        );
        for u in &self.unsafe_examples {
            let _ = writeln!(
                m,
                "- {:.3} s: {:?}, gateway {:?}, valves {:?}",
                u.time_s, u.rule, u.gateway_mode, u.valve_commands
            );
        }
        let _ = writeln!(
            m,
            "| shift | actions | digs + cleanups | track backs | benches | weight (kN) | controller faults | operator resumes | wall (s) |\n\
             |---|---|---|---|---|---|---|---|---|\n\
             | fault-free | {} | {} | {} | {} | {:.0} | {} | {} | {:.0} |\n\
             | under faults | {} | {} | {} | {} | {:.0} | {} | {} | {:.0} |\n",
            r.actions,
            r.digs,
            r.backups,
            r.benches,
            r.weight_n / 1e3,
            r.controller_faults,
            r.operator_resets,
            r.wall_time_s,
            f.actions,
            f.digs,
            f.backups,
            f.benches,
            f.weight_n / 1e3,
            f.controller_faults,
            f.operator_resets,
            f.wall_time_s,
        );
        let _ = writeln!(
            m,
            "Actions under faults: **{:.1} %** of the fault-free shift's (target {:.0} %).\n",
            100.0 * self.actions_ratio,
            100.0 * self.actions_target
        );
        let _ = writeln!(
            m,
            "| fault | count | detected | recovered | detect median / worst (s) | recover median / worst (s) | to neutral, worst (s) |\n\
             |---|---|---|---|---|---|---|"
        );
        for row in &self.faults {
            let _ = writeln!(
                m,
                "| {} | {} | {} | {} | {} / {} | {} / {} | {} |",
                row.kind.name(),
                row.count,
                row.detected,
                row.recovered,
                secs(row.detect_median_s),
                secs(row.detect_worst_s),
                secs(row.recover_median_s),
                secs(row.recover_worst_s),
                secs(row.neutral_worst_s)
            );
        }
        let _ = writeln!(
            m,
            "\nDetected: {}. Recovered: armed again after the fault's end with the gateway confirming \
             and no fault active.\n",
            FaultKind::ALL
                .iter()
                .map(|k| format!("{}: {}", k.name(), k.detection()))
                .collect::<Vec<_>>()
                .join("; ")
        );
        let hourly = self
            .rss_hourly_kib
            .iter()
            .map(|(h, k)| format!("{h} h {}", kib(Some(*k))))
            .collect::<Vec<_>>()
            .join(", ");
        let _ = writeln!(
            m,
            "Memory (RSS of the process, both shifts): after the warm-up {}, at the end {}{}.",
            kib(self.rss_start_kib),
            kib(self.rss_end_kib),
            if hourly.is_empty() {
                String::new()
            } else {
                format!(" (hourly: {hourly})")
            }
        );
        let missed = self.missed_targets();
        let _ = writeln!(
            m,
            "\nTargets: {}",
            if missed.is_empty() {
                "all met.".to_owned()
            } else {
                format!("MISSED: {}.", missed.join("; "))
            }
        );
        m
    }
}

/// Runs the fault-free and the faulted shift, writes `shift.md` and `shift.json` into `args.out`
/// and returns the report.
///
/// # Errors
/// Bad arguments, set-up and harness errors, the state file, writing the outputs.
pub fn run_shift(args: &ShiftArgs) -> anyhow::Result<ShiftReport> {
    let wall = Instant::now();
    anyhow::ensure!(
        args.hours.is_finite() && args.hours > 0.0 && args.hours <= MAX_HOURS,
        "--hours {}: more than 0, at most {MAX_HOURS}",
        args.hours
    );
    anyhow::ensure!(
        (0.0..=1.0).contains(&args.actions_target),
        "--actions-target {}: from 0 to 1",
        args.actions_target
    );
    let shift_s = args.hours * 3600.0;
    let faults = schedule(args.seed, shift_s, args.faults_per_hour)?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let setup = Setup::new(args)?;
    let state_path = onboard::resume::state_path(&args.out);
    // A state file of an earlier run would be resumed by the first restart.
    if state_path.exists() {
        std::fs::remove_file(&state_path)
            .with_context(|| format!("removing {}", state_path.display()))?;
    }
    let (reference, faulted) = std::thread::scope(|scope| {
        let reference = scope.spawn(|| Shift::new(&setup, &[], None)?.run(shift_s));
        let faulted = Shift::new(&setup, &faults, Some(state_path.clone()))?.run(shift_s);
        let reference = reference
            .join()
            .map_err(|_| anyhow::anyhow!("the fault-free shift panicked"))?;
        anyhow::Ok((reference?, faulted?))
    })?;
    let rss_end_kib = rss_kib();
    let report = ShiftReport {
        hours: args.hours,
        seed: args.seed,
        faults_per_hour: args.faults_per_hour,
        actions_target: args.actions_target,
        actions_ratio: if reference.totals.actions == 0 {
            0.0
        } else {
            faulted.totals.actions as f64 / reference.totals.actions as f64
        },
        reference: reference.totals,
        faulted: faulted.totals,
        unsafe_outputs: faulted.unsafe_outputs + reference.unsafe_outputs,
        unsafe_examples: faulted
            .unsafe_examples
            .iter()
            .chain(&reference.unsafe_examples)
            .take(UNSAFE_EXAMPLES)
            .cloned()
            .collect(),
        faults: fault_rows(&faulted.outcomes),
        fault_log: faulted.outcomes,
        rss_start_kib: faulted.rss_start_kib,
        rss_end_kib,
        rss_hourly_kib: faulted.rss_hourly_kib,
        wall_time_s: wall.elapsed().as_secs_f64(),
        cpu_time_s: cpu_time_s(),
    };
    let write = |name: &str, bytes: &[u8]| -> anyhow::Result<()> {
        let p = args.out.join(name);
        std::fs::write(&p, bytes).with_context(|| format!("writing {}", p.display()))
    };
    write("shift.json", &serde_json::to_vec_pretty(&report)?)?;
    write("shift.md", report.markdown().as_bytes())?;
    Ok(report)
}

/// Per kind, from every fault's outcome.
fn fault_rows(outcomes: &[FaultOutcome]) -> Vec<FaultRow> {
    let median = |mut v: Vec<f64>| -> Option<f64> {
        v.sort_by(f64::total_cmp);
        match v.len() {
            0 => None,
            n if n % 2 == 1 => Some(v[n / 2]),
            n => Some(0.5 * (v[n / 2 - 1] + v[n / 2])),
        }
    };
    let worst = |v: &[f64]| v.iter().copied().reduce(f64::max);
    FaultKind::ALL
        .iter()
        .map(|&kind| {
            let of: Vec<&FaultOutcome> = outcomes.iter().filter(|o| o.fault.kind == kind).collect();
            let detect: Vec<f64> = of.iter().filter_map(|o| o.detect_s).collect();
            let recover: Vec<f64> = of.iter().filter_map(|o| o.recover_s).collect();
            let neutral: Vec<f64> = of.iter().filter_map(|o| o.neutral_s).collect();
            FaultRow {
                kind,
                count: of.len(),
                detected: detect.len(),
                recovered: recover.len(),
                detect_worst_s: worst(&detect),
                detect_median_s: median(detect),
                recover_worst_s: worst(&recover),
                recover_median_s: median(recover),
                neutral_worst_s: worst(&neutral),
            }
        })
        .collect()
}

/// Resident memory of this process, KiB (Linux `/proc/self/status`).
fn rss_kib() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
}

/// CPU time of this process (user and system), s (Linux `/proc/self/stat`, at 100 ticks/s).
fn cpu_time_s() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // The fields after the command name (which may hold spaces), from field 3 on.
    let rest = stat.rsplit_once(')')?.1;
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let ticks = |i: usize| fields.get(i)?.parse::<u64>().ok();
    // utime and stime are fields 14 and 15 of the line, 12 and 13 after the name.
    Some((ticks(11)? + ticks(12)?) as f64 / 100.0)
}

/// What both shifts share: the simulator, the controller's configuration, the session identity,
/// the bench to start again from.
struct Setup {
    dargs: DemoArgs,
    sim: SimConfig,
    config: ControllerConfig,
    maps: AutodigMaps,
    identity: SessionIdentity,
    key: SessionKey,
    bench: TerrainGrid,
    start: MachinePose,
}

impl Setup {
    fn new(args: &ShiftArgs) -> anyhow::Result<Self> {
        let mut dargs = DemoArgs::defaults(args.out.clone());
        dargs.seed = Some(args.seed);
        let (sim, mut config, maps) = demo::setup(&dargs)?;
        // The session runs until its bench is done.
        config.cycle.max_digs = None;
        let planner = demo::planner_config(&dargs, &sim)?;
        let identity = onboard::run::session_identity(
            &sim.machine,
            &sim.scenario.site(),
            sim.scenario.seed,
            demo::DemoStrategy::Planned,
            &config,
            &planner,
            &maps,
        );
        let plant = sim.build().context("simulator")?;
        let bench = plant.world.terrain.clone();
        let start = plant.pose();
        let key = crate::harness::session_key(sim.scenario.seed);
        Ok(Self {
            dargs,
            sim,
            config,
            maps,
            identity,
            key,
            bench,
            start,
        })
    }

    /// A fresh controller and its session driver, going on from the state file `resume` when given
    /// and present (`run --resume`).
    fn controller(&self, resume: Option<&Path>) -> anyhow::Result<(ControllerNode, SessionDriver)> {
        let session = demo::build_session(&self.dargs, &self.sim, Strategy::Planned)?;
        let mut node =
            ControllerNode::new(&self.sim.machine, self.maps.clone(), self.config.clone())
                .context("controller")?;
        let mut driver = SessionDriver::new(Some(session), None, &mut node);
        if let Some(path) = resume.filter(|p| p.exists()) {
            let state: RunState = controller::session::session_state::load(path, &self.identity)
                .context("resuming the saved session")?;
            driver
                .restore(&state.driver, &mut node)
                .map_err(|e| StateFileError::field(path, e))
                .context("resuming the saved session")?;
        }
        Ok((node, driver))
    }
}

/// The monitor of the gateway's outputs (module docs, "Unsafe outputs"), fed after every physics
/// step.
#[derive(Debug)]
struct OutputMonitor {
    /// When the last valid heartbeat reached the gateway, s.
    last_heartbeat_s: f64,
    /// When the controller last received the sensor frames, s.
    last_sensors_s: f64,
    /// When an e-stop in force was requested, s.
    estop_since_s: Option<f64>,
    sensor_bound_s: f64,
    unsafe_outputs: u64,
    examples: Vec<UnsafeOutput>,
    /// The valves were all neutral in the last physics step, and since when.
    neutral_since_s: Option<f64>,
}

impl OutputMonitor {
    fn new(sensor_max_age_s: f64) -> Self {
        Self {
            last_heartbeat_s: 0.0,
            last_sensors_s: 0.0,
            estop_since_s: None,
            sensor_bound_s: sensor_max_age_s + 2.0 * PERIOD_S,
            unsafe_outputs: 0,
            examples: Vec::new(),
            neutral_since_s: Some(0.0),
        }
    }

    fn watch(&mut self, m: &MachineNode) {
        let t = m.time_s();
        let u = m.valve_commands();
        if u.iter().all(|&v| v == 0.0) {
            self.neutral_since_s.get_or_insert(t);
            return;
        }
        self.neutral_since_s = None;
        let mode = m.gateway().mode();
        // A little slack for the float sums of the step times.
        let over = |since: f64, bound: f64| t - since > bound + 1e-9;
        let rule = if !matches!(mode, GatewayMode::ArmedValve | GatewayMode::ArmedPosition) {
            Some(UnsafeRule::NotArmed)
        } else if self
            .estop_since_s
            .is_some_and(|s| over(s, GATEWAY_WATCHDOG_S))
        {
            Some(UnsafeRule::EStopped)
        } else if over(self.last_heartbeat_s, GATEWAY_WATCHDOG_S) {
            Some(UnsafeRule::NoHeartbeat)
        } else if over(self.last_sensors_s, self.sensor_bound_s) {
            Some(UnsafeRule::StaleSensors)
        } else {
            None
        };
        if let Some(rule) = rule {
            self.unsafe_outputs += 1;
            if self.examples.len() < UNSAFE_EXAMPLES {
                tracing::error!(time_s = t, ?rule, ?u, ?mode, "unsafe valve output");
                self.examples.push(UnsafeOutput {
                    time_s: t,
                    rule,
                    valve_commands: u,
                    gateway_mode: format!("{mode:?}"),
                });
            }
        }
    }
}

/// A fault in progress (from its start until it is recovered or the next one starts).
#[derive(Debug)]
struct Tracked {
    outcome: FaultOutcome,
    /// The end's action was taken (the bus back on, the reset, the restart).
    ended: bool,
    /// Counters at the start, to see the fault's frames counted.
    foreign_at_start: u64,
    bus_errors_at_start: u64,
    /// The gateway's session at the start (controller restart).
    session_at_start: u32,
}

/// The result of one shift.
#[derive(Debug)]
struct ShiftRun {
    totals: ShiftTotals,
    outcomes: Vec<FaultOutcome>,
    unsafe_outputs: u64,
    unsafe_examples: Vec<UnsafeOutput>,
    rss_start_kib: Option<u64>,
    rss_hourly_kib: Vec<(u32, u64)>,
}

/// One shift: the harness, the controller's session driver, the faults to inject.
struct Shift<'a> {
    setup: &'a Setup,
    faults: &'a [ScheduledFault],
    state_path: Option<PathBuf>,
    h: Harness,
    /// `None` while the controller is down.
    driver: Option<SessionDriver>,
    attacker: InProcessNode,
    rng: ChaCha8Rng,
    monitor: OutputMonitor,
    loop_monitor: LoopMonitor,
    foreign_seen: u64,
    overload_seen: bool,
    totals: ShiftTotals,
    /// Actions, digs, backups and weight of the finished benches.
    done: (usize, usize, usize, f64),
    /// Safety faults of the controllers that are gone.
    faults_before: u64,
    next_fault: usize,
    tracked: Option<Tracked>,
    outcomes: Vec<FaultOutcome>,
    bus_off: bool,
    reset_wanted_since_s: Option<f64>,
    rss_hourly_kib: Vec<(u32, u64)>,
}

impl<'a> Shift<'a> {
    fn new(
        setup: &'a Setup,
        faults: &'a [ScheduledFault],
        state_path: Option<PathBuf>,
    ) -> anyhow::Result<Self> {
        let options = HarnessOptions {
            key: Some(setup.key.clone()),
            ..HarnessOptions::default()
        };
        let mut h = Harness::with_options(
            &setup.sim,
            setup.maps.clone(),
            setup.config.clone(),
            &options,
        )
        .context("harness")?;
        let (node, driver) = setup.controller(None)?;
        h.start_controller(node);
        let attacker = h.bus.attach_with_queue(1);
        Ok(Self {
            setup,
            faults,
            state_path,
            h,
            driver: Some(driver),
            attacker,
            rng: ChaCha8Rng::seed_from_u64(setup.sim.scenario.seed ^ 0x4741_5242_4147_4521),
            monitor: OutputMonitor::new(setup.config.safety.sensor_max_age_s),
            loop_monitor: LoopMonitor::new(),
            foreign_seen: 0,
            overload_seen: false,
            totals: ShiftTotals {
                benches: 1,
                ..ShiftTotals::default()
            },
            done: (0, 0, 0, 0.0),
            faults_before: 0,
            next_fault: 0,
            tracked: None,
            outcomes: Vec::new(),
            bus_off: false,
            reset_wanted_since_s: None,
            rss_hourly_kib: Vec::new(),
        })
    }

    fn run(mut self, shift_s: f64) -> anyhow::Result<ShiftRun> {
        let wall = Instant::now();
        let mut next_hour = 1_u32;
        let mut rss_start_kib = None;
        while self.h.time_s() < shift_s {
            self.step()?;
            if rss_start_kib.is_none() && self.h.time_s() >= WARM_UP_S {
                rss_start_kib = rss_kib();
            }
            if self.h.time_s() >= f64::from(next_hour) * 3600.0 {
                if !self.faults.is_empty()
                    && let Some(k) = rss_kib()
                {
                    self.rss_hourly_kib.push((next_hour, k));
                }
                next_hour += 1;
            }
        }
        self.finish_tracked();
        self.count_actions();
        self.totals.sim_time_s = self.h.time_s();
        self.totals.wall_time_s = wall.elapsed().as_secs_f64();
        Ok(ShiftRun {
            totals: self.totals,
            outcomes: self.outcomes,
            unsafe_outputs: self.monitor.unsafe_outputs,
            unsafe_examples: self.monitor.examples,
            rss_start_kib,
            rss_hourly_kib: self.rss_hourly_kib,
        })
    }

    /// The current fault, if one is between its start and its end.
    fn active(&self) -> Option<FaultKind> {
        self.tracked
            .as_ref()
            .filter(|t| !t.ended)
            .map(|t| t.outcome.fault.kind)
    }

    /// One control period: the faults' transitions, the foreign frames, the harness's step with the
    /// output monitor, the session driver, detection and recovery.
    fn step(&mut self) -> anyhow::Result<()> {
        let now = self.h.time_s();
        self.fault_transitions(now)?;
        self.send_foreign_frames();
        let dropout = self.active() == Some(FaultKind::SensorDropout);
        let monitor = &mut self.monitor;
        let out = self.h.step_watched(
            |inbox| {
                if dropout {
                    inbox.retain(|f| !is_sensor_frame(f));
                }
            },
            |m| monitor.watch(m),
        )?;
        let t = self.h.time_s();
        let gateway_session = self.h.machine.node().gateway().session().session_id;
        if !self.bus_off {
            if !dropout {
                self.monitor.last_sensors_s = t;
            }
            let heartbeat = out.iter().any(|f| {
                matches!(
                    Message::decode(f).map(|d| d.message),
                    Ok(Message::ControllerHeartbeat(_))
                )
            });
            if heartbeat && self.h.node().and_then(ControllerNode::session) == Some(gateway_session)
            {
                // The gateway takes it in its next physics step.
                self.monitor.last_heartbeat_s = t + self.h.machine.physics_dt_s();
            }
        }
        self.watch_load(t);
        if let (Some(driver), Some((node, machine))) = (self.driver.as_mut(), self.h.parts_mut()) {
            driver.after_step(node, &mut SimScans::new(machine))?;
            if let (Some(path), Some(cp)) = (&self.state_path, driver.checkpoint()) {
                let state = onboard::resume::run_state(
                    &self.setup.identity,
                    cp.clone(),
                    RunRecords {
                        session_time_s: t,
                        ..RunRecords::default()
                    },
                );
                controller::session::state_file::save(path, &state)
                    .context("saving the session state")?;
            }
        }
        self.operator(t);
        self.track(t);
        if self.h.node().is_some_and(ControllerNode::finished) {
            self.new_bench()?;
        }
        Ok(())
    }

    /// Starts and ends the scheduled faults due at `now`.
    fn fault_transitions(&mut self, now: f64) -> anyhow::Result<()> {
        if let Some(t) = &self.tracked
            && !t.ended
            && now >= t.outcome.fault.end_s
        {
            let kind = t.outcome.fault.kind;
            self.end_fault(kind, now)?;
            if let Some(t) = &mut self.tracked {
                t.ended = true;
            }
        }
        if let Some(&fault) = self.faults.get(self.next_fault)
            && now >= fault.start_s
        {
            self.next_fault += 1;
            self.finish_tracked();
            let counters = self
                .h
                .node()
                .map(ControllerNode::counters)
                .unwrap_or_default();
            self.tracked = Some(Tracked {
                outcome: FaultOutcome {
                    fault,
                    detect_s: None,
                    recover_s: None,
                    neutral_s: None,
                },
                ended: false,
                foreign_at_start: counters.ignored + counters.faulty,
                bus_errors_at_start: counters.bus_errors,
                session_at_start: self.h.machine.node().gateway().session().session_id,
            });
            self.overload_seen = false;
            self.start_fault(fault.kind, now)?;
            if fault.end_s <= now
                && let Some(t) = &mut self.tracked
            {
                t.ended = true;
            }
        }
        Ok(())
    }

    fn start_fault(&mut self, kind: FaultKind, now: f64) -> anyhow::Result<()> {
        tracing::info!(time_s = now, fault = kind.name(), "fault injected");
        match kind {
            FaultKind::SensorDropout | FaultKind::Garbage | FaultKind::Flood => {}
            FaultKind::BusOff => {
                self.h
                    .bus
                    .inject_error(CanFrame::new_error(ERR_BUSOFF, [0; 8])?)?;
                self.h.bus.set_faults(FaultInjection {
                    loss_probability: 1.0,
                    ..FaultInjection::default()
                });
                self.bus_off = true;
            }
            FaultKind::GatewayFault => {
                // The gateway's clock steps back a second: it latches CLOCK_FAULT.
                self.h
                    .machine
                    .node_mut()
                    .gateway_mut()
                    .tick(now - 1.0, None);
            }
            FaultKind::EStop => {
                if let Some(node) = self.h.node_mut() {
                    operator::apply(node, Command::Estop, "shift: scheduled e-stop", now);
                    self.monitor.estop_since_s = Some(now);
                }
            }
            FaultKind::ControllerRestart => {
                self.kill_controller();
            }
        }
        Ok(())
    }

    fn end_fault(&mut self, kind: FaultKind, now: f64) -> anyhow::Result<()> {
        match kind {
            FaultKind::SensorDropout
            | FaultKind::Garbage
            | FaultKind::Flood
            | FaultKind::GatewayFault => {}
            FaultKind::BusOff => {
                self.h.bus.set_faults(FaultInjection::default());
                self.bus_off = false;
                self.h
                    .bus
                    .inject_error(CanFrame::new_error(ERR_RESTARTED, [0; 8])?)?;
            }
            FaultKind::EStop => {
                if let Some(node) = self.h.node_mut() {
                    operator::apply(node, Command::Reset, "shift: e-stop cleared", now);
                }
                self.monitor.estop_since_s = None;
            }
            FaultKind::ControllerRestart => {
                let (node, driver) = self.setup.controller(self.state_path.as_deref())?;
                self.h.start_controller(node);
                self.driver = Some(driver);
                self.foreign_seen = 0;
            }
        }
        Ok(())
    }

    /// The garbage and flood frames of this period, from the foreign node.
    fn send_foreign_frames(&mut self) {
        let frames = match self.active() {
            Some(FaultKind::Garbage) => (0..GARBAGE_PER_PERIOD)
                .filter_map(|_| garbage_frame(&mut self.rng))
                .collect(),
            Some(FaultKind::Flood) => {
                let data = [0xA5_u8; 8];
                (0..FLOOD_PER_PERIOD)
                    .filter_map(|_| CanFrame::new_extended(FLOOD_ID, &data).ok())
                    .collect()
            }
            _ => Vec::new(),
        };
        for f in frames {
            // The in-process bus never refuses a frame.
            let _ = self.attacker.send(f);
        }
    }

    /// The loop monitor over the controller's received frames (as `run`'s loop feeds it).
    fn watch_load(&mut self, t: f64) {
        let Some(node) = self.h.node() else {
            return;
        };
        for _ in self.h.inbox() {
            self.loop_monitor.on_received();
        }
        let c = node.counters();
        let foreign = c.ignored + c.faulty;
        self.loop_monitor
            .on_foreign(foreign.saturating_sub(self.foreign_seen));
        self.foreign_seen = foreign;
        if let Some(report) = self.loop_monitor.on_tick(t)
            && report.overloaded()
        {
            tracing::warn!(
                frames_per_s = report.frames_per_s.round(),
                foreign_per_s = report.foreign_per_s.round(),
                "bus overload"
            );
            self.overload_seen = true;
        }
    }

    /// The simulated operator: resumes (or resets, where the stop latches) a controller that waits
    /// for them after a fault, [`OPERATOR_RESPONSE_S`] after it started waiting (not an e-stop in
    /// force: its reset is the schedule's).
    fn operator(&mut self, t: f64) {
        let estop = self.monitor.estop_since_s.is_some();
        let Some(node) = self.h.node_mut() else {
            return;
        };
        if estop || !node.safety().needs_reset() {
            self.reset_wanted_since_s = None;
            return;
        }
        let since = *self.reset_wanted_since_s.get_or_insert(t);
        if t - since >= OPERATOR_RESPONSE_S {
            let (cmd, reason) = if node.safety().needs_full_reset() {
                (Command::Reset, "shift: the controller waits for a reset")
            } else {
                (Command::Resume, "shift: the controller waits for a resume")
            };
            operator::apply(node, cmd, reason, t);
            self.totals.operator_resets += 1;
            self.reset_wanted_since_s = None;
        }
    }

    /// Detection, neutral outputs and recovery of the fault in progress.
    fn track(&mut self, t: f64) {
        let Some(tr) = &mut self.tracked else {
            return;
        };
        let fault = tr.outcome.fault;
        if tr.outcome.neutral_s.is_none()
            && fault.kind.stops_motion()
            && let Some(since) = self.monitor.neutral_since_s
        {
            tr.outcome.neutral_s = Some((since - fault.start_s).max(0.0));
        }
        let node = self.h.node();
        let gateway = self.h.machine.node().gateway();
        if tr.outcome.detect_s.is_none() {
            let detected = match fault.kind {
                FaultKind::SensorDropout => node.is_some_and(|n| {
                    stale_sensor(n.safety().health().err()) || stale_sensor(n.fault())
                }),
                FaultKind::Garbage => node.is_some_and(|n| {
                    let c = n.counters();
                    c.ignored + c.faulty > tr.foreign_at_start
                }),
                FaultKind::Flood => self.overload_seen,
                FaultKind::BusOff => node.is_some_and(|n| {
                    n.counters().bus_errors > tr.bus_errors_at_start
                        || stale_sensor(n.safety().health().err())
                }),
                FaultKind::GatewayFault => node.is_some_and(|n| {
                    n.state()
                        .gateway
                        .is_some_and(|g| g.faults.contains(GatewayFaults::CLOCK_FAULT))
                        || matches!(
                            n.fault(),
                            Some(Fault::GatewayFault(_) | Fault::GatewayMode { .. })
                        )
                }),
                FaultKind::EStop => gateway.faults().contains(GatewayFaults::E_STOP),
                FaultKind::ControllerRestart => {
                    gateway.session().session_id != tr.session_at_start
                        && !matches!(
                            gateway.mode(),
                            GatewayMode::ArmedValve | GatewayMode::ArmedPosition
                        )
                }
            };
            if detected {
                tr.outcome.detect_s = Some(t - fault.start_s);
            }
        }
        if tr.ended && tr.outcome.recover_s.is_none() {
            let recovered = node.is_some_and(|n| {
                n.fault().is_none()
                    && n.safety()
                        .motion()
                        .is_some_and(|m| gateway.mode() == m.gateway_mode())
            });
            if recovered {
                tr.outcome.recover_s = Some((t - fault.end_s).max(0.0));
            }
        }
    }

    /// Files the fault in progress.
    fn finish_tracked(&mut self) {
        if let Some(t) = self.tracked.take() {
            if t.outcome.detect_s.is_none() || t.outcome.recover_s.is_none() {
                tracing::warn!(outcome = ?t.outcome, "fault not detected or not recovered");
            }
            self.outcomes.push(t.outcome);
        }
    }

    /// Adds the current session's completed actions to the totals.
    fn count_actions(&mut self) {
        let (actions, digs, backups, weight) = self.done;
        let (d, b, w) = match (self.h.node(), &self.driver) {
            (Some(n), Some(driver)) => (
                n.statistics().len(),
                driver.backups(),
                n.statistics()
                    .iter()
                    .filter_map(|s| s.weight_n)
                    .sum::<f64>(),
            ),
            _ => (0, 0, 0.0),
        };
        self.totals.actions = actions + d + b;
        self.totals.digs = digs + d;
        self.totals.backups = backups + b;
        self.totals.weight_n = weight + w;
        self.totals.controller_faults =
            self.faults_before + self.h.node().map_or(0, |n| n.safety().fault_count());
    }

    /// Stops the controller (its faults counted) and drops its driver.
    fn kill_controller(&mut self) {
        self.faults_before += self.h.node().map_or(0, |n| n.safety().fault_count());
        self.h.kill_controller();
        self.driver = None;
    }

    /// The session's bench is done: a fresh bench and a new session on it (module docs).
    fn new_bench(&mut self) -> anyhow::Result<()> {
        self.count_actions();
        self.done = (
            self.totals.actions,
            self.totals.digs,
            self.totals.backups,
            self.totals.weight_n,
        );
        let t = self.h.time_s();
        tracing::info!(
            time_s = t,
            bench = self.totals.benches,
            actions = self.totals.actions,
            "bench done: a fresh bench"
        );
        if let Some(node) = self.h.node_mut() {
            let frames = node.shutdown(t);
            self.h.send_from_controller(frames.as_slice())?;
        }
        self.kill_controller();
        self.h.machine.advance(2.0 * PERIOD_S);
        let plant = self.h.machine.node_mut().plant_mut();
        plant.world.terrain = self.setup.bench.clone();
        plant.place(self.setup.start);
        if let Some(p) = &self.state_path
            && p.exists()
        {
            std::fs::remove_file(p).with_context(|| format!("removing {}", p.display()))?;
        }
        let (node, driver) = self.setup.controller(None)?;
        self.h.start_controller(node);
        self.driver = Some(driver);
        self.foreign_seen = 0;
        self.totals.benches += 1;
        Ok(())
    }
}

/// Linux error class bits (`linux/can/error.h`): bus-off, restarted.
const ERR_BUSOFF: u32 = 0x040;
const ERR_RESTARTED: u32 = 0x100;

/// Whether `fault` is a stale control signal (not the gateway status).
fn stale_sensor(fault: Option<Fault>) -> bool {
    matches!(fault, Some(Fault::StaleSensor { signal, .. })
        if signal != controller::step::estimate::Signal::GatewayStatus)
}

/// Whether `f` is one of the gateway's sensor frames.
fn is_sensor_frame(f: &TimestampedFrame) -> bool {
    match Message::decode(&f.frame) {
        Ok(d) => {
            d.id.source_address() == GATEWAY_ADDRESS
                && matches!(
                    d.message,
                    Message::JointAngles(_)
                        | Message::JointRates(_)
                        | Message::AuxValveMeasured(_)
                        | Message::PumpPressures(_)
                        | Message::TrackOdometry(_)
                )
        }
        Err(_) => false,
    }
}

/// A random frame: a random 29- or 11-bit id, or one of the protocol's ids from the gateway's, the
/// controller's or another address; random length and bytes.
fn garbage_frame(rng: &mut ChaCha8Rng) -> Option<CanFrame> {
    let len = rng.random_range(0..=8_usize);
    let mut data = [0_u8; 8];
    for b in &mut data[..len] {
        *b = rng.random_range(0..=u8::MAX);
    }
    match rng.random_range(0..4_u8) {
        0 => CanFrame::new_extended(rng.random_range(0..=0x1FFF_FFFF_u32), &data[..len]).ok(),
        1 => CanFrame::new_standard(rng.random_range(0..=0x7FF_u16), &data[..len]).ok(),
        _ => {
            let desc = &MESSAGES[rng.random_range(0..MESSAGES.len())];
            let source = match rng.random_range(0..3_u8) {
                0 => GATEWAY_ADDRESS,
                1 => CONTROLLER_ADDRESS,
                _ => rng.random_range(0..=u8::MAX),
            };
            let id = J1939Id::from_raw(desc.default_id)
                .ok()?
                .with_source_address(source);
            // The protocol's length most of the time, so the bytes are what is wrong.
            let len = if rng.random_range(0..4_u8) == 0 {
                len
            } else {
                usize::from(desc.dlc).min(8)
            };
            CanFrame::new_extended(id.raw(), &data[..len]).ok()
        }
    }
}

/// The printed report of `experiment shift`: the markdown; an error after it when a target is
/// missed.
///
/// # Errors
/// As [`run_shift`]; a missed target.
pub fn report(args: &ShiftArgs) -> anyhow::Result<String> {
    let report = run_shift(args)?;
    let text = report.markdown();
    let missed = report.missed_targets();
    if missed.is_empty() {
        Ok(text)
    } else {
        print!("{text}");
        anyhow::bail!("shift under faults: {}", missed.join("; "))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_schedule_has_every_kind_in_slots_with_room_to_recover() {
        let shift_s = 3600.0;
        let faults = schedule(3, shift_s, 12.0).unwrap_or_else(|e| panic!("{e:#}"));
        assert_eq!(faults.len(), 12);
        for kind in FaultKind::ALL {
            assert!(faults.iter().any(|f| f.kind == kind), "{kind:?}");
        }
        for w in faults.windows(2) {
            assert!(w[0].end_s + RECOVERY_ROOM_S <= w[1].start_s, "{w:?}");
        }
        assert!(faults[0].start_s >= WARM_UP_S);
        assert!(faults.iter().all(|f| f.end_s + RECOVERY_ROOM_S <= shift_s));
        assert_eq!(faults, schedule(3, shift_s, 12.0).unwrap_or_default());
        assert_ne!(faults, schedule(4, shift_s, 12.0).unwrap_or_default());
    }

    #[test]
    fn a_schedule_too_dense_for_recovery_is_refused() {
        let err = schedule(1, 300.0, 12.0).map(|_| ()).unwrap_err();
        assert!(
            err.to_string().contains("fewer --faults-per-hour"),
            "{err:#}"
        );
        assert!(schedule(1, 3600.0, f64::NAN).is_err());
    }

    #[test]
    fn garbage_frames_are_varied_and_never_refused() {
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let frames: Vec<CanFrame> = (0..1000).filter_map(|_| garbage_frame(&mut rng)).collect();
        assert!(frames.len() > 990);
        let standard = frames
            .iter()
            .filter(|f| matches!(f.id(), firmware_bridge::frame::CanId::Standard(_)))
            .count();
        assert!(standard > 150 && standard < 350, "{standard}");
    }
}
