//! What a solution of the diagnosis' problem says: the linear part `A`, `b` (back from centred readings, and for
//! the scalar method from the linearisation), their standard errors, and each effect's parameters in report form.

use crate::effects::{Effect, Role, Value};
use crate::frames::{self, Mat3};
use crate::model::Model;

use super::candidates::Candidate;
use super::stats::{Problem, Solution};
use super::{LinearSe, Param, ParamValue};

/// The linear part of a solution: `A` and `b`, back from centred readings (`raw_mean`) and, for the scalar method,
/// from the linearisation about `base`.
pub(crate) fn linear_of(
    sol: &Solution,
    vector: bool,
    base: &Model,
    raw_mean: [f64; 3],
) -> (Mat3, [f64; 3]) {
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
}

/// A coefficient and its standard error (the residual variance per row `sigma2`, autocorrelation included).
pub(crate) fn coefficient(sol: &Solution, col: usize, sigma2: f64) -> Option<(f64, f64)> {
    sol.columns
        .iter()
        .position(|&c| c == col)
        .map(|p| (sol.beta[p], (sol.inverse[(p, p)] * sigma2).sqrt()))
}

/// Standard errors of the linear part `A`, `b` of a solution and of its offset `c = −A⁻¹·b` (`a`, `b`: the linear
/// part they are taken at). Of each quantity, the larger of its variance from the residual variance (allowing for
/// autocorrelated residuals and axes of unequal noise, [`Problem::model_covariance`], as the effects' are) and its
/// cluster-robust variance (allowing for residuals that vary
/// with the regressors in stretches of the recording, as a disturbance's tail does), with the covariances of the
/// entries it is made of. With readings centred on `raw_mean` the fitted offset is `b' = b + A·mean`, so
/// `db = db' − dA·mean` and `dc = −A⁻¹·(db' + dA·(c − mean))`.
pub(crate) fn linear_se(
    problem: &Problem,
    sol: &Solution,
    vector: bool,
    (a, b): (&Mat3, [f64; 3]),
    raw_mean: [f64; 3],
) -> LinearSe {
    let model_cov = problem.model_covariance(sol);
    let cluster = problem.cluster_covariance(sol);
    let pos = |c: usize| sol.columns.iter().position(|&x| x == c);
    // The variance of Σ g·θ over (column, g) pairs under each covariance, the larger one.
    let var = |g: &[(usize, f64)]| {
        let quad = |cov: &dyn Fn(usize, usize) -> f64| {
            let mut v = 0.0;
            for &(c, x) in g {
                for &(d, y) in g {
                    if let (Some(p), Some(q)) = (pos(c), pos(d)) {
                        v += x * cov(p, q) * y;
                    }
                }
            }
            v
        };
        let model = quad(&|p, q| model_cov[(p, q)]);
        let robust = cluster.as_ref().map_or(0.0, |m| quad(&|p, q| m[(p, q)]));
        model.max(robust).max(0.0).sqrt()
    };
    // The columns of A's entry (j, k) and of b'_j.
    let a_col = |j: usize, k: usize| {
        if vector {
            4 * j + k
        } else {
            SYM.iter()
                .position(|&(r, s)| (r, s) == (j.min(k), j.max(k)))
                .expect("a symmetric pair")
        }
    };
    let b_col = |j: usize| if vector { 4 * j + 3 } else { 6 + j };
    let a_se: Mat3 = std::array::from_fn(|j| std::array::from_fn(|k| var(&[(a_col(j, k), 1.0)])));
    let b_se = std::array::from_fn(|j| {
        let mut g = vec![(b_col(j), 1.0)];
        g.extend((0..3).map(|k| (a_col(j, k), -raw_mean[k])));
        var(&g)
    });
    let inv = nalgebra::Matrix3::from_fn(|j, k| a[j][k])
        .try_inverse()
        .unwrap_or_else(nalgebra::Matrix3::zeros);
    let c: [f64; 3] = std::array::from_fn(|k| -(0..3).map(|j| inv[(k, j)] * b[j]).sum::<f64>());
    let lever = frames::sub(c, raw_mean);
    let offset_se = std::array::from_fn(|k| {
        let mut g = Vec::with_capacity(12);
        for j in 0..3 {
            let w = -inv[(k, j)];
            g.push((b_col(j), w));
            g.extend((0..3).map(|m| (a_col(j, m), w * lever[m])));
        }
        var(&g)
    });
    LinearSe {
        a: a_se,
        b_ut: b_se,
        offset_ut: offset_se,
    }
}

