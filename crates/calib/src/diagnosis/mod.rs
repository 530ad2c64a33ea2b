//! The diagnosis: when a recording and the fitted model differ, find where, say which physics the model left out,
//! model it, and show the fit improve on held-out data.
//!
//! 1. The base model's residual is compared with the noise floor measured from the recording ([`crate::noise`]) and
//!    located: axes, time spans, orientations, and the recorded channel it follows.
//! 2. Every effect of the catalogue ([`crate::effects`]) the recording can observe becomes a candidate, its regressors
//!    computed by the effect's own definition (the one the simulator injects). Effects the recording cannot observe
//!    are reported untestable with the reason; candidates the base model absorbs (projected on the base design, less
//!    than 2 % remains) are reported as absorbed, with the part of the base fit they would bias.
//! 3. Candidates are judged by a Wald test with a BIC penalty (plus a penalty for a scanned time) *and*
//!    by blocked cross-validation over five contiguous time blocks, and chosen greedily. A candidate nearly as good as
//!    the chosen one that the chosen one explains away is reported as ambiguous with it, with the experiment that
//!    would separate them.
//! 4. The chosen effects are fitted jointly with `A` and `b`: residual and held-out residual before and after, the
//!    effects' parameters with standard errors, a sentence in physical terms, and the extended model (body-fixed
//!    effects become corrections `apply` removes).
//!
//! The vector method's problem has three rows per sample (`A·B̂ + b − Σ G·θ = B0`, the raw readings centred and the
//! errors-in-variables correction applied as in [`crate::vector`]); the scalar method's has one (the magnitude
//! residual linearised at the base fit, so body-fixed effects enter through `u·δ`, `u` the field direction).

mod candidates;
mod explain;
mod locate;
mod samples;
mod scan;
mod select;
mod stats;

use nalgebra::DVector;

pub use candidates::Untestable;
pub use locate::{Located, Orientation, Segment};

use crate::FitError;
use crate::effects::{Effect, EffectId, Frame};
use crate::frames::{self, Mat3};
use crate::model::Model;
use crate::noise::NoiseFloor;
use candidates::{Candidate, Offer};
use samples::Samples;
use select::{SetAside, select};
use stats::{Batches, BlockStats, Problem};

/// Fewest samples the diagnosis works on.
pub const MIN_SAMPLES: usize = 50;
/// Contiguous time blocks of the cross-validation.
const CV_BLOCKS: usize = 5;
/// Contiguous batches for the residual's autocorrelation (method of batch means).
const AUTOCORRELATION_BATCHES: usize = 100;

/// The reference a recording offers.
#[derive(Clone, Copy, Debug)]
pub enum Reference<'a> {
    /// Attitude quaternions (sensor → NED) and the world field: the vector method; world and timing effects testable.
    Attitude {
        /// Per sample, `[w, x, y, z]` (NaN = missing).
        quat: &'a [[f64; 4]],
        /// The assumed world field, NED, µT.
        field_ned_ut: [f64; 3],
    },
    /// The expected field in sensor axes (`rx,ry,rz`): the vector method without world-frame effects.
    Field {
        /// Per sample, µT (NaN = missing).
        expected_ut: &'a [[f64; 3]],
    },
    /// The field magnitude only: the scalar method.
    Magnitude {
        /// |B|, µT.
        field_ut: f64,
    },
}

/// What the diagnosis is given.
#[derive(Clone, Debug)]
pub struct DiagnosisInput<'a> {
    /// Raw readings, µT.
    pub raw_ut: &'a [[f64; 3]],
    /// Time, s.
    pub t_s: Option<&'a [f64]>,
    /// Temperature, °C.
    pub temp_c: Option<&'a [f64]>,
    /// Current channels: name (`i_<name>`) and values, A.
    pub currents: Vec<(&'a str, &'a [f64])>,
    /// The reference.
    pub reference: Reference<'a>,
    /// The raw noise floor.
    pub noise: NoiseFloor,
}

