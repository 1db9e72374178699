//! `run`'s log in its session folder: `run.log`, the log lines of the run in plain text (no colour
//! escapes), each stamped with the session clock so it lines up with the session's records.
//!
//! The binary adds [`layer`] to its subscriber beside the console's; it writes only while a session
//! log is open ([`open`], for the run's lifetime). The stamp is session seconds: the run's start
//! time (0, or the session time a resumed session had reached) plus the monotonic time since the
//! control loop started ([`SessionLog::start_clock`]) times the time scale, as the loop's own clock;
//! lines written before the loop starts carry the start time.

use std::io::Write as _;
use std::path::Path;
use std::sync::Mutex;
use std::time::Instant;

use tracing_subscriber::Layer;
use tracing_subscriber::fmt::format::Writer;
use tracing_subscriber::fmt::time::FormatTime;
use tracing_subscriber::layer::Filter;

/// The session log's file name in a session folder.
pub const FILE_NAME: &str = "run.log";

/// The open log: its file and its clock.
#[derive(Debug)]
struct Sink {
    file: std::fs::File,
    base_s: f64,
    scale: f64,
    loop_start: Option<Instant>,
}

impl Sink {
    fn now_s(&self) -> f64 {
        self.base_s
            + self
                .loop_start
                .map_or(0.0, |t| t.elapsed().as_secs_f64() * self.scale)
    }
}

static SINK: Mutex<Option<Sink>> = Mutex::new(None);

fn sink() -> std::sync::MutexGuard<'static, Option<Sink>> {
    // A panic while writing a line leaves a usable file.
    SINK.lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// The open session log; closed when dropped.
#[derive(Debug)]
#[must_use = "the log closes when this is dropped"]
pub struct SessionLog(());

/// Opens (appends to) the session log at `path`; its stamps start at `base_s` session seconds and
/// run `scale` times as fast as the monotonic clock.
///
/// # Errors
/// The file cannot be opened.
pub fn open(path: &Path, base_s: f64, scale: f64) -> std::io::Result<SessionLog> {
    let file = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(path)?;
    *sink() = Some(Sink {
        file,
        base_s,
        scale,
        loop_start: None,
    });
    Ok(SessionLog(()))
}

impl SessionLog {
    /// The control loop starts now: the session clock runs from here.
    pub fn start_clock(&self) {
        if let Some(s) = sink().as_mut() {
            s.loop_start = Some(Instant::now());
        }
    }
}

impl Drop for SessionLog {
    fn drop(&mut self) {
        if let Some(mut s) = sink().take() {
            let _ = s.file.flush();
        }
    }
}

/// Stamps a line with the session clock, `s` seconds with millisecond resolution.
#[derive(Debug, Clone, Copy, Default)]
pub struct SessionTime;

impl FormatTime for SessionTime {
    fn format_time(&self, w: &mut Writer<'_>) -> std::fmt::Result {
        match sink().as_ref() {
            Some(s) => write!(w, "{:.3}s", s.now_s()),
            None => write!(w, "-"),
        }
    }
}

/// Writes a formatted line to the open session log (nothing when none is open).
#[derive(Debug, Clone, Copy, Default)]
pub struct SessionLogWriter;

impl std::io::Write for SessionLogWriter {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        match sink().as_mut() {
            Some(s) => s.file.write_all(buf).map(|()| buf.len()),
            None => Ok(buf.len()),
        }
    }

    fn flush(&mut self) -> std::io::Result<()> {
        match sink().as_mut() {
            Some(s) => s.file.flush(),
            None => Ok(()),
        }
    }
}

/// Passes events only while a session log is open (nothing is formatted otherwise).
#[derive(Debug, Clone, Copy, Default)]
struct WhileOpen;

impl<S> Filter<S> for WhileOpen {
    fn enabled(
        &self,
        _meta: &tracing::Metadata<'_>,
        _cx: &tracing_subscriber::layer::Context<'_, S>,
    ) -> bool {
        sink().is_some()
    }
}

/// The session log's layer: plain text, session-clock stamps, written only while a log is open.
pub fn layer<S>() -> impl Layer<S>
where
    S: tracing::Subscriber + for<'a> tracing_subscriber::registry::LookupSpan<'a>,
{
    tracing_subscriber::fmt::layer()
        .with_ansi(false)
        .with_timer(SessionTime)
        .with_writer(|| SessionLogWriter)
        .with_filter(WhileOpen)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use tracing_subscriber::layer::SubscriberExt as _;

    #[test]
    fn operator_commands_reach_the_session_log_with_reason_and_session_time() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(super::FILE_NAME);
        let subscriber = tracing_subscriber::registry().with(super::layer());
        let mut node = controller::step::node::ControllerNode::new(
            &planner::machine::MachineConfig::default_machine().unwrap(),
            planner::autodig::AutodigMaps::builtin().unwrap(),
            controller::ControllerConfig::default(),
        )
        .unwrap();
        tracing::subscriber::with_default(subscriber, || {
            tracing::info!("before the log is open");
            // A resumed session at 42 s, at twice real time.
            let log = super::open(&path, 42.0, 2.0).unwrap();
            log.start_clock();
            controller::io::operator::apply(
                &mut node,
                controller::io::operator::Command::Estop,
                "terminal key space",
                42.0,
            );
            controller::io::operator::apply(
                &mut node,
                controller::io::operator::Command::Stop,
                "end of shift",
                42.0,
            );
            drop(log);
            tracing::info!("after the log is closed");
        });
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(!text.contains('\u{1b}'), "escape sequences in {text:?}");
        assert!(!text.contains("before the log") && !text.contains("after the log"));
        let lines: Vec<&str> = text.lines().filter(|l| l.contains("operator")).collect();
        assert_eq!(lines.len(), 2, "{text}");
        assert!(lines[0].contains("operator e-stop") && lines[0].contains("terminal key space"));
        assert!(lines[1].contains("operator stop") && lines[1].contains("end of shift"));
        for l in lines {
            let stamp: f64 = l
                .split_whitespace()
                .next()
                .and_then(|s| s.strip_suffix('s'))
                .unwrap()
                .parse()
                .unwrap();
            assert!((42.0..43.0).contains(&stamp), "{l}");
        }
    }
}
