//! One descriptor per effect ([`Descriptor`]): its id, where it lives, the channels it needs, its parameters with
//! their units and how each is known, and what it means when the recording does not excite it. Reports, parameter
//! files, command lines and the diagnosis' figures iterate over the descriptors instead of matching on each effect;
//! an effect's values are read and made in the descriptor's order ([`Effect::value`], [`Effect::from_values`]).

use super::{Effect, EffectId, Frame};

/// How a parameter is known.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Role {
    /// Fitted: the regression estimates it, with a standard error.
    Fitted,
    /// Fixed while fitting: set from the recording (a reference temperature or time) or given (where a magnet is).
    Fixed,
    /// A time located by a scan before fitting (a step, a window's start, then its end): its uncertainty is the
    /// scan's.
    Scanned,
    /// The current channel the effect follows: a name in files and on command lines, an index in a model.
    Channel,
}

/// What a parameter holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Shape {
    /// One number.
    Number,
    /// Three numbers (per calibrated axis, or north, east, down).
    Vector,
    /// A current channel.
    Channel,
}

/// What a parameter is when a command line leaves it out.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WhenOmitted {
    /// It must be given.
    Required,
    /// Zero.
    Zero,
    /// The scenario's reference temperature.
    ReferenceTemperature,
    /// The scenario's time at which a drifting field is the assumed one.
    FieldDriftTime,
    /// The scenario's first current channel.
    FirstChannel,
}

/// A parameter of an effect, named as reports, parameter files and command lines name it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ParamSpec {
    /// The name, with its unit in it (`coef_ut_per_c`).
    pub name: &'static str,
    /// The unit, in words for people (`µT/°C`).
    pub unit: &'static str,
    /// How it is known.
    pub role: Role,
    /// What it holds.
    pub shape: Shape,
    /// What it is when a command line leaves it out.
    pub default: WhenOmitted,
}

/// A channel of the recording an effect needs to be observed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Need {
    /// A temperature column.
    Temperature,
    /// An `i_<name>` current column.
    Current,
    /// A time column.
    Time,
    /// An attitude reference (the vector method).
    Reference,
    /// The attitude itself, to tell the world's frame from the sensor's.
    Attitude,
}

/// Everything the catalogue knows of one effect but its perturbation ([`Effect::perturbation_ut`]) and its wording
/// with numbers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Descriptor {
    /// The effect.
    pub id: EffectId,
    /// Its id in reports and parameter files.
    pub name: &'static str,
    /// Where it lives.
    pub frame: Frame,
    /// An event of one recording rather than a property of the sensor or the bench: never a correction for others.
    pub transient: bool,
    /// Its parameters, in the order reports and command lines give them.
    pub params: &'static [ParamSpec],
    /// The channels it needs.
    pub needs: &'static [Need],
    /// What it is, in a few words.
    pub summary: &'static str,
    /// Why a recording that has the channels may still not excite it.
    pub not_excited: &'static str,
}

/// A parameter's value.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Value {
    /// One number.
    Number(f64),
    /// Three numbers.
    Vector([f64; 3]),
    /// A current channel, by its index among the recording's.
    Channel(usize),
}

const fn p(name: &'static str, unit: &'static str, role: Role, shape: Shape) -> ParamSpec {
    ParamSpec {
        name,
        unit,
        role,
        shape,
        default: WhenOmitted::Required,
    }
}

const fn with_default(spec: ParamSpec, default: WhenOmitted) -> ParamSpec {
    ParamSpec { default, ..spec }
}

/// The signature of an effect is zero throughout the recording.
const ZERO_SIGNATURE: &str = "its signature is zero throughout this recording";
/// The temperature did not change.
const STEADY_TEMPERATURE: &str = "the temperature did not change during the recording";
/// Static poses only.
const STATIC_POSES: &str =
    "the attitude did not change while samples were taken (static poses only)";

