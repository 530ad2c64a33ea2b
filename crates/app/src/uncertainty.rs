//! How uncertain the calibrated field is at a given raw reading, from the fit's parameter covariance: what turns the
//! fit's standard errors into a heading uncertainty ([`crate::heading`]).
//!
//! - Vector fit: each calibrated axis is its own least-squares problem; [`VectorFit::field_se_ut`] propagates its
//!   4×4 covariance of `(a_j, b_j)` to the calibrated field. The rows are independent, so the 3×3 covariance is
//!   diagonal.
//! - Scalar fit: `B = A·(B̂ − c)`. The solver publishes the centre's covariance and the standard errors of the
//!   symmetric `A`'s six entries, not their correlations; they are propagated as independent:
//!   `Σ_B = A·Σ_c·Aᵀ + Σ_rs se_rs²·g_rs·g_rsᵀ`, with `g_rs = ∂B/∂A_rs` at `d = B̂ − c`. Fitting on the centre
//!   decouples `c` from `A` on a well-covered sphere; whether the whole is honest is checked against the spread of
//!   fits over simulated recordings (tests).
//!
//! [`FieldUncertainty::factors`] writes the same covariance as independent standard normal draws: what a figure that
//! is a function of the errors at many readings at once (the worst of 360 headings) is drawn with.

use magcal_calib::frames::{self, Mat3};
use magcal_calib::scalar::{SYM, ScalarFit};
use magcal_calib::vector::VectorFit;

use crate::fit::Fit;

/// The covariance of the calibrated field as a function of the raw reading.
#[derive(Clone, Debug)]
pub enum FieldUncertainty {
    /// A vector fit's per-axis covariances.
    Vector(Box<VectorFit>),
    /// A scalar fit's `A`, centre and their uncertainties.
    Scalar(Box<ScalarParts>),
}

/// What the scalar fit says of its `A` and centre.
#[derive(Clone, Debug)]
pub struct ScalarParts {
    /// `A`.
    pub a: Mat3,
    /// The centre `c`, µT.
    pub centre_ut: [f64; 3],
    /// The centre's covariance, µT².
    pub centre_cov_ut2: Mat3,
    /// Standard errors of `A`'s entries.
    pub a_se: Mat3,
}

impl FieldUncertainty {
    /// From a fit of either method.
    pub fn of(fit: &Fit) -> FieldUncertainty {
        match fit {
            Fit::Vector(v) => FieldUncertainty::vector(v),
            Fit::Scalar(s) => FieldUncertainty::scalar(s),
        }
    }

    /// From a vector fit.
    pub fn vector(fit: &VectorFit) -> FieldUncertainty {
        FieldUncertainty::Vector(Box::new(fit.clone()))
    }

    /// From a scalar fit.
    pub fn scalar(fit: &ScalarFit) -> FieldUncertainty {
        FieldUncertainty::Scalar(Box::new(ScalarParts {
            a: fit.a,
            centre_ut: fit.centre_ut,
            centre_cov_ut2: fit.centre_cov_ut2,
            a_se: fit.a_se,
        }))
    }

    /// The covariance of the calibrated field (µT², calibrated axes) at the raw reading `raw_ut`.
    pub fn covariance_at(&self, raw_ut: [f64; 3]) -> Mat3 {
        match self {
            FieldUncertainty::Vector(fit) => {
                let se = fit.field_se_ut(raw_ut);
                std::array::from_fn(|j| {
                    std::array::from_fn(|k| if j == k { se[j] * se[j] } else { 0.0 })
                })
            }
            FieldUncertainty::Scalar(parts) => {
                let ScalarParts {
                    a,
                    centre_ut,
                    centre_cov_ut2,
                    a_se,
                } = &**parts;
                let d = frames::sub(raw_ut, *centre_ut);
                // A·Σ_c·Aᵀ
                let mut c: Mat3 = std::array::from_fn(|j| {
                    std::array::from_fn(|k| {
                        (0..3)
                            .flat_map(|r| (0..3).map(move |s| (r, s)))
                            .map(|(r, s)| a[j][r] * centre_cov_ut2[r][s] * a[k][s])
                            .sum()
                    })
                });
                for &(r, s) in &SYM {
                    let mut g = [0.0; 3];
                    g[r] += d[s];
                    if r != s {
                        g[s] += d[r];
                    }
                    let var = a_se[r][s] * a_se[r][s];
                    for j in 0..3 {
                        for k in 0..3 {
                            c[j][k] += var * g[j] * g[k];
                        }
                    }
                }
                c
            }
        }
    }

