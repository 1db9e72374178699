//! The operator page: a small web page (static assets in `live/page/`, compiled into the binary, no
//! build step) served over HTTP beside the Foxglove WebSocket, showing the machine's state and
//! offering the operator commands of the session's control path.
//!
//! ```text
//! publisher thread --PageFeed (the page's view of the stream, JSON at most 10 Hz)--> watch channel
//!     --GET /events (server-sent events: `state`, `terrain` when it changed)--> the page
//! the page --POST /command {"cmd": "estop"}--> OperatorSender --bounded queue--> control loop
//! ```
//!
//! Nothing from the network is trusted: every request names an allowed `Host` ([`Access`]: loopback
//! by default, so a DNS-rebinding page is refused); a command is a JSON object of one known field
//! (`cmd`, one of the operator commands) in at most [`MAX_COMMAND_BYTES`], sent as
//! `application/json` (so a page of another origin cannot send it without a CORS preflight, which
//! is never granted), from an allowed origin when the browser names one, and carrying the session's
//! token in [`TOKEN_HEADER`] (random per server, known only to the page this server served); at most
//! [`MAX_EVENT_CLIENTS`] pages follow the state at once. Every command is logged with its surface.

use std::collections::VecDeque;
use std::convert::Infallible;
use std::sync::{Arc, OnceLock};
use std::time::{Duration, Instant};

