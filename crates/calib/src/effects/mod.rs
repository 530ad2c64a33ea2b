//! The catalogue of physics a 12-parameter calibration leaves out.
//!
//! Every effect is defined here once, as the perturbation `δ` (µT, calibrated sensor axes) it adds to what a perfectly
//! calibrated sensor would read:
//!
//! ```text
//! A·B̂ + b = B_sensor + Σ δ_k(context, params_k)
//! ```
//!
//! The simulator injects an effect by evaluating [`Effect::perturbation_ut`] with the true field; the fitter estimates
//! the same effect's parameters with the same function (it is linear in them for all but
//! [`Effect::FieldDirectionError`], see [`Effect::is_linear`]), and `apply` removes the body-fixed ones.

use crate::frames::{self, Mat3};

mod catalogue;

pub use catalogue::{CATALOGUE, Descriptor, Need, ParamSpec, Role, Shape, Value, WhenOmitted};

/// The stable identifier of an effect, as it appears in reports and parameter files.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum EffectId {
    /// Offset (hard iron) changing with temperature.
    TemperatureBias,
    /// Scale factors changing with temperature.
    TemperatureScale,
    /// Field of a current recorded in an `i_<name>` channel.
    CurrentBias,
    /// The magnetometer sample is late relative to the attitude reference (one delay for all axes).
    TimeLag,
    /// Each axis follows the rate of change of the field with its own delay (filters, eddy currents).
    RateCoupling,
    /// The world field changes during the recording.
    FieldDrift,
    /// The true field points elsewhere than the assumed one.
    FieldDirectionError,
    /// Response not linear in the field (per-axis cubic).
    Nonlinearity,
    /// A sudden offset change.
    BiasStep,
    /// Offset drifting with time, in sensor axes.
    BiasDrift,
    /// A transient external field, fixed in the world frame.
    Disturbance,
    /// A transient offset fixed to the sensor (something magnetic attached to the board for a while).
    BiasWindow,
    /// A magnet fixed in the room: its field depends on where the sensor is.
    MagnetNearby,
}

impl EffectId {
    /// Every effect, in catalogue order.
    pub const ALL: [EffectId; 13] = [
        EffectId::TemperatureBias,
        EffectId::TemperatureScale,
        EffectId::CurrentBias,
        EffectId::TimeLag,
        EffectId::RateCoupling,
        EffectId::FieldDrift,
        EffectId::FieldDirectionError,
        EffectId::Nonlinearity,
        EffectId::BiasStep,
        EffectId::BiasDrift,
        EffectId::Disturbance,
        EffectId::BiasWindow,
        EffectId::MagnetNearby,
    ];

    /// The id used in reports, e.g. `"temperature_bias"`.
    pub fn as_str(self) -> &'static str {
        self.descriptor().name
    }

    /// Parses a report id.
    pub fn parse(s: &str) -> Option<EffectId> {
        EffectId::ALL.into_iter().find(|id| id.as_str() == s)
    }

    /// Where the effect lives.
    pub fn frame(self) -> Frame {
        self.descriptor().frame
    }

    /// Whether the effect is an event of one recording (a disturbance that came and went) rather than a property
    /// of the sensor or the bench: never a correction for other recordings.
    pub fn is_transient(self) -> bool {
        self.descriptor().transient
    }

    /// Whether the effect is a correction `apply` removes: fixed to the sensor, and a property of it (not an event
    /// of one recording).
    pub fn is_correction(self) -> bool {
        self.frame() == Frame::Body && !self.is_transient()
    }
}

impl core::fmt::Display for EffectId {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// Where an effect lives, which decides what a recording must hold to observe it and whether `apply` can remove it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Frame {
    /// Fixed to the sensor: a property of the sensor and its mount; `apply` removes it.
    Body,
    /// Fixed to the world: a property of the field or the bench, seen through the attitude.
    World,
    /// Timing between the magnetometer and the attitude reference.
    Timing,
}

/// The attitude and the assumed world field at one sample.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WorldContext {
    /// Rotation taking sensor-frame vectors to NED.
    pub sensor_to_ned: Mat3,
    /// The world field the calibration assumes, NED, µT.
    pub field_ned_ut: [f64; 3],
    /// Where the sensor is, NED, m (zero when not known: no recording holds it; the simulator does).
    pub position_m: [f64; 3],
}

