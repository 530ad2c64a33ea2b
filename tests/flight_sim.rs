//! Simulated flight logs (issue 35, item 5's simulator part and acceptance 2 on logs): the simulator writes PX4
//! ULog files with a known motor coefficient and magnetometer lag; magcal-fit reads them as it reads a real log (the
//! reference re-headed, the field from the World Magnetic Model at the log's GPS fix) and its diagnosis recovers
//! them. Logs without a magnetometer or an attitude are refused by name.

mod common;

use std::path::{Path, PathBuf};

use common::magcal_fit;
use magcal_app::calibrate::calibrate;
use magcal_app::field::{FieldArgs, wmm};
use magcal_app::fit::Method;
use magcal_app::flight::{LogOptions, read_flight};
use magcal_calib::Effect;
use magcal_calib::diagnosis::ParamValue;
use magcal_flightlog::ulog;
use magcal_recording::{Date, Location};
use magcal_sim::dataflash::{DataflashCompass, DataflashSetup, write_dataflash};
use magcal_sim::ulog::{UlogSetup, UlogSlot, write_ulog};
use magcal_sim::{ChipModel, CurrentProfile, Scenario, SensorTruth, Trajectory, simulate};

/// The World Magnetic Model's field at the simulated log's fix and day.
fn field_at_fix(setup: &UlogSetup) -> [f64; 3] {
    let [lat_deg, lon_deg, alt_m] = setup.location;
    let date = Date::new(2025, 6, 1).unwrap();
    wmm(
        &Location {
            lat_deg,
            lon_deg,
            alt_m,
        },
        &date,
        "test",
    )
    .unwrap()
    .vector()
    .unwrap()
}

/// A flight of `duration_s` tumbling through all attitudes, a motor current switching between 0 and `on_a`, the
/// magnetometer seeing `coef` µT/A of it and sampling `lag_s` late; a sensor with a few per cent of soft iron and
/// 10–20 µT of hard iron, the autopilot holding an older calibration.
fn flight_log(
    dir: &Path,
    seed: u64,
    coef: [f64; 3],
    lag_s: f64,
    duration_s: f64,
    on_a: f64,
) -> PathBuf {
    let chip = ChipModel::by_name("lis3mdl").unwrap();
    let mut s = Scenario::new(
        &chip,
        Trajectory::Tumble {
            duration_s,
            rate_rad_s: 0.8,
        },
        seed,
    );
    let setup = UlogSetup {
        slot: UlogSlot {
            offset_g: [0.1, -0.15, 0.05],
            scale: [1.01, 0.98, 1.02],
            offdiag: [0.01, 0.0, -0.01],
        },
        ..UlogSetup::default()
    };
    s.field_ned_ut = field_at_fix(&setup);
    s.sensor = SensorTruth {
        a: [
            [1.03, 0.02, -0.01],
            [0.02, 0.97, 0.015],
            [-0.01, 0.015, 1.01],
        ],
        b_ut: [12.0, -18.0, 6.0],
    };
    s.currents = vec![CurrentProfile {
        name: "i_battery".to_owned(),
        on_a,
        mean_on_s: 3.0,
        mean_off_s: 3.0,
    }];
    s.effects = Vec::new();
    if coef != [0.0; 3] {
        s.effects.push(Effect::CurrentBias {
            channel: 0,
            coef_ut_per_a: coef,
        });
    }
    if lag_s != 0.0 {
        s.effects.push(Effect::TimeLag { lag_s });
    }
    let run = simulate(&s).unwrap();
    let path = dir.join(format!("flight-{seed}.ulg"));
    let mut file = std::io::BufWriter::new(std::fs::File::create(&path).unwrap());
    write_ulog(&run.recording, &setup, &mut file).unwrap();
    drop(file);
    if dir.ends_with("dataflash") {
        return dataflash_copy(&run.recording, &path);
    }
    path
}

/// The same flight as an ArduPilot DataFlash log beside `path`, its autopilot holding an older calibration.
fn dataflash_copy(rec: &magcal_recording::Recording, path: &Path) -> PathBuf {
    let setup = DataflashSetup {
        compass: DataflashCompass {
            ofs_mgauss: [-100.0, 150.0, -50.0],
            dia: [0.99, 1.02, 0.98],
            odi: [0.01, 0.0, -0.01],
        },
        ..DataflashSetup::default()
    };
    let out = path.with_extension("bin");
    let mut file = std::io::BufWriter::new(std::fs::File::create(&out).unwrap());
    write_dataflash(rec, &setup, &mut file).unwrap();
    out
}

