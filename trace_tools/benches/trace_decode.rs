//! Benchmark of `excavator-ctl trace decode` against `cantools decode` (figures printed, never
//! asserted).
//!
//! Writes a 1,000,000-frame candump log of the full message schedule (`trace_tools::synth`: 1192
//! frames/s, about 14 minutes of digging) to a temporary file, decodes it with the `trace decode`
//! logic into /dev/null, and prints frames/s and the peak RSS (`VmHWM` of /proc/self/status: the file
//! is streamed, so it stays at a few MB). Then, if cantools is installed, times
//! `python3 -m cantools decode gateway_core/excavator.dbc < sample > /dev/null` on the first
//! `CANTOOLS_SAMPLE` frames of the same file (cantools takes minutes for the whole file), scales its
//! rate, and prints the throughput ratio (the target is over 20x).
//!
//! `cargo bench -p controller --bench trace_decode`. Under `cargo test --all-targets` (no `--bench`
//! argument) it only runs a 10,000-frame smoke pass. `TRACE_BENCH_FRAMES` overrides the frame count.

use std::fs::File;
use std::io::{BufRead, BufReader, BufWriter, Write};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Instant;

use trace_tools::decode::{self, DecodeFilter};
use trace_tools::synth::{self, SynthConfig};

const FRAMES: u64 = 1_000_000;
const CANTOOLS_SAMPLE: u64 = 100_000;

fn vm_hwm_kib() -> Option<u64> {
    std::fs::read_to_string("/proc/self/status")
        .ok()?
        .lines()
        .find(|l| l.starts_with("VmHWM:"))?
        .split_whitespace()
        .nth(1)?
        .parse()
        .ok()
}

fn decode_file(path: &Path) -> Result<(u64, f64), Box<dyn std::error::Error>> {
    let input = BufReader::with_capacity(256 * 1024, File::open(path)?);
    let mut out = BufWriter::with_capacity(64 * 1024, File::create("/dev/null")?);
    let start = Instant::now();
    let summary = decode::decode_stream(
        input,
        DecodeFilter::default(),
        false,
        &mut out,
        &mut std::io::sink(),
        false,
    )?;
    Ok((summary.lines_out, start.elapsed().as_secs_f64()))
}

fn cantools_available() -> bool {
    Command::new("python3")
        .args(["-c", "import cantools"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let full = std::env::args().any(|a| a == "--bench");
    let frames = std::env::var("TRACE_BENCH_FRAMES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(if full { FRAMES } else { 10_000 });
    let dir = tempfile::tempdir()?;
    let log = dir.path().join("bench.log");

    let start = Instant::now();
    {
        let mut f = BufWriter::with_capacity(1 << 20, File::create(&log)?);
        synth::write_candump(
            &mut f,
            &SynthConfig {
                frames,
                ..SynthConfig::default()
            },
        )?;
        f.flush()?;
    }
    let bytes = std::fs::metadata(&log)?.len();
    println!(
        "trace_decode: wrote {frames} frames ({:.1} MB, {:.0} s of traffic) in {:.2} s",
        bytes as f64 / 1e6,
        frames as f64 / synth::frames_in(1.0) as f64,
        start.elapsed().as_secs_f64()
    );

    let (lines, secs) = decode_file(&log)?;
    let ours = lines as f64 / secs;
    println!(
        "trace_decode: excavator-ctl trace decode: {lines} frames in {secs:.3} s = {ours:.0} frames/s ({:.1} MB/s)",
        bytes as f64 / 1e6 / secs
    );
    match vm_hwm_kib() {
        Some(kib) => println!(
            "trace_decode: peak RSS (VmHWM) {:.1} MiB for a {:.1} MB trace",
            kib as f64 / 1024.0,
            bytes as f64 / 1e6
        ),
        None => println!("trace_decode: peak RSS unavailable (no /proc/self/status)"),
    }

    if !full {
        println!("trace_decode: smoke run (no --bench): cantools comparison skipped");
        return Ok(());
    }
    if !cantools_available() {
        println!("trace_decode: cantools not installed (pip install cantools): comparison skipped");
        return Ok(());
    }
    let sample_n = CANTOOLS_SAMPLE.min(frames);
    let sample = dir.path().join("sample.log");
    {
        let mut out = BufWriter::new(File::create(&sample)?);
        for line in BufReader::new(File::open(&log)?)
            .lines()
            .take(sample_n as usize)
        {
            writeln!(out, "{}", line?)?;
        }
        out.flush()?;
    }
    let dbc = Path::new(env!("CARGO_MANIFEST_DIR")).join("../gateway_core/excavator.dbc");
    let start = Instant::now();
    let status = Command::new("python3")
        .args(["-m", "cantools", "decode"])
        .arg(&dbc)
        .stdin(File::open(&sample)?)
        .stdout(File::create("/dev/null")?)
        .status()?;
    let their_secs = start.elapsed().as_secs_f64();
    if !status.success() {
        println!("trace_decode: cantools decode failed ({status}); comparison skipped");
        return Ok(());
    }
    let theirs = sample_n as f64 / their_secs;
    // The same sample through our decoder, for a like-for-like figure.
    let (_, our_sample_secs) = decode_file(&sample)?;
    println!(
        "trace_decode: cantools decode: {sample_n} frames (first {sample_n} of the {frames}-frame file) in {their_secs:.2} s = {theirs:.0} frames/s; scaled to the whole file: {:.0} s",
        frames as f64 / theirs
    );
    println!(
        "trace_decode: throughput ratio {:.0}x on the whole file ({:.0}x on the same {sample_n}-frame sample: {:.3} s); target > 20x",
        ours / theirs,
        their_secs / our_sample_secs,
        our_sample_secs
    );
    Ok(())
}
