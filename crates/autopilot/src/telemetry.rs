//! MAVLink messages as samples, each in the units its definition (`common.xml`) gives it:
//!
//! | message | what | unit sent | as read |
//! |---|---|---|---|
//! | `RAW_IMU` (ArduPilot) | the compass field, the autopilot's calibration applied, body axes | mGauss (ArduPilot's `Compass::get_field`; `common.xml` names no unit) | µT (÷ 10) |
//! | `SCALED_IMU2`, `SCALED_IMU3` | the second and third compass | mgauss | µT |
//! | `HIGHRES_IMU` (PX4) | the field, body axes | gauss | µT (× 100) |
//! | `RAW_IMU`, `SCALED_IMU*` `temperature` | the IMU's temperature | cdegC, 0 = not sent | °C |
//! | `HIGHRES_IMU` `temperature` | | degC | °C |
//! | `ATTITUDE_QUATERNION` | body (FRD) → NED, `q1..q4` = w, x, y, z | | unit quaternion |
//! | `BATTERY_STATUS`, `SYS_STATUS` `current_battery` | the battery current | cA, −1 = not measured | A |
//! | `PARAM_VALUE` | a parameter | its own | as sent |

use mavlink::dialects::common::MavMessage;

/// One sample of telemetry, in physical units.
#[derive(Debug, Clone, PartialEq)]
pub enum Telemetry {
    /// A magnetometer reading as the autopilot sent it (its calibration applied, body axes).
    Mag {
        /// Which compass: 0 (`RAW_IMU`, `HIGHRES_IMU`), 1 (`SCALED_IMU2`), 2 (`SCALED_IMU3`).
        instance: u8,
        /// The field, µT.
        field_ut: [f64; 3],
        /// The IMU's temperature, °C; NaN where not sent.
        temp_c: f64,
        /// The autopilot's time, s (since boot, or the UNIX epoch for `RAW_IMU`/`HIGHRES_IMU` if it has one).
        t_s: f64,
    },
    /// The attitude, body (FRD) into NED.
    Attitude {
        /// `[w, x, y, z]`, unit length.
        q: [f64; 4],
        /// Time since boot, s.
        t_s: f64,
    },
    /// The battery current, A.
    Current {
        /// A.
        current_a: f64,
    },
    /// A parameter's value (`PARAM_VALUE`).
    Param {
        /// Its name.
        name: String,
        /// Its value (integers are sent as floats).
        value: f64,
    },
}

/// A temperature in cdegC, 0 meaning "not sent" (`common.xml`: an IMU at 0 °C sends 1).
fn centi_c(t: i16) -> f64 {
    if t == 0 {
        f64::NAN
    } else {
        f64::from(t) / 100.0
    }
}

/// A field in mGauss as µT.
fn mgauss(x: i16, y: i16, z: i16) -> [f64; 3] {
    [x, y, z].map(|v| f64::from(v) / 10.0)
}

/// A current in cA as A; `None` for −1 (not measured).
fn centi_a(i: i16) -> Option<Telemetry> {
    (i >= 0).then(|| Telemetry::Current {
        current_a: f64::from(i) / 100.0,
    })
}

