//! Attitude references in another convention than magcal's, on the physical recordings: as given, none is taken
//! for one; with their quaternions rewritten as loggers also write them, the convention is named, and `magcal-fit`
//! says so in its verdict with or without the diagnosis.

mod common;

use common::{magcal_fit, real};
use magcal_calib::convention::{Convention, better_convention, clock_offset};
use magcal_calib::frames;
use magcal_recording::Recording;

/// The physical recordings with an attitude reference and a world field.
const WITH_ATTITUDE: [&str; 5] = [
    "broad/broad_02_undisturbed_slow_rotation.csv",
    "broad/broad_29_disturbed_stationary_magnet_B.csv",
    "broad/broad_33_disturbed_attached_magnet_2cm.csv",
    "inria-nexus5/nexus5_nodist_AR.csv",
    "inria-nexus5/nexus5_dist_AR.csv",
];

/// The recording's readings, attitude and field.
fn read(rel: &str) -> (Vec<[f64; 3]>, Vec<[f64; 4]>, [f64; 3]) {
    let rec = Recording::read(&real(rel)).unwrap();
    let field = rec.meta.field_ned_ut.expect("a field in the metadata");
    (rec.mag_ut, rec.quat.expect("quaternions"), field)
}

/// The attitude and field as a logger in convention `c` writes what magcal reads as `quat` and `field`.
fn written_in(c: Convention, quat: &[[f64; 4]], field: [f64; 3]) -> (Vec<[f64; 4]>, [f64; 3]) {
    let quat = quat.iter().map(|&q| c.written(q, field).0).collect();
    (quat, c.written([1.0, 0.0, 0.0, 0.0], field).1)
}

#[test]
fn physical_recordings_in_magcals_convention_are_left_alone() {
    for rel in WITH_ATTITUDE {
        let (raw, quat, field) = read(rel);
        assert_eq!(better_convention(&raw, &quat, field, None), None, "{rel}");
        // Nor out of step with their readings (the Nexus 5's reference lags by 25 ms: the diagnosis' time_lag).
        let expected: Vec<[f64; 3]> = quat
            .iter()
            .map(|q| frames::expected_sensor_field(*q, field))
            .collect();
        let t = Recording::read(&real(rel)).unwrap().t_s.unwrap();
        assert_eq!(clock_offset(&raw, &expected, &t, None), None, "{rel}");
    }
}

/// Every other convention on the undisturbed BROAD recording (slow turns: the wrong reference fits parts of it) and
/// on the Nexus 5's (a hard iron of 375 µT), and the inverse on the BROAD recording with a magnet near it.
#[test]
fn physical_recordings_written_in_another_convention_are_named() {
    for (rel, conventions) in [
        (
            WITH_ATTITUDE[0],
            Convention::all().skip(1).collect::<Vec<_>>(),
        ),
        (WITH_ATTITUDE[3], Convention::all().skip(1).collect()),
        (
            WITH_ATTITUDE[1],
            vec![Convention {
                inverse: true,
                ..Convention::MAGCAL
            }],
        ),
    ] {
        let (raw, quat, field) = read(rel);
        for c in conventions {
            let (written, given_field) = written_in(c, &quat, field);
            let found = better_convention(&raw, &written, given_field, None);
            // Where the field has no east component to speak of (BROAD's, -0.31 µT), a north-west-up world and a
            // reversed vertical field fit alike: either may come first, the other is named with it.
            let named = found.as_ref().map(|b| {
                let mut all = b.also.clone();
                all.insert(0, b.convention);
                all
            });
            assert!(
                named
                    .as_ref()
                    .is_some_and(|n| n.contains(&c) && n.len() <= 2),
                "{rel} {c:?}: {found:?}"
            );
        }
    }
}

/// The BROAD recording with its quaternions inverted: 37 % of it was left out as disturbed, the rest fitted at
/// 1.1 µT, and the diagnosis told of nine magnets; the verdict asked for a longer recording.
#[test]
fn magcal_fit_names_the_convention_of_a_physical_recording() {
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(real(WITH_ATTITUDE[0])).unwrap();
    let mut header: Option<Vec<String>> = None;
    let lines: Vec<String> = text
        .lines()
        .map(|line| {
            if line.starts_with('#') {
                return line.to_owned();
            }
            let Some(names) = &header else {
                header = Some(line.split(',').map(str::to_owned).collect());
                return line.to_owned();
            };
            let mut cells: Vec<String> = line.split(',').map(str::to_owned).collect();
            for (name, cell) in names.iter().zip(cells.iter_mut()) {
                if ["qx", "qy", "qz"].contains(&name.as_str()) && !cell.is_empty() {
                    *cell = format!("{}", -cell.parse::<f64>().unwrap());
                }
            }
            cells.join(",")
        })
        .collect();
    let path = dir.path().join("inverse.csv");
    std::fs::write(&path, lines.join("\n") + "\n").unwrap();
    let report = dir.path().join("report.json");
    for extra in [&[][..], &["--no-diagnose"][..]] {
        let mut args = vec![path.to_str().unwrap(), "--report", report.to_str().unwrap()];
        args.extend(extra);
        let out = magcal_fit(&args);
        assert!(out.status.success());
        let summary = String::from_utf8_lossy(&out.stdout);
        let verdict = summary.lines().find(|l| l.starts_with("verdict:")).unwrap();
        assert!(
            verdict.starts_with("verdict: REDO")
                && verdict.contains("read as the inverse quaternion"),
            "{summary}"
        );
        assert!(!summary.contains("disturbance "), "{summary}");
        let r: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
        let c = &r["attitude_convention"];
        assert_eq!(
            (
                c["inverse"].as_bool(),
                c["scalar_last"].as_bool(),
                c["world"].as_str()
            ),
            (Some(true), Some(false), Some("ned")),
            "{c}"
        );
        assert!(r.get("diagnosis").is_none(), "{}", r["diagnosis"]);
    }
}
