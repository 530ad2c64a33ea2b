//! Effects written on a command line (`magcal-sim --effect …`), with the parameter names of the report:
//! `id:name=value[,value,value][;name=value…]`, e.g. `temperature_bias:coef_ut_per_c=0.05,0,0;t_ref_c=25` or
//! `current_bias:channel=i_motor;coef_ut_per_a=0.3,0,0`.

use magcal_calib::effects::{Effect, EffectId, ParamSpec, Shape, Value, WhenOmitted};

/// An effect spec that cannot be used.
#[derive(Debug, thiserror::Error, PartialEq)]
#[error("effect {spec:?}: {why}")]
pub struct EffectSpecError {
    spec: String,
    why: String,
}

/// What an effect spec may leave out, taken from the scenario.
pub struct Defaults<'a> {
    /// Reference temperature, °C.
    pub t_ref_c: f64,
    /// Reference time of a field drift (the assumed field is right then), s.
    pub field_drift_t_ref_s: f64,
    /// The scenario's current channels, by column name.
    pub currents: &'a [String],
}

/// Parses one effect spec: every parameter its descriptor lists, in order, from the spec or its default.
pub fn parse(spec: &str, defaults: &Defaults<'_>) -> Result<Effect, EffectSpecError> {
    let err = |why: String| EffectSpecError {
        spec: spec.to_owned(),
        why,
    };
    let (id, rest) = spec.split_once(':').unwrap_or((spec, ""));
    let id = EffectId::parse(id.trim()).ok_or_else(|| {
        let known: Vec<&str> = EffectId::ALL.iter().map(|i| i.as_str()).collect();
        err(format!(
            "unknown effect {id:?}; known: {}",
            known.join(", ")
        ))
    })?;
    let mut values: Vec<(&str, &str)> = Vec::new();
    for part in rest.split(';').map(str::trim).filter(|p| !p.is_empty()) {
        let (name, value) = part
            .split_once('=')
            .ok_or_else(|| err(format!("{part:?} is not name=value")))?;
        values.push((name.trim(), value.trim()));
    }
    let params = id.descriptor().params;
    if let Some((name, _)) = values
        .iter()
        .find(|(n, _)| !params.iter().any(|p| p.name == *n))
    {
        let allowed: Vec<&str> = params.iter().map(|p| p.name).collect();
        return Err(err(format!(
            "{id} has no parameter {name:?}; it takes {}",
            allowed.join(", ")
        )));
    }
    let get = |name: &str| values.iter().find(|(n, _)| *n == name).map(|(_, v)| *v);
    let parsed = params
        .iter()
        .map(|p| value(p, get(p.name), defaults).map_err(err))
        .collect::<Result<Vec<Value>, _>>()?;
    Ok(Effect::from_values(id, &parsed).expect("the values follow the descriptor"))
}

/// A parameter's value from its text in a spec (`None`: left out, then its default).
fn value(p: &ParamSpec, text: Option<&str>, defaults: &Defaults<'_>) -> Result<Value, String> {
    let name = p.name;
    match p.shape {
        Shape::Channel => {
            let channel = text
                .or(defaults.currents.first().map(String::as_str))
                .ok_or(
                    "needs a current channel: add --current NAME:ON_A,MEAN_ON_S,MEAN_OFF_S"
                        .to_owned(),
                )?;
            defaults
                .currents
                .iter()
                .position(|c| c == channel)
                .map(Value::Channel)
                .ok_or_else(|| {
                    format!(
                        "no current channel {channel:?} (have {:?})",
                        defaults.currents
                    )
                })
        }
        Shape::Vector => {
            let v = text.ok_or_else(|| format!("{name} is required (three numbers)"))?;
            let parts: Vec<f64> = v
                .split(',')
                .map(|x| x.trim().parse::<f64>())
                .collect::<Result<_, _>>()
                .map_err(|_| format!("{name}: {v:?} is not three numbers"))?;
            let parts: [f64; 3] = parts
                .try_into()
                .map_err(|_| format!("{name}: {v:?} is not three numbers"))?;
            Ok(Value::Vector(parts))
        }
        Shape::Number => {
            let default = match p.default {
                WhenOmitted::Required | WhenOmitted::FirstChannel => None,
                WhenOmitted::Zero => Some(0.0),
                WhenOmitted::ReferenceTemperature => Some(defaults.t_ref_c),
                WhenOmitted::FieldDriftTime => Some(defaults.field_drift_t_ref_s),
            };
            match text {
                Some(v) => v
                    .parse()
                    .map(Value::Number)
                    .map_err(|_| format!("{name}: {v:?} is not a number")),
                None => default
                    .map(Value::Number)
                    .ok_or_else(|| format!("{name} is required")),
            }
        }
    }
}

