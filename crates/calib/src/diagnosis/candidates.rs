//! The candidate effects a recording can test, the reasons the others cannot be tested, and each candidate's
//! regressors — taken from [`Effect::perturbation_ut`], the same definition the simulator injects.

use std::cell::Cell;

use crate::effects::{Context, Effect, EffectId};
use crate::frames;
use crate::scan::{self, Scan};

use super::samples::Samples;
use super::setup::Setup;

/// One effect to test, with its hyperparameters fixed and its columns in the design.
#[derive(Clone, Debug)]
pub(crate) struct Candidate {
    /// The effect with zero parameters and its hyperparameters (reference temperature, step time, …) set.
    pub template: Effect,
    /// Number of fitted parameters.
    pub n: usize,
    /// First design column.
    pub first: usize,
    /// The current channel's name, for `current_bias`.
    pub channel: Option<String>,
    /// An effect this one generalises (its columns are replaced, not added to).
    pub supersedes: Option<EffectId>,
    /// Extra evidence demanded for a scanned hyperparameter, σ² units.
    pub scan_penalty: f64,
    /// Profile intervals of the scanned times (start, and end for a window), s.
    pub scan: Option<ScanTimes>,
    /// A gross span's effect: always in the model, not selected.
    pub forced: bool,
    /// Rows (one per sample and calibrated axis, or per sample for the scalar method) where its regressors are not
    /// all zero, counted while accumulating.
    pub active_rows: usize,
}

/// The typical time between samples, s.
pub(crate) fn sample_interval_s(s: &Samples) -> f64 {
    (s.t[s.len() - 1] - s.t[0]) / (s.len() - 1).max(1) as f64
}

/// The time of a change at sample `k`: it happened between samples `k − 1` and `k`, and the midpoint is the unbiased
/// estimate (it gives the same regressor, which switches at sample `k`).
pub(crate) fn between(s: &Samples, k: usize) -> f64 {
    match k {
        0 => s.t[0] - sample_interval_s(s) / 2.0,
        k if k >= s.len() => s.t[s.len() - 1] + sample_interval_s(s) / 2.0,
        k => (s.t[k - 1] + s.t[k]) / 2.0,
    }
}

/// The profile intervals of a scan in seconds (the end's only for a window).
pub(crate) fn scan_times(s: &Samples, scan: &Scan, window: bool) -> ScanTimes {
    ScanTimes {
        start_s: (
            between(s, scan.start_interval.0),
            between(s, scan.start_interval.1),
        ),
        end_s: window.then(|| {
            (
                between(s, scan.end_interval.0),
                between(s, scan.end_interval.1),
            )
        }),
        sample_interval_s: sample_interval_s(s),
    }
}

/// The profile intervals of a scanned hyperparameter, s.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct ScanTimes {
    /// Interval of the step time or window start.
    pub start_s: (f64, f64),
    /// Interval of the window end.
    pub end_s: Option<(f64, f64)>,
    /// The typical time between samples, s.
    pub sample_interval_s: f64,
}

impl Candidate {
    pub fn id(&self) -> EffectId {
        self.template.id()
    }

    pub fn columns(&self) -> std::ops::Range<usize> {
        self.first..self.first + self.n
    }

    /// Whether the effect is local (a step, a window) or a curve of the field: such effects must stand out from the
    /// reference's own error, which a smooth local wander of the reference can mimic.
    pub fn local(&self) -> bool {
        matches!(
            self.id(),
            EffectId::BiasStep
                | EffectId::Disturbance
                | EffectId::BiasWindow
                | EffectId::Nonlinearity
        )
    }

