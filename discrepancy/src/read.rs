//! Reading a measured session (the folder `excavator-ctl demo` writes, or the same files from a real
//! machine): `trace.log` (candump) and `scans/scan_NNNN.json` (docs/scan-protocol.md), into the
//! discrepancy workflow's 100 Hz records. Only the bus traffic and the scans are read; nothing else
//! in the folder (in particular not `summary.json`, whose `effects` field would reveal the answer).

use std::path::{Path, PathBuf};

use crate::{DigRecord, LoadTag, Sample, StageTag};
use anyhow::Context as _;
use firmware_bridge::messages::{Activity, AutodigStageCode, Message};
use lab::trace_samples::{BusSample, SampleSink, read_samples};
use planner::kinematics::{JointAngles, Kinematics, MachinePose};
use planner::machine::MachineConfig;
use planner::terrain::SectionProfile;
use serde::Deserialize;

/// A scan in the reply format of docs/scan-protocol.md.
#[derive(Debug, Clone, Deserialize)]
pub struct ScanFile {
    /// Time of the scan, s.
    pub time_s: f64,
    /// Sensor pose: position (world) and the heading of the digging plane.
    pub sensor: ScanSensor,
    /// Hits, world frame `[x, y, z]`.
    pub points: Vec<[f64; 3]>,
}

/// The sensor pose of a scan.
#[derive(Debug, Clone, Copy, Deserialize)]
pub struct ScanSensor {
    /// World x, m.
    pub x_m: f64,
    /// World y, m.
    pub y_m: f64,
    /// Height, m.
    pub z_m: f64,
    /// Azimuth of the digging plane the scan was turned to, rad.
    pub heading_rad: f64,
}

/// Status of the controller at a sample.
#[derive(Debug, Clone, Copy, Default)]
struct Status {
    activity: Activity,
    stage: AutodigStageCode,
    dig_index: u16,
    swept_volume_m3: f64,
    /// In the work cycle's Weigh: the controller reports `Idle` between the end of a dig (Autodig
    /// or cleanup) and the swing to the dump of the same dig index.
    weighing: bool,
}

fn stage_tag(code: AutodigStageCode) -> StageTag {
    match code {
        AutodigStageCode::BoomDown => StageTag::BoomDown,
        AutodigStageCode::PreDig => StageTag::PreDig,
        AutodigStageCode::Dig => StageTag::Dig,
        AutodigStageCode::Capture => StageTag::Capture,
        _ => StageTag::Outside,
    }
}

fn load_tag(status: &Status) -> LoadTag {
    if status.weighing {
        return LoadTag::Weighing;
    }
    let stage = stage_tag(status.stage);
    if stage.in_soil() || status.activity == Activity::Cleanup {
        return LoadTag::InSoil;
    }
    match status.activity {
        Activity::Idle
        | Activity::Paused
        | Activity::Scan
        | Activity::SwingToDig
        | Activity::Return
        | Activity::Track => LoadTag::EmptyFreeAir,
        Activity::Dig if stage == StageTag::BoomDown => LoadTag::EmptyFreeAir,
        _ => LoadTag::Loaded,
    }
}

/// Time after the gateway leaves its closed-loop position mode during which the spools still stand
/// where its position control left them, s: the replay starts every record's spool state at rest and
/// leaves out its first 0.5 s for the same reason (`crate::greybox`).
pub const POSITION_MODE_SETTLE_S: f64 = 0.5;

/// Reads `trace.log` into samples tagged with the dig index, one per `JointAngles` frame at its
/// session time (`lab::demo::trace_time_base`: the time of the scans), with the latest readings and
/// the commands the controller sent in answer to them (in force until the next sample).
///
/// Samples while the gateway runs its closed-loop position mode (`GatewayStatus` mode
/// `ArmedPosition`, the controller sending `PositionSetpoint`s: the cleanup) and for
/// [`POSITION_MODE_SETTLE_S`] after it are left out: the gateway's own position control sets the
/// spools then, and the bus carries no valve command, so the replay would drive the valves with the
/// last `AuxValveCommand` (neutral) while the machine moves and the pumps stand at 15-20 MPa
/// (session soil_cohesion_10000: pump 1 residual 4.4 MPa RMS on those samples against 0.11 MPa on
/// the rest, docs/discrepancy.md, 2026-11-25).
///
/// # Errors
/// Opening or reading the file; a trace without controller status frames.
pub fn read_trace(path: &Path) -> anyhow::Result<Vec<(u16, Sample)>> {
    /// The samples outside the position mode, with the controller's status folded over its frames.
    #[derive(Default)]
    struct Sink {
        out: Vec<(u16, Sample)>,
        status: Option<Status>,
    }
    impl SampleSink for Sink {
        fn message(&mut self, _time_s: f64, message: &Message) {
            let Message::ControllerStatus(s) = message else {
                return;
            };
            // Weigh follows the dig (Autodig, or a cleanup ending in Autodig) of the same index and
            // shows as Idle until the swing to the dump.
            let weighing = s.activity == Activity::Idle
                && self.status.is_some_and(|p| {
                    p.dig_index == s.dig_index
                        && (p.weighing || matches!(p.activity, Activity::Dig | Activity::Cleanup))
                });
            self.status = Some(Status {
                activity: s.activity,
                stage: s.stage,
                dig_index: s.dig_index,
                swept_volume_m3: s.swept_volume_m3,
                weighing,
            });
        }
        fn sample(&mut self, b: &BusSample) {
            let Some(st) = self.status else {
                return;
            };
            if b.time_s - b.position_mode_at_s <= POSITION_MODE_SETTLE_S {
                return;
            }
            let [boom, stick, bucket, swing] = b.angles_rad;
            let rates = b.rates_rad_per_s.unwrap_or_default();
            let stage = stage_tag(st.stage);
            let sample = Sample {
                time_s: b.time_s,
                command: [b.command[0], b.command[1], b.command[2]],
                swing_command: b.command[3],
                angles_rad: [boom, stick, bucket],
                rates_rad_per_s: [rates[0], rates[1], rates[2]],
                swing_rate_rad_per_s: rates[3],
                swing_rad: swing,
                head_pa: b.head_pa,
                rod_pa: b.rod_pa,
                pump_pa: b.pump_pa,
                stage,
                load: load_tag(&st),
                swept_volume_m3: if stage == StageTag::Outside {
                    0.0
                } else {
                    st.swept_volume_m3
                },
                tracking: st.activity == Activity::Track,
            };
            self.out.push((st.dig_index, sample));
        }
    }
    let mut sink = Sink::default();
    read_samples(path, &mut sink)?;
    if sink.status.is_none() {
        anyhow::bail!(
            "{}: no ControllerStatus frames: the workflow segments digs by the controller's status",
            path.display()
        );
    }
    Ok(sink.out)
}

