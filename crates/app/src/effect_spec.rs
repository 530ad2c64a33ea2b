//! Effects written on a command line (`magcal-sim --effect …`), with the parameter names of the report:
//! `id:name=value[,value,value][;name=value…]`, e.g. `temperature_bias:coef_ut_per_c=0.05,0,0;t_ref_c=25` or
//! `current_bias:channel=i_motor;coef_ut_per_a=0.3,0,0`.

use magcal_calib::effects::{Effect, EffectId};

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

/// Parses one effect spec.
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
    let get = |name: &str| values.iter().find(|(n, _)| *n == name).map(|(_, v)| *v);
    let num = |name: &str, default: Option<f64>| -> Result<f64, EffectSpecError> {
        match get(name) {
            Some(v) => v
                .parse()
                .map_err(|_| err(format!("{name}: {v:?} is not a number"))),
            None => default.ok_or_else(|| err(format!("{name} is required"))),
        }
    };
    let vec3 = |name: &str| -> Result<[f64; 3], EffectSpecError> {
        let v = get(name).ok_or_else(|| err(format!("{name} is required (three numbers)")))?;
        let parts: Vec<f64> = v
            .split(',')
            .map(|x| x.trim().parse::<f64>())
            .collect::<Result<_, _>>()
            .map_err(|_| err(format!("{name}: {v:?} is not three numbers")))?;
        parts
            .try_into()
            .map_err(|_| err(format!("{name}: {v:?} is not three numbers")))
    };
    let allowed: &[&str] = match id {
        EffectId::TemperatureBias => &["coef_ut_per_c", "t_ref_c"],
        EffectId::TemperatureScale => &["coef_per_c", "t_ref_c"],
        EffectId::CurrentBias => &["channel", "coef_ut_per_a"],
        EffectId::TimeLag => &["lag_s"],
        EffectId::RateCoupling => &["lag_axis_s"],
        EffectId::FieldDrift => &["rate_ut_per_s", "t_ref_s"],
        EffectId::FieldDirectionError => &["declination_error_deg", "inclination_error_deg"],
        EffectId::Nonlinearity => &["cubic_per_ut2"],
        EffectId::BiasStep => &["t_s", "step_ut"],
        EffectId::BiasDrift => &["rate_ut_per_s", "t_ref_s"],
        EffectId::Disturbance => &["t0_s", "t1_s", "field_ned_ut"],
        EffectId::BiasWindow => &["t0_s", "t1_s", "offset_ut"],
        EffectId::MagnetNearby => &["position_m", "moment_am2"],
    };
    if let Some((name, _)) = values.iter().find(|(n, _)| !allowed.contains(n)) {
        return Err(err(format!(
            "{id} has no parameter {name:?}; it takes {}",
            allowed.join(", ")
        )));
    }
    Ok(match id {
        EffectId::TemperatureBias => Effect::TemperatureBias {
            coef_ut_per_c: vec3("coef_ut_per_c")?,
            t_ref_c: num("t_ref_c", Some(defaults.t_ref_c))?,
        },
        EffectId::TemperatureScale => Effect::TemperatureScale {
            coef_per_c: vec3("coef_per_c")?,
            t_ref_c: num("t_ref_c", Some(defaults.t_ref_c))?,
        },
        EffectId::CurrentBias => {
            let name = get("channel")
                .or(defaults.currents.first().map(String::as_str))
                .ok_or_else(|| {
                    err(
                        "needs a current channel: add --current NAME:ON_A,MEAN_ON_S,MEAN_OFF_S"
                            .to_owned(),
                    )
                })?;
            let channel = defaults
                .currents
                .iter()
                .position(|c| c == name)
                .ok_or_else(|| {
                    err(format!(
                        "no current channel {name:?} (have {:?})",
                        defaults.currents
                    ))
                })?;
            Effect::CurrentBias {
                channel,
                coef_ut_per_a: vec3("coef_ut_per_a")?,
            }
        }
        EffectId::TimeLag => Effect::TimeLag {
            lag_s: num("lag_s", None)?,
        },
        EffectId::RateCoupling => Effect::RateCoupling {
            lag_axis_s: vec3("lag_axis_s")?,
        },
        EffectId::FieldDrift => Effect::FieldDrift {
            rate_ut_per_s: vec3("rate_ut_per_s")?,
            t_ref_s: num("t_ref_s", Some(defaults.field_drift_t_ref_s))?,
        },
        EffectId::FieldDirectionError => Effect::FieldDirectionError {
            declination_error_deg: num("declination_error_deg", Some(0.0))?,
            inclination_error_deg: num("inclination_error_deg", Some(0.0))?,
        },
        EffectId::Nonlinearity => Effect::Nonlinearity {
            cubic_per_ut2: vec3("cubic_per_ut2")?,
        },
        EffectId::BiasStep => Effect::BiasStep {
            t_s: num("t_s", None)?,
            step_ut: vec3("step_ut")?,
        },
        EffectId::BiasDrift => Effect::BiasDrift {
            rate_ut_per_s: vec3("rate_ut_per_s")?,
            t_ref_s: num("t_ref_s", Some(0.0))?,
        },
        EffectId::Disturbance => Effect::Disturbance {
            t0_s: num("t0_s", None)?,
            t1_s: num("t1_s", None)?,
            field_ned_ut: vec3("field_ned_ut")?,
        },
        EffectId::BiasWindow => Effect::BiasWindow {
            t0_s: num("t0_s", None)?,
            t1_s: num("t1_s", None)?,
            offset_ut: vec3("offset_ut")?,
        },
        EffectId::MagnetNearby => Effect::MagnetNearby {
            position_m: vec3("position_m")?,
            moment_am2: vec3("moment_am2")?,
        },
    })
}