/// The sample a message carries, if it carries one a calibration reads.
pub fn telemetry(msg: &MavMessage) -> Option<Telemetry> {
    Some(match msg {
        MavMessage::RAW_IMU(m) => Telemetry::Mag {
            instance: m.id,
            field_ut: mgauss(m.xmag, m.ymag, m.zmag),
            temp_c: centi_c(m.temperature),
            t_s: m.time_usec as f64 * 1e-6,
        },
        MavMessage::SCALED_IMU2(m) => Telemetry::Mag {
            instance: 1,
            field_ut: mgauss(m.xmag, m.ymag, m.zmag),
            temp_c: centi_c(m.temperature),
            t_s: f64::from(m.time_boot_ms) * 1e-3,
        },
        MavMessage::SCALED_IMU3(m) => Telemetry::Mag {
            instance: 2,
            field_ut: mgauss(m.xmag, m.ymag, m.zmag),
            temp_c: centi_c(m.temperature),
            t_s: f64::from(m.time_boot_ms) * 1e-3,
        },
        MavMessage::HIGHRES_IMU(m) => Telemetry::Mag {
            instance: m.id,
            field_ut: [m.xmag, m.ymag, m.zmag].map(|g| f64::from(g) * 100.0),
            temp_c: f64::from(m.temperature),
            t_s: m.time_usec as f64 * 1e-6,
        },
        MavMessage::ATTITUDE_QUATERNION(m) => {
            let q = [m.q1, m.q2, m.q3, m.q4].map(f64::from);
            let n = q.iter().map(|v| v * v).sum::<f64>().sqrt();
            if !(n.is_finite() && (n - 1.0).abs() < 0.01) {
                return None;
            }
            Telemetry::Attitude {
                q: q.map(|v| v / n),
                t_s: f64::from(m.time_boot_ms) * 1e-3,
            }
        }
        MavMessage::BATTERY_STATUS(m) if m.id == 0 => return centi_a(m.current_battery),
        MavMessage::SYS_STATUS(m) => return centi_a(m.current_battery),
        MavMessage::PARAM_VALUE(m) => Telemetry::Param {
            name: param_name(&m.param_id[..]),
            value: f64::from(m.param_value),
        },
        _ => return None,
    })
}

/// A parameter's name: its 16 bytes up to the first NUL.
fn param_name(id: &[u8]) -> String {
    let end = id.iter().position(|b| *b == 0).unwrap_or(id.len());
    String::from_utf8_lossy(&id[..end]).into_owned()
}

/// Why a byte stream was not read as MAVLink.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    /// The bytes hold no MAVLink frame at all (a port at the wrong baud rate, or not an autopilot).
    #[error(
        "{source_name}: {bytes} bytes and no MAVLink frame in them (no valid 0xFD or 0xFE start, length and \
         checksum): is it an autopilot, at the right baud rate (ArduPilot's default 115200, PX4's USB any)?"
    )]
    NotMavlink {
        /// Where the bytes came from.
        source_name: String,
        /// How many bytes were read.
        bytes: usize,
    },
}

/// Every MAVLink frame in `bytes` (MAVLink 1 and 2, the common dialect; frames with a bad checksum or of
/// messages the dialect lacks are skipped), with the sample of each that carries one. `source_name` names the bytes
/// in the error.
pub fn read_stream(
    bytes: &[u8],
    source_name: &str,
) -> Result<Vec<(MavMessage, Option<Telemetry>)>, ReadError> {
    let mut reader = mavlink::MavlinkReader::new(bytes);
    let mut out = Vec::new();
    loop {
        match reader.read_any_message::<MavMessage>() {
            Ok((_, msg)) => {
                let t = telemetry(&msg);
                out.push((msg, t));
            }
            Err(mavlink::error::MessageReadError::Io(_)) => break,
            Err(mavlink::error::MessageReadError::Parse(_)) => continue,
        }
    }
    if out.is_empty() && !bytes.is_empty() {
        return Err(ReadError::NotMavlink {
            source_name: source_name.to_owned(),
            bytes: bytes.len(),
        });
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_on_a_port_is_not_mavlink() {
        let err = read_stream(
            b"Raw:1,2,3,4,5,6,7,8,9\r\nRaw:1,2,3,4,5,6,7,8,9\r\n",
            "/dev/ttyACM0",
        )
        .unwrap_err();
        assert!(
            err.to_string()
                .starts_with("/dev/ttyACM0: 46 bytes and no MAVLink frame"),
            "{err}"
        );
        assert!(read_stream(b"", "x").unwrap().is_empty());
    }

    #[test]
    fn units_of_the_small_fields() {
        assert!(centi_c(0).is_nan());
        assert_eq!(centi_c(2950), 29.5);
        assert_eq!(mgauss(215, -13, 432), [21.5, -1.3, 43.2]);
        assert_eq!(centi_a(-1), None);
        assert_eq!(param_name(b"COMPASS_OFS_X\0\0\0"), "COMPASS_OFS_X");
        assert_eq!(param_name(b"CAL_MAG0_XCOMP16"), "CAL_MAG0_XCOMP16");
    }
}
