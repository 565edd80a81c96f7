//! Helpers shared by the tests that run the `ribreg` binary (each test binary uses a
//! subset of them).
#![allow(dead_code)]

use std::path::Path;
use std::process::{Command, Output};

/// Runs the `ribreg` binary built for these tests.
pub fn ribreg(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_ribreg"))
        .args(args)
        .output()
        .expect("the binary runs")
}

/// A temporary path as an argument.
pub fn s(p: &Path) -> &str {
    p.to_str().expect("temp paths are UTF-8")
}

/// The stdout of a run that must have succeeded (its stderr in the failure message).
pub fn stdout(o: &Output) -> String {
    assert!(
        o.status.success(),
        "stderr: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8_lossy(&o.stdout).into_owned()
}
