//! Operator control of a running controller: a Unix socket speaking one JSON object per line
//! (docs/controller.md, "Operator control"), `excavator-ctl ctl --socket PATH <command>`.
//!
//! ```text
//! client --line--> connection task: parse (bounded line, malformed -> error reply, counted)
//!                      --try_send--> bounded queue --try_recv, each tick--> OperatorPort::serve
//! terminal key --> key reader (lab::keys) --^                             -> apply(node): reply
//! ```
//!
//! The socket and the keys of `run`'s terminal go through the one queue ([`OperatorSender`]), so a
//! key does exactly what the same command on the socket does.
//!
//! The control loop never waits for the socket: [`OperatorPort::serve`] takes at most
//! [`MAX_REQUESTS_PER_TICK`] queued requests per control step without blocking and applies them
//! before the step, so an e-stop sends neutral valves and `Disarm` within one control period of its
//! arrival. Everything else (accepting, reading, parsing, answering) runs in tasks beside the loop,
//! with a bounded number of connections, a bounded line length and an idle timeout.
//!
//! Who may connect: the socket file is owner-only (0600, set and verified after the bind whatever
//! the umask), and each connection's peer credentials (`SO_PEERCRED`) must name the socket's owner,
//! root or the configured group ([`SocketAccess`]); anyone else is refused before a byte is read.
//! When all [`MAX_CONNECTIONS`] slots are busy (say, idle connections held open), a new connection
//! still gets one request read within [`OVERFLOW_TIMEOUT`], of which only `estop` is carried out, so
//! the stop can never be locked out; at most [`MAX_OVERFLOW`] such connections at once.
//!
//! The commands: `estop` (neutral valves and `Disarm` at once, latched until `reset`), `reset`
//! (clears the e-stop; motion resumes through the arming handshake), `pause` (the current action
//! runs to its end, then nothing new starts: the cycle holds neutral, disarmed), `resume` (goes on:
//! the cycle re-arms for the next action; after a fault that stopped motion, which waits for the
//! operator, it acknowledges the stop, except an e-stop or a latching fault, which take `reset`),
//! `stop` (the session ends cleanly after the current
//! action: return home, neutral, disarm), `status`. Each is logged with the operator's reason;
//! e-stop and pause show in `ControllerStatus` (`Faulted` with fault code 5, `Paused`).

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use serde::{Deserialize, Serialize};
use tokio::io::{AsyncBufReadExt as _, AsyncReadExt as _, AsyncWriteExt as _, BufReader};
use tokio::net::{UnixListener, UnixStream};
use tokio::sync::{Semaphore, mpsc, oneshot};

use crate::step::node::ControllerNode;

/// Longest request line, bytes (a request is under 100).
pub const MAX_LINE_BYTES: usize = 1024;
/// Connections served at once; more are answered with an error and closed.
pub const MAX_CONNECTIONS: usize = 4;
/// Requests queued for the control loop; more are answered `busy`.
pub const QUEUE: usize = 8;
/// Requests the control loop takes per step.
pub const MAX_REQUESTS_PER_TICK: usize = 4;
/// A connection without a request for this long is closed.
pub const IDLE_TIMEOUT: Duration = Duration::from_secs(60);
/// Connections beyond [`MAX_CONNECTIONS`] read at once for their one request (an `estop` only).
pub const MAX_OVERFLOW: usize = 16;
/// How long a connection beyond [`MAX_CONNECTIONS`] has to send its request.
pub const OVERFLOW_TIMEOUT: Duration = Duration::from_millis(500);
/// The socket file's mode: owner read and write only.
pub const SOCKET_MODE: u32 = 0o600;
/// The socket file's mode with a configured group ([`SocketAccess::group_gid`], the file's group):
/// owner and group read and write (connecting needs write permission on the file).
pub const GROUP_SOCKET_MODE: u32 = 0o660;
/// A request the control loop has not answered in this long gets an error (the loop is gone).
pub const REPLY_TIMEOUT: Duration = Duration::from_secs(2);

/// An operator command.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Command {
    /// State, faults, current action, dig count.
    Status,
    /// The current action runs to its end, then nothing new starts.
    Pause,
    /// Go on after a pause (re-arms for the next action), or after a fault stop that waits for the
    /// operator (not an e-stop or a latching fault: those take `reset`).
    Resume,
    /// Emergency stop: neutral valves and `Disarm` at once, latched until `reset`.
    Estop,
    /// Clear an e-stop, a latching fault or any fault stop (motion resumes through the arming
    /// handshake).
    Reset,
    /// End the session cleanly after the current action.
    Stop,
}

