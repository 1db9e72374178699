//! `excavator-ctl trace decode` against `cantools decode --single-line`, end to end as a user runs
//! them: two processes, each reading the same file and writing its output to a file (figures
//! printed, never asserted).
//!
//! The input is a candump log of every message of the DBC in turn with random in-range signal
//! values, encoded by cantools' own encoder (`cantools_frames.py`). Times are wall times of the
//! whole process (start-up, reading, decoding, writing); ours is the best of three runs, cantools'
//! one run. The target is a ratio of at least 20x.
//!
//! `cargo bench -p excavator-ctl --bench decode_vs_cantools` (1,000,000 lines; cantools takes about
//! 10 s); `DECODE_BENCH_LINES` overrides the count. Without `--bench` (`cargo test --all-targets`)
//! a 2,000-line smoke pass. Needs python3 with cantools (scripts/install-test-tools).

use std::fs::File;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Instant;

const LINES: u64 = 1_000_000;
const SMOKE_LINES: u64 = 2_000;
const GENERATOR: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/benches/cantools_frames.py");
const DBC: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../gateway_core/excavator.dbc");

/// Runs `cmd` with stdout into `out`; returns its wall time, s.
fn timed(mut cmd: Command, out: &Path) -> Result<f64, Box<dyn std::error::Error>> {
    let start = Instant::now();
    let status = cmd
        .stdout(File::create(out)?)
        .stderr(Stdio::inherit())
        .status()?;
    let secs = start.elapsed().as_secs_f64();
    if !status.success() {
        return Err(format!("{cmd:?} failed: {status}").into());
    }
    Ok(secs)
}

fn lines_of(path: &Path) -> Result<usize, Box<dyn std::error::Error>> {
    Ok(std::fs::read(path)?.iter().filter(|&&b| b == b'\n').count())
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let full = std::env::args().any(|a| a == "--bench");
    let lines = std::env::var("DECODE_BENCH_LINES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(if full { LINES } else { SMOKE_LINES });
    let have_cantools = Command::new("python3")
        .args(["-c", "import cantools"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !have_cantools {
        println!(
            "decode_vs_cantools: python3 without cantools (scripts/install-test-tools): skipped"
        );
        return Ok(());
    }
    let dir = tempfile::tempdir()?;
    let input = dir.path().join("frames.log");
    let start = Instant::now();
    let status = Command::new("python3")
        .arg(GENERATOR)
        .arg(DBC)
        .arg(lines.to_string())
        .arg(&input)
        .status()?;
    if !status.success() {
        return Err(format!("{GENERATOR} failed: {status}").into());
    }
    println!(
        "decode_vs_cantools: {lines} lines of every message with random in-range values (cantools' encoder), {:.1} MB, made in {:.1} s",
        std::fs::metadata(&input)?.len() as f64 / 1e6,
        start.elapsed().as_secs_f64()
    );

    let ours_out = dir.path().join("ours.txt");
    let mut ours = f64::INFINITY;
    for _ in 0..3 {
        let mut cmd = Command::new(env!("CARGO_BIN_EXE_excavator-ctl"));
        cmd.args(["trace", "decode"]).arg(&input);
        ours = ours.min(timed(cmd, &ours_out)?);
    }
    let theirs_out = dir.path().join("cantools.txt");
    let mut cmd = Command::new("python3");
    cmd.args(["-m", "cantools", "decode", "--single-line", DBC])
        .stdin(File::open(&input)?);
    let theirs = timed(cmd, &theirs_out)?;
    let (n_ours, n_theirs) = (lines_of(&ours_out)?, lines_of(&theirs_out)?);
    println!(
        "decode_vs_cantools: excavator-ctl trace decode FILE > out: {ours:.3} s ({:.0} lines/s, {n_ours} lines out, best of 3)",
        lines as f64 / ours
    );
    println!(
        "decode_vs_cantools: python3 -m cantools decode --single-line DBC < FILE > out: {theirs:.2} s ({:.0} lines/s, {n_theirs} lines out)",
        lines as f64 / theirs
    );
    println!(
        "decode_vs_cantools: ratio {:.1}x end to end (target >= 20x){}",
        theirs / ours,
        if full {
            ""
        } else {
            " [smoke run: start-up dominates]"
        }
    );
    if n_ours != n_theirs {
        println!("decode_vs_cantools: WARNING: the outputs differ in line count");
    }
    Ok(())
}
