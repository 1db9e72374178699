//! The machine as a CAN node, without I/O: the gateway firmware ([`firmware_bridge::gateway`]) in
//! front of the [`Plant`]. Frames go in with [`MachineNode::on_frame`]; [`MachineNode::step`] runs one
//! 1 kHz physics step and returns the frames to transmit. Both the real-time loop and the in-process
//! embedded machine drive this same code.
//!
//! Transmit schedule (gateway source address `0x80`), the rates of `docs/protocol.md` and
//! [`firmware_bridge::busload::SCHEDULE`] (a test checks they agree):
//! - every 10 ms (100 Hz): `JointAngles`, `JointRates`, `AuxValveMeasured` for boom, stick, bucket;
//! - every 20 ms (50 Hz): `PumpPressures`;
//! - every 50 ms (20 Hz): `TrackOdometry`, `GatewayStatus` and `GatewaySession`.
//!
//! A machine profile's gateway ([`MachineNode::with_timing`]) sends at the profile's periods and
//! keeps its watchdogs ([`Schedule`]).
//!
//! Before any of these the gateway claims its address (J1939-81 Address Claimed at the first step,
//! `firmware_bridge::address_claim`, with the NAME of the machine file's `[gateway_name]`); sensor
//! frames, odometry and status go out only once the claim has stood for 250 ms, and not after the
//! address was lost to a lower NAME (the gateway then holds the valves neutral with `ADDRESS_LOST`
//! latched) until a Request for Address Claimed to global made it claim again and that claim stood.
//! Claim frames (a re-claim, the answer to a request, Cannot Claim) go out at the next step.
//!
//! Only sensor readings and the gateway status go out; nothing reveals the hidden effects.

use firmware_bridge::CanFrame;
use firmware_bridge::gateway::{Gateway, GatewayConfig, GatewayConfigError};
use firmware_bridge::messages::{
    AuxValveMeasured, Cylinder, JointAngles, JointRates, Message, PumpPressures, TrackOdometry,
    ValveState,
};
use firmware_bridge::profile::GatewayTiming;
use firmware_bridge::secoc::{OsNonceSource, SessionKey};
use firmware_bridge::time::Instant;

use crate::plant::{PHYSICS_DT_S, PendingScan, Plant};
use crate::sensors::{Scan, ScanCast, ScanRequest, SensorReadings};

/// Physics steps in `period` (the DBC's cycle times are whole milliseconds, a whole number of steps:
/// a test checks).
const fn steps_of(period: std::time::Duration) -> u64 {
    // Rounded to the nearest step (`f64::round` is not `const` at the crate's rust-version).
    (period.as_secs_f64() / PHYSICS_DT_S + 0.5) as u64
}

/// Steps between sensor frames (10 ms, [`firmware_bridge::dbc::SENSOR_PERIOD`]).
pub const SENSOR_PERIOD_STEPS: u64 = steps_of(firmware_bridge::dbc::SENSOR_PERIOD);
/// Steps between pump pressure frames (20 ms, [`firmware_bridge::dbc::PUMP_PERIOD`]).
pub const PUMP_PERIOD_STEPS: u64 = steps_of(firmware_bridge::dbc::PUMP_PERIOD);
/// Steps between odometry frames (50 ms, [`firmware_bridge::dbc::ODOMETRY_PERIOD`]); the off-map
/// check runs at this rate too.
pub const ODOMETRY_PERIOD_STEPS: u64 = steps_of(firmware_bridge::dbc::ODOMETRY_PERIOD);
/// Steps between gateway status frames (50 ms, [`firmware_bridge::dbc::STATUS_PERIOD`]).
pub const STATUS_PERIOD_STEPS: u64 = steps_of(firmware_bridge::dbc::STATUS_PERIOD);

/// The gateway's transmit periods, physics steps.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Schedule {
    /// `JointAngles`, `JointRates`, `AuxValveMeasured` (the sensors are sampled at this rate).
    pub sensor: u64,
    /// `PumpPressures`.
    pub pump: u64,
    /// `TrackOdometry` (and the off-map check).
    pub odometry: u64,
    /// `GatewayStatus` and `GatewaySession`.
    pub status: u64,
}

