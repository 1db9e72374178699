//! The README's "Running on vcan" commands, run as written: the first `sh` block of that section,
//! line by line in `bash`, in a fresh folder holding the repository's `config/` and the release
//! binaries at `target/release/`.
//!
//! What the harness does instead of a line, each checked to be the README's line:
//! - `sudo modprobe vcan` and `sudo ip link add dev vcan0 ...`: the interface exists already
//!   (`scripts/vcan-vm` made it; the test runs on `vcan0`, the README's);
//! - `cargo build --release`: the binaries of `EXCAVATOR_BIN_DIR` stand at `target/release/`;
//! - `candump -L vcan0` ("in another terminal") runs in the background from the start.
//!
//! Inside the VM the controller's line gets `--config config/vm.toml`, as the README says a VM
//! needs (its text is checked to say so). The session must end with the three digs it asks for.
//!
//! `#[ignore]`d in a plain `cargo test`: it needs vcan0 and the binaries; `scripts/test-all` runs it
//! alone (it uses the README's fixed scan port 7878).

#![allow(clippy::unwrap_used)]

use std::os::unix::process::CommandExt as _;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use hil_tests::env;
use hil_tests::planned::{path_str, read_summary};
use hil_tests::process::Proc;

/// The README, from the repository root.
const README: &str = include_str!("../../README.md");
/// The section whose first `sh` block is run.
const SECTION: &str = "## Running on vcan";
/// What the README tells a VM user to add to `run`.
const VM_OPTION: &str = "--config config/vm.toml";
/// The digs the README's session asks for.
const README_DIGS: usize = 3;
/// A 3-dig planned session in real time takes about 100 s natively; the TCG VM is slower.
const SESSION_TIMEOUT: Duration = Duration::from_secs(900);

/// The commands of the section's first `sh` block, continuation lines joined.
fn readme_commands() -> Vec<String> {
    let section = README
        .split_once(SECTION)
        .unwrap_or_else(|| panic!("README.md has no section {SECTION:?}"))
        .1;
    let block = section
        .split_once("```sh\n")
        .and_then(|(_, rest)| rest.split_once("```"))
        .unwrap_or_else(|| panic!("the README's {SECTION:?} has no ```sh block"))
        .0;
    let mut commands = Vec::new();
    let mut current = String::new();
    for line in block.lines() {
        match line.strip_suffix('\\') {
            Some(head) => current.push_str(head),
            None => {
                current.push_str(line);
                commands.push(std::mem::take(&mut current));
            }
        }
    }
    commands.retain(|c| !c.trim().is_empty());
    commands
}

/// The folder the commands run in: `config/` of the repository and `target/release/` holding the
/// binaries under test.
fn working_folder(root: &Path) -> PathBuf {
    let repo = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let bin_dir = env::binary("excavator-ctl")
        .parent()
        .map(Path::to_path_buf)
        .unwrap();
    env::binary("excavator-sim");
    std::os::unix::fs::symlink(
        repo.join("config").canonicalize().unwrap(),
        root.join("config"),
    )
    .unwrap();
    std::fs::create_dir_all(root.join("target")).unwrap();
    std::os::unix::fs::symlink(
        bin_dir.canonicalize().unwrap(),
        root.join("target").join("release"),
    )
    .unwrap();
    root.to_owned()
}

#[test]
#[ignore = "needs vcan0 and the release binaries: run through scripts/test-all"]
fn the_readmes_vcan_commands_as_written_run_a_three_dig_session() {
    let iface = env::vcan_iface();
    assert_eq!(iface, "vcan0", "the README's commands use vcan0");
    env::tool("candump", "can-utils");
    let artifacts = env::artifacts("readme_vcan");
    let commands = readme_commands();

    // The lines the harness does itself.
    let [modprobe, link, build, rest @ ..] = &commands[..] else {
        panic!("the README's vcan block is shorter than expected: {commands:#?}")
    };
    assert_eq!(modprobe.trim(), "sudo modprobe vcan");
    assert!(
        link.trim()
            .starts_with("sudo ip link add dev vcan0 type vcan"),
        "{link}"
    );
    assert_eq!(build.trim(), "cargo build --release");
    let (candump, session) = rest.split_last().unwrap();
    assert!(candump.trim().starts_with("candump -L vcan0"), "{candump}");
    let run_line = session
        .iter()
        .position(|c| c.contains("excavator-ctl run"))
        .unwrap_or_else(|| panic!("no `excavator-ctl run` line in {session:#?}"));
    assert!(
        session[run_line].contains(&format!("--digs {README_DIGS}")),
        "{}",
        session[run_line]
    );
    let mut session = session.to_vec();
    if env::in_vm() {
        assert!(
            README
                .split_once(SECTION)
                .is_some_and(|(_, s)| s.contains(VM_OPTION)),
            "the README's vcan section does not tell a VM user to add {VM_OPTION}"
        );
        session[run_line] = format!("{} {VM_OPTION}", session[run_line].trim_end());
    }

    // A local folder: the VM's shared folders hold no Unix sockets (the control socket).
    let work = tempfile::tempdir().unwrap();
    let root = working_folder(work.path());
    let script = format!(
        "set -eu\ncandump -L vcan0 > candump.log &\n{}\n",
        session.join("\n")
    );
    std::fs::write(artifacts.join("commands.sh"), &script).unwrap();
    let mut command = Command::new("bash");
    command
        .args(["-c", &script])
        .current_dir(&root)
        .process_group(0);
    let mut shell = Proc::spawn_with("bash", &mut command, &artifacts.join("commands.log"));
    let status = shell.wait_timeout(SESSION_TIMEOUT);
    // The simulator and candump were started in the background: end the whole group.
    let _ = Command::new("kill")
        .args(["-KILL", "--", &format!("-{}", shell.id())])
        .status();
    let out = root.join("out").join("run");
    let _ = Command::new("cp")
        .args(["-r", path_str(&out), path_str(&artifacts)])
        .status();
    let _ = std::fs::copy(root.join("candump.log"), artifacts.join("candump.log"));
    let status = status.unwrap_or_else(|| {
        panic!(
            "the README's commands did not finish within {SESSION_TIMEOUT:?}: {}",
            shell.log_tail(40)
        )
    });
    assert!(
        status.success(),
        "the README's commands failed ({status}): {}",
        shell.log_tail(40)
    );

    let summary = read_summary(&out);
    assert_eq!(summary.command, "run");
    assert_eq!(summary.strategy, "planned");
    assert_eq!(
        summary.totals.digs, README_DIGS,
        "end {:?}, error {:?}",
        summary.end, summary.error
    );
    assert!(summary.error.is_none(), "{:?}", summary.error);
    let trace = std::fs::read_to_string(root.join("candump.log")).unwrap();
    for source in ["27#", "80#"] {
        assert!(
            trace.lines().any(|l| l.contains(source)),
            "candump saw no frame from source address 0x{}",
            &source[..2]
        );
    }
    eprintln!(
        "README vcan session: {} digs ({} dig, {} cleanup actions), end {:?}, {:.0} s wall, {} scans",
        summary.totals.digs,
        summary.totals.dig_actions,
        summary.totals.cleanup_actions,
        summary.end,
        summary.totals.wall_time_s,
        summary.totals.scans
    );
}
