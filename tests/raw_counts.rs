//! A board that prints raw counts (issue 34, row 1 and acceptance 4): with the field known, `A` maps counts to µT and
//! every export works — the C header from the readings as recorded to µT, the autopilot files from the milligauss or
//! gauss their drivers make of the chip's counts — and the two agree; without a field, the scale is said plainly and
//! only what needs none is written; the units are labelled right.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use nalgebra::{Matrix3, Vector3};

/// The shared QMC5883L recording: the chip's counts × 100/12000 (its README), with the place and date in its metadata.
const QMC: &str = "qmc5883l/qmc5883l_filtered_raw.csv";

/// Runs `magcal-fit` with `args` in `dir`.
fn fit_in(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_magcal-fit"))
        .args(args)
        .current_dir(dir)
        .output()
        .expect("magcal-fit runs")
}

/// The numbers of a C header: `MAGCAL_A` and `b` (named `name`).
fn header(text: &str, name: &str) -> (Matrix3<f64>, Vector3<f64>) {
    let numbers = |line: &str| -> Vec<f64> {
        line.split(['{', '}', ','])
            .filter_map(|c| c.trim().trim_end_matches('f').parse().ok())
            .collect()
    };
    let lines: Vec<&str> = text.lines().collect();
    let at = lines
        .iter()
        .position(|l| l.contains("MAGCAL_A[3][3]"))
        .expect("MAGCAL_A");
    let rows: Vec<Vec<f64>> = lines[at + 1..at + 4].iter().map(|l| numbers(l)).collect();
    let b_line = lines
        .iter()
        .find(|l| l.contains(&format!(" {name}[3]")))
        .unwrap_or_else(|| panic!("{name} in\n{text}"));
    let b = numbers(b_line.split('=').nth(1).unwrap());
    (
        Matrix3::from_fn(|j, k| rows[j][k]),
        Vector3::new(b[0], b[1], b[2]),
    )
}

/// ArduPilot's `M` and `OFS` from a `.param` file.
fn ardupilot(text: &str) -> (Matrix3<f64>, Vector3<f64>) {
    let v = |name: &str| -> f64 {
        text.lines()
            .find_map(|l| l.strip_prefix(&format!("{name},")))
            .unwrap_or_else(|| panic!("{name} in\n{text}"))
            .parse()
            .unwrap()
    };
    let (dx, dy, dz) = (v("COMPASS_DIA_X"), v("COMPASS_DIA_Y"), v("COMPASS_DIA_Z"));
    let (ox, oy, oz) = (v("COMPASS_ODI_X"), v("COMPASS_ODI_Y"), v("COMPASS_ODI_Z"));
    (
        Matrix3::new(dx, ox, oy, ox, dy, oz, oy, oz, dz),
        Vector3::new(v("COMPASS_OFS_X"), v("COMPASS_OFS_Y"), v("COMPASS_OFS_Z")),
    )
}

/// Every 50th reading of a recording's text.
fn readings(text: &str) -> Vec<Vector3<f64>> {
    text.lines()
        .filter(|l| l.starts_with(|c: char| c.is_ascii_digit() || c == '-'))
        .step_by(50)
        .map(|l| {
            let f: Vec<f64> = l.split(',').map(|c| c.parse().unwrap()).collect();
            Vector3::new(f[1], f[2], f[3])
        })
        .collect()
}

/// Checks that the C header's `B = A·raw + b` and ArduPilot's `M·(raw_mG + OFS)`, its driver reading `mg_per_raw`
/// milligauss per unit of the readings, give the same field (`mg_per_out` milligauss per unit of the header's B),
/// and that the header's field has magnitude near `field`.
fn agree(
    h: &str,
    b_name: &str,
    param: &str,
    rec: &str,
    mg_per_raw: f64,
    mg_per_out: f64,
    field: Option<f64>,
) {
    let (a, b) = header(h, b_name);
    let (m, ofs) = ardupilot(param);
    let mut worst = 0.0f64;
    for r in readings(rec) {
        let ours = a * r + b;
        let theirs = m * (r * mg_per_raw + ofs) / mg_per_out;
        worst = worst.max((ours - theirs).norm() / ours.norm());
        if let Some(field) = field {
            assert!(
                (ours.norm() / field - 1.0).abs() < 0.2,
                "|B| {} where the field is {field}",
                ours.norm()
            );
        }
    }
    // The files' digits: six decimals in the matrix, three in the offsets.
    assert!(
        worst < 2e-4,
        "the C header and the ArduPilot file differ by {worst:.2e}"
    );
}

