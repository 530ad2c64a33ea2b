//! `magcal-fit --write-to` for chips: the LIS2MDL's offset registers get the hard-iron offset and are read back; a
//! chip that does not keep what was written fails the verification; chips without offset registers are refused with
//! a reason; the parameters file is written before the device is tried.

mod common;

use std::cell::RefCell;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::rc::Rc;

use magcal_app::source::sim::bench_config;
use magcal_app::writeback::{WriteBackError, write_lis2mdl_offset};
use magcal_driver::ChipKind;
use magcal_mockhw::{Fault, SimChip, VirtualClock};
use magcal_sim::bench::Bench;

/// A simulated free-rotation recording of the chip `device` names (`sim:CHIP`).
fn recording(dir: &Path, device: &str) -> PathBuf {
    common::sim_recording(dir, device, "free")
}

/// Fits a recording of the chip `device` names and writes it to `device`.
fn fit_to(dir: &Path, device: &str) -> Output {
    fit_recording_of(dir, device, device)
}

/// Fits a recording of `recorded` and writes it to `device`.
fn fit_recording_of(dir: &Path, recorded: &str, device: &str) -> Output {
    Command::new(env!("CARGO_BIN_EXE_magcal-fit"))
        .arg(recording(dir, recorded))
        .args(["--out", dir.join("params.toml").to_str().unwrap()])
        .args(["--report", dir.join("report.json").to_str().unwrap()])
        .args(["--write-to", device])
        .output()
        .unwrap()
}

#[test]
fn the_lis2mdl_offset_registers_get_the_fitted_offset_and_read_it_back() {
    let dir = tempfile::tempdir().unwrap();
    let out = fit_to(dir.path(), "sim:lis2mdl");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("report.json")).unwrap())
            .unwrap();
    // The device holds A and b only: the final model's when it has no body-fixed corrections, the fit without them
    // (what `--no-diagnose` gives) when it has.
    let offset = if report["calibration"]["corrections"]
        .as_array()
        .unwrap()
        .is_empty()
    {
        common::floats(&report["calibration"]["offset_ut"])
    } else {
        let base = common::fit_report(&dir.path().join("rec.csv"), &["--no-diagnose"]);
        common::floats(&base["calibration"]["offset_ut"])
    };
    let line = stdout
        .lines()
        .find(|l| l.starts_with("sim:lis2mdl: wrote the hard-iron offset ["))
        .unwrap_or_else(|| panic!("no write-back line in\n{stdout}"));
    let numbers = |text: &str| -> Vec<f64> {
        let inside = &text[text.find('[').unwrap() + 1..text.find(']').unwrap()];
        inside.split(", ").map(|v| v.parse().unwrap()).collect()
    };
    let (wrote, held) = line.split_once("read back").unwrap();
    let (wrote, held) = (numbers(wrote), numbers(held));
    for k in 0..3 {
        assert!((wrote[k] - offset[k]).abs() < 1e-3, "{line}");
        assert!((held[k] - offset[k]).abs() <= 0.075 + 1e-3, "{line}");
        let steps = held[k] / 0.15;
        assert!(
            (steps - steps.round()).abs() < 0.01,
            "{line}: the registers hold 0.15 µT steps"
        );
    }
}

#[test]
fn chips_without_offset_registers_are_refused_after_the_parameters_are_written() {
    let dir = tempfile::tempdir().unwrap();
    let out = fit_to(dir.path(), "sim:qmc5883l");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        stderr.contains("sim:qmc5883l: the qmc5883l has no offset registers to hold a calibration"),
        "{stderr}"
    );
    assert!(dir.path().join("params.toml").exists());
}

#[test]
fn another_chips_calibration_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let out = fit_recording_of(dir.path(), "sim:lis3mdl", "sim:lis2mdl");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        stderr
            .contains("sim:lis2mdl: the recording is of a lis3mdl (its metadata: `sensor: lis3mdl"),
        "{stderr}"
    );
    assert!(dir.path().join("params.toml").exists());
}

#[test]
fn a_missing_bus_is_an_error_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let out = fit_recording_of(
        dir.path(),
        "sim:lis2mdl",
        "i2c:/dev/i2c-no-such-bus:lis2mdl",
    );
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        stderr.contains("i2c:/dev/i2c-no-such-bus:lis2mdl: cannot open the bus"),
        "{stderr}"
    );
}

fn twin(faults: &[Fault]) -> SimChip {
    let bench = Bench::new(bench_config(ChipKind::Lis2mdl, 1)).unwrap();
    let mut chip = SimChip::new(
        ChipKind::Lis2mdl,
        Rc::new(RefCell::new(bench)),
        VirtualClock::new(),
    );
    for f in faults {
        chip.inject(*f);
    }
    chip
}

#[test]
fn what_the_chip_holds_is_checked() {
    let offset = [-18.99, 3.53, 28.34];
    let held = write_lis2mdl_offset(twin(&[]), 0x1E, "sim:lis2mdl", offset).unwrap();
    assert!(
        (0..3).all(|k| (held[k] - offset[k]).abs() <= 0.075),
        "{held:?}"
    );

    // A chip that acknowledges the write but keeps its old offset.
    let err = write_lis2mdl_offset(
        twin(&[Fault::IgnoreWrites { at_s: 0.0 }]),
        0x1E,
        "sim:lis2mdl",
        offset,
    )
    .unwrap_err();
    assert!(matches!(err, WriteBackError::Verification { .. }), "{err}");
    assert_eq!(
        err.to_string(),
        "sim:lis2mdl: verification failed: wrote the offset [-18.990, 3.530, 28.340] µT, the chip holds \
         [0.000, 0.000, 0.000] µT"
    );

    // A bus that fails.
    let err = write_lis2mdl_offset(
        twin(&[Fault::DropBus { at_s: 0.0 }]),
        0x1E,
        "sim:lis2mdl",
        offset,
    )
    .unwrap_err();
    assert!(
        err.to_string()
            .starts_with("sim:lis2mdl: identifying the LIS2MDL: I2C bus error"),
        "{err}"
    );

    // Another chip at the address.
    let bench = Bench::new(bench_config(ChipKind::Hmc5883l, 1)).unwrap();
    let hmc = SimChip::new(
        ChipKind::Hmc5883l,
        Rc::new(RefCell::new(bench)),
        VirtualClock::new(),
    );
    let err = write_lis2mdl_offset(hmc, 0x1E, "i2c:/dev/i2c-1:lis2mdl", offset).unwrap_err();
    assert!(
        err.to_string().contains("wrong chip id: expected 0x40"),
        "{err}"
    );
}
