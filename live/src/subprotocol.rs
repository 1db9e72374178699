//! The WebSocket subprotocols of the Foxglove server: the `foxglove` crate negotiates
//! `foxglove.sdk.v1` and `foxglove.sdk.v1.1` only, while older Foxglove Studio and Lichtblick ask
//! for `foxglove.websocket.v1`, the same protocol under its former name. An accept shim in front of
//! the crate's server (which listens on loopback behind it) renames that subprotocol in the upgrade
//! request and back in the answer, then copies the connection both ways.
//!
//! ```text
//! client --HTTP upgrade (Sec-WebSocket-Protocol: foxglove.websocket.v1)--> shim (the --live port)
//!     --same request, foxglove.sdk.v1--> foxglove server (loopback, any free port)
//!     <--101, foxglove.sdk.v1-- ... client <--101, foxglove.websocket.v1--
//! then the frames are copied unchanged in both directions
//! ```
//!
//! Nothing from the network is trusted: a request head longer than [`MAX_HEAD_BYTES`] or not
//! finished within [`HEAD_TIMEOUT`] closes the connection, and one whose `Host`, or `Origin` when
//! it names one, is not on the allow-list ([`crate::access`]) is answered 403 and closed.

use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use tokio::io::{AsyncRead, AsyncReadExt as _, AsyncWriteExt as _};
use tokio::net::{TcpListener, TcpStream};

use crate::access::Access;

/// The subprotocol's former name, which older clients ask for.
pub const LEGACY: &str = "foxglove.websocket.v1";
/// The name the `foxglove` crate's server negotiates for the same protocol.
pub const CURRENT: &str = "foxglove.sdk.v1";

/// Longest HTTP request or response head the shim reads, bytes.
pub const MAX_HEAD_BYTES: usize = 16 * 1024;
/// How long a client has to send its upgrade request.
pub const HEAD_TIMEOUT: Duration = Duration::from_secs(10);

const PROTOCOL_HEADER: &str = "sec-websocket-protocol";

/// Accepts connections on `listener` and serves each through the shim to the server at `upstream`
/// (those `access` allows), until the task is aborted.
pub(crate) async fn serve(listener: TcpListener, upstream: SocketAddr, access: Arc<Access>) {
    let port = listener.local_addr().map_or(0, |a| a.port());
    loop {
        let Ok((client, peer)) = listener.accept().await else {
            // Out of descriptors or similar: wait rather than spin.
            tokio::time::sleep(Duration::from_millis(50)).await;
            continue;
        };
        let access = Arc::clone(&access);
        tokio::spawn(async move {
            if let Err(e) = relay(client, upstream, &access, port).await {
                tracing::debug!(%peer, error = %e, "live: WebSocket connection ended");
            }
        });
    }
}

/// One connection: checked against `access` (the shim listens on `port`), the request head
/// renamed, the answer renamed back, then a plain copy.
async fn relay(
    mut client: TcpStream,
    upstream: SocketAddr,
    access: &Access,
    port: u16,
) -> std::io::Result<()> {
    let (head, rest) = tokio::time::timeout(HEAD_TIMEOUT, read_head(&mut client))
        .await
        .map_err(|_| std::io::Error::new(std::io::ErrorKind::TimedOut, "no request head"))??;
    if let Err(why) = access.check(
        header_value(&head, "host"),
        header_value(&head, "origin"),
        port,
        true,
    ) {
        tracing::warn!(why, "live: WebSocket connection refused");
        let answer = format!(
            "HTTP/1.1 403 Forbidden\r\nContent-Type: text/plain\r\nContent-Length: {}\r\n\
             Connection: close\r\n\r\n{why}",
            why.len()
        );
        client.write_all(answer.as_bytes()).await?;
        return Ok(());
    }
    let (head, legacy) = rename_request(&head);
    let mut server = TcpStream::connect(upstream).await?;
    server.write_all(head.as_bytes()).await?;
    server.write_all(&rest).await?;
    let (answer, rest) = read_head(&mut server).await?;
    let answer = if legacy {
        rename_response(&answer)
    } else {
        answer
    };
    client.write_all(answer.as_bytes()).await?;
    client.write_all(&rest).await?;
    tokio::io::copy_bidirectional(&mut client, &mut server).await?;
    Ok(())
}