/// Reads every `scans/scan_*.json` of a session folder, in name order. A file that does not parse
/// (cut short when the recording stopped, corrupted) is skipped with a warning: the digs after it
/// take their terrain from the scan before it.
///
/// # Errors
/// Listing the folder or reading a scan file.
pub fn read_scans(dir: &Path) -> anyhow::Result<Vec<ScanFile>> {
    let scans_dir = dir.join("scans");
    if !scans_dir.is_dir() {
        return Ok(Vec::new());
    }
    let mut names: Vec<PathBuf> = std::fs::read_dir(&scans_dir)
        .with_context(|| format!("listing {}", scans_dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "json"))
        .collect();
    names.sort();
    let mut scans = Vec::with_capacity(names.len());
    for p in &names {
        let text =
            std::fs::read_to_string(p).with_context(|| format!("reading {}", p.display()))?;
        match serde_json::from_str(&text) {
            Ok(scan) => scans.push(scan),
            Err(e) => tracing::warn!(
                "{}: not a readable scan ({e}): skipped; the digs after it use the scan before it",
                p.display()
            ),
        }
    }
    Ok(scans)
}

/// Half width of the band of scan points around the digging plane that makes its section, m. The
/// digs of a session lie 10-20 degrees apart, so at the 5-7 m where the bucket cuts the trench of the
/// neighbouring dig (1.3 m wide) comes within 0.4-0.55 m of the plane; with 1-2 points per 0.1 m bin
/// a 0.5 m band took the trench floor for the ground ahead of the edge (effect-free session
/// none_s200, digs beside an earlier one: the section 0.13-0.17 m below the simulator's true surface
/// ahead of the edge; docs/discrepancy.md, 2026-11-22 soil effects).
pub const SECTION_HALF_WIDTH_M: f64 = 0.25;

/// The terrain section of a scan along the digging plane at world azimuth `plane_azimuth_rad`, in the
/// base frame (x from the swing axis, z up): points within [`SECTION_HALF_WIDTH_M`] of the plane,
/// median height per 0.1 m bin, gaps interpolated. The machine position follows from the sensor pose
/// (its heading is the azimuth the cab faced during the scan) and the machine file's `[sensor]` mount.
pub fn scan_section(
    scan: &ScanFile,
    machine: &MachineConfig,
    plane_azimuth_rad: f64,
    floor: &CutFloor,
) -> Option<SectionProfile> {
    scan_section_beside(
        scan,
        machine,
        plane_azimuth_rad,
        0.0,
        SECTION_HALF_WIDTH_M,
        floor,
    )
}

/// As [`scan_section`], with the ground the scan did not see on the plane passing no higher than
/// the dig's first contact, `contact_m` (`[r, z]`: the cutting edge where Boom-Down met the
/// ground, base frame): between the seen ground either side of that unseen run, the section is
/// at most the two straight lines through it. From the cab the crest of the face hides the face
/// below it, and the section bridges the shadow along the line of sight, an upper bound of the
/// ground: in a 40 kPa cohesion session the edge met the ground 0.08-0.17 m below that bridge in
/// the seven digs whose contact it hid, and within 0.05 m of the section in the three it did not.
pub fn scan_section_through_contact(
    scan: &ScanFile,
    machine: &MachineConfig,
    plane_azimuth_rad: f64,
    floor: &CutFloor,
    contact_m: Option<[f64; 2]>,
) -> Option<SectionProfile> {
    section_of(
        scan,
        machine,
        (plane_azimuth_rad, 0.0, SECTION_HALF_WIDTH_M),
        floor,
        contact_m,
    )
}

/// Lanes beside the digging plane (each side): lateral offset and the half width of the band of
/// scan points each is made of, m. Across the bucket width every 0.25 m: the ground the edge cuts is
/// not the section's all across (the trench of a neighbouring or earlier dig, an earlier dig's spill
/// pile along its own plane), and taking the section across the width cut 0.1-0.5 m^3 more per dig
/// than the simulator did (effect-free session none_s200, docs/discrepancy.md, 2026-11-22 soil
/// effects). Beyond it, out to the reach of a full bucket's spill
/// (crate::soil_replay::SPILL_REACH_M), every 0.5 m.
pub const LANES_M: [(f64, f64); 7] = [
    (0.25, 0.125),
    (0.5, 0.125),
    (0.75, 0.125),
    (1.0, 0.25),
    (1.5, 0.25),
    (2.0, 0.25),
    (2.5, 0.25),
];

/// Step of a section's bins along the plane, m.
const SECTION_STEP_M: f64 = 0.1;
/// Distance from the swing axis of a section's first bin, m.
const SECTION_R0_M: f64 = 1.0;
/// Bins of a section (out to 14 m).
const SECTION_BINS: usize = 130;

/// Longest run of bins without a scan point on the section's line itself (within
/// [`SEEN_HALF_WIDTH_M`] of it) that counts as seen ground, m; a longer run is ground the scanner
/// did not see there, and the section is lowered to the earlier digs' edge paths ([`CutFloor`]).
/// From the cab the crest of the face, a face cut steeper than the line of sight and the near wall
/// of a trench hide the ground just beyond them, and a trench an earlier dig cut there is in
/// neither the section's bridge over a gap nor its medians, which the band's points beside the
/// trench (higher ground) then make: a 40 kPa cohesion session, digs at 4.4-4.9 m in the crest's
/// shadow, the bridge 0.4-0.5 m above the simulator's ground; a 10 kPa session, its pre-dig
/// sections against the simulator's true ones along the plane: median +0.37 m at 4.0 m, 75 % of
/// the bins there off by more than 0.2 m (with the rule: median 0.00 m, 50 %).
pub const SEEN_GAP_M: f64 = 0.2;

/// Half width of the band of scan points that counts a bin as seen on the section's line, m.
pub const SEEN_HALF_WIDTH_M: f64 = 0.05;

/// Cell of a [`CutFloor`], m.
const FLOOR_CELL_M: f64 = 0.1;

/// The lowest the cutting edge of the earlier digs of a session has passed over each world cell
/// (world `[x, y]` on a 0.1 m grid, height in the base frame as the sections): the edge lowers every
/// point within half the bucket width of it to its own height (thesis 3.2), so the ground there is
/// at most that, until something is piled on it.
#[derive(Debug, Clone, Default)]
pub struct CutFloor {
    cells: std::collections::HashMap<(i64, i64), f64>,
}

