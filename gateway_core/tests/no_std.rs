//! The gateway core stays portable: the crate is `#![no_std]` without `alloc`, and nothing in its
//! dependency tree turns on a `std` or `alloc` feature (so a dependency cannot bring the standard
//! library in behind the crate's back). `scripts/build-mcu` proves it on a target without `std`.

use std::process::Command;

#[test]
fn the_crate_is_no_std_without_alloc() {
    let lib = include_str!("../src/lib.rs");
    assert!(
        lib.lines().any(|l| l.trim() == "#![no_std]"),
        "src/lib.rs must say #![no_std]"
    );
    // `std` only for the tests and the host conveniences of the `std` feature.
    assert!(lib.contains("#[cfg(any(test, feature = \"std\"))]\nextern crate std;"));
    assert!(
        !lib.contains("extern crate alloc"),
        "the core does not allocate"
    );
}

#[test]
fn no_dependency_enables_std_or_alloc() {
    // The library's own dependencies with their features as built without the `std` feature
    // (`-e normal`: dev-dependencies, which enable `std` for the tests, are left out).
    let out = Command::new(env!("CARGO"))
        .args([
            "tree",
            "--offline",
            "--manifest-path",
            concat!(env!("CARGO_MANIFEST_DIR"), "/Cargo.toml"),
            "-p",
            "gateway_core",
            "-e",
            "normal,features",
            "--prefix",
            "none",
        ])
        .output()
        .expect("run cargo tree");
    assert!(
        out.status.success(),
        "cargo tree failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let tree = String::from_utf8_lossy(&out.stdout);
    for crate_name in ["aes", "cmac", "crc", "libm", "embedded-can", "thiserror"] {
        assert!(
            tree.lines()
                .any(|l| l.starts_with(&format!("{crate_name} v"))),
            "{crate_name} missing from the tree:\n{tree}"
        );
    }
    let offending: Vec<&str> = tree
        .lines()
        .filter(|l| l.contains("feature \"std\"") || l.contains("feature \"alloc\""))
        .collect();
    assert!(
        offending.is_empty(),
        "features that need the standard library: {offending:?}"
    );
}
