//! `trace replay` timing without a CAN bus: the replay loop drives a recording [`Bus`] under tokio's
//! paused clock, so the send times are exact and the test takes no wall time.

#![allow(clippy::unwrap_used)] // helpers outside #[test] functions fail loudly on purpose

use std::sync::Mutex;

use firmware_bridge::frame::CanFrame;
use firmware_bridge::transport::{Bus, Result, TimestampedFrame, TraceClock};
use tokio::time::{Duration, Instant};
use trace_tools::replay::{self, ReplayClock, ReplayOptions};
use trace_tools::synth::{self, SynthConfig};

/// A bus that remembers when each frame was sent (tokio clock) and never receives.
struct RecordingBus {
    start: Instant,
    sent: Mutex<Vec<(Duration, CanFrame)>>,
}

impl RecordingBus {
    fn new() -> Self {
        Self {
            start: Instant::now(),
            sent: Mutex::new(Vec::new()),
        }
    }

    fn sent(&self) -> Vec<(Duration, CanFrame)> {
        self.sent.lock().unwrap().clone()
    }
}

impl Bus for RecordingBus {
    async fn send(&self, frame: CanFrame) -> Result<()> {
        let at = Instant::now() - self.start;
        self.sent.lock().unwrap().push((at, frame));
        Ok(())
    }

    async fn recv(&self) -> Result<TimestampedFrame> {
        std::future::pending().await
    }

    fn now_ns(&self) -> u64 {
        (Instant::now() - self.start).as_nanos() as u64
    }

    fn interface(&self) -> &str {
        "recording"
    }

    fn trace_clock(&self) -> TraceClock {
        TraceClock::WallAtRead
    }
}

fn fixture(dir: &std::path::Path, frames: u64) -> (std::path::PathBuf, Vec<(u64, CanFrame)>) {
    let cfg = SynthConfig {
        frames,
        ..SynthConfig::default()
    };
    let path = dir.join("dig.log");
    let mut f = std::fs::File::create(&path).unwrap();
    synth::write_candump(&mut f, &cfg).unwrap();
    (path, synth::SyntheticTrace::new(cfg).collect())
}

/// Every frame at `speed`, the controller's included (a bench without a machine).
fn all_frames(speed: f64) -> ReplayOptions {
    ReplayOptions {
        speed,
        allow_control_frames: true,
        ..ReplayOptions::default()
    }
}

/// Regression: `trace replay --iface` of a controller trace armed a live gateway. Without
/// `--allow-control-frames` no frame from the controller's address and no heartbeat goes out.
#[tokio::test(start_paused = true)]
async fn replay_withholds_the_controllers_frames_unless_allowed() {
    let dir = tempfile::tempdir().unwrap();
    let one_second = synth::frames_in(1.0);
    let (path, frames) = fixture(dir.path(), one_second);
    let bus = RecordingBus::new();
    let options = ReplayOptions {
        allow_control_frames: false,
        ..all_frames(1.0)
    };
    let summary = replay::replay_to(&bus, &path, &options, std::future::pending())
        .await
        .unwrap();
    let control = frames
        .iter()
        .filter(|(_, f)| replay::is_control_frame(f))
        .count() as u64;
    assert!(control > 500, "the fixture has the controller's traffic");
    assert_eq!(summary.withheld_control, control);
    assert_eq!(summary.sent, one_second - control);
    let sent = bus.sent();
    assert!(sent.iter().all(|(_, f)| !replay::is_control_frame(f)));
    // Heartbeats from another address are withheld too: they are arming requests.
    let foreign_hb =
        CanFrame::new_extended(0x0CFF_6133, &[0x51, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0])
            .unwrap();
    assert!(replay::is_control_frame(&foreign_hb));
    let gateway = CanFrame::new_extended(0x0CFF_5080, &[0; 8]).unwrap();
    assert!(!replay::is_control_frame(&gateway));
}

#[tokio::test(start_paused = true)]
async fn replay_keeps_the_recorded_spacing() {
    let dir = tempfile::tempdir().unwrap();
    let one_second = synth::frames_in(1.0);
    let (path, frames) = fixture(dir.path(), one_second);
    let bus = RecordingBus::new();
    let summary = replay::replay_to(&bus, &path, &all_frames(1.0), std::future::pending())
        .await
        .unwrap();
    assert_eq!(summary.sent, one_second);
    let sent = bus.sent();
    let t0 = frames[0].0;
    for ((at, frame), (t, original)) in sent.iter().zip(&frames) {
        assert_eq!(frame, original);
        // Candump keeps microseconds; the paused clock is exact to the millisecond granularity of
        // tokio's timer wheel.
        let want = Duration::from_nanos(t - t0);
        let err = at.abs_diff(want);
        assert!(err <= Duration::from_millis(1), "{at:?} vs {want:?}");
    }
    // The whole second of traffic took one (virtual) second.
    let last = sent.last().unwrap().0;
    assert!(
        last > Duration::from_millis(985) && last < Duration::from_millis(1001),
        "{last:?}"
    );
}

