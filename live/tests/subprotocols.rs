//! The live view's WebSocket speaks both names of the Foxglove protocol: a client asking for
//! `foxglove.websocket.v1` (older Foxglove Studio, Lichtblick) and one asking for `foxglove.sdk.v1`
//! (or `foxglove.sdk.v1.1`) each get the subprotocol they asked for, the server's info and the
//! advertisement of the stream's channels; an unknown subprotocol is still refused, and so is an
//! upgrade whose `Origin` or `Host` is not on the allow-list (DNS rebinding).

#![allow(clippy::unwrap_used)]

use std::time::Duration;

use futures::StreamExt as _;
use tokio_tungstenite::tungstenite::client::IntoClientRequest as _;
use tokio_tungstenite::tungstenite::http::HeaderValue;
use tokio_tungstenite::tungstenite::{self, Message};

/// Connects to `port` offering `subprotocol`; returns the subprotocol the server chose and the
/// topics of its first `advertise`.
async fn advertised(port: u16, subprotocol: &str) -> tungstenite::Result<(String, Vec<String>)> {
    advertised_with(port, subprotocol, &[]).await
}

/// [`advertised`] with the extra (or replaced) request `headers`.
async fn advertised_with(
    port: u16,
    subprotocol: &str,
    headers: &[(&'static str, String)],
) -> tungstenite::Result<(String, Vec<String>)> {
    let mut request = format!("ws://127.0.0.1:{port}/")
        .into_client_request()
        .unwrap();
    request.headers_mut().insert(
        "Sec-WebSocket-Protocol",
        HeaderValue::from_str(subprotocol).unwrap(),
    );
    for (name, value) in headers {
        request
            .headers_mut()
            .insert(*name, HeaderValue::from_str(value).unwrap());
    }
    let (mut ws, response) = tokio_tungstenite::connect_async(request).await?;
    let chosen = response
        .headers()
        .get("sec-websocket-protocol")
        .and_then(|v| v.to_str().ok())
        .unwrap_or_default()
        .to_owned();
    let mut ops = Vec::new();
    while let Some(msg) = ws.next().await {
        let Message::Text(text) = msg? else {
            continue;
        };
        let value: serde_json::Value = serde_json::from_str(&text).unwrap();
        ops.push(value["op"].as_str().unwrap_or_default().to_owned());
        if value["op"] == "advertise" {
            assert_eq!(ops[0], "serverInfo", "{ops:?}");
            let topics = value["channels"]
                .as_array()
                .unwrap()
                .iter()
                .map(|c| c["topic"].as_str().unwrap().to_owned())
                .collect();
            return Ok((chosen, topics));
        }
    }
    panic!("{subprotocol}: the connection ended before an advertise ({ops:?})");
}

#[test]
fn clients_of_either_protocol_name_get_the_advertisement() {
    let machine = planner::machine::MachineConfig::default_machine().unwrap();
    let stream = live::LiveStream::start(
        &live::LiveArgs {
            live: Some("127.0.0.1:0".into()),
            pace: None,
            live_queue: live::DEFAULT_QUEUE,
            ..Default::default()
        },
        &machine,
    )
    .unwrap();
    let port = stream.port();
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    runtime.block_on(async {
        for (offered, chosen) in [
            (live::subprotocol::LEGACY, live::subprotocol::LEGACY),
            (live::subprotocol::CURRENT, live::subprotocol::CURRENT),
            ("foxglove.sdk.v1.1", "foxglove.sdk.v1.1"),
            (
                "foxglove.websocket.v1, foxglove.sdk.v1.1",
                "foxglove.sdk.v1.1",
            ),
        ] {
            let (got, topics) =
                tokio::time::timeout(Duration::from_secs(20), advertised(port, offered))
                    .await
                    .unwrap_or_else(|_| panic!("{offered}: no advertise within 20 s"))
                    .unwrap_or_else(|e| panic!("{offered}: {e}"));
            assert_eq!(got, chosen, "{offered}");
            for topic in ["/tf", "/terrain", "/scene", "/signals", "/log"] {
                assert!(topics.iter().any(|t| t == topic), "{offered}: {topics:?}");
            }
        }
        match advertised(port, "mqtt").await {
            Err(tungstenite::Error::Http(r)) => assert_eq!(r.status(), 400),
            other => panic!("an unknown subprotocol was not refused: {other:?}"),
        }
    });
    drop(runtime);
    drop(stream);
}

#[test]
fn websocket_upgrades_from_foreign_origins_or_hosts_are_refused() {
    let machine = planner::machine::MachineConfig::default_machine().unwrap();
    let stream = live::LiveStream::start(
        &live::LiveArgs {
            live: Some("127.0.0.1:0".into()),
            live_allow_origin: vec!["https://app.foxglove.dev".into()],
            live_queue: live::DEFAULT_QUEUE,
            ..Default::default()
        },
        &machine,
    )
    .unwrap();
    let port = stream.port();
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    runtime.block_on(async {
        let evil = "evil.example".to_owned();
        for headers in [
            vec![("Origin", format!("http://{evil}"))],
            vec![("Origin", format!("http://{evil}:{port}"))],
            vec![("Host", format!("{evil}:{port}"))],
            // DNS rebinding: the page's own name in both.
            vec![
                ("Host", format!("{evil}:{port}")),
                ("Origin", format!("http://{evil}:{port}")),
            ],
        ] {
            match advertised_with(port, live::subprotocol::CURRENT, &headers).await {
                Err(tungstenite::Error::Http(r)) => assert_eq!(r.status(), 403, "{headers:?}"),
                other => panic!("{headers:?}: not refused: {other:?}"),
            }
        }
        // Allowed: loopback origins with the port, and the configured one.
        for origin in [
            format!("http://127.0.0.1:{port}"),
            format!("http://localhost:{port}"),
            "https://app.foxglove.dev".to_owned(),
        ] {
            let (_, topics) = tokio::time::timeout(
                Duration::from_secs(20),
                advertised_with(
                    port,
                    live::subprotocol::CURRENT,
                    &[("Origin", origin.clone())],
                ),
            )
            .await
            .unwrap_or_else(|_| panic!("{origin}: no advertise within 20 s"))
            .unwrap_or_else(|e| panic!("{origin}: {e}"));
            assert!(
                topics.iter().any(|t| t == "/signals"),
                "{origin}: {topics:?}"
            );
        }
    });
    drop(runtime);
    drop(stream);
}