use axum::Router;
use axum::body::Bytes;
use axum::extract::{DefaultBodyLimit, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use controller::io::operator::{Command, OperatorSender, Request};
use controller::step::cycle::Action;
use controller::step::cycle::DigStats;
use firmware_bridge::messages::Valve;
use futures::Stream;
use futures::StreamExt as _;
use planner::terrain::TerrainGrid;
use serde::{Deserialize, Serialize};
use tokio::sync::{Semaphore, watch};

use crate::access::{Access, TOKEN_HEADER, Token};

/// Longest command body, bytes (a command is under 40).
pub const MAX_COMMAND_BYTES: usize = 1024;
/// Pages following the state at once; more are answered 503.
pub const MAX_EVENT_CLIENTS: usize = 8;
/// The page's state is sent at most this often (wall time).
pub const STATE_EVERY: Duration = Duration::from_millis(100);
/// Log lines the page shows.
const LOG_LINES: usize = 8;

const INDEX_HTML: &str = include_str!("../page/index.html");
/// Where the page's HTML takes the session's token.
const TOKEN_PLACEHOLDER: &str = "{{OPERATOR_TOKEN}}";
const APP_JS: &str = include_str!("../page/app.js");
const STYLE_CSS: &str = include_str!("../page/style.css");

/// What the page is sent: the state (JSON) and the terrain map (JSON, with a version that changes
/// with each new map).
#[derive(Debug, Clone, Default)]
pub(crate) struct Snapshot {
    state: Arc<str>,
    terrain: Option<(u64, Arc<str>)>,
    /// The session is over: this is the last state, and the event streams end after sending it.
    finished: bool,
}

/// The last finished dig as the page shows it.
#[derive(Debug, Clone, Serialize)]
struct LastDig {
    /// The dig number, from 1 (`controller::step::cycle::dig_number`).
    number: u32,
    action: String,
    weight_n: Option<f64>,
    time_s: f64,
    energy_kj: f64,
    swept_volume_m3: f64,
}

/// The page's `state` event.
#[derive(Debug, Clone, Default, Serialize)]
struct PageState {
    time_s: f64,
    activity: String,
    stage: String,
    /// Digs finished.
    digs_done: u32,
    /// The number of the dig in progress (from the move to it to its dump), from 1.
    current_dig: Option<u32>,
    safety: &'static str,
    fault: Option<String>,
    fault_count: u64,
    paused: bool,
    stopping: bool,
    action: Option<Action>,
    /// The dead-reckoned base pose in the world: x, y (m), heading (rad).
    pose: [f64; 3],
    /// The bucket tip in the world, m.
    tip_m: [f64; 3],
    /// The valve commands, in the protocol's valve order.
    valves: Vec<PageValve>,
    last_dig: Option<LastDig>,
    /// The chosen dig's planned start in the world, m.
    next_dig_m: Option<[f64; 3]>,
    log: VecDeque<String>,
    /// Whether the page's commands reach a control loop.
    operator: bool,
    /// Why the session ended, once it has.
    session_over: Option<String>,
}

/// One valve's command as the page shows it.
#[derive(Debug, Clone, Serialize)]
struct PageValve {
    /// The protocol's name of the valve (`AuxValveCommand_Boom` is `Boom`).
    name: String,
    /// The commanded port flow, % of full flow (signed: negative is the other port); null in
    /// position mode, where the gateway's loops drive the valves.
    command_pct: Option<f64>,
}

/// The page's `terrain` event: the controller's terrain map.
#[derive(Debug, Serialize)]
struct PageTerrain {
    nx: usize,
    ny: usize,
    origin_m: [f64; 2],
    cell_m: f64,
    /// Row-major (`j * nx + i`), heights in m rounded to 1 cm, null where unknown.
    z_m: Vec<Option<f64>>,
}

/// One control step as the page needs it (built by the publisher from its queue).
#[derive(Debug, Clone, Copy)]
pub(crate) struct PageStep {
    pub time_s: f64,
    pub activity: firmware_bridge::messages::Activity,
    pub stage: firmware_bridge::messages::AutodigStageCode,
    pub digs_done: u32,
    pub current_dig: Option<u32>,
    pub safety: &'static str,
    pub fault_count: u64,
    pub paused: bool,
    pub stopping: bool,
    pub action: Option<Action>,
    pub pose: [f64; 3],
    pub tip_m: [f64; 3],
    pub valves: [Option<f64>; 6],
}

/// The publisher's side of the page: keeps the page's state and hands it to the server.
#[derive(Debug)]
pub(crate) struct PageFeed {
    tx: watch::Sender<Snapshot>,
    state: PageState,
    terrain: Option<(u64, Arc<str>)>,
    dirty: bool,
    sent_at: Option<Instant>,
}

impl PageFeed {
    pub(crate) fn new(tx: watch::Sender<Snapshot>, operator: bool) -> Self {
        Self {
            tx,
            state: PageState {
                operator,
                safety: "ListenOnly",
                valves: Valve::ALL
                    .iter()
                    .map(|v| PageValve {
                        name: format!("{v:?}"),
                        command_pct: None,
                    })
                    .collect(),
                ..PageState::default()
            },
            terrain: None,
            dirty: true,
            sent_at: None,
        }
    }

    pub(crate) fn set_operator(&mut self, operator: bool) {
        self.state.operator = operator;
        self.dirty = true;
    }

    pub(crate) fn step(&mut self, s: &PageStep, fault: Option<String>) {
        let st = &mut self.state;
        st.time_s = s.time_s;
        st.activity = format!("{:?}", s.activity);
        st.stage = format!("{:?}", s.stage);
        st.digs_done = s.digs_done;
        st.current_dig = s.current_dig;
        st.safety = s.safety;
        st.fault = fault;
        st.fault_count = s.fault_count;
        st.paused = s.paused;
        st.stopping = s.stopping;
        st.action = s.action;
        st.pose = s.pose;
        st.tip_m = s.tip_m;
        for (v, fraction) in st.valves.iter_mut().zip(s.valves) {
            v.command_pct = fraction.map(|f| f * 100.0);
        }
        self.dirty = true;
    }

    pub(crate) fn log(&mut self, line: &str) {
        if self.state.log.len() == LOG_LINES {
            self.state.log.pop_front();
        }
        self.state.log.push_back(line.to_owned());
        self.dirty = true;
    }

    pub(crate) fn dig_done(&mut self, d: &DigStats) {
        self.state.last_dig = Some(LastDig {
            number: d.number(),
            action: format!("{:?}", d.action),
            weight_n: d.weight_n.filter(|w| w.is_finite()),
            time_s: d.time_s,
            energy_kj: d.energy_kj(),
            swept_volume_m3: d.swept_volume_m3,
        });
        self.dirty = true;
    }

    pub(crate) fn next_dig(&mut self, at_m: [f64; 3]) {
        self.state.next_dig_m = Some(at_m);
        self.dirty = true;
    }

    pub(crate) fn terrain(&mut self, grid: &TerrainGrid) {
        let (nx, ny) = (grid.nx(), grid.ny());
        let mut z_m = Vec::with_capacity(nx * ny);
        for j in 0..ny {
            for i in 0..nx {
                z_m.push(
                    grid.cell(i, j)
                        .filter(|z| z.is_finite())
                        .map(|z| (z * 100.0).round() / 100.0),
                );
            }
        }
        let t = PageTerrain {
            nx,
            ny,
            origin_m: grid.origin(),
            cell_m: grid.resolution_m(),
            z_m,
        };
        let version = self.terrain.as_ref().map_or(1, |(v, _)| v + 1);
        self.terrain = Some((version, to_json(&t)));
        self.dirty = true;
    }

    pub(crate) fn finished(&mut self, reason: &str) {
        self.state.session_over = Some(reason.to_owned());
        self.dirty = true;
        self.flush(true);
    }

    /// Sends the state when it changed and [`STATE_EVERY`] has passed (or at once with `force`).
    pub(crate) fn flush(&mut self, force: bool) {
        if !self.dirty || !(force || self.sent_at.is_none_or(|t| t.elapsed() >= STATE_EVERY)) {
            return;
        }
        let snapshot = Snapshot {
            state: to_json(&self.state),
            terrain: self.terrain.clone(),
            finished: self.state.session_over.is_some(),
        };
        // No page connected is not an error: the latest state waits for the next one.
        self.tx.send_replace(snapshot);
        self.dirty = false;
        self.sent_at = Some(Instant::now());
    }
}

fn to_json<T: Serialize>(value: &T) -> Arc<str> {
    // The page's types hold strings, numbers and options only: serialising cannot fail.
    serde_json::to_string(value)
        .unwrap_or_else(|e| format!("{{\"error\": \"{e}\"}}"))
        .into()
}

/// The server's shared state.
#[derive(Clone)]
pub(crate) struct App {
    snapshots: watch::Receiver<Snapshot>,
    operator: Arc<OnceLock<OperatorSender>>,
    event_slots: Arc<Semaphore>,
    access: Arc<Access>,
    token: Token,
    /// The page's HTML with the token in it.
    index_html: Arc<str>,
    /// The port the page is served on (the `Host` and `Origin` name it).
    port: u16,
}

impl App {
    pub(crate) fn new(
        snapshots: watch::Receiver<Snapshot>,
        operator: Arc<OnceLock<OperatorSender>>,
        access: Access,
        token: Token,
        port: u16,
    ) -> Self {
        Self {
            snapshots,
            operator,
            event_slots: Arc::new(Semaphore::new(MAX_EVENT_CLIENTS)),
            access: Arc::new(access),
            index_html: INDEX_HTML.replace(TOKEN_PLACEHOLDER, token.as_str()).into(),
            token,
            port,
        }
    }

    /// The refusal of a request whose `Host` or `Origin` is not allowed, if it is one.
    fn refused(&self, headers: &HeaderMap) -> Option<Response> {
        let text = |name| {
            headers
                .get(name)
                .map(|v| v.to_str().unwrap_or("(not text)"))
        };
        self.access
            .check(text(header::HOST), text(header::ORIGIN), self.port, false)
            .err()
            .map(|why| refuse(StatusCode::FORBIDDEN, why))
    }

    /// Whether no page follows the state (every event stream has ended).
    pub(crate) fn idle(&self) -> impl Fn() -> bool + Send + 'static {
        let slots = Arc::clone(&self.event_slots);
        move || slots.available_permits() == MAX_EVENT_CLIENTS
    }
}