/// The catalogue, in [`EffectId::ALL`]'s order.
pub const CATALOGUE: [Descriptor; 13] = [
    Descriptor {
        id: EffectId::TemperatureBias,
        name: "temperature_bias",
        frame: Frame::Body,
        transient: false,
        params: &[
            p("coef_ut_per_c", "µT/°C", Role::Fitted, Shape::Vector),
            with_default(
                p("t_ref_c", "°C", Role::Fixed, Shape::Number),
                WhenOmitted::ReferenceTemperature,
            ),
        ],
        needs: &[Need::Temperature],
        summary: "offset (hard iron) changing with temperature",
        not_excited: STEADY_TEMPERATURE,
    },
    Descriptor {
        id: EffectId::TemperatureScale,
        name: "temperature_scale",
        frame: Frame::Body,
        transient: false,
        params: &[
            p("coef_per_c", "1/°C", Role::Fitted, Shape::Vector),
            with_default(
                p("t_ref_c", "°C", Role::Fixed, Shape::Number),
                WhenOmitted::ReferenceTemperature,
            ),
        ],
        needs: &[Need::Temperature],
        summary: "scale factors changing with temperature",
        not_excited: STEADY_TEMPERATURE,
    },
    Descriptor {
        id: EffectId::CurrentBias,
        name: "current_bias",
        frame: Frame::Body,
        transient: false,
        params: &[
            with_default(
                p("channel", "", Role::Channel, Shape::Channel),
                WhenOmitted::FirstChannel,
            ),
            p("coef_ut_per_a", "µT/A", Role::Fitted, Shape::Vector),
        ],
        needs: &[Need::Current],
        summary: "the field of a current recorded in an i_<name> channel",
        not_excited: "the current did not change during the recording",
    },
    Descriptor {
        id: EffectId::TimeLag,
        name: "time_lag",
        frame: Frame::Timing,
        transient: false,
        params: &[p("lag_s", "s", Role::Fitted, Shape::Number)],
        needs: &[Need::Reference, Need::Time],
        summary: "the magnetometer sample late relative to the attitude reference (one delay for all axes)",
        not_excited: STATIC_POSES,
    },
    Descriptor {
        id: EffectId::RateCoupling,
        name: "rate_coupling",
        frame: Frame::Timing,
        transient: false,
        params: &[p("lag_axis_s", "s", Role::Fitted, Shape::Vector)],
        needs: &[Need::Reference, Need::Time],
        summary: "each axis following the field's rate of change with its own delay (filters, eddy currents)",
        not_excited: STATIC_POSES,
    },
    Descriptor {
        id: EffectId::FieldDrift,
        name: "field_drift",
        frame: Frame::World,
        transient: false,
        params: &[
            p("rate_ut_per_s", "µT/s (NED)", Role::Fitted, Shape::Vector),
            with_default(
                p("t_ref_s", "s", Role::Fixed, Shape::Number),
                WhenOmitted::FieldDriftTime,
            ),
        ],
        needs: &[Need::Attitude, Need::Time],
        summary: "the world field changing during the recording",
        not_excited: ZERO_SIGNATURE,
    },
    Descriptor {
        id: EffectId::FieldDirectionError,
        name: "field_direction_error",
        frame: Frame::World,
        transient: false,
        params: &[
            with_default(
                p("declination_error_deg", "°", Role::Fitted, Shape::Number),
                WhenOmitted::Zero,
            ),
            with_default(
                p("inclination_error_deg", "°", Role::Fitted, Shape::Number),
                WhenOmitted::Zero,
            ),
        ],
        needs: &[Need::Attitude],
        summary: "the true field pointing elsewhere than the assumed one",
        not_excited: ZERO_SIGNATURE,
    },
    Descriptor {
        id: EffectId::Nonlinearity,
        name: "nonlinearity",
        frame: Frame::Body,
        transient: false,
        params: &[p("cubic_per_ut2", "1/µT²", Role::Fitted, Shape::Vector)],
        needs: &[],
        summary: "a response not linear in the field (a cubic per axis)",
        not_excited: ZERO_SIGNATURE,
    },
    Descriptor {
        id: EffectId::BiasStep,
        name: "bias_step",
        frame: Frame::Body,
        transient: false,
        params: &[
            p("t_s", "s", Role::Scanned, Shape::Number),
            p("step_ut", "µT", Role::Fitted, Shape::Vector),
        ],
        needs: &[Need::Time],
        summary: "a sudden change of the offset",
        not_excited: ZERO_SIGNATURE,
    },
    Descriptor {
        id: EffectId::BiasDrift,
        name: "bias_drift",
        frame: Frame::Body,
        transient: false,
        params: &[
            p("rate_ut_per_s", "µT/s", Role::Fitted, Shape::Vector),
            with_default(
                p("t_ref_s", "s", Role::Fixed, Shape::Number),
                WhenOmitted::Zero,
            ),
        ],
        needs: &[Need::Time],
        summary: "the offset drifting with time",
        not_excited: ZERO_SIGNATURE,
    },
    Descriptor {
        id: EffectId::Disturbance,
        name: "disturbance",
        frame: Frame::World,
        transient: true,
        params: &[
            p("t0_s", "s", Role::Scanned, Shape::Number),
            p("t1_s", "s", Role::Scanned, Shape::Number),
            p("field_ned_ut", "µT (NED)", Role::Fitted, Shape::Vector),
        ],
        needs: &[Need::Attitude, Need::Time],
        summary: "a transient external field fixed in the world",
        not_excited: ZERO_SIGNATURE,
    },
    Descriptor {
        id: EffectId::BiasWindow,
        name: "bias_window",
        frame: Frame::Body,
        transient: true,
        params: &[
            p("t0_s", "s", Role::Scanned, Shape::Number),
            p("t1_s", "s", Role::Scanned, Shape::Number),
            p("offset_ut", "µT", Role::Fitted, Shape::Vector),
        ],
        needs: &[Need::Time],
        summary: "a transient offset fixed to the sensor (something magnetic attached to the board for a while)",
        not_excited: ZERO_SIGNATURE,
    },
    Descriptor {
        id: EffectId::MagnetNearby,
        name: "magnet_nearby",
        frame: Frame::World,
        transient: true,
        params: &[
            p("position_m", "m (NED)", Role::Fixed, Shape::Vector),
            p("moment_am2", "A·m² (NED)", Role::Fitted, Shape::Vector),
        ],
        needs: &[Need::Attitude],
        summary: "a magnet fixed in the room: its field depends on where the sensor is",
        not_excited: ZERO_SIGNATURE,
    },
];

