//! Child processes for the end-to-end tests: killed when the test ends (pass or fail), stderr kept in a
//! file the failure message can show.

use std::fs::File;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

/// A running child process, killed (SIGKILL) and reaped on drop.
#[derive(Debug)]
pub struct Proc {
    name: String,
    child: Option<Child>,
    log: PathBuf,
}

impl Proc {
    /// Starts `program args` with stdout and stderr into `log`.
    ///
    /// # Panics
    /// When the log cannot be created or the program cannot start.
    pub fn spawn(name: &str, program: &Path, args: &[&str], log: &Path) -> Self {
        Self::spawn_with(name, Command::new(program).args(args), log)
    }

    /// Starts `command` with stdout and stderr into `log`.
    ///
    /// # Panics
    /// When the log cannot be created or the program cannot start.
    pub fn spawn_with(name: &str, command: &mut Command, log: &Path) -> Self {
        let out =
            File::create(log).unwrap_or_else(|e| panic!("cannot create {}: {e}", log.display()));
        let err = out
            .try_clone()
            .unwrap_or_else(|e| panic!("cannot clone {}: {e}", log.display()));
        let child = command
            .stdin(Stdio::null())
            .stdout(out)
            .stderr(err)
            .spawn()
            .unwrap_or_else(|e| panic!("cannot start {name} ({command:?}): {e}"));
        Self {
            name: name.to_owned(),
            child: Some(child),
            log: log.to_owned(),
        }
    }

    /// The process id.
    pub fn id(&self) -> u32 {
        self.child.as_ref().map_or(0, Child::id)
    }

    /// The log so far, without ANSI colour sequences (tracing colours its fields).
    pub fn log(&self) -> String {
        strip_ansi(&std::fs::read_to_string(&self.log).unwrap_or_default())
    }

    /// The last `n` lines of the log, for failure messages.
    pub fn log_tail(&self, n: usize) -> String {
        let log = self.log();
        let lines: Vec<&str> = log.lines().collect();
        lines[lines.len().saturating_sub(n)..].join("\n")
    }

    /// Panics with the log tail if the process has exited.
    ///
    /// # Panics
    /// When it exited.
    pub fn assert_running(&mut self) {
        if let Some(child) = self.child.as_mut()
            && let Ok(Some(status)) = child.try_wait()
        {
            panic!(
                "{} exited early ({status}); its log:\n{}",
                self.name,
                self.log_tail(40)
            );
        }
    }

    /// Sends a signal by number (`kill -s`), e.g. 15 (SIGTERM) or 2 (SIGINT).
    ///
    /// # Panics
    /// When `kill` cannot run.
    pub fn signal(&self, signal: &str) {
        let status = Command::new("kill")
            .args(["-s", signal, &self.id().to_string()])
            .status()
            .unwrap_or_else(|e| panic!("cannot run kill: {e}"));
        assert!(status.success(), "kill -s {signal} {} failed", self.id());
    }

    /// SIGKILL now, and reap.
    pub fn kill(&mut self) {
        if let Some(child) = self.child.as_mut() {
            let _ = child.kill();
            let _ = child.wait();
        }
    }

    /// Waits up to `timeout` for the exit; `None` if it is still running.
    pub fn wait_timeout(&mut self, timeout: Duration) -> Option<ExitStatus> {
        let deadline = Instant::now() + timeout;
        let child = self.child.as_mut()?;
        loop {
            match child.try_wait() {
                Ok(Some(status)) => return Some(status),
                Ok(None) if Instant::now() < deadline => {
                    std::thread::sleep(Duration::from_millis(50))
                }
                _ => return None,
            }
        }
    }

    /// Waits until the log contains `needle`, up to `timeout`; false on timeout or exit.
    pub fn wait_for_log(&mut self, needle: &str, timeout: Duration) -> bool {
        let deadline = Instant::now() + timeout;
        while Instant::now() < deadline {
            if self.log().contains(needle) {
                return true;
            }
            if let Some(child) = self.child.as_mut()
                && matches!(child.try_wait(), Ok(Some(_)))
            {
                return self.log().contains(needle);
            }
            std::thread::sleep(Duration::from_millis(100));
        }
        false
    }
}

impl Drop for Proc {
    fn drop(&mut self) {
        self.kill();
    }
}

/// Removes ANSI escape sequences (`ESC [ ... letter`).
pub fn strip_ansi(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut chars = text.chars();
    while let Some(c) = chars.next() {
        if c == '\u{1b}' {
            for d in chars.by_ref() {
                if d.is_ascii_alphabetic() {
                    break;
                }
            }
        } else {
            out.push(c);
        }
    }
    out
}

/// One request on `excavator-ctl run`'s control socket (docs/controller.md, "Operator control"),
/// asserted to succeed; the reply.
///
/// # Panics
/// When the socket cannot be reached, the reply is not JSON or not `ok`.
pub fn operator(socket: &Path, cmd: &str) -> serde_json::Value {
    use std::io::{BufRead as _, Write as _};
    let mut stream = std::os::unix::net::UnixStream::connect(socket)
        .unwrap_or_else(|e| panic!("cannot connect to {}: {e}", socket.display()));
    stream
        .set_read_timeout(Some(Duration::from_secs(10)))
        .unwrap_or_else(|e| panic!("{e}"));
    writeln!(stream, r#"{{"cmd": "{cmd}", "reason": "HIL test"}}"#)
        .unwrap_or_else(|e| panic!("{cmd}: {e}"));
    let mut line = String::new();
    std::io::BufReader::new(stream)
        .read_line(&mut line)
        .unwrap_or_else(|e| panic!("{cmd}: {e}"));
    let reply: serde_json::Value =
        serde_json::from_str(&line).unwrap_or_else(|e| panic!("reply to {cmd} {line:?}: {e}"));
    assert_eq!(reply["ok"], true, "{cmd}: {reply}");
    reply
}
