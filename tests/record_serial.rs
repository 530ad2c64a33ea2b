//! Acceptance, over a pseudo-terminal: a simulated MotionCal-style board streams `Raw:` lines with garbage mixed in,
//! then is unplugged; `magcal-record --device serial:…` records every sample, counts the garbage, and leaves a
//! valid file.

mod pty;

use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use magcal_app::record::sim::bench_config;
use magcal_driver::ChipKind;
use magcal_mockhw::firmware::FirmwareConfig;
use magcal_recording::Recording;

#[test]
fn every_raw_line_is_recorded_garbage_is_counted_and_an_unplug_leaves_a_valid_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("serial.csv");
    let pty = pty::open();
    let device = format!("serial:{}:115200:motioncal", pty.slave_path);
    let mut child = Command::new(env!("CARGO_BIN_EXE_magcal-record"))
        .args([
            "--device",
            &device,
            "--routine",
            "free",
            "--coverage",
            "1",
            "--out",
        ])
        .arg(&path)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // The board starts streaming once the recorder has the port open.
    let mut stdout = BufReader::new(child.stdout.take().unwrap()).lines();
    let first = stdout.next().unwrap().unwrap();
    assert!(first.starts_with(&format!("recording {device}")), "{first}");
    let drain = std::thread::spawn(move || stdout.map(Result::unwrap).collect::<Vec<String>>());

    let mut config = FirmwareConfig::new(bench_config(ChipKind::Lis3mdl, 5));
    config.raw_lines = Some(1500);
    config.garbage_every = Some(37);
    config.lines_per_wall_s = 3000.0;
    let report = pty::firmware(pty.master, config, Arc::new(AtomicBool::new(false)))
        .join()
        .unwrap();
    assert_eq!((report.raw_lines, report.garbage_lines), (1500, 40));

    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    let stdout = drain.join().unwrap().join("\n");
    assert!(
        !out.status.success(),
        "an unplug mid-routine is an error: {stdout}"
    );
    assert!(
        stderr.contains(&format!("{device}: disconnected after 1500 samples"))
            && stderr.contains("keeps the 1500 samples recorded before")
            && stderr.contains("garbage lines skipped: 40 (binary 10, field_count 10, bad_number 10, unrecognized 10)"),
        "{stderr}"
    );
    let rec = Recording::read(&path).expect("the file is valid after the unplug");
    assert_eq!(rec.len(), 1500);
    assert_eq!(rec.meta.routine.as_deref(), Some("free"));
    // The samples are the bench's field through the simulated sensor: about the world's magnitude, offset by the
    // hard iron, and quantised to MotionCal's 0.1 µT.
    for m in &rec.mag_ut {
        let norm = (m[0] * m[0] + m[1] * m[1] + m[2] * m[2]).sqrt();
        assert!((5.0..130.0).contains(&norm), "{m:?}");
        assert!(
            m.iter()
                .all(|v| ((v * 10.0) - (v * 10.0).round()).abs() < 1e-6),
            "{m:?}"
        );
    }
}
