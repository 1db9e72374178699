//! A vcan session for the end-to-end tests: `candump -L` recording the bus, `excavator-sim` with its
//! state log and scan socket, `excavator-ctl run` with the HIL plan, each a separate process on the
//! real SocketCAN interface, both provisioned with the same fresh machine key (`--key-file`), so the
//! control path is authenticated as on a machine. Everything is killed when the session drops (also on a failed assertion);
//! the logs stay in the artefact directory and their tails are printed on failure.

#![allow(dead_code, clippy::unwrap_used)]

use std::path::PathBuf;
use std::time::{Duration, Instant};

use firmware_bridge::messages::{ControllerStatus, Message};
use firmware_bridge::{CONTROLLER_ADDRESS, CanFrame as BridgeFrame, CanId};
use hil_tests::env;
use hil_tests::process::Proc;
use socketcan::{CanFrame, CanSocket, EmbeddedFrame, ExtendedId, Id, Socket, StandardId};

/// Generous waits: the VM runs under TCG on a shared machine.
pub const START_TIMEOUT: Duration = Duration::from_secs(60);

/// The processes of one session.
pub struct Session {
    /// Artefact directory.
    pub dir: PathBuf,
    /// The interface.
    pub iface: String,
    /// `candump -L` of the whole session.
    pub candump: Proc,
    /// The simulator.
    pub sim: Proc,
    /// The controller (taken when it is killed).
    pub ctl: Option<Proc>,
    /// Where candump writes.
    pub candump_log: PathBuf,
    /// The simulator's state log.
    pub state_log: PathBuf,
    /// The controller's own trace.
    pub ctl_trace: PathBuf,
    /// Raw socket of the test.
    pub socket: CanSocket,
    /// The machine key both ends hold (in `key_dir`).
    pub key_file: PathBuf,
    /// The controller's `run` arguments (for a restart).
    ctl_args: Vec<String>,
    /// The scan socket's address.
    scan_addr: String,
    /// Controllers started so far (names their logs).
    ctl_starts: u32,
    /// Holds the key file: a private temporary directory (the artefact directory may be a shared
    /// folder without Unix permissions).
    _key_dir: tempfile::TempDir,
}

/// Wall-clock time, UNIX s (the clock of candump's timestamps).
pub fn unix_now_s() -> f64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64())
}

/// A free loopback TCP port.
fn free_port() -> u16 {
    let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    l.local_addr().unwrap().port()
}

/// Opens a raw CAN socket with a short read timeout.
pub fn open_socket(iface: &str) -> CanSocket {
    let socket = CanSocket::open(iface)
        .unwrap_or_else(|e| panic!("cannot open a SocketCAN socket on {iface}: {e}"));
    socket.set_read_timeout(Duration::from_millis(100)).unwrap();
    socket
}

/// A frame of the project's type as a socketcan frame.
pub fn to_socketcan(frame: &BridgeFrame) -> CanFrame {
    let id: Id = match frame.id() {
        CanId::Extended(raw) => Id::Extended(ExtendedId::new(raw).unwrap()),
        CanId::Standard(raw) => Id::Standard(StandardId::new(raw).unwrap()),
    };
    CanFrame::new(id, frame.data()).unwrap()
}

/// A socketcan data frame as the project's type (None for other kinds).
pub fn from_socketcan(frame: &CanFrame) -> Option<BridgeFrame> {
    if !matches!(frame, CanFrame::Data(_)) {
        return None;
    }
    let id = match frame.id() {
        Id::Extended(id) => CanId::Extended(id.as_raw()),
        Id::Standard(id) => CanId::Standard(id.as_raw()),
    };
    BridgeFrame::new_data(id, frame.data()).ok()
}

/// Starts `candump -L iface` into `log` and waits until it records (a marker frame sent on `socket`
/// shows in its log).
///
/// # Panics
/// When candump exits or records nothing within [`START_TIMEOUT`].
pub fn start_candump(iface: &str, socket: &CanSocket, log: &std::path::Path) -> Proc {
    let candump_bin = env::tool("candump", "can-utils");
    let mut candump = Proc::spawn("candump", &candump_bin, &["-L", iface], log);
    let marker = CanFrame::new(StandardId::new(0x7FF).unwrap(), &[0xC0, 0xDE]).unwrap();
    let deadline = Instant::now() + START_TIMEOUT;
    loop {
        socket.write_frame(&marker).unwrap();
        std::thread::sleep(Duration::from_millis(100));
        if candump.log().contains("7FF#C0DE") {
            return candump;
        }
        candump.assert_running();
        assert!(
            Instant::now() < deadline,
            "candump -L {iface} recorded nothing"
        );
    }
}

impl Session {
    /// Starts candump, the simulator and the controller (with `ctl_args` added to `run`).
    pub fn start(test: &str, ctl_args: &[&str]) -> Self {
        Self::start_with(test, &[], ctl_args)
    }

    /// As [`Session::start`], with `sim_args` added to `excavator-sim`.
    pub fn start_with(test: &str, sim_args: &[&str], ctl_args: &[&str]) -> Self {
        let mut s = Self::start_simulator(test, sim_args, ctl_args);
        s.start_controller();
        s.sim.assert_running();
        s
    }