impl std::str::FromStr for Command {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        serde_json::from_value(serde_json::Value::String(s.to_owned())).map_err(|_| {
            format!("unknown command {s:?}: one of status, pause, resume, estop, reset, stop")
        })
    }
}

/// A request line: `{"cmd": "estop", "reason": "person in the swing area"}`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Request {
    /// The command.
    pub cmd: Command,
    /// Why (logged with the command).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
}

/// The controller's state as `status` reports it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Status {
    /// The work-cycle phase.
    pub phase: String,
    /// The safety state.
    pub safety: String,
    /// The active fault, if any.
    pub fault: Option<String>,
    /// The most recent fault.
    pub last_fault: Option<String>,
    /// The current action.
    pub action: Option<String>,
    /// Its index in the plan.
    pub action_index: usize,
    /// Digs and cleanups completed.
    pub digs: u32,
    /// Paused by the operator.
    pub paused: bool,
    /// The operator asked for a stop after the current action.
    pub stopping: bool,
    /// Malformed requests answered with an error since the start.
    pub malformed_requests: u64,
}

/// A reply line: `{"ok": true}` (with `status` for `status`), or `{"ok": false, "error": "..."}`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Response {
    /// Whether the request was carried out.
    pub ok: bool,
    /// Why not.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    /// The state (every command answers with the state after it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub status: Option<Status>,
}

impl Response {
    fn error(message: impl Into<String>) -> Self {
        Self {
            ok: false,
            error: Some(message.into()),
            status: None,
        }
    }
}

/// Carries out `cmd` on `node` at session time `now_s`, logs it with `reason`; returns the state
/// after it.
pub fn apply(node: &mut ControllerNode, cmd: Command, reason: &str, now_s: f64) -> Status {
    match cmd {
        Command::Status => {}
        Command::Estop => {
            tracing::warn!(reason, "operator e-stop: valves neutral, disarm");
            node.request_estop(now_s);
        }
        Command::Reset => {
            tracing::warn!(reason, "operator reset");
            node.reset();
        }
        Command::Pause => {
            tracing::warn!(
                reason,
                "operator pause: no new action after the current one"
            );
            node.set_paused(true);
        }
        Command::Resume => {
            tracing::warn!(reason, "operator resume");
            node.resume();
        }
        Command::Stop => {
            tracing::warn!(
                reason,
                "operator stop: the session ends after the current action"
            );
            node.request_stop();
        }
    }
    status_of(node, 0)
}

fn status_of(node: &ControllerNode, malformed_requests: u64) -> Status {
    let s = node.status();
    Status {
        phase: format!("{:?}", s.phase),
        safety: format!("{:?}", s.safety),
        fault: node.fault().map(|f| f.to_string()),
        last_fault: node.last_fault().map(|f| f.to_string()),
        action: node.action().map(|a| format!("{a:?}")),
        action_index: s.action_index,
        digs: s.dig_index,
        paused: node.cycle().paused(),
        stopping: node.cycle().stop_requested(),
        malformed_requests,
    }
}

/// A queued request and where its reply goes.
type Queued = (Request, oneshot::Sender<Response>);

/// The control loop's end of the operator's commands (module docs): the socket's and the terminal
/// keys' requests ([`OperatorSender`]) meet in its one queue.
#[derive(Debug)]
pub struct OperatorPort {
    rx: mpsc::Receiver<Queued>,
    tx: mpsc::Sender<Queued>,
    malformed: Arc<AtomicU64>,
}

impl Default for OperatorPort {
    fn default() -> Self {
        Self::new()
    }
}

impl OperatorPort {
    /// A port with an empty queue and no socket yet ([`Self::listen`]).
    pub fn new() -> Self {
        let (tx, rx) = mpsc::channel(QUEUE);
        Self {
            rx,
            tx,
            malformed: Arc::new(AtomicU64::new(0)),
        }
    }

    /// A handle that queues requests for this port (the terminal keys' path; the socket's
    /// connections use the same).
    pub fn sender(&self) -> OperatorSender {
        OperatorSender {
            tx: self.tx.clone(),
        }
    }

