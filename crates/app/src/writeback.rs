//! Writing a fitted calibration back to the device (`magcal-fit --write-to DEV`), verified by reading it back.
//!
//! - `serial:…`: MotionCal's calibration packet (hard-iron offset `V = −A⁻¹·b`, soft-iron matrix `S`, the field
//!   magnitude), confirmed by the firmware's `Cal1:`/`Cal2:` echo. `S` is the symmetric positive-definite polar
//!   factor of `A` (for a symmetric `A`, `A` itself), so the firmware's `S·(raw − V)` has the magnitude of magcal's
//!   `A·raw + b`; the rotation a vector fit also holds cannot be sent, and is reported.
//! - `i2c:…:lis2mdl` and `sim:lis2mdl`: the LIS2MDL's hard-iron offset registers, which the chip subtracts from
//!   every sample, get `V` in the chip's raw axes; they are read back and compared. The chip clears them at reset and
//!   power-up, so firmware must write them at start-up.
//! - `mavlink:…`: an ArduPilot or PX4 flight controller ([`write_back_autopilot`]): the export's parameters (the same
//!   values and units as `--export ardupilot|px4`), the current values read first and saved to an undo `.param`
//!   file, then each set with `PARAM_SET`, confirmed by its `PARAM_VALUE` and read back; a refused or unconfirmed
//!   parameter sets back what was written ([`magcal_autopilot::write_all`]) and is an error naming it.
//! - Other chips hold no calibration: that is an error that says so.

use std::cell::RefCell;
use std::path::Path;
use std::rc::Rc;
use std::time::Duration;

use embedded_hal::i2c::I2c;
use magcal_autopilot::params::{param_file, parse_param_file, read_all, write_all};
use magcal_autopilot::{Autopilot, Connection, ParamValue};
use magcal_driver::serial::{CalibrationPacket, WriteError, split_affine};
use magcal_driver::{ChipKind, Error as ChipError, HardIronOffset, Lis2mdl, Magnetometer};
use magcal_mockhw::{SimChip, VirtualClock};
use magcal_sim::bench::Bench;

use crate::device::{DeviceSpec, MavlinkPort};
use crate::export::{ExportFormat, autopilot_params, current_params, refusal, warnings};
use crate::fit::Calibration;
use crate::source::sim::bench_config;

/// How long the firmware gets to echo a calibration (Adafruit's sketches echo about once a second).
pub const ECHO_TIMEOUT: Duration = Duration::from_secs(5);
/// A read-back offset may differ from the one written by half the register's resolution (0.15 µT), plus rounding.
const OFFSET_TOLERANCE_UT: f64 = 0.075 + 1e-4;

/// Why a write-back failed.
#[derive(Debug, thiserror::Error)]
pub enum WriteBackError {
    /// The chip has no place to hold a calibration.
    #[error(
        "{device}: the {chip} has no offset registers to hold a calibration (of the supported chips only the LIS2MDL \
         has); apply the parameters file in your firmware instead"
    )]
    NoOffsetRegisters {
        /// The device string.
        device: String,
        /// The chip.
        chip: ChipKind,
    },
    /// The recording was made with another chip than the device's.
    #[error(
        "{device}: the recording is of a {recorded} (its metadata: `sensor: {sensor}`), the device a {chip}: a \
         calibration belongs to the sensor it was recorded with; record this device and fit that"
    )]
    OtherChip {
        /// The device string.
        device: String,
        /// The device's chip.
        chip: ChipKind,
        /// The chip the recording names.
        recorded: ChipKind,
        /// The recording's `sensor` metadata.
        sensor: String,
    },
    /// The calibration cannot be expressed in the device's form.
    #[error("{device}: this calibration cannot be sent: {why}")]
    Unsendable {
        /// The device string.
        device: String,
        /// Why.
        why: String,
    },
    /// The device could not be reached.
    #[error("{device}: {error}")]
    Device {
        /// The device string.
        device: String,
        /// What went wrong.
        error: String,
    },
    /// The device did not confirm what was written.
    #[error("{device}: verification failed: {detail}")]
    Verification {
        /// The device string.
        device: String,
        /// What differs.
        detail: String,
    },
}

