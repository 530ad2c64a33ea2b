//! magcal-fit as a user meets it: clear errors on bad input, parameters written atomically and never clobbered by a
//! failed run, the report contract, exports.

mod common;

use common::{fit_report, floats, magcal_fit, simulate};

#[test]
fn broken_recordings_exit_non_zero_naming_file_line_and_column() {
    let dir = tempfile::tempdir().unwrap();
    let cases: [(&str, &[u8], &str); 7] = [
        ("nan_mag.csv", b"t,mx,my,mz\n0,1,2,3\n0.1,nan,2,3\n", ":3:2"),
        ("text.csv", b"t,mx,my,mz\n0,1,2,3\n0.1,1,x2,3\n", ":3:3"),
        (
            "short.csv",
            b"# magcal-recording v1\nt,mx,my,mz\n0,1,2\n",
            ":3",
        ),
        ("backwards.csv", b"t,mx,my,mz\n1,1,2,3\n0.5,1,2,3\n", ":3:1"),
        (
            "huge.csv",
            b"t,mx,my,mz\n0,1,2,3\n0.1,1,1e308,3\n",
            ":3:3 (my): out of range",
        ),
        (
            "cr-only.csv",
            b"# magcal-recording v1\rt,mx,my,mz\r0,1,2,3\r0.1,1,x,3\r",
            ":4:3 (my): not a number",
        ),
        (
            "gzip.csv",
            b"\x1f\x8b\x08\0\0\0",
            ": a gzip file, not a recording",
        ),
    ];
    for (name, text, position) in cases {
        let path = dir.path().join(name);
        std::fs::write(&path, text).unwrap();
        let out = magcal_fit(&[path.to_str().unwrap()]);
        assert!(!out.status.success(), "{name} was accepted");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(&format!("{name}{position}")), "{name}: {err}");
        assert!(!err.contains("panicked"), "{err}");
    }
    let out = magcal_fit(&["/no/such/recording.csv"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("/no/such/recording.csv"));
}

#[test]
fn a_failed_fit_never_clobbers_a_good_parameters_file() {
    let dir = tempfile::tempdir().unwrap();
    let good = simulate(dir.path(), "good.csv", &["--duration", "40", "--seed", "4"]);
    let planar = simulate(
        dir.path(),
        "planar.csv",
        &["--routine", "turntable", "--duration", "20"],
    );
    let broken = dir.path().join("broken.csv");
    std::fs::write(&broken, "t,mx,my,mz\n0,1,2,3\n0,1,2\n").unwrap();
    let params = dir.path().join("params.toml");
    let out = magcal_fit(&[good.to_str().unwrap(), "--out", params.to_str().unwrap()]);
    assert!(out.status.success());
    let before = std::fs::read(&params).unwrap();
    for bad in [&planar, &broken] {
        let out = magcal_fit(&[bad.to_str().unwrap(), "--out", params.to_str().unwrap()]);
        assert!(!out.status.success());
        assert_eq!(
            std::fs::read(&params).unwrap(),
            before,
            "{} clobbered the parameters",
            bad.display()
        );
    }
    // Only the parameters file itself in the directory besides the recordings: no temporaries left behind.
    let names: Vec<String> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    assert!(
        names.iter().all(|n| !n.starts_with(".magcal-")),
        "{names:?}"
    );
}

#[test]
fn the_report_keeps_its_contract_names() {
    let dir = tempfile::tempdir().unwrap();
    let rec = simulate(dir.path(), "r.csv", &["--duration", "40", "--seed", "5"]);
    let r = fit_report(&rec, &[]);
    assert_eq!(r["method"], "vector");
    assert_eq!(r["calibration"]["A"].as_array().unwrap().len(), 3);
    assert_eq!(floats(&r["calibration"]["b_ut"]).len(), 3);
    assert!(r["residual"]["rms_ut"].as_f64().unwrap() > 0.0);
    assert!(r["residual"]["noise_floor_ut"].as_f64().unwrap() > 0.0);
    assert_eq!(r["base"]["A"].as_array().unwrap().len(), 3);
    assert!(r["base"]["rms_ut"].as_f64().is_some());
    let scalar = fit_report(&rec, &["--method", "scalar"]);
    assert_eq!(scalar["method"], "scalar");
    assert!(
        scalar["notes"]
            .as_array()
            .unwrap()
            .iter()
            .any(|n| n.as_str().unwrap().contains("rotation not observable"))
    );
}

