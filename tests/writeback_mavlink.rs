//! Acceptance (issue 35, 1's write-back half and 5's write-back case), over a pseudo-terminal: `magcal-fit
//! --write-to mavlink:…` sets a fitted calibration in the autopilot twin — ArduPilot and PX4, told apart by the
//! heartbeat — and what the twin then holds is the `--export` of the same fit; the undo file holds the values before,
//! and loading it gives them back. A parameter the autopilot refuses stops the write-back, names the parameter, exits
//! non-zero and leaves every parameter as it was; a port that speaks no MAVLink is said to be one. The write-back
//! and its undo are also made over UDP.

mod pty;

use pty::{Twin, same};

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use magcal_app::device::DeviceSpec;
use magcal_app::source::sim::bench_config;
use magcal_app::writeback::load_param_file;
use magcal_autopilot::{Autopilot, parse_param_file};
use magcal_driver::ChipKind;
use magcal_mockhw::autopilot::TwinConfig;
use magcal_mockhw::firmware::FirmwareConfig;

/// A simulated recording (a tumble with an attitude reference), made once per test.
fn recording(dir: &Path) -> PathBuf {
    let rec = dir.join("rec.csv");
    let out = Command::new(env!("CARGO_BIN_EXE_magcal-sim"))
        .args(["--duration", "40", "--seed", "35", "--out"])
        .arg(&rec)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    rec
}

fn fit(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_magcal-fit"))
        .args(args)
        .output()
        .unwrap()
}

/// The twin of `autopilot` with non-default calibration parameters (what the vehicle held before) and the parameter
/// `ranges` it refuses values outside of.
fn twin_config(autopilot: Autopilot, ranges: Vec<(String, f64, f64)>) -> TwinConfig {
    let mut config = TwinConfig::new(autopilot, bench_config(ChipKind::Lis3mdl, 3));
    config.speed = 1.0;
    config.values = match autopilot {
        Autopilot::ArduPilot => vec![
            ("COMPASS_OFS_X".into(), -35.0),
            ("COMPASS_OFS_Z".into(), 12.5),
            ("COMPASS_DIA_Y".into(), 1.02),
        ],
        Autopilot::Px4 => vec![
            ("CAL_MAG0_XOFF".into(), 0.035),
            ("CAL_MAG0_ZOFF".into(), -0.0125),
            ("CAL_MAG0_YSCALE".into(), 1.02),
        ],
    };
    config.ranges = ranges;
    config
}

/// What [`twin_config`] gives a parameter before any write-back.
fn twin_default(name: &str) -> f64 {
    let set = [
        ("COMPASS_OFS_X", -35.0),
        ("COMPASS_OFS_Z", 12.5),
        ("COMPASS_DIA_Y", 1.02),
        ("CAL_MAG0_XOFF", 0.035),
        ("CAL_MAG0_ZOFF", -0.0125),
        ("CAL_MAG0_YSCALE", 1.02),
    ];
    set.iter().find(|(n, _)| *n == name).map_or_else(
        || {
            if name.contains("DIA_") || name.contains("SCALE") {
                1.0
            } else {
                0.0
            }
        },
        |(_, v)| *v,
    )
}

