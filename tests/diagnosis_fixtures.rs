//! Acceptance: the concealed fixtures in `fixtures/diagnosis/` — one per effect of the catalogue, each below the
//! noise in every sample and partly absorbed by the 12-parameter model, plus recordings without any effect whose
//! temperature and current vary — are diagnosed as their effect with its parameters recovered within their
//! uncertainty, and the null ones come out consistent.

mod common;

use std::path::{Path, PathBuf};

use common::{effect_ids, fit_report};
use magcal_app::effect_spec::{self, Defaults};
use magcal_app::params::ParamsFile;
use magcal_calib::Inputs;
use magcal_calib::effects::{Context, Effect, WorldContext};
use magcal_calib::effects::{Frame, Need};
use magcal_calib::frames;
use magcal_recording::Recording;
use nalgebra::{DMatrix, DVector};
use serde_json::Value;

fn dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/diagnosis")
}

/// The fixtures: (name, magcal-sim arguments) from commands.txt.
fn fixtures() -> Vec<(String, Vec<String>)> {
    std::fs::read_to_string(dir().join("commands.txt"))
        .unwrap()
        .lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .map(|l| {
            let (name, args) = l.split_once('|').unwrap();
            (
                name.trim().to_owned(),
                args.split_whitespace().map(str::to_owned).collect(),
            )
        })
        .collect()
}

struct Truth {
    noise_ut: [f64; 3],
    effects: Vec<Effect>,
}

fn truth(name: &str, rec: &Recording) -> Truth {
    let text = std::fs::read_to_string(dir().join(format!("{name}.truth.toml"))).unwrap();
    let value: toml::Value = toml::from_str(&text).unwrap();
    let noise: Vec<f64> = value["noise_ut"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_float().unwrap())
        .collect();
    let currents: Vec<String> = rec.currents.iter().map(|c| c.name.clone()).collect();
    let defaults = Defaults {
        t_ref_c: f64::NAN,
        field_drift_t_ref_s: f64::NAN,
        currents: &currents,
    };
    Truth {
        noise_ut: [noise[0], noise[1], noise[2]],
        effects: value["effects"]
            .as_array()
            .unwrap()
            .iter()
            .map(|e| effect_spec::parse(e.as_str().unwrap(), &defaults).unwrap())
            .collect(),
    }
}

/// The effect's perturbation at every sample, from the recording's own channels and its (exact) attitude.
fn perturbation(rec: &Recording, e: &Effect) -> Vec<[f64; 3]> {
    let f = rec
        .meta
        .field_ned_ut
        .expect("vector fixtures carry the field");
    let q = rec.quat.as_ref().unwrap();
    let t = rec.t_s.as_ref().unwrap();
    let field: Vec<[f64; 3]> = q
        .iter()
        .map(|q| frames::expected_sensor_field(*q, f))
        .collect();
    let n = rec.len();
    (0..n)
        .map(|i| {
            let (a, b) = (i.saturating_sub(1), (i + 1).min(n - 1));
            let rate = frames::scale(frames::sub(field[b], field[a]), 1.0 / (t[b] - t[a]));
            let currents: Vec<f64> = rec.currents.iter().map(|c| c.values[i]).collect();
            let ctx = Context {
                t_s: t[i],
                temp_c: rec.temp_c.as_ref().map_or(f64::NAN, |c| c[i]),
                currents_a: &currents,
                field_ut: field[i],
                field_rate_ut_per_s: rate,
                world: Some(WorldContext {
                    sensor_to_ned: frames::quat_to_matrix(q[i]),
                    field_ned_ut: f,
                    position_m: [0.0; 3],
                }),
            };
            e.perturbation_ut(&ctx)
        })
        .collect()
}