/// The overall finding.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Verdict {
    /// The residual is noise: nothing left out that this recording can show.
    Consistent,
    /// The model misses something: effects found, or a residual above the noise left unexplained.
    Mismatch,
}

/// A parameter's value in a report.
#[derive(Clone, Debug, PartialEq)]
pub enum ParamValue {
    /// A number.
    Number(f64),
    /// Three numbers.
    Vector([f64; 3]),
    /// Text (a channel name).
    Text(String),
}

/// A named parameter with its standard error.
#[derive(Clone, Debug, PartialEq)]
pub struct Param {
    /// The report name (`lag_s`, `coef_ut_per_c`, …).
    pub name: &'static str,
    /// Its value.
    pub value: ParamValue,
    /// Its standard error, if estimated.
    pub se: Option<ParamValue>,
}

/// An effect the diagnosis found and modelled.
#[derive(Clone, Debug, PartialEq)]
pub struct FoundEffect {
    /// The effect with its fitted parameters (from the final joint fit).
    pub effect: Effect,
    /// The current channel, for `current_bias`.
    pub channel: Option<String>,
    /// Its parameters as reported.
    pub params: Vec<Param>,
    /// Residual RMS before and after adding it, µT.
    pub rms_before_ut: f64,
    /// See `rms_before_ut`.
    pub rms_after_ut: f64,
    /// Held-out (blocked cross-validation) RMS before and after adding it, µT.
    pub holdout_rms_before_ut: f64,
    /// See `holdout_rms_before_ut`.
    pub holdout_rms_after_ut: f64,
    /// Evidence for it: the Wald statistic minus the complexity penalty, σ² units.
    pub evidence: f64,
    /// The finding in words.
    pub explanation: String,
}

/// Two effects that explain the same residual.
#[derive(Clone, Debug, PartialEq)]
pub struct Ambiguity {
    /// The effect modelled and the alternative.
    pub ids: [EffectId; 2],
    /// Why they cannot be told apart here.
    pub why: String,
    /// The experiment that would separate them.
    pub experiment: String,
}

/// A fit's linear part and residuals.
#[derive(Clone, Debug, PartialEq)]
pub struct FitSummary {
    /// `A`.
    pub a: Mat3,
    /// `b`, µT.
    pub b_ut: [f64; 3],
    /// Standard errors of `A` and `b` (vector method; the scalar method's come from its own fit).
    pub se: Option<(Mat3, [f64; 3])>,
    /// Residual RMS (per axis, or of |B|), µT.
    pub rms_ut: f64,
    /// Held-out residual RMS, µT.
    pub holdout_rms_ut: f64,
}

/// Per-sample residuals before and after, for plots: one component per calibrated axis (vector) or one (|B|).
#[derive(Clone, Debug, PartialEq)]
pub struct Residuals {
    /// The recording rows used.
    pub rows: Vec<usize>,
    /// Time, s (zero without a time column).
    pub t_s: Vec<f64>,
    /// The field direction in sensor axes.
    pub direction: Vec<[f64; 3]>,
    /// Residual of the base fit, µT.
    pub base: Vec<Vec<f64>>,
    /// Residual of the extended fit, µT.
    pub extended: Vec<Vec<f64>>,
    /// The channels the residual was compared with (`temp`, `i_<name>`, `t`, `rotation_rate`), per sample.
    pub channels: Vec<(String, Vec<f64>)>,
}

