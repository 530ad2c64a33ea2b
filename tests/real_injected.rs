//! Semi-real cases: the physical BROAD 02 recording (undisturbed: its own fit is the truth, A ≈ I, offset < 0.5 µT)
//! with disturbances added to its readings — its real noise, its reference's real error and its real motion kept.
//! Each case is one a probe of 508 such fits (2026-11-26) found wrong or refused; the simulator agrees with the
//! fitter by construction, these do not.

mod common;

use std::path::{Path, PathBuf};

use common::{effect_ids, fit_report, floats, magcal_fit, matrix, real};
use magcal_calib::effects::{Context, Effect, WorldContext};
use magcal_calib::frames;
use serde_json::Value;

const BROAD_02: &str = "broad/broad_02_undisturbed_slow_rotation.csv";

/// A field added to the readings: one of the catalogue's effects (a field in the room is seen through the attitude:
/// rows without one get none), or a pass by a magnet.
enum Added {
    /// An effect as the simulator adds it (`Effect::Disturbance`, `Effect::BiasWindow`).
    Effect(Effect),
    /// A pass by a magnet: `peak_ned_ut` (room axes) at `tc_s`, falling as `(1 + ((t − tc)/w)²)^(−3/2)`.
    Pass {
        tc_s: f64,
        w_s: f64,
        peak_ned_ut: [f64; 3],
    },
    /// A source moving past from `t0_s` to `t1_s`: in room axes, `peak_ut·sin²(π·u)` along a direction turning from
    /// `from` to `to` (`u` the share of the window gone), nothing outside it.
    Moving {
        t0_s: f64,
        t1_s: f64,
        peak_ut: f64,
        from: [f64; 3],
        to: [f64; 3],
    },
}

impl Added {
    /// The field in sensor axes at time `t` with attitude `q` (sensor to NED), if any.
    fn at(&self, t: f64, q: Option<[f64; 4]>) -> [f64; 3] {
        match *self {
            Added::Effect(e) => {
                let mut ctx = Context::body(t, f64::NAN, &[], [0.0; 3]);
                ctx.world = q.map(|q| WorldContext {
                    sensor_to_ned: frames::quat_to_matrix(q),
                    field_ned_ut: [0.0; 3],
                    position_m: [0.0; 3],
                });
                e.perturbation_ut(&ctx)
            }
            Added::Pass {
                tc_s,
                w_s,
                peak_ned_ut,
            } => q.map_or([0.0; 3], |q| {
                let share = (1.0 + ((t - tc_s) / w_s).powi(2)).powf(-1.5);
                frames::expected_sensor_field(q, frames::scale(peak_ned_ut, share))
            }),
            Added::Moving {
                t0_s,
                t1_s,
                peak_ut,
                from,
                to,
            } => match q {
                Some(q) if (t0_s..=t1_s).contains(&t) => {
                    let u = (t - t0_s) / (t1_s - t0_s);
                    let d = frames::add(frames::scale(from, 1.0 - u), frames::scale(to, u));
                    let size = peak_ut * (std::f64::consts::PI * u).sin().powi(2);
                    frames::expected_sensor_field(q, frames::scale(d, size / frames::norm(d)))
                }
                _ => [0.0; 3],
            },
        }
    }
}