    /// Applies the queued requests (at most [`MAX_REQUESTS_PER_TICK`], never waiting) to `node`
    /// at `now_s` and answers them. Returns the commands applied.
    pub fn serve(&mut self, node: &mut ControllerNode, now_s: f64) -> usize {
        let mut n = 0;
        while n < MAX_REQUESTS_PER_TICK {
            let Ok((req, reply)) = self.rx.try_recv() else {
                break;
            };
            let mut status = apply(
                node,
                req.cmd,
                req.reason.as_deref().unwrap_or("no reason given"),
                now_s,
            );
            status.malformed_requests = self.malformed.load(Ordering::Relaxed);
            // The client may have gone; the command stands.
            let _ = reply.send(Response {
                ok: true,
                error: None,
                status: Some(status),
            });
            n += 1;
        }
        n
    }

    /// Malformed requests answered with an error so far.
    pub fn malformed(&self) -> u64 {
        self.malformed.load(Ordering::Relaxed)
    }

    /// Serves the socket at `path` into this port: a listener task that runs until the port is
    /// dropped. Removes a stale socket file (one nobody listens on); refuses one a running
    /// controller serves.
    ///
    /// # Errors
    /// The path is in use by a running controller, or cannot be bound.
    pub fn listen(&self, path: &Path) -> std::io::Result<tokio::task::JoinHandle<()>> {
        self.listen_with(path, SocketAccess::default())
    }

    /// [`Self::listen`] letting the members of `access`'s group connect too: the socket file then
    /// belongs to that group with [`GROUP_SOCKET_MODE`].
    ///
    /// # Errors
    /// As [`Self::listen`], or the socket's group or mode cannot be set ([`SOCKET_MODE`], or
    /// [`GROUP_SOCKET_MODE`] with a group: the process must be a member of it).
    pub fn listen_with(
        &self,
        path: &Path,
        access: SocketAccess,
    ) -> std::io::Result<tokio::task::JoinHandle<()>> {
        use std::os::unix::fs::{MetadataExt as _, PermissionsExt as _};
        if path.exists() {
            if std::os::unix::net::UnixStream::connect(path).is_ok() {
                return Err(std::io::Error::new(
                    std::io::ErrorKind::AddrInUse,
                    format!("{}: another controller serves it", path.display()),
                ));
            }
            std::fs::remove_file(path)?;
        }
        let listener = UnixListener::bind(path)?;
        // The bind created the file under the umask: set the group and the mode and check they
        // took. Until then a connection of another user is still refused by its credentials.
        let mode = match access.group_gid {
            Some(gid) => {
                std::os::unix::fs::chown(path, None, Some(gid)).map_err(|e| {
                    std::io::Error::new(
                        e.kind(),
                        format!(
                            "{}: cannot give the socket to group {gid} (is the controller a \
                             member?): {e}",
                            path.display()
                        ),
                    )
                })?;
                GROUP_SOCKET_MODE
            }
            None => SOCKET_MODE,
        };
        std::fs::set_permissions(path, std::fs::Permissions::from_mode(mode))?;
        let meta = std::fs::metadata(path)?;
        if meta.mode() & 0o777 != mode || access.group_gid.is_some_and(|g| g != meta.gid()) {
            return Err(std::io::Error::new(
                std::io::ErrorKind::PermissionDenied,
                format!(
                    "{}: mode {:o} group {}, not {mode:o}{}",
                    path.display(),
                    meta.mode() & 0o777,
                    meta.gid(),
                    access
                        .group_gid
                        .map_or(String::new(), |g| format!(" group {g}"))
                ),
            ));
        }
        // The file is this process's: its owner is our effective uid.
        let owner_uid = meta.uid();
        Ok(tokio::spawn(accept(
            listener,
            self.tx.clone(),
            Arc::clone(&self.malformed),
            Peers { owner_uid, access },
        )))
    }
}

/// Who may connect to the control socket besides its owner and root.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SocketAccess {
    /// A group whose members (by the peer's primary gid) may connect too.
    pub group_gid: Option<u32>,
}

/// The allowed peers of one socket.
#[derive(Debug, Clone, Copy)]
struct Peers {
    owner_uid: u32,
    access: SocketAccess,
}

/// Whether a peer of `peer_uid` and `peer_gid` may use a socket owned by `owner_uid`: the owner,
/// root, or a member of the configured group.
#[must_use]
pub fn peer_allowed(peer_uid: u32, peer_gid: u32, owner_uid: u32, access: SocketAccess) -> bool {
    peer_uid == owner_uid || peer_uid == 0 || access.group_gid == Some(peer_gid)
}

/// Queues requests for an [`OperatorPort`] from outside the control loop (cheap to clone).
#[derive(Debug, Clone)]
pub struct OperatorSender {
    tx: mpsc::Sender<Queued>,
}