/// The page's routes: `/`, `/app.js`, `/style.css`, `/events`, `/command`.
pub(crate) fn router(app: App) -> Router {
    Router::new()
        .route(
            "/",
            get(|State(app): State<App>, headers: HeaderMap| async move {
                let html = Arc::clone(&app.index_html);
                app.refused(&headers)
                    .unwrap_or_else(|| asset(html.to_string(), "text/html; charset=utf-8"))
            }),
        )
        .route(
            "/app.js",
            get(|State(app): State<App>, headers: HeaderMap| async move {
                app.refused(&headers)
                    .unwrap_or_else(|| asset(APP_JS, "text/javascript; charset=utf-8"))
            }),
        )
        .route(
            "/style.css",
            get(|State(app): State<App>, headers: HeaderMap| async move {
                app.refused(&headers)
                    .unwrap_or_else(|| asset(STYLE_CSS, "text/css; charset=utf-8"))
            }),
        )
        .route("/events", get(events))
        .route("/command", post(command))
        .layer(DefaultBodyLimit::max(MAX_COMMAND_BYTES))
        .with_state(app)
}

fn asset(body: impl Into<axum::body::Body>, content_type: &'static str) -> Response {
    (
        [
            (header::CONTENT_TYPE, content_type),
            (header::CACHE_CONTROL, "no-store"),
            // Only this server's own scripts, styles and connections.
            (
                header::CONTENT_SECURITY_POLICY,
                "default-src 'self'; img-src 'self' data:",
            ),
            (header::X_CONTENT_TYPE_OPTIONS, "nosniff"),
        ],
        body.into(),
    )
        .into_response()
}

