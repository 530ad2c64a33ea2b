//! Acceptance: power and false alarms of the diagnosis over 200 random seeds (random sensor, field, trajectory, noise
//! 0.05–0.5 µT, 20–100 Hz, 2–5 minutes; temperature and a current always recorded). For each effect at 0.5 σ RMS per
//! axis (a bias window and a magnet nearby aside: tests/disturbed_study.rs) the detection rate with the right id is at least 95 %; on null recordings the false-alarm rate is at most 1 %.
//!
//! For the effects detected, each fitted parameter's error divided by its reported standard error is collected: its
//! standard deviation must be near 1 (0.75–1.3) for the uncertainties to be honest.
//!
//! Heavy; regenerate the tables in docs/diagnosis.md with
//! `cargo test --release --test diagnosis_power -- --ignored --nocapture`.

mod common;

use std::collections::BTreeMap;
use std::sync::Mutex;

use magcal_app::effect_spec;
use magcal_calib::diagnosis::{FoundEffect, ParamValue};
use magcal_calib::effects::Effect;

use magcal_app::calibrate::calibrate;
use magcal_app::field::ReferenceField;
use magcal_app::fit::Method;
use magcal_calib::diagnosis::{Diagnosis, Verdict};
use magcal_calib::effects::EffectId;
use magcal_sim::study::{random_effect, random_scenario, scale_to_rms};
use magcal_sim::{Scenario, simulate};

const SEEDS: u64 = 200;
const SIZE_IN_SIGMA: f64 = 0.5;

/// The diagnosis, and the reference's heading when the fit found it off true north (degrees east, its standard
/// error): a field given off in declination is the same misfit as a reference turned about down, and the fit takes it
/// as the heading when that explains it ([`magcal_app::reference_heading`]).
fn diagnose_with_heading(s: &Scenario) -> (Diagnosis, Option<(f64, f64)>) {
    let run = simulate(s).expect("valid scenario");
    let field = ReferenceField::Vector {
        field_ned_ut: s.field_ned_ut,
        source: "simulated".into(),
    };
    let cal = calibrate(&run.recording, Method::Auto, field, true).expect("fits");
    let heading = cal
        .reference_heading
        .as_ref()
        .map(|h| (h.estimate.heading_deg, h.estimate.se_deg));
    (cal.diagnosis.expect("diagnosed"), heading)
}

fn diagnose(s: &Scenario) -> Diagnosis {
    diagnose_with_heading(s).0
}

#[derive(Default, Clone, Copy)]
struct Tally {
    runs: usize,
    /// The right id among the effects found.
    detected: usize,
    /// Exactly the right id, with no ambiguity.
    exact: usize,
    /// The right id reported ambiguous with another.
    ambiguous: usize,
    /// Another effect found besides (or instead of) the right one.
    extra: usize,
}

impl Tally {
    /// Counts one run with effect `id` injected and diagnosis `d`.
    fn record(&mut self, id: EffectId, d: &Diagnosis) {
        let found: Vec<EffectId> = d.effects.iter().map(|e| e.effect.id()).collect();
        let ambiguous = d.ambiguous.iter().any(|a| a.ids.contains(&id));
        self.runs += 1;
        self.detected += usize::from(found.contains(&id));
        self.exact += usize::from(found == [id] && !ambiguous);
        self.ambiguous += usize::from(ambiguous);
        self.extra += usize::from(found.iter().any(|f| *f != id));
    }
}

/// Error over standard error of each fitted parameter of `found`, by parameter name, against the injected `truth`.
fn z_scores(found: &FoundEffect, truth: &Effect) -> Vec<(&'static str, f64)> {
    let spec = effect_spec::format(truth, &["i_motor".to_owned()]);
    let truth_values: Vec<(&str, Vec<f64>)> = spec
        .split_once(':')
        .map_or("", |(_, p)| p)
        .split(';')
        .filter_map(|part| part.split_once('='))
        .filter_map(|(name, v)| {
            v.split(',')
                .map(|x| x.parse().ok())
                .collect::<Option<Vec<f64>>>()
                .map(|v| (name, v))
        })
        .collect();
    let mut out = Vec::new();
    for p in &found.params {
        let Some((_, want)) = truth_values.iter().find(|(n, _)| *n == p.name) else {
            continue;
        };
        let (got, se) = match (&p.value, &p.se) {
            (ParamValue::Number(v), Some(ParamValue::Number(s))) => (vec![*v], vec![*s]),
            (ParamValue::Vector(v), Some(ParamValue::Vector(s))) => (v.to_vec(), s.to_vec()),
            _ => continue,
        };
        out.extend((0..got.len()).map(|k| (p.name, (got[k] - want[k]) / se[k])));
    }
    out
}