/// Writes a fitted calibration's `A` and `b` to the device and verifies it; the field magnitude is the one the fit
/// used (for a scalar fit without one, the fitted radius). Body-fixed corrections in the model stay in the
/// parameters file: no device here can hold them, so the device gets the base fit (`A` and `b` fitted without them,
/// [`crate::verdict::target_model`]), and a line says so. A recording whose `sensor` metadata names another chip
/// than the device's is refused.
pub fn write_back_calibration(
    spec: &DeviceSpec,
    cal: &Calibration,
    sensor: Option<&str>,
) -> Result<Vec<String>, WriteBackError> {
    if let (Some(chip), Some(sensor)) = (spec.chip(), sensor) {
        let named = sensor.to_lowercase();
        let recorded = ChipKind::ALL.into_iter().find(|c| named.contains(c.name()));
        if let Some(recorded) = recorded.filter(|r| *r != chip) {
            return Err(WriteBackError::OtherChip {
                device: spec.to_string(),
                chip,
                recorded,
                sensor: sensor.to_owned(),
            });
        }
    }
    let model = crate::verdict::target_model(cal);
    let field_ut = cal.field.magnitude().or(cal.fit.face().magnitude_ut());
    let mut lines = write_back(spec, &model.a, &model.b_ut, field_ut)?;
    let corrections = cal.model().corrections().count();
    if corrections > 0 {
        lines.push(format!(
            "  the model's {corrections} body-fixed correction(s) cannot be held by the device: it got A and b fitted \
             without them; apply them from the parameters file"
        ));
    }
    Ok(lines)
}

/// Writes the calibration `B = A·raw + b` (µT) to the device and verifies it. `field_ut` is the field magnitude the
/// calibration maps onto, which MotionCal's packet carries (needed for serial devices only). Returns lines saying
/// what was done.
pub fn write_back(
    spec: &DeviceSpec,
    a: &[[f64; 3]; 3],
    b_ut: &[f64; 3],
    field_ut: Option<f64>,
) -> Result<Vec<String>, WriteBackError> {
    let device = spec.to_string();
    let unsendable = |why: String| WriteBackError::Unsendable {
        device: device.clone(),
        why,
    };
    let model = split_affine(a, b_ut).map_err(|e| unsendable(e.to_string()))?;
    let offset_ut = model.hard_iron_ut;
    match spec {
        DeviceSpec::Serial(s) => {
            let field_ut = field_ut.ok_or_else(|| {
                unsendable(
                    "MotionCal's packet carries the field magnitude, which this fit does not know (give \
                     --field-ned, --location/--date or --field-ut)"
                        .to_owned(),
                )
            })?;
            let packet = CalibrationPacket::magnetic(offset_ut, field_ut, model.soft_iron)
                .map_err(|e| unsendable(e.to_string()))?;
            let mut port = s.open().map_err(|e| WriteBackError::Device {
                device: device.clone(),
                error: e.to_string(),
            })?;
            let verified = port
                .write_calibration(&packet, ECHO_TIMEOUT)
                .map_err(|e| match e {
                    WriteError::Verification(v) => WriteBackError::Verification {
                        device: device.clone(),
                        detail: v.to_string(),
                    },
                    other => WriteBackError::Device {
                        device: device.clone(),
                        error: other.to_string(),
                    },
                })?;
            let mut lines = vec![format!(
                "{device}: sent the MotionCal packet (offset [{:.3}, {:.3}, {:.3}] µT, field {field_ut:.3} µT); \
                 the firmware's echo confirmed it after {:.2} s",
                offset_ut[0], offset_ut[1], offset_ut[2], verified.elapsed_s
            )];
            if model.dropped_rotation_deg > 0.01 || model.dropped_reflection {
                lines.push(format!(
                    "  the firmware holds a symmetric matrix: the {:.2}° rotation in A (sensor misalignment against \
                     the reference){} was not sent",
                    model.dropped_rotation_deg,
                    if model.dropped_reflection { " and an axis reflection" } else { "" }
                ));
            }
            Ok(lines)
        }
        DeviceSpec::I2c {
            path,
            chip: ChipKind::Lis2mdl,
            address,
        } => {
            let bus =
                magcal_driver::linux::I2cdev::new(path).map_err(|e| WriteBackError::Device {
                    device: device.clone(),
                    error: format!("cannot open the bus: {e}"),
                })?;
            let address = address.unwrap_or(ChipKind::Lis2mdl.default_address());
            let held = write_lis2mdl_offset(bus, address, &device, offset_ut)?;
            Ok(offset_lines(&device, offset_ut, held))
        }
        DeviceSpec::Sim {
            chip: ChipKind::Lis2mdl,
        } => {
            let bench = Bench::new(bench_config(ChipKind::Lis2mdl, 1)).map_err(|e| {
                WriteBackError::Device {
                    device: device.clone(),
                    error: e.to_string(),
                }
            })?;
            let twin = SimChip::new(
                ChipKind::Lis2mdl,
                Rc::new(RefCell::new(bench)),
                VirtualClock::new(),
            );
            let held = write_lis2mdl_offset(
                twin,
                ChipKind::Lis2mdl.default_address(),
                &device,
                offset_ut,
            )?;
            Ok(offset_lines(&device, offset_ut, held))
        }
        DeviceSpec::Mavlink { .. } => Err(unsendable(
            "a flight controller takes the fitted calibration as parameters (magcal-fit --write-to)".to_owned(),
        )),
        DeviceSpec::I2c { chip, .. } | DeviceSpec::Sim { chip } => {
            Err(WriteBackError::NoOffsetRegisters {
                device,
                chip: *chip,
            })
        }
    }
}

