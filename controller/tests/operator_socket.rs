//! The operator's control socket ([`controller::io::operator`]): requests over a real Unix socket,
//! served by a loop that never waits for it; malformed input answered with an error and counted.

#![allow(clippy::unwrap_used)]

mod common;
use common::node;

use std::time::Duration;

use controller::io::operator::{self, Command, Request, Response};
use tokio::io::{AsyncBufReadExt as _, AsyncWriteExt as _, BufReader};
use tokio::net::UnixStream;

/// Sends raw `lines` on one connection and reads one reply per line.
async fn exchange(path: &std::path::Path, lines: &[&[u8]]) -> Vec<Response> {
    let stream = UnixStream::connect(path).await.unwrap();
    let (read, mut write) = stream.into_split();
    let mut read = BufReader::new(read);
    let mut replies = Vec::new();
    for l in lines {
        write.write_all(l).await.unwrap();
        let mut reply = String::new();
        read.read_line(&mut reply).await.unwrap();
        replies.push(serde_json::from_str(&reply).unwrap());
    }
    replies
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn malformed_requests_get_an_error_and_are_counted_while_good_ones_act() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("control.sock");
    let (mut port, server) = operator::listen(&path).unwrap();
    // The control loop: serves the port every 10 ms, never waiting.
    let (stop_tx, mut stop_rx) = tokio::sync::oneshot::channel::<()>();
    let control = tokio::spawn(async move {
        let mut node = node();
        let mut t = 0.0;
        let mut served = 0;
        loop {
            served += port.serve(&mut node, t);
            t += 0.01;
            tokio::select! {
                _ = &mut stop_rx => return (node, port, served),
                () = tokio::time::sleep(Duration::from_millis(10)) => {}
            }
        }
    });
    let long = [b'x'; operator::MAX_LINE_BYTES + 10];
    let mut overlong = long.to_vec();
    overlong.push(b'\n');
    let replies = exchange(
        &path,
        &[
            b"not json\n",
            b"{\"cmd\": \"launch\"}\n",
            b"{\"cmd\": \"estop\", \"extra\": 1}\n",
            b"{\"cmd\": \"pause\", \"reason\": \"truck late\"}\n",
            b"{\"cmd\": \"status\"}\n",
        ],
    )
    .await;
    for r in &replies[..3] {
        assert!(!r.ok && r.error.is_some(), "{r:?}");
    }
    assert!(replies[3].ok, "{:?}", replies[3]);
    let status = replies[4].status.clone().unwrap();
    assert!(status.paused, "{status:?}");
    assert_eq!(status.malformed_requests, 3);
    // An overlong line: an error, then the connection is closed.
    let r = exchange(&path, &[&overlong]).await;
    assert!(!r[0].ok);
    // The client of `excavator-ctl ctl`.
    let r = operator::request(
        &path,
        &Request {
            cmd: Command::Estop,
            reason: Some("test".into()),
        },
    )
    .await
    .unwrap();
    let s = r.status.unwrap();
    assert!(
        s.fault.as_ref().is_some_and(|f| f.contains("emergency")),
        "{:?}",
        s.fault
    );
    assert_eq!(s.malformed_requests, 4);
    stop_tx.send(()).unwrap();
    let (node, port, served) = control.await.unwrap();
    assert_eq!(served, 3);
    assert_eq!(port.malformed(), 4);
    assert!(node.cycle().paused());
    server.abort();
    let _ = server.await;
    // A socket nobody serves any more is replaced; a served one is refused.
    let (_port, again) = operator::listen(&path).unwrap();
    assert!(operator::listen(&path).is_err());
    again.abort();
}
