//! Findings in words: one sentence per effect in physical terms, and the experiment that would separate two effects
//! that explain the same residual.

use crate::coverage::describe;
use crate::effects::{Effect, EffectId};
use crate::frames;

use super::gross::{Declined, Span, SpanKind};

/// A direction and size: "0.31 µT/°C along +X", or along a direction when no axis dominates.
fn along(v: [f64; 3], unit: &str) -> String {
    let m = frames::norm(v);
    if m == 0.0 {
        return format!("0 {unit}");
    }
    let d = describe(frames::scale(v, 1.0 / m))
        .replace("sensor axis ≈ ", "")
        .replace("sensor direction ", "");
    format!("{m:.3} {unit} along {d}")
}

/// What a found effect is, with its main parameters in physical units (`field_ut`: the field's magnitude, for the
/// non-linearity's size).
pub(crate) fn what(e: &Effect, channel: Option<&str>, field_ut: f64) -> String {
    match *e {
        Effect::TemperatureBias { coef_ut_per_c, .. } => {
            format!(
                "offset follows temperature: {}",
                along(coef_ut_per_c, "µT/°C")
            )
        }
        Effect::TemperatureScale { coef_per_c: k, .. } => format!(
            "scale factors change with temperature: {:+.0}, {:+.0}, {:+.0} ppm/°C on X, Y, Z",
            k[0] * 1e6,
            k[1] * 1e6,
            k[2] * 1e6
        ),
        Effect::CurrentBias { coef_ut_per_a, .. } => format!(
            "the current in {} adds a field of {} (a wire, motor or heater near the sensor)",
            channel.unwrap_or("a current channel"),
            along(coef_ut_per_a, "µT/A")
        ),
        Effect::TimeLag { lag_s } => format!(
            "the magnetometer sample is {} by {:.1} ms relative to the attitude reference",
            if lag_s >= 0.0 { "late" } else { "early" },
            lag_s.abs() * 1e3
        ),
        Effect::RateCoupling { lag_axis_s: l } => format!(
            "each axis follows the field's change with its own delay — {:.1}, {:.1}, {:.1} ms on X, Y, Z (filters or \
             eddy currents, not one timing offset)",
            l[0] * 1e3,
            l[1] * 1e3,
            l[2] * 1e3
        ),
        Effect::FieldDrift {
            rate_ut_per_s: r, ..
        } => format!(
            "the world field drifts during the recording by {:.3} µT/min (N {:+.3}, E {:+.3}, D {:+.3} µT/min): \
             geomagnetic variation or a moving magnetic object outside",
            frames::norm(r) * 60.0,
            r[0] * 60.0,
            r[1] * 60.0,
            r[2] * 60.0
        ),
        Effect::FieldDirectionError {
            declination_error_deg: d,
            inclination_error_deg: i,
        } => format!(
            "the true field points {d:+.3}° in declination and {i:+.3}° in inclination away from the assumed one \
             (a wrong declination, a reference whose north is off, or a local anomaly)"
        ),
        Effect::Nonlinearity { cubic_per_ut2: k } => format!(
            "the response is not linear in the field: a cubic term worth {:.3}, {:.3}, {:.3} µT at ±{field_ut:.0} µT \
             on X, Y, Z",
            k[0] * field_ut.powi(3),
            k[1] * field_ut.powi(3),
            k[2] * field_ut.powi(3)
        ),
        Effect::BiasStep { t_s, step_ut } => format!(
            "the offset jumped by {} at t = {t_s:.2} s (the sensor was magnetised, or a set/reset event)",
            along(step_ut, "µT")
        ),
        Effect::BiasDrift { rate_ut_per_s, .. } => {
            format!(
                "the offset drifts with time: {}",
                along(frames::scale(rate_ut_per_s, 60.0), "µT/min")
            )
        }
        Effect::Disturbance {
            t0_s,
            t1_s,
            field_ned_ut: d,
        } => format!(
            "a transient external field of {:.3} µT, fixed in the world (N {:+.3}, E {:+.3}, D {:+.3} µT), from \
             t = {t0_s:.2} s to {t1_s:.2} s: something magnetic near the bench",
            frames::norm(d),
            d[0],
            d[1],
            d[2]
        ),
        Effect::BiasWindow {
            t0_s,
            t1_s,
            offset_ut,
        } => format!(
            "a field of {} fixed to the sensor from t = {t0_s:.2} s to {t1_s:.2} s: something magnetic attached to \
             the board (or carried with it) for that time",
            along(offset_ut, "µT")
        ),
        Effect::MagnetNearby { moment_am2, .. } => format!(
            "a magnet of {:.2} A·m² fixed in the room",
            frames::norm(moment_am2)
        ),
    }
}

/// The sentence for a found effect (`what`, from [`what`]), ending with the held-out residual before and after
/// against the noise floor.
pub(crate) fn explain(what: &str, holdout: (f64, f64), floor_ut: f64) -> String {
    format!(
        "{what}; after modelling, held-out residual {:.3} → {:.3} µT, noise floor {floor_ut:.3} µT",
        holdout.0, holdout.1
    )
}