fn offset_lines(device: &str, offset_ut: [f64; 3], held: [f64; 3]) -> Vec<String> {
    vec![
        format!(
            "{device}: wrote the hard-iron offset [{:.3}, {:.3}, {:.3}] µT to the offset registers; they read back \
             [{:.3}, {:.3}, {:.3}] µT (0.15 µT steps)",
            offset_ut[0], offset_ut[1], offset_ut[2], held[0], held[1], held[2]
        ),
        "  the chip now subtracts it from every sample: readings from it need only A (b = 0). It clears the \
         registers at reset and power-up, so firmware must write them at start-up."
            .to_owned(),
    ]
}

/// Writes `offset_ut` (raw axes, µT) to a LIS2MDL's offset registers at `address` and reads them back; returns what
/// the chip holds, or a verification error if that is not what was written (to within the registers' 0.15 µT).
pub fn write_lis2mdl_offset<I: I2c>(
    i2c: I,
    address: u8,
    device: &str,
    offset_ut: [f64; 3],
) -> Result<[f64; 3], WriteBackError> {
    let failed = |what: &str, e: ChipError<I::Error>| WriteBackError::Device {
        device: device.to_owned(),
        error: format!("{what}: {e}"),
    };
    let mut chip = Lis2mdl::with_address(i2c, address);
    chip.identify()
        .map_err(|e| failed("identifying the LIS2MDL", e))?;
    chip.write_offset_ut(offset_ut.map(|v| v as f32))
        .map_err(|e| failed("writing the offset registers", e))?;
    let held = chip
        .read_offset_ut()
        .map_err(|e| failed("reading the offset registers back", e))?
        .map(f64::from);
    if (0..3).any(|k| (held[k] - offset_ut[k]).abs() > OFFSET_TOLERANCE_UT) {
        return Err(WriteBackError::Verification {
            device: device.to_owned(),
            detail: format!(
                "wrote the offset [{:.3}, {:.3}, {:.3}] µT, the chip holds [{:.3}, {:.3}, {:.3}] µT",
                offset_ut[0], offset_ut[1], offset_ut[2], held[0], held[1], held[2]
            ),
        });
    }
    Ok(held)
}

/// How long a flight controller has to send its heartbeat (ArduPilot and PX4 send one a second).
pub const HEARTBEAT_TIMEOUT: Duration = Duration::from_secs(5);