impl Default for Schedule {
    fn default() -> Self {
        Self {
            sensor: SENSOR_PERIOD_STEPS,
            pump: PUMP_PERIOD_STEPS,
            odometry: ODOMETRY_PERIOD_STEPS,
            status: STATUS_PERIOD_STEPS,
        }
    }
}

impl Schedule {
    /// The periods of a profile's gateway (whole ms, so whole steps; at least one step each).
    pub fn of(timing: &GatewayTiming) -> Self {
        let steps = |ms: u32| steps_in(GatewayTiming::secs(ms)).max(1);
        Self {
            sensor: steps(timing.sensor_period_ms),
            pump: steps(timing.pump_period_ms),
            odometry: steps(timing.odometry_period_ms),
            status: steps(timing.status_period_ms),
        }
    }
}

/// The gateway and the plant behind it.
#[derive(Debug, Clone)]
pub struct MachineNode {
    plant: Plant,
    gateway: Gateway,
    schedule: Schedule,
    readings: Option<SensorReadings>,
    steps: u64,
    valve_commands: [f64; 6],
    encode_errors: u64,
    /// Whether the machine stands outside the simulated terrain map (warned once on leaving).
    off_map: bool,
    /// Whether the lost address claim has been logged.
    address_lost_logged: bool,
}

impl MachineNode {
    /// A node with the default gateway configuration, its session nonces from the OS random source
    /// (a simulation that must be reproducible reseeds them: [`Self::set_security`]).
    pub fn new(plant: Plant) -> Self {
        Self::with(plant, Gateway::with_default_config(&mut OsNonceSource))
    }

    /// A node with a given gateway configuration.
    ///
    /// # Errors
    /// [`GatewayConfigError`] if the configuration does not validate.
    pub fn with_gateway(plant: Plant, config: GatewayConfig) -> Result<Self, GatewayConfigError> {
        Ok(Self::with(plant, Gateway::new(config, &mut OsNonceSource)?))
    }

    /// The same node with the gateway's key (both ends hold it; [`SessionKey::PUBLIC`] when none is
    /// provisioned) and session seed (see [`Gateway::with_security`]: it must differ at every start
    /// outside a reproducible simulation).
    pub fn with_security(mut self, key: &SessionKey, session_seed: u64) -> Self {
        self.set_security(key, session_seed);
        self
    }

    /// As [`Self::with_security`] in place (before the first step: the gateway starts a new session).
    pub fn set_security(&mut self, key: &SessionKey, session_seed: u64) {
        self.gateway.set_security(key, session_seed);
    }

    /// A node whose gateway sends at `timing`'s periods and keeps its watchdogs (a machine profile's
    /// gateway; [`GatewayTiming::canonical`] is [`Self::new`]'s).
    ///
    /// # Errors
    /// [`GatewayConfigError`] if the timeouts do not validate.
    pub fn with_timing(plant: Plant, timing: &GatewayTiming) -> Result<Self, GatewayConfigError> {
        let config = GatewayConfig {
            heartbeat_timeout_s: GatewayTiming::secs(timing.heartbeat_timeout_ms),
            command_timeout_s: GatewayTiming::secs(timing.command_timeout_ms),
            ..GatewayConfig::default()
        };
        let mut node = Self::with_gateway(plant, config)?;
        node.schedule = Schedule::of(timing);
        Ok(node)
    }

    /// The gateway's transmit periods.
    pub fn schedule(&self) -> Schedule {
        self.schedule
    }

    /// Sets the gateway's J1939 NAME (the machine file's `[gateway_name]`, [`crate::SimConfig`]).
    /// Call before the first step.
    pub fn set_gateway_name(&mut self, name: firmware_bridge::address_claim::Name) {
        self.gateway.set_name(name);
    }

    /// Makes the gateway hold its address claim `margin_ns` longer than 250 ms
    /// ([`Gateway::with_claim_hold_margin`]). Call before the first step.
    pub fn set_claim_hold_margin(&mut self, margin_ns: i64) {
        self.gateway.set_claim_hold_margin(margin_ns);
    }

    fn with(plant: Plant, gateway: Gateway) -> Self {
        Self {
            plant,
            gateway,
            schedule: Schedule::default(),
            readings: None,
            steps: 0,
            valve_commands: [0.0; 6],
            encode_errors: 0,
            off_map: false,
            address_lost_logged: false,
        }
    }