/// What the diagnosis found: the current's coefficient with its standard error (µT/A), and the lag (s).
#[derive(Debug)]
struct Found {
    coef: Option<([f64; 3], [f64; 3])>,
    lag_s: Option<f64>,
}

fn fit(path: &Path) -> Found {
    let input = read_flight(path, &LogOptions::default(), &FieldArgs::default()).unwrap();
    let cal = calibrate(&input.rec, Method::Vector, input.field.clone(), true).unwrap();
    let d = cal.diagnosis.expect("diagnosed");
    let mut found = Found {
        coef: None,
        lag_s: None,
    };
    for e in &d.effects {
        match e.effect {
            Effect::CurrentBias { coef_ut_per_a, .. } => {
                let se = e.params.iter().find_map(|p| match (p.name, &p.se) {
                    ("coef_ut_per_a", Some(ParamValue::Vector(se))) => Some(*se),
                    _ => None,
                });
                found.coef = Some((coef_ut_per_a, se.expect("a standard error")));
            }
            Effect::TimeLag { lag_s } => found.lag_s = Some(lag_s),
            // The lag as each axis' own: taken as the lag when the three agree within 5 ms.
            Effect::RateCoupling {
                lag_axis_s: [x, y, z],
            } if x.max(y).max(z) - x.min(y).min(z) <= 0.005 => {
                found.lag_s = Some((x + y + z) / 3.0)
            }
            _ => {}
        }
    }
    found
}

/// Within 10 % and within three standard errors on every axis: one coefficient in twenty is beyond two, so a test of
/// a few logs asks for three and the study counts the twos (it finds 93 %).
fn recovered(found: &Found, coef: [f64; 3]) -> bool {
    let Some((est, se)) = found.coef else {
        return false;
    };
    (0..3).all(|k| {
        let err = (est[k] - coef[k]).abs();
        err <= 0.1 * coef[k].abs() && err <= 3.0 * se[k]
    })
}

#[test]
fn a_simulated_flight_reads_back_as_it_was_simulated() {
    let dir = tempfile::tempdir().unwrap();
    let chip = ChipModel::by_name("lis3mdl").unwrap();
    let mut s = Scenario::new(
        &chip,
        Trajectory::Tumble {
            duration_s: 20.0,
            rate_rad_s: 0.8,
        },
        7,
    );
    s.currents = vec![CurrentProfile {
        name: "i_battery".to_owned(),
        on_a: 30.0,
        mean_on_s: 2.0,
        mean_off_s: 2.0,
    }];
    let run = simulate(&s).unwrap();
    let setup = UlogSetup {
        calibrated_mag: true,
        ..UlogSetup::default()
    };
    let path = dir.path().join("sim.ulg");
    write_ulog(
        &run.recording,
        &setup,
        &mut std::fs::File::create(&path).unwrap(),
    )
    .unwrap();
    let log = ulog::read(&path).unwrap();
    assert_eq!(log.mags.len(), 2, "sensor_mag and vehicle_magnetometer");
    for which in [0, 1] {
        let back = log
            .recording(Some(magcal_flightlog::Instance(which)))
            .unwrap();
        let rec = &back.rec;
        assert_eq!(rec.len(), run.recording.len());
        for i in (0..rec.len()).step_by(97) {
            for k in 0..3 {
                assert!(
                    (rec.mag_ut[i][k] - run.recording.mag_ut[i][k]).abs() < 1e-3,
                    "row {i}"
                );
            }
            let (q, want) = (
                rec.quat.as_ref().unwrap()[i],
                run.recording.quat.as_ref().unwrap()[i],
            );
            let dot: f64 = (0..4).map(|k| q[k] * want[k]).sum();
            assert!(dot.abs() > 1.0 - 1e-9, "row {i}: {q:?} {want:?}");
            assert_eq!(
                rec.currents[0].values[i] as f32,
                run.recording.currents[0].values[i] as f32
            );
            assert!(
                (rec.t_s.as_ref().unwrap()[i] - run.recording.t_s.as_ref().unwrap()[i]).abs()
                    < 1e-6
            );
            if which == 0 {
                let (t, want) = (
                    rec.temp_c.as_ref().unwrap()[i],
                    run.recording.temp_c.as_ref().unwrap()[i],
                );
                assert!((t - want).abs() < 1e-4, "row {i}: {t} {want}");
            }
        }
        assert_eq!(
            rec.meta.date.map(|d| d.to_string()).as_deref(),
            Some("2025-06-01")
        );
        assert_eq!(rec.meta.location.map(|l| l.lat_deg), Some(47.3566));
    }
}