impl CutFloor {
    /// Adds the edge at world `[x, y]`, height `z_m`, on a digging plane of azimuth
    /// `plane_azimuth_rad`, for a bucket `width_m` wide.
    pub fn add(&mut self, xy: [f64; 2], z_m: f64, plane_azimuth_rad: f64, width_m: f64) {
        if !(xy.iter().all(|v| v.is_finite()) && z_m.is_finite() && width_m.is_finite()) {
            return;
        }
        let (sin, cos) = plane_azimuth_rad.sin_cos();
        let n = (0.5 * width_m / FLOOR_CELL_M).floor() as i64;
        for k in -n..=n {
            let off = k as f64 * FLOOR_CELL_M;
            let key = (
                ((xy[0] - off * sin) / FLOOR_CELL_M).floor() as i64,
                ((xy[1] + off * cos) / FLOOR_CELL_M).floor() as i64,
            );
            let h = self.cells.entry(key).or_insert(f64::INFINITY);
            *h = h.min(z_m);
        }
    }

    /// The lowest edge height over the cell of world `[x, y]` (`None`: no edge passed there).
    #[must_use]
    pub fn lowest(&self, xy: [f64; 2]) -> Option<f64> {
        let key = (
            (xy[0] / FLOOR_CELL_M).floor() as i64,
            (xy[1] / FLOOR_CELL_M).floor() as i64,
        );
        self.cells.get(&key).copied()
    }
}

/// As [`scan_section`], for the points within `half_width_m` of the line parallel to the digging
/// plane at `lateral_m` (left positive).
pub fn scan_section_beside(
    scan: &ScanFile,
    machine: &MachineConfig,
    plane_azimuth_rad: f64,
    lateral_m: f64,
    half_width_m: f64,
    floor: &CutFloor,
) -> Option<SectionProfile> {
    section_of(
        scan,
        machine,
        (plane_azimuth_rad, lateral_m, half_width_m),
        floor,
        None,
    )
}

/// The section of [`scan_section_beside`] on the line `(azimuth, lateral offset, half width)`,
/// lowered through `contact_m` as [`scan_section_through_contact`].
fn section_of(
    scan: &ScanFile,
    machine: &MachineConfig,
    (plane_azimuth_rad, lateral_m, half_width_m): (f64, f64, f64),
    floor: &CutFloor,
    contact_m: Option<[f64; 2]>,
) -> Option<SectionProfile> {
    let (mut heights, seen) =
        section_bins(scan, machine, plane_azimuth_rad, lateral_m, half_width_m);
    let first = heights.iter().position(Option::is_some)?;
    let last = heights.iter().rposition(Option::is_some)?;
    if last <= first {
        return None;
    }
    let origin = machine_origin(scan, machine);
    let (sin, cos) = plane_azimuth_rad.sin_cos();
    let world = |b: usize| {
        let r = SECTION_R0_M + b as f64 * SECTION_STEP_M;
        [
            origin[0] + r * cos - lateral_m * sin,
            origin[1] + r * sin + lateral_m * cos,
        ]
    };
    let mut k = first;
    while k < last {
        let next = (k + 1..=last).find(|j| heights[*j].is_some())?;
        let (a, b) = (heights[k]?, heights[next]?);
        for (j, h) in heights.iter_mut().enumerate().take(next).skip(k + 1) {
            let t = (j - k) as f64 / (next - k) as f64;
            *h = Some(a + t * (b - a));
        }
        k = next;
    }
    // Ground the scan did not see on the line itself is at most where an earlier dig's edge
    // left it.
    let runs = unseen_runs(&seen, first, last);
    for &(from, to) in &runs {
        for (j, h) in heights.iter_mut().enumerate().take(to).skip(from) {
            if let (Some(height), Some(cut)) = (*h, floor.lowest(world(j))) {
                *h = Some(height.min(cut));
            }
        }
    }
    if let Some(c) = contact_m.filter(|c| c.iter().all(|v| v.is_finite())) {
        lower_through(&mut heights, &runs, (first, last), c);
    }
    let values: Vec<f64> = heights[first..=last]
        .iter()
        .map(|h| h.unwrap_or(0.0))
        .collect();
    SectionProfile::new(
        SECTION_R0_M + first as f64 * SECTION_STEP_M,
        SECTION_STEP_M,
        values,
    )
    .ok()
}

/// Lowers the bins of the unseen run (of `runs`) that holds the point `[r, z]` to at most the two
/// straight lines from the seen bins either side of the run (within `first..=last`) through the
/// point, where the point lies below the section (every bin of `first..=last` has a height).
fn lower_through(
    heights: &mut [Option<f64>],
    runs: &[(usize, usize)],
    (first, last): (usize, usize),
    [r, z]: [f64; 2],
) {
    let bin_r = |j: usize| SECTION_R0_M + j as f64 * SECTION_STEP_M;
    let at = ((r - SECTION_R0_M) / SECTION_STEP_M).round();
    if at.is_nan() || at < 0.0 {
        return;
    }
    let at = at as usize;
    let Some(&(from, to)) = runs.iter().find(|(f, t)| (*f..*t).contains(&at)) else {
        return;
    };
    let (a, b) = (from.saturating_sub(1).max(first), to.min(last));
    let (Some(Some(ha)), Some(Some(hb)), Some(Some(here))) =
        (heights.get(a), heights.get(b), heights.get(at))
    else {
        return;
    };
    let (ha, hb) = (*ha, *hb);
    if z >= *here {
        return;
    }
    let line = |(r0, z0): (f64, f64), (r1, z1): (f64, f64), q: f64| {
        if (r1 - r0).abs() < 1e-9 {
            z1
        } else {
            z0 + (q - r0) / (r1 - r0) * (z1 - z0)
        }
    };
    for (j, h) in heights.iter_mut().enumerate().take(b + 1).skip(a) {
        let q = bin_r(j);
        let bound = if q <= r {
            line((bin_r(a), ha), (r, z), q)
        } else {
            line((r, z), (bin_r(b), hb), q)
        };
        if let Some(h) = h.as_mut() {
            *h = h.min(bound);
        }
    }
}

/// The runs `[from, to)` of bins between `first` and `last` not `seen`, longer than
/// [`SEEN_GAP_M`].
fn unseen_runs(seen: &[bool], first: usize, last: usize) -> Vec<(usize, usize)> {
    let mut runs = Vec::new();
    let mut j = first;
    while j <= last {
        if seen.get(j).copied().unwrap_or(false) {
            j += 1;
            continue;
        }
        let end = (j..=last)
            .find(|q| seen.get(*q).copied().unwrap_or(false))
            .unwrap_or(last + 1);
        if (end - j) as f64 * SECTION_STEP_M > SEEN_GAP_M + 1e-9 {
            runs.push((j, end));
        }
        j = end;
    }
    runs
}