    /// Whether the machine stands outside the simulated terrain map: the terrain there is not
    /// simulated, so scans see nothing and a planner finds no material.
    pub fn off_map(&self) -> bool {
        self.off_map
    }

    /// Simulation time (s).
    pub fn time_s(&self) -> f64 {
        self.plant.time_s()
    }

    /// The plant.
    pub fn plant(&self) -> &Plant {
        &self.plant
    }

    /// The plant, mutably (tests and tools).
    pub fn plant_mut(&mut self) -> &mut Plant {
        &mut self.plant
    }

    /// The gateway firmware.
    pub fn gateway(&self) -> &Gateway {
        &self.gateway
    }

    /// The gateway firmware, mutably (fault injection in tests and the lab: a clock step, say).
    pub fn gateway_mut(&mut self) -> &mut Gateway {
        &mut self.gateway
    }

    /// The valve commands the gateway applied in the last step.
    pub fn valve_commands(&self) -> [f64; 6] {
        self.valve_commands
    }

    /// Frames that could not be encoded (values outside the DBC ranges); they are not sent.
    pub fn encode_errors(&self) -> u64 {
        self.encode_errors
    }

    /// The gateway's clock: the physics steps done, as an integer [`Instant`] (the simulation time
    /// on the exact millisecond grid, as a microcontroller's timer counts; the plant's `f64` time
    /// accumulates rounding over hours).
    pub fn gateway_time(&self) -> Instant {
        // Whole steps of 1 ms as f64 seconds convert exactly (`time::Instant::from_secs_f64`); a
        // count beyond 292 years of steps saturates.
        Instant::from_secs_f64(self.steps as f64 * PHYSICS_DT_S)
            .unwrap_or(Instant::from_nanos(i64::MAX))
    }

    /// Hands a received frame to the gateway.
    pub fn on_frame(&mut self, frame: &CanFrame) {
        let now = self.gateway_time();
        self.gateway.on_frame(frame, now);
    }

    /// A terrain scan from the cab's range sensor.
    pub fn scan(&mut self, request: &ScanRequest) -> Scan {
        self.plant.scan(request)
    }

    /// The rays of a scan to cast elsewhere ([`Plant::prepare_scan`]); [`Self::finish_scan`] makes
    /// the scan of the cast.
    pub fn prepare_scan(&self, request: &ScanRequest) -> PendingScan {
        self.plant.prepare_scan(request)
    }

    /// The scan of rays cast from [`Self::prepare_scan`] ([`Plant::finish_scan`]).
    pub fn finish_scan(&mut self, cast: ScanCast) -> Scan {
        self.plant.finish_scan(cast)
    }

    /// Whether the next [`Self::step`] samples the sensors (every [`Schedule::sensor`] steps): the
    /// plant's state before that step is what the sensor frames sent one period later measure.
    pub fn samples_sensors_next(&self) -> bool {
        self.steps.is_multiple_of(self.schedule.sensor)
    }