/// Index pairs of the scalar method's symmetric `A` parameters (as in [`crate::scalar`]).
pub(crate) const SYM: [(usize, usize); 6] = [(0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)];

/// The report parameters of a fitted effect, in its descriptor's order, with standard errors (`se` per fitted
/// parameter; `sigma2` the residual variance per row, µT²): a fitted vector's three, a fitted number's own; a scanned
/// time's from its scan ([`scanned_se`]); none for a fixed one.
pub(crate) fn params_of(e: &Effect, se: [f64; 3], cand: &Candidate, sigma2: f64) -> Vec<Param> {
    // The size of the jump a scanned time is the time of: the effect's fitted vector.
    let jump2 = match e
        .values()
        .find(|(s, _)| s.role == Role::Fitted)
        .map(|(_, v)| v)
    {
        Some(Value::Vector(v)) if e.values().any(|(s, _)| s.role == Role::Scanned) => {
            frames::dot(v, v)
        }
        _ => f64::INFINITY,
    };
    let (mut fitted_numbers, mut scanned) = (0, 0);
    e.values()
        .map(|(spec, value)| {
            let (value, se) = match (spec.role, value) {
                (Role::Fitted, Value::Vector(v)) => {
                    (ParamValue::Vector(v), Some(ParamValue::Vector(se)))
                }
                (Role::Fitted, Value::Number(x)) => {
                    fitted_numbers += 1;
                    (
                        ParamValue::Number(x),
                        Some(ParamValue::Number(se[fitted_numbers - 1])),
                    )
                }
                (Role::Scanned, Value::Number(t)) => {
                    scanned += 1;
                    let interval = cand.scan.and_then(|s| {
                        if scanned == 1 {
                            Some(s.start_s)
                        } else {
                            s.end_s
                        }
                    });
                    let se = interval.map_or(f64::NAN, |i| scanned_se(i, cand, sigma2, jump2));
                    (ParamValue::Number(t), Some(ParamValue::Number(se)))
                }
                (Role::Channel, _) => (
                    ParamValue::Text(cand.channel.clone().unwrap_or_default()),
                    None,
                ),
                (_, Value::Vector(v)) => (ParamValue::Vector(v), None),
                (_, Value::Number(x)) => (ParamValue::Number(x), None),
                (_, Value::Channel(_)) => unreachable!("only a channel parameter holds a channel"),
            };
            Param {
                name: spec.name,
                value,
                se,
            }
        })
        .collect()
}

/// A scanned time's uncertainty from its profile interval `(lo, hi)`, s. A change point is not a regular parameter
/// and its profile interval under-covers; the location error of a jump Δ (`jump2` = |Δ|²) in white noise σ
/// (`sigma2` = σ²) spreads like the argmax of a two-sided random walk with drift, whose standard deviation is
/// √26·σ²/|Δ|² samples (Yao, Ann. Statist. 15, 1987). The larger of the two, and at least half a sample interval.
fn scanned_se((lo, hi): (f64, f64), cand: &Candidate, sigma2: f64, jump2: f64) -> f64 {
    let dt = cand.scan.map_or(0.0, |s| s.sample_interval_s);
    ((hi - lo) / 2.0)
        .max(26f64.sqrt() * sigma2 / jump2 * dt)
        .max(dt / 2.0)
}

#[cfg(test)]
mod tests {
    use nalgebra::{DMatrix, DVector};