/// What the diagnosis found.
#[derive(Clone, Debug, PartialEq)]
pub struct Diagnosis {
    /// The overall finding.
    pub verdict: Verdict,
    /// Effects found and modelled, in the order they were chosen.
    pub effects: Vec<FoundEffect>,
    /// Effects that could not be told apart.
    pub ambiguous: Vec<Ambiguity>,
    /// Effects this recording cannot test (including the absorbed ones).
    pub untestable: Vec<Untestable>,
    /// Where the base model's residual departs from the noise.
    pub located: Located,
    /// The 12-parameter (or scalar) base fit on the samples used.
    pub base: FitSummary,
    /// The fit with the effects found.
    pub extended: FitSummary,
    /// The extended model: `A`, `b` and the body-fixed effects as corrections.
    pub model: Model,
    /// The noise floor in calibrated units, µT (per axis RMS, or of |B|).
    pub noise_floor_ut: f64,
    /// Samples used; rows left out for a missing channel.
    pub samples_used: usize,
    /// See `samples_used`.
    pub samples_left_out: usize,
    /// Per-sample residuals before and after.
    pub residuals: Residuals,
}

/// Diagnoses a recording against its base fit `base` (the linear model from [`crate::vector`] or [`crate::scalar`]).
pub fn diagnose(input: &DiagnosisInput<'_>, base: &Model) -> Result<Diagnosis, FitError> {
    let samples = Samples::gather(input, base);
    let n = samples.len();
    if n < MIN_SAMPLES {
        return Err(FitError::TooFewSamples {
            needed: MIN_SAMPLES,
            got: n,
        });
    }
    let vector = !matches!(input.reference, Reference::Magnitude { .. });
    let field_ut = match input.reference {
        Reference::Magnitude { field_ut } => field_ut,
        _ => samples.field.iter().map(|f| frames::norm(*f)).sum::<f64>() / n as f64,
    };
    let raw_mean = samples.raw.iter().fold([0.0; 3], |s, m| frames::add(s, *m));
    let raw_mean = frames::scale(raw_mean, 1.0 / n as f64);

    // Base residuals, for the scans and for locating.
    let residual: Vec<Vec<f64>> = (0..n)
        .map(|i| {
            let cal = frames::add(frames::mat_vec(&base.a, samples.raw[i]), base.b_ut);
            if vector {
                frames::sub(cal, samples.field[i]).to_vec()
            } else {
                vec![frames::norm(cal) - field_ut]
            }
        })
        .collect();
    let dims = if vector { 3 } else { 1 };
    let sigma2 = residual
        .iter()
        .map(|r| r.iter().map(|v| v * v).sum::<f64>())
        .sum::<f64>()
        / (n * dims) as f64;
    let unit: Vec<[f64; 3]> = samples
        .field
        .iter()
        .map(|f| frames::scale(*f, 1.0 / frames::norm(*f)))
        .collect();
    let residual3: Vec<[f64; 3]> = if vector {
        residual.iter().map(|r| [r[0], r[1], r[2]]).collect()
    } else {
        Vec::new()
    };
    let step = if !samples.has_time {
        None
    } else if vector {
        scan::step_vector(&residual3, sigma2)
    } else {
        let rho: Vec<f64> = residual.iter().map(|r| r[0]).collect();
        scan::step_scalar(&rho, &unit, sigma2)
    };
    let window = match (&samples.rot, vector && samples.has_time) {
        (Some(rot), true) => scan::window(&residual3, rot, sigma2),
        _ => None,
    };

    let n_base = if vector { 12 } else { 9 };
    let current_names: Vec<&str> = input.currents.iter().map(|(name, _)| *name).collect();
    let offer = Offer {
        samples: &samples,
        vector,
        current_names: &current_names,
        step,
        window,
    };
    let (cands, mut untestable) = candidates::candidates(&offer, n_base);
    let columns = cands.last().map_or(n_base, |c| c.first + c.n);

    // Accumulate the normal equations per block.
    let mut blocks: Vec<BlockStats> = (0..CV_BLOCKS).map(|_| BlockStats::new(columns)).collect();
    let mut batches = Batches::new(AUTOCORRELATION_BATCHES, dims, columns);
    let mut entries: Vec<(usize, f64)> = Vec::with_capacity(columns);
    let mut regs: Vec<[[f64; 3]; 3]> = vec![[[0.0; 3]; 3]; cands.len()];
    for i in 0..n {
        let block = &mut blocks[i * CV_BLOCKS / n];
        let batch = i * AUTOCORRELATION_BATCHES / n;
        block.samples += 1;
        let ctx = samples.context(i);
        for (c, cand) in cands.iter().enumerate() {
            regs[c] = cand.regressors(&ctx);
        }
        let mc = frames::sub(samples.raw[i], raw_mean);
        if vector {
            for j in 0..3 {
                entries.clear();
                entries.extend((0..3).map(|k| (4 * j + k, mc[k])));
                entries.push((4 * j + 3, 1.0));
                for (c, cand) in cands.iter().enumerate() {
                    entries.extend((0..cand.n).map(|k| (cand.first + k, -regs[c][k][j])));
                }
                block.add_row(&entries, samples.field[i][j]);
                batches.add_row(batch, j, &entries, samples.field[i][j]);
            }
        } else {
            // ρ + J·Δ − u·G·θ ≈ 0 around the base fit (ρ: its residual), with the readings centred.
            let u = unit[i];
            entries.clear();
            for (k, (r, s)) in SYM.iter().enumerate() {
                let d = if r == s {
                    u[*r] * mc[*s]
                } else {
                    u[*r] * mc[*s] + u[*s] * mc[*r]
                };
                entries.push((k, d));
            }
            entries.extend((0..3).map(|k| (6 + k, u[k])));
            for (c, cand) in cands.iter().enumerate() {
                entries.extend((0..cand.n).map(|k| (cand.first + k, -frames::dot(u, regs[c][k]))));
            }
            let y = -residual[i][0];
            block.add_row(&entries, y);
            batches.add_row(batch, 0, &entries, y);
        }
    }
    let correction: Vec<DVector<f64>> = blocks
        .iter()
        .map(|b| {
            let mut c = DVector::zeros(columns);
            if vector {
                for j in 0..3 {
                    for k in 0..3 {
                        c[4 * j + k] = b.samples as f64 * input.noise.floor_ut[k].powi(2);
                    }
                }
            }
            c
        })
        .collect();
    let problem = Problem::new(blocks, batches, correction);
    let base_columns: Vec<usize> = (0..n_base).collect();
    let a_columns: Vec<usize> = if vector {
        (0..3)
            .flat_map(|j| (0..3).map(move |k| 4 * j + k))
            .collect()
    } else {
        (0..6).collect()
    };
    let noise_floor_ut = if vector {
        input.noise.calibrated_rms_ut(&base.a)
    } else {
        // |B| noise: the calibrated noise along the field direction, averaged.
        let f = input.noise.floor_ut;
        let along: f64 = unit
            .iter()
            .map(|u| {
                let au = frames::mat_t_vec(&base.a, *u);
                (0..3).map(|k| (au[k] * f[k]).powi(2)).sum::<f64>()
            })
            .sum::<f64>()
            / n as f64;
        along.sqrt()
    };
    let sel = select(
        &problem,
        &base_columns,
        &cands,
        &a_columns,
        noise_floor_ut.powi(2),
    )
    .ok_or(FitError::Singular(
        "the diagnosis' base problem has no solution",
    ))?;

    let rows = problem.total.rows as f64;
    let rms = |rss: f64| (rss / rows).sqrt();
    // The final joint fit's parameters.
    let last = &sel.last;
    let dof = (rows - last.columns.len() as f64).max(1.0);
    // Standard errors allow for residuals that are alike from sample to sample (see `select`): the variance per row
    // is scaled by the autocorrelation factor.
    let tau_last = problem.autocorrelation(last);
    let sigma2_last = last.rss / dof * tau_last;
    let coef = |col: usize| {
        last.columns
            .iter()
            .position(|&c| c == col)
            .map(|p| (last.beta[p], (last.inverse[(p, p)] * sigma2_last).sqrt()))
    };
    // A and b of a solution, back from the centred readings (and, for the scalar method, from the linearisation).
    let linear_of = |sol: &stats::Solution| -> (Mat3, [f64; 3]) {
        let get = |col: usize| {
            sol.columns
                .iter()
                .position(|&c| c == col)
                .map(|p| sol.beta[p])
        };
        if vector {
            let a: Mat3 =
                std::array::from_fn(|j| std::array::from_fn(|k| get(4 * j + k).unwrap_or(0.0)));
            let b_c: [f64; 3] = std::array::from_fn(|j| get(4 * j + 3).unwrap_or(0.0));
            // Back from centred readings: b = b' − A·mean.
            (a, frames::sub(b_c, frames::mat_vec(&a, raw_mean)))
        } else {
            let mut a = base.a;
            for (k, (r, s)) in SYM.iter().enumerate() {
                let d = get(k).unwrap_or(0.0);
                a[*r][*s] += d;
                if r != s {
                    a[*s][*r] += d;
                }
            }
            // b' = b + A·mean was linearised; b = b' − A·mean with the updated A.
            let b_c0 = frames::add(base.b_ut, frames::mat_vec(&base.a, raw_mean));
            let b_c: [f64; 3] = std::array::from_fn(|k| b_c0[k] + get(6 + k).unwrap_or(0.0));
            (a, frames::sub(b_c, frames::mat_vec(&a, raw_mean)))
        }
    };
    let (base_a, base_b) = linear_of(&sel.base);
    let (ext_a, ext_b) = linear_of(last);

    let mut model = Model::linear(ext_a, ext_b);
    let mut effects = Vec::new();
    // The chosen effects with their fitted parameters (steps replaced later — a lag generalised to per-axis lags —
    // are not in the final model).
    let mut chosen: Vec<(&select::Step, Candidate, Effect, [f64; 3])> = Vec::new();
    for step in &sel.steps {
        if sel.steps.iter().any(|s| s.replaced == Some(step.cand)) {
            continue;
        }
        let cand = cands[step.cand].clone();
        let mut p = [0.0; 3];
        let mut se = [0.0; 3];
        for k in 0..cand.n {
            let (v, s) = coef(cand.first + k).unwrap_or((0.0, f64::NAN));
            p[k] = v;
            se[k] = s;
        }
        let effect = cand.template.with_params(p);
        chosen.push((step, cand, effect, se));
    }
    // A scanned time was located on the base residual, which the base fit had partly bent to the effect; locate it
    // again on the extended fit's residual with every other effect removed.
    for k in 0..chosen.len() {
        let scanned = matches!(
            chosen[k].2,
            Effect::BiasStep { .. } | Effect::Disturbance { .. }
        );
        if !scanned {
            continue;
        }
        let partial: Vec<[f64; 3]> = (0..n)
            .map(|i| {
                let ctx = samples.context(i);
                let others = chosen
                    .iter()
                    .enumerate()
                    .filter(|(j, _)| *j != k)
                    .fold([0.0; 3], |acc, (_, c)| {
                        frames::add(acc, c.2.perturbation_ut(&ctx))
                    });
                frames::sub(
                    frames::add(frames::mat_vec(&ext_a, samples.raw[i]), ext_b),
                    others,
                )
            })
            .collect();
        let rescan = match (chosen[k].2, vector) {
            (Effect::BiasStep { .. }, true) => {
                let e: Vec<[f64; 3]> = (0..n)
                    .map(|i| frames::sub(partial[i], samples.field[i]))
                    .collect();
                scan::step_vector(&e, last.rss / rows)
            }
            (Effect::BiasStep { .. }, false) => {
                let rho: Vec<f64> = partial
                    .iter()
                    .map(|c| frames::norm(*c) - field_ut)
                    .collect();
                scan::step_scalar(&rho, &unit, last.rss / rows)
            }
            (_, _) => samples.rot.as_ref().and_then(|rot| {
                let e: Vec<[f64; 3]> = (0..n)
                    .map(|i| frames::sub(partial[i], samples.field[i]))
                    .collect();
                scan::window(&e, rot, last.rss / rows)
            }),
        };
        if let Some(w) = rescan {
            let (_, cand, effect, _) = &mut chosen[k];
            cand.scan = Some(candidates::scan_times(
                &samples,
                &w,
                matches!(effect, Effect::Disturbance { .. }),
            ));
            match effect {
                Effect::BiasStep { t_s, .. } => *t_s = candidates::between(&samples, w.start),
                Effect::Disturbance { t0_s, t1_s, .. } => {
                    *t0_s = candidates::between(&samples, w.start);
                    *t1_s = candidates::between(&samples, w.end);
                }
                _ => {}
            }
        }
    }
    for (step, cand, effect, se) in &chosen {
        let effect = *effect;
        if effect.id().frame() == Frame::Body {
            model
                .add_correction(effect)
                .expect("candidates are limited so that every body-fixed effect fits in a model");
        }
        let holdout = (rms(step.cv.0), rms(step.cv.1));
        effects.push(FoundEffect {
            explanation: explain::explain(
                &effect,
                cand.channel.as_deref(),
                holdout,
                noise_floor_ut,
                field_ut,
            ),
            params: params_of(&effect, *se, cand, last.rss / rows * tau_last),
            effect,
            channel: cand.channel.clone(),
            rms_before_ut: rms(step.rss.0),
            rms_after_ut: rms(step.rss.1),
            holdout_rms_before_ut: holdout.0,
            holdout_rms_after_ut: holdout.1,
            evidence: step.evidence,
        });
    }
    let ambiguous = sel
        .ambiguous
        .iter()
        .map(|&(a, b)| {
            let ids = [cands[a].id(), cands[b].id()];
            let (why, experiment) = explain::separate(ids[0], ids[1]);
            Ambiguity {
                ids,
                why,
                experiment,
            }
        })
        .collect();
    for (c, why) in &sel.set_aside {
        let cand = &cands[*c];
        let name = cand
            .channel
            .as_deref()
            .map_or(String::new(), |ch| format!(" ({ch})"));
        untestable.push(Untestable {
            id: cand.id(),
            why: match why {
                SetAside::NotExcited => format!("not excited{name}: {}", not_excited(cand.id())),
                SetAside::Absorbed { unabsorbed, takes_up } => format!(
                    "absorbed — not testable with this data{name}: the base fit takes up {:.1} % of it, so it would \
                     bias {takes_up}",
                    100.0 * (1.0 - unabsorbed)
                ),
            },
        });
    }

    let directions = unit;
    let mut channels: Vec<(&str, Vec<f64>)> = Vec::new();
    if samples.has_temp {
        channels.push(("temp", samples.temp.clone()));
    }
    for (k, name) in current_names.iter().enumerate() {
        channels.push((
            name,
            (0..n)
                .map(|i| samples.currents[i * samples.n_currents + k])
                .collect(),
        ));
    }
    if samples.has_time {
        channels.push(("t", samples.t.clone()));
    }
    if vector && samples.has_time {
        channels.push((
            "rotation_rate",
            samples.rate.iter().map(|r| frames::norm(*r)).collect(),
        ));
    }
    let floor_axes: Vec<f64> = if vector {
        input.noise.calibrated_ut(&base.a).to_vec()
    } else {
        vec![noise_floor_ut]
    };
    let located = locate::locate(
        &residual,
        &floor_axes,
        samples.has_time.then_some(samples.t.as_slice()),
        &directions,
        &channels,
    );
    // The extended fit's residual per sample, from the effects' own definitions.
    let extended: Vec<Vec<f64>> = (0..n)
        .map(|i| {
            let ctx = samples.context(i);
            let delta = effects.iter().fold([0.0; 3], |acc, f| {
                frames::add(acc, f.effect.perturbation_ut(&ctx))
            });
            let cal = frames::sub(
                frames::add(frames::mat_vec(&ext_a, samples.raw[i]), ext_b),
                delta,
            );
            if vector {
                frames::sub(cal, samples.field[i]).to_vec()
            } else {
                vec![frames::norm(cal) - field_ut]
            }
        })
        .collect();
    let unexplained = rms(sel.last.rss) > 1.2 * noise_floor_ut && !located.axes.is_empty();
    let verdict = if effects.is_empty() && !unexplained {
        Verdict::Consistent
    } else {
        Verdict::Mismatch
    };
    Ok(Diagnosis {
        verdict,
        effects,
        ambiguous,
        untestable,
        located,
        base: FitSummary {
            a: base_a,
            b_ut: base_b,
            se: vector.then(|| linear_se(&problem, &sel.base, rows, raw_mean)),
            rms_ut: rms(sel.base.rss),
            holdout_rms_ut: rms(sel.base_cv),
        },
        extended: FitSummary {
            a: ext_a,
            b_ut: ext_b,
            se: vector.then(|| linear_se(&problem, &sel.last, rows, raw_mean)),
            rms_ut: rms(sel.last.rss),
            holdout_rms_ut: rms(sel.last_cv),
        },
        model,
        noise_floor_ut,
        samples_used: n,
        samples_left_out: samples.left_out,
        residuals: Residuals {
            rows: samples.rows,
            t_s: samples.t,
            direction: directions,
            base: residual,
            extended,
            channels: channels
                .into_iter()
                .map(|(name, v)| (name.to_owned(), v))
                .collect(),
        },
    })
}

