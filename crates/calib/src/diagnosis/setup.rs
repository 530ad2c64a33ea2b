//! What every stage of the diagnosis shares: the samples, what the reference offers (vector or magnitude), the
//! field's direction per sample, the noise floor in calibrated units, and the residual of a model with effects.

use crate::chunks;
use crate::effects::Effect;
use crate::frames::{self, Mat3};
use crate::model::Model;
use crate::robust::RobustProblem;

use super::samples::Samples;
use super::{DiagnosisInput, Reference};

/// What every stage shares: the samples and what the reference offers.
pub(crate) struct Setup<'a> {
    pub input: &'a DiagnosisInput<'a>,
    pub samples: &'a Samples<'a>,
    /// The vector method (three residual components per sample), or the scalar one (the magnitude's).
    pub vector: bool,
    /// The field magnitude (scalar: the fitted one; vector: the reference's mean), µT.
    pub field_ut: f64,
    /// The raw readings' mean, µT: the design's readings are centred on it.
    pub raw_mean: [f64; 3],
    /// The field direction per sample, sensor axes.
    pub unit: Vec<[f64; 3]>,
    /// The current channels' names (`i_<name>`).
    pub current_names: Vec<&'a str>,
    /// The noise floor in calibrated units (per axis RMS, or of |B|), µT.
    pub noise_floor_ut: f64,
    /// Columns of the base model in the design: 12 (vector) or 9 (scalar: `A`'s symmetric part and the offset).
    pub n_base: usize,
    /// The base fit the samples' fields were computed with (the scalar method's linearisation point).
    pub base: Model,
}

