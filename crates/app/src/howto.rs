//! After the fit, a few lines on how to put the calibration to use on the chosen target (`--export`, `--write-to`),
//! and how to check it on a second recording.

use std::fmt::Write;
use std::path::Path;

use magcal_calib::diagnosis::FoundEffect;

use crate::device::DeviceSpec;
use crate::export::{ExportFormat, Holder, c_b_name, left_out_lines};
use crate::units::Units;

/// Where the calibration goes.
#[derive(Clone, Copy, Debug)]
pub enum Target<'a> {
    /// Nowhere yet: only the parameters file, if any.
    None,
    /// An export format, written to a file or to stdout.
    Export {
        /// The format.
        format: ExportFormat,
        /// The file, if not stdout.
        path: Option<&'a Path>,
    },
    /// A device it was written to.
    Device(&'a DeviceSpec),
}

/// How to check the result: `magcal-apply` on a second recording.
fn check_line(params: Option<&Path>) -> String {
    format!(
        "to check it, record again and run: magcal-apply {} SECOND.csv\n",
        params.map_or("PARAMS.toml".to_owned(), |p| p.display().to_string())
    )
}

/// The lines for a target; `params` is the parameters file written (`--out`), `found` the effects the diagnosis found,
/// each named with why the target does not carry it ([`left_out_lines`]), `units` the readings' ([`Units`]).
pub fn how_to_apply(
    target: Target<'_>,
    params: Option<&Path>,
    found: &[FoundEffect],
    units: &Units,
) -> String {
    let mut out = String::new();
    let axes = "the values are in the sensor's axes as recorded: they fit where the magnetometer reports those same \
                axes (record through the autopilot, or with the sensor aligned with the vehicle)";
    match target {
        Target::None => {
            out += "to use it: --export c-header | ardupilot | px4 | json, or --write-to DEV (a MotionCal-style \
                    board, a LIS2MDL)\n";
        }
        Target::Export { format, path } => {
            let file = |default: &str| path.map_or(default.to_owned(), |p| p.display().to_string());
            match format {
                ExportFormat::CHeader => {
                    let name = path
                        .and_then(|p| p.file_name())
                        .map_or("magcal_calibration.h".to_owned(), |n| {
                            n.to_string_lossy().into_owned()
                        });
                    let _ = writeln!(
                        out,
                        "to apply it in C (an Arduino sketch, say): put {} next to your code and",
                        file("the header (stdout) in magcal_calibration.h")
                    );
                    let _ = writeln!(out, "  #include \"{name}\"");
                    let _ = writeln!(
                        out,
                        "  /* raw: the reading in {}, in the sensor's axes, scaled as in the recording; cal: in {} */",
                        units.raw_label(),
                        units.calibrated_label()
                    );
                    out += "  void magcal_apply(const float raw[3], float cal[3]) {\n";
                    out += "    for (int j = 0; j < 3; j++)\n";
                    let _ = writeln!(
                        out,
                        "      cal[j] = MAGCAL_A[j][0] * raw[0] + MAGCAL_A[j][1] * raw[1] + MAGCAL_A[j][2] * raw[2] \
                         + {}[j];",
                        c_b_name(units)
                    );
                    out += "  }\n";
                    out += "  /* level, x forward: heading = atan2(-cal[1], cal[0]) with z down, atan2(cal[1], cal[0]) \
                            with z up (radians from magnetic north) */\n";
                }
                ExportFormat::Ardupilot => {
                    let _ = writeln!(
                        out,
                        "to load it into ArduPilot: MAVProxy `param load {}`, or Mission Planner: Config → Full \
                         Parameter List → Load from file → Write Params; then reboot",
                        file("magcal.param")
                    );
                    let _ = writeln!(
                        out,
                        "  {axes}; ArduPilot applies them after COMPASS_ORIENT (external) or AHRS_ORIENTATION \
                         (internal), so that rotation must be none; COMPASS_SCALE at 0 or 1"
                    );
                }
                ExportFormat::Px4 => {
                    let _ = writeln!(
                        out,
                        "to load it into PX4: QGroundControl → Vehicle Setup → Parameters → Tools → Load from file \
                         ({}); then reboot",
                        file("magcal.params")
                    );
                    let _ = writeln!(
                        out,
                        "  {axes}; the values go to calibration slot 0 (CAL_MAG0_*), the one PX4 uses for the \
                         magnetometer whose id is CAL_MAG0_ID"
                    );
                }
                ExportFormat::Json => {
                    out += "the JSON holds A, b_ut and offset_ut: calibrated = A·raw + b (µT, sensor axes), or \
                            equally A·(raw − offset)\n";
                }
            }
        }
        Target::Device(DeviceSpec::Serial(_)) => {
            out += "the board now holds it (MotionCal's calibration packet): MotionCal-style firmware keeps it and \
                    corrects every reading as S·(raw − V) before its orientation filter; its Raw: lines stay raw, so a \
                    new recording through it can be checked\n";
        }
        Target::Device(DeviceSpec::Mavlink { .. }) => {
            out += "the flight controller now holds them (its compass parameters, set and read back): it applies them \
                    to the compass at once and keeps them over a reboot; to undo, load the undo file the write-back \
                    named (Mission Planner: Config → Full Parameter List → Load from file; QGroundControl: \
                    Parameters → Tools → Load from file)\n";
        }
        Target::Device(_) => {
            out += "the chip now subtracts the hard-iron offset itself until it is reset or powered off: firmware \
                    must write the offset registers at start-up and apply A itself (magcal-record resets the chip, so \
                    a recording to check with is raw again)\n";
        }
    }
    let holder = match target {
        Target::None => None,
        Target::Export { format, .. } => Some(Holder::Format(format)),
        Target::Device(DeviceSpec::Serial(_)) => Some(Holder::Board),
        Target::Device(DeviceSpec::Mavlink { .. }) => Some(Holder::Autopilot),
        Target::Device(_) => Some(Holder::Chip),
    };
    let corrections = found
        .iter()
        .filter(|e| e.effect.id().is_correction())
        .count();
    if let Some(holder) = holder {
        if corrections > 0 {
            let _ = writeln!(
                out,
                "  the model's {corrections} body-fixed correction(s) have no place there: it gets A and b fitted \
                 without them; the parameters file keeps them"
            );
        }
        for line in left_out_lines(found, holder) {
            let _ = writeln!(out, "  {line}");
        }
    }
    out + &check_line(params)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_target_says_how_and_how_to_check() {
        let params = Path::new("params.toml");
        let c = how_to_apply(
            Target::Export {
                format: ExportFormat::CHeader,
                path: Some(Path::new("cal.h")),
            },
            Some(params),
            &[],
            &Units::Microtesla,
        );
        assert!(
            c.contains("cal.h") && c.contains("MAGCAL_A[j][0] * raw[0]"),
            "{c}"
        );
        assert!(c.contains("magcal-apply params.toml"), "{c}");
        let ap = how_to_apply(
            Target::Export {
                format: ExportFormat::Ardupilot,
                path: None,
            },
            None,
            &crate::export::tests::three_found(),
            &Units::Microtesla,
        );
        assert!(
            ap.contains("param load") && ap.contains("COMPASS_ORIENT"),
            "{ap}"
        );
        assert!(ap.contains("2 body-fixed correction(s)"), "{ap}");
        assert!(
            ap.contains("\n  left out: current_bias, 0.171 µT RMS per axis on this recording: what current_bias; not written"),
            "{ap}"
        );
        let px = how_to_apply(
            Target::Export {
                format: ExportFormat::Px4,
                path: None,
            },
            None,
            &[],
            &Units::Microtesla,
        );
        assert!(
            px.contains("QGroundControl") && px.contains("CAL_MAG0_ID"),
            "{px}"
        );
        assert!(how_to_apply(Target::None, None, &[], &Units::Microtesla).contains("--export"));
    }
}