/// The share of the perturbation's energy the base model (per axis: the field components and a constant) takes up.
fn absorbed_share(rec: &Recording, delta: &[[f64; 3]]) -> f64 {
    let f = rec.meta.field_ned_ut.unwrap();
    let r: Vec<[f64; 3]> = rec
        .quat
        .as_ref()
        .unwrap()
        .iter()
        .map(|q| frames::expected_sensor_field(*q, f))
        .collect();
    let x = DMatrix::from_fn(r.len(), 4, |i, k| if k < 3 { r[i][k] } else { 1.0 });
    let (mut total, mut left) = (0.0, 0.0);
    for j in 0..3 {
        let y = DVector::from_iterator(r.len(), delta.iter().map(|d| d[j]));
        let beta = x.clone().svd(true, true).solve(&y, 1e-12).unwrap();
        let resid = &y - &x * beta;
        total += y.norm_squared();
        left += resid.norm_squared();
    }
    1.0 - left / total
}

/// Each fitted parameter of `found` (a report effect) is within `k` standard errors of the truth.
fn assert_params_within(name: &str, found: &Value, truth: &Effect, currents: &[String], k: f64) {
    let spec = effect_spec::format(truth, currents);
    let params = &found["params"];
    for part in spec.split_once(':').unwrap().1.split(';') {
        let (pname, values) = part.split_once('=').unwrap();
        let Some(se) = params.get(format!("{pname}_se")) else {
            continue;
        };
        let want: Vec<f64> = values.split(',').map(|v| v.parse().unwrap()).collect();
        let got: Vec<f64> = match &params[pname] {
            Value::Array(a) => a.iter().map(|v| v.as_f64().unwrap()).collect(),
            v => vec![v.as_f64().unwrap()],
        };
        let se: Vec<f64> = match se {
            Value::Array(a) => a.iter().map(|v| v.as_f64().unwrap()).collect(),
            v => vec![v.as_f64().unwrap()],
        };
        for c in 0..want.len() {
            let z = (got[c] - want[c]) / se[c];
            assert!(
                z.abs() <= k,
                "{name}: {pname}[{c}] = {} ± {}, truth {} (z = {z:.2})",
                got[c],
                se[c],
                want[c]
            );
        }
    }
}

#[test]
fn each_concealed_effect_is_diagnosed_with_its_parameters() {
    for (name, _) in fixtures() {
        let path = dir().join(format!("{name}.csv"));
        let rec = Recording::read(&path).unwrap();
        let truth = truth(&name, &rec);
        let report = fit_report(&path, &[]);
        let d = &report["diagnosis"];
        let ids = effect_ids(&report);
        let Some(effect) = truth.effects.first() else {
            assert_eq!(d["verdict"], "consistent", "{name}: {ids:?}");
            assert!(ids.is_empty());
            continue;
        };
        assert_eq!(d["verdict"], "mismatch", "{name}");
        assert_eq!(ids, vec![effect.id().as_str()], "{name}");
        let found = &d["effects"][0];
        let currents: Vec<String> = rec.currents.iter().map(|c| c.name.clone()).collect();
        // Three standard errors: a parameter outside is a 0.3 % event for a Gaussian estimate.
        assert_params_within(&name, found, effect, &currents, 3.0);
        let (before, after) = (
            found["holdout_rms_before_ut"].as_f64().unwrap(),
            found["holdout_rms_after_ut"].as_f64().unwrap(),
        );
        assert!(after < before, "{name}: held-out {before} → {after}");
    }
}

#[test]
fn the_effects_are_concealed_below_the_noise_and_partly_absorbed() {
    for (name, args) in fixtures() {
        if args.iter().any(|a| a == "none") {
            continue; // scalar fixtures: no attitude to evaluate world-frame context with
        }
        let rec = Recording::read(&dir().join(format!("{name}.csv"))).unwrap();
        let truth = truth(&name, &rec);
        let noise_rms = (truth.noise_ut.iter().map(|s| s * s).sum::<f64>() / 3.0).sqrt();
        for e in &truth.effects {
            let delta = perturbation(&rec, e);
            let largest = delta
                .iter()
                .map(|d| frames::norm(*d) / 3f64.sqrt())
                .fold(0.0, f64::max);
            assert!(
                largest < noise_rms,
                "{name}: a sample carries {largest:.3} µT per axis, noise {noise_rms:.3}"
            );
            let share = absorbed_share(&rec, &delta);
            assert!(
                share > 0.005 && share < 0.98,
                "{name}: the base model absorbs {:.1} %",
                100.0 * share
            );
        }
    }
}

