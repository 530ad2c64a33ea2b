//! Flight-controller logs as magcal recordings.
//!
//! A PX4 ULog ([`ulog::read`]) or an ArduPilot DataFlash log ([`dataflash::read`]) is read into a [`FlightLog`]: every magnetometer instance with the calibration the
//! autopilot applied to it ([`LoggedCalibration`], from `CAL_MAGn_*`), the attitude, the battery current, the GPS
//! fixes. [`FlightLog::recording`] turns one instance into a [`magcal_recording::Recording`]: the chip's own field
//! (the logged calibration undone), the attitude as quaternions from sensor axes into NED, the current as an
//! `i_battery` channel, the temperature where logged, the place and date of the first GPS fix for the World
//! Magnetic Model. The estimator's heading is partly the compass's own: [`heading`] fits the calibration to the
//! field's magnitude and dip only, and gives the reference the heading of that fit.

pub mod calibration;
pub mod dataflash;
pub mod error;
pub mod heading;
pub mod recording;
pub mod rotation;
pub mod series;
pub mod ulog;

pub use calibration::LoggedCalibration;
pub use error::LogError;
pub use recording::{FlightRecording, Instance};

use series::Series;

/// Reads a flight log by its extension: `.bin` as ArduPilot DataFlash, anything else as PX4 ULog.
pub fn read(path: &std::path::Path) -> Result<FlightLog, LogError> {
    let dataflash = path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("bin"));
    if dataflash {
        dataflash::read(path)
    } else {
        ulog::read(path)
    }
}

/// One magnetometer as logged.
#[derive(Debug, Clone)]
pub struct MagStream {
    /// The instance number (`multi_id`) of its topic.
    pub instance: u8,
    /// The topic it came from (`sensor_mag`: the driver's output; `vehicle_magnetometer`: after the calibration).
    pub topic: &'static str,
    /// The device id, where logged (`CAL_MAGn_ID` names the same number).
    pub device_id: Option<u32>,
    /// Whether the logged values have the calibration applied (and are in body axes).
    pub calibrated: bool,
    /// The field as logged, gauss, with the time of each sample.
    pub field_g: Series<[f64; 3]>,
    /// The chip's temperature, °C, where logged (NaN where missing).
    pub temp_c: Option<Vec<f64>>,
    /// The calibration the autopilot applied to it, found by device id (or the only one enabled).
    pub calibration: Option<LoggedCalibration>,
    /// For a calibrated stream: the bias PX4's magnetometer bias estimator had subtracted (body axes, gauss, held
    /// from each valid `magnetometer_bias_estimate` until the next; PX4 1.12 and later, `SENS_MAG_AUTOCAL`).
    pub estimator_bias_g: Option<Series<[f64; 3]>>,
}

/// A GPS fix.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GpsFix {
    /// Time, µs since the autopilot started.
    pub t_us: u64,
    /// Latitude, degrees north.
    pub lat_deg: f64,
    /// Longitude, degrees east.
    pub lon_deg: f64,
    /// Altitude above mean sea level, m.
    pub alt_m: f64,
    /// UTC, µs since 1970 (0 where the receiver had none).
    pub utc_us: u64,
    /// Fix type (3: 3-D fix and better).
    pub fix_type: u8,
}

/// What a flight log holds for a calibration.
#[derive(Debug, Clone)]
pub struct FlightLog {
    /// The file, as named to the user.
    pub file: String,
    /// The autopilot's hardware (`ver_hw`), where logged.
    pub hardware: Option<String>,
    /// Every magnetometer found, in topic then instance order.
    pub mags: Vec<MagStream>,
    /// Attitude: body (FRD) into NED, `[w, x, y, z]`.
    pub attitude: Series<[f64; 4]>,
    /// Battery current, A (`battery_status.current_a`, instance 0), where logged.
    pub current_a: Option<Series<f64>>,
    /// Every GPS sample (with or without a fix).
    pub gps: Vec<GpsFix>,
    /// The parameters at the start of the log.
    pub params: std::collections::BTreeMap<String, f64>,
    /// What the reader noticed that the user should know (a truncated log, calibration changed in flight).
    pub notes: Vec<String>,
}

impl FlightLog {
    /// The first GPS sample with a 3-D fix.
    pub fn first_fix(&self) -> Option<&GpsFix> {
        self.gps
            .iter()
            .find(|g| g.fix_type >= 3 && (g.lat_deg != 0.0 || g.lon_deg != 0.0))
    }

    /// The instance a fit takes unless told: the raw (`sensor_mag`) stream of the magnetometer the autopilot used
    /// (`CAL_MAG_PRIME`, else the highest `CAL_MAGn_PRIO`, else the one `vehicle_magnetometer` names), else the
    /// first raw stream, else the first stream.
    pub fn default_instance(&self) -> Option<usize> {
        let used = self.used_device_id();
        let raw = |m: &MagStream| !m.calibrated;
        self.mags
            .iter()
            .position(|m| raw(m) && used.is_some() && m.device_id == used)
            .or_else(|| self.mags.iter().position(raw))
            .or_else(|| (!self.mags.is_empty()).then_some(0))
    }

    /// The device id of the magnetometer the autopilot used for its heading.
    fn used_device_id(&self) -> Option<u32> {
        if let Some(prime) = self.params.get("CAL_MAG_PRIME").filter(|p| **p != 0.0) {
            return Some(*prime as u32);
        }
        let best = (0..4)
            .filter_map(|n| {
                let id = *self.params.get(&format!("CAL_MAG{n}_ID"))?;
                let prio = *self.params.get(&format!("CAL_MAG{n}_PRIO"))?;
                (id != 0.0 && prio > 0.0).then_some((prio, id as u32))
            })
            .max_by(|a, b| a.0.total_cmp(&b.0));
        best.map(|(_, id)| id).or_else(|| {
            self.mags
                .iter()
                .find(|m| m.topic == "vehicle_magnetometer")
                .and_then(|m| m.device_id)
        })
    }
}
