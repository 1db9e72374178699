//! The live view of a session: a Foxglove WebSocket server (the `foxglove` crate) that streams what
//! the controller believes while a session runs, for Foxglove (or a compatible viewer) to show the
//! machine over its terrain map with the plots beside it. `excavator-ctl demo --live [ADDR]` serves it
//! (docs/live-view.md).
//!
//! # Layout
//!
//! - [`LiveArgs`]: the command-line options (`--live [ADDR]`, `--pace FACTOR`, `--live-queue N`).
//! - [`stream`]: [`LiveStream`], a `controller::session::driver::SessionObserver`. On the control loop it only
//!   copies what the publisher needs of each step (plain values: the estimate's angles, pose,
//!   pressures and tip, the status, the command) into a preallocated single-producer queue (dropped
//!   and counted when full; no allocation, lock or system call) and paces virtual time when asked; a
//!   publisher thread turns the queue into Foxglove messages ([`trace_tools::view`], the schemas
//!   `trace convert --to mcap` writes too) on the server's channels.
//! - [`subprotocol`]: the accept shim on the `--live` port in front of the crate's server (on
//!   loopback), so that clients asking for `foxglove.websocket.v1` (older Foxglove Studio,
//!   Lichtblick) are served as well as those asking for `foxglove.sdk.v1`.
//! - [`access`]: who may use the page and the WebSocket: `Host` and `Origin` against an allow-list
//!   (loopback by default, `--live-allow-host`), and the page's per-session command token.
//! - [`page`]: the operator page (static assets in `live/page/`), served over HTTP on the port after
//!   the WebSocket's: the publisher keeps its state, the page follows it as server-sent events and
//!   sends the operator commands of the session's control path (`SessionObserver::operator_control`).
//!
//! # Data flow
//!
//! ```text
//! control loop --SessionObserver::after_step--> Update (step record by value, rare events)
//!     --rtrb ring buffer (push; full: dropped, counted)--> publisher thread --view::*--> channels
//!     --foxglove WebSocket server (its own runtime, per-client backlog)--subprotocol shim--> Foxglove
//!                   \--page state (at most 10 Hz)--> HTTP server (same runtime) --SSE--> the page
//! the page --POST /command--> controller::io::operator::OperatorSender --> the control loop's port
//! ```

pub mod access;
pub mod page;
pub mod stream;
pub mod subprotocol;

pub use stream::{LiveStats, LiveStream};

/// The address `--live` binds without a value: loopback only.
pub const DEFAULT_ADDR: &str = "127.0.0.1:8765";

/// Updates the queue holds by default (about 10 s of control steps at 100 Hz).
pub const DEFAULT_QUEUE: usize = 1024;

/// Errors of the live view.
#[derive(Debug, thiserror::Error)]
pub enum LiveError {
    /// `--live` is not `HOST:PORT`.
    #[error("--live {0:?}: expected HOST:PORT (e.g. 127.0.0.1:8765)")]
    Address(String),
    /// `--pace` is not a positive finite factor.
    #[error("--pace {0}: expected a positive factor of real time (1 = real time)")]
    Pace(f64),
    /// `--live-queue` is zero.
    #[error("--live-queue 0: the queue needs room for at least one update")]
    Queue,
    /// The server could not start (address in use, say).
    #[error("starting the Foxglove WebSocket server on {addr}: {source}")]
    Server {
        /// The address.
        addr: String,
        /// Why.
        #[source]
        source: foxglove::FoxgloveError,
    },
    /// The WebSocket's address could not be bound (in use, say).
    #[error("starting the Foxglove WebSocket server on {addr}: {source}")]
    Bind {
        /// The address.
        addr: String,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// The operator page's port (the WebSocket's + 1) does not exist.
    #[error("--live port {0}: the operator page needs the next port; pick a lower one")]
    PagePort(u16),
    /// The operator page's server could not bind.
    #[error("starting the operator page on {addr}: {source}")]
    Page {
        /// The address.
        addr: String,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// The server's runtime or the publisher thread could not start.
    #[error("starting the live view: {0}")]
    Io(#[from] std::io::Error),
    /// The machine's kinematics could not be built.
    #[error("machine kinematics: {0}")]
    Kinematics(#[from] planner::kinematics::KinematicsError),
}

/// The live view's command-line options.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct LiveArgs {
    /// Serve the session live to Foxglove on a WebSocket at ADDR (HOST:PORT; without a value
    /// 127.0.0.1:8765, port 0 picks a free port). Open Foxglove, "Open connection", ws://ADDR.
    #[arg(long, value_name = "ADDR", num_args = 0..=1, default_missing_value = DEFAULT_ADDR)]
    pub live: Option<String>,
    /// Pace the session at FACTOR times real time so a person can watch (1 = real time); without
    /// it the session runs as fast as it can and the stream drops what the client cannot take.
    #[arg(long, value_name = "FACTOR", requires = "live")]
    pub pace: Option<f64>,
    /// Updates queued for the stream before it drops (and counts) them.
    #[arg(long, value_name = "N", default_value_t = DEFAULT_QUEUE, requires = "live")]
    pub live_queue: usize,
    /// Also allow HOST (a name or address the operator's browser uses for this machine) in the
    /// `Host` and `Origin` of the page and the WebSocket; loopback (localhost, 127.0.0.1, `[::1]`)
    /// and the `--live` address are always allowed. Repeat for more.
    #[arg(long, value_name = "HOST", requires = "live")]
    pub live_allow_host: Vec<String>,
    /// Also accept ORIGIN (exactly, e.g. `https://app.foxglove.dev`) on the WebSocket, whose
    /// stream is read only; never on the page's commands. Repeat for more.
    #[arg(long, value_name = "ORIGIN", requires = "live")]
    pub live_allow_origin: Vec<String>,
}

/// A parsed `--live` address.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LiveAddr {
    /// Host name or address.
    pub host: String,
    /// Port (0: any free port).
    pub port: u16,
}

impl LiveAddr {
    /// Parses `HOST:PORT` (`[::1]:8765` for IPv6).
    ///
    /// # Errors
    /// [`LiveError::Address`] when it is not.
    pub fn parse(text: &str) -> Result<Self, LiveError> {
        let bad = || LiveError::Address(text.to_owned());
        let (host, port) = text.rsplit_once(':').ok_or_else(bad)?;
        let host = host.trim_start_matches('[').trim_end_matches(']');
        if host.is_empty() {
            return Err(bad());
        }
        let port = port.parse::<u16>().map_err(|_| bad())?;
        Ok(Self {
            host: host.to_owned(),
            port,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn addresses_parse_or_name_the_problem() {
        assert_eq!(
            LiveAddr::parse("127.0.0.1:8765").unwrap(),
            LiveAddr {
                host: "127.0.0.1".into(),
                port: 8765
            }
        );
        assert_eq!(LiveAddr::parse("[::1]:0").unwrap().host, "::1");
        for bad in ["8765", ":8765", "localhost:", "localhost:99999", "a:b"] {
            let e = LiveAddr::parse(bad).unwrap_err().to_string();
            assert!(e.contains(bad), "{e}");
        }
    }
}