#[test]
fn logs_without_a_magnetometer_or_an_attitude_say_so() {
    let dir = tempfile::tempdir().unwrap();
    let chip = ChipModel::by_name("lis3mdl").unwrap();
    let run = simulate(&Scenario::new(
        &chip,
        Trajectory::Tumble {
            duration_s: 5.0,
            rate_rad_s: 0.8,
        },
        3,
    ))
    .unwrap();
    for (setup, want) in [
        (
            UlogSetup {
                raw_mag: false,
                ..UlogSetup::default()
            },
            "no magnetometer in the log",
        ),
        (
            UlogSetup {
                attitude: false,
                ..UlogSetup::default()
            },
            "no attitude in the log",
        ),
    ] {
        let path = dir.path().join("partial.ulg");
        write_ulog(
            &run.recording,
            &setup,
            &mut std::fs::File::create(&path).unwrap(),
        )
        .unwrap();
        let out = magcal_fit(&[path.to_str().unwrap()]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success());
        assert!(
            err.contains(&format!("{}: {want}", path.display())),
            "{err}"
        );
    }
}

/// The motor current for a coefficient: the field it makes stays under 2 µT (larger ones are left out as gross
/// disturbances by the diagnosis, see docs/flight-logs.md), up to 40 A.
fn current_for(coef: [f64; 3]) -> f64 {
    let size = magcal_calib::frames::norm(coef);
    if size == 0.0 {
        30.0
    } else {
        (2.0 / size).min(40.0)
    }
}

#[test]
fn a_motor_coefficient_and_a_lag_are_recovered_from_a_simulated_log() {
    let dir = tempfile::tempdir().unwrap();
    for (seed, coef, lag_s) in [
        (11, [0.05, -0.05, 0.05], 0.02),
        (12, [1.0, 0.3, -0.6], 0.005),
        (14, [-0.3, 0.6, 0.4], 0.05),
    ] {
        let t0 = std::time::Instant::now();
        let found = fit(&flight_log(
            dir.path(),
            seed,
            coef,
            lag_s,
            120.0,
            current_for(coef),
        ));
        eprintln!("{coef:?} {lag_s}: {found:?} in {:?}", t0.elapsed());
        assert!(recovered(&found, coef), "{coef:?}: {found:?}");
        let lag = found.lag_s.expect("the lag found");
        assert!((lag - lag_s).abs() <= 0.005, "lag {lag} against {lag_s}");
    }
    let found = fit(&flight_log(dir.path(), 13, [0.0; 3], 0.0, 120.0, 30.0));
    assert!(found.coef.is_none(), "{found:?}");
}

