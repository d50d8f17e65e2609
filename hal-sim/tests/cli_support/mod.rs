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

/// Runs `piezo` with `args` and fails the test unless it succeeds; its output.
pub fn piezo(args: &[&dyn AsRef<std::ffi::OsStr>]) -> Output {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_piezo"))
        .args(args.iter().map(|a| a.as_ref()))
        .output()
        .unwrap();
    ok(&out);
    out
}
