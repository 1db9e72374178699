//! Helpers of the live view's integration tests.

use tokio::io::{AsyncReadExt as _, AsyncWriteExt as _};

/// Reads the page's event stream at `addr` until a `state` event satisfies `done`; returns it.
pub async fn wait_for_state(
    addr: &str,
    done: impl Fn(&serde_json::Value) -> bool,
) -> serde_json::Value {
    let mut s = tokio::net::TcpStream::connect(addr).await.unwrap();
    s.write_all(format!("GET /events HTTP/1.1\r\nHost: {addr}\r\n\r\n").as_bytes())
        .await
        .unwrap();
    let mut text = String::new();
    let mut buf = vec![0_u8; 64 * 1024];
    loop {
        let n = s.read(&mut buf).await.unwrap();
        assert!(n > 0, "the event stream ended: {text}");
        text.push_str(&String::from_utf8_lossy(&buf[..n]));
        // Events are `event: state\ndata: {...}\n\n`; keep the unfinished tail.
        while let Some(end) = text.find("\n\n") {
            let event: String = text.drain(..end + 2).collect();
            if let Some(at) = event.find("event: state\ndata: ") {
                let data = event[at + "event: state\ndata: ".len()..].trim();
                let state: serde_json::Value = serde_json::from_str(data).unwrap();
                if done(&state) {
                    return state;
                }
            }
        }
    }
}

/// The operator page's command token at `addr`, read from the page it serves.
#[allow(
    dead_code,
    reason = "not every test that shares these helpers sends commands"
)]
pub async fn page_token(addr: &str) -> String {
    let mut s = tokio::net::TcpStream::connect(addr).await.unwrap();
    s.write_all(format!("GET / HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n").as_bytes())
        .await
        .unwrap();
    let mut text = String::new();
    s.read_to_string(&mut text).await.unwrap();
    let at = text.find("name=\"operator-token\" content=\"").unwrap() + 31;
    text[at..at + 32].to_owned()
}