/// Standard errors of `A` and `b` from a vector-method solution on centred readings (allowing for autocorrelated
/// residuals, as the effects' are): `b = b' − A·mean`, so
/// `var(b_j) = gᵀ·C_j·g` with `g = (−mean, 1)` and `C_j` the covariance of row `j`'s `(a_j, b'_j)`.
fn linear_se(
    problem: &Problem,
    sol: &stats::Solution,
    rows: f64,
    raw_mean: [f64; 3],
) -> (Mat3, [f64; 3]) {
    let s2 = sol.rss / (rows - sol.columns.len() as f64).max(1.0) * problem.autocorrelation(sol);
    let pos = |c: usize| sol.columns.iter().position(|&x| x == c);
    let cov = |c: usize, d: usize| match (pos(c), pos(d)) {
        (Some(p), Some(q)) => sol.inverse[(p, q)] * s2,
        _ => 0.0,
    };
    let a_se: Mat3 =
        std::array::from_fn(|j| std::array::from_fn(|k| cov(4 * j + k, 4 * j + k).sqrt()));
    let b_se = std::array::from_fn(|j| {
        let g = [-raw_mean[0], -raw_mean[1], -raw_mean[2], 1.0];
        let mut v = 0.0;
        for r in 0..4 {
            for c in 0..4 {
                v += g[r] * cov(4 * j + r, 4 * j + c) * g[c];
            }
        }
        v.max(0.0).sqrt()
    });
    (a_se, b_se)
}