/// Writes an effect as a spec that [`parse`] reads back (`currents` names the channels).
pub fn format(e: &Effect, currents: &[String]) -> String {
    let params: Vec<String> = e
        .values()
        .map(|(spec, value)| {
            let value = match value {
                Value::Number(x) => format!("{x}"),
                Value::Vector(x) => format!("{},{},{}", x[0], x[1], x[2]),
                Value::Channel(c) => currents.get(c).map_or("?", String::as_str).to_owned(),
            };
            format!("{}={value}", spec.name)
        })
        .collect();
    format!("{}:{}", e.id(), params.join(";"))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn defaults() -> Defaults<'static> {
        static CURRENTS: [String; 0] = [];
        Defaults {
            t_ref_c: 25.0,
            field_drift_t_ref_s: 60.0,
            currents: &CURRENTS,
        }
    }

    #[test]
    fn parses_report_names_with_defaults() {
        assert_eq!(
            parse("temperature_bias:coef_ut_per_c=0.05,0,-0.1", &defaults()),
            Ok(Effect::TemperatureBias {
                coef_ut_per_c: [0.05, 0.0, -0.1],
                t_ref_c: 25.0
            })
        );
        assert_eq!(
            parse("time_lag:lag_s=0.012", &defaults()),
            Ok(Effect::TimeLag { lag_s: 0.012 })
        );
        let currents = ["i_led".to_owned(), "i_motor".to_owned()];
        let d = Defaults {
            currents: &currents,
            ..defaults()
        };
        assert_eq!(
            parse("current_bias:channel=i_motor;coef_ut_per_a=1,2,3", &d),
            Ok(Effect::CurrentBias {
                channel: 1,
                coef_ut_per_a: [1.0, 2.0, 3.0]
            })
        );
    }

    #[test]
    fn every_effect_round_trips_through_its_spec() {
        let currents = ["i_motor".to_owned()];
        let d = Defaults {
            currents: &currents,
            ..defaults()
        };
        let effects = [
            Effect::TemperatureBias {
                coef_ut_per_c: [0.1, -0.2, 0.3],
                t_ref_c: 21.5,
            },
            Effect::TemperatureScale {
                coef_per_c: [1e-4, 0.0, -2e-4],
                t_ref_c: 20.0,
            },
            Effect::CurrentBias {
                channel: 0,
                coef_ut_per_a: [0.5, 0.25, 0.0],
            },
            Effect::TimeLag { lag_s: -0.0125 },
            Effect::RateCoupling {
                lag_axis_s: [0.01, 0.0, 0.002],
            },
            Effect::FieldDrift {
                rate_ut_per_s: [1e-3, 0.0, -2e-3],
                t_ref_s: 45.0,
            },
            Effect::FieldDirectionError {
                declination_error_deg: 0.3,
                inclination_error_deg: -0.1,
            },
            Effect::Nonlinearity {
                cubic_per_ut2: [1e-6, 0.0, 0.0],
            },
            Effect::BiasStep {
                t_s: 33.3,
                step_ut: [0.1, 0.0, 0.0],
            },
            Effect::BiasDrift {
                rate_ut_per_s: [0.0, 1e-3, 0.0],
                t_ref_s: 0.0,
            },
            Effect::Disturbance {
                t0_s: 10.0,
                t1_s: 20.0,
                field_ned_ut: [0.0, 0.5, 0.0],
            },
        ];
        for e in effects {
            assert_eq!(parse(&format(&e, &currents), &d), Ok(e));
        }
    }

    #[test]
    fn says_what_is_wrong() {
        let e = |s: &str| parse(s, &defaults()).unwrap_err().to_string();
        assert!(e("magnet:x=1").contains("unknown effect"));
        assert!(e("time_lag:lag=1").contains("takes lag_s"));
        assert!(e("time_lag").contains("lag_s is required"));
        assert!(e("bias_step:t_s=3;step_ut=1,2").contains("three numbers"));
        assert!(e("current_bias:coef_ut_per_a=1,1,1").contains("--current"));
    }
}