/// Everything an effect may depend on at one sample.
#[derive(Clone, Copy, Debug)]
pub struct Context<'a> {
    /// Time, s.
    pub t_s: f64,
    /// Temperature, °C (NaN if not recorded).
    pub temp_c: f64,
    /// Currents, A, in the order of the recording's `i_<name>` channels.
    pub currents_a: &'a [f64],
    /// The field in calibrated sensor axes, µT: the true field in the simulator, the reference (vector method) or the
    /// calibrated reading (scalar method) in the fitter.
    pub field_ut: [f64; 3],
    /// Time derivative of `field_ut`, µT/s.
    pub field_rate_ut_per_s: [f64; 3],
    /// Attitude and assumed world field, when the recording has an attitude reference.
    pub world: Option<WorldContext>,
}

impl Context<'_> {
    /// A context for the body-fixed effects only (no attitude, no field rate), as `apply` has.
    pub fn body(t_s: f64, temp_c: f64, currents_a: &[f64], field_ut: [f64; 3]) -> Context<'_> {
        Context {
            t_s,
            temp_c,
            currents_a,
            field_ut,
            field_rate_ut_per_s: [0.0; 3],
            world: None,
        }
    }
}

/// One effect with its parameters. Parameter names follow the report contract.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Effect {
    /// `δ = coef·(T − T_ref)`.
    TemperatureBias {
        /// µT/°C per calibrated axis.
        coef_ut_per_c: [f64; 3],
        /// Reference temperature, °C (a shift of it is absorbed by the offset `b`).
        t_ref_c: f64,
    },
    /// `δ_j = coef_j·(T − T_ref)·B_j`.
    TemperatureScale {
        /// Relative scale change per °C per calibrated axis.
        coef_per_c: [f64; 3],
        /// Reference temperature, °C (a shift of it is absorbed by `A`).
        t_ref_c: f64,
    },
    /// `δ = coef·i_channel`.
    CurrentBias {
        /// Index of the current among the recording's `i_<name>` channels.
        channel: usize,
        /// µT/A per calibrated axis.
        coef_ut_per_a: [f64; 3],
    },
    /// `δ = −lag·dB/dt`: the reading at `t` is the field at `t − lag` (positive = magnetometer late).
    TimeLag {
        /// Delay, s.
        lag_s: f64,
    },
    /// `δ_j = −lag_j·dB_j/dt`: a per-axis delay.
    RateCoupling {
        /// Delay per calibrated axis, s.
        lag_axis_s: [f64; 3],
    },
    /// `δ = Rᵀ·rate·(t − t_ref)`: the world field is the assumed one plus a drift, exact at `t_ref`.
    FieldDrift {
        /// Drift rate, NED, µT/s.
        rate_ut_per_s: [f64; 3],
        /// Time at which the assumed field is right, s.
        t_ref_s: f64,
    },
    /// `δ = Rᵀ·(F_true − F_assumed)`, `F_true` having the assumed magnitude and the given angle errors.
    FieldDirectionError {
        /// True minus assumed declination, degrees.
        declination_error_deg: f64,
        /// True minus assumed inclination, degrees.
        inclination_error_deg: f64,
    },
    /// `δ_j = k_j·B_j³`.
    Nonlinearity {
        /// Cubic coefficient per calibrated axis, 1/µT².
        cubic_per_ut2: [f64; 3],
    },
    /// `δ = step` for `t ≥ t_s`, zero before.
    BiasStep {
        /// Time of the step, s.
        t_s: f64,
        /// Offset change, µT per calibrated axis.
        step_ut: [f64; 3],
    },
    /// `δ = rate·(t − t_ref)`.
    BiasDrift {
        /// Drift, µT/s per calibrated axis.
        rate_ut_per_s: [f64; 3],
        /// Reference time, s (a shift of it is absorbed by `b`).
        t_ref_s: f64,
    },
    /// `δ = Rᵀ·field_ned` for `t0 ≤ t < t1`, zero outside.
    Disturbance {
        /// Start, s.
        t0_s: f64,
        /// End, s.
        t1_s: f64,
        /// The disturbing field, NED, µT.
        field_ned_ut: [f64; 3],
    },
    /// `δ = offset` for `t0 ≤ t < t1`, zero outside: a field fixed to the sensor for a while.
    BiasWindow {
        /// Start, s.
        t0_s: f64,
        /// End, s.
        t1_s: f64,
        /// The offset, µT per calibrated axis.
        offset_ut: [f64; 3],
    },
    /// `δ = Rᵀ·μ0/(4π)·(3(m·r̂)r̂ − m)/|r|³`: the dipole field of a magnet at `position` with moment `m`, at the
    /// sensor's position (`r` from the magnet to the sensor).
    MagnetNearby {
        /// Where the magnet is, NED, m.
        position_m: [f64; 3],
        /// Its magnetic moment, NED, A·m².
        moment_am2: [f64; 3],
    },
}