    /// The standard error (µT) of the calibrated field's component along the unit vector `dir` at `raw_ut`.
    pub fn se_along_ut(&self, raw_ut: [f64; 3], dir: [f64; 3]) -> f64 {
        let c = self.covariance_at(raw_ut);
        frames::dot(dir, frames::mat_vec(&c, dir)).max(0.0).sqrt()
    }

    /// The calibrated field's error as independent standard normal draws `z_m`: at the raw reading `raw`, the error
    /// is `Σ_m z_m·(M_m·raw + v_m)` µT, with the covariance [`FieldUncertainty::covariance_at`] gives (each
    /// parameter block's covariance factored by its eigenvectors, negative eigenvalues taken as zero).
    pub fn factors(&self) -> Vec<ErrorFactor> {
        match self {
            FieldUncertainty::Vector(fit) => (0..3)
                .flat_map(|j| {
                    // The error of row j is (δa_j·raw + δb_j) along axis j; δ(a_j, b_j) = L_j·z, L_j·L_jᵀ = Σ_j.
                    let l = square_root(&fit.covariance[j]);
                    (0..4).map(move |m| {
                        let mut f = ErrorFactor::default();
                        f.m[j] = [l[0][m], l[1][m], l[2][m]];
                        f.v_ut[j] = l[3][m];
                        f
                    })
                })
                .collect(),
            FieldUncertainty::Scalar(parts) => {
                let ScalarParts {
                    a,
                    centre_ut,
                    centre_cov_ut2,
                    a_se,
                } = &**parts;
                // δB = −A·δc + δA·(raw − c): the centre's draws through A, then each entry of the symmetric A.
                let l = square_root(centre_cov_ut2);
                let centre = (0..3).map(|m| ErrorFactor {
                    m: [[0.0; 3]; 3],
                    v_ut: frames::mat_vec(a, [l[0][m], l[1][m], l[2][m]]),
                });
                let entries = SYM.iter().map(|&(r, s)| {
                    let mut m = [[0.0; 3]; 3];
                    m[r][s] = a_se[r][s];
                    m[s][r] = a_se[r][s];
                    ErrorFactor {
                        m,
                        v_ut: frames::scale(frames::mat_vec(&m, *centre_ut), -1.0),
                    }
                });
                centre.chain(entries).collect()
            }
        }
    }
}

/// One independent draw's share of the calibrated field's error ([`FieldUncertainty::factors`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ErrorFactor {
    /// The part that grows with the raw reading, per µT of it.
    pub m: Mat3,
    /// The part that does not, µT.
    pub v_ut: [f64; 3],
}

impl ErrorFactor {
    /// This draw's error (µT per unit draw) at the raw reading `raw_ut`.
    pub fn at(&self, raw_ut: [f64; 3]) -> [f64; 3] {
        frames::add(frames::mat_vec(&self.m, raw_ut), self.v_ut)
    }
}

