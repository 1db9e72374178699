//! The Debian package and its systemd unit (docs/deployment.md, "The package"):
//!
//! - the unit in `packaging/` passes `systemd-analyze verify` (its `ExecStart` binary replaced by
//!   an executable that exists here);
//! - the package `scripts/package` built (`EXCAVATOR_DEB`, else the newest in
//!   `$CARGO_TARGET_DIR/debian/`), unpacked into a throwaway root with `dpkg-deb -x` (no root
//!   needed): its files, its conffiles, a stripped binary, the unit, and the unit's `ExecStart`
//!   run from that root against a missing interface.
//!
//! - in the VM (`#[ignore]`d, needs vcan0): the installed unit's `ExecStart`, as an unprivileged
//!   user, monitors vcan0 listen-only and stops cleanly on SIGTERM.
//!
//! On the host a missing tool or package is a skip, or a failure with `EXCAVATOR_REQUIRE_TOOLS=1`
//! (`scripts/package` sets it); in the VM a missing package is a failure.

#![allow(clippy::unwrap_used)]

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use hil_tests::process::Proc;

/// The unit as the repository holds it.
const UNIT: &str = include_str!("../../packaging/excavator-ctl@.service");
/// The installed binary's path in the unit.
const INSTALLED_BIN: &str = "/usr/bin/excavator-ctl";

/// `have`, or else a skip message, or a failure where the tools are required.
fn have_or_skip(have: bool, what: &str) -> bool {
    if !have {
        assert!(
            std::env::var("EXCAVATOR_REQUIRE_TOOLS").as_deref() != Ok("1"),
            "{what} is required (scripts/package)"
        );
        println!("skip: no {what}");
    }
    have
}

fn have(tool: &str) -> bool {
    Command::new(tool).arg("--version").output().is_ok()
}

/// The value of the unit's `key=`, the last one where it is given twice.
fn unit_value<'a>(unit: &'a str, key: &str) -> Option<&'a str> {
    unit.lines()
        .rev()
        .find_map(|l| l.strip_prefix(key)?.strip_prefix('='))
}

/// `systemd-analyze verify` on `unit` (a template) for the instance `can0`, with `ExecStart`'s
/// binary replaced by `bin`; panics with its output when it fails.
fn verify(unit: &str, bin: &Path) {
    let dir = tempfile::tempdir().unwrap();
    let text = unit.replace(INSTALLED_BIN, bin.to_str().unwrap());
    std::fs::write(dir.path().join("excavator-ctl@.service"), text).unwrap();
    let out = Command::new("systemd-analyze")
        .arg("verify")
        .arg(dir.path().join("excavator-ctl@can0.service"))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    println!("systemd-analyze verify: {}, {stderr:?}", out.status);
    assert!(out.status.success(), "systemd-analyze verify: {stderr}");
    assert!(
        !stderr.contains("excavator-ctl@"),
        "warnings about the unit: {stderr}"
    );
}

#[test]
fn unit_passes_systemd_analyze_verify() {
    if !have_or_skip(have("systemd-analyze"), "systemd-analyze") {
        return;
    }
    // The unit, not the binary, is under test: any executable stands for it.
    verify(UNIT, &std::env::current_exe().unwrap());
}

#[test]
fn unit_runs_unprivileged_never_restarts_and_keeps_to_its_address_families() {
    assert_eq!(unit_value(UNIT, "User"), Some("excavator"));
    assert_eq!(unit_value(UNIT, "Restart"), Some("no"));
    // The control loop feeds the watchdog (controller::io::sd_notify): a stalled loop is ended.
    assert_eq!(unit_value(UNIT, "Type"), Some("notify"));
    assert!(unit_value(UNIT, "WatchdogSec").is_some_and(|v| v.ends_with('s')));
    assert_eq!(unit_value(UNIT, "CapabilityBoundingSet"), Some(""));
    assert_eq!(unit_value(UNIT, "NoNewPrivileges"), Some("yes"));
    assert_eq!(unit_value(UNIT, "ProtectSystem"), Some("strict"));
    assert_eq!(unit_value(UNIT, "CPUSchedulingPolicy"), Some("fifo"));
    assert_eq!(
        unit_value(UNIT, "RestrictAddressFamilies"),
        Some("AF_CAN AF_NETLINK AF_UNIX")
    );
    let exec = unit_value(UNIT, "ExecStart").unwrap();
    assert!(
        exec.starts_with(INSTALLED_BIN) && exec.contains("--config-dir /etc/excavator"),
        "{exec}"
    );
    let env = include_str!("../../packaging/run.env");
    assert!(
        env.lines().any(|l| l == "EXCAVATOR_RUN_ARGS=--listen-only"),
        "the package starts listen-only"
    );
}

