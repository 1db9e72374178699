//! `excavator-ctl demo` writes all its outputs with the documented fields (docs/demo-output.md).

#![allow(clippy::unwrap_used)]

mod common;
#[path = "support/markdown.rs"]
mod markdown;

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

use lab::demo::{DemoArgs, DemoSummary, run_session, summary_markdown};

#[test]
fn demo_writes_all_outputs_with_the_documented_fields_for_two_digs() {
    let dir = tempfile::tempdir().unwrap();
    let mut args = DemoArgs::fixed(dir.path().join("demo"));
    args.digs = 2;
    let summary = run_session(&args, &AtomicBool::new(false)).unwrap();
    assert!(summary.totals.finished, "{:?}", summary.totals);
    assert_eq!(summary.digs.len(), 2);
    let out = dir.path().join("demo");
    for f in [
        "trace.log",
        "summary.json",
        "summary.md",
        "plan.json",
        "trajectories.svg",
        "terrain_before.svg",
        "terrain_after.svg",
        "dig_stats.svg",
        "scans/scan_0000.json",
    ] {
        let p = out.join(f);
        assert!(p.metadata().map(|m| m.len() > 0).unwrap_or(false), "{f}");
    }
    // summary.json has the documented fields.
    let json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("summary.json")).unwrap()).unwrap();
    let digs = json["digs"].as_array().unwrap();
    assert_eq!(digs.len(), 2);
    assert_eq!(
        json["soil_contact"], "implicit",
        "the plant the session ran on"
    );
    for d in digs {
        for k in [
            "index",
            "action",
            "swing_deg",
            "start_pose",
            "weight_n",
            "time_s",
            "energy_kj",
            "swept_volume_m3",
            "end_reason",
        ] {
            assert!(d.get(k).is_some(), "dig field {k}: {d}");
        }
        assert!(d["time_s"].as_f64().unwrap() > 0.0);
        assert!(d["energy_kj"].as_f64().unwrap() > 0.0);
    }
    // The first dig fills the bucket from the default start (> 80 % of the rated 2550 kg).
    let full_kg = planner::machine::MachineConfig::default_machine()
        .unwrap()
        .rated_payload_kg();
    assert!(
        digs[0]["true_payload_kg"].as_f64().unwrap() > 0.8 * full_kg,
        "{}",
        digs[0]
    );
    assert!(digs[0]["swept_volume_m3"].as_f64().unwrap() > 0.0);
    for k in [
        "digs",
        "weight_n",
        "mean_time_s",
        "energy_kj",
        "sim_time_s",
        "trace_frames",
    ] {
        assert!(json["totals"].get(k).is_some(), "totals field {k}");
    }
    assert_eq!(json["totals"]["trace_dropped"].as_u64(), Some(0));
    // The scans are in the scan-protocol reply format.
    let scan: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("scans/scan_0000.json")).unwrap()).unwrap();
    assert!(scan["time_s"].is_number() && scan["sensor"]["heading_rad"].is_number());
    assert!(!scan["points"].as_array().unwrap().is_empty());
    // The trace is candump -L text with both directions, closed (the last line is complete).
    let trace = std::fs::read_to_string(out.join("trace.log")).unwrap();
    assert!(trace.ends_with('\n'));
    let first = trace.lines().find(|l| l.starts_with('(')).unwrap();
    assert!(first.contains(" vcan0 "), "{first}");
    assert!(
        trace.contains("#27") || trace.contains("27#"),
        "controller frames"
    );
    assert!(trace.lines().count() as u64 >= json["totals"]["trace_frames"].as_u64().unwrap());
    assert_clean_protocol(&out.join("trace.log"));
    assert_epoch_stamps(&out.join("trace.log"), &summary);
    markdown::assert_tables_render(&std::fs::read_to_string(out.join("summary.md")).unwrap());
    // The soil estimator's samples of the planned session, for `model soil-cv`.
    let soil: onboard::record::SoilSamplesFile =
        serde_json::from_slice(&std::fs::read(out.join("soil_samples.json")).unwrap()).unwrap();
    assert!(soil.digs.iter().all(|d| d.index < 2));
    assert!(soil.digs.iter().flat_map(|d| &d.samples).all(|s| {
        s.geometry.depth_m > 0.0 && s.force.fx_n.is_finite() && s.force.fz_n.is_finite()
    }));
}