/// A MAVLink connection to the flight controller `spec` names: its port opened
/// ([`crate::device::MavlinkLink::open`]), its heartbeat awaited; returns the connection and the autopilot (the one
/// named in the device string, or the heartbeat's).
fn connect(
    spec: &DeviceSpec,
) -> Result<(Connection<Box<dyn MavlinkPort>>, Autopilot), WriteBackError> {
    let device = spec.to_string();
    let DeviceSpec::Mavlink { link, autopilot } = spec else {
        return Err(WriteBackError::Unsendable {
            device,
            why: "not a flight controller (mavlink:PATH[:BAUD] or mavlink:udp:HOST:PORT)"
                .to_owned(),
        });
    };
    let port = link.open().map_err(|error| WriteBackError::Device {
        device: device.clone(),
        error,
    })?;
    let mut conn = Connection::new(port, &link.name());
    let found = conn
        .wait_heartbeat(HEARTBEAT_TIMEOUT, *autopilot)
        .map_err(|e| WriteBackError::Device {
            device: device.clone(),
            error: format!("{e}; nothing was written"),
        })?;
    Ok((conn, found))
}

/// The export format of `autopilot`.
fn format_of(autopilot: Autopilot) -> ExportFormat {
    match autopilot {
        Autopilot::ArduPilot => ExportFormat::Ardupilot,
        Autopilot::Px4 => ExportFormat::Px4,
    }
}

/// Reads the current values of `wanted`'s parameters, saves them to `undo` (atomically, in the autopilot's
/// parameter file format, with `comments`), then sets `wanted` ([`write_all`]). Returns what was read back and what
/// was there before.
fn set_with_undo<P: std::io::Read + std::io::Write>(
    conn: &mut Connection<P>,
    autopilot: Autopilot,
    device: &str,
    wanted: &[(String, f64)],
    undo: Option<(&Path, &[String])>,
) -> Result<(Vec<ParamValue>, Vec<ParamValue>), WriteBackError> {
    let names: Vec<&str> = wanted.iter().map(|(n, _)| n.as_str()).collect();
    let previous = read_all(conn, &names).map_err(|e| WriteBackError::Device {
        device: device.to_owned(),
        error: format!("reading the current values: {e}; nothing was written"),
    })?;
    if let Some((path, comments)) = undo {
        let text = param_file(autopilot, &previous, comments);
        crate::files::write_atomic(path, text.as_bytes()).map_err(|e| WriteBackError::Device {
            device: device.to_owned(),
            error: format!(
                "writing the undo file {}: {e}; nothing was written to the autopilot",
                path.display()
            ),
        })?;
    }
    let back = write_all(conn, wanted, &previous).map_err(|e| WriteBackError::Verification {
        device: device.to_owned(),
        detail: e.to_string(),
    })?;
    Ok((back, previous))
}

/// Writes a fitted calibration to the flight controller `spec` names (`mavlink:…`): the export's parameters for
/// its autopilot ([`autopilot_params`], the base fit [`crate::verdict::target_model`]), the current values saved
/// first to `undo` (ArduPilot's `NAME,VALUE` or QGroundControl's tab-separated lines), each set, confirmed and read
/// back; anything refused or unconfirmed sets back what was written and is an error naming the parameter.
pub fn write_back_autopilot(
    spec: &DeviceSpec,
    cal: &Calibration,
    undo: &Path,
) -> Result<Vec<String>, WriteBackError> {
    let device = spec.to_string();
    let model = crate::verdict::target_model(cal);
    let (mut conn, autopilot) = connect(spec)?;
    let format = format_of(autopilot);
    if let Some(why) = refusal(&model, format, &cal.units) {
        return Err(WriteBackError::Unsendable { device, why });
    }
    let wanted = autopilot_params(&model, format, &cal.units);
    let comments = [format!(
        "{autopilot}'s values before magcal-fit wrote its calibration to {device}: load this file to undo it"
    )];
    let (back, previous) = set_with_undo(
        &mut conn,
        autopilot,
        &device,
        &wanted,
        Some((undo, &comments)),
    )?;
    let mut lines = vec![format!(
        "{device}: {autopilot} (by its heartbeat{}): set {} parameters, each confirmed by the autopilot and read back; \
         the previous values are in {}",
        if matches!(
            spec,
            DeviceSpec::Mavlink {
                autopilot: Some(_),
                ..
            }
        ) {
            ", or as named"
        } else {
            ""
        },
        back.len(),
        undo.display()
    )];
    for (b, p) in back.iter().zip(&previous) {
        lines.push(format!("  {:<16} {:>14} (was {})", b.name, b.wire, p.wire));
    }
    for w in warnings(&model, format, &cal.units) {
        lines.push(format!("  WARNING: {w}"));
    }
    let corrections = cal.model().corrections().count();
    if corrections > 0 {
        lines.push(format!(
            "  the model's {corrections} body-fixed correction(s) are not among these parameters: it got A and b \
             fitted without them; the parameters file keeps them"
        ));
    }
    Ok(lines)
}