    /// The effects whose perturbations are its regressors, made once for a pass over the samples.
    pub fn probes(&self) -> Probes {
        let linear = self.template.is_linear();
        let with = |k: usize, v: f64| {
            let mut p = [0.0; 3];
            p[k] = v;
            self.template.with_params(p)
        };
        Probes {
            n: self.n,
            linear,
            effects: std::array::from_fn(|k| {
                if linear {
                    [with(k, 1.0); 2]
                } else {
                    [with(k, STEP), with(k, -STEP)]
                }
            }),
            world: Cell::new(None),
        }
    }
}

/// Step of the central differences of a non-linear effect (the only one is the field direction error, in degrees:
/// second-order terms are ~1e-4 of the first for errors of a degree).
const STEP: f64 = 1e-2;

/// An assumed world field (NED, µT) and, per parameter, the NED regressor it gives.
type WorldColumns = ([f64; 3], [[f64; 3]; 3]);

/// A candidate's effects with one parameter set: per parameter, at 1 (a linear effect) or at ±[`STEP`].
pub(crate) struct Probes {
    n: usize,
    linear: bool,
    effects: [[Effect; 2]; 3],
    /// For an effect that adds the same world-frame field at every sample: the assumed field and, per parameter,
    /// the regressor in NED it gives (computed once, rotated per sample).
    world: Cell<Option<WorldColumns>>,
}

impl Probes {
    /// The regressors at one sample: column `k` is the perturbation per unit of parameter `k`, in calibrated axes
    /// (linearised at zero by central differences for a non-linear effect).
    pub fn regressors(&self, ctx: &Context<'_>) -> [[f64; 3]; 3] {
        if let Some(w) = ctx.world
            && let Some(ned) = self.world_columns(w.field_ned_ut)
        {
            return ned.map(|col| frames::mat_t_vec(&w.sensor_to_ned, col));
        }
        let mut out = [[0.0; 3]; 3];
        for (col, [plus, minus]) in out.iter_mut().zip(&self.effects).take(self.n) {
            *col = if self.linear {
                plus.perturbation_ut(ctx)
            } else {
                let (plus, minus) = (plus.perturbation_ut(ctx), minus.perturbation_ut(ctx));
                difference(plus, minus)
            };
        }
        out
    }

    /// The NED regressors of an effect that adds the same world-frame field at every sample, for the assumed field.
    fn world_columns(&self, field_ned_ut: [f64; 3]) -> Option<[[f64; 3]; 3]> {
        if let Some((f, cols)) = self.world.get()
            && f == field_ned_ut
        {
            return Some(cols);
        }
        let mut cols = [[0.0; 3]; 3];
        for (col, [plus, minus]) in cols.iter_mut().zip(&self.effects).take(self.n) {
            let plus = plus.constant_world_field_ut(field_ned_ut)?;
            *col = if self.linear {
                plus
            } else {
                difference(plus, minus.constant_world_field_ut(field_ned_ut)?)
            };
        }
        self.world.set(Some((field_ned_ut, cols)));
        Some(cols)
    }
}

/// The central difference of two probes at ±[`STEP`].
fn difference(plus: [f64; 3], minus: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|j| (plus[j] - minus[j]) / (2.0 * STEP))
}

/// An effect that cannot be tested on this recording, and why.
#[derive(Clone, Debug, PartialEq)]
pub struct Untestable {
    /// The effect.
    pub id: EffectId,
    /// Why, in words.
    pub why: String,
}

/// What the recording offers.
pub(crate) struct Offer<'a> {
    pub samples: &'a Samples<'a>,
    pub vector: bool,
    pub current_names: &'a [&'a str],
    /// The likeliest step, or why none is offered.
    pub step: Result<Scan, &'static str>,
    pub window: Option<Scan>,
    /// The modelled gross spans: their effect with its times set, and the times' profile intervals.
    pub spans: Vec<(Effect, ScanTimes)>,
}

/// Why no step is offered when the recording is too short to scan for one.
const NO_STEP_SCAN: &str = "the recording is too short to look for a step";
/// Why the scalar method offers no step when one side of it hardly turned.
const STILL_SIDE_OF_STEP: &str = "the sensor turned too little on one side of the likeliest step for the magnitude to \
                                  show the offset there";