/// The median height of the scan points in each bin along the line parallel to the digging plane
/// at `lateral_m`, within `half_width_m` of it (`None`: no point), and whether the bin has a point
/// within [`SEEN_HALF_WIDTH_M`] of the line itself (one pass over the scan for both).
fn section_bins(
    scan: &ScanFile,
    machine: &MachineConfig,
    plane_azimuth_rad: f64,
    lateral_m: f64,
    half_width_m: f64,
) -> (Vec<Option<f64>>, Vec<bool>) {
    let (sin, cos) = plane_azimuth_rad.sin_cos();
    let origin = machine_origin(scan, machine);
    let on_line_m = half_width_m.min(SEEN_HALF_WIDTH_M);
    let mut bins: Vec<Vec<f64>> = vec![Vec::new(); SECTION_BINS];
    let mut seen = vec![false; SECTION_BINS];
    for p in &scan.points {
        let (dx, dy) = (p[0] - origin[0], p[1] - origin[1]);
        let along = dx * cos + dy * sin;
        let off = (-dx * sin + dy * cos - lateral_m).abs();
        if off > half_width_m || !p[2].is_finite() {
            continue;
        }
        let b = ((along - SECTION_R0_M) / SECTION_STEP_M).round();
        if b >= 0.0 && (b as usize) < SECTION_BINS {
            bins[b as usize].push(p[2]);
            seen[b as usize] |= off <= on_line_m;
        }
    }
    let medians = bins
        .iter_mut()
        .map(|v| {
            if v.is_empty() {
                None
            } else {
                v.sort_by(f64::total_cmp);
                Some(v[v.len() / 2])
            }
        })
        .collect();
    (medians, seen)
}

/// The machine's position (its swing axis, world `[x, y]`) during a scan: the sensor's, less its
/// mount's radial offset along the mount's bearing (machine file `[sensor]`).
fn machine_origin(scan: &ScanFile, machine: &MachineConfig) -> [f64; 2] {
    let mount = scan.sensor.heading_rad + machine.sensor.bearing_rad;
    [
        scan.sensor.x_m - machine.sensor.radial_offset_m * mount.cos(),
        scan.sensor.y_m - machine.sensor.radial_offset_m * mount.sin(),
    ]
}

/// Clearance above the scanned ground below which an empty bucket may touch it, m: the bucket's
/// pin-to-tip chord is checked, and its shell bulges up to about 0.3 m below the chord.
pub const GROUND_CLEARANCE_M: f64 = 0.4;

/// Cell of the ground map, m.
const GROUND_CELL_M: f64 = 0.25;

/// Distance around a point of the bucket within which the ground is searched, m: half the bucket
/// width and a cell.
const GROUND_SEARCH_M: f64 = 0.9;

/// The ground a scan saw: the highest hit per cell of [`GROUND_CELL_M`] (world frame).
struct GroundMap {
    cells: std::collections::HashMap<(i64, i64), f64>,
}

impl GroundMap {
    fn new(scan: &ScanFile) -> Self {
        let mut cells = std::collections::HashMap::new();
        for p in scan
            .points
            .iter()
            .filter(|p| p.iter().all(|v| v.is_finite()))
        {
            let key = (
                (p[0] / GROUND_CELL_M).floor() as i64,
                (p[1] / GROUND_CELL_M).floor() as i64,
            );
            let h = cells.entry(key).or_insert(f64::NEG_INFINITY);
            *h = h.max(p[2]);
        }
        Self { cells }
    }

    /// The highest ground within [`GROUND_SEARCH_M`] of world `[x, y]` (`None`: not scanned there).
    fn height_near(&self, xy: [f64; 2]) -> Option<f64> {
        let r = (GROUND_SEARCH_M / GROUND_CELL_M).ceil() as i64;
        let (cx, cy) = (
            (xy[0] / GROUND_CELL_M).floor() as i64,
            (xy[1] / GROUND_CELL_M).floor() as i64,
        );
        (-r..=r)
            .flat_map(|i| (-r..=r).map(move |j| (cx + i, cy + j)))
            .filter_map(|k| self.cells.get(&k).copied())
            .reduce(f64::max)
    }
}

/// The base where `scan` was taken, heading `base_heading_rad`, and the first of `samples` it
/// stood there for: the one after the record's last Track sample (before it the base stood
/// elsewhere).
fn scanned_base(
    samples: &[Sample],
    scan: &ScanFile,
    machine: &MachineConfig,
    base_heading_rad: f64,
) -> (MachinePose, usize) {
    let origin = machine_origin(scan, machine);
    let pose = MachinePose {
        x_m: origin[0],
        y_m: origin[1],
        heading_rad: base_heading_rad,
    };
    let from = samples
        .iter()
        .rposition(|s| s.tracking)
        .map_or(0, |k| k + 1);
    (pose, from)
}

/// Adds the edge path of a record's Autodig stages (where the edge cuts) to `floor`, the base at
/// the scan's position with heading `base_heading_rad`, from the record's last Track sample on.
fn add_cuts(
    floor: &mut CutFloor,
    samples: &[Sample],
    scan: &ScanFile,
    machine: &MachineConfig,
    kin: &Kinematics,
    base_heading_rad: f64,
) {
    let (pose, from) = scanned_base(samples, scan, machine, base_heading_rad);
    for s in samples[from..]
        .iter()
        .filter(|s| s.stage != StageTag::Outside)
    {
        let tip = kin.forward(&JointAngles {
            boom_rad: s.angles_rad[0],
            stick_rad: s.angles_rad[1],
            bucket_rad: s.angles_rad[2],
        });
        let [x, y, _] = pose.world_from_base(s.swing_rad, tip.x_m, tip.z_m);
        floor.add(
            [x, y],
            tip.z_m,
            pose.dig_plane_azimuth_rad(s.swing_rad),
            machine.bucket.width_m,
        );
    }
}