/// Writes a bench motor test's current term to the flight controller `spec` names (`mavlink:…`): its motor
/// compensation ([`current_params`]: `COMPASS_MOT_*` with `COMPASS_MOTCT` 2, or `CAL_MAG0_*COMP` with
/// `CAL_MAG_COMP_TYP` 2) for the current term `k_ut_per_a` in the field calibrated by `a`, as
/// [`write_back_autopilot`] writes a calibration: the previous values saved first to `undo`, each set, confirmed and
/// read back, or what was written set back.
pub fn write_back_current(
    spec: &DeviceSpec,
    k_ut_per_a: [f64; 3],
    a: &[[f64; 3]; 3],
    undo: &Path,
) -> Result<Vec<String>, WriteBackError> {
    let device = spec.to_string();
    let (mut conn, autopilot) = connect(spec)?;
    let wanted = current_params(format_of(autopilot), k_ut_per_a, a).map_err(|why| {
        WriteBackError::Unsendable {
            device: device.clone(),
            why,
        }
    })?;
    let comments = [format!(
        "{autopilot}'s values before magcal-fit wrote a bench motor test's compensation to {device}: load this file to \
         undo it"
    )];
    let (back, previous) = set_with_undo(
        &mut conn,
        autopilot,
        &device,
        &wanted,
        Some((undo, &comments)),
    )?;
    let mut lines = vec![format!(
        "{device}: {autopilot}: set the motor compensation, {} parameters, each confirmed by the autopilot and read \
         back; the previous values are in {}",
        back.len(),
        undo.display()
    )];
    // Decoded (PX4 carries an integer's bytes in the float), and as the float the autopilot holds.
    for (b, p) in back.iter().zip(&previous) {
        lines.push(format!(
            "  {:<16} {:>14} (was {})",
            b.name, b.value as f32, p.value as f32
        ));
    }
    Ok(lines)
}

/// Loads a parameter file (an undo file [`write_back_autopilot`] wrote, or any ArduPilot `.param` / QGroundControl
/// `.params`) into the flight controller `spec` names, as the write-back does: every parameter confirmed and read
/// back, or what was written set back. Returns lines saying what was done.
pub fn load_param_file(spec: &DeviceSpec, path: &Path) -> Result<Vec<String>, WriteBackError> {
    let device = spec.to_string();
    let text = std::fs::read_to_string(path).map_err(|e| WriteBackError::Device {
        device: device.clone(),
        error: format!("reading {}: {e}", path.display()),
    })?;
    let wanted = parse_param_file(&text).map_err(|why| WriteBackError::Unsendable {
        device: device.clone(),
        why: format!("{}: {why}", path.display()),
    })?;
    let (mut conn, autopilot) = connect(spec)?;
    let (back, _) = set_with_undo(&mut conn, autopilot, &device, &wanted, None)?;
    Ok(vec![format!(
        "{device}: {autopilot}: loaded {} parameters from {}, each confirmed and read back",
        back.len(),
        path.display()
    )])
}