impl EffectId {
    /// The effect's descriptor.
    pub fn descriptor(self) -> &'static Descriptor {
        &CATALOGUE[self as usize]
    }
}

impl Effect {
    /// Its `k`-th parameter in its descriptor's order.
    ///
    /// # Panics
    /// When the effect has no such parameter.
    pub fn value(&self, k: usize) -> Value {
        use Value::{Channel, Number, Vector};
        match (*self, k) {
            (Effect::TemperatureBias { coef_ut_per_c, .. }, 0) => Vector(coef_ut_per_c),
            (Effect::TemperatureBias { t_ref_c, .. }, 1) => Number(t_ref_c),
            (Effect::TemperatureScale { coef_per_c, .. }, 0) => Vector(coef_per_c),
            (Effect::TemperatureScale { t_ref_c, .. }, 1) => Number(t_ref_c),
            (Effect::CurrentBias { channel, .. }, 0) => Channel(channel),
            (Effect::CurrentBias { coef_ut_per_a, .. }, 1) => Vector(coef_ut_per_a),
            (Effect::TimeLag { lag_s }, 0) => Number(lag_s),
            (Effect::RateCoupling { lag_axis_s }, 0) => Vector(lag_axis_s),
            (Effect::FieldDrift { rate_ut_per_s, .. }, 0) => Vector(rate_ut_per_s),
            (Effect::FieldDrift { t_ref_s, .. }, 1) => Number(t_ref_s),
            (
                Effect::FieldDirectionError {
                    declination_error_deg,
                    ..
                },
                0,
            ) => Number(declination_error_deg),
            (
                Effect::FieldDirectionError {
                    inclination_error_deg,
                    ..
                },
                1,
            ) => Number(inclination_error_deg),
            (Effect::Nonlinearity { cubic_per_ut2 }, 0) => Vector(cubic_per_ut2),
            (Effect::BiasStep { t_s, .. }, 0) => Number(t_s),
            (Effect::BiasStep { step_ut, .. }, 1) => Vector(step_ut),
            (Effect::BiasDrift { rate_ut_per_s, .. }, 0) => Vector(rate_ut_per_s),
            (Effect::BiasDrift { t_ref_s, .. }, 1) => Number(t_ref_s),
            (Effect::Disturbance { t0_s, .. }, 0) | (Effect::BiasWindow { t0_s, .. }, 0) => {
                Number(t0_s)
            }
            (Effect::Disturbance { t1_s, .. }, 1) | (Effect::BiasWindow { t1_s, .. }, 1) => {
                Number(t1_s)
            }
            (Effect::Disturbance { field_ned_ut, .. }, 2) => Vector(field_ned_ut),
            (Effect::BiasWindow { offset_ut, .. }, 2) => Vector(offset_ut),
            (Effect::MagnetNearby { position_m, .. }, 0) => Vector(position_m),
            (Effect::MagnetNearby { moment_am2, .. }, 1) => Vector(moment_am2),
            (e, k) => panic!("{} has no parameter {k}", e.id()),
        }
    }