/// The declination error found and its standard error, degrees.
fn declination(f: &FoundEffect) -> Option<(f64, f64)> {
    let p = f
        .params
        .iter()
        .find(|p| p.name == "declination_error_deg")?;
    match (&p.value, &p.se) {
        (ParamValue::Number(v), Some(ParamValue::Number(se))) => Some((*v, *se)),
        _ => None,
    }
}

#[test]
#[ignore = "statistics over 200 seeds × 12 recordings: run in release (CI does)"]
fn detection_at_half_sigma_and_false_alarms_over_200_seeds() {
    // A bias window and a magnet nearby are gross disturbances, found as excluded spans: their study is
    // tests/disturbed_study.rs, at 3–300 µT.
    let ids: Vec<EffectId> = EffectId::ALL
        .into_iter()
        .filter(|id| !matches!(id, EffectId::BiasWindow | EffectId::MagnetNearby))
        .collect();
    let tallies = Mutex::new(vec![Tally::default(); ids.len()]);
    let nulls = Mutex::new((0usize, 0usize, Vec::new()));
    let zs: Mutex<BTreeMap<&str, Vec<f64>>> = Mutex::new(BTreeMap::new());
    common::for_each_seed(SEEDS, |seed| {
        let base = random_scenario(seed);
        let null = diagnose(&base);
        {
            let mut n = nulls.lock().unwrap();
            n.0 += 1;
            if null.verdict != Verdict::Consistent {
                n.1 += 1;
                let found: Vec<&str> = null
                    .effects
                    .iter()
                    .map(|e| e.effect.id().as_str())
                    .collect();
                n.2.push(format!("seed {seed}: {found:?}"));
            }
        }
        for (k, id) in ids.iter().enumerate() {
            let mut s = base.clone();
            let e = scale_to_rms(
                &s,
                &random_effect(*id, &s, seed),
                SIZE_IN_SIGMA * s.noise_ut[0],
            );
            s.effects = vec![e];
            let (d, heading) = diagnose_with_heading(&s);
            let found = d.effects.iter().find(|f| f.effect.id() == *id);
            let mut z = zs.lock().unwrap();
            if let Some(f) = found {
                for (name, v) in z_scores(f, &e) {
                    z.entry(name).or_default().push(v);
                }
            }
            // A declination error taken as the reference's heading: the declination it stands for is the heading
            // reversed, plus what the diagnosis found on the reference turned by it.
            let direction = matches!(e, Effect::FieldDirectionError { .. });
            if let (true, Some((heading_deg, heading_se_deg))) = (direction, heading) {
                let entry = z.entry("declination_error_deg").or_default();
                let (found_deg, found_se_deg) =
                    found.and_then(declination).map_or((0.0, 0.0), |(v, se)| {
                        entry.pop();
                        (v, se)
                    });
                let Effect::FieldDirectionError {
                    declination_error_deg,
                    ..
                } = e
                else {
                    unreachable!()
                };
                entry.push(
                    (found_deg - heading_deg - declination_error_deg)
                        / heading_se_deg.hypot(found_se_deg),
                );
            }
            drop(z);
            let mut tally = tallies.lock().unwrap();
            tally[k].record(*id, &d);
            if direction && heading.is_some() && found.is_none() {
                // Named in the summary as the reference's north or a declination given wrong: found.
                tally[k].detected += 1;
            }
        }
    });
    let tallies = tallies.into_inner().unwrap();
    let (null_runs, alarms, alarm_list) = nulls.into_inner().unwrap();
    let pct = |a: usize, n: usize| 100.0 * a as f64 / n as f64;
    println!(
        "| effect (0.5 σ RMS per axis) | detected, right id | exactly it, unambiguous | reported ambiguous | other effect also found |"
    );
    println!("|---|---|---|---|---|");
    for (id, t) in ids.iter().zip(&tallies) {
        println!(
            "| `{id}` | {:.1} % | {:.1} % | {:.1} % | {:.1} % |",
            pct(t.detected, t.runs),
            pct(t.exact, t.runs),
            pct(t.ambiguous, t.runs),
            pct(t.extra, t.runs)
        );
    }
    println!(
        "| none (null recordings) | false alarms: {alarms} of {null_runs} ({:.1} %) | | | |",
        pct(alarms, null_runs)
    );
    for a in &alarm_list {
        println!("false alarm: {a}");
    }
    println!();
    println!("| parameter | estimates | mean error / SE | SD of error / SE |");
    println!("|---|---|---|---|");
    let zs = zs.into_inner().unwrap();
    let moments = |z: &[f64]| {
        let n = z.len() as f64;
        let mean = z.iter().sum::<f64>() / n;
        (
            mean,
            (z.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt(),
        )
    };
    for (name, z) in &zs {
        let (mean, sd) = moments(z);
        println!("| `{name}` | {} | {mean:+.2} | {sd:.2} |", z.len());
    }
    for (name, z) in &zs {
        let (_, sd) = moments(z);
        assert!(
            (0.75..=1.3).contains(&sd),
            "{name}: SD of error/SE {sd:.2}: the uncertainties are not honest"
        );
    }
    for (id, t) in ids.iter().zip(&tallies) {
        assert!(
            pct(t.detected, t.runs) >= 95.0,
            "{id}: detected in {} of {}",
            t.detected,
            t.runs
        );
    }
    assert!(
        pct(alarms, null_runs) <= 1.0,
        "{alarms} false alarms in {null_runs} null recordings"
    );
}

/// The scalar method (no attitude reference, the magnitude known): the body-fixed effects it can test.
const SCALAR_IDS: [EffectId; 6] = [
    EffectId::TemperatureBias,
    EffectId::TemperatureScale,
    EffectId::CurrentBias,
    EffectId::Nonlinearity,
    EffectId::BiasStep,
    EffectId::BiasDrift,
];
/// The scalar method's false alarms allowed (%): the 1 %.
const SCALAR_FALSE_ALARM_PCT: f64 = 1.0;
/// The scalar method sees a body-fixed effect only along the field: its detection table is taken at 1 σ.
const SCALAR_SIZE_IN_SIGMA: f64 = 1.0;

fn diagnose_scalar(s: &Scenario) -> Diagnosis {
    let mut s = s.clone();
    s.attitude = magcal_sim::AttitudeOutput::None;
    let run = simulate(&s).expect("valid scenario");
    let field = ReferenceField::Magnitude {
        field_ut: magcal_calib::frames::norm(s.field_ned_ut),
        source: "simulated".into(),
    };
    calibrate(&run.recording, Method::Auto, field, true)
        .expect("fits")
        .diagnosis
        .expect("diagnosed")
}

/// Issue 7, acceptance 3: the scalar method's false alarms over 200 null recordings (at most 1 %) and its detection
/// table at 1 σ RMS per axis (measured, not asserted: what the magnitude alone can show).
#[test]
#[ignore = "statistics over 200 seeds: run in release (CI does)"]
fn scalar_false_alarms_over_200_seeds_and_detection_table() {
    let tallies = Mutex::new(vec![Tally::default(); SCALAR_IDS.len()]);
    let nulls = Mutex::new((0usize, Vec::new()));
    common::for_each_seed(SEEDS, |seed| {
        let base = random_scenario(seed);
        let null = diagnose_scalar(&base);
        {
            let mut n = nulls.lock().unwrap();
            n.0 += 1;
            if null.verdict != Verdict::Consistent {
                let found: Vec<&str> = null
                    .effects
                    .iter()
                    .map(|e| e.effect.id().as_str())
                    .collect();
                n.1.push(format!(
                    "seed {seed}: {found:?}, {} spans",
                    null.spans.len()
                ));
            }
        }
        // The detection table on every other seed (it is measured, not asserted).
        if seed % 2 == 1 {
            return;
        }
        for (k, id) in SCALAR_IDS.iter().enumerate() {
            let mut s = base.clone();
            let e = scale_to_rms(
                &s,
                &random_effect(*id, &s, seed),
                SCALAR_SIZE_IN_SIGMA * s.noise_ut[0],
            );
            s.effects = vec![e];
            let d = diagnose_scalar(&s);
            tallies.lock().unwrap()[k].record(*id, &d);
        }
    });
    let tallies = tallies.into_inner().unwrap();
    let (null_runs, alarms) = nulls.into_inner().unwrap();
    let pct = |a: usize, n: usize| 100.0 * a as f64 / n.max(1) as f64;
    println!(
        "| scalar method, effect (1 σ RMS per axis) | detected, right id | exactly it, unambiguous | reported ambiguous | other effect also found |"
    );
    println!("|---|---|---|---|---|");
    for (id, t) in SCALAR_IDS.iter().zip(&tallies) {
        println!(
            "| `{id}` | {:.1} % | {:.1} % | {:.1} % | {:.1} % |",
            pct(t.detected, t.runs),
            pct(t.exact, t.runs),
            pct(t.ambiguous, t.runs),
            pct(t.extra, t.runs)
        );
    }
    println!(
        "| none (null recordings) | false alarms: {} of {null_runs} ({:.1} %) | | | |",
        alarms.len(),
        pct(alarms.len(), null_runs)
    );
    for a in &alarms {
        println!("false alarm: {a}");
    }
    // Measured 2026-11-24: 0 of 200 (6 of 200, every one a `nonlinearity`, before the noise shared by the magnitude
    // and the regressors was corrected; docs/diagnosis.md).
    assert!(
        pct(alarms.len(), null_runs) <= SCALAR_FALSE_ALARM_PCT,
        "{} false alarms in {null_runs} scalar null recordings",
        alarms.len()
    );
}