/// The trace is stamped with the virtual time from the fixed epoch, which `trace_time_base` (the
/// reader's view of it) turns back into the session's time: the first frame within the first control
/// steps, the last at the session's end.
fn assert_epoch_stamps(trace: &Path, summary: &DemoSummary) {
    use firmware_bridge::transport::{TraceClock, VIRTUAL_EPOCH_UNIX_NS};
    assert_eq!(summary.trace_clock, Some(TraceClock::Virtual));
    let records: Vec<_> = std::fs::read_to_string(trace)
        .unwrap()
        .lines()
        .map(|l| firmware_bridge::trace::parse_line(l).unwrap())
        .collect();
    let mut base = lab::demo::trace_time_base(trace).unwrap();
    let first = records.first().unwrap().timestamp_ns;
    let last = records.last().unwrap().timestamp_ns;
    assert!(first >= VIRTUAL_EPOCH_UNIX_NS, "first stamp {first} ns");
    assert!(base.session_s(first) < 0.05, "{}", base.session_s(first));
    assert_eq!(base.origin_ns(), Some(VIRTUAL_EPOCH_UNIX_NS));
    let end_s = summary.totals.sim_time_s;
    assert!(
        (base.session_s(last) - end_s).abs() < 0.05,
        "last frame at {} s of a {end_s} s session",
        base.session_s(last)
    );
}

/// A clean session's trace has no protocol error in `trace stats` (alive counters, checksums,
/// out-of-range or backward frames, unknown ids, error frames), and the gateway's own status reports no
/// rejected or unexpected frame.
fn assert_clean_protocol(trace: &std::path::Path) {
    use firmware_bridge::messages::Message;
    use firmware_bridge::trace::{ReadMode, TraceReader};
    let file = std::io::BufReader::new(std::fs::File::open(trace).unwrap());
    let report = trace_tools::stats::collect(
        file,
        trace_tools::stats::StatsOptions::default(),
        true,
        &mut std::io::sink(),
    )
    .unwrap();
    assert_eq!(report.malformed_lines, 0);
    assert_eq!(report.unknown_id_frames, 0);
    assert_eq!(report.error_frames, 0);
    for id in &report.ids {
        let what = format!("{} {}", id.id, id.message);
        assert_eq!(id.alive_errors.unwrap_or(0), 0, "alive counter: {what}");
        assert_eq!(id.checksum_errors.unwrap_or(0), 0, "checksum: {what}");
        assert_eq!(id.invalid, 0, "invalid: {what} {:?}", id.last_invalid);
        assert_eq!(id.backwards, 0, "time backwards: {what}");
    }
    let reader = TraceReader::new(
        std::io::BufReader::new(std::fs::File::open(trace).unwrap()),
        ReadMode::Stop,
    );
    let mut statuses = 0;
    for record in reader {
        if let Ok(decoded) = Message::decode(&record.unwrap().frame)
            && let Message::GatewayStatus(status) = decoded.message
        {
            statuses += 1;
            assert_eq!(status.rejected_frames, 0, "{status:?}");
            assert_eq!(status.unexpected_frames, 0, "{status:?}");
        }
    }
    assert!(statuses > 0, "the gateway's status is in the trace");
}

