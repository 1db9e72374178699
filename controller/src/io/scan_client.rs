//! The range-scan client of the real-time loop (docs/scan-protocol.md): JSON lines over TCP.
//!
//! The session driver ([`crate::session::driver::SessionDriver`]) asks for scans: the work cycle's before each
//! dig, and the planner's workspace scan before it plans. Over the network its [`ScanSource`] is
//! [`ScanService`], a tokio task that owns the connection, so the control loop never waits on the
//! network. The task
//!
//! 1. connects (or reuses the connection; a failed exchange drops it and the next request reconnects),
//! 2. writes one [`ScanRequest`] as a JSON line and reads one reply line,
//! 3. parses the [`Scan`] (or the server's `{"error": ...}`) on tokio's blocking pool, because a
//!    default scan is about 10,000 points,
//!
//! all within one timeout, and hands back the raw scan or a [`ScanError`] naming the reason. The
//! driver fuses the scan into the planner's map (or bins it on the cycle's grid without a planner)
//! exactly as with the in-process simulator's scans; a failure is logged and Autodig falls back to
//! its plain angle rules (the cycle's own `scan_timeout_s` also covers a reply that never comes).

use std::time::Duration;

use firmware_bridge::scan::{Scan, ScanRequest};
use planner::terrain::TerrainGrid;
use tokio::io::{AsyncBufReadExt, AsyncWriteExt, BufReader};
use tokio::net::TcpStream;
use tokio::net::tcp::{OwnedReadHalf, OwnedWriteHalf};
use tokio::sync::mpsc;

use crate::session::driver::{BoxError, ScanSource};
use crate::step::cycle::ScanGrid;

/// Longest reply line accepted (a 2000 x 2000 scan would be far larger; the default is about 0.5 MB).
pub const MAX_REPLY_BYTES: usize = 64 * 1024 * 1024;

/// Why a scan did not produce a terrain map.
#[derive(Debug, thiserror::Error)]
pub enum ScanError {
    /// The TCP connection could not be opened.
    // The causes are in the messages and not also `source`s: printed with the chain (`{:#}`) they
    // would show again.
    #[error("cannot connect to the scan service at {addr}: {error}")]
    Connect {
        /// The address.
        addr: String,
        /// The socket error.
        error: std::io::Error,
    },
    /// Reading or writing failed.
    #[error("scan connection to {addr}: {error}")]
    Io {
        /// The address.
        addr: String,
        /// The socket error.
        error: std::io::Error,
    },
    /// The service closed the connection before replying.
    #[error("the scan service at {addr} closed the connection")]
    Closed {
        /// The address.
        addr: String,
    },
    /// No reply within the timeout.
    #[error("no scan from {addr} within {timeout_s} s")]
    Timeout {
        /// The address.
        addr: String,
        /// The timeout, s.
        timeout_s: f64,
    },
    /// The reply line is longer than [`MAX_REPLY_BYTES`].
    #[error("scan reply longer than {MAX_REPLY_BYTES} bytes")]
    TooLong,
    /// The service answered with an error object.
    #[error("the scan service refused the request: {0}")]
    Refused(String),
    /// The reply is not a scan.
    #[error("malformed scan reply: {0}")]
    Malformed(String),
    /// The points do not make a terrain map (none in the grid, gaps too large).
    #[error("terrain from the scan: {0}")]
    Terrain(String),
    /// The scan task is gone.
    #[error("the scan task stopped")]
    TaskGone,
}

/// Where and how to scan.
#[derive(Debug, Clone, PartialEq)]
pub struct ScanClientConfig {
    /// `HOST:PORT` of the scan service.
    pub addr: String,
    /// Connect, request, reply and terrain building must finish within this.
    pub timeout: Duration,
    /// The request sent (default: the protocol's default scan).
    pub request: ScanRequest,
    /// The grid the points are binned into.
    pub grid: ScanGrid,
}