/// Why two effects explain the same residual, and the experiment that would tell them apart.
pub(crate) fn separate(a: EffectId, b: EffectId) -> (String, String) {
    use EffectId::*;
    let pair = |x: EffectId, y: EffectId| (a == x && b == y) || (a == y && b == x);
    let (why, experiment) = if pair(TemperatureBias, BiasDrift) || pair(TemperatureScale, BiasDrift)
    {
        (
            "the temperature changed almost in step with time, so a temperature effect and a drift over time fit \
             the same residual",
            "let the temperature change without a trend in time: warm the sensor and let it cool again while \
             recording, or hold it at one temperature for as long",
        )
    } else if pair(TimeLag, RateCoupling) {
        (
            "one delay on all axes and a delay per axis fit the same residual",
            "rotate quickly about each sensor axis in turn: one timing offset delays all axes alike, per-axis \
             couplings do not",
        )
    } else if pair(FieldDrift, BiasDrift) || pair(FieldDrift, TemperatureBias) {
        (
            "the attitude changed too little during the drift to tell a world-fixed change from a sensor-fixed one",
            "turn the sensor through many orientations while the drift goes on (a world-fixed drift rotates with \
             the attitude, a sensor-fixed one does not), or return to one reference pose at the start and the end",
        )
    } else if pair(TemperatureBias, TemperatureScale) {
        (
            "an offset and a scale change with temperature fit the same residual",
            "vary the temperature while the sensor points in several directions: a scale change grows with the \
             field along each axis, an offset does not",
        )
    } else if pair(BiasStep, Disturbance) || pair(BiasStep, BiasDrift) {
        (
            "a lasting jump and a transient or gradual change fit the same residual",
            "record longer after the event, turning the sensor: a step stays and turns with the sensor",
        )
    } else {
        (
            "both fit the same residual about equally well",
            "record again varying the channel one effect depends on while holding the other's steady",
        )
    };
    (format!("{} and {}: {why}", a, b), experiment.to_owned())
}

/// What became of a gross span, for its wording.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Fate {
    /// The calibration's: modelled, or left out of it (with the reason when modelling it was declined).
    Calibration,
    /// A check of parameters fitted elsewhere: left out of the check.
    Check,
}

/// A gross span in words (`when`: its time or samples): what it was, and what became of it.
pub(crate) fn span(sp: &Span, when: &str, vector: bool, fate: Fate) -> String {
    let (what, sep, in_calibration) = span_parts(sp, vector);
    match fate {
        Fate::Calibration => format!("{when}: {what}{sep}{in_calibration}"),
        Fate::Check => format!("{when}: {what}{sep}left out of the check"),
    }
}

/// A gross span's description, the separator before its fate, and its fate in the calibration (with the reason it
/// was left out when modelling it was declined).
fn span_parts(sp: &Span, vector: bool) -> (String, &'static str, String) {
    const LEFT_OUT: &str = "left out of the calibration";
    match sp.kind {
        SpanKind::SensorFixed { offset_ut, .. }
        | SpanKind::RoomFixed {
            field_ned_ut: offset_ut,
        } if !sp.turned => (
            format!(
                "a constant field of {:.1} µT while the sensor hardly turned (fixed to the sensor or to the room: \
                 they cannot be told apart, nor from something that moved)",
                frames::norm(offset_ut)
            ),
            " — ",
            LEFT_OUT.to_owned(),
        ),
        SpanKind::SensorFixed {
            offset_ut,
            told_apart: true,
        }
        | SpanKind::RoomFixed {
            field_ned_ut: offset_ut,
        } if sp.declined.is_some() => (
            format!(
                "a field of {:.1} µT fixed to the {}",
                frames::norm(offset_ut),
                if matches!(sp.kind, SpanKind::RoomFixed { .. }) {
                    "room"
                } else {
                    "sensor"
                }
            ),
            " — ",
            format!(
                "{LEFT_OUT}: {}",
                match sp.declined {
                    Some(Declined::Undetermined) => "modelled, it left the fit without a solution",
                    _ =>
                        "with its samples kept and modelled, the clean part fitted no better on held-out data",
                }
            ),
        ),
        SpanKind::SensorFixed {
            offset_ut,
            told_apart: true,
        } => (
            format!(
                "a field of {:.1} µT fixed to the sensor",
                frames::norm(offset_ut)
            ),
            " — ",
            "modelled (bias_window), the samples it explains kept".to_owned(),
        ),
        SpanKind::SensorFixed { offset_ut, .. } => (
            format!(
                "a constant field of {:.1} µT, fixed to the sensor or to the room: the two cannot be told apart \
                 here{}",
                frames::norm(offset_ut),
                if vector {
                    ""
                } else {
                    " (the magnitude alone does not show the frame)"
                }
            ),
            " — ",
            LEFT_OUT.to_owned(),
        ),
        SpanKind::RoomFixed { field_ned_ut } => (
            format!(
                "a field of {:.1} µT fixed in the room",
                frames::norm(field_ned_ut)
            ),
            " — ",
            "modelled (disturbance), the samples it explains kept".to_owned(),
        ),
        SpanKind::MagnitudeShift { shift_ut } => (
            format!(
                "the field's magnitude {} by {:.1} µT throughout while the sensor turned — a field fixed in the room \
                 (a magnet or steel placed nearby, then taken away)",
                if shift_ut > 0.0 { "raised" } else { "lowered" },
                shift_ut.abs()
            ),
            "; ",
            LEFT_OUT.to_owned(),
        ),
        SpanKind::Moving => (
            format!(
                "up to {:.1} µT, changing as the sensor moved — a magnet or steel nearby",
                sp.peak_ut
            ),
            "; ",
            LEFT_OUT.to_owned(),
        ),
        SpanKind::Unexplained => (
            format!(
                "up to {:.1} µT, neither fixed to the sensor nor to the room while the sensor was still (something \
                 moved near it)",
                sp.peak_ut
            ),
            " — ",
            LEFT_OUT.to_owned(),
        ),
    }
}