    /// Starts candump and the simulator (with `sim_args`), no controller yet; `ctl_args` are
    /// kept for [`Session::start_controller`].
    pub fn start_simulator(test: &str, sim_args: &[&str], ctl_args: &[&str]) -> Self {
        let iface = env::vcan_iface();
        let sim_bin = env::binary("excavator-sim");
        let dir = env::artifacts(test);
        let socket = open_socket(&iface);

        // candump first, so nothing of the session is missed.
        let candump_log = dir.join("candump.log");
        let candump = start_candump(&iface, &socket, &candump_log);

        let state_log = dir.join("state.jsonl");
        let scan_addr = format!("127.0.0.1:{}", free_port());
        let key_dir = tempfile::tempdir().unwrap();
        let key_file = hil_tests::plan::write_key_file(key_dir.path());
        let mut args = vec![
            "--iface",
            &iface,
            "--seed",
            "1",
            "--state-log",
            state_log.to_str().unwrap(),
            "--scan-socket",
            &scan_addr,
            "--key-file",
            key_file.to_str().unwrap(),
        ];
        args.extend_from_slice(sim_args);
        let mut sim = Proc::spawn("excavator-sim", &sim_bin, &args, &dir.join("sim.log"));
        assert!(
            sim.wait_for_log("scan socket listening", START_TIMEOUT),
            "excavator-sim did not start: {}",
            sim.log_tail(30)
        );

        let ctl_trace = dir.join("ctl-trace.log");
        Self {
            dir,
            iface,
            candump,
            sim,
            ctl: None,
            candump_log,
            state_log,
            ctl_trace,
            socket,
            key_file,
            ctl_args: ctl_args.iter().map(|a| (*a).to_owned()).collect(),
            scan_addr,
            ctl_starts: 0,
            _key_dir: key_dir,
        }
    }

    /// Starts `excavator-ctl run` with the HIL plan, the session's key and the session's extra
    /// arguments. The first one writes `ctl-trace.log` and `ctl.log`; a restart `ctl-trace-N.log` and
    /// `ctl-N.log`.
    ///
    /// # Panics
    /// When a controller is running.
    pub fn start_controller(&mut self) {
        self.spawn_controller(true);
    }

    /// As [`Session::start_controller`] without `--key-file`: a controller with no key provisioned.
    pub fn start_controller_without_key(&mut self) {
        self.spawn_controller(false);
    }

    fn spawn_controller(&mut self, keyed: bool) {
        assert!(self.ctl.is_none(), "a controller is running");
        let ctl_bin = env::binary("excavator-ctl");
        let plan = hil_tests::plan::write_plan(&self.dir);
        let (trace, log) = match self.ctl_starts {
            0 => (self.ctl_trace.clone(), self.dir.join("ctl.log")),
            n => (
                self.dir.join(format!("ctl-trace-{n}.log")),
                self.dir.join(format!("ctl-{n}.log")),
            ),
        };
        self.ctl_starts += 1;
        let mut args: Vec<&str> = vec![
            "run",
            "--iface",
            &self.iface,
            "--config",
            plan.to_str().unwrap(),
            "--trace",
            trace.to_str().unwrap(),
            "--scan-addr",
            &self.scan_addr,
        ];
        if keyed {
            args.extend(["--key-file", self.key_file.to_str().unwrap()]);
        }
        args.extend(self.ctl_args.iter().map(String::as_str));
        self.ctl = Some(Proc::spawn("excavator-ctl", &ctl_bin, &args, &log));
    }

    /// The controller.
    pub fn ctl(&mut self) -> &mut Proc {
        self.ctl.as_mut().expect("the controller was killed")
    }

    /// Reads the bus until a `ControllerStatus` satisfies `pred`; returns it and its arrival time.
    pub fn wait_status(
        &mut self,
        timeout: Duration,
        mut pred: impl FnMut(&ControllerStatus) -> bool,
    ) -> Option<ControllerStatus> {
        let deadline = Instant::now() + timeout;
        while Instant::now() < deadline {
            let Ok(frame) = self.socket.read_frame() else {
                continue;
            };
            let Some(frame) = from_socketcan(&frame) else {
                continue;
            };
            if let Ok(d) = Message::decode(&frame)
                && d.id.source_address() == CONTROLLER_ADDRESS
                && let Message::ControllerStatus(s) = d.message
                && pred(&s)
            {
                return Some(s);
            }
        }
        None
    }

    /// Stops the controller with SIGTERM (neutral, disarm) and waits for it.
    pub fn stop_controller(&mut self) -> Option<std::process::ExitStatus> {
        let ctl = self.ctl.as_mut()?;
        ctl.signal("TERM");
        ctl.wait_timeout(Duration::from_secs(30))
    }

    /// Stops the simulator with SIGINT (it flushes the state log) and candump (SIGINT), and waits.
    pub fn stop_sim_and_candump(&mut self) {
        self.sim.signal("INT");
        assert!(
            self.sim.wait_timeout(Duration::from_secs(30)).is_some(),
            "excavator-sim did not stop on SIGINT"
        );
        // Let candump write the last frames before it goes.
        std::thread::sleep(Duration::from_millis(300));
        self.candump.signal("INT");
        let _ = self.candump.wait_timeout(Duration::from_secs(10));
    }

    /// The logs' tails, for failure messages.
    pub fn logs(&self) -> String {
        let ctl = self.ctl.as_ref().map_or(String::new(), |c| c.log_tail(25));
        format!(
            "--- excavator-ctl log (tail) ---\n{ctl}\n--- excavator-sim log (tail) ---\n{}\n\
             (artefacts in {})",
            self.sim.log_tail(15),
            self.dir.display()
        )
    }
}
