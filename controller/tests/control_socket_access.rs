//! Who may use the operator's control socket ([`controller::io::operator`]): the socket is
//! owner-only whatever the umask, and connections held open in every slot do not lock the e-stop
//! out. (The peer credential rule itself is unit-tested in the module: a second uid cannot be had
//! in a test.)

#![allow(clippy::unwrap_used)]

mod common;
use common::node;

use std::os::unix::fs::PermissionsExt as _;
use std::time::Duration;

use controller::io::operator::{self, Command, Request};
use tokio::net::UnixStream;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_socket_is_owner_only_at_umask_000_and_idle_connections_do_not_lock_out_estop() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("control.sock");
    let old = nix::sys::stat::umask(nix::sys::stat::Mode::empty());
    let listened = operator::listen(&path);
    nix::sys::stat::umask(old);
    let (mut port, server) = listened.unwrap();
    let mode = std::fs::metadata(&path).unwrap().permissions().mode() & 0o777;
    assert_eq!(mode, operator::SOCKET_MODE, "mode {mode:o}");
    // The control loop: serves the port every 10 ms, never waiting.
    let (stop_tx, mut stop_rx) = tokio::sync::oneshot::channel::<()>();
    let control = tokio::spawn(async move {
        let mut node = node();
        let mut t = 0.0;
        loop {
            port.serve(&mut node, t);
            t += 0.01;
            tokio::select! {
                _ = &mut stop_rx => return,
                () = tokio::time::sleep(Duration::from_millis(10)) => {}
            }
        }
    });
    // Every slot held by a connection that never sends anything.
    let mut idle = Vec::new();
    for _ in 0..operator::MAX_CONNECTIONS {
        idle.push(UnixStream::connect(&path).await.unwrap());
    }
    tokio::time::sleep(Duration::from_millis(50)).await;
    for attempt in 0..10 {
        let r = operator::request(
            &path,
            &Request {
                cmd: Command::Estop,
                reason: Some("test".into()),
            },
        )
        .await
        .unwrap();
        assert!(r.ok, "estop {attempt} with every slot busy: {r:?}");
        let status = r.status.unwrap();
        assert!(
            status.fault.as_deref().is_some_and(|f| f.contains("stop")),
            "{status:?}"
        );
        // Anything else beyond the limit is refused.
        let r = operator::request(
            &path,
            &Request {
                cmd: Command::Reset,
                reason: None,
            },
        )
        .await
        .unwrap();
        assert!(
            !r.ok && r.error.as_deref().is_some_and(|e| e.contains("too many")),
            "{r:?}"
        );
    }
    // An overflow connection that sends nothing is dropped after its deadline.
    let mut silent = UnixStream::connect(&path).await.unwrap();
    let mut buf = Vec::new();
    let read = tokio::time::timeout(
        operator::OVERFLOW_TIMEOUT * 4,
        tokio::io::AsyncReadExt::read_to_end(&mut silent, &mut buf),
    )
    .await;
    assert!(read.is_ok(), "a silent overflow connection was kept open");
    drop(idle);
    stop_tx.send(()).unwrap();
    control.await.unwrap();
    server.abort();
}

/// With a configured group the socket file belongs to it, mode 660 (a member can open it; the peer
/// check lets the group's members in), whatever the umask.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn with_a_group_the_socket_belongs_to_it_with_mode_660() {
    use std::os::unix::fs::MetadataExt as _;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("control.sock");
    let gid = nix::unistd::getegid().as_raw();
    let port = operator::OperatorPort::new();
    let old = nix::sys::stat::umask(nix::sys::stat::Mode::empty());
    let listened = port.listen_with(
        &path,
        operator::SocketAccess {
            group_gid: Some(gid),
        },
    );
    nix::sys::stat::umask(old);
    let server = listened.unwrap();
    let meta = std::fs::metadata(&path).unwrap();
    assert_eq!(meta.mode() & 0o777, operator::GROUP_SOCKET_MODE);
    assert_eq!(meta.gid(), gid);
    server.abort();
}