/// The study (release, `--ignored`): 100 logs, coefficients of 0.05–1 µT/A (0.5–10 µT per 10 A) on every axis with
/// every sign (the axes within a factor 1.7 of one another, so that a current keeping the field under 2 µT excites
/// each), and lags of 5–50 ms: every coefficient within 10 %, and within two standard errors as often as honest
/// standard errors are (95 %: at least 276 of 300, which they miss once in 300 studies), every lag within 5 ms; and
/// 200 logs without a current term, of which at most 1 % report one.
#[test]
#[ignore]
fn study_motor_coefficients_lags_and_no_false_current_terms() {
    use std::sync::Mutex;
    let dir = tempfile::tempdir().unwrap();
    let sizes: [f64; 5] = [0.05, 0.1, 0.3, 0.6, 1.0];
    let lags = [0.005, 0.01, 0.02, 0.035, 0.05];
    let failures = Mutex::new(Vec::new());
    // Worst relative error, worst error in standard errors, axes within two, Σ (error/SE)², worst lag error.
    let worst = Mutex::new((0.0f64, 0.0f64, 0usize, 0.0f64, 0.0f64));
    common::for_each_seed(100, |seed| {
        let i = ((seed - 1) % 25) as usize;
        let sign = |k: u64| if (seed >> k) & 1 == 1 { -1.0 } else { 1.0 };
        let shares: [f64; 3] = [1.0, 0.6, 0.8];
        let coef: [f64; 3] = std::array::from_fn(|k| {
            (sizes[i % 5] * shares[(i + k) % 3]).clamp(0.05, 1.0) * sign(k as u64)
        });
        let lag_s = lags[i / 5];
        let found = fit(&flight_log(
            dir.path(),
            1000 + seed,
            coef,
            lag_s,
            120.0,
            current_for(coef),
        ));
        let lag = found.lag_s.unwrap_or(f64::NAN);
        let Some((est, se)) = found.coef else {
            failures
                .lock()
                .unwrap()
                .push(format!("{coef:?} {lag_s}: no current term: {found:?}"));
            return;
        };
        let mut w = worst.lock().unwrap();
        for k in 0..3 {
            let err = (est[k] - coef[k]).abs();
            w.0 = w.0.max(err / coef[k].abs());
            w.1 = w.1.max(err / se[k]);
            w.2 += usize::from(err <= 2.0 * se[k]);
            w.3 += (err / se[k]).powi(2);
            if err > 0.1 * coef[k].abs() {
                failures
                    .lock()
                    .unwrap()
                    .push(format!("{coef:?} {lag_s}: {found:?}"));
            }
        }
        w.4 = w.4.max((lag - lag_s).abs());
        if (lag - lag_s).abs().is_nan() || (lag - lag_s).abs() > 0.005 {
            failures
                .lock()
                .unwrap()
                .push(format!("{coef:?} {lag_s}: the lag {lag}"));
        }
    });
    let none = std::sync::atomic::AtomicUsize::new(0);
    common::for_each_seed(200, |seed| {
        if fit(&flight_log(
            dir.path(),
            5000 + seed,
            [0.0; 3],
            0.0,
            60.0,
            30.0,
        ))
        .coef
        .is_some()
        {
            none.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        }
    });
    let (rel, z, within, z2, lag) = *worst.lock().unwrap();
    let false_terms = none.into_inner();
    eprintln!(
        "worst relative error {:.1} %, worst error {z:.2} standard errors, {within} of 300 within two, RMS error \
         {:.2} standard errors, worst lag error {:.2} ms; current terms reported without one injected: \
         {false_terms} of 200",
        100.0 * rel,
        (z2 / 300.0).sqrt(),
        1000.0 * lag
    );
    let failures = failures.into_inner().unwrap();
    assert!(failures.is_empty(), "{failures:#?}");
    assert!(
        within >= 276,
        "{within} of 300 within two standard errors, worst {z}"
    );
    assert!(false_terms <= 2, "{false_terms} of 200");
}

#[test]
fn a_simulated_dataflash_log_reads_back_as_it_was_simulated() {
    let dir = tempfile::tempdir().unwrap();
    let chip = ChipModel::by_name("lis3mdl").unwrap();
    let mut s = Scenario::new(
        &chip,
        Trajectory::Tumble {
            duration_s: 20.0,
            rate_rad_s: 0.8,
        },
        8,
    );
    s.currents = vec![CurrentProfile {
        name: "i_battery".to_owned(),
        on_a: 30.0,
        mean_on_s: 2.0,
        mean_off_s: 2.0,
    }];
    let run = simulate(&s).unwrap();
    let path = dataflash_copy(&run.recording, &dir.path().join("sim.ulg"));
    let log = magcal_flightlog::read(&path).unwrap();
    assert_eq!(log.mags.len(), 1);
    let cal = log.mags[0]
        .calibration
        .as_ref()
        .expect("COMPASS_* in the parameters");
    assert!(
        (cal.offset_g[1] + 0.150).abs() < 1e-6 && (cal.scale[1][1] - 1.02).abs() < 1e-6,
        "{cal:?}"
    );
    let back = log.recording(None).unwrap().rec;
    assert_eq!(back.len(), run.recording.len());
    for i in (0..back.len()).step_by(53) {
        // The field is logged in whole mGauss: 0.05 µT of rounding, undone through the matrix.
        for k in 0..3 {
            assert!(
                (back.mag_ut[i][k] - run.recording.mag_ut[i][k]).abs() < 0.06,
                "row {i}"
            );
        }
        let (q, want) = (
            back.quat.as_ref().unwrap()[i],
            run.recording.quat.as_ref().unwrap()[i],
        );
        let dot: f64 = (0..4).map(|k| q[k] * want[k]).sum();
        // Centidegrees: a few thousandths of a degree.
        assert!(
            2.0 * dot.abs().min(1.0).acos().to_degrees() < 0.02,
            "row {i}: {q:?} {want:?}"
        );
        assert_eq!(
            back.currents[0].values[i] as f32,
            run.recording.currents[0].values[i] as f32
        );
    }
    assert_eq!(
        back.meta.date.map(|d| d.to_string()).as_deref(),
        Some("2025-06-01")
    );
    assert_eq!(back.meta.location.map(|l| l.lat_deg), Some(47.3566));
}