/// `GET /events`: the state (and the terrain map when it changed) as server-sent events.
async fn events(State(app): State<App>, headers: HeaderMap) -> Response {
    if let Some(r) = app.refused(&headers) {
        return r;
    }
    let Ok(permit) = Arc::clone(&app.event_slots).try_acquire_owned() else {
        return (
            StatusCode::SERVICE_UNAVAILABLE,
            format!("at most {MAX_EVENT_CLIENTS} pages at once"),
        )
            .into_response();
    };
    let stream = snapshot_events(app.snapshots.clone()).map(move |e| {
        // The slot is held as long as the page follows.
        let _held = &permit;
        e
    });
    Sse::new(stream)
        .keep_alive(KeepAlive::default())
        .into_response()
}

/// The events of `rx`: the current snapshot at once, then each new one; ends after the session's
/// last state or when the publisher ends.
fn snapshot_events(
    rx: watch::Receiver<Snapshot>,
) -> impl Stream<Item = Result<Event, Infallible>> + Send {
    futures::stream::unfold(
        (rx, 0_u64, true),
        |(mut rx, terrain_sent, first)| async move {
            if !first {
                if rx.borrow().finished {
                    return None;
                }
                rx.changed().await.ok()?;
            }
            let snap = rx.borrow_and_update().clone();
            let mut out = Vec::with_capacity(2);
            let mut terrain_sent = terrain_sent;
            if let Some((version, terrain)) = &snap.terrain
                && *version != terrain_sent
            {
                out.push(Ok(Event::default().event("terrain").data(&**terrain)));
                terrain_sent = *version;
            }
            if !snap.state.is_empty() {
                out.push(Ok(Event::default().event("state").data(&*snap.state)));
            }
            Some((futures::stream::iter(out), (rx, terrain_sent, false)))
        },
    )
    .flatten()
}

/// A command from the page: `{"cmd": "estop"}`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct PageCommand {
    cmd: Command,
}

/// A reply to the page.
fn reply(status: StatusCode, body: &controller::io::operator::Response) -> Response {
    let mut r = (status, to_json(body).to_string()).into_response();
    r.headers_mut().insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static("application/json"),
    );
    r
}

fn refuse(status: StatusCode, why: impl Into<String>) -> Response {
    let why = why.into();
    tracing::warn!(%status, why, "operator page: command refused");
    reply(
        status,
        &controller::io::operator::Response {
            ok: false,
            error: Some(why),
            status: None,
        },
    )
}

/// `POST /command`: checks the request (module docs) and hands the command to the control loop.
async fn command(State(app): State<App>, headers: HeaderMap, body: Bytes) -> Response {
    let is_json = headers
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .is_some_and(|v| {
            v.split(';')
                .next()
                .is_some_and(|m| m.trim() == "application/json")
        });
    if !is_json {
        return refuse(
            StatusCode::UNSUPPORTED_MEDIA_TYPE,
            "a command is application/json",
        );
    }
    if let Some(r) = app.refused(&headers) {
        return r;
    }
    let token = headers.get(TOKEN_HEADER).map(HeaderValue::as_bytes);
    if !token.is_some_and(|t| app.token.matches(t)) {
        return refuse(
            StatusCode::FORBIDDEN,
            "a command comes from the operator page of this server only (missing or wrong token)",
        );
    }
    let cmd = match serde_json::from_slice::<PageCommand>(&body) {
        Ok(c) => c.cmd,
        Err(e) => {
            return refuse(
                StatusCode::BAD_REQUEST,
                format!(
                    "malformed command ({e}); expected {{\"cmd\": \
                     \"pause|resume|estop|reset|stop|status\"}}"
                ),
            );
        }
    };
    let Some(sender) = app.operator.get() else {
        return refuse(
            StatusCode::SERVICE_UNAVAILABLE,
            "this session takes no operator commands",
        );
    };
    tracing::info!(surface = "page", ?cmd, "operator command");
    let response = sender
        .send(Request {
            cmd,
            reason: Some("operator page".to_owned()),
        })
        .await;
    let status = if response.ok {
        StatusCode::OK
    } else {
        StatusCode::CONFLICT
    };
    reply(status, &response)
}

