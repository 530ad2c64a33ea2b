//! One magnetometer of a flight log as a [`Recording`]: a row per magnetometer sample inside the attitude's span,
//! the chip's own field in its sensor axes, µT (the logged calibration undone where the topic had it applied), the
//! attitude from sensor axes into NED (the estimator's body attitude turned by the sensor's rotation), the battery
//! current as `i_battery`, the chip's temperature where logged, the place and date of the first GPS fix.

use magcal_calib::frames::{IDENTITY, Mat3, add, mat_t_vec, sub};
use magcal_recording::{Date, Layout, Location, Metadata, Recording, Sample};

use crate::{FlightLog, LogError, MagStream};

/// Largest gap between two attitude samples a row is interpolated across, µs.
const ATTITUDE_GAP_US: u64 = 200_000;
/// Largest gap between two current samples a row is interpolated across, µs.
const CURRENT_GAP_US: u64 = 3_000_000;

/// A magnetometer picked by its place in [`FlightLog::mags`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Instance(pub usize);

/// A flight log's magnetometer as a recording, with what a comparison with the autopilot's own calibration needs.
#[derive(Debug, Clone)]
pub struct FlightRecording {
    /// The recording: raw field (µT, sensor axes), quaternions (sensor → NED, the estimator's), `i_battery`, `temp`.
    pub rec: Recording,
    /// Which magnetometer, in words.
    pub mag: String,
    /// The field as the autopilot used it (the logged calibration and the estimator's bias applied), sensor axes, µT,
    /// one per row (`None` without a slot).
    pub logged_ut: Option<Vec<[f64; 3]>>,
}

/// A unit quaternion `[w, x, y, z]` of a rotation matrix (Shepperd's method).
pub fn matrix_to_quat(m: &Mat3) -> [f64; 4] {
    let trace = m[0][0] + m[1][1] + m[2][2];
    let q = if trace > 0.0 {
        let s = 2.0 * (trace + 1.0).sqrt();
        [
            0.25 * s,
            (m[2][1] - m[1][2]) / s,
            (m[0][2] - m[2][0]) / s,
            (m[1][0] - m[0][1]) / s,
        ]
    } else if m[0][0] > m[1][1] && m[0][0] > m[2][2] {
        let s = 2.0 * (1.0 + m[0][0] - m[1][1] - m[2][2]).sqrt();
        [
            (m[2][1] - m[1][2]) / s,
            0.25 * s,
            (m[0][1] + m[1][0]) / s,
            (m[0][2] + m[2][0]) / s,
        ]
    } else if m[1][1] > m[2][2] {
        let s = 2.0 * (1.0 + m[1][1] - m[0][0] - m[2][2]).sqrt();
        [
            (m[0][2] - m[2][0]) / s,
            (m[0][1] + m[1][0]) / s,
            0.25 * s,
            (m[1][2] + m[2][1]) / s,
        ]
    } else {
        let s = 2.0 * (1.0 + m[2][2] - m[0][0] - m[1][1]).sqrt();
        [
            (m[1][0] - m[0][1]) / s,
            (m[0][2] + m[2][0]) / s,
            (m[1][2] + m[2][1]) / s,
            0.25 * s,
        ]
    };
    let n = q.iter().map(|v| v * v).sum::<f64>().sqrt();
    q.map(|v| v / n)
}

/// The Hamilton product `a ⊗ b` (the turn `b`, then `a`).
pub fn quat_mul(a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
    let [aw, ax, ay, az] = a;
    let [bw, bx, by, bz] = b;
    [
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    ]
}

/// The calendar date of a UTC time in µs since 1970.
pub fn utc_date(utc_us: u64) -> Option<Date> {
    let days = (utc_us / 86_400_000_000) as i64;
    // Days to civil date (H. Hinnant's algorithm).
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = (doy - (153 * mp + 2) / 5 + 1) as u8;
    let month = if mp < 10 { mp + 3 } else { mp - 9 } as u8;
    let year = (yoe + era * 400 + i64::from(month <= 2)) as i32;
    Date::new(year, month, day).ok()
}

impl MagStream {
    /// The stream in words: topic, instance, device.
    pub fn name(&self) -> String {
        let id = self
            .device_id
            .map_or(String::new(), |id| format!(", device {id}"));
        format!("{}[{}]{id}", self.topic, self.instance)
    }
}