/// The scalar method offers a step only when the clean samples on each side of it cover at least this share of the
/// directions all of them cover: on the physical BROAD 02 and Nexus 5 recordings with disturbances added, steps
/// with a side at 0.20 and 0.32 of it took up what was left of a field on the board or a magnet's pass, 3–7 µT off
/// in the offset; every step of the simulated power study (200 recordings) is still offered (at 0.5, 6 % were not).
const STEP_SIDE_COVERAGE: f64 = 0.35;
/// Cells of the sphere of directions for [`STEP_SIDE_COVERAGE`].
const STEP_SIDE_CELLS: usize = 100;

/// What the recording offers to the candidates of a round: the likeliest step and disturbance window, scanned on the
/// `clean` samples of `residual`, and the modelled spans' effects `spans`.
pub(crate) fn offer<'a>(
    setup: &'a Setup<'a>,
    residual: &[[f64; 3]],
    clean: &[bool],
    spans: Vec<(Effect, ScanTimes)>,
) -> Offer<'a> {
    let s = setup.samples;
    let n = s.len();
    // Scans for small steps and windows run on the clean samples.
    let clean_idx: Vec<usize> = (0..n).filter(|&i| clean[i]).collect();
    let sigma2 = clean_idx
        .iter()
        .map(|&i| frames::dot(residual[i], residual[i]))
        .sum::<f64>()
        / (clean_idx.len().max(1) * if setup.vector { 3 } else { 1 }) as f64;
    let step = if !s.has_time {
        None
    } else if setup.vector {
        let e_clean: Vec<[f64; 3]> = clean_idx.iter().map(|&i| residual[i]).collect();
        scan::step_vector(&e_clean, sigma2)
    } else {
        let rho_clean: Vec<f64> = clean_idx.iter().map(|&i| residual[i][0]).collect();
        let u_clean: Vec<[f64; 3]> = clean_idx.iter().map(|&i| setup.unit[i]).collect();
        scan::step_scalar(&rho_clean, &u_clean, sigma2)
    };
    let step = step
        .map(|st| st.through(&clean_idx, n))
        .ok_or(NO_STEP_SCAN)
        .and_then(|st| step_seen(setup, clean, st));
    let window = match (s.rot(), setup.vector && s.has_time) {
        (Some(rot), true) => {
            let world: Vec<[f64; 3]> = clean_idx
                .iter()
                .map(|&i| frames::mat_vec(&rot.at(i), residual[i]))
                .collect();
            scan::window(&world, sigma2)
        }
        _ => None,
    };
    Offer {
        samples: s,
        vector: setup.vector,
        current_names: &setup.current_names,
        step,
        window: window.map(|w| w.through(&clean_idx, n)),
        spans,
    }
}