#[test]
fn the_world_magnetic_model_supplies_the_field_from_location_and_date() {
    let dir = tempfile::tempdir().unwrap();
    // A sensor in Berlin (WMM2020 for 2021-05-10: 18.63 N, 1.44 E, 46.20 D µT): simulate in that field, fit with
    // the field from the WMM; the fit is then at the noise floor.
    let rec = simulate(
        dir.path(),
        "berlin.csv",
        &["--duration", "40", "--field-ned", "18.63,1.44,46.20"],
    );
    let r = fit_report(
        &rec,
        &["--location", "52.51,13.32,50", "--date", "2021-05-10"],
    );
    assert!(
        r["field"]["source"]
            .as_str()
            .unwrap()
            .contains("World Magnetic Model")
    );
    let f = floats(&r["field"]["ned_ut"]);
    for (got, want) in f.iter().zip([18.63, 1.44, 46.20]) {
        assert!((got - want).abs() < 0.01, "{f:?}");
    }
    let excess = r["residual"]["rms_ut"].as_f64().unwrap()
        / r["residual"]["noise_floor_ut"].as_f64().unwrap();
    assert!(excess < 1.05, "residual {excess}× the noise floor");
    let out = magcal_fit(&[rec.to_str().unwrap(), "--location", "52.5,13.3,50"]);
    assert!(
        !out.status.success(),
        "--location without --date must be refused"
    );
}

#[test]
fn exports_go_to_stdout_with_the_summary_on_stderr() {
    let dir = tempfile::tempdir().unwrap();
    let rec = simulate(dir.path(), "r.csv", &["--duration", "40", "--seed", "6"]);
    let out = magcal_fit(&[rec.to_str().unwrap(), "--export", "ardupilot"]);
    assert!(out.status.success());
    let stdout = String::from_utf8(out.stdout).unwrap();
    assert!(
        stdout.lines().filter(|l| l.starts_with("COMPASS_")).count() == 9,
        "{stdout}"
    );
    assert!(String::from_utf8_lossy(&out.stderr).contains("residual RMS"));
    let path = dir.path().join("cal.params");
    let out = magcal_fit(&[
        rec.to_str().unwrap(),
        "--export",
        "px4",
        "--export-out",
        path.to_str().unwrap(),
    ]);
    assert!(out.status.success());
    assert!(
        std::fs::read_to_string(&path)
            .unwrap()
            .contains("CAL_MAG0_XOFF")
    );
}

#[test]
fn a_reader_that_goes_away_ends_the_summary_not_the_fit() {
    // `magcal-fit rec.csv --out params.toml | head -3`: the reader closes the pipe before the summary is written; and
    // with `2>&1 | head`, standard error too, before the plots' lines.
    let dir = tempfile::tempdir().unwrap();
    let rec = simulate(dir.path(), "r.csv", &["--duration", "40", "--seed", "6"]);
    for close_stderr in [false, true] {
        let params = dir.path().join(format!("params-{close_stderr}.toml"));
        let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_magcal-fit"))
            .arg(&rec)
            .arg("--out")
            .arg(&params)
            .arg("--plots")
            .arg(dir.path().join("plots"))
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        drop(child.stdout.take());
        if close_stderr {
            drop(child.stderr.take());
        }
        let out = child.wait_with_output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "{close_stderr}: {err}");
        assert!(!err.contains("panicked"), "{err}");
        assert!(
            std::fs::read_to_string(&params)
                .unwrap()
                .contains("[calibration]"),
            "{close_stderr}: the parameters were not written"
        );
    }
}