/// `rel` with `added` in its readings, written to `dir/name`; without its quaternion columns if `scalar` (a
/// hand-held recording without a reference, for the scalar method).
fn with_added(rel: &str, dir: &Path, name: &str, added: &[Added], scalar: bool) -> PathBuf {
    let text = std::fs::read_to_string(real(rel)).unwrap();
    let mut out = String::new();
    let mut header: Vec<String> = Vec::new();
    for line in text.lines() {
        if line.starts_with('#') {
            out.push_str(line);
            out.push('\n');
            continue;
        }
        let mut cells: Vec<String> = line.split(',').map(str::to_owned).collect();
        if header.is_empty() {
            header = cells.clone();
        } else {
            let column = |name: &str| header.iter().position(|c| c == name).unwrap();
            let t: f64 = cells[column("t")].parse().unwrap();
            let q: Option<[f64; 4]> = ["qw", "qx", "qy", "qz"]
                .iter()
                .map(|c| {
                    cells[column(c)]
                        .parse::<f64>()
                        .ok()
                        .filter(|v| v.is_finite())
                })
                .collect::<Option<Vec<f64>>>()
                .map(|v| [v[0], v[1], v[2], v[3]]);
            let d = added
                .iter()
                .fold([0.0; 3], |acc, a| frames::add(acc, a.at(t, q)));
            for (k, axis) in ["mx", "my", "mz"].into_iter().enumerate() {
                let v: f64 = cells[column(axis)].parse().unwrap();
                cells[column(axis)] = format!("{:.6}", v + d[k]);
            }
        }
        let kept: Vec<&str> = cells
            .iter()
            .zip(&header)
            .filter(|(_, name)| !(scalar && ["qw", "qx", "qy", "qz"].contains(&name.as_str())))
            .map(|(c, _)| c.as_str())
            .collect();
        out.push_str(&kept.join(","));
        out.push('\n');
    }
    let path = dir.join(name);
    std::fs::write(&path, out).unwrap();
    path
}

/// The report's offset −A⁻¹b, µT.
fn offset(r: &Value) -> [f64; 3] {
    let a = matrix(&r["calibration"]["A"]);
    let b = floats(&r["calibration"]["b_ut"]);
    magcal_calib::scalar::centre(&a, [b[0], b[1], b[2]])
}

/// The truth: A and the offset of `clean`, the report of the undisturbed recording's fit.
fn truth(clean: &Value) -> ([[f64; 3]; 3], [f64; 3]) {
    (matrix(&clean["calibration"]["A"]), offset(clean))
}

/// The effects of a report, sorted (a recording made of an undisturbed one with its timing shifted should find the
/// undisturbed one's).
fn sorted_effects(r: &Value) -> Vec<String> {
    let mut ids: Vec<String> = effect_ids(r).into_iter().map(str::to_owned).collect();
    ids.sort();
    ids
}

/// Whether the offset of `r` agrees with the undisturbed recording's (`clean`, its report) within three of their
/// combined standard errors on every axis.
fn offset_agrees(r: &Value, clean: &Value) -> bool {
    let (o, c) = (offset(r), offset(clean));
    let (so, sc) = (
        floats(&r["calibration"]["offset_se_ut"]),
        floats(&clean["calibration"]["offset_se_ut"]),
    );
    (0..3).all(|k| (o[k] - c[k]).abs() <= 3.0 * so[k].hypot(sc[k]))
}

/// Largest |A − A'| element and |offset − offset'|, µT.
fn errors(r: &Value, truth: &([[f64; 3]; 3], [f64; 3])) -> (f64, f64) {
    let a = matrix(&r["calibration"]["A"]);
    let a_err = (0..9)
        .map(|i| (a[i / 3][i % 3] - truth.0[i / 3][i % 3]).abs())
        .fold(0.0, f64::max);
    (a_err, frames::norm(frames::sub(offset(r), truth.1)))
}