impl<'a> Setup<'a> {
    /// The shared part of the stages for `samples` of `input`, against the base fit `base`.
    pub fn new(input: &'a DiagnosisInput<'a>, samples: &'a Samples, base: &Model) -> Setup<'a> {
        let n = samples.len();
        let vector = !matches!(input.reference, Reference::Magnitude { .. });
        let field_ut = match input.reference {
            Reference::Magnitude { field_ut } => field_ut,
            _ => samples.field.iter().map(|f| frames::norm(*f)).sum::<f64>() / n as f64,
        };
        let raw_mean = frames::scale(
            samples.raw.iter().fold([0.0; 3], |s, m| frames::add(s, *m)),
            1.0 / n as f64,
        );
        let unit: Vec<[f64; 3]> = chunks::map(n, |i| {
            let f = samples.field[i];
            frames::scale(f, 1.0 / frames::norm(f))
        });
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
        Setup {
            input,
            samples,
            vector,
            field_ut,
            raw_mean,
            unit,
            current_names: input.currents.iter().map(|(name, _)| *name).collect(),
            noise_floor_ut,
            n_base: if vector { 12 } else { 9 },
            base: *base,
        }
    }

    /// The residual per sample of `A·B̂ + b − Σδ` against the reference: three components (vector), or the
    /// magnitude's in the first (scalar). Computed on all threads.
    pub fn residual(&self, a: &Mat3, b: [f64; 3], effects: &[Effect]) -> Vec<[f64; 3]> {
        let s = self.samples;
        chunks::map(s.len(), |i| {
            let ctx = s.context(i);
            let delta = effects
                .iter()
                .fold([0.0; 3], |acc, e| frames::add(acc, e.perturbation_ut(&ctx)));
            let cal = frames::sub(frames::add(frames::mat_vec(a, s.raw[i]), b), delta);
            if self.vector {
                frames::sub(cal, s.field[i])
            } else {
                [frames::norm(cal) - self.field_ut, 0.0, 0.0]
            }
        })
    }

    /// A residual's size, as the robust fit judges it.
    pub fn size(&self, e: &[f64; 3]) -> f64 {
        if self.vector {
            frames::norm(*e)
        } else {
            e[0].abs()
        }
    }

    /// The residual's scale: its median size as a standard deviation (per axis, or of |B|).
    pub fn scale(&self, residual: &[[f64; 3]]) -> f64 {
        let mut v: Vec<f64> = residual.iter().map(|e| self.size(e)).collect();
        let mid = v.len() / 2;
        let median = *v.select_nth_unstable_by(mid, f64::total_cmp).1;
        median / self.median_of_unit()
    }

    /// The median residual size of pure noise of unit standard deviation, for this method.
    pub fn median_of_unit(&self) -> f64 {
        if self.vector {
            <crate::vector::VectorProblem<'_> as RobustProblem>::MEDIAN_OF_UNIT
        } else {
            <crate::scalar::ScalarProblem<'_> as RobustProblem>::MEDIAN_OF_UNIT
        }
    }

    /// The scale of `residual` and, per sample, whether it lies outside the gross spans of the state most samples
    /// are in ([`crate::robust::state_spans`], with this method's ramp tail).
    pub fn state_kept(&self, residual: &[[f64; 3]]) -> (f64, Vec<bool>) {
        let sizes: Vec<f64> = residual.iter().map(|e| self.size(e)).collect();
        let times = self.samples.has_time.then_some(&self.samples.t[..]);
        let tail = if self.vector {
            <crate::vector::VectorProblem<'_> as RobustProblem>::RAMP_TAIL
        } else {
            <crate::scalar::ScalarProblem<'_> as RobustProblem>::RAMP_TAIL
        };
        let (scale, spans) = crate::robust::state_spans(
            &sizes,
            self.scale(residual),
            self.median_of_unit_in_mode(),
            times,
            tail,
        );
        (scale, crate::robust::outside(&spans, sizes.len()))
    }

    /// The same median among sizes below [`crate::robust::MODE_WINDOW`], for this method.
    pub fn median_of_unit_in_mode(&self) -> f64 {
        if self.vector {
            <crate::vector::VectorProblem<'_> as RobustProblem>::MEDIAN_OF_UNIT_IN_MODE
        } else {
            <crate::scalar::ScalarProblem<'_> as RobustProblem>::MEDIAN_OF_UNIT_IN_MODE
        }
    }

    /// The columns of `A` in the design.
    pub fn a_columns(&self) -> Vec<usize> {
        if self.vector {
            (0..3)
                .flat_map(|j| (0..3).map(move |k| 4 * j + k))
                .collect()
        } else {
            (0..6).collect()
        }
    }

    /// The scalar method's base residual of sample `i` (zero for the vector method, whose rows need none).
    pub fn base_rho(&self, i: usize) -> f64 {
        if self.vector {
            0.0
        } else {
            frames::norm(self.samples.field[i]) - self.field_ut
        }
    }

    /// The channels the residual is compared with, per sample.
    pub fn channels(&self) -> Vec<(String, Vec<f64>)> {
        let s = self.samples;
        let n = s.len();
        let mut channels: Vec<(String, Vec<f64>)> = Vec::new();
        if s.has_temp {
            channels.push(("temp".to_owned(), s.temp.to_vec()));
        }
        for (k, name) in self.current_names.iter().enumerate() {
            channels.push((
                (*name).to_owned(),
                (0..n).map(|i| s.currents[i * s.n_currents + k]).collect(),
            ));
        }
        if s.has_time {
            channels.push(("t".to_owned(), s.t.to_vec()));
        }
        if self.vector && s.has_time {
            channels.push((
                "rotation_rate".to_owned(),
                s.rate.iter().map(|r| frames::norm(*r)).collect(),
            ));
        }
        channels
    }
}

#[cfg(test)]
mod tests {
    use super::super::testbench::{Bench, NOISE_UT, true_model};
    use super::*;

    #[test]
    fn the_true_models_residual_is_the_noise() {
        let bench = Bench::new(2000, &[], 5);
        let input = bench.input(None, f64::NAN);
        let model = true_model();
        let samples = Samples::gather(&input, &model, false);
        let setup = Setup::new(&input, &samples, &model);
        assert!(setup.vector && setup.n_base == 12);
        let residual = setup.residual(&model.a, model.b_ut, &[]);
        let rms =
            (residual.iter().map(|e| frames::dot(*e, *e)).sum::<f64>() / (3.0 * 2000.0)).sqrt();
        // The readings' noise through A (gains near one).
        assert!((rms / NOISE_UT - 1.0).abs() < 0.1, "{rms}");
        assert!((setup.scale(&residual) / NOISE_UT - 1.0).abs() < 0.15);
        assert!(
            (setup.noise_floor_ut / NOISE_UT - 1.0).abs() < 0.15,
            "{}",
            setup.noise_floor_ut
        );
        // An effect's perturbation comes out of the residual: with a made-up offset added, it is there again.
        let shifted = Model::linear(model.a, frames::add(model.b_ut, [1.0, 0.0, 0.0]));
        let e = setup.residual(
            &shifted.a,
            shifted.b_ut,
            &[Effect::BiasDrift {
                rate_ut_per_s: [0.0; 3],
                t_ref_s: 0.0,
            }],
        );
        let mean_x = e.iter().map(|v| v[0]).sum::<f64>() / 2000.0;
        assert!((mean_x - 1.0).abs() < 0.05, "{mean_x}");
    }
}