impl OperatorSender {
    /// Queues `req` and waits (here, not in the loop) for the loop's reply; `busy` when the queue
    /// is full, an error when the loop does not answer within [`REPLY_TIMEOUT`].
    pub async fn send(&self, req: Request) -> Response {
        forward(&self.tx, req).await
    }
}

/// A port with the socket at `path` ([`OperatorPort::new`], [`OperatorPort::listen`]).
///
/// # Errors
/// As [`OperatorPort::listen`].
pub fn listen(path: &Path) -> std::io::Result<(OperatorPort, tokio::task::JoinHandle<()>)> {
    let port = OperatorPort::new();
    let task = port.listen(path)?;
    Ok((port, task))
}

/// Accepts connections of allowed peers, at most [`MAX_CONNECTIONS`] at once (and
/// [`MAX_OVERFLOW`] for an e-stop beyond), until the [`OperatorPort`] is dropped.
async fn accept(
    listener: UnixListener,
    tx: mpsc::Sender<Queued>,
    malformed: Arc<AtomicU64>,
    peers: Peers,
) {
    let slots = Arc::new(Semaphore::new(MAX_CONNECTIONS));
    let overflow = Arc::new(Semaphore::new(MAX_OVERFLOW));
    loop {
        // The loop's port gone (the controller stopped, or was dropped mid-run): stop listening.
        // The port holds a sender too, so `closed` waits for its receiver.
        let accepted = tokio::select! {
            () = tx.closed() => return,
            a = listener.accept() => a,
        };
        let Ok((mut stream, _)) = accepted else {
            continue;
        };
        let allowed = match stream.peer_cred() {
            Ok(c) => {
                let ok = peer_allowed(c.uid(), c.gid(), peers.owner_uid, peers.access);
                if !ok {
                    tracing::warn!(
                        uid = c.uid(),
                        gid = c.gid(),
                        "operator socket: peer not allowed: connection refused"
                    );
                }
                ok
            }
            Err(e) => {
                tracing::warn!(error = %e, "operator socket: no peer credentials: connection refused");
                false
            }
        };
        if !allowed {
            let _ = write_reply(&mut stream, &Response::error("not allowed")).await;
            continue;
        }
        let tx = tx.clone();
        let malformed = Arc::clone(&malformed);
        if let Ok(permit) = Arc::clone(&slots).try_acquire_owned() {
            tokio::spawn(async move {
                connection(stream, tx, malformed).await;
                drop(permit);
            });
        } else if let Ok(permit) = Arc::clone(&overflow).try_acquire_owned() {
            tokio::spawn(async move {
                overflow_connection(stream, &tx).await;
                drop(permit);
            });
        } else {
            let _ = write_reply(&mut stream, &Response::error("too many connections")).await;
        }
    }
}

/// A connection beyond [`MAX_CONNECTIONS`]: one request, read within [`OVERFLOW_TIMEOUT`]; an
/// `estop` is carried out, anything else is answered `too many connections`.
async fn overflow_connection(stream: UnixStream, tx: &mpsc::Sender<Queued>) {
    let (read, mut write) = stream.into_split();
    let mut reader = BufReader::new(read);
    let mut line = Vec::with_capacity(MAX_LINE_BYTES);
    let limit = u64::try_from(MAX_LINE_BYTES + 1).unwrap_or(u64::MAX);
    let read = tokio::time::timeout(
        OVERFLOW_TIMEOUT,
        (&mut reader).take(limit).read_until(b'\n', &mut line),
    )
    .await;
    let request = match read {
        Ok(Ok(n)) if n > 0 && line.len() <= MAX_LINE_BYTES => {
            serde_json::from_slice::<Request>(&line).ok()
        }
        _ => None,
    };
    let reply = match request {
        Some(req) if req.cmd == Command::Estop => {
            tracing::info!(surface = "socket", cmd = ?req.cmd, "operator command (beyond the connection limit)");
            forward(tx, req).await
        }
        _ => Response::error(format!(
            "too many connections ({MAX_CONNECTIONS} busy): only estop is taken"
        )),
    };
    let _ = write_reply(&mut write, &reply).await;
}

async fn write_reply(
    stream: &mut (impl tokio::io::AsyncWrite + Unpin),
    r: &Response,
) -> std::io::Result<()> {
    let mut line = serde_json::to_vec(r).unwrap_or_else(|_| b"{\"ok\":false}".to_vec());
    line.push(b'\n');
    stream.write_all(&line).await
}

