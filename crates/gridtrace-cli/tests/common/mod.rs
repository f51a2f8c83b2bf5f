//! Shared by the CLI's integration tests.

use std::process::Command;

/// Runs the `gridtrace` binary; whether it succeeded, and its stdout then stderr.
pub fn gridtrace(args: &[&str]) -> (bool, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_gridtrace"))
        .args(args)
        .output()
        .expect("run gridtrace");
    let text = String::from_utf8_lossy(&out.stdout).to_string() + &String::from_utf8_lossy(&out.stderr);
    (out.status.success(), text)
}
