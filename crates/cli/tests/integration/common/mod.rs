//! Running the `volmorph` binary from the end-to-end tests.

#![allow(dead_code)] // each test file uses its own subset

use std::process::{Command, Output};

/// Run `volmorph` with `args`.
pub fn volmorph(args: &[&dyn AsRef<std::ffi::OsStr>]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_volmorph"))
        .args(args.iter().map(|a| a.as_ref()))
        .output()
        .expect("the volmorph binary runs")
}

/// Runs a command that must succeed; returns its standard output.
pub fn ok(args: &[&dyn AsRef<std::ffi::OsStr>]) -> String {
    let out = volmorph(args);
    assert!(
        out.status.success(),
        "volmorph failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).expect("utf-8 output")
}

/// Runs a command that must fail cleanly; returns its standard error.
pub fn fails(args: &[&dyn AsRef<std::ffi::OsStr>]) -> String {
    let out = volmorph(args);
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(1), "expected exit 1, stderr: {err}");
    assert!(!err.contains("panicked"), "panic: {err}");
    err
}