/// A JSON-lines connection to the scan service; reconnects after any failure.
#[derive(Debug)]
pub struct ScanClient {
    config: ScanClientConfig,
    conn: Option<(BufReader<OwnedReadHalf>, OwnedWriteHalf)>,
    line: String,
}

impl ScanClient {
    /// A client for `config` (connects on the first request).
    pub fn new(config: ScanClientConfig) -> Self {
        Self {
            config,
            conn: None,
            line: String::new(),
        }
    }

    /// The configuration.
    pub fn config(&self) -> &ScanClientConfig {
        &self.config
    }

    /// One scan for `request`, within the configured timeout (the reply is parsed on tokio's
    /// blocking pool: a default scan is about 10,000 points, 0.5 MB of JSON).
    ///
    /// # Errors
    /// [`ScanError`] naming what failed; the connection is dropped and reopened next time.
    pub async fn scan(&mut self, request: &ScanRequest) -> Result<Scan, ScanError> {
        let timeout = self.config.timeout;
        let addr = self.config.addr.clone();
        let timed_out = || ScanError::Timeout {
            addr: addr.clone(),
            timeout_s: timeout.as_secs_f64(),
        };
        let result = match tokio::time::timeout(timeout, self.exchange(request)).await {
            Ok(Ok(line)) => {
                let task = tokio::task::spawn_blocking(move || scan_from_reply(&line));
                // The timeout covers the whole exchange; what is left of it bounds the parsing.
                match tokio::time::timeout(timeout, task).await {
                    Ok(Ok(r)) => r,
                    Ok(Err(e)) => Err(ScanError::Malformed(format!("parsing task failed: {e}"))),
                    Err(_) => Err(timed_out()),
                }
            }
            Ok(Err(e)) => Err(e),
            Err(_) => Err(timed_out()),
        };
        if result.is_err() {
            // A late reply to this request must not be taken as the answer to the next one.
            self.conn = None;
        }
        result
    }

    /// One scan with the configured request turned into a terrain map on the configured grid.
    ///
    /// # Errors
    /// As [`Self::scan`]; [`ScanError::Terrain`] when the points make no map.
    pub async fn terrain(&mut self) -> Result<TerrainGrid, ScanError> {
        let request = self.config.request;
        let scan = self.scan(&request).await?;
        self.config
            .grid
            .terrain(&scan.points)
            .map_err(|e| ScanError::Terrain(e.to_string()))
    }

    /// Sends the request and returns the reply line.
    async fn exchange(&mut self, request: &ScanRequest) -> Result<String, ScanError> {
        let addr = self.config.addr.clone();
        let io = |error| ScanError::Io {
            addr: addr.clone(),
            error,
        };
        if self.conn.is_none() {
            let stream = TcpStream::connect(&addr)
                .await
                .map_err(|error| ScanError::Connect {
                    addr: addr.clone(),
                    error,
                })?;
            // Small request lines: do not let Nagle hold them back.
            let _ = stream.set_nodelay(true);
            let (read, write) = stream.into_split();
            self.conn = Some((BufReader::new(read), write));
        }
        let Some((read, write)) = self.conn.as_mut() else {
            return Err(ScanError::Closed { addr });
        };
        let mut request = serde_json::to_string(request)
            .map_err(|e| ScanError::Malformed(format!("encoding the request: {e}")))?;
        request.push('\n');
        write.write_all(request.as_bytes()).await.map_err(io)?;
        write.flush().await.map_err(io)?;
        self.line.clear();
        let n = read.read_line(&mut self.line).await.map_err(io)?;
        if n == 0 {
            return Err(ScanError::Closed { addr });
        }
        if self.line.len() > MAX_REPLY_BYTES {
            return Err(ScanError::TooLong);
        }
        Ok(std::mem::take(&mut self.line))
    }
}