/// One client: a request per line, a reply per request.
async fn connection(stream: UnixStream, tx: mpsc::Sender<Queued>, malformed: Arc<AtomicU64>) {
    let (read, mut write) = stream.into_split();
    // One byte more than the limit tells an overlong line from one at the limit.
    let mut reader = BufReader::new(read);
    let mut line = Vec::with_capacity(MAX_LINE_BYTES);
    loop {
        line.clear();
        let limit = u64::try_from(MAX_LINE_BYTES + 1).unwrap_or(u64::MAX);
        let read = tokio::time::timeout(
            IDLE_TIMEOUT,
            (&mut reader).take(limit).read_until(b'\n', &mut line),
        )
        .await;
        let n = match read {
            Ok(Ok(n)) => n,
            _ => return, // idle, or the client went
        };
        if n == 0 {
            return;
        }
        if line.len() > MAX_LINE_BYTES {
            malformed.fetch_add(1, Ordering::Relaxed);
            tracing::warn!("operator socket: request line too long: connection closed");
            let _ = write_reply(
                &mut write,
                &Response::error(format!("request longer than {MAX_LINE_BYTES} bytes")),
            )
            .await;
            return;
        }
        let reply = match serde_json::from_slice::<Request>(&line) {
            Ok(req) => {
                tracing::info!(surface = "socket", cmd = ?req.cmd, "operator command");
                forward(&tx, req).await
            }
            Err(e) => {
                let count = malformed.fetch_add(1, Ordering::Relaxed) + 1;
                tracing::warn!(error = %e, count, "operator socket: malformed request");
                Response::error(format!(
                    "malformed request ({e}); expected {{\"cmd\": \
                     \"status|pause|resume|estop|reset|stop\", \"reason\": \"...\"}}"
                ))
            }
        };
        if write_reply(&mut write, &reply).await.is_err() {
            return;
        }
    }
}

/// Hands `req` to the control loop and waits (here, not in the loop) for its reply.
async fn forward(tx: &mpsc::Sender<Queued>, req: Request) -> Response {
    let (reply_tx, reply_rx) = oneshot::channel();
    if tx.try_send((req, reply_tx)).is_err() {
        return Response::error("busy: the controller's request queue is full, try again");
    }
    match tokio::time::timeout(REPLY_TIMEOUT, reply_rx).await {
        Ok(Ok(r)) => r,
        _ => Response::error("the control loop did not answer (stopped?)"),
    }
}

/// Sends `request` to the controller at `path` and returns its reply (the client of
/// `excavator-ctl ctl`).
///
/// # Errors
/// The socket cannot be reached, or the reply is not a response.
pub async fn request(path: &Path, request: &Request) -> std::io::Result<Response> {
    let mut stream = UnixStream::connect(path)
        .await
        .map_err(|e| std::io::Error::new(e.kind(), format!("{}: {e}", path.display())))?;
    let mut line = serde_json::to_vec(request).map_err(std::io::Error::other)?;
    line.push(b'\n');
    stream.write_all(&line).await?;
    let mut reader = BufReader::new(stream);
    let mut reply = String::new();
    tokio::time::timeout(REPLY_TIMEOUT * 2, reader.read_line(&mut reply))
        .await
        .map_err(|_| std::io::Error::new(std::io::ErrorKind::TimedOut, "no reply"))??;
    serde_json::from_str(&reply).map_err(std::io::Error::other)
}

/// The socket's default path in a session folder.
#[must_use]
pub fn default_path(session_dir: &Path) -> PathBuf {
    session_dir.join("control.sock")
}

#[cfg(test)]
mod tests {
    use super::*;

    const OWNER: u32 = 1000;
    const OTHER: u32 = 1001;
    const GROUP: u32 = 2000;

    #[test]
    fn only_the_owner_root_or_the_configured_group_may_connect() {
        let none = SocketAccess::default();
        let group = SocketAccess {
            group_gid: Some(GROUP),
        };
        assert!(peer_allowed(OWNER, OWNER, OWNER, none));
        assert!(peer_allowed(0, 0, OWNER, none));
        assert!(!peer_allowed(OTHER, OTHER, OWNER, none));
        assert!(!peer_allowed(OTHER, GROUP, OWNER, none));
        assert!(peer_allowed(OTHER, GROUP, OWNER, group));
        assert!(!peer_allowed(OTHER, OTHER, OWNER, group));
    }
}