/// Index pairs of the scalar method's symmetric `A` parameters (as in [`crate::scalar`]).
const SYM: [(usize, usize); 6] = [(0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)];

fn not_excited(id: EffectId) -> &'static str {
    match id {
        EffectId::TemperatureBias | EffectId::TemperatureScale => {
            "the temperature did not change during the recording"
        }
        EffectId::CurrentBias => "the current did not change during the recording",
        EffectId::TimeLag | EffectId::RateCoupling => {
            "the attitude did not change while samples were taken (static poses only)"
        }
        _ => "its signature is zero throughout this recording",
    }
}

/// The report parameters of a fitted effect, with standard errors (`se` per fitted parameter; `sigma2` the residual
/// variance per row, µT²).
fn params_of(e: &Effect, se: [f64; 3], cand: &Candidate, sigma2: f64) -> Vec<Param> {
    let num = |name, v: f64, s: f64| Param {
        name,
        value: ParamValue::Number(v),
        se: Some(ParamValue::Number(s)),
    };
    let vec3 = |name, v: [f64; 3]| Param {
        name,
        value: ParamValue::Vector(v),
        se: Some(ParamValue::Vector(se)),
    };
    let fixed = |name, v: f64| Param {
        name,
        value: ParamValue::Number(v),
        se: None,
    };
    // A scanned time's uncertainty. A change point is not a regular parameter and its profile interval under-covers;
    // the location error of a jump Δ in white noise σ spreads like the argmax of a two-sided random walk with drift,
    // whose standard deviation is √26·σ²/|Δ|² samples (Yao, Ann. Statist. 15, 1987). The larger of the two, and at
    // least half a sample interval.
    let jump2 = match *e {
        Effect::BiasStep { step_ut, .. } => frames::dot(step_ut, step_ut),
        Effect::Disturbance { field_ned_ut, .. } => frames::dot(field_ned_ut, field_ned_ut),
        _ => f64::INFINITY,
    };
    let half = |(lo, hi): (f64, f64)| {
        let dt = cand.scan.map_or(0.0, |s| s.sample_interval_s);
        ((hi - lo) / 2.0)
            .max(26f64.sqrt() * sigma2 / jump2 * dt)
            .max(dt / 2.0)
    };
    match *e {
        Effect::TemperatureBias {
            coef_ut_per_c,
            t_ref_c,
        } => {
            vec![
                vec3("coef_ut_per_c", coef_ut_per_c),
                fixed("t_ref_c", t_ref_c),
            ]
        }
        Effect::TemperatureScale {
            coef_per_c,
            t_ref_c,
        } => vec![vec3("coef_per_c", coef_per_c), fixed("t_ref_c", t_ref_c)],
        Effect::CurrentBias { coef_ut_per_a, .. } => vec![
            Param {
                name: "channel",
                value: ParamValue::Text(cand.channel.clone().unwrap_or_default()),
                se: None,
            },
            vec3("coef_ut_per_a", coef_ut_per_a),
        ],
        Effect::TimeLag { lag_s } => vec![num("lag_s", lag_s, se[0])],
        Effect::RateCoupling { lag_axis_s } => vec![vec3("lag_axis_s", lag_axis_s)],
        Effect::FieldDrift {
            rate_ut_per_s,
            t_ref_s,
        } => vec![
            vec3("rate_ut_per_s", rate_ut_per_s),
            fixed("t_ref_s", t_ref_s),
        ],
        Effect::FieldDirectionError {
            declination_error_deg,
            inclination_error_deg,
        } => vec![
            num("declination_error_deg", declination_error_deg, se[0]),
            num("inclination_error_deg", inclination_error_deg, se[1]),
        ],
        Effect::Nonlinearity { cubic_per_ut2 } => vec![vec3("cubic_per_ut2", cubic_per_ut2)],
        Effect::BiasStep { t_s, step_ut } => vec![
            num("t_s", t_s, cand.scan.map_or(f64::NAN, |s| half(s.start_s))),
            vec3("step_ut", step_ut),
        ],
        Effect::BiasDrift {
            rate_ut_per_s,
            t_ref_s,
        } => vec![
            vec3("rate_ut_per_s", rate_ut_per_s),
            fixed("t_ref_s", t_ref_s),
        ],
        Effect::Disturbance {
            t0_s,
            t1_s,
            field_ned_ut,
        } => vec![
            num(
                "t0_s",
                t0_s,
                cand.scan.map_or(f64::NAN, |s| half(s.start_s)),
            ),
            num(
                "t1_s",
                t1_s,
                cand.scan.and_then(|s| s.end_s).map_or(f64::NAN, half),
            ),
            vec3("field_ned_ut", field_ned_ut),
        ],
    }
}