/// Two planned sessions of one seed write the same files byte for byte: the trace, the scans, the
/// plans and plots; `summary.json` apart from its wall-clock figures, which
/// `DemoSummary::without_wall_clock` names (and `summary.md` prints nothing else beyond it).
#[test]
fn demo_sessions_of_one_seed_are_byte_identical() {
    let dir = tempfile::tempdir().unwrap();
    let run = |name: &str| {
        let out = dir.path().join(name);
        let mut args = DemoArgs::defaults(out.clone());
        args.digs = 1;
        args.seed = Some(5);
        let summary = run_session(&args, &AtomicBool::new(false)).unwrap();
        assert_eq!(summary.digs.len(), 1, "{:?}", summary.totals);
        assert!(summary.totals.trace_frames > 0);
        out
    };
    let (a, b) = (run("a"), run("b"));
    let files = files_under(&a);
    assert_eq!(files, files_under(&b), "the same files");
    assert!(files.iter().any(|f| f.starts_with("scans")), "{files:?}");
    for f in &files {
        let (fa, fb) = (a.join(f), b.join(f));
        match f.to_str() {
            Some("summary.json") => {
                let (sa, sb) = (summary_of(&fa), summary_of(&fb));
                assert_eq!(sa.without_wall_clock(), sb.without_wall_clock());
            }
            Some("summary.md") => {
                for (md, json) in [(&fa, a.join("summary.json")), (&fb, b.join("summary.json"))] {
                    let text = std::fs::read_to_string(md).unwrap();
                    assert_eq!(
                        text,
                        summary_markdown(&summary_of(&json)),
                        "{}",
                        md.display()
                    );
                }
            }
            _ => {
                let (ba, bb) = (std::fs::read(&fa).unwrap(), std::fs::read(&fb).unwrap());
                if ba != bb {
                    let line = ba
                        .split(|&c| c == b'\n')
                        .zip(bb.split(|&c| c == b'\n'))
                        .position(|(x, y)| x != y)
                        .map_or(0, |i| i + 1);
                    panic!(
                        "{} differs between the sessions from line {line}",
                        f.display()
                    );
                }
            }
        }
    }
}

/// The files under `root`, relative to it, sorted.
fn files_under(root: &Path) -> Vec<PathBuf> {
    let mut files = Vec::new();
    let mut dirs = vec![root.to_path_buf()];
    while let Some(d) = dirs.pop() {
        for entry in std::fs::read_dir(&d).unwrap() {
            let p = entry.unwrap().path();
            if p.is_dir() {
                dirs.push(p);
            } else {
                files.push(p.strip_prefix(root).unwrap().to_path_buf());
            }
        }
    }
    files.sort();
    files
}

fn summary_of(path: &Path) -> DemoSummary {
    serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap()
}

#[test]
fn demo_rejects_unknown_effects() {
    let dir = tempfile::tempdir().unwrap();
    let mut args = DemoArgs::fixed(dir.path().join("demo"));
    args.effects = vec!["no_such_effect=1".to_owned()];
    let err = run_session(&args, &AtomicBool::new(false)).unwrap_err();
    assert!(format!("{err:#}").contains("no_such_effect"), "{err:#}");
}

#[test]
fn demo_stops_cleanly_when_asked() {
    let dir = tempfile::tempdir().unwrap();
    let args = DemoArgs::fixed(dir.path().join("demo"));
    let summary = run_session(&args, &AtomicBool::new(true)).unwrap();
    assert!(!summary.totals.finished);
    assert!(dir.path().join("demo/trace.log").exists());
    assert!(dir.path().join("demo/summary.json").exists());
}

/// `--plant-machine`: the simulated machine is built from the file (a boom bore 20 % larger), the
/// controller keeps the built-in machine; `summary.json` records the file and its hash; the
/// session differs from the nominal one of the same seed; a bad file is an error naming it and
/// the field.
#[test]
fn demo_plant_machine_changes_the_plant_and_not_the_controller() {
    use sha2::Digest as _;
    let dir = tempfile::tempdir().unwrap();
    let nominal = planner::machine::MachineConfig::default_machine().unwrap();
    let text =
        planner::machine::DEFAULT_MACHINE_TOML.replacen("bore_m = 0.120", "bore_m = 0.144", 1);
    let plant_file = dir.path().join("plant.toml");
    std::fs::write(&plant_file, &text).unwrap();

    let mut args = DemoArgs::fixed(dir.path().join("plant"));
    args.digs = 1;
    args.seed = Some(5);
    args.plant_machine = Some(plant_file.clone());
    let (sim, _, _) = lab::demo::setup(&args).unwrap();
    assert_eq!(sim.machine.cylinders.boom.bore_m, 0.144, "the plant's file");
    let controller = lab::demo::controller_machine(&args, &sim).unwrap();
    assert_eq!(controller, nominal, "the controller keeps its own machine");

    let changed = run_session(&args, &AtomicBool::new(false)).unwrap();
    let recorded = changed.plant_machine.clone().unwrap();
    assert_eq!(recorded.path, plant_file.display().to_string());
    let hash: String = sha2::Sha256::digest(text.as_bytes())
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect();
    assert_eq!(recorded.sha256, hash);
    let json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("plant/summary.json")).unwrap())
            .unwrap();
    assert_eq!(json["plant_machine"]["sha256"], hash.as_str());

    let mut plain = args.clone();
    plain.plant_machine = None;
    plain.out = dir.path().join("nominal");
    let same_seed = run_session(&plain, &AtomicBool::new(false)).unwrap();
    assert!(same_seed.plant_machine.is_none());
    assert_ne!(
        std::fs::read(dir.path().join("plant/trace.log")).unwrap(),
        std::fs::read(dir.path().join("nominal/trace.log")).unwrap(),
        "the larger boom bore changes the measured pressures"
    );
    assert_ne!(changed.digs[0].energy_kj, same_seed.digs[0].energy_kj);

    std::fs::write(
        &plant_file,
        planner::machine::DEFAULT_MACHINE_TOML.replacen("bore_m = 0.120", "bore_m = -0.1", 1),
    )
    .unwrap();
    let err = format!("{:#}", lab::demo::setup(&args).unwrap_err());
    assert!(
        err.contains(&plant_file.display().to_string()) && err.contains("bore_m"),
        "{err}"
    );
}