#[cfg(test)]
mod tests {
    use super::*;

    const ESTOP: &str = r#"{"cmd":"estop"}"#;

    /// The page's server with a fresh token on a free loopback port; its address and token.
    async fn serve(operator: Option<OperatorSender>) -> (String, String, watch::Sender<Snapshot>) {
        let (tx, rx) = watch::channel(Snapshot::default());
        let cell = Arc::new(OnceLock::new());
        if let Some(s) = operator {
            let _ = cell.set(s);
        }
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
        let addr = listener.local_addr().unwrap();
        let token = Token::random().unwrap();
        let text = token.as_str().to_owned();
        let app = App::new(rx, cell, Access::loopback(), token, addr.port());
        tokio::spawn(async move {
            axum::serve(listener, router(app)).await.unwrap();
        });
        (format!("{addr}"), text, tx)
    }

    /// A raw HTTP/1.1 request; returns the status code and the body.
    async fn http(addr: &str, request: &str) -> (u16, String) {
        use tokio::io::{AsyncReadExt as _, AsyncWriteExt as _};
        let mut s = tokio::net::TcpStream::connect(addr).await.unwrap();
        s.write_all(request.as_bytes()).await.unwrap();
        let mut text = String::new();
        s.read_to_string(&mut text).await.unwrap();
        let code = text[9..12].parse().unwrap();
        let body = text.split("\r\n\r\n").nth(1).unwrap_or_default().to_owned();
        (code, body)
    }

    /// A command request naming `host`: `extra` header lines (each ending `\r\n`).
    fn post_with(host: &str, content_type: &str, extra: &str, body: &str) -> String {
        format!(
            "POST /command HTTP/1.1\r\nHost: {host}\r\nContent-Type: {content_type}\r\n{extra}\
             Content-Length: {}\r\nConnection: close\r\n\r\n{body}",
            body.len()
        )
    }

    /// A command request with the page's `token` and, when given, an `Origin`.
    fn post(
        addr: &str,
        token: &str,
        content_type: &str,
        origin: Option<&str>,
        body: &str,
    ) -> String {
        let origin = origin.map_or(String::new(), |o| format!("Origin: {o}\r\n"));
        let extra = format!("{origin}X-Operator-Token: {token}\r\n");
        post_with(addr, content_type, &extra, body)
    }

    /// A controller node of the default machine.
    fn node() -> controller::step::node::ControllerNode {
        let machine = planner::machine::MachineConfig::load_or_default(None).unwrap();
        controller::step::node::ControllerNode::new(
            &machine,
            planner::autodig::AutodigMaps::builtin().unwrap(),
            controller::ControllerConfig::default(),
        )
        .unwrap()
    }

