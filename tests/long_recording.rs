//! A recording longer than the diagnosis looks at sample by sample (`MOST_SAMPLES`, 200,000): 300,000 samples with a
//! magnet on the board for five minutes. The diagnosis looks at every second sample, says so, locates the window to
//! two samples and keeps the base fit's standard errors; a check of the parameters on a second such recording leaves
//! out the window's rows, all of them but at its edges, not only the samples it looked at.

mod common;

use common::{fit_report, magcal_apply, magcal_fit, matrix, simulate};

/// 50 minutes of one simulated sensor at 100 Hz with a magnet on its board from `t0_s` to `t1_s`, as `dir/name`.
fn long(dir: &std::path::Path, name: &str, t0_s: f64, t1_s: f64) -> std::path::PathBuf {
    let window = format!("bias_window:t0_s={t0_s};t1_s={t1_s};offset_ut=20,-10,5");
    let args = [
        "--duration",
        "3000",
        "--rate",
        "100",
        "--seed",
        "7",
        "--effect",
        &window,
    ];
    simulate(dir, name, &args)
}

#[test]
fn a_long_recording_is_diagnosed_on_every_second_sample_and_its_window_left_out_whole() {
    let dir = tempfile::tempdir().unwrap();
    let rec = long(dir.path(), "long.csv", 1200.03, 1500.07);
    let report = fit_report(&rec, &[]);
    let notes: Vec<&str> = report["notes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|n| n.as_str().unwrap())
        .collect();
    assert!(
        notes
            .iter()
            .any(|n| n.starts_with("the diagnosis looked at one sample in 2 (150000 samples")),
        "{notes:?}"
    );
    let d = &report["diagnosis"];
    let spans = d["spans"].as_array().unwrap();
    assert_eq!(spans.len(), 1, "{spans:?}");
    let (t0, t1) = (
        spans[0]["t0_s"].as_f64().unwrap(),
        spans[0]["t1_s"].as_f64().unwrap(),
    );
    // Two samples at 100 Hz.
    assert!(
        (t0 - 1200.03).abs() <= 0.02 && (t1 - 1500.07).abs() <= 0.02,
        "{t0}–{t1} s"
    );
    // A thinned diagnosis that finds nothing to model keeps the base fit of every row and its standard errors: the
    // plain fit's, not those of the samples the diagnosis looked at.
    // (The plain fit turns the attitude into the field as it reads it: the last digit may differ.)
    let plain = fit_report(&rec, &["--no-diagnose"]);
    for key in ["A", "A_se"] {
        let (x, y) = (
            matrix(&report["calibration"][key]),
            matrix(&plain["calibration"][key]),
        );
        for (j, k) in (0..3).flat_map(|j| (0..3).map(move |k| (j, k))) {
            assert!(
                (x[j][k] - y[j][k]).abs() <= 1e-9 * y[j][k].abs(),
                "{key}[{j}][{k}]: {} against the plain fit's {}",
                x[j][k],
                y[j][k]
            );
        }
    }

    // Checked on a recording of the same sensor with the window elsewhere, the rows left out are the window's 10,004.
    let params = dir.path().join("long.toml");
    let out = magcal_fit(&[
        rec.to_str().unwrap(),
        "--no-diagnose",
        "--out",
        params.to_str().unwrap(),
    ]);
    assert!(out.status.success());
    let second = long(dir.path(), "second.csv", 100.03, 200.07);
    let out = magcal_apply(&params, &second, &[]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}");
    let head = stdout.lines().next().unwrap();
    let left_out: usize = head
        .split_once(" in disturbed spans left out of the check")
        .and_then(|(before, _)| before.rsplit('(').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("{head}"));
    assert!(left_out.abs_diff(10_004) <= 2, "{head}");
}