/// Marks the empty-bucket samples outside Autodig whose bucket (pin, middle of the chord and tip)
/// comes within [`GROUND_CLEARANCE_M`] of the ground of `scan` as [`LoadTag::NearGround`]: the
/// base at the scan's position with heading `base_heading_rad`, from the record's last Track
/// sample on (before it the base stood elsewhere).
fn mark_near_ground(
    samples: &mut [Sample],
    scan: &ScanFile,
    machine: &MachineConfig,
    kin: &Kinematics,
    base_heading_rad: f64,
) {
    let ground = GroundMap::new(scan);
    let (pose, from) = scanned_base(samples, scan, machine, base_heading_rad);
    for s in &mut samples[from..] {
        if s.load != LoadTag::EmptyFreeAir || s.stage != StageTag::Outside {
            continue;
        }
        let p = kin.linkage_points(&JointAngles {
            boom_rad: s.angles_rad[0],
            stick_rad: s.angles_rad[1],
            bucket_rad: s.angles_rad[2],
        });
        let mid = [
            0.5 * (p.bucket_pin[0] + p.tip[0]),
            0.5 * (p.bucket_pin[1] + p.tip[1]),
        ];
        let near = [p.bucket_pin, mid, p.tip].iter().any(|b| {
            let w = pose.world_from_base(s.swing_rad, b[0], b[1]);
            ground
                .height_near([w[0], w[1]])
                .is_some_and(|g| w[2] - g < GROUND_CLEARANCE_M)
        });
        if near {
            s.load = LoadTag::NearGround;
        }
    }
}

/// The cutting edge (base frame `[r, z]`) where Boom-Down first met the ground in `samples`: the
/// first sample after a Boom-Down sample in Pre-Dig or Dig (Boom-Down ends on the contact
/// signature, thesis 3.1).
fn first_contact(samples: &[Sample], kin: &Kinematics) -> Option<[f64; 2]> {
    samples
        .windows(2)
        .find(|w| {
            w[0].stage == StageTag::BoomDown
                && matches!(w[1].stage, StageTag::PreDig | StageTag::Dig)
        })
        .map(|w| {
            let tip = kin.forward(&JointAngles {
                boom_rad: w[1].angles_rad[0],
                stick_rad: w[1].angles_rad[1],
                bucket_rad: w[1].angles_rad[2],
            });
            [tip.x_m, tip.z_m]
        })
}

/// Swing angle at time `t_s`: the sample nearest in time (samples in time order).
fn swing_at(samples: &[(u16, Sample)], t_s: f64) -> Option<f64> {
    let k = samples.partition_point(|(_, s)| s.time_s < t_s);
    let near = |j: usize| {
        samples
            .get(j)
            .map(|(_, s)| ((s.time_s - t_s).abs(), s.swing_rad))
    };
    let best = match (k.checked_sub(1).and_then(near), near(k)) {
        (Some(a), Some(b)) => Some(if a.0 <= b.0 { a } else { b }),
        (a, b) => a.or(b),
    }?;
    (best.0 < 0.5).then_some(best.1)
}

/// Reads a session folder into one record per dig index (every sample of that work cycle), each with
/// the section of the last scan before its Autodig started, cut along the dig's own digging plane:
/// the machine heading at the scan (the scan's heading less the swing angle then) plus the swing
/// angle when the dig starts (the cab usually faces the dump, not the dig, while it scans).
///
/// # Errors
/// Reading the trace or the scans.
pub fn read_session(dir: &Path, machine: &MachineConfig) -> anyhow::Result<Vec<DigRecord>> {
    let samples = read_trace(&dir.join("trace.log"))?;
    let kin = Kinematics::new(machine)?;
    let scans = read_scans(dir)?;
    let scan_swing: Vec<Option<f64>> = scans.iter().map(|s| swing_at(&samples, s.time_s)).collect();
    let mut records: Vec<DigRecord> = Vec::new();
    for (index, s) in samples {
        match records.last_mut() {
            Some(r) if r.index == u32::from(index) => r.samples.push(s),
            _ => records.push(DigRecord {
                index: u32::from(index),
                samples: vec![s],
                section: None,
                lanes: Vec::new(),
            }),
        }
    }
    let mut floor = CutFloor::default();
    for r in &mut records {
        let dig_start = r
            .samples
            .iter()
            .find(|s| s.stage != StageTag::Outside || s.load == LoadTag::InSoil)
            .map(|s| (s.time_s, s.swing_rad));
        if let Some((t0, dig_swing)) = dig_start {
            let scan = scans
                .iter()
                .zip(&scan_swing)
                .rev()
                .find(|(s, _)| s.time_s <= t0 + 1e-9);
            if let Some((s, swing)) = scan {
                // Without the swing angle at the scan, the scan's own heading is the best guess.
                let base_heading = s.sensor.heading_rad - swing.unwrap_or(dig_swing);
                let azimuth = base_heading + dig_swing;
                r.section = scan_section_through_contact(
                    s,
                    machine,
                    azimuth,
                    &floor,
                    first_contact(&r.samples, &kin),
                );
                r.lanes = LANES_M
                    .iter()
                    .flat_map(|&(o, w)| [(o, w), (-o, w)])
                    .filter_map(|(o, w)| {
                        scan_section_beside(s, machine, azimuth, o, w, &floor).map(|l| (o, l))
                    })
                    .collect();
                mark_near_ground(&mut r.samples, s, machine, &kin, base_heading);
                add_cuts(&mut floor, &r.samples, s, machine, &kin, base_heading);
            }
        }
    }
    records.retain(|r| r.samples.len() >= 200 && r.validate().is_ok());
    Ok(records)
}

#[cfg(test)]
mod tests {
    use super::*;
    use firmware_bridge::messages::GatewayMode;

    /// A scanner 3 m up at the world origin, facing +x.
    fn cab_sensor() -> ScanSensor {
        ScanSensor {
            x_m: 0.0,
            y_m: 0.0,
            z_m: 3.0,
            heading_rad: 0.0,
        }
    }

    /// A bench top at 2 m with the trench of a neighbouring dig (floor 1 m) from 0.3 m beside the
    /// plane, scanned sparsely: per 0.1 m along the plane two points on the ground at the plane and
    /// three in the trench within 0.5 m of it. The section is the ground on the plane.
    #[test]
    fn a_neighbouring_trench_beside_the_plane_does_not_lower_the_section() {
        let machine = MachineConfig::default_machine().expect("machine");
        let sensor = cab_sensor();
        let mount = sensor.heading_rad + machine.sensor.bearing_rad;
        let origin = [
            sensor.x_m - machine.sensor.radial_offset_m * mount.cos(),
            sensor.y_m - machine.sensor.radial_offset_m * mount.sin(),
        ];
        let mut points = Vec::new();
        for k in 0..40 {
            let along = 5.0 + 0.1 * f64::from(k);
            for lateral in [-0.2, 0.0, 0.35, 0.42, 0.48] {
                let z = if lateral > 0.3 { 1.0 } else { 2.0 };
                points.push([origin[0] + along, origin[1] + lateral, z]);
            }
        }
        let scan = ScanFile {
            time_s: 0.0,
            sensor,
            points,
        };
        let section = scan_section(&scan, &machine, 0.0, &CutFloor::default()).expect("section");
        for r in [5.5, 6.0, 7.0, 8.5] {
            let h = section.height_at(r).expect("on the section");
            assert!((h - 2.0).abs() < 1e-9, "ground at r = {r}: {h}");
        }
        // The trench itself, as a lane beside the plane.
        let lane = scan_section_beside(&scan, &machine, 0.0, 0.42, 0.1, &CutFloor::default())
            .expect("lane");
        assert!((lane.height_at(6.0).expect("on") - 1.0).abs() < 1e-9);
    }