    /// One physics step: gateway tick, plant step, and the frames due now (appended to `out`).
    pub fn step(&mut self, out: &mut Vec<CanFrame>) {
        if self.samples_sensors_next() {
            self.readings = Some(self.plant.read_sensors());
        }
        let now = self.gateway_time();
        let measured = self.readings.map(|r| r.angles_rad);
        let outputs = self.gateway.tick(now, measured);
        self.valve_commands = outputs.valve_commands;
        self.plant.step(outputs.valve_commands);
        self.steps += 1;
        if let Some(frame) = self.gateway.take_claim_frame() {
            out.push(frame);
        }
        match (
            self.gateway.address_claim().lost(),
            self.address_lost_logged,
        ) {
            (Some(by), false) => {
                self.address_lost_logged = true;
                tracing::error!(
                    address = self.gateway.address_claim().address(),
                    winner_name = format_args!("{:#018X}", by.raw()),
                    "gateway address lost to a node with a lower NAME: Cannot Claim sent, valves \
                     neutral, no more sensor or status frames until a Request for Address Claimed \
                     makes it claim again"
                );
            }
            (None, true) => {
                self.address_lost_logged = false;
                tracing::warn!(
                    address = self.gateway.address_claim().address(),
                    "Request for Address Claimed: the gateway claims its address again (disarmed, \
                     ADDRESS_LOST until the controller's Disarm)"
                );
            }
            _ => {}
        }
        let transmit = self.gateway.may_transmit();
        let Schedule {
            sensor,
            pump,
            odometry,
            status,
        } = self.schedule;
        if transmit && let Some(r) = self.readings {
            if self.steps.is_multiple_of(sensor) {
                self.sensor_frames(&r, out);
            }
            if self.steps.is_multiple_of(pump) {
                self.push(pump_message(&r), out);
            }
        }
        if transmit && self.steps.is_multiple_of(status) {
            // Status and session nonce, built by the gateway core as on the machine.
            match self.gateway.status_frames::<CanFrame>() {
                Ok(frames) => out.extend(frames.into_iter().flatten()),
                Err(_) => self.encode_errors += 1,
            }
        }
        if transmit {
            // J1939-73 DM1: the gateway core keeps its schedule (1 s, and on a change of the faults).
            match self.gateway.dm1_frame::<CanFrame>() {
                Ok(frame) => out.extend(frame),
                Err(_) => self.encode_errors += 1,
            }
        }
        if self.steps.is_multiple_of(odometry) {
            let pose = self.plant.pose();
            let off_map = self
                .plant
                .world
                .terrain
                .height_at(pose.x_m, pose.y_m)
                .is_err();
            if off_map && !self.off_map {
                tracing::warn!(
                    x_m = pose.x_m,
                    y_m = pose.y_m,
                    "the machine left the simulated terrain map: the terrain beyond is not simulated \
                     (scans see nothing there; grid.* in the bench file sets the map)"
                );
            }
            self.off_map = off_map;
            if !transmit {
                return;
            }
            // Inside the DBC's range (both tracks share it).
            let range = firmware_bridge::dbc::track_odometry::LEFT_TRACK_TRAVEL;
            let odo = |v: f64| v.clamp(range.min, range.max);
            self.push(
                Message::TrackOdometry(TrackOdometry {
                    left_m: self.readings.map_or(0.0, |r| odo(r.odometry_m[0])),
                    right_m: self.readings.map_or(0.0, |r| odo(r.odometry_m[1])),
                }),
                out,
            );
        }
    }

    /// Runs `n` physics steps, collecting the frames to send.
    pub fn run_steps(&mut self, n: u64, out: &mut Vec<CanFrame>) {
        for _ in 0..n {
            self.step(out);
        }
    }

    fn push(&mut self, msg: Message, out: &mut Vec<CanFrame>) {
        match msg.encode() {
            Ok(frame) => out.push(frame),
            Err(_) => self.encode_errors += 1,
        }
    }

    fn sensor_frames(&mut self, r: &SensorReadings, out: &mut Vec<CanFrame>) {
        let [boom, stick, bucket, ..] = self.valve_commands;
        for msg in sensor_messages(&self.plant, r, [boom, stick, bucket]) {
            self.push(msg, out);
        }
    }
}

/// The sensor messages the gateway sends every [`SENSOR_PERIOD_STEPS`] for one set of `readings`, in
/// transmit order: `JointAngles`, `JointRates`, `AuxValveMeasured` for boom, stick and bucket.
/// Angles and rates are clamped into their DBC ranges; the measured flow is the
/// cylinder's oil flow as a percentage of one pump's rated flow, on the side the valve command
/// (`valve_commands`, boom, stick, bucket) opens. Every program that writes the gateway's frames
/// (this node, the lab's simulated digs) encodes these, so their traces cannot drift apart.
pub fn sensor_messages(
    plant: &Plant,
    readings: &SensorReadings,
    valve_commands: [f64; 3],
) -> [Message; 5] {
    use firmware_bridge::dbc::{joint_angles, joint_rates};
    let r = readings;
    // Inside each signal's DBC range (the four angles and the four rates share theirs).
    let in_range = |sig: &firmware_bridge::dbc::SignalDesc, v: f64| v.clamp(sig.min, sig.max);
    let angle = |a: f64| in_range(&joint_angles::BOOM_ANGLE, a);
    let rate = |w: f64| in_range(&joint_rates::BOOM_RATE, w);
    let h = &plant.hydraulics;
    let rated = h.params().pumps[0].max_flow_m3_per_s;
    let valve = |i: usize| {
        let a = h.actuators[i];
        let cmd = valve_commands[i];
        let (state, area) = if cmd > 0.0 {
            (ValveState::Extend, h.head_area_m2(i))
        } else if cmd < 0.0 {
            (ValveState::Retract, h.rod_area_m2(i))
        } else {
            (ValveState::Block, 0.0)
        };
        let flow = in_range(
            &firmware_bridge::dbc::aux_valve_measured_boom::MEASURED_FLOW,
            a.velocity.abs() * area / rated * 100.0,
        );
        Message::AuxValveMeasured(AuxValveMeasured {
            cylinder: Cylinder::ALL[i],
            flow_percent: flow,
            state,
            head_pressure_pa: r.head_pa[i],
            rod_pressure_pa: r.rod_pa[i],
        })
    };
    [
        Message::JointAngles(JointAngles {
            boom_rad: angle(r.angles_rad[0]),
            stick_rad: angle(r.angles_rad[1]),
            bucket_rad: angle(r.angles_rad[2]),
            swing_rad: angle(r.angles_rad[3]),
        }),
        Message::JointRates(JointRates {
            boom_rad_per_s: rate(r.rates_rad_per_s[0]),
            stick_rad_per_s: rate(r.rates_rad_per_s[1]),
            bucket_rad_per_s: rate(r.rates_rad_per_s[2]),
            swing_rad_per_s: rate(r.rates_rad_per_s[3]),
        }),
        valve(0),
        valve(1),
        valve(2),
    ]
}

