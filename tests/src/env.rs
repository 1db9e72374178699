//! The test environment: the vcan interface (`EXCAVATOR_VCAN_IFACE`), the release binaries
//! (`EXCAVATOR_BIN_DIR`) and can-utils. Anything missing is a failure that says how to get it, never a
//! skip.

use std::path::{Path, PathBuf};

/// The interface under test, checked to exist, to be a CAN interface and to be up.
///
/// # Panics
/// When it is missing, not CAN or down, with the commands that fix it.
pub fn vcan_iface() -> String {
    let iface = std::env::var("EXCAVATOR_VCAN_IFACE").unwrap_or_else(|_| "vcan0".to_owned());
    let sys = Path::new("/sys/class/net").join(&iface);
    assert!(
        sys.exists(),
        "CAN interface {iface} does not exist (EXCAVATOR_VCAN_IFACE={iface}): these tests need a vcan \
         interface. Run them through scripts/test-all (it uses scripts/vcan-vm: native vcan or a qemu \
         VM), or create one: sudo modprobe vcan; sudo ip link add dev {iface} type vcan; \
         sudo ip link set up {iface}"
    );
    let kind = std::fs::read_to_string(sys.join("type")).unwrap_or_default();
    assert_eq!(
        kind.trim(),
        "280",
        "{iface} is not a CAN interface (ARPHRD type {})",
        kind.trim()
    );
    let flags = std::fs::read_to_string(sys.join("flags")).unwrap_or_default();
    let flags = u32::from_str_radix(flags.trim().trim_start_matches("0x"), 16).unwrap_or(0);
    assert!(
        flags & 1 == 1,
        "{iface} is down: sudo ip link set up {iface}"
    );
    iface
}

/// `EXCAVATOR_BIN_DIR/name`, checked to exist.
///
/// # Panics
/// When `EXCAVATOR_BIN_DIR` is unset or the binary is missing.
pub fn binary(name: &str) -> PathBuf {
    let Some(dir) = std::env::var_os("EXCAVATOR_BIN_DIR") else {
        panic!(
            "EXCAVATOR_BIN_DIR is not set: it must name the directory with excavator-sim and \
             excavator-ctl (scripts/test-all sets it to the `checked` profile's folder; by hand: \
             EXCAVATOR_BIN_DIR=target/checked after `cargo build --profile checked`)"
        );
    };
    let path = PathBuf::from(dir).join(name);
    assert!(
        path.is_file(),
        "{} does not exist: cargo build --release -p vcan_sim -p controller (EXCAVATOR_BIN_DIR={})",
        path.display(),
        path.parent()
            .map(Path::display)
            .map_or(String::new(), |d| d.to_string())
    );
    path
}

/// A program on PATH.
///
/// # Panics
/// When it is not found, naming the package.
pub fn tool(name: &str, package: &str) -> PathBuf {
    let path = std::env::var_os("PATH").unwrap_or_default();
    for dir in std::env::split_paths(&path) {
        let candidate = dir.join(name);
        if candidate.is_file() {
            return candidate;
        }
    }
    panic!(
        "{name} ({package}) is not on PATH: install {package} (scripts/install-test-tools does)"
    );
}

/// True inside the `scripts/vcan-vm` guest (`EXCAVATOR_VCAN_VM_GUEST=1`), where timing is looser.
pub fn in_vm() -> bool {
    std::env::var("EXCAVATOR_VCAN_VM_GUEST").is_ok_and(|v| v == "1")
}

/// Where a test keeps its artefacts: `EXCAVATOR_HIL_ARTIFACTS/<test>` when set (a `--rw` share, so
/// the logs survive the VM), otherwise a fresh directory under the system temp dir.
///
/// # Panics
/// When the directory cannot be created.
pub fn artifacts(test: &str) -> PathBuf {
    let dir = match std::env::var_os("EXCAVATOR_HIL_ARTIFACTS") {
        Some(root) => PathBuf::from(root).join(test),
        None => std::env::temp_dir().join(format!("excavator-hil-{}-{test}", std::process::id())),
    };
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir)
        .unwrap_or_else(|e| panic!("cannot create {}: {e}", dir.display()));
    dir
}