/// The shared recording's text with `edit` applied to its metadata and `value` to each reading, written to `dir`.
fn rewritten(
    dir: &Path,
    name: &str,
    keep_meta: impl Fn(&str) -> bool,
    value: impl Fn(f64) -> f64,
) -> PathBuf {
    let text = std::fs::read_to_string(common::real(QMC)).unwrap();
    let mut out = String::new();
    for line in text.lines() {
        if line.starts_with('#') {
            if keep_meta(line) {
                out += line;
                out.push('\n');
            }
        } else if line.starts_with('t') {
            out += line;
            out.push('\n');
        } else {
            let cells: Vec<String> = line
                .split(',')
                .enumerate()
                .map(|(i, c)| match i {
                    1..=3 => format!("{}", value(c.parse::<f64>().unwrap())),
                    _ => c.to_owned(),
                })
                .collect();
            out += &cells.join(",");
            out.push('\n');
        }
    }
    let path = dir.join(name);
    std::fs::write(&path, out).unwrap();
    path
}

/// Acceptance 4: the README's commands for a board that prints raw counts, run as written on the shared QMC5883L
/// recording, give a C header and an ArduPilot parameter file whose numbers agree (ArduPilot's driver reads this
/// chip's counts as the recording holds them: µT at the datasheet's sensitivity, 10 mGauss each).
#[test]
fn the_readme_gives_a_c_header_and_an_ardupilot_file_that_agree() {
    let readme =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("README.md")).unwrap();
    let section = readme
        .split("### A board that prints raw counts")
        .nth(1)
        .expect("the README's section on raw counts");
    let commands: Vec<&str> = section
        .lines()
        .filter(|l| l.starts_with("magcal-fit ../shared/data/real/qmc5883l/"))
        .collect();
    assert_eq!(commands.len(), 2, "{section}");
    let dir = tempfile::tempdir().unwrap();
    let shared = common::real("");
    for command in &commands {
        let args: Vec<String> = command
            .split_whitespace()
            .skip(1)
            .map(|a| a.replace("../shared/data/real/", shared.to_str().unwrap()))
            .collect();
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let out = fit_in(dir.path(), &args);
        assert!(
            out.status.success(),
            "{command}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let summary = String::from_utf8_lossy(&out.stdout);
        // Units labelled: b in µT, the offset in the readings' units, never "µT" for it.
        assert!(
            summary.contains("µT   (offset −A⁻¹b = [") && summary.contains("] raw units)"),
            "{summary}"
        );
        assert!(
            summary.contains("the raw readings are not in µT"),
            "{summary}"
        );
    }
    let h = std::fs::read_to_string(dir.path().join("magcal_calibration.h")).unwrap();
    let param = std::fs::read_to_string(dir.path().join("magcal.param")).unwrap();
    assert!(
        h.contains("B in microtesla; raw: the readings as recorded"),
        "{h}"
    );
    assert!(
        param.contains("# the readings were raw units, 100 a gauss"),
        "{param}"
    );
    let rec = std::fs::read_to_string(common::real(QMC)).unwrap();
    // The World Magnetic Model's field at the recording's place and date: 23.04 µT.
    agree(&h, "MAGCAL_B_UT", &param, &rec, 10.0, 10.0, Some(23.04));
}