/// Reads an HTTP head (through the blank line); returns it and the bytes read after it.
async fn read_head<S: AsyncRead + Unpin>(stream: &mut S) -> std::io::Result<(String, Vec<u8>)> {
    let mut buf = Vec::with_capacity(1024);
    let mut chunk = [0_u8; 1024];
    loop {
        if let Some(end) = buf.windows(4).position(|w| w == b"\r\n\r\n") {
            let rest = buf.split_off(end + 4);
            let head = String::from_utf8(buf).map_err(|_| {
                std::io::Error::new(std::io::ErrorKind::InvalidData, "HTTP head is not UTF-8")
            })?;
            return Ok((head, rest));
        }
        if buf.len() > MAX_HEAD_BYTES {
            return Err(std::io::Error::new(
                std::io::ErrorKind::InvalidData,
                format!("HTTP head longer than {MAX_HEAD_BYTES} bytes"),
            ));
        }
        let n = stream.read(&mut chunk).await?;
        if n == 0 {
            return Err(std::io::ErrorKind::UnexpectedEof.into());
        }
        buf.extend_from_slice(&chunk[..n]);
    }
}

/// The value of the first header `name` (lowercase) of `head`.
fn header_value<'a>(head: &'a str, name: &str) -> Option<&'a str> {
    head.split("\r\n").skip(1).find_map(|line| {
        let (n, v) = line.split_once(':')?;
        n.trim().eq_ignore_ascii_case(name).then(|| v.trim())
    })
}

/// The value of a `Sec-WebSocket-Protocol` header line, if `line` is one.
fn protocol_value(line: &str) -> Option<&str> {
    let (name, value) = line.split_once(':')?;
    name.trim()
        .eq_ignore_ascii_case(PROTOCOL_HEADER)
        .then(|| value.trim())
}

/// `head` with [`LEGACY`] offered as [`CURRENT`] (when the client does not offer that too), and
/// whether it was; other lines unchanged.
fn rename_request(head: &str) -> (String, bool) {
    let offered: Vec<&str> = head
        .split("\r\n")
        .filter_map(protocol_value)
        .flat_map(|v| v.split(','))
        .map(str::trim)
        .collect();
    let legacy = offered.contains(&LEGACY) && !offered.contains(&CURRENT);
    if !legacy {
        return (head.to_owned(), false);
    }
    let renamed = map_protocol_lines(head, |token| if token == LEGACY { CURRENT } else { token });
    (renamed, true)
}

/// `head` (the server's answer) with [`CURRENT`] named [`LEGACY`], for a client that asked for that.
fn rename_response(head: &str) -> String {
    map_protocol_lines(head, |token| if token == CURRENT { LEGACY } else { token })
}

/// `head` with each token of its `Sec-WebSocket-Protocol` lines passed through `rename`.
fn map_protocol_lines(head: &str, rename: impl Fn(&str) -> &str) -> String {
    head.split("\r\n")
        .map(|line| match protocol_value(line) {
            Some(value) => {
                let tokens: Vec<&str> = value.split(',').map(|t| rename(t.trim())).collect();
                format!("Sec-WebSocket-Protocol: {}", tokens.join(", "))
            }
            None => line.to_owned(),
        })
        .collect::<Vec<_>>()
        .join("\r\n")
}

#[cfg(test)]
mod tests {
    use super::*;

    const LEGACY_REQUEST: &str = "GET / HTTP/1.1\r\nHost: x\r\nsec-websocket-protocol: other, \
                                  foxglove.websocket.v1\r\nSec-WebSocket-Key: k\r\n\r\n";

    #[test]
    fn the_legacy_name_is_offered_as_the_current_one_and_answered_in_kind() {
        let (head, legacy) = rename_request(LEGACY_REQUEST);
        assert!(legacy);
        assert!(
            head.contains("Sec-WebSocket-Protocol: other, foxglove.sdk.v1\r\n"),
            "{head}"
        );
        assert!(head.ends_with("\r\n\r\n") && head.contains("Sec-WebSocket-Key: k"));
        let answer =
            "HTTP/1.1 101 Switching Protocols\r\nsec-websocket-protocol: foxglove.sdk.v1\r\n\r\n";
        assert_eq!(
            rename_response(answer),
            "HTTP/1.1 101 Switching Protocols\r\nSec-WebSocket-Protocol: foxglove.websocket.v1\r\n\r\n"
        );
    }

    #[test]
    fn current_clients_pass_unchanged() {
        for offered in [
            "foxglove.sdk.v1",
            "foxglove.sdk.v1.1",
            "foxglove.websocket.v1, foxglove.sdk.v1",
        ] {
            let request = format!("GET / HTTP/1.1\r\nSec-WebSocket-Protocol: {offered}\r\n\r\n");
            assert_eq!(rename_request(&request), (request.clone(), false));
        }
    }
}