/// Three fields in the room (8.5 µT for 44 s, 40 µT for 3 s, 114 µT for 2 s while the sensor rests): a span modelled
/// as a field in the room made the diagnosis' base problem singular, and magcal-fit refused the recording ("the
/// diagnosis' base problem has no solution") though its robust base fit was 0.04 µT from the truth. The spans are
/// now left out instead, and a diagnosis that still cannot be made leaves the base fit standing, said in a note.
#[test]
fn a_diagnosis_that_cannot_model_the_spans_does_not_refuse_the_recording() {
    let dir = tempfile::tempdir().unwrap();
    let added = [
        Added::Effect(Effect::Disturbance {
            t0_s: 73.414,
            t1_s: 76.381,
            field_ned_ut: [16.85, 28.48, 21.71],
        }),
        Added::Effect(Effect::Disturbance {
            t0_s: 156.75,
            t1_s: 158.712,
            field_ned_ut: [27.01, -19.37, -108.67],
        }),
        Added::Effect(Effect::Disturbance {
            t0_s: 20.596,
            t1_s: 64.743,
            field_ned_ut: [1.54, 0.41, 8.51],
        }),
    ];
    let path = with_added(BROAD_02, dir.path(), "rooms.csv", &added, false);
    let out = magcal_fit(&[path.to_str().unwrap()]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let r = fit_report(&path, &[]);
    let clean = fit_report(&real(BROAD_02), &[]);
    let (a_err, o_err) = errors(&r, &truth(&clean));
    assert!(
        a_err < 0.01 && o_err < 0.5 && offset_agrees(&r, &clean),
        "A {a_err}, offset {o_err} µT"
    );
    // The spans say why they were left out.
    let said = r["diagnosis"]["spans"]
        .as_array()
        .unwrap()
        .iter()
        .any(|sp| {
            sp["explanation"]
                .as_str()
                .unwrap()
                .contains("modelled, it left the fit without a solution")
        });
    assert!(said, "{}", r["diagnosis"]["spans"]);
}

/// Passes by a magnet of 4.3 and 3.1 µT at their peaks, without the attitude (the scalar method): the robust fit's
/// scan for shifted windows took 61.9–150.0 s — most of the turning — for a window shifted in |B| (its statistic 313
/// against the 307 a long window needs, its shift 3.6 times the noise against 3: the recording's own structure
/// between turning and rest), and the minutes at rest left fitted A 0.40 off (A_xx 1.37), graded usable. A window
/// that takes most of the directions away is not left out now.
#[test]
fn a_shifted_window_holding_most_of_the_turning_is_not_left_out() {
    let dir = tempfile::tempdir().unwrap();
    let added = [
        Added::Pass {
            tc_s: 110.534,
            w_s: 1.546,
            peak_ned_ut: [-2.28, -0.33, 2.08],
        },
        Added::Pass {
            tc_s: 55.586,
            w_s: 1.513,
            peak_ned_ut: [-1.56, -0.67, -3.95],
        },
    ];
    let path = with_added(BROAD_02, dir.path(), "passes.csv", &added, true);
    let bare = with_added(BROAD_02, dir.path(), "bare.csv", &[], true);
    let truth = truth(&fit_report(&bare, &[]));
    for args in [&[][..], &["--no-diagnose"][..]] {
        let r = fit_report(&path, args);
        assert_eq!(r["method"], "scalar");
        let (a_err, o_err) = errors(&r, &truth);
        assert!(
            a_err < 0.02 && o_err < 0.5,
            "{args:?}: A {a_err}, offset {o_err} µT"
        );
    }
}

/// Three fields on the board without the attitude (64 µT for 56 s, 114 µT for 9 s, and 15 µT for 28 s that outlasts
/// the first by 5 s): the windows were located, but a `bias_step` of 6.5 µT at 104.65 s took up what was left of the
/// third beyond the span, and since the sensor rested for most of the time before it (a fifth of the directions the
/// recording covers), any offset fitted there: the parameters file's offset was 6.7 µT off (the base fit 0.13). The
/// scalar method now offers a step only where the sensor turned on both sides of it.
#[test]
fn a_step_where_the_sensor_rested_on_one_side_is_not_offered_to_the_magnitude() {
    let dir = tempfile::tempdir().unwrap();
    let added = [
        Added::Effect(Effect::BiasWindow {
            t0_s: 44.998,
            t1_s: 101.259,
            offset_ut: [64.07, -3.3, -35.85],
        }),
        Added::Effect(Effect::BiasWindow {
            t0_s: 15.027,
            t1_s: 23.564,
            offset_ut: [39.46, 61.46, -87.41],
        }),
        Added::Effect(Effect::BiasWindow {
            t0_s: 78.643,
            t1_s: 106.699,
            offset_ut: [7.69, 7.11, -10.86],
        }),
    ];
    let path = with_added(BROAD_02, dir.path(), "boards.csv", &added, true);
    let bare = with_added(BROAD_02, dir.path(), "bare.csv", &[], true);
    let truth = truth(&fit_report(&bare, &[]));
    let r = fit_report(&path, &[]);
    let ids = effect_ids(&r);
    assert!(!ids.contains(&"bias_step"), "{ids:?}");
    let (a_err, o_err) = errors(&r, &truth);
    assert!(a_err < 0.02 && o_err < 0.5, "A {a_err}, offset {o_err} µT");
}

/// 300 µT on the board for the middle 90 s of the turning (49.9–140.1 s): the robust fit took the state with most
/// directions — the one with the magnet — and the stretches before and after, on the sensor's own offset, for
/// spans; the calibration was 300 µT off, graded usable with a warning that the rest "sat on another offset". The
/// recording began and ended on that offset: the verdict became redo, saying so. With the noise measured per sample
/// (BROAD's is alike in neighbouring samples, and its floor was read 30 % low) the fit now takes the state the
/// recording began and ended in, the sensor's own: either is no silent error.
#[test]
fn a_calibration_of_the_state_between_two_stretches_on_another_offset_is_redo() {
    let dir = tempfile::tempdir().unwrap();
    let added = [Added::Effect(Effect::BiasWindow {
        t0_s: 49.911,
        t1_s: 140.099,
        offset_ut: [-100.71, -269.24, 85.84],
    })];
    let path = with_added(BROAD_02, dir.path(), "middle.csv", &added, false);
    let r = fit_report(&path, &[]);
    let clean = fit_report(&real(BROAD_02), &[]);
    // Either the calibration is of the sensor's own state (the start's and the end's), or the verdict says it is not.
    let (a_err, o_err) = errors(&r, &truth(&clean));
    assert!(
        r["verdict"]["grade"] == "redo" || (a_err < 0.02 && o_err < 1.0),
        "A {a_err}, offset {o_err} µT, {}",
        r["verdict"]
    );
    // The readings the fit kept are in µT: the stretches on the other offset are no unit.
    let warnings = r["warnings"].as_array().expect("the report's warnings");
    assert!(
        warnings
            .iter()
            .any(|w| w.to_string().contains("another offset"))
            && !warnings.iter().any(|w| w.to_string().contains("not in µT")),
        "{warnings:?}"
    );
    // Without the magnet, nothing of the sort.
    assert_ne!(clean["verdict"]["grade"], "redo", "{}", clean["verdict"]);
}

/// 5.6 µT on the board for 53 s (103.9–157.0 s, 28 % of the recording): beside the reference's own error (0.9 µT)
/// it is gross only in places, and the robust fit kept the stretches between — the diagnosis modelled seven windows
/// and the calibration was A 0.08 off, graded usable. Spans that one constant explains with the stretches between
/// are now one window, its edges located again, and the vector method's final fit is the diagnosis' own when it
/// holds every row the base fit kept (moved from the base fit by the clean rows' difference, it took the stretches'
/// pull back in).
#[test]
fn a_field_on_the_board_gross_only_in_places_is_one_window() {
    let dir = tempfile::tempdir().unwrap();
    let (t0_s, t1_s) = (103.912, 157.026);
    let added = [Added::Effect(Effect::BiasWindow {
        t0_s,
        t1_s,
        offset_ut: [4.78, -2.59, 1.33],
    })];
    let path = with_added(BROAD_02, dir.path(), "body.csv", &added, false);
    let r = fit_report(&path, &[]);
    let windows: Vec<&Value> = r["diagnosis"]["effects"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|e| e["id"] == "bias_window")
        .collect();
    assert_eq!(windows.len(), 1, "{}", r["diagnosis"]["effects"]);
    let p = &windows[0]["params"];
    let (f0, f1) = (p["t0_s"].as_f64().unwrap(), p["t1_s"].as_f64().unwrap());
    assert!(
        (f0 - t0_s).abs() < 1.0 && (f1 - t1_s).abs() < 1.0,
        "{f0}–{f1} s"
    );
    let clean = fit_report(&real(BROAD_02), &[]);
    let (a_err, o_err) = errors(&r, &truth(&clean));
    assert!(
        a_err < 0.01 && o_err < 0.5 && offset_agrees(&r, &clean),
        "A {a_err}, offset {o_err} µT"
    );
}

/// The same 5.6 µT on the board without the quaternions (the scalar method): the window scan finds it exactly, but
/// the sensor turned most while it was there — the samples left would cover 44 % of the directions against 92 %.
/// It used to stay in the fit, which landed 5 µT off (graded usable at 4° with nothing said, then with a warning that
/// the calibration mixed the two states). The window is now a second centre fitted with the rest: its readings give
/// the shape, the rest the offset: measured against the undisturbed recording's calibration, A within 0.0023 and the
/// offset 1.27 µT off — along x, where the rest turned least, 2.9 of its standard errors (0.43 µT) — graded usable,
/// the window said as another offset.
#[test]
fn a_window_holding_most_of_the_turning_is_a_second_centre() {
    let dir = tempfile::tempdir().unwrap();
    let added = [Added::Effect(Effect::BiasWindow {
        t0_s: 103.912,
        t1_s: 157.026,
        offset_ut: [4.78, -2.59, 1.33],
    })];
    let path = with_added(BROAD_02, dir.path(), "body.csv", &added, true);
    let bare = with_added(BROAD_02, dir.path(), "bare.csv", &[], true);
    let r = fit_report(&path, &[]);
    assert_eq!(r["method"], "scalar");
    let said = |what: &str| {
        r["warnings"]
            .as_array()
            .expect("the report's warnings")
            .iter()
            .filter(|w| w.to_string().contains(what))
            .map(|w| w.to_string())
            .collect::<Vec<_>>()
    };
    assert!(said("mixes the two states").is_empty(), "{}", r["warnings"]);
    let other = said("sat on another offset");
    assert!(
        other.len() == 1 && other[0].contains("103.9–157.0 s"),
        "{}",
        r["warnings"]
    );
    let (a_err, o_err) = errors(&r, &truth(&fit_report(&bare, &[])));
    assert!(a_err < 0.01 && o_err < 1.5, "A {a_err}, offset {o_err} µT");
    assert_ne!(r["verdict"]["grade"], "good", "{}", r["verdict"]);
}

/// 300 µT on the board for the middle 90 s, without the quaternions: the scalar method cannot calibrate it, and said
/// so as a "planar rotation" — "the sensor turned about that axis only; also tip the sensor" — though the sensor had
/// turned through every direction. The refusal now says that the readings spread over more than turning in the
/// field can take them: two centres, something magnetic on the board. (A genuinely planar recording, a turntable's,
/// is refused as before, without it: `tests/scalar_ellipsoids.rs`.)
#[test]
fn a_refusal_for_want_of_directions_says_when_the_readings_sit_on_two_centres() {
    let dir = tempfile::tempdir().unwrap();
    let added = [Added::Effect(Effect::BiasWindow {
        t0_s: 49.911,
        t1_s: 140.099,
        offset_ut: [-100.71, -269.24, 85.84],
    })];
    let path = with_added(BROAD_02, dir.path(), "middle.csv", &added, true);
    let out = magcal_fit(&[path.to_str().unwrap()]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        err.contains("two centres") && err.contains("The fit itself says: planar rotation"),
        "{err}"
    );
}

/// `rel` with its attitude reference `rows` rows ahead of the readings (each row's quaternion the one `rows` after;
/// none for the last ones), written to `dir/name`.
fn with_reference_ahead(rel: &str, dir: &Path, name: &str, rows: usize) -> PathBuf {
    let text = std::fs::read_to_string(real(rel)).unwrap();
    let (meta, data): (Vec<&str>, Vec<&str>) = text.lines().partition(|l| l.starts_with('#'));
    let header: Vec<&str> = data[0].split(',').collect();
    let quat: Vec<usize> = ["qw", "qx", "qy", "qz"]
        .iter()
        .map(|c| header.iter().position(|h| h == c).unwrap())
        .collect();
    let cells: Vec<Vec<&str>> = data[1..].iter().map(|l| l.split(',').collect()).collect();
    let mut out: Vec<String> = meta.iter().map(|l| l.to_string()).collect();
    out.push(data[0].to_owned());
    for (i, row) in cells.iter().enumerate() {
        let mut row = row.clone();
        for &c in &quat {
            row[c] = cells.get(i + rows).map_or("", |later| later[c]);
        }
        out.push(row.join(","));
    }
    let path = dir.join(name);
    std::fs::write(&path, out.join("\n") + "\n").unwrap();
    path
}

/// BROAD 02 with its reference 49 ms ahead of the readings (seven rows; they already lag it by 15 ms: 64 ms in all): while
/// the sensor turns at up to 7 rad/s the field turns by up to 0.45 rad in the lag, beyond the first-order term of
/// `time_lag`, and the diagnosis reported 19 disturbances of 5–8 µT and a `rate_coupling` of 56–61 ms per axis,
/// with "record again with magnets, metal and cables away from the sensor". The lag is now found coarsely first and
/// the effect linearised there: one `time_lag` of 64 ms, nothing else, and the calibration of the recording as it
/// was.
#[test]
fn readings_late_by_tens_of_milliseconds_are_a_time_lag_not_disturbances() {
    let dir = tempfile::tempdir().unwrap();
    let path = with_reference_ahead(BROAD_02, dir.path(), "ahead.csv", 7);
    let r = fit_report(&path, &[]);
    let clean = fit_report(&real(BROAD_02), &[]);
    let d = &r["diagnosis"];
    assert_eq!(
        sorted_effects(&r),
        sorted_effects(&clean),
        "{}",
        d["effects"]
    );
    let lag_s = d["effects"]
        .as_array()
        .unwrap()
        .iter()
        .find(|e| e["id"] == "time_lag")
        .expect("a time lag")["params"]["lag_s"]
        .as_f64()
        .unwrap();
    assert!((lag_s - 0.0638).abs() < 0.003, "{lag_s} s");
    assert_eq!(d["spans"].as_array().unwrap().len(), 0, "{}", d["spans"]);
    let (a_err, o_err) = errors(&r, &truth(&clean));
    assert!(a_err < 0.005 && o_err < 0.3, "A {a_err}, offset {o_err} µT");
    // The summary counts the rows the final model used, and says what the base fit left out.
    let out = magcal_fit(&[path.to_str().unwrap()]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    let head = stdout.lines().next().unwrap();
    let used = d["samples_used"].as_u64().unwrap();
    let base_used = r["samples"]["used"].as_u64().unwrap();
    assert!(used > base_used + 1000, "{used} against {base_used}");
    assert!(
        head.contains(&format!(", {used} of "))
            && head.contains(&format!(
                "the base fit, without the effects the diagnosis found, used {base_used}"
            )),
        "{head}"
    );
}

/// The same 49 ms on broad 33, where a magnet sat on the board for 56 s: the lag bent the base fit's gains (A 0.19
/// off), the guard then refused the lag itself ("the gains would move by 5.1 % from the base fit's") and the final
/// model stayed 0.12 off in A. A timing effect corrects the reference, not the sensor: the gains are now judged
/// against the base fit with it, and the calibration lands where the recording as it was puts it (the issue's
/// tolerances: A within 0.065 of I, offset within 2.9 µT of 0).
#[test]
fn a_late_reference_and_a_magnet_on_the_board_are_both_modelled() {
    let dir = tempfile::tempdir().unwrap();
    let path = with_reference_ahead(
        "broad/broad_33_disturbed_attached_magnet_2cm.csv",
        dir.path(),
        "ahead.csv",
        7,
    );
    let r = fit_report(&path, &[]);
    let effects = r["diagnosis"]["effects"].as_array().unwrap();
    let window = effects.iter().find(|e| e["id"] == "bias_window");
    let window = window.unwrap_or_else(|| panic!("{effects:?}"));
    let (t0, t1) = (
        window["params"]["t0_s"].as_f64().unwrap(),
        window["params"]["t1_s"].as_f64().unwrap(),
    );
    // Attached by hand around 40–42 s, taken off around 98.6 s (as tests/real_disturbed.rs has it).
    assert!(
        (39.0..=44.0).contains(&t0) && (96.6..=100.6).contains(&t1),
        "{t0}–{t1} s"
    );
    let lags: Vec<f64> = effects
        .iter()
        .filter_map(|e| match e["id"].as_str() {
            Some("time_lag") => Some(vec![e["params"]["lag_s"].as_f64().unwrap()]),
            Some("rate_coupling") => Some(floats(&e["params"]["lag_axis_s"])),
            _ => None,
        })
        .flatten()
        .collect();
    assert!(
        !lags.is_empty() && lags.iter().all(|l| (l - 0.065).abs() < 0.006),
        "{lags:?} s"
    );
    let a = matrix(&r["calibration"]["A"]);
    let a_err = (0..9)
        .map(|i| (a[i / 3][i % 3] - f64::from(u8::from(i / 3 == i % 3))).abs())
        .fold(0.0, f64::max);
    let o = frames::norm(offset(&r));
    assert!(a_err < 0.065 && o < 2.9, "A {a_err}, offset {o} µT");
}

/// BROAD 02 with 250 µT in the room for 28 s (a sixth of it) and a smaller field overlapping it, and with 280 µT on
/// the board for 37 s: plain fits against the sixteen attitude conventions were dragged, and a wrong one came out
/// with half the median misfit of magcal's; then trimmed fits from all samples did not recover from the board's
/// field (magcal's convention explained 53 % of the readings, a wrong one 69 %). Both calibrations (A within 0.003
/// of the truth) were graded redo as "the scalar last, with a north-west-up world". The conventions are now compared
/// by the share of the readings a trimmed fit explains, each fit starting from the robust fit's samples.
#[test]
fn a_field_in_the_room_or_on_the_board_for_a_while_is_no_other_attitude_convention() {
    let dir = tempfile::tempdir().unwrap();
    let room = [
        Added::Effect(Effect::Disturbance {
            t0_s: 84.216,
            t1_s: 112.244,
            field_ned_ut: [175.29, 180.93, -159.99],
        }),
        Added::Effect(Effect::Disturbance {
            t0_s: 79.88,
            t1_s: 88.433,
            field_ned_ut: [-6.65, -8.77, 3.03],
        }),
    ];
    let board = [
        Added::Effect(Effect::BiasWindow {
            t0_s: 125.377,
            t1_s: 161.979,
            offset_ut: [-100.59, 184.61, 192.91],
        }),
        Added::Effect(Effect::BiasWindow {
            t0_s: 44.687,
            t1_s: 47.154,
            offset_ut: [-39.46, 4.15, -55.8],
        }),
    ];
    let truth = truth(&fit_report(&real(BROAD_02), &[]));
    for (name, added) in [("room.csv", &room), ("board.csv", &board)] {
        let path = with_added(BROAD_02, dir.path(), name, added, false);
        let r = fit_report(&path, &[]);
        assert!(
            r.get("attitude_convention").is_none(),
            "{name}: {}",
            r["attitude_convention"]
        );
        let (a_err, o_err) = errors(&r, &truth);
        assert!(
            a_err < 0.02 && o_err < 1.0,
            "{name}: A {a_err}, offset {o_err} µT"
        );
        assert_ne!(r["verdict"]["grade"], "redo", "{name}: {}", r["verdict"]);
    }
}

/// BROAD 02 with its reference a quarter of a second to a second ahead of the readings (two streams on different
/// clocks): the diagnosis took 250–500 ms for a filter's delay on each axis ("rate_coupling", three delays within 2
/// ms of each other, "not one timing offset") and graded redo "for want of directions"; at a second the base fit's
/// gains differed 85-fold, the readings were "not in µT" and nine magnets were found. Now the offset is named, with
/// or without the diagnosis; below 0.2 s it stays the diagnosis' `time_lag`.
#[test]
fn a_reference_out_of_step_with_the_readings_is_named_with_its_offset() {
    let dir = tempfile::tempdir().unwrap();
    // 36 and 143 rows of 7 ms, and BROAD's own 15 ms.
    for (rows, offset_s) in [(36, 0.267), (143, 1.016)] {
        let path = with_reference_ahead(BROAD_02, dir.path(), &format!("ahead{rows}.csv"), rows);
        for extra in [&[][..], &["--no-diagnose"][..]] {
            let r = fit_report(&path, extra);
            let found = r["reference_offset"]["offset_s"].as_f64();
            assert!(
                found.is_some_and(|s| (s - offset_s).abs() < 0.01),
                "{rows} rows {extra:?}: {}",
                r["reference_offset"]
            );
            assert_eq!(r["verdict"]["grade"], "redo", "{}", r["verdict"]);
            assert!(r.get("diagnosis").is_none(), "{}", r["diagnosis"]);
            let warnings = r["warnings"].to_string();
            assert!(
                warnings.contains("out of step") && !warnings.contains("not in µT"),
                "{warnings}"
            );
        }
    }
    // 21 rows (147 ms, 162 in all): the diagnosis models it.
    let path = with_reference_ahead(BROAD_02, dir.path(), "ahead21.csv", 21);
    let r = fit_report(&path, &[]);
    assert!(
        r.get("reference_offset").is_none(),
        "{}",
        r["reference_offset"]
    );
    assert_eq!(
        sorted_effects(&r),
        sorted_effects(&fit_report(&real(BROAD_02), &[])),
        "{}",
        r["diagnosis"]["effects"]
    );
}

/// Sources moving past for `share` of the referenced time `t0_s..t1_s`: windows of 3–8 s at random places until
/// their union covers it, each with a peak of 10–40 µT along a direction turning as it goes.
fn moving_sources(t0_s: f64, t1_s: f64, share: f64, seed: u64) -> Vec<Added> {
    use rand::{RngExt, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut windows: Vec<(f64, f64)> = Vec::new();
    let covered = |w: &[(f64, f64)]| {
        let mut v: Vec<(f64, f64)> = w.iter().map(|&(a, b)| (a.max(t0_s), b.min(t1_s))).collect();
        v.sort_by(|x, y| x.0.total_cmp(&y.0));
        let (mut total, mut end) = (0.0, f64::NEG_INFINITY);
        for (a, b) in v {
            if b > end.max(a) {
                total += b - end.max(a);
                end = b;
            }
        }
        total
    };
    while covered(&windows) < share * (t1_s - t0_s) {
        let w = rng.random_range(3.0..8.0);
        let a = rng.random_range(t0_s - w / 2.0..t1_s - w / 2.0);
        windows.push((a, a + w));
    }
    let mut direction = || -> [f64; 3] { std::array::from_fn(|_| rng.random_range(-1.0..1.0)) };
    windows
        .iter()
        .map(|&(a, b)| Added::Moving {
            t0_s: a,
            t1_s: b,
            peak_ut: 10.0 + 30.0 * direction()[0].abs(),
            from: direction(),
            to: direction(),
        })
        .collect()
}

/// Issue 37, acceptance 2: BROAD 02 and the Nexus 5 NoDist trial with sources moving past (world-fixed, several,
/// changing as they go) for 50 %, 70 % and 85 % of the referenced time. The fit of the majority follows the
/// disturbances (before: "the reference is likely in another convention" at 70 % and 85 %); the consistent part
/// calibrates within the shared README's tolerances, or the verdict is redo (naming the part that agrees and what it
/// lacks when it does not predict itself) — never a convention or a clock.
#[test]
fn the_consistent_part_of_a_mostly_disturbed_recording_calibrates_or_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let nexus = "inria-nexus5/nexus5_nodist_AR.csv";
    // The referenced time of each (the Nexus 5's reference ends at 64 s).
    for (rel, t0_s, t1_s, a_tol, offset_tol_ut) in [
        (BROAD_02, 0.3, 186.0, 0.03, 1.0),
        (nexus, 0.0, 64.0, 0.05, 3.0),
    ] {
        let clean = truth(&fit_report(&real(rel), &[]));
        for share in [0.5, 0.7, 0.85] {
            let name = format!("{}_{share}.csv", rel.replace('/', "_"));
            let added = moving_sources(t0_s, t1_s, share, 1);
            let path = with_added(rel, dir.path(), &name, &added, false);
            let r = fit_report(&path, &[]);
            let warnings = r["warnings"].to_string();
            let verdict = r["verdict"].to_string();
            assert!(
                r.get("attitude_convention").is_none()
                    && r.get("reference_offset").is_none()
                    && !warnings.contains("another convention")
                    && !verdict.contains("convention and timing"),
                "{name}: a convention or a clock named: {warnings} {verdict}"
            );
            if r.get("undetermined_part").is_some() {
                assert_eq!(r["verdict"]["grade"], "redo", "{name}");
                assert!(warnings.contains("do not determine"), "{name}: {warnings}");
                continue;
            }
            // Within the tolerances, or redo: never a wrong calibration graded usable.
            let (a_err, offset_err) = errors(&r, &clean);
            assert!(
                (a_err < a_tol && offset_err < offset_tol_ut) || r["verdict"]["grade"] == "redo",
                "{name}: A off by {a_err:.3}, offset by {offset_err:.2} µT ({verdict})"
            );
            eprintln!(
                "{name}: A off by {a_err:.3}, offset by {offset_err:.2} µT, {}",
                r["verdict"]["grade"]
            );
        }
    }
}