    /// A crest at 4.5 m (height 0) hiding a 45 degree face down to a floor at -2 m from 6.5 m on:
    /// the scan sees the bench top to 4.5 m and the floor from 7.5 m, so the section bridges the
    /// shadow in a straight line 0-1 m above the face. Boom-Down met the face at 5.5 m (height
    /// -1.0); the section then runs from the crest through that contact to the first seen floor,
    /// never above the bridge; seen ground stays as scanned. A contact above the section, or
    /// where the scan saw the ground, changes nothing.
    #[test]
    fn unseen_ground_passes_no_higher_than_the_first_contact() {
        let machine = MachineConfig::default_machine().expect("machine");
        let scan0 = ScanFile {
            time_s: 0.0,
            sensor: cab_sensor(),
            points: Vec::new(),
        };
        let origin = machine_origin(&scan0, &machine);
        let ground = |along: f64| (4.5 - along).clamp(-2.0, 0.0);
        let points = (0..=60)
            .map(|k| 2.0 + 0.1 * f64::from(k))
            .filter(|along| !(4.55..7.45).contains(along))
            .map(|along| [origin[0] + along, origin[1], ground(along)])
            .collect();
        let scan = ScanFile { points, ..scan0 };
        let floor = CutFloor::default();
        let at = |section: &SectionProfile, r: f64| section.height_at(r).expect("on the section");
        let bridged = scan_section(&scan, &machine, 0.0, &floor).expect("section");
        let bridge = |r: f64| -2.0 * (r - 4.5) / 3.0;
        assert!((at(&bridged, 5.5) - bridge(5.5)).abs() < 1e-9);
        let lowered = scan_section_through_contact(&scan, &machine, 0.0, &floor, Some([5.5, -1.0]))
            .expect("section");
        assert!((at(&lowered, 5.5) + 1.0).abs() < 1e-9);
        // Crest to contact, then contact to the first seen floor at 7.5 m (above the bridge:
        // the bridge).
        assert!((at(&lowered, 5.0) + 0.5).abs() < 1e-9);
        for r in [6.0, 6.5, 7.0] {
            let through = -1.0 - (r - 5.5) / 2.0;
            assert!(
                (at(&lowered, r) - through.min(bridge(r))).abs() < 1e-9,
                "{r}"
            );
        }
        for r in [3.0, 4.0, 4.5, 7.5, 8.0] {
            assert!((at(&lowered, r) - ground(r)).abs() < 1e-9, "seen at {r}");
        }
        for contact in [[5.5, -0.5], [4.0, -1.0], [7.8, -3.0]] {
            let same = scan_section_through_contact(&scan, &machine, 0.0, &floor, Some(contact))
                .expect("section");
            for r in [4.0, 5.0, 5.5, 6.0, 7.0, 8.0] {
                assert!(
                    (at(&same, r) - at(&bridged, r)).abs() < 1e-9,
                    "{contact:?} at {r}"
                );
            }
        }
    }

    /// A face scanned from the cab with a shadow behind its crest: points every 0.1 m from 4 to
    /// 8 m along the plane, none from 5.0 to 5.6 m, where an earlier dig's edge passed at 0.5 m (the
    /// bridge there 0.4-1.0 m). The section is lowered to the edge's path in the shadow only; seen
    /// ground stays the scan's, even where the edge passed above or below it, and without that
    /// dig the shadow is bridged. The same when the band beside the plane has points in the
    /// shadow but the plane itself has none.
    #[test]
    fn ground_the_scan_did_not_see_is_lowered_to_an_earlier_digs_edge_path() {
        let machine = MachineConfig::default_machine().expect("machine");
        let sensor = cab_sensor();
        let scan0 = ScanFile {
            time_s: 0.0,
            sensor,
            points: Vec::new(),
        };
        let origin = machine_origin(&scan0, &machine);
        let ground = |along: f64| 6.0 - along; // a 45 degree face
        let mut points = Vec::new();
        for k in 0..=40 {
            let along = 4.0 + 0.1 * f64::from(k);
            if (4.95..5.65).contains(&along) {
                continue;
            }
            points.push([origin[0] + along, origin[1], ground(along)]);
        }
        let scan = ScanFile { points, ..scan0 };
        // The earlier dig: its edge at 0.5 m from 4.0 to 7.0 m along the same plane.
        let mut floor = CutFloor::default();
        for k in 0..=300 {
            let along = 4.0 + 0.01 * f64::from(k);
            floor.add(
                [origin[0] + along, origin[1]],
                0.5,
                0.0,
                machine.bucket.width_m,
            );
        }
        let lowered = scan_section(&scan, &machine, 0.0, &floor).expect("section");
        let bridged = scan_section(&scan, &machine, 0.0, &CutFloor::default()).expect("section");
        for r in [5.1, 5.3, 5.5] {
            let h = lowered.height_at(r).expect("on");
            assert!((h - 0.5).abs() < 1e-9, "shadow at {r}: {h}");
            let b = bridged.height_at(r).expect("on");
            assert!((b - ground(r)).abs() < 1e-9, "bridge at {r}: {b}");
        }
        for r in [4.2, 4.8, 5.8, 6.5, 7.5] {
            let h = lowered.height_at(r).expect("on");
            assert!((h - ground(r)).abs() < 1e-9, "seen at {r}: {h}");
        }
        // A lane beside the plane within the bucket's half width has the same shadow, lowered.
        let points_beside: Vec<[f64; 3]> = scan
            .points
            .iter()
            .map(|p| [p[0], p[1] + 0.5, p[2]])
            .collect();
        let beside = ScanFile {
            points: points_beside,
            ..scan
        };
        let lane = scan_section_beside(&beside, &machine, 0.0, 0.5, 0.125, &floor).expect("lane");
        assert!((lane.height_at(5.3).expect("on") - 0.5).abs() < 1e-9);
        // The trench seen only from beside: in the shadow the band's points are the higher ground
        // 0.2 m either side of the plane, none on the plane itself. The medians are that ground,
        // and the section is still lowered to the edge's path; without the dig it is the medians.
        let mut walls = beside.points.clone();
        walls.retain(|p| (p[0] - origin[0] - 5.3).abs() > 0.35);
        for p in &mut walls {
            p[1] -= 0.5;
        }
        for k in 0..7 {
            let along = 5.0 + 0.1 * f64::from(k);
            for side in [-0.2, 0.2] {
                walls.push([origin[0] + along, origin[1] + side, ground(along) + 0.6]);
            }
        }
        let from_beside = ScanFile {
            points: walls,
            ..beside
        };
        let lowered = scan_section(&from_beside, &machine, 0.0, &floor).expect("section");
        let medians =
            scan_section(&from_beside, &machine, 0.0, &CutFloor::default()).expect("section");
        for r in [5.1, 5.3, 5.5] {
            let h = lowered.height_at(r).expect("on");
            assert!((h - 0.5).abs() < 1e-9, "trench at {r}: {h}");
            let m = medians.height_at(r).expect("on");
            assert!((m - ground(r) - 0.6).abs() < 1e-9, "medians at {r}: {m}");
        }
        assert!((lowered.height_at(6.5).expect("on") - ground(6.5)).abs() < 1e-9);
    }