#[tokio::test(start_paused = true)]
async fn replay_speed_and_id_filter() {
    let dir = tempfile::tempdir().unwrap();
    let one_second = synth::frames_in(1.0);
    let (path, frames) = fixture(dir.path(), one_second);
    let bus = RecordingBus::new();
    let options = ReplayOptions {
        ids: vec![0x0CFF_5080, 0x0CFF_6127],
        ..all_frames(4.0)
    };
    let summary = replay::replay_to(&bus, &path, &options, std::future::pending())
        .await
        .unwrap();
    // One second: 100 JointAngles and 20 heartbeats.
    assert_eq!(summary.sent, 120);
    assert_eq!(summary.filtered, one_second - 120);
    let sent = bus.sent();
    let t0 = frames[0].0;
    let last_angles = frames
        .iter()
        .rev()
        .find(|(_, f)| f.id().raw() == 0x0CFF_5080)
        .unwrap();
    let want = Duration::from_nanos((last_angles.0 - t0) / 4);
    let got = sent
        .iter()
        .rev()
        .find(|(_, f)| f.id().raw() == 0x0CFF_5080)
        .unwrap()
        .0;
    assert!(
        got.abs_diff(want) <= Duration::from_millis(1),
        "{got:?} vs {want:?}"
    );
}

#[tokio::test(start_paused = true)]
async fn replay_loops_until_stopped() {
    let dir = tempfile::tempdir().unwrap();
    let (path, _) = fixture(dir.path(), 116);
    let bus = RecordingBus::new();
    // 116 frames span about 0.1 s; stop after 1.05 s: about ten passes.
    let options = ReplayOptions {
        repeat: true,
        ..all_frames(1.0)
    };
    let summary = replay::replay_to(
        &bus,
        &path,
        &options,
        tokio::time::sleep(Duration::from_millis(1050)),
    )
    .await
    .unwrap();
    assert!((9..=11).contains(&summary.passes), "{summary:?}");
    assert!(bus.sent().len() as u64 >= summary.passes * 116);
}

#[test]
fn schedule_is_relative_scaled_and_monotonic() {
    let mut clock = ReplayClock::new(0.5).unwrap();
    let t0 = 1_700_000_000_000_000_000u64;
    let offsets: Vec<Duration> = [
        t0,
        t0 + 1_000_000,
        t0 + 3_000_000,
        t0 + 2_000_000,
        t0 + 10_000_000,
    ]
    .into_iter()
    .map(|t| clock.offset(t))
    .collect();
    assert_eq!(
        offsets,
        [0, 2, 6, 6, 20].map(Duration::from_millis).to_vec()
    );
}

/// Regression: `trace replay` of a trace recorded with a machine profile withheld 0 of its
/// controller frames (it knew only the project's ids). With `--profile` every controller frame and
/// heartbeat of the profile's wire protocol is withheld, the gateway's go out as recorded; without
/// it they are sent, counted as frames that are not the project's.
#[tokio::test(start_paused = true)]
async fn replay_of_a_profile_trace_withholds_that_profiles_controller_frames() {
    let profile_path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../examples/other_gateway.toml"
    );
    let profile = std::sync::Arc::new(
        firmware_bridge::profile::Profile::load(std::path::Path::new(profile_path)).unwrap(),
    );
    let dir = tempfile::tempdir().unwrap();
    let (_, frames) = fixture(dir.path(), 1170);
    let mut text = String::new();
    let mut control = 0u64;
    let mut wire_frames = Vec::new();
    for (t, canonical) in &frames {
        // Network management does not cross this (non-J1939) wire bus.
        let Ok(wire) = profile.to_wire(canonical) else {
            continue;
        };
        if replay::is_control_frame(canonical) {
            control += 1;
        }
        wire_frames.push(wire);
        text += &firmware_bridge::trace::format_line(*t, "vcan0", &wire, None);
        text.push('\n');
    }
    assert!(control > 500, "the fixture has the controller's traffic");
    let path = dir.path().join("wire.log");
    std::fs::write(&path, text).unwrap();

    let bus = RecordingBus::new();
    let options = ReplayOptions {
        speed: 1.0,
        profile: Some(profile.clone()),
        ..ReplayOptions::default()
    };
    let summary = replay::replay_to(&bus, &path, &options, std::future::pending())
        .await
        .unwrap();
    assert_eq!(summary.withheld_control, control);
    assert_eq!(summary.sent, wire_frames.len() as u64 - control);
    assert_eq!(summary.foreign, 0);
    for (_, sent) in bus.sent() {
        let canonical = profile.from_wire(&sent).unwrap();
        assert!(!replay::is_control_frame(&canonical), "{sent:?} sent");
        assert!(wire_frames.contains(&sent), "the wire frame as recorded");
    }

    // Without the profile nothing is recognised as the controller's: all sent, all foreign.
    let bus = RecordingBus::new();
    let options = ReplayOptions {
        speed: 1.0,
        ..ReplayOptions::default()
    };
    let summary = replay::replay_to(&bus, &path, &options, std::future::pending())
        .await
        .unwrap();
    assert_eq!(summary.withheld_control, 0);
    assert_eq!(summary.foreign, wire_frames.len() as u64);
}