/// Row 1: the chip's own counts — the shared recording scaled to a QMC5883L's at ±2 G (12000 counts a gauss) in its
/// field (× 276: as recorded, it reads the field 2.3 times weak) — no unit stated. `--chip qmc5883l` takes the setting that fits the field, and both files agree with ArduPilot's driver
/// reading 1000/12000 mGauss a count; a setting that does not fit is refused naming the one that does.
#[test]
fn counts_with_the_chip_go_to_every_export() {
    let dir = tempfile::tempdir().unwrap();
    let counts = rewritten(
        dir.path(),
        "counts.csv",
        |l| !l.starts_with("# units") && !l.starts_with("# sensor"),
        |v| (v * 276.0).round(),
    );
    let c = counts.to_str().unwrap();
    for (format, file) in [
        ("c-header", "q.h"),
        ("ardupilot", "q.param"),
        ("json", "q.json"),
    ] {
        let out = fit_in(
            dir.path(),
            &[
                c,
                "--chip",
                "qmc5883l",
                "--no-diagnose",
                "--export",
                format,
                "--export-out",
                file,
            ],
        );
        assert!(
            out.status.success(),
            "{format}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let summary = String::from_utf8_lossy(&out.stdout);
        assert!(
            summary.contains("] counts)")
                && summary
                    .contains("12000 of them make a gauss (--chip QMC5883L: ±2 G, 12000 LSB/G)"),
            "{summary}"
        );
    }
    let h = std::fs::read_to_string(dir.path().join("q.h")).unwrap();
    let param = std::fs::read_to_string(dir.path().join("q.param")).unwrap();
    let rec = std::fs::read_to_string(&counts).unwrap();
    agree(
        &h,
        "MAGCAL_B_UT",
        &param,
        &rec,
        1000.0 / 12000.0,
        10.0,
        Some(23.04),
    );
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("q.json")).unwrap()).unwrap();
    assert_eq!(json["raw_units"]["per_gauss"], 12000.0);
    assert!(
        json["b_ut"].is_array() && json["offset_raw"].is_array() && json["offset_ut"].is_null()
    );
    // The wrong setting stated: refused, naming the one that fits.
    let out = fit_in(
        dir.path(),
        &[
            c,
            "--chip",
            "qmc5883l:8g",
            "--no-diagnose",
            "--export",
            "ardupilot",
        ],
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("Give --chip qmc5883l:2g"),
        "{err}"
    );
    // No chip and no unit: the autopilot is refused saying what to give; the C header is written.
    let out = fit_in(dir.path(), &[c, "--no-diagnose", "--export", "ardupilot"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("--chip CHIP[:SETTING]"),
        "{err}"
    );
    let out = fit_in(dir.path(), &[c, "--no-diagnose", "--export", "c-header"]);
    assert!(out.status.success());
}

/// Row 1, without a field: the calibrated field keeps the readings' scale, said plainly; the C header names its `b`
/// without µT; an autopilot file is written only with the chip's counts per gauss, and then agrees with the header
/// in the driver's nominal milligauss.
#[test]
fn without_a_field_the_scale_is_said_and_only_what_needs_none_is_written() {
    let dir = tempfile::tempdir().unwrap();
    let counts = rewritten(
        dir.path(),
        "nofield.csv",
        |l| l.starts_with("# magcal-recording"),
        |v| (v * 120.0).round(),
    );
    let c = counts.to_str().unwrap();
    let out = fit_in(
        dir.path(),
        &[
            c,
            "--no-diagnose",
            "--export",
            "c-header",
            "--export-out",
            "n.h",
        ],
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let summary = String::from_utf8_lossy(&out.stdout);
    assert!(
        summary.contains("No field magnitude was given, so the calibrated field")
            && summary.contains("] raw units   (offset −A⁻¹b")
            && !summary.contains("] µT   (offset"),
        "{summary}"
    );
    let h = std::fs::read_to_string(dir.path().join("n.h")).unwrap();
    assert!(
        h.contains("MAGCAL_B[3]") && !h.contains("MAGCAL_B_UT"),
        "{h}"
    );
    let out = fit_in(dir.path(), &[c, "--no-diagnose", "--export", "ardupilot"]);
    assert!(!out.status.success());
    let out = fit_in(
        dir.path(),
        &[
            c,
            "--no-diagnose",
            "--chip",
            "qmc5883l:2g",
            "--export",
            "ardupilot",
            "--export-out",
            "n.param",
        ],
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let param = std::fs::read_to_string(dir.path().join("n.param")).unwrap();
    let rec = std::fs::read_to_string(&counts).unwrap();
    agree(
        &h,
        "MAGCAL_B",
        &param,
        &rec,
        1000.0 / 12000.0,
        1000.0 / 12000.0,
        None,
    );
}
