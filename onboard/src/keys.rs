//! The operator's keys at the terminal of `excavator-ctl run`: space is the e-stop, and a key each
//! for pause, resume, reset and stop ([`KEYS`], shown once at the start).
//!
//! ```text
//! terminal --byte--> key reader thread: command_for --OperatorSender--> the operator queue
//!                                                         (the control socket's own; controller::io::operator)
//! ```
//!
//! A key is a request on the very path of the control socket ([`OperatorSender`]): the control loop
//! applies it before its next step and logs it with its reason (`terminal key ...`).
//!
//! The terminal is put in cbreak mode, not raw mode: keys arrive one at a time without echo, while
//! the terminal keeps its signals (Ctrl-C is still SIGINT, which stops `run` through its ordinary
//! shutdown) and its output processing (log lines and the progress line end their lines as
//! before). Reads time out every [`READ_TIMEOUT_DS`] tenths of a second, so the reader thread ends
//! when the [`KeyReader`] is dropped. The terminal's settings are restored when the reader is
//! dropped (normal end, error, Ctrl-C) and by a panic hook (a panic anywhere in the process); only a
//! `kill -9` leaves the terminal in cbreak mode (`stty sane` mends it).

use std::io::Read;
use std::os::fd::{AsFd, OwnedFd};
use std::sync::Arc;
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, Ordering};

use controller::io::operator::{Command, OperatorSender, Request};
use nix::sys::termios::{self, LocalFlags, SetArg, SpecialCharacterIndices, Termios};

/// The keys and their commands (letters in either case).
pub const KEYS: [(char, Command, &str); 5] = [
    (' ', Command::Estop, "space e-stop"),
    ('p', Command::Pause, "p pause"),
    ('c', Command::Resume, "c continue (resume)"),
    ('r', Command::Reset, "r reset the e-stop"),
    ('s', Command::Stop, "s stop after the current action"),
];

/// Tenths of a second a read waits for a key before the reader checks whether it should end.
pub const READ_TIMEOUT_DS: u8 = 1;

/// The command of a key, if it has one.
#[must_use]
pub fn command_for(byte: u8) -> Option<Command> {
    let key = char::from(byte).to_ascii_lowercase();
    KEYS.iter().find(|(k, _, _)| *k == key).map(|(_, c, _)| *c)
}

/// The keys as the one line shown at the start.
#[must_use]
pub fn help() -> String {
    let keys: Vec<&str> = KEYS.iter().map(|(_, _, h)| *h).collect();
    format!("operator keys: {} (Ctrl-C ends the run)", keys.join(" | "))
}

/// The terminal settings to put back (by the reader's drop, or by the panic hook).
static SAVED: Mutex<Option<(OwnedFd, Termios)>> = Mutex::new(None);

/// Restores the saved settings, if any (idempotent).
fn restore() {
    // A poisoned lock still holds the settings: restore them anyway.
    let mut saved = SAVED
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    if let Some((fd, t)) = saved.take()
        && let Err(e) = termios::tcsetattr(&fd, SetArg::TCSANOW, &t)
    {
        eprintln!("could not restore the terminal's settings ({e}): run `stty sane`");
    }
}

/// Installs (once) a panic hook that restores the terminal before the previous hook prints.
fn restore_on_panic() {
    static HOOK: std::sync::Once = std::sync::Once::new();
    HOOK.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            restore();
            previous(info);
        }));
    });
}

/// Reads the operator's keys from a terminal until dropped (module docs).
#[derive(Debug)]
pub struct KeyReader {
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl KeyReader {
    /// Puts `tty` in cbreak mode and reads its keys on a thread, sending each key's command through
    /// `sender` (awaited on `runtime`, the control loop's runtime).
    ///
    /// # Errors
    /// `tty` is not a terminal, or its settings cannot be read or set.
    pub fn start(
        tty: std::fs::File,
        sender: OperatorSender,
        runtime: tokio::runtime::Handle,
    ) -> std::io::Result<Self> {
        let original = termios::tcgetattr(&tty).map_err(std::io::Error::from)?;
        let mut cbreak = original.clone();
        cbreak.local_flags &= !(LocalFlags::ICANON | LocalFlags::ECHO);
        cbreak.control_chars[SpecialCharacterIndices::VMIN as usize] = 0;
        cbreak.control_chars[SpecialCharacterIndices::VTIME as usize] = READ_TIMEOUT_DS;
        {
            let mut saved = SAVED
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner);
            *saved = Some((tty.as_fd().try_clone_to_owned()?, original));
        }
        restore_on_panic();
        if let Err(e) = termios::tcsetattr(&tty, SetArg::TCSANOW, &cbreak) {
            restore();
            return Err(e.into());
        }
        let stop = Arc::new(AtomicBool::new(false));
        let thread = {
            let stop = Arc::clone(&stop);
            std::thread::Builder::new()
                .name("operator-keys".into())
                .spawn(move || read_keys(tty, &sender, &runtime, &stop))
        };
        match thread {
            Ok(t) => Ok(Self {
                stop,
                thread: Some(t),
            }),
            Err(e) => {
                restore();
                Err(e)
            }
        }
    }
}

impl Drop for KeyReader {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        // The read times out within READ_TIMEOUT_DS; a reader stuck in a request gives up after the
        // operator queue's reply timeout.
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
        restore();
    }
}

/// The reader thread: a key's command through `sender`, until `stop` or the terminal goes.
fn read_keys(
    mut tty: std::fs::File,
    sender: &OperatorSender,
    runtime: &tokio::runtime::Handle,
    stop: &AtomicBool,
) {
    let mut buf = [0_u8; 16];
    while !stop.load(Ordering::Relaxed) {
        let n = match tty.read(&mut buf) {
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => {
                tracing::warn!(error = %e, "operator keys: the terminal cannot be read: no keys");
                return;
            }
        };
        for &byte in &buf[..n] {
            let Some(cmd) = command_for(byte) else {
                continue;
            };
            let key = if byte == b' ' {
                "space".to_owned()
            } else {
                char::from(byte).to_string()
            };
            tracing::info!(surface = "terminal", ?cmd, key, "operator command");
            let reply = runtime.block_on(sender.send(Request {
                cmd,
                reason: Some(format!("terminal key {key}")),
            }));
            if !reply.ok {
                tracing::warn!(
                    error = reply.error.as_deref().unwrap_or("unknown"),
                    ?cmd,
                    "operator key not carried out"
                );
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn space_is_the_estop_and_each_command_has_one_key() {
        assert_eq!(command_for(b' '), Some(Command::Estop));
        assert_eq!(command_for(b'p'), Some(Command::Pause));
        assert_eq!(command_for(b'P'), Some(Command::Pause));
        assert_eq!(command_for(b'c'), Some(Command::Resume));
        assert_eq!(command_for(b'r'), Some(Command::Reset));
        assert_eq!(command_for(b's'), Some(Command::Stop));
        assert_eq!(command_for(b'\n'), None);
        assert_eq!(command_for(b'x'), None);
        assert_eq!(command_for(0xFF), None);
        let mut commands: Vec<String> = KEYS.iter().map(|(_, c, _)| format!("{c:?}")).collect();
        commands.sort();
        commands.dedup();
        assert_eq!(commands.len(), KEYS.len(), "one key per command");
        assert!(!commands.contains(&"Status".to_owned()));
        let line = help();
        assert!(
            line.contains("space e-stop") && line.contains("s stop"),
            "{line}"
        );
    }
}