    /// The effect `id` with these parameter values, in its descriptor's order; `None` when they are not its
    /// parameters' number and shapes.
    pub fn from_values(id: EffectId, values: &[Value]) -> Option<Effect> {
        use Value::{Channel as C, Number as N, Vector as V};
        Some(match (id, values) {
            (EffectId::TemperatureBias, &[V(coef_ut_per_c), N(t_ref_c)]) => {
                Effect::TemperatureBias {
                    coef_ut_per_c,
                    t_ref_c,
                }
            }
            (EffectId::TemperatureScale, &[V(coef_per_c), N(t_ref_c)]) => {
                Effect::TemperatureScale {
                    coef_per_c,
                    t_ref_c,
                }
            }
            (EffectId::CurrentBias, &[C(channel), V(coef_ut_per_a)]) => Effect::CurrentBias {
                channel,
                coef_ut_per_a,
            },
            (EffectId::TimeLag, &[N(lag_s)]) => Effect::TimeLag { lag_s },
            (EffectId::RateCoupling, &[V(lag_axis_s)]) => Effect::RateCoupling { lag_axis_s },
            (EffectId::FieldDrift, &[V(rate_ut_per_s), N(t_ref_s)]) => Effect::FieldDrift {
                rate_ut_per_s,
                t_ref_s,
            },
            (
                EffectId::FieldDirectionError,
                &[N(declination_error_deg), N(inclination_error_deg)],
            ) => Effect::FieldDirectionError {
                declination_error_deg,
                inclination_error_deg,
            },
            (EffectId::Nonlinearity, &[V(cubic_per_ut2)]) => Effect::Nonlinearity { cubic_per_ut2 },
            (EffectId::BiasStep, &[N(t_s), V(step_ut)]) => Effect::BiasStep { t_s, step_ut },
            (EffectId::BiasDrift, &[V(rate_ut_per_s), N(t_ref_s)]) => Effect::BiasDrift {
                rate_ut_per_s,
                t_ref_s,
            },
            (EffectId::Disturbance, &[N(t0_s), N(t1_s), V(field_ned_ut)]) => Effect::Disturbance {
                t0_s,
                t1_s,
                field_ned_ut,
            },
            (EffectId::BiasWindow, &[N(t0_s), N(t1_s), V(offset_ut)]) => Effect::BiasWindow {
                t0_s,
                t1_s,
                offset_ut,
            },
            (EffectId::MagnetNearby, &[V(position_m), V(moment_am2)]) => Effect::MagnetNearby {
                position_m,
                moment_am2,
            },
            _ => return None,
        })
    }