#[test]
fn the_fixtures_are_what_their_commands_write() {
    let tmp = tempfile::tempdir().unwrap();
    let common = [
        "--duration",
        "90",
        "--rate",
        "30",
        "--temperature",
        "22,6,40,1,35",
        "--current",
        "motor:1.2,4,6",
    ];
    for (name, args) in fixtures() {
        let out = tmp.path().join(format!("{name}.csv"));
        let truth = tmp.path().join(format!("{name}.truth.toml"));
        let status = std::process::Command::new(env!("CARGO_BIN_EXE_magcal-sim"))
            .args(common)
            .args(&args)
            .arg("--out")
            .arg(&out)
            .arg("--truth")
            .arg(&truth)
            .stderr(std::process::Stdio::null())
            .status()
            .unwrap();
        assert!(status.success());
        // The truth, in the layout magcal-record writes too.
        let read = |p: &Path| magcal_app::truth::TruthFile::read(p).unwrap();
        assert_eq!(
            read(&truth),
            read(&dir().join(format!("{name}.truth.toml"))),
            "{name}"
        );
        let (a, b) = (
            Recording::read(&out).unwrap(),
            Recording::read(&dir().join(format!("{name}.csv"))).unwrap(),
        );
        assert_eq!(a.len(), b.len(), "{name}");
        for (x, y) in a.mag_ut.iter().zip(&b.mag_ut) {
            assert!(
                (0..3).all(|k| (x[k] - y[k]).abs() < 1e-5),
                "{name}: {x:?} vs {y:?}"
            );
        }
    }
}

/// The extended model goes to the parameters file, and `apply` with it removes the body-fixed effect: applied to
/// the fixture, the file's model leaves the residual the report gives for the final model.
#[test]
fn the_extended_model_is_written_and_applied() {
    for (name, args) in fixtures() {
        if args.iter().any(|a| a == "none") {
            continue;
        }
        let path = dir().join(format!("{name}.csv"));
        let rec = Recording::read(&path).unwrap();
        let Some(effect) = truth(&name, &rec).effects.first().copied() else {
            continue;
        };
        if effect.id().frame() != Frame::Body {
            continue;
        }
        let tmp = tempfile::tempdir().unwrap();
        let params = tmp.path().join("params.toml");
        let report = fit_report(&path, &["--out", params.to_str().unwrap()]);
        let text = std::fs::read_to_string(&params).unwrap();
        if effect.id().descriptor().needs.contains(&Need::Time) {
            // Tied to this recording's clock (a drift, a step): the report's, not the sensor's model.
            assert!(
                !text.contains(&format!("id = \"{}\"", effect.id()))
                    && text.contains(&format!("# {} of the recording", effect.id())),
                "{name}: {text}"
            );
            continue;
        }
        assert!(
            text.contains(&format!("id = \"{}\"", effect.id())),
            "{name}: {text}"
        );
        let channels: Vec<String> = rec.currents.iter().map(|c| c.name.clone()).collect();
        let model = ParamsFile::read(&params).unwrap().model(&channels).unwrap();
        let f = rec.meta.field_ned_ut.unwrap();
        let (q, t, temp) = (
            rec.quat.as_ref().unwrap(),
            rec.t_s.as_ref().unwrap(),
            rec.temp_c.as_ref().unwrap(),
        );
        let mut ss = 0.0;
        for i in 0..rec.len() {
            let currents: Vec<f64> = rec.currents.iter().map(|c| c.values[i]).collect();
            let inputs = Inputs {
                t_s: t[i],
                temp_c: temp[i],
                currents_a: &currents,
            };
            let d = frames::sub(
                model.apply(rec.mag_ut[i], &inputs),
                frames::expected_sensor_field(q[i], f),
            );
            ss += frames::dot(d, d);
        }
        let applied = (ss / (3.0 * rec.len() as f64)).sqrt();
        let reported = report["residual"]["rms_ut"].as_f64().unwrap();
        assert!(
            (applied / reported - 1.0).abs() < 0.01,
            "{name}: apply gives {applied}, the report {reported}"
        );
        assert!(
            reported < report["base"]["rms_ut"].as_f64().unwrap(),
            "{name}"
        );
    }
}
