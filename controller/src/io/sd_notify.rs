//! systemd's service notification (`sd_notify(3)`) fed by the control loop: `READY=1` at the first
//! tick and `WATCHDOG=1` every half of the unit's `WatchdogSec=`, both from the loop's tick, so a loop
//! that stalls stops feeding the watchdog and systemd ends the process (the unit is `Type=notify`,
//! docs/deployment.md). The gateway's heartbeat watchdog has neutralised the valves long before.
//!
//! The protocol is one datagram of `KEY=VALUE` lines to the Unix socket named by `$NOTIFY_SOCKET`
//! (a path, or `@name` in the abstract namespace); `$WATCHDOG_USEC` is the watchdog's timeout and
//! `$WATCHDOG_PID`, when set, the process it is meant for. Without `$NOTIFY_SOCKET` (not under
//! systemd, or not `Type=notify`) the notifier does nothing. A send never blocks the loop: the socket
//! is non-blocking and a failed send is logged once and dropped (the next tick tries again).

use std::os::unix::net::{SocketAddr, UnixDatagram};
use std::time::{Duration, Instant};

/// The notifier of one control loop.
#[derive(Debug)]
pub struct LoopNotifier {
    target: Option<(UnixDatagram, SocketAddr)>,
    /// Half the watchdog timeout: the longest time between two `WATCHDOG=1`.
    ping_every: Option<Duration>,
    last_ping: Option<Instant>,
    ready_sent: bool,
    send_failed: bool,
}

impl LoopNotifier {
    /// The notifier systemd's environment asks for (`$NOTIFY_SOCKET`, `$WATCHDOG_USEC`,
    /// `$WATCHDOG_PID`); one that does nothing when there is no notification socket or it cannot be
    /// used (logged).
    pub fn from_env() -> Self {
        let var = |k| std::env::var_os(k).and_then(|v| v.into_string().ok());
        let watchdog_for_us = var("WATCHDOG_PID")
            .and_then(|p| p.parse::<u32>().ok())
            .is_none_or(|pid| pid == std::process::id());
        let watchdog = var("WATCHDOG_USEC")
            .and_then(|v| v.parse::<u64>().ok())
            .filter(|&us| us > 0 && watchdog_for_us)
            .map(Duration::from_micros);
        match var("NOTIFY_SOCKET") {
            Some(socket) => Self::new(&socket, watchdog).unwrap_or_else(|e| {
                tracing::warn!("NOTIFY_SOCKET {socket}: {e}: no systemd notification");
                Self::inactive()
            }),
            None => Self::inactive(),
        }
    }

    /// A notifier sending to `socket` (a path, or `@name` for the abstract namespace), with a
    /// watchdog timeout of `watchdog` if any.
    ///
    /// # Errors
    /// The socket address is invalid or no datagram socket can be made.
    pub fn new(socket: &str, watchdog: Option<Duration>) -> std::io::Result<Self> {
        let addr = match socket.strip_prefix('@') {
            Some(name) => {
                use std::os::linux::net::SocketAddrExt as _;
                SocketAddr::from_abstract_name(name.as_bytes())?
            }
            None => SocketAddr::from_pathname(socket)?,
        };
        let sock = UnixDatagram::unbound()?;
        sock.set_nonblocking(true)?;
        Ok(Self {
            target: Some((sock, addr)),
            ping_every: watchdog.map(|w| w / 2),
            last_ping: None,
            ready_sent: false,
            send_failed: false,
        })
    }

    /// A notifier that sends nothing.
    pub fn inactive() -> Self {
        Self {
            target: None,
            ping_every: None,
            last_ping: None,
            ready_sent: false,
            send_failed: false,
        }
    }