    #[tokio::test]
    async fn commands_reach_the_operator_port_and_bad_ones_are_refused() {
        let mut port = controller::io::operator::OperatorPort::new();
        let (addr, token, _tx) = serve(Some(port.sender())).await;
        // Unknown command, unknown field, wrong type, foreign origin, oversized body.
        for (ct, origin, body, code) in [
            ("application/json", None, r#"{"cmd":"launch"}"#, 400),
            ("application/json", None, r#"{"cmd":"estop","x":1}"#, 400),
            ("text/plain", None, ESTOP, 415),
            ("application/json", Some("http://evil.example"), ESTOP, 403),
            (
                "application/json",
                None,
                &"x".repeat(MAX_COMMAND_BYTES + 1),
                413,
            ),
        ] {
            let (got, body_text) = http(&addr, &post(&addr, &token, ct, origin, body)).await;
            assert_eq!(got, code, "{ct} {origin:?} {body}: {body_text}");
        }
        // A good one from the page's own origin: queued for the control loop, which answers it.
        let page = format!("http://{addr}");
        let request = post(&addr, &token, "application/json", Some(&page), ESTOP);
        let client = tokio::spawn({
            let addr = addr.clone();
            async move { http(&addr, &request).await }
        });
        let mut node = node();
        while port.serve(&mut node, 0.0) == 0 {
            tokio::time::sleep(Duration::from_millis(5)).await;
        }
        let (code, body) = client.await.unwrap();
        assert_eq!(code, 200, "{body}");
        let reply: controller::io::operator::Response = serde_json::from_str(&body).unwrap();
        let status = reply.status.unwrap();
        assert!(
            status.fault.as_deref().is_some_and(|f| f.contains("stop")),
            "{status:?}"
        );
    }

    #[tokio::test]
    async fn without_an_operator_path_commands_are_unavailable() {
        let (addr, token, _tx) = serve(None).await;
        let (code, body) = http(&addr, &post(&addr, &token, "application/json", None, ESTOP)).await;
        assert_eq!(code, 503, "{body}");
        let (code, page) = http(
            &addr,
            &format!("GET / HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n"),
        )
        .await;
        assert_eq!(code, 200);
        assert!(page.contains("app.js"), "{page}");
        // The page carries the session's token.
        assert!(
            page.contains(&format!(
                "<meta name=\"operator-token\" content=\"{token}\">"
            )),
            "{page}"
        );
    }

    #[tokio::test]
    async fn a_dns_rebinding_reset_is_refused_and_the_estop_stays() {
        let mut port = controller::io::operator::OperatorPort::new();
        let (addr, token, _tx) = serve(Some(port.sender())).await;
        let mut node = node();
        let _ = controller::io::operator::apply(&mut node, Command::Estop, "test", 0.0);
        let port_n = addr.rsplit_once(':').unwrap().1;
        let evil = format!("evil.example:{port_n}");
        let json = "application/json";
        let reset = r#"{"cmd":"reset"}"#;
        let token_line = format!("X-Operator-Token: {token}\r\n");
        let origin = |o: &str| format!("Origin: http://{o}\r\n");
        for (what, host, extra) in [
            // The rebinding page: Host = Origin = its own name; even with the token.
            (
                "Host = Origin = evil",
                evil.clone(),
                origin(&evil) + &token_line,
            ),
            (
                "Host = Origin = evil, no token",
                evil.clone(),
                origin(&evil),
            ),
            ("Host evil, no Origin", evil.clone(), token_line.clone()),
            ("foreign Origin", addr.clone(), origin(&evil) + &token_line),
            (
                "null Origin",
                addr.clone(),
                "Origin: null\r\n".to_owned() + &token_line,
            ),
            ("no token", addr.clone(), origin(&addr)),
            (
                "wrong token",
                addr.clone(),
                origin(&addr) + "X-Operator-Token: 00000000000000000000000000000000\r\n",
            ),
            (
                "token prefix",
                addr.clone(),
                origin(&addr) + &format!("X-Operator-Token: {}\r\n", &token[..16]),
            ),
        ] {
            let (code, body) = http(&addr, &post_with(&host, json, &extra, reset)).await;
            assert_eq!(code, 403, "{what}: {body}");
        }
        // Nothing reached the control loop: the e-stop stays.
        assert_eq!(port.serve(&mut node, 0.0), 0);
        let status = controller::io::operator::apply(&mut node, Command::Status, "test", 0.0);
        assert!(
            status.fault.as_deref().is_some_and(|f| f.contains("stop")),
            "{status:?}"
        );
        // The state and the page itself are not served to the rebinding name either.
        for path in ["/", "/events", "/app.js"] {
            let (code, _) = http(
                &addr,
                &format!("GET {path} HTTP/1.1\r\nHost: {evil}\r\nConnection: close\r\n\r\n"),
            )
            .await;
            assert_eq!(code, 403, "{path}");
        }
    }

    #[tokio::test]
    async fn the_event_stream_sends_the_terrain_once_and_every_state() {
        let (tx, rx) = watch::channel(Snapshot::default());
        let mut feed = PageFeed::new(tx, true);
        let grid = TerrainGrid::new_flat(0.0, 0.0, 1.0, 3, 2, 0.5).unwrap();
        feed.terrain(&grid);
        feed.log("hello");
        feed.flush(true);
        let mut events = Box::pin(snapshot_events(rx));
        let first: Vec<String> = vec![
            format!("{:?}", events.next().await.unwrap().unwrap()),
            format!("{:?}", events.next().await.unwrap().unwrap()),
        ];
        assert!(
            first[0].contains("terrain") && first[0].contains("nx"),
            "{first:?}"
        );
        assert!(first[1].contains("hello"), "{first:?}");
        feed.log("again");
        feed.flush(true);
        let next = format!("{:?}", events.next().await.unwrap().unwrap());
        assert!(next.contains("again") && !next.contains("\"nx\""), "{next}");
    }
}