    /// The edge lowers the cells across the bucket width, across its own plane (here at 90
    /// degrees: across is along world x); a non-finite edge adds nothing.
    #[test]
    fn the_cut_floor_spans_the_bucket_width_across_the_plane() {
        let mut floor = CutFloor::default();
        floor.add([0.05, 5.05], -1.0, std::f64::consts::FRAC_PI_2, 1.3);
        floor.add([0.05, 5.05], -0.5, std::f64::consts::FRAC_PI_2, 1.3);
        for x in [-0.55, 0.05, 0.65] {
            assert_eq!(floor.lowest([x, 5.05]), Some(-1.0), "x = {x}");
        }
        assert_eq!(floor.lowest([0.95, 5.05]), None);
        assert_eq!(floor.lowest([0.05, 5.25]), None);
        floor.add([f64::NAN, 5.0], -3.0, 0.0, 1.3);
        floor.add([0.05, 5.05], f64::INFINITY, 0.0, 1.3);
        assert_eq!(floor.lowest([0.05, 5.05]), Some(-1.0));
    }

    /// An empty bucket outside Autodig whose tip comes within the clearance of a scanned pile is
    /// near the ground, the same bucket high above it is in free air; samples before the record's
    /// last Track sample (the base stood elsewhere) and in the Autodig stages are left as they are.
    #[test]
    fn an_empty_bucket_low_over_the_scanned_ground_is_near_it() {
        let machine = MachineConfig::default_machine().expect("machine");
        let kin = Kinematics::new(&machine).expect("kinematics");
        let sensor = cab_sensor();
        let origin = machine_origin(
            &ScanFile {
                time_s: 0.0,
                sensor,
                points: Vec::new(),
            },
            &machine,
        );
        let angles_rad = [0.2, -1.6, -1.2];
        let tip = kin.forward(&JointAngles {
            boom_rad: angles_rad[0],
            stick_rad: angles_rad[1],
            bucket_rad: angles_rad[2],
        });
        // A pile 0.2 m below the tip around it, flat ground 3 m below elsewhere.
        let mut points = Vec::new();
        for i in -40..40 {
            for j in -40..40 {
                let (x, y) = (
                    origin[0] + 0.1 * f64::from(i) + 5.0,
                    origin[1] + 0.1 * f64::from(j),
                );
                let on_pile = (x - origin[0] - tip.x_m).abs() < 0.5 && y.abs() < 0.5;
                let z = if on_pile {
                    tip.z_m - 0.2
                } else {
                    tip.z_m - 3.0
                };
                points.push([x, y, z]);
            }
        }
        let scan = ScanFile {
            time_s: 0.0,
            sensor,
            points,
        };
        let sample = |swing_rad: f64, stage: StageTag, tracking: bool| Sample {
            angles_rad,
            swing_rad,
            stage,
            tracking,
            ..Sample::default()
        };
        let mut samples = vec![
            sample(0.0, StageTag::Outside, false),
            sample(0.0, StageTag::Outside, true),
            sample(0.0, StageTag::Outside, false),
            sample(1.2, StageTag::Outside, false),
            sample(0.0, StageTag::BoomDown, false),
        ];
        mark_near_ground(&mut samples, &scan, &machine, &kin, 0.0);
        let loads: Vec<LoadTag> = samples.iter().map(|s| s.load).collect();
        assert_eq!(
            loads,
            [
                LoadTag::EmptyFreeAir,
                LoadTag::EmptyFreeAir,
                LoadTag::NearGround,
                LoadTag::EmptyFreeAir,
                LoadTag::EmptyFreeAir,
            ]
        );
    }

    /// Writes `m` into the trace as received at `t_s` of virtual time, stamped as `demo` stamps it
    /// (from the virtual clock's epoch).
    fn record(rec: &firmware_bridge::trace::Recorder, t_s: f64, m: &Message) {
        let frame = m.encode().expect("encode");
        rec.record(
            firmware_bridge::transport::TraceClock::Virtual.trace_ns((t_s * 1e9).round() as u64),
            firmware_bridge::trace::Direction::Receive,
            &frame,
        );
    }

