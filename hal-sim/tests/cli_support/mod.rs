//! Running the `piezo` binary from integration tests.
use std::process::Output;

/// Fails the test with the command's stderr unless it exited successfully.
pub fn ok(out: &Output) {
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}