/// The step `st` if the recording can show it: the magnitude shows a step of the offset only where the sensor turned
/// on both sides of it ([`STEP_SIDE_COVERAGE`]): from a still stretch any offset fits, and a step there soaks up what
/// is left of a disturbance beside it. The vector method sees every step.
fn step_seen(setup: &Setup<'_>, clean: &[bool], st: Scan) -> Result<Scan, &'static str> {
    if setup.vector {
        return Ok(st);
    }
    let n = setup.samples.len();
    let covered = |r: std::ops::Range<usize>| {
        crate::coverage::sphere_fraction(
            r.filter(|&i| clean[i]).map(|i| setup.unit[i]),
            STEP_SIDE_CELLS,
        )
    };
    let all = covered(0..n);
    let side = covered(0..st.start).min(covered(st.start..n));
    if side >= STEP_SIDE_COVERAGE * all {
        Ok(st)
    } else {
        Err(STILL_SIDE_OF_STEP)
    }
}

/// Evidence demanded for the step time scanned over every sample (about 2·ln of the number of effectively
/// independent splits), σ² units; calibrated on null recordings.
pub(crate) const STEP_SCAN_PENALTY: f64 = 14.0;
/// Evidence demanded for the disturbance window scanned over pairs of boundaries.
pub(crate) const WINDOW_SCAN_PENALTY: f64 = 24.0;

/// The candidates and the untestable effects, with columns numbered from `first_column`: the modelled spans'
/// effects (forced into the model), then the catalogue's in a fixed order — temperature, currents, timing, the
/// world's, the response's, time's — each offered where the recording can observe it, or said untestable with why.
pub(crate) fn candidates(
    offer: &Offer<'_>,
    first_column: usize,
) -> (Vec<Candidate>, Vec<Untestable>) {
    let mut list = List {
        out: Vec::new(),
        untestable: Vec::new(),
        column: first_column,
    };
    for (effect, times) in &offer.spans {
        list.add(*effect, None, None, 0.0, Some(*times), true);
    }
    list.temperature(offer);
    list.currents(offer);
    list.timing(offer);
    list.world(offer);
    list.push(
        Effect::Nonlinearity {
            cubic_per_ut2: [0.0; 3],
        },
        None,
        None,
        0.0,
        None,
    );
    list.time(offer);
    (list.out, list.untestable)
}

/// The candidates as they are offered, and the effects said untestable.
struct List {
    out: Vec<Candidate>,
    untestable: Vec<Untestable>,
    /// The next candidate's first design column.
    column: usize,
}

/// Why temperature effects are untestable without a temperature.
const NO_TEMP: &str = "the recording has no temp column";
/// Why time effects are untestable without time.
const NO_TIME: &str = "the recording has no t column";

impl List {
    /// A candidate with its columns next.
    fn add(
        &mut self,
        template: Effect,
        channel: Option<String>,
        supersedes: Option<EffectId>,
        scan_penalty: f64,
        scan: Option<ScanTimes>,
        forced: bool,
    ) {
        let n = template.params().1;
        self.out.push(Candidate {
            template,
            n,
            first: self.column,
            channel,
            supersedes,
            scan_penalty,
            scan,
            forced,
            active_rows: 0,
        });
        self.column += n;
    }

    /// A catalogue candidate (selected, not forced).
    fn push(
        &mut self,
        template: Effect,
        channel: Option<String>,
        supersedes: Option<EffectId>,
        scan_penalty: f64,
        scan: Option<ScanTimes>,
    ) {
        self.add(template, channel, supersedes, scan_penalty, scan, false)
    }

    /// An effect this recording cannot test, and why.
    fn refuse(&mut self, id: EffectId, why: &str) {
        self.untestable.push(Untestable {
            id,
            why: why.to_owned(),
        })
    }

    /// The temperature's effects, about the mean temperature.
    fn temperature(&mut self, offer: &Offer<'_>) {
        let s = offer.samples;
        if !s.has_temp {
            self.refuse(EffectId::TemperatureBias, NO_TEMP);
            self.refuse(EffectId::TemperatureScale, NO_TEMP);
            return;
        }
        let t_ref_c = mean(&s.temp);
        self.push(
            Effect::TemperatureBias {
                coef_ut_per_c: [0.0; 3],
                t_ref_c,
            },
            None,
            None,
            0.0,
            None,
        );
        self.push(
            Effect::TemperatureScale {
                coef_per_c: [0.0; 3],
                t_ref_c,
            },
            None,
            None,
            0.0,
            None,
        );
    }

    /// A current bias per current channel, as many as fit in one model with every other body-fixed effect.
    fn currents(&mut self, offer: &Offer<'_>) {
        // Every body-fixed effect must fit in one model: five besides the currents.
        let max_currents = crate::model::MAX_CORRECTIONS - 5;
        if offer.current_names.is_empty() {
            self.refuse(
                EffectId::CurrentBias,
                "the recording has no current channel (i_<name> column)",
            );
        }
        for name in offer.current_names.iter().skip(max_currents) {
            self.refuse(
                EffectId::CurrentBias,
                &format!("{name}: only the first {max_currents} current channels are tested"),
            );
        }
        for (channel, name) in offer.current_names.iter().enumerate().take(max_currents) {
            self.push(
                Effect::CurrentBias {
                    channel,
                    coef_ut_per_a: [0.0; 3],
                },
                Some((*name).to_owned()),
                None,
                0.0,
                None,
            );
        }
    }

    /// A timing lag, and per-axis delays that generalise it: with a reference and time.
    fn timing(&mut self, offer: &Offer<'_>) {
        const NO_REFERENCE: &str = "the scalar method has no attitude reference: a timing error between sensor and reference needs one";
        match (offer.vector, offer.samples.has_time) {
            (true, true) => {
                self.push(Effect::TimeLag { lag_s: 0.0 }, None, None, 0.0, None);
                self.push(
                    Effect::RateCoupling {
                        lag_axis_s: [0.0; 3],
                    },
                    None,
                    Some(EffectId::TimeLag),
                    0.0,
                    None,
                );
            }
            (false, _) => {
                self.refuse(EffectId::TimeLag, NO_REFERENCE);
                self.refuse(EffectId::RateCoupling, NO_REFERENCE);
            }
            (true, false) => {
                self.refuse(EffectId::TimeLag, NO_TIME);
                self.refuse(EffectId::RateCoupling, NO_TIME);
            }
        }
    }

    /// The world's effects: with the attitude only (to tell the world's frame from the sensor's).
    fn world(&mut self, offer: &Offer<'_>) {
        let s = offer.samples;
        let world_why = if !offer.vector {
            Some(
                "a world-frame effect: the scalar method sees |B| only, with no attitude to tell world from sensor axes",
            )
        } else if s.quat.is_none() {
            Some(
                "a world-frame effect: the recording gives the expected field in sensor axes (rx,ry,rz) but not the attitude",
            )
        } else {
            None
        };
        if let Some(why) = world_why {
            self.refuse(EffectId::FieldDrift, why);
            self.refuse(EffectId::FieldDirectionError, why);
            self.refuse(EffectId::Disturbance, why);
            self.refuse(EffectId::MagnetNearby, why);
            return;
        }
        self.refuse(
            EffectId::MagnetNearby,
            "needs where the sensor was, which no recording holds: such a magnet's spans are located and left out \
             instead",
        );
        if s.has_time {
            self.push(
                Effect::FieldDrift {
                    rate_ut_per_s: [0.0; 3],
                    t_ref_s: mean(&s.t),
                },
                None,
                None,
                0.0,
                None,
            );
        } else {
            self.refuse(EffectId::FieldDrift, NO_TIME);
        }
        self.push(
            Effect::FieldDirectionError {
                declination_error_deg: 0.0,
                inclination_error_deg: 0.0,
            },
            None,
            None,
            0.0,
            None,
        );
        match (s.has_time, offer.window) {
            (true, Some(w)) => self.push(
                Effect::Disturbance {
                    t0_s: between(s, w.start),
                    t1_s: between(s, w.end),
                    field_ned_ut: [0.0; 3],
                },
                None,
                None,
                WINDOW_SCAN_PENALTY,
                Some(scan_times(s, &w, true)),
            ),
            (true, None) => self.refuse(
                EffectId::Disturbance,
                "the recording is too short to look for a transient",
            ),
            (false, _) => self.refuse(EffectId::Disturbance, NO_TIME),
        }
    }

    /// Time's effects on the offset: the likeliest step, and a drift about the mean time.
    fn time(&mut self, offer: &Offer<'_>) {
        let s = offer.samples;
        if !s.has_time {
            self.refuse(EffectId::BiasStep, NO_TIME);
            self.refuse(EffectId::BiasDrift, NO_TIME);
            return;
        }
        match offer.step {
            Ok(step) => self.push(
                Effect::BiasStep {
                    t_s: between(s, step.start),
                    step_ut: [0.0; 3],
                },
                None,
                None,
                STEP_SCAN_PENALTY,
                Some(scan_times(s, &step, false)),
            ),
            Err(why) => self.refuse(EffectId::BiasStep, why),
        }
        self.push(
            Effect::BiasDrift {
                rate_ut_per_s: [0.0; 3],
                t_ref_s: mean(&s.t),
            },
            None,
            None,
            0.0,
            None,
        );
    }
}

/// The mean of a column.
fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

#[cfg(test)]
mod tests {
    use super::super::Reference;
    use super::super::testbench::{Bench, true_model};
    use super::*;

    fn ids(cands: &[Candidate]) -> Vec<EffectId> {
        cands.iter().map(Candidate::id).collect()
    }

    #[test]
    fn every_effect_the_recording_can_observe_is_offered_with_its_columns() {
        let bench = Bench::new(1500, &[], 6);
        let input = bench.input(None, f64::NAN);
        let model = true_model();
        let samples = Samples::gather(&input, &model, false);
        let setup = Setup::new(&input, &samples, &model);
        let residual = setup.residual(&model.a, model.b_ut, &[]);
        let offer = offer(&setup, &residual, &vec![true; samples.len()], Vec::new());
        let (cands, untestable) = candidates(&offer, 12);
        use EffectId::*;
        let mut want = vec![
            TemperatureBias,
            TemperatureScale,
            CurrentBias,
            TimeLag,
            RateCoupling,
            FieldDrift,
            FieldDirectionError,
        ];
        if offer.window.is_some() {
            want.push(Disturbance);
        }
        want.push(Nonlinearity);
        if offer.step.is_ok() {
            want.push(BiasStep);
        }
        want.push(BiasDrift);
        assert_eq!(ids(&cands), want);
        // Columns follow one another from the first given.
        let mut column = 12;
        for c in &cands {
            assert_eq!(c.first, column, "{:?}", c.id());
            column += c.n;
        }
        assert_eq!(cands[2].channel.as_deref(), Some("i_motor"));
        // A magnet fixed in the room needs where the sensor was.
        assert!(untestable.iter().any(|u| u.id == MagnetNearby));
        // The reference temperature is the recording's mean.
        let Effect::TemperatureBias { t_ref_c, .. } = cands[0].template else {
            panic!()
        };
        let mean_c = bench.temp_c.iter().sum::<f64>() / 1500.0;
        assert!((t_ref_c - mean_c).abs() < 1e-9);
    }

    #[test]
    fn without_a_reference_or_a_temperature_the_effects_that_need_them_are_untestable() {
        let bench = Bench::new(600, &[], 7);
        let mut input = bench.input(None, f64::NAN);
        input.reference = Reference::Magnitude { field_ut: 50.0 };
        input.temp_c = None;
        let model = true_model();
        let samples = Samples::gather(&input, &model, false);
        let setup = Setup::new(&input, &samples, &model);
        let residual = setup.residual(&model.a, model.b_ut, &[]);
        let offer = offer(&setup, &residual, &vec![true; samples.len()], Vec::new());
        let (cands, untestable) = candidates(&offer, 9);
        let why = |id: EffectId| {
            untestable
                .iter()
                .find(|u| u.id == id)
                .map(|u| u.why.clone())
                .unwrap_or_default()
        };
        assert_eq!(why(EffectId::TemperatureBias), NO_TEMP);
        assert!(why(EffectId::TimeLag).contains("no attitude reference"));
        assert!(why(EffectId::FieldDrift).contains("scalar method sees |B| only"));
        assert!(
            ids(&cands)
                .iter()
                .all(|id| id.frame() != crate::effects::Frame::World)
        );
    }
}