/// μ0/(4π) in µT·m³/(A·m²).
const MU0_OVER_4PI_UT: f64 = 0.1;

/// How much the true field differs from the assumed one (NED, µT) when its declination and inclination are off by
/// these angles (degrees), its magnitude the same.
fn field_direction_shift_ned(
    field_ned_ut: [f64; 3],
    declination_error_deg: f64,
    inclination_error_deg: f64,
) -> [f64; 3] {
    let (d, i, m) = frames::field_angles(field_ned_ut);
    let truth = frames::field_from_angles(d + declination_error_deg, i + inclination_error_deg, m);
    frames::sub(truth, field_ned_ut)
}

impl Effect {
    /// The effect's id.
    pub fn id(&self) -> EffectId {
        match self {
            Effect::TemperatureBias { .. } => EffectId::TemperatureBias,
            Effect::TemperatureScale { .. } => EffectId::TemperatureScale,
            Effect::CurrentBias { .. } => EffectId::CurrentBias,
            Effect::TimeLag { .. } => EffectId::TimeLag,
            Effect::RateCoupling { .. } => EffectId::RateCoupling,
            Effect::FieldDrift { .. } => EffectId::FieldDrift,
            Effect::FieldDirectionError { .. } => EffectId::FieldDirectionError,
            Effect::Nonlinearity { .. } => EffectId::Nonlinearity,
            Effect::BiasStep { .. } => EffectId::BiasStep,
            Effect::BiasDrift { .. } => EffectId::BiasDrift,
            Effect::Disturbance { .. } => EffectId::Disturbance,
            Effect::BiasWindow { .. } => EffectId::BiasWindow,
            Effect::MagnetNearby { .. } => EffectId::MagnetNearby,
        }
    }

    /// The world-frame field this effect adds, NED, µT, when it is the same at every sample (a wrong direction of
    /// the assumed field `field_ned_ut`): its perturbation is this rotated into sensor axes. `None` otherwise.
    pub fn constant_world_field_ut(&self, field_ned_ut: [f64; 3]) -> Option<[f64; 3]> {
        match *self {
            Effect::FieldDirectionError {
                declination_error_deg,
                inclination_error_deg,
            } => Some(field_direction_shift_ned(
                field_ned_ut,
                declination_error_deg,
                inclination_error_deg,
            )),
            _ => None,
        }
    }

    /// The perturbation this effect adds at one sample, µT in calibrated sensor axes.
    ///
    /// World-frame effects are zero without an attitude (`ctx.world == None`); effects of a channel that is NaN at
    /// this sample are NaN.
    pub fn perturbation_ut(&self, ctx: &Context<'_>) -> [f64; 3] {
        let b = ctx.field_ut;
        match *self {
            Effect::TemperatureBias {
                coef_ut_per_c,
                t_ref_c,
            } => frames::scale(coef_ut_per_c, ctx.temp_c - t_ref_c),
            Effect::TemperatureScale {
                coef_per_c,
                t_ref_c,
            } => {
                let dt = ctx.temp_c - t_ref_c;
                [
                    coef_per_c[0] * dt * b[0],
                    coef_per_c[1] * dt * b[1],
                    coef_per_c[2] * dt * b[2],
                ]
            }
            Effect::CurrentBias {
                channel,
                coef_ut_per_a,
            } => {
                let i = ctx.currents_a.get(channel).copied().unwrap_or(f64::NAN);
                frames::scale(coef_ut_per_a, i)
            }
            Effect::TimeLag { lag_s } => frames::scale(ctx.field_rate_ut_per_s, -lag_s),
            Effect::RateCoupling { lag_axis_s } => {
                let r = ctx.field_rate_ut_per_s;
                [
                    -lag_axis_s[0] * r[0],
                    -lag_axis_s[1] * r[1],
                    -lag_axis_s[2] * r[2],
                ]
            }
            Effect::FieldDrift {
                rate_ut_per_s,
                t_ref_s,
            } => match ctx.world {
                Some(w) => frames::mat_t_vec(
                    &w.sensor_to_ned,
                    frames::scale(rate_ut_per_s, ctx.t_s - t_ref_s),
                ),
                None => [0.0; 3],
            },
            Effect::FieldDirectionError {
                declination_error_deg,
                inclination_error_deg,
            } => match ctx.world {
                Some(w) => frames::mat_t_vec(
                    &w.sensor_to_ned,
                    field_direction_shift_ned(
                        w.field_ned_ut,
                        declination_error_deg,
                        inclination_error_deg,
                    ),
                ),
                None => [0.0; 3],
            },
            Effect::Nonlinearity { cubic_per_ut2 } => [
                cubic_per_ut2[0] * b[0] * b[0] * b[0],
                cubic_per_ut2[1] * b[1] * b[1] * b[1],
                cubic_per_ut2[2] * b[2] * b[2] * b[2],
            ],
            Effect::BiasStep { t_s, step_ut } => {
                if ctx.t_s >= t_s {
                    step_ut
                } else {
                    [0.0; 3]
                }
            }
            Effect::BiasDrift {
                rate_ut_per_s,
                t_ref_s,
            } => frames::scale(rate_ut_per_s, ctx.t_s - t_ref_s),
            Effect::Disturbance {
                t0_s,
                t1_s,
                field_ned_ut,
            } => match ctx.world {
                Some(w) if ctx.t_s >= t0_s && ctx.t_s < t1_s => {
                    frames::mat_t_vec(&w.sensor_to_ned, field_ned_ut)
                }
                _ => [0.0; 3],
            },
            Effect::BiasWindow {
                t0_s,
                t1_s,
                offset_ut,
            } => {
                if ctx.t_s >= t0_s && ctx.t_s < t1_s {
                    offset_ut
                } else {
                    [0.0; 3]
                }
            }
            Effect::MagnetNearby {
                position_m,
                moment_am2,
            } => match ctx.world {
                Some(w) => {
                    let r = frames::sub(w.position_m, position_m);
                    let d = frames::norm(r);
                    if d > 0.0 {
                        let u = frames::scale(r, 1.0 / d);
                        let radial = frames::scale(u, 3.0 * frames::dot(moment_am2, u));
                        let field = frames::scale(
                            frames::sub(radial, moment_am2),
                            MU0_OVER_4PI_UT / (d * d * d),
                        );
                        frames::mat_t_vec(&w.sensor_to_ned, field)
                    } else {
                        [f64::NAN; 3]
                    }
                }
                None => [0.0; 3],
            },
        }
    }