    /// Its parameters with their specs, in its descriptor's order.
    pub fn values(&self) -> impl Iterator<Item = (&'static ParamSpec, Value)> + '_ {
        self.id()
            .descriptor()
            .params
            .iter()
            .enumerate()
            .map(|(k, spec)| (spec, self.value(k)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One effect of each kind, with every parameter non-zero and distinct.
    fn one_of_each() -> [Effect; 13] {
        [
            Effect::TemperatureBias {
                coef_ut_per_c: [0.1, -0.2, 0.3],
                t_ref_c: 21.5,
            },
            Effect::TemperatureScale {
                coef_per_c: [1e-4, 2e-4, -2e-4],
                t_ref_c: 20.0,
            },
            Effect::CurrentBias {
                channel: 2,
                coef_ut_per_a: [0.5, 0.25, 0.125],
            },
            Effect::TimeLag { lag_s: -0.0125 },
            Effect::RateCoupling {
                lag_axis_s: [0.01, 0.02, 0.002],
            },
            Effect::FieldDrift {
                rate_ut_per_s: [1e-3, 3e-3, -2e-3],
                t_ref_s: 45.0,
            },
            Effect::FieldDirectionError {
                declination_error_deg: 0.3,
                inclination_error_deg: -0.1,
            },
            Effect::Nonlinearity {
                cubic_per_ut2: [1e-6, 2e-6, 3e-6],
            },
            Effect::BiasStep {
                t_s: 33.3,
                step_ut: [0.1, 0.2, 0.3],
            },
            Effect::BiasDrift {
                rate_ut_per_s: [4e-3, 1e-3, 2e-3],
                t_ref_s: 7.0,
            },
            Effect::Disturbance {
                t0_s: 10.0,
                t1_s: 20.0,
                field_ned_ut: [0.7, 0.5, 0.6],
            },
            Effect::BiasWindow {
                t0_s: 11.0,
                t1_s: 21.0,
                offset_ut: [1.0, 2.0, 3.0],
            },
            Effect::MagnetNearby {
                position_m: [0.1, 0.2, 0.3],
                moment_am2: [0.4, 0.5, 0.6],
            },
        ]
    }

    #[test]
    fn the_catalogue_is_in_the_order_of_the_ids_with_unique_names() {
        for (k, id) in EffectId::ALL.into_iter().enumerate() {
            assert_eq!(CATALOGUE[k].id, id);
            assert_eq!(id.descriptor().id, id);
            assert_eq!(EffectId::parse(id.descriptor().name), Some(id));
            let names: Vec<&str> = id.descriptor().params.iter().map(|p| p.name).collect();
            for (j, n) in names.iter().enumerate() {
                assert!(!names[j + 1..].contains(n), "{id}: {n} twice");
            }
        }
    }

    #[test]
    fn values_follow_the_descriptor_and_make_the_effect_again() {
        for e in one_of_each() {
            let d = e.id().descriptor();
            let values: Vec<Value> = e.values().map(|(_, v)| v).collect();
            assert_eq!(values.len(), d.params.len(), "{}", e.id());
            for (spec, v) in e.values() {
                let shape = match v {
                    Value::Number(_) => Shape::Number,
                    Value::Vector(_) => Shape::Vector,
                    Value::Channel(_) => Shape::Channel,
                };
                assert_eq!(shape, spec.shape, "{}: {}", e.id(), spec.name);
            }
            assert_eq!(Effect::from_values(e.id(), &values), Some(e));
            // Another effect's values are not this one's.
            assert_eq!(
                Effect::from_values(e.id(), &values[1..]),
                None,
                "{}",
                e.id()
            );
        }
    }

    #[test]
    fn the_fitted_parameters_are_those_the_descriptor_marks_fitted() {
        for e in one_of_each() {
            let (p, n) = e.params();
            let fitted: usize = e
                .values()
                .filter(|(s, _)| s.role == Role::Fitted)
                .map(|(_, v)| match v {
                    Value::Vector(_) => 3,
                    _ => 1,
                })
                .sum();
            assert_eq!(n, fitted, "{}", e.id());
            // Putting them back gives the effect; other values change only them.
            assert_eq!(e.with_params(p), e);
            let moved = e.with_params(p.map(|x| 2.0 * x + 1.0));
            for ((spec, before), (_, after)) in e.values().zip(moved.values()) {
                assert_eq!(
                    spec.role == Role::Fitted,
                    before != after,
                    "{}: {}",
                    e.id(),
                    spec.name
                );
            }
        }
    }

    #[test]
    fn corrections_are_the_body_fixed_properties_of_the_sensor() {
        let corrections: Vec<&str> = EffectId::ALL
            .into_iter()
            .filter(|id| id.is_correction())
            .map(EffectId::as_str)
            .collect();
        assert_eq!(
            corrections,
            [
                "temperature_bias",
                "temperature_scale",
                "current_bias",
                "nonlinearity",
                "bias_step",
                "bias_drift"
            ]
        );
    }
}