/// The package to check: `EXCAVATOR_DEB`, else the newest `excavator-ctl_*.deb` in the target
/// directory's `debian/`.
fn package() -> Option<PathBuf> {
    if let Some(p) = std::env::var_os("EXCAVATOR_DEB") {
        let p = PathBuf::from(p);
        assert!(
            p.is_file(),
            "EXCAVATOR_DEB={}: no such file (an absolute path: this test runs in {})",
            p.display(),
            std::env::current_dir().map_or_else(|e| e.to_string(), |d| d.display().to_string())
        );
        return Some(p);
    }
    // This test is TARGET/<profile>/deps/package-<hash>.
    let exe = std::env::current_exe().ok()?;
    let target = exe.parent()?.parent()?.parent()?;
    std::fs::read_dir(target.join("debian"))
        .ok()?
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| {
            p.file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.starts_with("excavator-ctl_") && n.ends_with(".deb"))
        })
        .max_by_key(|p| p.metadata().and_then(|m| m.modified()).ok())
}

/// `deb` unpacked with `dpkg-deb -x` into a fresh directory that any user may read.
fn unpack(deb: &Path) -> tempfile::TempDir {
    use std::os::unix::fs::PermissionsExt as _;
    let root = tempfile::tempdir().unwrap();
    std::fs::set_permissions(root.path(), std::fs::Permissions::from_mode(0o755)).unwrap();
    let st = Command::new("dpkg-deb")
        .arg("-x")
        .arg(deb)
        .arg(root.path())
        .status()
        .unwrap();
    assert!(st.success(), "dpkg-deb -x {}", deb.display());
    root
}

/// Whether the ELF file at `path` has a symbol table or DWARF (its section names are in
/// `.shstrtab`, so a byte search finds them).
fn has_symbols(path: &Path) -> bool {
    let bytes = std::fs::read(path).unwrap();
    [&b"\0.symtab\0"[..], b"\0.debug_info\0"]
        .iter()
        .any(|name| bytes.windows(name.len()).any(|w| w == *name))
}

#[test]
fn the_changelog_names_the_workspace_version() {
    let changelog = include_str!("../../packaging/debian/changelog");
    let first = changelog.lines().next().unwrap_or_default();
    assert!(
        first.starts_with(&format!("excavator-ctl ({}-", env!("CARGO_PKG_VERSION"))),
        "{first}"
    );
}

#[test]
fn the_package_installs_its_files_and_its_unit_runs() {
    if !have_or_skip(have("dpkg-deb"), "dpkg-deb") {
        return;
    }
    let Some(deb) = package() else {
        have_or_skip(false, "package (scripts/package builds it)");
        return;
    };
    let size = deb.metadata().unwrap().len();
    println!("{}: {size} bytes", deb.display());
    let root = unpack(&deb);
    let root = root.path();
    for file in [
        "usr/bin/excavator-ctl",
        "usr/lib/systemd/system/excavator-ctl@.service",
        "usr/lib/sysusers.d/excavator-ctl.conf",
        "etc/excavator/run.env",
        "etc/excavator/README",
        "usr/share/doc/excavator-ctl/deployment.md",
        "usr/share/doc/excavator-ctl/examples/80-can0.network",
        "usr/share/doc/excavator-ctl/examples/config/machine.toml",
        "usr/share/doc/excavator-ctl/examples/config/controller.toml",
        "usr/share/doc/excavator-ctl/changelog.Debian.gz",
        "usr/share/man/man1/excavator-ctl.1.gz",
        "usr/share/man/man1/excavator-ctl-run.1.gz",
        "usr/share/bash-completion/completions/excavator-ctl",
        "usr/share/zsh/vendor-completions/_excavator-ctl",
        "usr/share/fish/vendor_completions.d/excavator-ctl.fish",
        "usr/share/doc/excavator-ctl/examples/profiles/other_gateway.toml",
        "usr/share/doc/excavator-ctl/examples/profiles/other_gateway.dbc",
        "usr/share/doc/excavator-ctl/machine-profile.md",
    ] {
        assert!(root.join(file).is_file(), "{file} not in the package");
    }
    let bin = root.join("usr/bin/excavator-ctl");
    assert!(!has_symbols(&bin), "the packaged binary is not stripped");
    let unit = std::fs::read_to_string(root.join("usr/lib/systemd/system/excavator-ctl@.service"))
        .unwrap();
    assert_eq!(unit, UNIT, "the package's unit is the repository's");
    let sysusers =
        std::fs::read_to_string(root.join("usr/lib/sysusers.d/excavator-ctl.conf")).unwrap();
    assert!(sysusers.lines().any(|l| l.starts_with("u excavator ")));

    // The control part: run.env is a conffile, postinst creates the user.
    let control = tempfile::tempdir().unwrap();
    let st = Command::new("dpkg-deb")
        .arg("-e")
        .arg(&deb)
        .arg(control.path())
        .status()
        .unwrap();
    assert!(st.success());
    let conffiles = std::fs::read_to_string(control.path().join("conffiles")).unwrap();
    assert!(conffiles.lines().any(|l| l == "/etc/excavator/run.env"));
    let postinst = std::fs::read_to_string(control.path().join("postinst")).unwrap();
    assert!(postinst.contains("systemd-sysusers excavator-ctl.conf"));

    if have("systemd-analyze") {
        verify(&unit, &bin);
    }
    if have_or_skip(have("lintian"), "lintian") {
        let out = Command::new("lintian")
            .args(["--fail-on", "error,warning"])
            .arg(&deb)
            .output()
            .unwrap();
        let report = String::from_utf8_lossy(&out.stdout);
        println!("lintian: {report}");
        assert!(out.status.success(), "lintian: {report}");
        assert!(
            !report
                .lines()
                .any(|l| l.starts_with("E: ") || l.starts_with("W: "))
        );
    }

    // The unit's ExecStart from the unpacked root: --help, then against a missing interface (netlink
    // answers on any kernel, with or without SocketCAN).
    let help = Command::new(&bin).args(["run", "--help"]).output().unwrap();
    assert!(help.status.success());
    assert!(String::from_utf8_lossy(&help.stdout).contains("--config-dir"));
    let args = exec_start_args(&unit, root, "nosuchcan0");
    let out = Command::new(&bin)
        .args(&args[1..])
        .env("NO_COLOR", "1")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("\"nosuchcan0\" not found")
            && stderr.contains("type can bitrate 500000 restart-ms 100"),
        "{stderr}"
    );
    assert!(!stderr.contains('\x1b'), "ANSI escapes in {stderr:?}");
}

