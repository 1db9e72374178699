//! One dig numbering everywhere: a short in-process demo session (as `demo --live` runs it, the live
//! stream observing it) numbers its digs from 1 in the session's events (the bus's `DigIndex` of the
//! dig in progress, the statistics' `number`), the live stream's log lines (`dig N started`,
//! `dig N done`, read by a Foxglove client on `/log`), the operator page's final state and the
//! summary (`summary.json` and the table of `summary.md`).

#![allow(clippy::unwrap_used)]

mod common;

use std::sync::atomic::AtomicBool;
use std::time::Duration;

use controller::session::driver::{SessionEvent, SessionObserver};
use controller::session::planned::PlannedSession;
use controller::step::node::ControllerNode;
use futures::{SinkExt as _, StreamExt as _};
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::tungstenite::client::IntoClientRequest as _;
use tokio_tungstenite::tungstenite::http::HeaderValue;

const DIGS: u32 = 2;

/// The live stream, and the dig numbers of the session's events beside it.
struct Recorded {
    stream: live::LiveStream,
    /// The bus's `DigIndex` when each dig started.
    started: Vec<u16>,
    /// The statistics' number of each finished dig.
    finished: Vec<u32>,
}

impl SessionObserver for Recorded {
    fn after_step(
        &mut self,
        time_s: f64,
        node: &ControllerNode,
        session: Option<&PlannedSession>,
        events: &[SessionEvent],
    ) {
        for e in events {
            match e {
                SessionEvent::DigStarted { .. } => self.started.push(node.bus_status().dig_index),
                SessionEvent::DigFinished { index, .. } => {
                    self.finished.push(node.statistics()[*index].number());
                }
                _ => {}
            }
        }
        self.stream.after_step(time_s, node, session, events);
    }

    fn finished(&mut self, time_s: f64, reason: &str) {
        self.stream.finished(time_s, reason);
    }

    fn operator_control(&mut self, sender: controller::io::operator::OperatorSender) {
        self.stream.operator_control(sender);
    }
}

/// Subscribes to `/log` on the stream's WebSocket at `port`, says so on `ready`, and returns the
/// log lines until `session over`.
async fn log_lines(port: u16, ready: std::sync::mpsc::Sender<()>) -> Vec<String> {
    use foxglove::Decode as _;
    let mut request = format!("ws://127.0.0.1:{port}/")
        .into_client_request()
        .unwrap();
    request.headers_mut().insert(
        "Sec-WebSocket-Protocol",
        HeaderValue::from_static("foxglove.sdk.v1"),
    );
    let (mut ws, _) = tokio_tungstenite::connect_async(request).await.unwrap();
    let mut lines = Vec::new();
    while let Some(msg) = ws.next().await {
        match msg.unwrap() {
            Message::Text(text) => {
                let v: serde_json::Value = serde_json::from_str(&text).unwrap();
                if v["op"] != "advertise" {
                    continue;
                }
                let Some(log) = v["channels"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .find(|c| c["topic"] == "/log")
                else {
                    continue;
                };
                let subscribe = serde_json::json!({
                    "op": "subscribe",
                    "subscriptions": [{"id": 1, "channelId": log["id"]}],
                });
                ws.send(Message::text(subscribe.to_string())).await.unwrap();
                // The server takes the subscription before the next message it reads.
                tokio::time::sleep(Duration::from_millis(200)).await;
                ready.send(()).unwrap();
            }
            // messageData: opcode 1, subscription id (u32), log time (u64), the message.
            Message::Binary(data) if data.first() == Some(&1) => {
                let log = foxglove::messages::Log::decode(&data[13..]).unwrap();
                let over = log.message.starts_with("session over");
                lines.push(log.message);
                if over {
                    return lines;
                }
            }
            _ => {}
        }
    }
    panic!("the stream ended before the session did: {lines:?}");
}

/// The numbers `dig N <what>` of `lines`, in order.
fn numbers(lines: &[String], what: &str) -> Vec<u32> {
    lines
        .iter()
        .filter_map(|l| {
            let rest = l.strip_prefix("dig ")?;
            let (n, tail) = rest.split_once(' ')?;
            tail.starts_with(what).then(|| n.parse().unwrap())
        })
        .collect()
}

#[test]
fn digs_are_numbered_from_1_in_the_events_the_stream_the_page_and_the_summary() {
    let dir = tempfile::tempdir().unwrap();
    let mut args = lab::demo::DemoArgs::defaults(dir.path().join("demo"));
    args.digs = DIGS;
    let (sim, _, _) = lab::demo::setup(&args).unwrap();
    let stream = live::LiveStream::start(
        &live::LiveArgs {
            live: Some("127.0.0.1:0".into()),
            pace: None,
            live_queue: live::DEFAULT_QUEUE,
            ..Default::default()
        },
        &sim.machine,
    )
    .unwrap();
    let (port, page) = (stream.port(), format!("127.0.0.1:{}", stream.page_port()));
    let (ready_tx, ready_rx) = std::sync::mpsc::channel();
    let client = std::thread::spawn(move || {
        tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .unwrap()
            .block_on(log_lines(port, ready_tx))
    });
    ready_rx
        .recv_timeout(Duration::from_secs(30))
        .expect("the Foxglove client never subscribed to /log");
    let mut observer = Recorded {
        stream,
        started: Vec::new(),
        finished: Vec::new(),
    };
    let summary =
        lab::demo::run_session_observed(&args, &AtomicBool::new(false), &mut observer).unwrap();
    // The page's state after the session (the stream still serves it until it is dropped).
    let state = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap()
        .block_on(common::wait_for_state(&page, |s| {
            !s["session_over"].is_null()
        }));
    let lines = client.join().unwrap();
    drop(observer.stream);

    let expected: Vec<u32> = (1..=DIGS).collect();
    // The events: the bus numbers the dig in progress, the statistics the finished one.
    let started: Vec<u32> = observer.started.iter().map(|&n| u32::from(n)).collect();
    assert_eq!(started, expected, "DigIndex at each DigStarted");
    assert_eq!(
        observer.finished, expected,
        "DigStats::number at each DigFinished"
    );
    // The live stream's log lines.
    assert_eq!(numbers(&lines, "started"), expected, "{lines:#?}");
    assert_eq!(numbers(&lines, "done"), expected, "{lines:#?}");
    // The operator page after the session: all done, none in progress, the last one numbered.
    assert_eq!(state["digs_done"], DIGS, "{state}");
    assert_eq!(state["current_dig"], serde_json::Value::Null, "{state}");
    assert_eq!(state["last_dig"]["number"], DIGS, "{state}");
    // The summary: its records and the table of summary.md.
    let recorded: Vec<u32> = summary.digs.iter().map(|d| d.number()).collect();
    assert_eq!(recorded, expected);
    let md = std::fs::read_to_string(args.out.join("summary.md")).unwrap();
    let table: Vec<u32> = md
        .lines()
        .filter_map(|l| {
            let mut cells = l.split('|').map(str::trim).skip(1);
            let n = cells.next()?.parse().ok()?;
            matches!(cells.next(), Some("Dig" | "Cleanup")).then_some(n)
        })
        .collect();
    assert_eq!(table, expected, "{md}");
}