/// Parses one reply line: a [`Scan`] or `{"error": ...}`.
///
/// # Errors
/// [`ScanError::Refused`] or [`ScanError::Malformed`].
pub fn scan_from_reply(line: &str) -> Result<Scan, ScanError> {
    let value: serde_json::Value =
        serde_json::from_str(line.trim_end()).map_err(|e| ScanError::Malformed(e.to_string()))?;
    if let Some(error) = value.get("error") {
        let text = error
            .as_str()
            .map_or_else(|| error.to_string(), str::to_owned);
        return Err(ScanError::Refused(text));
    }
    serde_json::from_value(value).map_err(|e| ScanError::Malformed(e.to_string()))
}

/// The scan task seen from the control loop, the session driver's [`ScanSource`] over the network:
/// a request goes in without waiting, the raw scan is taken on a later step when it is there (the
/// session fuses it into its map exactly as the in-process demo does).
#[derive(Debug)]
pub struct ScanService {
    requests: mpsc::Sender<ScanRequest>,
    results: mpsc::Receiver<Result<Scan, ScanError>>,
    addr: String,
}

impl ScanService {
    /// Spawns the task owning `client` on the current tokio runtime.
    pub fn spawn(mut client: ScanClient) -> Self {
        let addr = client.config().addr.clone();
        let (requests, mut pending) = mpsc::channel::<ScanRequest>(1);
        let (done, results) = mpsc::channel(1);
        tokio::spawn(async move {
            while let Some(request) = pending.recv().await {
                let result = client.scan(&request).await;
                if done.send(result).await.is_err() {
                    break;
                }
            }
        });
        Self {
            requests,
            results,
            addr,
        }
    }

    /// The service address.
    pub fn addr(&self) -> &str {
        &self.addr
    }

    /// Asks for a scan. Returns false when one is still in flight (the request is then answered by
    /// that one) or the task is gone.
    pub fn send_request(&self, request: &ScanRequest) -> bool {
        self.requests.try_send(*request).is_ok()
    }

    /// The next result (cancel-safe).
    pub async fn next_result(&mut self) -> Result<Scan, ScanError> {
        self.results
            .recv()
            .await
            .unwrap_or(Err(ScanError::TaskGone))
    }
}

impl ScanSource for ScanService {
    fn request(&mut self, request: &ScanRequest) {
        if !self.send_request(request) {
            tracing::debug!("a range scan is already in flight");
        }
    }

    fn take(&mut self) -> Option<Result<Scan, BoxError>> {
        match self.results.try_recv() {
            Ok(r) => Some(r.map_err(|e| Box::new(e) as BoxError)),
            Err(mpsc::error::TryRecvError::Empty) => None,
            Err(mpsc::error::TryRecvError::Disconnected) => {
                Some(Err(Box::new(ScanError::TaskGone)))
            }
        }
    }
}

/// No scan service (`run` without `--scan-addr`): every request fails at once with the reason.
#[derive(Debug, Default)]
pub struct NoScans {
    failed: bool,
}

impl ScanSource for NoScans {
    fn request(&mut self, _request: &ScanRequest) {
        self.failed = true;
    }