impl FlightLog {
    /// The magnetometer `which` (default: [`FlightLog::default_instance`]) as a recording.
    pub fn recording(&self, which: Option<Instance>) -> Result<FlightRecording, LogError> {
        let index = match which {
            Some(Instance(i)) => i,
            None => self.default_instance().unwrap_or(0),
        };
        let Some(mag) = self.mags.get(index) else {
            let available = self
                .mags
                .iter()
                .enumerate()
                .map(|(i, m)| format!("{i}: {}", m.name()))
                .collect::<Vec<_>>()
                .join("; ");
            return Err(LogError::NoSuchInstance {
                file: self.file.clone(),
                asked: index.to_string(),
                available,
            });
        };
        let cal = mag.calibration.as_ref();
        if mag.calibrated && cal.is_none() {
            return Err(LogError::Calibration {
                file: self.file.clone(),
                mag: mag.name(),
                why: "its values are calibrated, and the log has no CAL_MAGn slot for it, so the calibration \
                      cannot be undone; pick a sensor_mag instance (--mag) or log sensor_mag"
                    .to_owned(),
            });
        }
        let rotation = cal.map_or(IDENTITY, |c| c.rotation);
        let sensor_to_body = matrix_to_quat(&rotation);
        let temp = mag
            .temp_c
            .as_ref()
            .is_some_and(|t| t.iter().any(|v| v.is_finite()));
        let layout = Layout {
            t: true,
            temp,
            quat: true,
            currents: self
                .current_a
                .iter()
                .map(|_| "i_battery".to_owned())
                .collect(),
            ..Layout::default()
        };
        let mut rec =
            Recording::new(self.metadata(mag), &layout).map_err(|e| LogError::Calibration {
                file: self.file.clone(),
                mag: mag.name(),
                why: format!("its metadata cannot be written: {e}"),
            })?;
        let mut logged_ut = cal.map(|_| Vec::new());
        let t0 = mag.field_g.t_us[0];
        for (i, (&t, &v)) in mag.field_g.t_us.iter().zip(&mag.field_g.values).enumerate() {
            let Some(q_body) = self.attitude.at(t, ATTITUDE_GAP_US) else {
                continue;
            };
            let current = self
                .current_a
                .as_ref()
                .and_then(|c| c.at(t, CURRENT_GAP_US))
                .unwrap_or(f64::NAN);
            let power = cal.map_or(0.0, |c| c.power(current));
            let bias = mag
                .estimator_bias_g
                .as_ref()
                .and_then(|b| b.held_at(t))
                .unwrap_or([0.0; 3]);
            let raw_g = match cal {
                Some(c) if mag.calibrated => c.undo(add(v, bias), power).ok_or_else(|| LogError::Calibration {
                    file: self.file.clone(),
                    mag: mag.name(),
                    why: "its logged scale matrix (CAL_MAGn_SCALE, ODIAG) is singular: the calibration cannot be \
                          undone"
                        .to_owned(),
                })?,
                _ => v,
            };
            let sample = Sample {
                t_s: (t - t0) as f64 * 1e-6,
                mag_ut: raw_g.map(|g| g * 100.0),
                temp_c: mag.temp_c.as_ref().map_or(f64::NAN, |c| c[i]),
                quat: quat_mul(q_body, sensor_to_body),
                currents_a: self.current_a.iter().map(|_| current).collect(),
                ..Sample::default()
            };
            if rec.push(&sample).is_err() {
                continue;
            }
            if let (Some(out), Some(c)) = (&mut logged_ut, cal) {
                let applied = sub(
                    c.apply_in_sensor_axes(raw_g, power),
                    mat_t_vec(&c.rotation, bias),
                );
                out.push(applied.map(|g| g * 100.0));
            }
        }
        if rec.is_empty() {
            return Err(LogError::NoOverlap {
                file: self.file.clone(),
                mag: mag.name(),
            });
        }
        Ok(FlightRecording {
            rec,
            mag: mag.name(),
            logged_ut,
        })
    }

    /// The recording's metadata: the magnetometer, the place and date of the first GPS fix, where it came from.
    fn metadata(&self, mag: &MagStream) -> Metadata {
        let mut meta = Metadata {
            sensor: Some(format!(
                "{} of a flight log{}",
                mag.name(),
                self.hardware
                    .as_ref()
                    .map_or(String::new(), |h| format!(" ({h})"))
            )),
            routine: Some("flight".to_owned()),
            ..Metadata::default()
        };
        if let Some(fix) = self.first_fix() {
            // To 0.1 m: more digits than the receiver has would only clutter the output.
            let round = |v: f64, digits: usize| format!("{v:.digits$}").parse().unwrap_or(v);
            meta.location = Some(Location {
                lat_deg: round(fix.lat_deg, 6),
                lon_deg: round(fix.lon_deg, 6),
                alt_m: if fix.alt_m.is_finite() {
                    round(fix.alt_m, 1)
                } else {
                    0.0
                },
            });
            meta.date = utc_date(fix.utc_us).filter(|d| d.year >= 2000);
        }
        meta.other.push(("source".to_owned(), self.file.clone()));
        if let Some(c) = &mag.calibration {
            meta.other
                .push(("logged_calibration".to_owned(), c.describe()));
        }
        meta
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use magcal_calib::frames::quat_to_matrix;

    #[test]
    fn dates_of_utc_times() {
        assert_eq!(utc_date(0), Date::new(1970, 1, 1).ok());
        // 2019-03-01 12:00 UTC.
        assert_eq!(utc_date(1_551_441_600_000_000), Date::new(2019, 3, 1).ok());
        assert_eq!(utc_date(951_782_400_000_000), Date::new(2000, 2, 29).ok());
    }

    #[test]
    fn quaternions_of_matrices_and_their_products() {
        for v in 0..42 {
            let m = crate::rotation::sensor_to_body(v).unwrap();
            let back = quat_to_matrix(matrix_to_quat(&m));
            for r in 0..3 {
                for c in 0..3 {
                    assert!((back[r][c] - m[r][c]).abs() < 1e-9, "rotation {v}");
                }
            }
        }
        let a = matrix_to_quat(&crate::rotation::sensor_to_body(2).unwrap());
        let b = matrix_to_quat(&crate::rotation::sensor_to_body(8).unwrap());
        let ab = quat_to_matrix(quat_mul(a, b));
        let (ma, mb) = (quat_to_matrix(a), quat_to_matrix(b));
        for r in 0..3 {
            for c in 0..3 {
                let want: f64 = (0..3).map(|k| ma[r][k] * mb[k][c]).sum();
                assert!((ab[r][c] - want).abs() < 1e-12);
            }
        }
    }
}