/// The export's parameters of the same fit, by name.
fn exported(rec: &Path, dir: &Path, format: &str) -> Vec<(String, f64)> {
    let path = dir.join(format!("export.{format}"));
    let out = fit(&[
        rec.to_str().unwrap(),
        "--export",
        format,
        "--export-out",
        path.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    parse_param_file(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// Writes the fit of `rec` to `twin` at `device` (`mavlink:…`) and checks it as a ground station would: the
/// write-back says each parameter was confirmed and read back; the twin holds the `--export` of the same fit; the undo
/// file, next to the parameters file, holds the values before; loading it over `device` gives them back.
fn writes_back_and_undoes(rec: &Path, dir: &Path, autopilot: Autopilot, twin: Twin, device: &str) {
    let format = autopilot.name();
    let want = exported(rec, dir, format);
    assert_eq!(want.len(), 9);
    let params = dir.join(format!("{format}.toml"));
    let out = fit(&[
        rec.to_str().unwrap(),
        "--out",
        params.to_str().unwrap(),
        "--write-to",
        device,
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        stdout.contains(&format!(
            "{device}: {autopilot} (by its heartbeat): set 9 parameters, each confirmed by the autopilot and read back"
        )),
        "{stdout}"
    );
    // The undo file, next to the parameters file, holds the values before.
    let undo = dir.join(format!("{format}.undo.param"));
    let old = parse_param_file(&std::fs::read_to_string(&undo).unwrap()).unwrap();
    assert_eq!(old.len(), 9);
    // Read back as a ground station: the export's values.
    twin.assert_holds(&want, &autopilot.to_string());
    let names: Vec<&str> = want.iter().map(|(n, _)| n.as_str()).collect();
    // The write-back's own read-back lines say the same.
    for (name, value) in &want {
        let line = stdout
            .lines()
            .find(|l| l.trim_start().starts_with(&format!("{name} ")))
            .unwrap_or_else(|| panic!("{name} in {stdout}"));
        let shown: f64 = line.split_whitespace().nth(1).unwrap().parse().unwrap();
        assert!(same(name, shown, *value), "{name}: {shown} vs {value}");
    }
    // Loading the undo file gives the old values back.
    let spec: DeviceSpec = device.parse().unwrap();
    let lines = load_param_file(&spec, &undo).unwrap();
    assert!(lines[0].contains("loaded 9 parameters"), "{lines:?}");
    let restored = twin.read(&names);
    let report = twin.finish();
    for ((name, value), (_, r)) in old.iter().zip(&restored) {
        assert_eq!(*r as f32, *value as f32, "{name}");
        assert_eq!(
            report.param(name).map(|v| v as f32),
            Some(*value as f32),
            "{name}"
        );
    }
    for (name, value) in &old {
        assert_eq!(
            *value as f32,
            twin_default(name) as f32,
            "the undo file holds what the twin held before: {name}"
        );
    }
    assert!(report.sets_taken >= 18, "{}", report.sets_taken);
}

#[test]
fn a_fit_written_to_each_autopilot_reads_back_as_its_export_and_the_undo_file_restores_the_old_values()
 {
    let dir = tempfile::tempdir().unwrap();
    let rec = recording(dir.path());
    for autopilot in [Autopilot::ArduPilot, Autopilot::Px4] {
        let twin = Twin::start(twin_config(autopilot, Vec::new()));
        let device = format!("mavlink:{}:115200", twin.path);
        writes_back_and_undoes(&rec, dir.path(), autopilot, twin, &device);
    }
}

/// The same over UDP (`mavlink:udp:HOST:PORT`): PX4 as a simulator sending to the tools' port, ArduPilot as a
/// router's server endpoint the tools send to first.
#[test]
fn a_fit_written_over_udp_reads_back_as_its_export_and_the_undo_file_restores_the_old_values() {
    let dir = tempfile::tempdir().unwrap();
    let rec = recording(dir.path());
    for autopilot in [Autopilot::Px4, Autopilot::ArduPilot] {
        // Each of its turns ends in a read that waits 20 ms for a datagram, so it turns at most 50 times a wall
        // second: at 10 Hz and 5 times real time its heartbeat (each bench second), which each connection waits for,
        // comes 5 times a wall second.
        let mut config = twin_config(autopilot, Vec::new());
        (config.rate_hz, config.speed) = (10.0, 5.0);
        let twin = Twin::start_udp(config, autopilot == Autopilot::ArduPilot);
        let device = format!("mavlink:{}", twin.path);
        writes_back_and_undoes(&rec, dir.path(), autopilot, twin, &device);
    }
}

#[test]
fn a_refused_parameter_stops_the_write_back_names_it_and_leaves_the_previous_values() {
    let dir = tempfile::tempdir().unwrap();
    let rec = recording(dir.path());
    for (autopilot, refused) in [
        (Autopilot::ArduPilot, "COMPASS_DIA_Y"),
        (Autopilot::Px4, "CAL_MAG0_YSCALE"),
    ] {
        // Its range excludes whatever the fit gives.
        let twin = Twin::start(twin_config(autopilot, vec![(refused.to_owned(), 5.0, 6.0)]));
        let device = format!("mavlink:{}", twin.path);
        let undo = dir.path().join(format!("{}.undo.param", autopilot.name()));
        let out = fit(&[
            rec.to_str().unwrap(),
            "--write-to",
            &device,
            "--undo-out",
            undo.to_str().unwrap(),
        ]);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{stderr}");
        assert!(
            stderr.contains(&format!(
                "verification failed: {refused}: the autopilot refused"
            )),
            "{stderr}"
        );
        assert!(
            stderr.contains("the 4 parameter(s) already written were set back to their previous values and confirmed"),
            "{stderr}"
        );
        assert!(
            stderr.contains("the autopilot keeps its previous values"),
            "{stderr}"
        );
        let old = parse_param_file(&std::fs::read_to_string(&undo).unwrap()).unwrap();
        let report = twin.finish();
        assert_eq!(report.sets_refused, 1);
        for (name, value) in &old {
            assert_eq!(
                report.param(name).map(|v| v as f32),
                Some(*value as f32),
                "{name}"
            );
        }
        // An undo file is never replaced: a second write-back names another.
        let again = fit(&[
            rec.to_str().unwrap(),
            "--write-to",
            &device,
            "--undo-out",
            undo.to_str().unwrap(),
        ]);
        let stderr = String::from_utf8_lossy(&again.stderr);
        assert!(
            !again.status.success() && stderr.contains("the file exists"),
            "{stderr}"
        );
    }
}

#[test]
fn a_port_that_speaks_no_mavlink_is_said_to_be_one_and_nothing_is_written() {
    let dir = tempfile::tempdir().unwrap();
    let rec = recording(dir.path());
    let pty = pty::open();
    let stop = Arc::new(AtomicBool::new(false));
    let board = pty::firmware(
        pty.master.try_clone().unwrap(),
        FirmwareConfig::new(bench_config(ChipKind::Lis3mdl, 4)),
        stop.clone(),
    );
    let undo = dir.path().join("undo.param");
    let out = fit(&[
        rec.to_str().unwrap(),
        "--write-to",
        &format!("mavlink:{}", pty.slave_path),
        "--undo-out",
        undo.to_str().unwrap(),
    ]);
    stop.store(true, Ordering::Relaxed);
    board.join().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(stderr.contains("and no MAVLink frame in them"), "{stderr}");
    assert!(stderr.contains("It sends: Raw:"), "{stderr}");
    assert!(stderr.contains("nothing was written"), "{stderr}");
    assert!(!undo.exists());
}