    fn take(&mut self) -> Option<Result<Scan, BoxError>> {
        std::mem::take(&mut self.failed)
            .then(|| Err("no scan service is configured (--scan-addr)".into()))
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;
    use tokio::net::TcpListener;

    /// A flat patch of ground 6-8 m out, well inside the default grid.
    fn flat_scan_json() -> String {
        let mut points = Vec::new();
        for i in 0..20 {
            for j in 0..10 {
                points.push([6.0 + 0.1 * f64::from(i), -0.5 + 0.1 * f64::from(j), 1.5]);
            }
        }
        serde_json::json!({
            "time_s": 1.0,
            "sensor": {"x_m": 0.8, "y_m": 0.0, "z_m": 3.0, "heading_rad": 0.0},
            "points": points,
        })
        .to_string()
    }

    fn config(addr: String, timeout_ms: u64) -> ScanClientConfig {
        ScanClientConfig {
            addr,
            timeout: Duration::from_millis(timeout_ms),
            request: ScanRequest::default(),
            grid: ScanGrid::default(),
        }
    }

    /// Serves `replies` in order on one connection per accept; `None` = read the request, never reply.
    async fn server(replies: Vec<Option<String>>) -> String {
        let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
        let addr = listener.local_addr().unwrap().to_string();
        tokio::spawn(async move {
            let mut replies = replies.into_iter();
            while let Ok((stream, _)) = listener.accept().await {
                let (read, mut write) = stream.into_split();
                let mut lines = BufReader::new(read).lines();
                while let Ok(Some(line)) = lines.next_line().await {
                    serde_json::from_str::<ScanRequest>(&line).unwrap();
                    match replies.next() {
                        Some(Some(reply)) => {
                            write.write_all(reply.as_bytes()).await.unwrap();
                            write.write_all(b"\n").await.unwrap();
                        }
                        Some(None) => break,
                        None => return,
                    }
                }
            }
        });
        addr
    }

    #[tokio::test]
    async fn a_scan_becomes_a_terrain_map_and_the_connection_is_reused() {
        let addr = server(vec![Some(flat_scan_json()), Some(flat_scan_json())]).await;
        let mut client = ScanClient::new(config(addr, 5000));
        for _ in 0..2 {
            let grid = client.terrain().await.unwrap();
            let z = grid.height_at(6.95, 0.05).unwrap();
            assert!((z - 1.5).abs() < 1e-9, "{z}");
        }
    }

    #[tokio::test]
    async fn failures_name_their_reason() {
        // Nothing listens on a port we just closed.
        let closed = {
            let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
            l.local_addr().unwrap().to_string()
        };
        let e = ScanClient::new(config(closed, 2000))
            .terrain()
            .await
            .unwrap_err();
        assert!(matches!(e, ScanError::Connect { .. }), "{e}");
        // The cause once, as `run` prints the session's error with its chain: it was three times.
        let ended = crate::session::driver::DriverError::Scan(Box::new(e));
        let mut shown = ended.to_string();
        let mut cause = std::error::Error::source(&ended);
        while let Some(c) = cause {
            shown += &format!(": {c}");
            cause = c.source();
        }
        assert!(
            shown.starts_with("range scan: cannot connect to the scan service at "),
            "{shown}"
        );
        assert_eq!(shown.matches("refused").count(), 1, "{shown}");

        let addr = server(vec![
            Some(r#"{"error": "bad request: nope"}"#.to_owned()),
            Some("not json".to_owned()),
            Some(r#"{"time_s": 1, "sensor": {"x_m": 0, "y_m": 0, "z_m": 3, "heading_rad": 0}, "points": []}"#.to_owned()),
            None,
        ])
        .await;
        let mut client = ScanClient::new(config(addr, 300));
        let e = client.terrain().await.unwrap_err();
        assert!(
            matches!(e, ScanError::Refused(ref m) if m.contains("nope")),
            "{e}"
        );
        let e = client.terrain().await.unwrap_err();
        assert!(matches!(e, ScanError::Malformed(_)), "{e}");
        let e = client.terrain().await.unwrap_err();
        assert!(matches!(e, ScanError::Terrain(_)), "{e}");
        // The server reads the request and never answers.
        let e = client.terrain().await.unwrap_err();
        assert!(
            matches!(e, ScanError::Timeout { .. } | ScanError::Closed { .. }),
            "{e}"
        );
    }

    #[tokio::test]
    async fn the_service_answers_without_blocking_the_caller() {
        let addr = server(vec![Some(flat_scan_json())]).await;
        let mut service = ScanService::spawn(ScanClient::new(config(addr, 5000)));
        assert!(service.send_request(&ScanRequest::default()));
        let scan = service.next_result().await.unwrap();
        assert_eq!(scan.points.len(), 200);
    }
}