#[test]
fn no_output_ever_overwrites_the_input_and_nothing_is_written_when_one_would() {
    let dir = tempfile::tempdir().unwrap();
    let rec = simulate(dir.path(), "rec.csv", &["--duration", "30", "--seed", "2"]);
    let original = std::fs::read(&rec).unwrap();
    let link = dir.path().join("link.csv");
    std::os::unix::fs::symlink(&rec, &link).unwrap();
    let rec_s = rec.to_str().unwrap();
    let report = dir.path().join("report.json");
    let report_s = report.to_str().unwrap();
    let same_by_dots = format!("{}/./rec.csv", dir.path().display());
    // (the options, what the message must say)
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (vec!["--out", rec_s], "--out"),
        (vec!["--report", rec_s], "--report"),
        (
            vec!["--export", "json", "--export-out", rec_s],
            "--export-out",
        ),
        (vec!["--plots", rec_s], "--plots"),
        (vec!["--report", report_s, "--out", &same_by_dots], "--out"),
        (
            vec!["--report", report_s, "--out", link.to_str().unwrap()],
            "--out",
        ),
        (
            vec!["--report", report_s, "--out", report_s],
            "--out and --report both name",
        ),
    ];
    for (options, says) in cases {
        let mut args = vec![rec_s];
        args.extend(&options);
        let out = magcal_fit(&args);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{options:?} was accepted");
        assert!(
            err.contains(says) && err.contains("nothing was written"),
            "{options:?}: {err}"
        );
        assert_eq!(
            std::fs::read(&rec).unwrap(),
            original,
            "{options:?}: the input changed"
        );
        assert!(
            !report.exists(),
            "{options:?}: the report was written before the refusal"
        );
    }
    // Plots into the place of another file (not the input): refused before the report is written.
    let note = dir.path().join("notes.txt");
    std::fs::write(&note, "mine").unwrap();
    let out = magcal_fit(&[
        rec_s,
        "--report",
        report_s,
        "--plots",
        note.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("names a directory"),
        "{err}"
    );
    assert!(!report.exists());
    assert_eq!(std::fs::read_to_string(&note).unwrap(), "mine");
    // The same outputs elsewhere are written.
    let out = magcal_fit(&[
        rec_s,
        "--report",
        report_s,
        "--out",
        dir.path().join("p.toml").to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(report.exists());
}

/// A recording is never replaced by an output (found 2026-11-27: `--out other.csv` replaced another recording, as
/// did magcal-apply's and magcal-sim's `--out`); a tool's own kind of recording may be made again: magcal-sim's
/// simulated ones, magcal-apply's calibrated copies.
#[test]
fn outputs_never_replace_a_recording() {
    let dir = tempfile::tempdir().unwrap();
    let rec = simulate(dir.path(), "rec.csv", &["--duration", "30", "--seed", "2"]);
    let real = dir.path().join("real.csv");
    std::fs::write(
        &real,
        "# magcal-recording v1\n# sensor: lis3mdl\nt,mx,my,mz\n0,1,2,3\n",
    )
    .unwrap();
    let logger = dir.path().join("logger.csv");
    std::fs::write(&logger, "time;MX;MY;MZ\n0;1;2;3\n").unwrap();
    let before = |p: &std::path::Path| std::fs::read(p).unwrap();
    let (real_bytes, logger_bytes) = (before(&real), before(&logger));
    let params = dir.path().join("p.toml");
    assert!(
        magcal_fit(&[rec.to_str().unwrap(), "--out", params.to_str().unwrap()])
            .status
            .success()
    );
    for target in [&real, &logger] {
        let t = target.to_str().unwrap();
        for options in [
            vec!["--out", t],
            vec!["--report", t],
            vec!["--export", "json", "--export-out", t],
        ] {
            let mut args = vec![rec.to_str().unwrap()];
            args.extend(&options);
            let out = magcal_fit(&args);
            let err = String::from_utf8_lossy(&out.stderr);
            assert!(
                !out.status.success() && err.contains("holds a recording"),
                "{options:?}: {err}"
            );
        }
        let out = common::magcal_apply(&params, &rec, &["--out", t]);
        assert!(!out.status.success(), "magcal-apply --out {t}");
        let out = common::magcal_sim(&["--duration", "10"], target);
        assert!(!out.status.success(), "magcal-sim --out {t}");
    }
    assert_eq!(before(&real), real_bytes);
    assert_eq!(before(&logger), logger_bytes);
    // Its own kind again: a simulated recording over a simulated one, a calibrated copy over one.
    assert!(
        common::magcal_sim(&["--duration", "10"], &rec)
            .status
            .success()
    );
    let copy = dir.path().join("calibrated.csv");
    for _ in 0..2 {
        let out = common::magcal_apply(&params, &rec, &["--out", copy.to_str().unwrap()]);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
}

/// The named lines of an effect left out, as the export and the terminal print them.
fn named(kind: &str, effect: &serde_json::Value) -> String {
    format!(
        "{kind} {}, {:.3} µT RMS per axis on this recording: {}",
        effect["id"].as_str().unwrap(),
        effect["size_ut"].as_f64().unwrap(),
        effect["what"].as_str().unwrap()
    )
}

/// Issue 7, defect 7: an export names each effect the diagnosis found, with its size on the recording and its
/// parameters, says what the target holds, and claims to hold none of them; the terminal shows the same lines.
#[test]
fn exports_name_each_correction_left_out_with_its_size() {
    let dir = tempfile::tempdir().unwrap();
    let fixture = |name: &str| {
        format!(
            "{}/fixtures/diagnosis/{name}.csv",
            env!("CARGO_MANIFEST_DIR")
        )
    };
    let run = |name: &str, extra: &[&str]| {
        let rec = fixture(name);
        let mut args = vec![rec.as_str()];
        args.extend_from_slice(extra);
        let out = magcal_fit(&args);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        (
            String::from_utf8(out.stdout).unwrap(),
            String::from_utf8(out.stderr).unwrap(),
        )
    };

    // The JSON lists them in full, with the report's size and parameters.
    let (report, json) = (dir.path().join("r.json"), dir.path().join("e.json"));
    let (rs, js) = (report.to_str().unwrap(), json.to_str().unwrap());
    run(
        "temperature_bias",
        &["--report", rs, "--export", "json", "--export-out", js],
    );
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    let export: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let found = &report["diagnosis"]["effects"];
    let left = export["left_out"].as_array().unwrap();
    assert_eq!(left.len(), 1, "{export}");
    let temp = &left[0];
    assert_eq!(temp["id"], "temperature_bias");
    assert_eq!(temp["correction"], true);
    assert_eq!(temp["size_ut"], found[0]["size_ut"]);
    assert_eq!(
        temp["params"]["coef_ut_per_c"],
        found[0]["params"]["coef_ut_per_c"]
    );
    let size = temp["size_ut"].as_f64().unwrap();
    assert!(size > 0.03 && size < 0.2, "{size}");
    // The fixture's coefficient is 0.073 µT/°C (its .truth.toml): said in human units.
    assert!(
        temp["what"]
            .as_str()
            .unwrap()
            .starts_with("offset follows temperature: 0.07"),
        "{temp}"
    );
    let line = named("left out:", temp);

    // Every text format names it in the file, and the terminal says the same.
    for (format, holds, parameter) in [
        (
            "ardupilot",
            "# what the target holds: ArduPilot's COMPASS_*",
            "COMPASS_",
        ),
        (
            "px4",
            "# what the target holds: PX4's CAL_MAG0_*",
            "1\t1\tCAL_MAG0_",
        ),
        (
            "c-header",
            "/* what the target holds: the header holds A and b only */",
            "static const",
        ),
    ] {
        let (stdout, stderr) = run("temperature_bias", &["--export", format]);
        assert!(stdout.contains(holds), "{format}:\n{stdout}");
        assert!(stdout.contains(&line), "{format}: no {line}\n{stdout}");
        assert!(stderr.contains(&format!("  {line}")), "{format}:\n{stderr}");
        // Only the linear model is written: no compensation the target could hold is claimed.
        let written: Vec<&str> = stdout
            .lines()
            .filter(|l| l.starts_with(parameter))
            .collect();
        assert!(
            written.len() == if format == "c-header" { 2 } else { 9 }
                && written
                    .iter()
                    .all(|l| !l.contains("COMPASS_MOT") && !l.contains("COMP\t")),
            "{format}: {written:?}"
        );
    }

    // A current's field: ArduPilot and PX4 have a place for one, not written with A and b fitted without it.
    let (ap, _) = run("current_bias", &["--export", "ardupilot"]);
    let (px, _) = run("current_bias", &["--export", "px4"]);
    for (text, place) in [
        (&ap, "not written: COMPASS_MOT_X/Y/Z"),
        (&px, "not written: CAL_MAG0_XCOMP/YCOMP/ZCOMP"),
    ] {
        let line = text
            .lines()
            .find(|l| l.contains("left out: current_bias, "))
            .unwrap_or_else(|| panic!("{text}"));
        assert!(
            line.contains("the current in i_motor adds a field of 0.") && line.contains(place),
            "{line}"
        );
    }

    // A timing effect is no correction: named as such, nothing said left out or fitted without.
    let (stdout, _) = run("time_lag", &["--export", "px4"]);
    assert!(
        stdout.contains("# not a correction: time_lag, ")
            && stdout.contains("the magnetometer sample is late by"),
        "{stdout}"
    );
    assert!(
        !stdout.contains("left out:") && !stdout.contains("fitted without"),
        "{stdout}"
    );

    // A chip's offset registers (--write-to): the same named list (the fixture's sensor named the LIS2MDL, the chip
    // with offset registers, as a recording of it would).
    let lis2mdl = dir.path().join("lis2mdl.csv");
    let text = std::fs::read_to_string(fixture("temperature_bias")).unwrap();
    std::fs::write(
        &lis2mdl,
        text.replacen("# sensor: lis3mdl", "# sensor: lis2mdl", 1),
    )
    .unwrap();
    let out = magcal_fit(&[lis2mdl.to_str().unwrap(), "--write-to", "sim:lis2mdl"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stdout = String::from_utf8(out.stdout).unwrap();
    assert!(
        stdout.contains("the chip's offset registers hold an offset only")
            && stdout.contains(&format!("  {line}")),
        "{stdout}"
    );
}

#[test]
fn a_field_fixed_in_the_room_during_a_scalar_recording_is_a_shifted_window_left_out() {
    // 3 µT down in the room from 40 to 70 s, along most of the field (20, 0, 45): |B| rises by ~2.9 µT while the
    // sensor tumbles, too little to be gross (8 times the noise of |B|).
    let dir = tempfile::tempdir().unwrap();
    let common = [
        "--reference",
        "none",
        "--seed",
        "3",
        "--field-ned",
        "20,0,45",
    ];
    let disturbed = simulate(
        dir.path(),
        "shift.csv",
        &[
            &common[..],
            &["--effect", "disturbance:t0_s=40;t1_s=70;field_ned_ut=0,0,3"],
        ]
        .concat(),
    );
    let clean = simulate(dir.path(), "clean.csv", &common);
    let r = fit_report(&disturbed, &[]);
    let spans = r["diagnosis"]["spans"].as_array().unwrap();
    assert_eq!(spans.len(), 1, "{spans:?}");
    let sp = &spans[0];
    assert_eq!(sp["kind"], "magnitude_shift");
    assert!((sp["t0_s"].as_f64().unwrap() - 40.0).abs() < 0.5, "{sp}");
    assert!((sp["t1_s"].as_f64().unwrap() - 70.0).abs() < 0.5, "{sp}");
    assert!((sp["shift_ut"].as_f64().unwrap() - 2.9).abs() < 0.3, "{sp}");
    assert_eq!(r["diagnosis"]["verdict"], "mismatch");
    // The calibration is the clean recording's, within its standard errors.
    let c = fit_report(&clean, &[]);
    let (o, oc) = (
        floats(&r["calibration"]["offset_ut"]),
        floats(&c["calibration"]["offset_ut"]),
    );
    let se = floats(&r["calibration"]["offset_se_ut"]);
    for k in 0..3 {
        assert!(
            (o[k] - oc[k]).abs() < 3.0 * se[k],
            "{o:?} against {oc:?} ± {se:?}"
        );
    }
    assert_eq!(c["diagnosis"]["spans"].as_array().unwrap().len(), 0);
}

#[test]
fn a_scalar_fit_never_blames_a_reference_it_does_not_have() {
    // A hand-held QMC5883L recording without any attitude reference, its |B| residual above the sensor's noise.
    let out = magcal_fit(&[common::real("qmc5883l/qmc5883l_filtered_raw.csv")
        .to_str()
        .unwrap()]);
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("left unexplained"), "{text}");
    assert!(!text.contains("reference's own error"), "{text}");
}

#[test]
fn headers_cut_off_files_and_zero_readings_are_explained() {
    let dir = tempfile::tempdir().unwrap();
    let zeros: String = (0..300).map(|i| format!("{i},0,0,0\n")).collect();
    let cases: [(&str, String, &str); 4] = [
        (
            "units.csv",
            "t,mx_uT,my_uT,mz_uT\n0,1,2,3\n".to_owned(),
            "units.csv:1: missing required column \"mx\" (mx, my and mz are required); the header line 1 was read \
             as 4 columns: \"t\", \"mx_uT\", \"my_uT\", \"mz_uT\";",
        ),
        (
            "spaces.csv",
            "t mx my mz\n0 1 2 3\n".to_owned(),
            "read as 1 column: \"t mx my mz\"; name the field columns mx, my and mz",
        ),
        (
            "cut.csv",
            "t,mx,my,mz\n0,1,2,3\n0.1,1,2".to_owned(),
            "cut.csv:3: short row: 3 fields, the header has 4; the file ends in the middle of this line (cut off, \
             e.g. a logger stopped while writing): remove this last line and the rest can be read",
        ),
        (
            "zeros.csv",
            format!("t,mx,my,mz\n{zeros}"),
            "every reading is zero (|m| below 1e-9 in all 300 rows): the sensor returned only zeros",
        ),
    ];
    for (name, text, says) in cases {
        let path = dir.path().join(name);
        std::fs::write(&path, text).unwrap();
        let out = magcal_fit(&[path.to_str().unwrap(), "--no-diagnose"]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success() && err.contains(says), "{name}: {err}");
    }
}

#[test]
fn a_recording_given_before_the_parameters_to_magcal_apply_is_named_as_one() {
    let dir = tempfile::tempdir().unwrap();
    let rec = dir.path().join("rec.csv");
    std::fs::write(&rec, "# magcal-recording v1\nt,mx,my,mz\n0,1,2,3\n").unwrap();
    let params = dir.path().join("params.toml");
    std::fs::write(&params, "format = \"magcal-params v1\"\n").unwrap();
    let out = common::magcal_apply(&rec, &params, &[]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success()
            && err.contains(
                "rec.csv: looks like a recording, not a parameters file: the parameters come first (magcal-apply \
                 PARAMS.toml RECORDING.csv)"
            ),
        "{err}"
    );
}

#[test]
fn magcal_refusing_an_existing_recording_names_its_own_options() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("recording.csv"), "precious\n").unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_magcal"))
        .args(["--out-dir", dir.path().to_str().unwrap()])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success()
            && err.contains(
                "recording.csv exists: a recording is never replaced; choose another --out-dir, or add --force"
            )
            && !err.contains("--out,"),
        "{err}"
    );
    let kept = std::fs::read_to_string(dir.path().join("recording.csv")).unwrap();
    assert_eq!(kept, "precious\n");
}

#[test]
fn magcal_does_not_replace_an_earlier_runs_parameters_unasked() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("params.toml"), "precious\n").unwrap();
    let run = |extra: &[&str]| {
        std::process::Command::new(env!("CARGO_BIN_EXE_magcal"))
            .args(["--out-dir", dir.path().to_str().unwrap()])
            .args(extra)
            .output()
            .unwrap()
    };
    let out = run(&[]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success()
            && err.contains("params.toml exists")
            && err.contains("--force")
            && !dir.path().join("recording.csv").exists(),
        "{err}"
    );
    let kept = std::fs::read_to_string(dir.path().join("params.toml")).unwrap();
    assert_eq!(kept, "precious\n");
    let out = run(&["--force"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let made = std::fs::read_to_string(dir.path().join("params.toml")).unwrap();
    assert_ne!(made, "precious\n");
}
