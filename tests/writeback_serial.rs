//! Acceptance, over a pseudo-terminal: `magcal-fit --write-to serial:…` sends MotionCal's calibration packet, the
//! simulated firmware checks its CRC, stores it and echoes it, and the tool confirms; a firmware that echoes a wrong
//! value makes the write a failed verification, and the parameters file is written all the same.

mod pty;

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use magcal_app::source::sim::bench_config;
use magcal_driver::ChipKind;
use magcal_mockhw::firmware::{EchoMode, FirmwareConfig, FirmwareReport};
use nalgebra::{Matrix3, Vector3};

/// A simulated cube24 recording (a vector fit, so A is not symmetric and the packet needs the polar factor).
fn recording(dir: &Path) -> PathBuf {
    common::sim_recording(dir, "sim:lis3mdl", "cube24")
}

/// Runs `magcal-fit REC --out --report --write-to serial:PTY` against a firmware echoing as `echo`.
fn fit_and_write(dir: &Path, echo: EchoMode) -> (Output, FirmwareReport) {
    let rec = recording(dir);
    let pty = pty::open();
    let mut config = FirmwareConfig::new(bench_config(ChipKind::Lis3mdl, 2));
    config.echo = echo;
    let stop = Arc::new(AtomicBool::new(false));
    let board = pty::firmware(pty.master, config, stop.clone());
    let out = Command::new(env!("CARGO_BIN_EXE_magcal-fit"))
        .arg(&rec)
        .args(["--out", dir.join("params.toml").to_str().unwrap()])
        .args(["--report", dir.join("report.json").to_str().unwrap()])
        .args(["--write-to", &format!("serial:{}", pty.slave_path)])
        .output()
        .unwrap();
    stop.store(true, Ordering::Relaxed);
    (out, board.join().unwrap())
}

#[test]
fn the_packet_is_sent_checked_stored_and_confirmed() {
    let dir = tempfile::tempdir().unwrap();
    let (out, board) = fit_and_write(dir.path(), EchoMode::Faithful);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        stdout.contains("the firmware's echo confirmed it"),
        "{stdout}"
    );
    assert!(
        stdout.contains("rotation in A"),
        "a vector fit's rotation is reported: {stdout}"
    );
    assert_eq!((board.packets_accepted, board.packets_rejected), (1, 0));

    // What the board holds is MotionCal's form of the fit: V = −A⁻¹·b, S the symmetric polar factor of A.
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("report.json")).unwrap())
            .unwrap();
    let cal = &report["calibration"];
    let a = Matrix3::from_fn(|j, k| cal["A"][j][k].as_f64().unwrap());
    let b = Vector3::from_fn(|k, _| cal["b_ut"][k].as_f64().unwrap());
    let v = -(a.try_inverse().unwrap() * b);
    let svd = a.svd(true, true);
    let v_t = svd.v_t.unwrap();
    let s = v_t.transpose() * Matrix3::from_diagonal(&svd.singular_values) * v_t;
    let held = board.calibration;
    let close = |got: f32, want: f64, what: &str| {
        assert!(
            (f64::from(got) - want).abs() < 1e-4 * want.abs().max(1.0),
            "{what}: {got} vs {want}"
        );
    };
    for k in 0..3 {
        close(held[6 + k], v[k], "hard iron");
        close(held[10 + k], s[(k, k)], "soft iron diagonal");
    }
    close(held[13], s[(0, 1)], "S01");
    close(held[14], s[(0, 2)], "S02");
    close(held[15], s[(1, 2)], "S12");
    close(
        held[9],
        (19.8f64 * 19.8 + 1.2 * 1.2 + 45.3 * 45.3).sqrt(),
        "field",
    );
}

#[test]
fn a_corrupted_echo_is_a_failed_verification_and_the_parameters_are_still_written() {
    let dir = tempfile::tempdir().unwrap();
    let (out, board) = fit_and_write(dir.path(), EchoMode::CorruptHardIron);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        stderr.contains("verification failed") && stderr.contains("hard_iron_ut[1]"),
        "{stderr}"
    );
    assert_eq!(
        board.packets_accepted, 1,
        "the board took the packet; its echo is wrong"
    );
    let params =
        std::fs::read_to_string(dir.path().join("params.toml")).expect("params.toml written first");
    assert!(params.contains("magcal-params v1"));
}
