//! Acceptance (issue 9): every tool's `-h` and `--help` open with what the tool is for, not the package description.

use std::process::Command;

/// Each tool and a word its first help line must hold.
const TOOLS: [(&str, &str); 7] = [
    (env!("CARGO_BIN_EXE_magcal"), "workflow"),
    (env!("CARGO_BIN_EXE_magcal-fit"), "Fit"),
    (env!("CARGO_BIN_EXE_magcal-batch"), "recording of a lot"),
    (env!("CARGO_BIN_EXE_magcal-apply"), "Check a calibration"),
    (env!("CARGO_BIN_EXE_magcal-record"), "Record"),
    (env!("CARGO_BIN_EXE_magcal-sim"), "simulated recording"),
    (env!("CARGO_BIN_EXE_magcal-paper"), "seed paper"),
];

#[test]
fn every_help_opens_with_what_the_tool_is_for() {
    let package = env!("CARGO_PKG_DESCRIPTION");
    for (tool, word) in TOOLS {
        for flag in ["-h", "--help"] {
            let out = Command::new(tool).arg(flag).output().unwrap();
            assert!(out.status.success(), "{tool} {flag}");
            let text = String::from_utf8(out.stdout).unwrap();
            let first = text.lines().next().unwrap_or("");
            assert!(first.contains(word), "{tool} {flag}: {first:?}");
            assert!(
                !text.contains(package),
                "{tool} {flag} shows the package description"
            );
        }
    }
}
