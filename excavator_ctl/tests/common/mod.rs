//! Helpers shared by the integration tests that use third-party tools.

/// `have`, or else a skip message, or a failure where the tools are required (CI,
/// scripts/test-all, which installs them with scripts/install-test-tools).
pub fn have_or_skip(have: bool, what: &str) -> bool {
    if !have {
        assert!(
            std::env::var("EXCAVATOR_REQUIRE_TOOLS").as_deref() != Ok("1"),
            "{what} is required (scripts/install-test-tools)"
        );
        println!("skip: no {what} (scripts/install-test-tools installs it)");
    }
    have
}