    /// A cleanup's position-mode phase (gateway `ArmedPosition`, `PositionSetpoint`s, no valve
    /// commands) from 1.0 to 2.0 s in a 4 s trace: its samples and those of the settling time after
    /// it are left out, the others kept with their dig index.
    #[test]
    fn samples_under_the_gateways_position_mode_are_left_out() {
        use firmware_bridge::messages::{
            ControllerStatus, GatewayFaults, GatewayStatus, JointAngles, PositionSetpoint,
        };
        use firmware_bridge::trace::Recorder;

        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("trace.log");
        let rec = Recorder::create(&path, "vcan0").expect("recorder");
        let put = |t_s: f64, m: Message| record(&rec, t_s, &m);
        let position = |t_s: f64| (1.0..2.0).contains(&t_s);
        put(
            0.0,
            Message::ControllerStatus(ControllerStatus {
                activity: Activity::Cleanup,
                dig_index: 3,
                ..Default::default()
            }),
        );
        for k in 1..400 {
            let t = 0.01 * f64::from(k);
            if k % 5 == 0 {
                put(
                    t,
                    Message::GatewayStatus(GatewayStatus {
                        mode: if position(t) {
                            GatewayMode::ArmedPosition
                        } else {
                            GatewayMode::ArmedValve
                        },
                        faults: GatewayFaults(0),
                        alive_counter: (k / 5 % 256) as u8,
                        unexpected_frames: 0,
                        rejected_frames: 0,
                    }),
                );
            }
            if position(t) {
                put(
                    t,
                    Message::PositionSetpoint(PositionSetpoint {
                        boom_rad: 0.1,
                        stick_rad: -1.5,
                        bucket_rad: -0.8,
                        swing_rad: 0.0,
                    }),
                );
            }
            put(
                t + 0.001,
                Message::JointAngles(JointAngles {
                    boom_rad: 0.1,
                    ..Default::default()
                }),
            );
        }
        rec.close().expect("close");
        // The session's summary says the trace is in virtual time (from its epoch): the samples are
        // in session time, as the scans.
        std::fs::write(
            dir.path().join("summary.json"),
            r#"{"trace_clock": "virtual"}"#,
        )
        .expect("summary");

        let samples = read_trace(&path).expect("read");
        let times: Vec<f64> = samples.iter().map(|(_, s)| s.time_s).collect();
        assert!(samples.iter().all(|(d, _)| *d == 3));
        // Before the position mode: every angle frame (0.011 .. 0.991 s).
        assert_eq!(times.iter().filter(|t| **t < 1.0).count(), 99);
        // Under it and for the settling time after its last status (1.95 s) and setpoint (1.99 s):
        // nothing.
        let settled = 1.99 + POSITION_MODE_SETTLE_S;
        assert!(times.iter().all(|t| *t < 1.0 || *t > settled), "{times:?}");
        // After it: the rest.
        assert_eq!(
            times.iter().filter(|t| **t > settled).count(),
            times.len() - 99
        );
        assert!(times.iter().filter(|t| **t > settled).count() > 100);
    }

    /// A corrupt scan file failed the whole session; it is skipped and the others are read.
    #[test]
    fn a_corrupt_scan_is_skipped() {
        let dir = tempfile::tempdir().expect("tempdir");
        let scans = dir.path().join("scans");
        std::fs::create_dir_all(&scans).expect("scans dir");
        let scan = r#"{"time_s":1.5,"sensor":{"x_m":0.87,"y_m":0.5,"z_m":3.1,"heading_rad":0.0},"points":[[2.0,0.0,0.1]]}"#;
        std::fs::write(scans.join("scan_0000.json"), scan).expect("scan 0");
        std::fs::write(scans.join("scan_0001.json"), &scan[..40]).expect("scan 1");
        std::fs::write(scans.join("scan_0002.json"), scan.replace("1.5", "9.5")).expect("scan 2");
        let read = read_scans(dir.path()).expect("scans");
        let times: Vec<f64> = read.iter().map(|s| s.time_s).collect();
        assert_eq!(times, vec![1.5, 9.5]);
    }

    /// A recording cut mid-line (the logger stopped, a killed `demo`) was an error that lost the
    /// whole session; what precedes the cut is analysed.
    #[test]
    fn a_trace_cut_mid_line_keeps_what_precedes_the_cut() {
        use firmware_bridge::messages::{ControllerStatus, JointAngles};
        use firmware_bridge::trace::Recorder;

        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("trace.log");
        let rec = Recorder::create(&path, "vcan0").expect("recorder");
        let put = |t_s: f64, m: Message| record(&rec, t_s, &m);
        put(
            0.0,
            Message::ControllerStatus(ControllerStatus {
                activity: Activity::Dig,
                dig_index: 1,
                ..Default::default()
            }),
        );
        for k in 1..=50 {
            put(
                0.01 * f64::from(k),
                Message::JointAngles(JointAngles::default()),
            );
        }
        rec.close().expect("close");
        let whole = read_trace(&path).expect("whole trace").len();
        assert!(whole >= 49, "{whole} samples");
        let mut text = std::fs::read_to_string(&path).expect("read back");
        text.push_str("(0.510000) vcan0 0CFE32");
        std::fs::write(&path, text).expect("cut");
        let cut = read_trace(&path).expect("a cut trace is read up to the cut");
        assert_eq!(cut.len(), whole);
    }

    /// The work cycle's Weigh shows as `Idle` between a dig and its swing to the dump: those samples
    /// are tagged `Weighing`; an `Idle` that follows anything else (the start of a session, a swing)
    /// or comes with the next dig index is not.
    #[test]
    fn idle_after_a_dig_of_the_same_index_is_the_weighing() {
        use firmware_bridge::messages::{ControllerStatus, JointAngles};
        use firmware_bridge::trace::Recorder;

        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("trace.log");
        let rec = Recorder::create(&path, "vcan0").expect("recorder");
        let put = |t_s: f64, m: Message| record(&rec, t_s, &m);
        // (from, activity, dig index)
        let phases = [
            (0.0, Activity::Idle, 0),
            (1.0, Activity::Dig, 1),
            (2.0, Activity::Idle, 1),
            (3.0, Activity::SwingToDump, 1),
            (4.0, Activity::Idle, 1),
            (5.0, Activity::Cleanup, 2),
            (6.0, Activity::Idle, 2),
            (7.0, Activity::Idle, 3),
        ];
        for k in 0..800 {
            let t = 0.01 * f64::from(k);
            if k % 10 == 0 {
                let (_, activity, dig_index) = phases
                    .iter()
                    .rev()
                    .find(|(from, _, _)| *from <= t + 1e-9)
                    .copied()
                    .expect("phase");
                put(
                    t,
                    Message::ControllerStatus(ControllerStatus {
                        activity,
                        dig_index,
                        ..Default::default()
                    }),
                );
            }
            put(t + 0.001, Message::JointAngles(JointAngles::default()));
        }
        rec.close().expect("close");

        let samples = read_trace(&path).expect("read");
        // A sample takes the status in force when its successor arrives (the controller's answer
        // to it): the last sample before a status change is tagged with the new one.
        for (d, s) in samples
            .iter()
            .filter(|(_, s)| (s.time_s - s.time_s.round()).abs() > 0.02)
        {
            let weighing = (2.0..3.0).contains(&s.time_s) || (6.0..7.0).contains(&s.time_s);
            assert_eq!(
                s.load == LoadTag::Weighing,
                weighing,
                "t = {:.3} s, dig {d}: {:?}",
                s.time_s,
                s.load
            );
        }
        assert!(
            samples
                .iter()
                .filter(|(_, s)| s.load == LoadTag::Weighing)
                .count()
                > 150
        );
    }
}