/// The unit's `ExecStart` as systemd would run it for instance `iface` from the unpacked `root`:
/// `%i` replaced, `$EXCAVATOR_RUN_ARGS` from `run.env`, paths under `/etc` and `/run` moved into
/// `root`.
fn exec_start_args(unit: &str, root: &Path, iface: &str) -> Vec<String> {
    let env = std::fs::read_to_string(root.join("etc/excavator/run.env")).unwrap();
    let run_args = unit_value(&env, "EXCAVATOR_RUN_ARGS").unwrap_or("");
    let run_dir = root.join("run/excavator-ctl");
    std::fs::create_dir_all(&run_dir).unwrap();
    unit_value(unit, "ExecStart")
        .unwrap()
        .split_whitespace()
        .flat_map(|w| match w {
            "$EXCAVATOR_RUN_ARGS" => run_args.split_whitespace().map(str::to_owned).collect(),
            w => vec![
                w.replace("%i", iface)
                    .replace(
                        INSTALLED_BIN,
                        root.join("usr/bin/excavator-ctl").to_str().unwrap(),
                    )
                    .replace(
                        "/etc/excavator",
                        root.join("etc/excavator").to_str().unwrap(),
                    )
                    .replace("/run/excavator-ctl", run_dir.to_str().unwrap()),
            ],
        })
        .collect()
}

/// The package's listen-only default against the VM's vcan0, the unit's command line run as an
/// unprivileged user (`setpriv`; the VM's read-only `/etc/passwd` has no `excavator` user, so
/// `nobody`'s ids stand for it): it starts, reports the link, and stops
/// cleanly on SIGTERM, the unit's `KillSignal`.
#[test]
#[ignore = "needs vcan0 and the package: scripts/vcan-vm with EXCAVATOR_DEB"]
fn installed_unit_monitors_vcan0_listen_only_as_an_unprivileged_user() {
    use std::os::unix::fs::PermissionsExt as _;
    const NOBODY: &str = "65534";
    let iface = hil_tests::env::vcan_iface();
    let deb = package().expect("no package: EXCAVATOR_DEB=path (scripts/package builds it)");
    let root = unpack(&deb);
    let root = root.path();
    let unit = std::fs::read_to_string(root.join("usr/lib/systemd/system/excavator-ctl@.service"))
        .unwrap();
    let args = exec_start_args(&unit, root, &iface);
    std::fs::set_permissions(
        root.join("run/excavator-ctl"),
        std::fs::Permissions::from_mode(0o777),
    )
    .unwrap();
    assert!(args.iter().any(|a| a == "--listen-only"), "{args:?}");
    let logs = tempfile::tempdir().unwrap();
    let mut ctl = Proc::spawn_with(
        "installed excavator-ctl",
        Command::new("setpriv")
            .args(["--reuid", NOBODY, "--regid", NOBODY, "--clear-groups", "--"])
            .args(&args),
        &logs.path().join("ctl.log"),
    );
    let link = format!(
        "CAN link: {iface} up, bitrate none (virtual interface), state none (virtual interface)"
    );
    assert!(
        ctl.wait_for_log(&link, Duration::from_secs(60)),
        "no link report; log:\n{}",
        ctl.log_tail(40)
    );
    std::thread::sleep(Duration::from_secs(2));
    ctl.assert_running();
    ctl.signal("15");
    let status = ctl.wait_timeout(Duration::from_secs(10));
    let raw = std::fs::read_to_string(logs.path().join("ctl.log")).unwrap();
    assert!(
        status.is_some_and(|s| s.success()),
        "{status:?}; log:\n{}",
        ctl.log_tail(40)
    );
    assert!(raw.contains("listen_only=true"), "{raw}");
    assert!(
        !raw.contains('\x1b'),
        "ANSI escapes in the journal's text: {raw:?}"
    );
}
