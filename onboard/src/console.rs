//! The console of `demo` and `run`: one progress line on stderr (digs done, current action and
//! phase, faults) that log lines do not break, drawn only when stderr is a terminal.
//!
//! The progress lines live in one [`MultiProgress`] ([`progress`]); the log goes through
//! [`ConsoleWriter`], which clears the lines, writes the log line and draws them again. When stderr is
//! not a terminal (a pipe, a file, a journal) nothing is drawn and the log lines pass through as they
//! are, without escape sequences (the binary turns the log's colours off there too).

use std::sync::OnceLock;

use controller::step::node::ControllerNode;
use indicatif::{MultiProgress, ProgressBar, ProgressStyle};

/// The process's progress lines (drawn on stderr, hidden when it is not a terminal).
pub fn progress() -> &'static MultiProgress {
    static PROGRESS: OnceLock<MultiProgress> = OnceLock::new();
    PROGRESS.get_or_init(MultiProgress::new)
}

/// A `std::io::Write` for the log (`tracing_subscriber::fmt().with_writer(|| ConsoleWriter)`): each
/// write goes to stderr with the progress lines cleared around it.
#[derive(Debug, Clone, Copy, Default)]
pub struct ConsoleWriter;

impl std::io::Write for ConsoleWriter {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        progress().suspend(|| std::io::stderr().lock().write_all(buf))?;
        Ok(buf.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        std::io::stderr().flush()
    }
}

/// A session's progress line: `digs` the dig count of the session (`None`: open-ended). `None` when
/// `quiet` or when stderr is not a terminal.
pub fn session_bar(digs: Option<u32>, quiet: bool) -> Option<ProgressBar> {
    use std::io::IsTerminal as _;
    if quiet || !std::io::stderr().is_terminal() {
        return None;
    }
    let (bar, template) = match digs {
        Some(n) => (
            ProgressBar::new(u64::from(n)),
            "{spinner} {elapsed_precise} [{bar:25}] {pos}/{len} digs | {msg}",
        ),
        None => (
            ProgressBar::no_length(),
            "{spinner} {elapsed_precise} {pos} digs | {msg}",
        ),
    };
    if let Ok(style) = ProgressStyle::with_template(template) {
        bar.set_style(style.progress_chars("=> "));
    }
    let bar = progress().add(bar);
    bar.enable_steady_tick(std::time::Duration::from_millis(200));
    Some(bar)
}

/// The progress line's message: the current action and phase, track backs, and the faults so far
/// with the active one.
pub fn status_message(node: &ControllerNode, backups: usize) -> String {
    let action = node
        .action()
        .map_or_else(|| "no action".to_owned(), |a| format!("{:?}", a.kind()));
    let phase = node.status().phase;
    let faults = node.safety().fault_count();
    let active = node
        .fault()
        .map_or(String::new(), |f| format!(" (now: {f})"));
    format!("{action} {phase:?} | {backups} track backs | {faults} faults{active}")
}

/// Updates `bar` (if any) with the session's dig count and [`status_message`].
pub fn update(bar: Option<&ProgressBar>, digs_done: usize, node: &ControllerNode, backups: usize) {
    if let Some(bar) = bar {
        bar.set_position(digs_done as u64);
        bar.set_message(status_message(node, backups));
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use std::io::Write as _;

    #[test]
    fn without_a_terminal_no_line_is_drawn_and_the_log_passes_through() {
        // The test harness captures stderr: not a terminal.
        assert!(super::session_bar(Some(3), false).is_none());
        assert!(super::session_bar(None, true).is_none());
        let mut w = super::ConsoleWriter;
        assert_eq!(w.write(b"a log line\n").unwrap(), 11);
    }

    #[test]
    fn the_message_names_action_phase_and_faults() {
        let node = controller::step::node::ControllerNode::new(
            &planner::machine::MachineConfig::default_machine().unwrap(),
            planner::autodig::AutodigMaps::builtin().unwrap(),
            controller::ControllerConfig::default(),
        )
        .unwrap();
        let m = super::status_message(&node, 2);
        assert!(m.contains("2 track backs") && m.contains("0 faults"), "{m}");
    }
}