    /// One tick of the control loop at `now`: `READY=1` the first time, `WATCHDOG=1` when half the
    /// watchdog timeout has passed since the last one.
    pub fn on_tick(&mut self, now: Instant) {
        let Some((sock, addr)) = &self.target else {
            return;
        };
        let ping = self.ping_every.is_some_and(|every| {
            self.last_ping
                .is_none_or(|last| now.saturating_duration_since(last) >= every)
        });
        let message = match (self.ready_sent, ping) {
            (false, true) => "READY=1\nWATCHDOG=1\n",
            (false, false) => "READY=1\n",
            (true, true) => "WATCHDOG=1\n",
            (true, false) => return,
        };
        match sock.send_to_addr(message.as_bytes(), addr) {
            Ok(_) => {
                self.ready_sent = true;
                if ping {
                    self.last_ping = Some(now);
                }
            }
            Err(e) if !self.send_failed => {
                self.send_failed = true;
                tracing::warn!("systemd notification: {e} (retried every tick, logged once)");
            }
            Err(_) => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The unit's `WatchdogSec=` in the tests.
    const WATCHDOG: Duration = Duration::from_secs(2);
    /// The control period.
    const TICK: Duration = Duration::from_millis(10);

    fn listener() -> (tempfile::TempDir, UnixDatagram, String) {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("notify");
        let sock = UnixDatagram::bind(&path).unwrap();
        sock.set_nonblocking(true).unwrap();
        (dir, sock, path.to_str().unwrap().to_owned())
    }

    fn received(sock: &UnixDatagram) -> Vec<String> {
        let mut out = Vec::new();
        let mut buf = [0u8; 256];
        while let Ok(n) = sock.recv(&mut buf) {
            out.push(String::from_utf8_lossy(&buf[..n]).into_owned());
        }
        out
    }

    #[test]
    fn ready_at_the_first_tick_then_a_watchdog_ping_every_half_timeout() {
        let (_dir, sock, path) = listener();
        let mut n = LoopNotifier::new(&path, Some(WATCHDOG)).unwrap();
        let t0 = Instant::now();
        // 3 s of ticks at 100 Hz.
        let mut pings_at_ms = Vec::new();
        for k in 0..300u32 {
            n.on_tick(t0 + TICK * k);
            for m in received(&sock) {
                if m.contains("WATCHDOG=1") {
                    pings_at_ms.push(k * 10);
                }
                if k == 0 {
                    assert_eq!(m, "READY=1\nWATCHDOG=1\n");
                } else {
                    assert_eq!(m, "WATCHDOG=1\n");
                }
            }
        }
        assert_eq!(pings_at_ms, [0, 1000, 2000]);
    }

    #[test]
    fn a_stalled_loop_sends_nothing_and_without_a_watchdog_only_ready() {
        let (_dir, sock, path) = listener();
        let mut n = LoopNotifier::new(&path, None).unwrap();
        let t0 = Instant::now();
        n.on_tick(t0);
        assert_eq!(received(&sock), ["READY=1\n"]);
        n.on_tick(t0 + Duration::from_secs(10));
        assert!(received(&sock).is_empty());
        let mut n = LoopNotifier::new(&path, Some(WATCHDOG)).unwrap();
        n.on_tick(t0);
        assert_eq!(received(&sock).len(), 1);
        // No tick for longer than the timeout: nothing was sent in between.
        assert!(received(&sock).is_empty());
        n.on_tick(t0 + Duration::from_millis(999));
        assert!(received(&sock).is_empty());
    }

    #[test]
    fn abstract_socket_names_are_accepted_and_a_missing_socket_does_not_fail_the_tick() {
        assert!(LoopNotifier::new("@excavator-test-notify", None).is_ok());
        let dir = tempfile::tempdir().unwrap();
        let gone = dir.path().join("absent");
        let mut n = LoopNotifier::new(gone.to_str().unwrap(), Some(WATCHDOG)).unwrap();
        n.on_tick(Instant::now());
        n.on_tick(Instant::now());
        assert!(n.send_failed && !n.ready_sent);
        LoopNotifier::inactive().on_tick(Instant::now());
    }
}