#[test]
fn a_motor_coefficient_and_a_lag_are_recovered_from_a_simulated_dataflash_log() {
    let dir = tempfile::tempdir().unwrap();
    let dir = dir.path().join("dataflash");
    std::fs::create_dir(&dir).unwrap();
    let coef = [0.3, -0.2, 0.25];
    let path = flight_log(&dir, 21, coef, 0.02, 120.0, current_for(coef));
    assert_eq!(path.extension().and_then(|e| e.to_str()), Some("bin"));
    let found = fit(&path);
    assert!(recovered(&found, coef), "{coef:?}: {found:?}");
    let lag = found.lag_s.expect("the lag found");
    assert!((lag - 0.02).abs() <= 0.005, "lag {lag}");
}

#[test]
fn damaged_or_partial_dataflash_logs_say_so() {
    let dir = tempfile::tempdir().unwrap();
    let chip = ChipModel::by_name("lis3mdl").unwrap();
    let run = simulate(&Scenario::new(
        &chip,
        Trajectory::Tumble {
            duration_s: 5.0,
            rate_rad_s: 0.8,
        },
        3,
    ))
    .unwrap();
    let path = dir.path().join("log.bin");
    for (setup, want) in [
        (
            DataflashSetup {
                mag: false,
                ..DataflashSetup::default()
            },
            "no magnetometer in the log",
        ),
        (
            DataflashSetup {
                attitude: false,
                ..DataflashSetup::default()
            },
            "no attitude in the log",
        ),
    ] {
        write_dataflash(
            &run.recording,
            &setup,
            &mut std::fs::File::create(&path).unwrap(),
        )
        .unwrap();
        let out = magcal_fit(&[path.to_str().unwrap()]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            !out.status.success() && err.contains(&format!("{}: {want}", path.display())),
            "{err}"
        );
    }
    write_dataflash(
        &run.recording,
        &DataflashSetup::default(),
        &mut std::fs::File::create(&path).unwrap(),
    )
    .unwrap();
    let whole = std::fs::read(&path).unwrap();
    // Cut, and with bytes changed: read up to the damage, with a note.
    std::fs::write(&path, &whole[..whole.len() * 2 / 3 + 5]).unwrap();
    let log = magcal_flightlog::read(&path).unwrap();
    assert!(
        log.notes.iter().any(|n| n.contains("ends partway")),
        "{:?}",
        log.notes
    );
    let mut damaged = whole.clone();
    for k in 0..50 {
        damaged[2_000 + k * 300] ^= 0xA5;
    }
    std::fs::write(&path, &damaged).unwrap();
    let log = magcal_flightlog::read(&path).unwrap();
    assert!(
        log.notes.iter().any(|n| n.contains("skipped (damage)")),
        "{:?}",
        log.notes
    );
    // Empty, and not a DataFlash log.
    for (content, want) in [
        (&b""[..], "the file is empty"),
        (&b"t,mx,my,mz\n1,2,3,4\n"[..], "no DataFlash message"),
    ] {
        std::fs::write(&path, content).unwrap();
        let out = magcal_fit(&[path.to_str().unwrap()]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success() && err.contains(want), "{err}");
    }
}