/// Writes an effect as a spec that [`parse`] reads back (`currents` names the channels).
pub fn format(e: &Effect, currents: &[String]) -> String {
    let v = |x: [f64; 3]| format!("{},{},{}", x[0], x[1], x[2]);
    let params = match *e {
        Effect::TemperatureBias {
            coef_ut_per_c,
            t_ref_c,
        } => {
            format!("coef_ut_per_c={};t_ref_c={t_ref_c}", v(coef_ut_per_c))
        }
        Effect::TemperatureScale {
            coef_per_c,
            t_ref_c,
        } => format!("coef_per_c={};t_ref_c={t_ref_c}", v(coef_per_c)),
        Effect::CurrentBias {
            channel,
            coef_ut_per_a,
        } => format!(
            "channel={};coef_ut_per_a={}",
            currents.get(channel).map_or("?", String::as_str),
            v(coef_ut_per_a)
        ),
        Effect::TimeLag { lag_s } => format!("lag_s={lag_s}"),
        Effect::RateCoupling { lag_axis_s } => format!("lag_axis_s={}", v(lag_axis_s)),
        Effect::FieldDrift {
            rate_ut_per_s,
            t_ref_s,
        } => format!("rate_ut_per_s={};t_ref_s={t_ref_s}", v(rate_ut_per_s)),
        Effect::FieldDirectionError {
            declination_error_deg,
            inclination_error_deg,
        } => format!(
            "declination_error_deg={declination_error_deg};inclination_error_deg={inclination_error_deg}"
        ),
        Effect::Nonlinearity { cubic_per_ut2 } => format!("cubic_per_ut2={}", v(cubic_per_ut2)),
        Effect::BiasStep { t_s, step_ut } => format!("t_s={t_s};step_ut={}", v(step_ut)),
        Effect::BiasDrift {
            rate_ut_per_s,
            t_ref_s,
        } => format!("rate_ut_per_s={};t_ref_s={t_ref_s}", v(rate_ut_per_s)),
        Effect::Disturbance {
            t0_s,
            t1_s,
            field_ned_ut,
        } => {
            format!("t0_s={t0_s};t1_s={t1_s};field_ned_ut={}", v(field_ned_ut))
        }
        Effect::BiasWindow {
            t0_s,
            t1_s,
            offset_ut,
        } => format!("t0_s={t0_s};t1_s={t1_s};offset_ut={}", v(offset_ut)),
        Effect::MagnetNearby {
            position_m,
            moment_am2,
        } => format!("position_m={};moment_am2={}", v(position_m), v(moment_am2)),
    };
    format!("{}:{params}", e.id())
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
