//! Streaming: decoding, statistics and conversion hold per-id (or per-signal) state only, so the
//! peak memory does not grow with the length of the trace. The trace is produced on the fly by a
//! `Read` adapter (never held in memory), and the peak RSS (`VmHWM`) is compared before and after.
//! One test in its own executable, so no other test allocates meanwhile.

#![allow(clippy::unwrap_used)] // helpers outside #[test] functions fail loudly on purpose

use std::io::{self, Read};

use trace_tools::convert::{self, Rows};
use trace_tools::decode::{self, DecodeFilter};
use trace_tools::stats::{self, StatsOptions};
use trace_tools::synth::{SynthConfig, SyntheticTrace};

/// `candump -L` text of a synthetic trace, generated as it is read.
struct LiveTrace {
    frames: SyntheticTrace,
    line: Vec<u8>,
    pos: usize,
}

impl LiveTrace {
    fn new(frames: u64) -> Self {
        Self {
            frames: SyntheticTrace::new(SynthConfig {
                frames,
                ..SynthConfig::default()
            }),
            line: Vec::new(),
            pos: 0,
        }
    }
}

impl Read for LiveTrace {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        if self.pos == self.line.len() {
            let Some((t, frame)) = self.frames.next() else {
                return Ok(0);
            };
            self.line = firmware_bridge::trace::format_line(t, "vcan0", &frame, None).into_bytes();
            self.line.push(b'\n');
            self.pos = 0;
        }
        let n = buf.len().min(self.line.len() - self.pos);
        buf[..n].copy_from_slice(&self.line[self.pos..self.pos + n]);
        self.pos += n;
        Ok(n)
    }
}

fn vm_hwm_kib() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    status
        .lines()
        .find(|l| l.starts_with("VmHWM:"))?
        .split_whitespace()
        .nth(1)?
        .parse()
        .ok()
}

#[test]
fn memory_does_not_grow_with_the_trace() {
    // Warm up (lazy tables, allocator arenas) on a short trace.
    let short = io::BufReader::new(LiveTrace::new(20_000));
    decode::decode_stream(
        short,
        DecodeFilter::default(),
        true,
        &mut io::sink(),
        &mut io::sink(),
        false,
    )
    .unwrap();
    let Some(before) = vm_hwm_kib() else {
        println!("skip: no /proc/self/status");
        return;
    };
    // 200,000 frames: about 11 MB of candump text, 168 s of traffic.
    const FRAMES: u64 = 200_000;
    let summary = decode::decode_stream(
        io::BufReader::new(LiveTrace::new(FRAMES)),
        DecodeFilter::default(),
        true,
        &mut io::sink(),
        &mut io::sink(),
        false,
    )
    .unwrap();
    assert_eq!(summary.lines_out, FRAMES);
    let report = stats::collect(
        io::BufReader::new(LiveTrace::new(FRAMES)),
        StatsOptions::default(),
        true,
        &mut io::sink(),
    )
    .unwrap();
    assert_eq!(report.frames, FRAMES);
    let csv = convert::to_csv(
        io::BufReader::new(LiveTrace::new(FRAMES)),
        &mut io::sink(),
        Rows::Frame,
        0.01,
        &[],
        true,
        &mut io::sink(),
    )
    .unwrap();
    assert_eq!(csv.written, FRAMES);
    let after = vm_hwm_kib().unwrap_or(before);
    println!("VmHWM before {before} KiB, after {after} KiB");
    // Holding the trace would take tens of MB; the streams need well under 8 MiB more.
    assert!(
        after.saturating_sub(before) < 8 * 1024,
        "{before} -> {after} KiB"
    );
}