/// `--profile`: the demo's controller and simulated gateway speak another gateway's protocol
/// (`examples/other_gateway.toml`) on the in-process bus, at its rates: the session digs, the trace
/// holds only that gateway's 11-bit frames (each translating back), its angles come every 20 ms
/// after the gateway's 250 ms address-claim hold,
/// and `summary.json` records the profile and its hash. The default profile gives the trace of no
/// profile, byte for byte.
#[test]
fn demo_speaks_a_machine_profile_on_the_bus() {
    use sha2::Digest as _;
    let root = concat!(env!("CARGO_MANIFEST_DIR"), "/..");
    let example = Path::new(root).join("examples/other_gateway.toml");
    let profile = firmware_bridge::profile::Profile::load(&example).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let mut args = DemoArgs::fixed(dir.path().join("other"));
    args.digs = 1;
    args.profile = Some(example.clone());
    let summary = run_session(&args, &AtomicBool::new(false)).unwrap();
    assert!(summary.totals.finished, "{:?}", summary.totals);
    assert_eq!(summary.digs.len(), 1);
    let recorded = summary.profile.clone().unwrap();
    assert_eq!(recorded.path, example.display().to_string());
    let hash: String = sha2::Sha256::digest(std::fs::read(&example).unwrap())
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect();
    assert_eq!(recorded.sha256, hash);

    let (frames, angles, heartbeats) =
        common::wire_trace_counts(&dir.path().join("other/trace.log"), &profile);
    assert_eq!(u64::from(frames), summary.totals.trace_frames);
    eprintln!(
        "other gateway: {frames} frames, {angles} joint angles, {heartbeats} heartbeats in {:.2} s",
        summary.totals.sim_time_s
    );
    // One angle frame per 20 ms of the session once the gateway's address claim has stood.
    let hold_s = firmware_bridge::address_claim::CLAIM_HOLD_NS as f64 * 1e-9;
    let expected = (summary.totals.sim_time_s - hold_s) / 0.02;
    assert!(
        (f64::from(angles) - expected).abs() <= 2.0,
        "{angles} joint angles in {} s",
        summary.totals.sim_time_s
    );
    assert!(heartbeats > 0);

    // The default profile is the identity: the same trace as no profile.
    let mut plain = DemoArgs::fixed(dir.path().join("plain"));
    plain.digs = 1;
    run_session(&plain, &AtomicBool::new(false)).unwrap();
    let mut default = plain.clone();
    default.out = dir.path().join("default");
    default.profile = Some(Path::new(root).join("profiles/default.toml"));
    run_session(&default, &AtomicBool::new(false)).unwrap();
    assert_eq!(
        std::fs::read(dir.path().join("default/trace.log")).unwrap(),
        std::fs::read(dir.path().join("plain/trace.log")).unwrap()
    );

    // A broken profile stops the demo before it runs, naming the file.
    let broken = dir.path().join("broken.toml");
    std::fs::write(&broken, "dbc = \"nowhere.dbc\"\n[messages]\n").unwrap();
    let mut bad = args.clone();
    bad.profile = Some(broken);
    let err = format!(
        "{:#}",
        run_session(&bad, &AtomicBool::new(false)).unwrap_err()
    );
    assert!(err.contains("nowhere.dbc"), "{err}");
}
