//! The recordings of physical sensors in `shared/data/real` (beside the repository) all read, with the right
//! shape; expected counts were taken from the files with awk.

use std::path::{Path, PathBuf};

use magcal_recording::{Date, MissingCounts, ReadErrorKind, Recording};

const REAL: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/data/real");

fn real(rel: &str) -> PathBuf {
    Path::new(REAL).join(rel)
}

fn read(rel: &str) -> Recording {
    Recording::read(&real(rel)).unwrap_or_else(|e| panic!("{e}"))
}

/// All `.csv` files under `dir`, recursively.
fn csv_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display())) {
        let path = entry.unwrap().path();
        if path.is_dir() {
            csv_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "csv") {
            out.push(path);
        }
    }
}

#[test]
fn every_real_recording_reads() {
    let mut files = Vec::new();
    csv_files(Path::new(REAL), &mut files);
    let mut recordings = 0;
    for path in files {
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        let result = Recording::read(&path);
        if name.ends_with("_android_hardiron.csv") || name == "published_calibration_counts.csv" {
            // Plain CSVs beside the recordings, not recordings.
            let err = result.expect_err(&name);
            assert!(
                matches!(err.kind(), ReadErrorKind::MissingColumn("mx")),
                "{err}"
            );
            continue;
        }
        let rec = result.unwrap_or_else(|e| panic!("{e}"));
        assert!(rec.len() > 1000, "{name}: {} rows", rec.len());
        assert!(
            rec.meta.sensor.is_some() && rec.meta.sample_rate_hz.is_some(),
            "{name}"
        );
        recordings += 1;
    }
    assert!(
        recordings >= 7,
        "found {recordings} recordings under {REAL}"
    );
}

#[test]
fn nexus5_nodist_reports_nan_quaternions_as_missing() {
    let rec = read("inria-nexus5/nexus5_nodist_AR.csv");
    assert_eq!(
        rec.missing_counts(),
        MissingCounts {
            rows: 6323,
            temp: None,
            quat: Some(3157),
            reference: None,
            gyro: Some(1771),
            currents: vec![]
        }
    );
    assert_eq!(
        rec.meta.date,
        Some(Date {
            year: 2016,
            month: 6,
            day: 2
        })
    );
    assert_eq!(rec.meta.field_ned_ut, Some([22.74, 0.58, 36.02]));
    assert_eq!(rec.meta.other[0], ("units".to_owned(), "uT".to_owned()));
    assert!(
        rec.meta.other[1]
            .1
            .starts_with("fitted against the Qualisys reference")
    );
    let t = rec.t_s.as_ref().unwrap();
    assert_eq!(t[0], -2.426);
    // The reference is good in 0 <= t < 64 s but for 11 rows, absent from 64 s to 120 s.
    let quat = rec.quat.as_ref().unwrap();
    let missing_in = |lo: f64, hi: f64| {
        t.iter()
            .zip(quat)
            .filter(|(t, _)| (lo..hi).contains(*t))
            .filter(|(_, q)| q[0].is_nan())
            .count()
    };
    assert_eq!(missing_in(0.0, 64.0), 11);
    let rows_64_120 = t.iter().filter(|t| (64.0..120.0).contains(*t)).count();
    assert_eq!(missing_in(64.0, 120.0), rows_64_120);
    for q in quat.iter().filter(|q| !q[0].is_nan()) {
        assert!((q.iter().map(|v| v * v).sum::<f64>() - 1.0).abs() < 1e-12);
    }
}

#[test]
fn row_counts_and_missing_values_of_the_other_recordings() {
    let broad = read("broad/broad_02_undisturbed_slow_rotation.csv");
    assert_eq!(broad.len(), 26620);
    assert_eq!(
        broad.missing_counts().quat,
        Some(853),
        "empty fields are missing values"
    );
    assert_eq!(broad.meta.location.map(|l| l.lat_deg), Some(52.51));
    assert_eq!(broad.meta.other.len(), 2);

    let sphere = read("hmc5883l/set2_full_sphere.csv");
    assert_eq!(sphere.len(), 8190);
    let counts = sphere.missing_counts();
    assert_eq!(
        (counts.temp, counts.gyro, counts.quat),
        (Some(2), Some(2), None)
    );
    assert_eq!(
        sphere.meta.routine.as_deref(),
        Some("hand-held full sphere")
    );

    assert_eq!(
        read("hmc5883l/set2_unmoved_x_forward_10min.csv").len(),
        50401
    );
    let dance = read("inria-nexus5/nexus5_calib_dance.csv");
    assert_eq!(dance.len(), 4204);
    assert!(dance.quat.is_none() && dance.gyro_rad_s.is_some());
    let filtered = read("qmc5883l/qmc5883l_filtered_raw.csv");
    assert_eq!(filtered.len(), 22745);
    assert_eq!(filtered.layout().column_names(), ["t", "mx", "my", "mz"]);
    assert_eq!(read("qmc5883l/qmc5883l_noisy_raw.csv").len(), 22743);
}

#[test]
fn real_recordings_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    for rel in [
        "inria-nexus5/nexus5_nodist_AR.csv",
        "broad/broad_02_undisturbed_slow_rotation.csv",
    ] {
        let first = read(rel);
        let path = dir.path().join("copy.csv");
        first.write(&path).unwrap();
        let second = Recording::read(&path).unwrap();
        assert_eq!(first.meta, second.meta, "{rel}");
        assert_eq!(first.missing_counts(), second.missing_counts(), "{rel}");
        for (a, b) in first.rows().zip(second.rows()) {
            assert_eq!(
                a.t_s, b.t_s,
                "{rel}: t has 6 decimals in the file, kept exactly"
            );
            assert_eq!(
                a.mag_ut, b.mag_ut,
                "{rel}: 6 decimals in the file, kept exactly"
            );
            let dq = a
                .quat
                .iter()
                .zip(&b.quat)
                .map(|(x, y)| (x - y).abs())
                .fold(0.0, f64::max);
            assert!(dq < 1e-9, "{rel}: quaternion moved by {dq}");
        }
    }
}