    use super::super::candidates::ScanTimes;
    use super::*;

    fn solution(beta: Vec<f64>) -> Solution {
        let n = beta.len();
        Solution {
            columns: (0..n).collect(),
            beta: DVector::from_vec(beta),
            inverse: DMatrix::identity(n, n) * 0.01,
            rss: 1.0,
        }
    }

    #[test]
    fn the_linear_part_is_taken_back_from_centred_readings() {
        // Rows of A then b' per axis: b = b' − A·mean.
        let mut beta = Vec::new();
        for j in 0..3 {
            beta.extend((0..3).map(|k| if j == k { 2.0 } else { 0.0 }));
            beta.push(10.0 * (j + 1) as f64);
        }
        let mean = [1.0, 2.0, 3.0];
        let base = Model::linear(frames::IDENTITY, [0.0; 3]);
        let (a, b) = linear_of(&solution(beta), true, &base, mean);
        assert_eq!(a, [[2.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 2.0]]);
        assert_eq!(b, [8.0, 16.0, 24.0]);
        // The scalar method's columns move the base fit's symmetric A and its offset.
        let (a, _) = linear_of(
            &solution(vec![0.1, 0.0, 0.0, 0.05, 0.0, 0.0, 0.0, 0.0, 0.0]),
            false,
            &base,
            mean,
        );
        assert_eq!((a[0][0], a[0][1], a[1][0]), (1.1, 0.05, 0.05));
        assert_eq!(coefficient(&solution(vec![3.0]), 0, 4.0), Some((3.0, 0.2)));
    }

    fn candidate(template: Effect, scan: Option<ScanTimes>) -> Candidate {
        Candidate {
            n: template.params().1,
            template,
            first: 12,
            channel: Some("i_motor".to_owned()),
            supersedes: None,
            scan_penalty: 0.0,
            scan,
            forced: false,
            active_rows: 0,
        }
    }

    #[test]
    fn each_parameter_is_reported_in_the_descriptors_order_with_its_own_uncertainty() {
        let current = Effect::CurrentBias {
            channel: 0,
            coef_ut_per_a: [0.3, 0.0, -0.2],
        };
        let p = params_of(&current, [0.01, 0.02, 0.03], &candidate(current, None), 0.1);
        assert_eq!(p[0].value, ParamValue::Text("i_motor".to_owned()));
        assert_eq!((p[0].name, p[0].se.clone()), ("channel", None));
        assert_eq!(p[1].se, Some(ParamValue::Vector([0.01, 0.02, 0.03])));
        let direction = Effect::FieldDirectionError {
            declination_error_deg: 2.0,
            inclination_error_deg: -1.0,
        };
        let p = params_of(
            &direction,
            [0.1, 0.2, 0.0],
            &candidate(direction, None),
            0.1,
        );
        assert_eq!(p[1].se, Some(ParamValue::Number(0.2)));
        // A window's times: their profile intervals, at least half a sample apart, and no less than a jump of its
        // size in this noise allows.
        let window = Effect::Disturbance {
            t0_s: 10.0,
            t1_s: 20.0,
            field_ned_ut: [3.0, 0.0, 4.0],
        };
        let scan = ScanTimes {
            start_s: (9.9, 10.3),
            end_s: Some((19.99, 20.01)),
            sample_interval_s: 0.02,
        };
        let p = params_of(&window, [0.1; 3], &candidate(window, Some(scan)), 0.25);
        let names: Vec<&str> = p.iter().map(|x| x.name).collect();
        assert_eq!(names, ["t0_s", "t1_s", "field_ned_ut"]);
        let se = |k: usize| match p[k].se {
            Some(ParamValue::Number(x)) => x,
            _ => panic!(),
        };
        assert!((se(0) - 0.2).abs() < 1e-12);
        let yao = 26f64.sqrt() * 0.25 / 25.0 * 0.02;
        assert!((se(1) - yao.max(0.01)).abs() < 1e-12, "{}", se(1));
    }
}