    /// Whether the perturbation is linear in [`Effect::params`] (all but the field direction error).
    pub fn is_linear(&self) -> bool {
        !matches!(self, Effect::FieldDirectionError { .. })
    }

    /// The fitted parameters (the rest — reference temperature or time, channel, step time, window — are fixed while
    /// fitting) and how many of the array's entries are used: a vector's three, or the numbers in order.
    pub fn params(&self) -> ([f64; 3], usize) {
        let (mut p, mut n) = ([0.0; 3], 0);
        for (spec, v) in self.values() {
            match (spec.role, v) {
                (Role::Fitted, Value::Vector(x)) => (p, n) = (x, 3),
                (Role::Fitted, Value::Number(x)) => {
                    p[n] = x;
                    n += 1;
                }
                _ => {}
            }
        }
        (p, n)
    }

    /// The same effect with other fitted parameters (the first `params().1` entries of `p` are used).
    pub fn with_params(&self, p: [f64; 3]) -> Effect {
        let mut values = [Value::Number(0.0); 3];
        let mut used = 0;
        for (k, (spec, v)) in self.values().enumerate() {
            values[k] = match (spec.role, v) {
                (Role::Fitted, Value::Vector(_)) => Value::Vector(p),
                (Role::Fitted, Value::Number(_)) => {
                    used += 1;
                    Value::Number(p[used - 1])
                }
                (_, v) => v,
            };
        }
        let count = self.id().descriptor().params.len();
        Effect::from_values(self.id(), &values[..count]).expect("an effect's own values fit it")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ctx<'a>(currents: &'a [f64], world: Option<WorldContext>) -> Context<'a> {
        Context {
            t_s: 10.0,
            temp_c: 30.0,
            currents_a: currents,
            field_ut: [20.0, -10.0, 40.0],
            field_rate_ut_per_s: [1.0, 2.0, -3.0],
            world,
        }
    }

    #[test]
    fn ids_round_trip() {
        for id in EffectId::ALL {
            assert_eq!(EffectId::parse(id.as_str()), Some(id));
        }
        assert_eq!(EffectId::parse("magic"), None);
    }

    #[test]
    fn linear_effects_are_linear_in_their_params() {
        let world = WorldContext {
            sensor_to_ned: frames::quat_to_matrix(
                [0.9, 0.1, -0.3, 0.2].map(|x| x / 0.9899494936611666),
            ),
            field_ned_ut: [20.0, 1.0, 45.0],
            position_m: [0.3, -0.1, 0.2],
        };
        let currents = [0.7];
        let c = ctx(&currents, Some(world));
        let effects = [
            Effect::TemperatureBias {
                coef_ut_per_c: [0.0; 3],
                t_ref_c: 25.0,
            },
            Effect::TemperatureScale {
                coef_per_c: [0.0; 3],
                t_ref_c: 25.0,
            },
            Effect::CurrentBias {
                channel: 0,
                coef_ut_per_a: [0.0; 3],
            },
            Effect::TimeLag { lag_s: 0.0 },
            Effect::RateCoupling {
                lag_axis_s: [0.0; 3],
            },
            Effect::FieldDrift {
                rate_ut_per_s: [0.0; 3],
                t_ref_s: 2.0,
            },
            Effect::Nonlinearity {
                cubic_per_ut2: [0.0; 3],
            },
            Effect::BiasStep {
                t_s: 5.0,
                step_ut: [0.0; 3],
            },
            Effect::BiasDrift {
                rate_ut_per_s: [0.0; 3],
                t_ref_s: 0.0,
            },
            Effect::Disturbance {
                t0_s: 9.0,
                t1_s: 11.0,
                field_ned_ut: [0.0; 3],
            },
            Effect::BiasWindow {
                t0_s: 9.0,
                t1_s: 11.0,
                offset_ut: [0.0; 3],
            },
            Effect::MagnetNearby {
                position_m: [0.0, 0.1, 0.0],
                moment_am2: [0.0; 3],
            },
        ];
        for e in effects {
            assert!(e.is_linear());
            let p1 = [0.3, -0.2, 0.5];
            let p2 = [-0.1, 0.4, 0.25];
            let sum = [p1[0] + p2[0], p1[1] + p2[1], p1[2] + p2[2]];
            let d1 = e.with_params(p1).perturbation_ut(&c);
            let d2 = e.with_params(p2).perturbation_ut(&c);
            let d12 = e.with_params(sum).perturbation_ut(&c);
            for k in 0..3 {
                assert!((d1[k] + d2[k] - d12[k]).abs() < 1e-9, "{:?}", e.id());
            }
            assert_ne!(d1, [0.0; 3], "{:?} has no effect here", e.id());
        }
    }

    #[test]
    fn time_lag_reads_the_earlier_field() {
        let e = Effect::TimeLag { lag_s: 0.01 };
        let d = e.perturbation_ut(&ctx(&[], None));
        assert_eq!(d, [-0.01, -0.02, 0.03]);
    }

    #[test]
    fn declination_error_rotates_the_horizontal_field() {
        let world = WorldContext {
            sensor_to_ned: frames::IDENTITY,
            field_ned_ut: [20.0, 0.0, 40.0],
            position_m: [0.0; 3],
        };
        let e = Effect::FieldDirectionError {
            declination_error_deg: 90.0,
            inclination_error_deg: 0.0,
        };
        let d = e.perturbation_ut(&ctx(&[], Some(world)));
        // The true field points east: δ = (0, 20, 40) − (20, 0, 40).
        assert!((d[0] + 20.0).abs() < 1e-9 && (d[1] - 20.0).abs() < 1e-9 && d[2].abs() < 1e-9);
    }

    #[test]
    fn world_effects_need_an_attitude_and_channels_propagate_nan() {
        let drift = Effect::FieldDrift {
            rate_ut_per_s: [1.0; 3],
            t_ref_s: 0.0,
        };
        assert_eq!(drift.perturbation_ut(&ctx(&[], None)), [0.0; 3]);
        let current = Effect::CurrentBias {
            channel: 0,
            coef_ut_per_a: [1.0; 3],
        };
        assert!(current.perturbation_ut(&ctx(&[], None))[0].is_nan());
    }

    #[test]
    fn a_magnet_nearby_is_a_dipole_falling_with_the_cube_of_distance() {
        let at = |x: f64| {
            let world = WorldContext {
                sensor_to_ned: frames::IDENTITY,
                field_ned_ut: [20.0, 0.0, 40.0],
                position_m: [x, 0.0, 0.0],
            };
            Effect::MagnetNearby {
                position_m: [0.0; 3],
                moment_am2: [1.0, 0.0, 0.0],
            }
            .perturbation_ut(&ctx(&[], Some(world)))
        };
        // On the moment's axis: 2·μ0/(4π)·m/r³ = 0.2 µT·m³ / r³.
        let near = at(0.1);
        assert!(
            (near[0] - 200.0).abs() < 1e-9 && near[1].abs() < 1e-12,
            "{near:?}"
        );
        assert!((at(0.2)[0] - 25.0).abs() < 1e-9);
    }
}