/// `L` with `L·Lᵀ = c` for a symmetric `c` (eigenvectors scaled by the roots of the eigenvalues, negative ones
/// taken as zero).
fn square_root<const N: usize>(c: &[[f64; N]; N]) -> [[f64; N]; N] {
    let eigen =
        nalgebra::DMatrix::from_fn(N, N, |j, k| 0.5 * (c[j][k] + c[k][j])).symmetric_eigen();
    std::array::from_fn(|j| {
        std::array::from_fn(|m| eigen.eigenvectors[(j, m)] * eigen.eigenvalues[m].max(0.0).sqrt())
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use magcal_sim::{ChipModel, Scenario, SensorTruth, Trajectory, simulate};

    /// At the raw reading zero the calibrated field is `b`: the propagated covariance there gives the solver's own
    /// standard errors of `b` (which it propagates with the correlations), within what leaving out the correlations
    /// between `A`'s entries and the centre costs on a well-covered sphere.
    #[test]
    fn at_zero_the_scalar_propagation_gives_the_standard_errors_of_b() {
        use crate::calibrate::calibrate;
        use crate::field::ReferenceField;
        use crate::fit::{Fit, Method};
        use magcal_sim::AttitudeOutput;

        let chip = ChipModel::by_name("lis3mdl").unwrap();
        let mut s = Scenario::new(
            &chip,
            Trajectory::Tumble {
                duration_s: 60.0,
                rate_rad_s: 1.0,
            },
            3,
        );
        s.sensor = SensorTruth::mounted(
            [[1.08, 0.03, -0.01], [0.03, 0.95, 0.04], [-0.01, 0.04, 1.12]],
            [12.0, -30.0, 8.0],
            [0.0; 3],
        );
        s.attitude = AttitudeOutput::None;
        let run = simulate(&s).unwrap();
        let cal = calibrate(
            &run.recording,
            Method::Scalar,
            ReferenceField::Unknown,
            false,
        )
        .unwrap();
        let Fit::Scalar(fit) = &cal.fit else {
            panic!("not scalar")
        };
        let c = FieldUncertainty::scalar(fit).covariance_at([0.0; 3]);
        for j in 0..3 {
            let ratio = c[j][j].sqrt() / fit.b_se_ut[j];
            println!("axis {j}: propagated over the solver's SE of b: {ratio:.3}");
            assert!((0.75..1.33).contains(&ratio), "axis {j}: {ratio}");
        }
    }

    /// The draws' factors give the covariance the propagation gives, for both methods, at readings near and far.
    #[test]
    fn the_factors_give_the_propagated_covariance() {
        use crate::calibrate::calibrate;
        use crate::field::ReferenceField;
        use crate::fit::Method;

        let chip = ChipModel::by_name("lis3mdl").unwrap();
        let mut s = Scenario::new(
            &chip,
            Trajectory::Tumble {
                duration_s: 20.0,
                rate_rad_s: 1.0,
            },
            5,
        );
        s.sensor = SensorTruth::mounted(
            [[1.08, 0.03, -0.01], [0.03, 0.95, 0.04], [-0.01, 0.04, 1.12]],
            [12.0, -30.0, 8.0],
            [0.02, -0.03, 0.01],
        );
        let run = simulate(&s).unwrap();
        let field = ReferenceField::Vector {
            field_ned_ut: s.field_ned_ut,
            source: "test".into(),
        };
        for method in [Method::Vector, Method::Scalar] {
            let cal = calibrate(&run.recording, method, field.clone(), false).unwrap();
            let u = FieldUncertainty::of(&cal.fit);
            let factors = u.factors();
            assert_eq!(factors.len(), if method == Method::Vector { 12 } else { 9 });
            for raw in [[0.0; 3], [30.0, -20.0, 45.0], [-50.0, 10.0, -5.0]] {
                let want = u.covariance_at(raw);
                let scale = (0..3).map(|j| want[j][j]).fold(0.0, f64::max);
                for j in 0..3 {
                    for k in 0..3 {
                        let got: f64 = factors.iter().map(|f| f.at(raw)[j] * f.at(raw)[k]).sum();
                        assert!(
                            (got - want[j][k]).abs() <= 1e-9 * scale,
                            "{method:?} at {raw:?}, ({j}, {k}): {got} against {}",
                            want[j][k]
                        );
                    }
                }
            }
        }
    }

    /// The propagated uncertainty is honest: over many simulated recordings of one sensor, the error of the fitted
    /// calibration across the horizontal field direction, at each level heading, divided by the predicted standard
    /// error, has an RMS near 1 for the vector fit (with its misalignment; measured 1.00) and at most 1 for the
    /// scalar fit (a symmetric sensor, the magnitude given; measured 0.81). Heavy: run in release with `--ignored`.
    #[test]
    #[ignore = "statistics over 120 simulated recordings: run in release"]
    fn predicted_errors_match_the_spread_of_fits_over_seeds() {
        use crate::calibrate::calibrate;
        use crate::field::ReferenceField;
        use crate::fit::{Fit, Method};
        use crate::heading::{Face, LocalField};
        use magcal_sim::AttitudeOutput;

        let chip = ChipModel::by_name("lis3mdl").unwrap();
        for method in [Method::Vector, Method::Scalar] {
            let mut sum_z2 = 0.0;
            let mut count = 0usize;
            for seed in 1..=60 {
                let mut s = Scenario::new(
                    &chip,
                    Trajectory::Tumble {
                        duration_s: 60.0,
                        rate_rad_s: 1.0,
                    },
                    seed,
                );
                let mount = if method == Method::Vector {
                    [0.02, -0.03, 0.01]
                } else {
                    [0.0; 3]
                };
                s.sensor = SensorTruth::mounted(
                    [[1.08, 0.03, -0.01], [0.03, 0.95, 0.04], [-0.01, 0.04, 1.12]],
                    [12.0, -30.0, 8.0],
                    mount,
                );
                s.noise_ut = [0.4; 3];
                s.attitude = if method == Method::Vector {
                    AttitudeOutput::Quaternion
                } else {
                    AttitudeOutput::None
                };
                let run = simulate(&s).unwrap();
                let f = s.field_ned_ut;
                let field = match method {
                    Method::Vector => ReferenceField::Vector {
                        field_ned_ut: f,
                        source: "test".into(),
                    },
                    _ => ReferenceField::Magnitude {
                        field_ut: frames::norm(f),
                        source: "test".into(),
                    },
                };
                let cal = calibrate(&run.recording, method, field, false).unwrap();
                let u = match &cal.fit {
                    Fit::Vector(v) => FieldUncertainty::vector(v),
                    Fit::Scalar(sf) => FieldUncertainty::scalar(sf),
                };
                let m = cal.model();
                let forward = run.truth.sensor.forward();
                let local = LocalField::new(frames::field_angles(f).1, frames::norm(f));
                for k in (0..360).step_by(15) {
                    let r = Face::ZDown.sensor_to_level(f64::from(k).to_radians());
                    let truth =
                        frames::mat_t_vec(&r, [local.horizontal_ut, 0.0, local.vertical_ut]);
                    let raw = forward(truth);
                    let across = frames::mat_t_vec(&r, [0.0, 1.0, 0.0]);
                    let err = frames::dot(
                        frames::sub(m.apply(raw, &magcal_calib::Inputs::NONE), truth),
                        across,
                    );
                    let z = err / u.se_along_ut(raw, across);
                    sum_z2 += z * z;
                    count += 1;
                }
            }
            let rms_z = (sum_z2 / count as f64).sqrt();
            println!(
                "{method:?}: error over predicted standard error, RMS {rms_z:.3} over {count}"
            );
            // The scalar solver's standard errors are the larger of the model-based and the cluster-robust ones,
            // with a shape prior, and their correlations are left out here: conservative, not optimistic.
            let honest = match method {
                Method::Vector => 0.8..1.25,
                _ => 0.6..1.25,
            };
            assert!(
                honest.contains(&rms_z),
                "{method:?}: errors over predicted standard errors have RMS {rms_z}"
            );
        }
    }
}