/// The `PumpPressures` message for `readings` (sent every [`PUMP_PERIOD_STEPS`], after that step's
/// [`sensor_messages`]).
pub fn pump_message(readings: &SensorReadings) -> Message {
    Message::PumpPressures(PumpPressures {
        pump1_pa: readings.pump_pa[0],
        pump2_pa: readings.pump_pa[1],
    })
}

/// Number of physics steps in `dt_s` seconds (rounded to the nearest step).
pub fn steps_in(dt_s: f64) -> u64 {
    if dt_s.is_finite() && dt_s > 0.0 {
        (dt_s / PHYSICS_DT_S).round() as u64
    } else {
        0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::SimConfig;

    #[test]
    fn the_schedule_is_the_dbcs_cycle_times_in_whole_physics_steps() {
        use firmware_bridge::dbc;
        for (steps, period) in [
            (SENSOR_PERIOD_STEPS, dbc::SENSOR_PERIOD),
            (PUMP_PERIOD_STEPS, dbc::PUMP_PERIOD),
            (ODOMETRY_PERIOD_STEPS, dbc::ODOMETRY_PERIOD),
            (STATUS_PERIOD_STEPS, dbc::STATUS_PERIOD),
        ] {
            assert!(steps > 0, "{period:?}");
            let back_s = steps as f64 * PHYSICS_DT_S;
            assert!((back_s - period.as_secs_f64()).abs() < 1e-12, "{period:?}");
        }
        assert_eq!(
            (
                SENSOR_PERIOD_STEPS,
                PUMP_PERIOD_STEPS,
                ODOMETRY_PERIOD_STEPS,
                STATUS_PERIOD_STEPS
            ),
            (10, 20, 50, 50)
        );
    }

    #[test]
    fn the_sensor_clamps_are_the_dbcs_ranges_of_every_joint() {
        use firmware_bridge::dbc::{joint_angles as a, joint_rates as r};
        let range = |s: &firmware_bridge::dbc::SignalDesc| (s.min, s.max);
        for s in [&a::STICK_ANGLE, &a::BUCKET_ANGLE, &a::SWING_ANGLE] {
            assert_eq!(range(s), range(&a::BOOM_ANGLE), "{}", s.name);
        }
        for s in [&r::STICK_RATE, &r::BUCKET_RATE, &r::SWING_RATE] {
            assert_eq!(range(s), range(&r::BOOM_RATE), "{}", s.name);
        }
        for s in [
            &firmware_bridge::dbc::aux_valve_measured_stick::MEASURED_FLOW,
            &firmware_bridge::dbc::aux_valve_measured_bucket::MEASURED_FLOW,
        ] {
            assert_eq!(
                range(s),
                range(&firmware_bridge::dbc::aux_valve_measured_boom::MEASURED_FLOW)
            );
        }
    }

    /// A node on the built-in configuration, its start moved to `start_x_m`.
    fn node_at(start_x_m: f64) -> MachineNode {
        let mut cfg = SimConfig::load::<&str>(None, None, None, &[]).expect("built-in config");
        cfg.scenario.start.x_m = start_x_m;
        MachineNode::new(cfg.build().expect("plant"))
    }

    /// Regression: every `MachineNode::new` started its gateway at the same session nonce, so a
    /// recording of one simulator run verified in the next.
    #[test]
    fn two_machine_nodes_start_different_sessions() {
        let (a, b) = (node_at(0.0), node_at(0.0));
        assert_ne!(a.gateway().session(), b.gateway().session());
    }

    /// A node whose address claim has stood (its sensor frames go out from the next step on).
    fn claimed_node_at(start_x_m: f64) -> MachineNode {
        let mut node = node_at(start_x_m);
        let mut out = Vec::new();
        while !node.gateway().may_transmit() {
            node.step(&mut out);
        }
        node
    }

    /// Steps one odometry period (when the map check runs) and reports whether the node is off its map.
    fn off_map_after_one_odometry_period(start_x_m: f64) -> bool {
        let mut node = node_at(start_x_m);
        let mut out = Vec::new();
        node.run_steps(ODOMETRY_PERIOD_STEPS, &mut out);
        node.off_map()
    }

    #[test]
    fn every_sensor_sample_is_sent_as_one_joint_angles_frame_a_period_later() {
        let mut node = claimed_node_at(0.0);
        // The claim stood in the middle of a sensor period: finish it.
        let mut out = Vec::new();
        while !node.samples_sensors_next() {
            node.step(&mut out);
        }
        let (mut samples, mut frames) = (0, 0);
        let mut out = Vec::new();
        for step in 0..10 * SENSOR_PERIOD_STEPS {
            if node.samples_sensors_next() {
                assert_eq!(step % SENSOR_PERIOD_STEPS, 0);
                samples += 1;
            }
            out.clear();
            node.step(&mut out);
            frames += out
                .iter()
                .filter(|f| {
                    matches!(
                        Message::decode(f).map(|d| d.message),
                        Ok(Message::JointAngles(_))
                    )
                })
                .count();
            assert_eq!(
                frames,
                samples - usize::from(!node.samples_sensors_next()),
                "step {step}"
            );
        }
        assert_eq!((samples, frames), (10, 10));
    }

    #[test]
    fn a_machine_outside_the_terrain_map_is_reported_off_map() {
        assert!(!off_map_after_one_odometry_period(0.0));
        assert!(off_map_after_one_odometry_period(-100.0));
    }

    /// Regression (#20): pump pressures went out at 100 Hz and the status at 20 Hz while
    /// docs/protocol.md and the bus-load schedule said 50 and 10 Hz (the status stays at 20 Hz, now
    /// documented: docs/protocol.md, "Rates and bus load").
    #[test]
    fn transmit_rates_are_the_documented_schedule() {
        const SECONDS: u64 = 2;
        let mut node = claimed_node_at(0.0);
        let mut out = Vec::new();
        node.run_steps(SECONDS * steps_in(1.0), &mut out);
        for entry in firmware_bridge::busload::SCHEDULE {
            let desc =
                firmware_bridge::busload::descriptor(entry).expect("scheduled message in DBC");
            if desc.transmitter != "Gateway" {
                continue;
            }
            let sent = out
                .iter()
                .filter(|f| f.id().raw() & 0x1FFF_FFFF == desc.default_id)
                .count();
            let rate_hz = sent as f64 / SECONDS as f64;
            assert_eq!(rate_hz, entry.rate_hz, "{}", entry.message);
        }
        assert_eq!(node.encode_errors(), 0);
    }

    /// Regression (#20): consecutive status frames must carry consecutive alive counters
    /// (`excavator-ctl trace stats` counted 1554 errors in 1555 frames).
    #[test]
    fn the_gateway_sends_dm1_once_per_second_from_its_address() {
        let mut node = claimed_node_at(0.0);
        let mut out = Vec::new();
        node.run_steps(3000, &mut out);
        let dm1: Vec<_> = out
            .iter()
            .filter_map(|f| match Message::decode(f) {
                Ok(d) => match d.message {
                    Message::Dm1(m) => Some((d.id.source_address(), m)),
                    _ => None,
                },
                Err(_) => None,
            })
            .collect();
        assert_eq!(dm1.len(), 3, "{dm1:?}");
        for (source, m) in dm1 {
            assert_eq!(source, firmware_bridge::GATEWAY_ADDRESS);
            assert_eq!(m.dtc, firmware_bridge::messages::Dtc::NONE);
        }
    }

    #[test]
    fn status_frames_carry_consecutive_alive_counters() {
        let mut node = claimed_node_at(0.0);
        let mut out = Vec::new();
        node.run_steps(60 * STATUS_PERIOD_STEPS, &mut out);
        let counters: Vec<u8> = out
            .iter()
            .filter_map(|f| match Message::decode(f).map(|d| d.message) {
                Ok(Message::GatewayStatus(s)) => Some(s.alive_counter),
                _ => None,
            })
            .collect();
        assert_eq!(counters.len(), 60);
        for w in counters.windows(2) {
            assert!(
                firmware_bridge::messages::is_next_alive(w[0], w[1], 8),
                "{counters:?}"
            );
        }
    }

    #[test]
    fn the_gateway_claims_first_and_sends_nothing_else_for_250_ms() {
        let mut node = node_at(0.0);
        let mut out = Vec::new();
        node.run_steps(steps_in(0.25), &mut out);
        let ids: Vec<u32> = out.iter().map(|f| f.id().raw()).collect();
        assert_eq!(ids, [0x18EE_FF80]);
        node.run_steps(steps_in(0.05), &mut out);
        assert!(out.len() > 10, "{} frames", out.len());
    }

    #[test]
    fn a_lost_address_stops_the_gateways_frames_and_holds_the_valves_neutral() {
        use firmware_bridge::address_claim::{GATEWAY_NAME, Name};
        use firmware_bridge::messages::{AddressClaimed, GatewayFaults};
        let mut node = claimed_node_at(0.0);
        let winner = Name::from_raw(GATEWAY_NAME.raw() - 1);
        let claim = Message::AddressClaimed(AddressClaimed { name: winner })
            .encode_from(firmware_bridge::GATEWAY_ADDRESS)
            .unwrap();
        node.on_frame(&claim);
        let mut out = Vec::new();
        node.run_steps(steps_in(1.0), &mut out);
        let ids: Vec<u32> = out.iter().map(|f| f.id().raw()).collect();
        assert_eq!(ids, [0x18EE_FFFE], "only Cannot Claim");
        assert!(
            node.gateway()
                .faults()
                .contains(GatewayFaults::ADDRESS_LOST)
        );
        assert_eq!(node.valve_commands(), [0.0; 6]);

        // The controller's Request for Address Claimed after the operator's reset: the gateway claims
        // 0x80 again, stays silent 250 ms, then reports Faulted (ADDRESS_LOST) and stays disarmed.
        let request = firmware_bridge::address_claim::request_address_claimed(
            firmware_bridge::id::GLOBAL_ADDRESS,
            firmware_bridge::address_claim::NULL_ADDRESS,
        )
        .unwrap();
        node.on_frame(&request);
        let mut out = Vec::new();
        node.run_steps(steps_in(0.25) - 1, &mut out);
        let ids: Vec<u32> = out.iter().map(|f| f.id().raw()).collect();
        assert_eq!(ids, [0x18EE_FF80], "the re-claim, then nothing for 250 ms");
        out.clear();
        node.run_steps(steps_in(1.0), &mut out);
        let status = out
            .iter()
            .find_map(|f| match Message::decode(f).map(|d| d.message) {
                Ok(Message::GatewayStatus(s)) => Some(s),
                _ => None,
            })
            .expect("status after the claim stood");
        assert_eq!(status.mode, firmware_bridge::messages::GatewayMode::Faulted);
        assert!(status.faults.contains(GatewayFaults::ADDRESS_LOST));
        assert_eq!(node.valve_commands(), [0.0; 6]);
    }

    #[test]
    fn the_gateway_claims_with_the_configured_name() {
        use firmware_bridge::address_claim::{GATEWAY_NAME, Name};
        let mut node = node_at(0.0);
        let name = Name::from_raw(GATEWAY_NAME.raw() + 5);
        node.set_gateway_name(name);
        let mut out = Vec::new();
        node.step(&mut out);
        assert_eq!(out[0].data(), &name.to_le_bytes());
    }
}
