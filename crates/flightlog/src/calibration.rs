//! The calibration PX4 applied to a magnetometer before logging it, from the log's parameters, as PX4 documents and
//! applies it (`src/lib/sensor_calibration/Magnetometer.hpp`): `corrected = R · S · (raw + power·COMP − OFF)`, in
//! gauss, where `OFF` is `CAL_MAGn_{X,Y,Z}OFF`, `S` the symmetric matrix with `CAL_MAGn_{X,Y,Z}SCALE` on its diagonal
//! and `CAL_MAGn_{X,Y,Z}ODIAG` off it (XODIAG at (0,1), YODIAG at (0,2), ZODIAG at (1,2)), `COMP` the motor
//! compensation `CAL_MAGn_{X,Y,Z}COMP` scaled by `power` (`CAL_MAG_COMP_TYP` 2 or 3: the battery current in kA;
//! 1: the throttle, 0 to 1), and `R` the rotation from sensor into body axes: `CAL_MAGn_ROT` for an external
//! magnetometer, the board's `SENS_BOARD_ROT` for an internal one (`CAL_MAGn_ROT` = −1).

use std::collections::BTreeMap;

use magcal_calib::frames::{IDENTITY, Mat3, mat_t_vec, mat_vec};
use nalgebra::Matrix3;

use crate::rotation::sensor_to_body;

/// One `CAL_MAGn_*` slot as logged.
#[derive(Debug, Clone, PartialEq)]
pub struct LoggedCalibration {
    /// The parameters' name in words (`CAL_MAG0`, `COMPASS_*2`).
    pub name: String,
    /// The slot `n` of `CAL_MAGn_*` (PX4), the compass instance (ArduPilot).
    pub slot: u8,
    /// `CAL_MAGn_ID`: the device the slot belongs to.
    pub device_id: u32,
    /// `CAL_MAGn_{X,Y,Z}OFF`, gauss, sensor axes.
    pub offset_g: [f64; 3],
    /// `S`: `CAL_MAGn_{X,Y,Z}SCALE` on the diagonal, `CAL_MAGn_{X,Y,Z}ODIAG` off it.
    pub scale: Mat3,
    /// `R`: sensor axes into body (FRD) axes.
    pub rotation: Mat3,
    /// Where `R` came from, in words.
    pub rotation_source: String,
    /// `CAL_MAGn_{X,Y,Z}COMP`: gauss per kA (compensation types 2, 3) or per unit of throttle (type 1).
    pub comp: [f64; 3],
    /// `CAL_MAG_COMP_TYP` (0: none, 1: throttle, 2: current of battery 0, 3: of battery 1).
    pub comp_type: i64,
    /// Whether the autopilot uses it (`CAL_MAGn_PRIO` > 0 or `CAL_MAGn_EN` = 1; true where neither is logged).
    pub enabled: bool,
}

/// A parameter by name.
fn get(params: &BTreeMap<String, f64>, name: &str) -> Option<f64> {
    params.get(name).copied()
}

impl LoggedCalibration {
    /// Slot `n` of the parameters, if its `CAL_MAGn_ID` is logged and not 0.
    pub fn from_params(params: &BTreeMap<String, f64>, n: u8) -> Option<LoggedCalibration> {
        let p = |suffix: &str| get(params, &format!("CAL_MAG{n}_{suffix}"));
        let device_id = p("ID").filter(|id| *id != 0.0)? as i64 as u32;
        let axes = |kind: &str, default: f64| -> [f64; 3] {
            ["X", "Y", "Z"].map(|a| p(&format!("{a}{kind}")).unwrap_or(default))
        };
        let (diag, off) = (axes("SCALE", 1.0), axes("ODIAG", 0.0));
        let scale = [
            [diag[0], off[0], off[1]],
            [off[0], diag[1], off[2]],
            [off[1], off[2], diag[2]],
        ];
        let rot = p("ROT").unwrap_or(-1.0) as i64;
        let (rotation, rotation_source) = match sensor_to_body(rot) {
            Some(r) => (r, format!("CAL_MAG{n}_ROT = {rot} (external)")),
            None => {
                let board = get(params, "SENS_BOARD_ROT").unwrap_or(0.0) as i64;
                match sensor_to_body(board) {
                    Some(r) => (r, format!("SENS_BOARD_ROT = {board} (internal)")),
                    None => (
                        IDENTITY,
                        format!("SENS_BOARD_ROT = {board} unknown: taken as none"),
                    ),
                }
            }
        };
        let enabled = match (p("PRIO"), p("EN")) {
            (Some(prio), _) => prio > 0.0,
            (None, Some(en)) => en != 0.0,
            (None, None) => true,
        };
        Some(LoggedCalibration {
            name: format!("CAL_MAG{n}"),
            slot: n,
            device_id,
            offset_g: axes("OFF", 0.0),
            scale,
            rotation,
            rotation_source,
            comp: axes("COMP", 0.0),
            comp_type: get(params, "CAL_MAG_COMP_TYP").unwrap_or(0.0) as i64,
            enabled,
        })
    }

    /// ArduPilot's parameter suffix of compass instance `n`: none, `2`, `3`.
    fn ardupilot_suffix(n: u8) -> String {
        if n == 0 {
            String::new()
        } else {
            (n + 1).to_string()
        }
    }

    /// ArduPilot's device id of compass instance `n` (`COMPASS_DEV_ID`, `COMPASS_DEV_ID2`, …), where logged.
    pub fn ardupilot_device_id(params: &BTreeMap<String, f64>, n: u8) -> Option<u32> {
        let id = get(
            params,
            &format!("COMPASS_DEV_ID{}", Self::ardupilot_suffix(n)),
        )?;
        (id != 0.0).then_some(id as i64 as u32)
    }

    /// ArduPilot's calibration of compass instance `n`, as `AP_Compass_Backend::correct_field` applies it (current
    /// versions): `M·(SCALE·(raw + OFS)) + MOT·I` in mGauss, after the rotation into body axes, `M` symmetric with
    /// `COMPASS_DIA_*` on its diagonal and `COMPASS_ODI_*` off it, `MOT` in mGauss/A with `COMPASS_MOTCT` = 2. Written
    /// in PX4's form (gauss, `R` = none: the axes are the body's), `COMP = S⁻¹·MOT` (1 mGauss/A = 1 G/kA). `None`
    /// without `COMPASS_OFS*_X` in the parameters.
    pub fn from_ardupilot(params: &BTreeMap<String, f64>, n: u8) -> Option<LoggedCalibration> {
        let sfx = Self::ardupilot_suffix(n);
        let axes = |kind: &str, default: f64| -> [f64; 3] {
            ["X", "Y", "Z"]
                .map(|a| get(params, &format!("COMPASS_{kind}{sfx}_{a}")).unwrap_or(default))
        };
        get(params, &format!("COMPASS_OFS{sfx}_X"))?;
        let scale = get(params, &format!("COMPASS_SCALE{sfx}"))
            .filter(|s| *s > 0.0)
            .unwrap_or(1.0);
        let dia = axes("DIA", 1.0);
        let dia = if dia == [0.0; 3] { [1.0; 3] } else { dia };
        let odi = axes("ODI", 0.0);
        let m = [
            [dia[0], odi[0], odi[1]],
            [odi[0], dia[1], odi[2]],
            [odi[1], odi[2], dia[2]],
        ];
        let s = m.map(|row| row.map(|v| v * scale));
        let mot_g_per_ka = axes("MOT", 0.0).map(|v| v * 1e-3 * 1e3);
        let comp = Matrix3::from_fn(|r, c| s[r][c])
            .try_inverse()
            .map_or([0.0; 3], |inv| {
                (inv * nalgebra::Vector3::from(mot_g_per_ka)).into()
            });
        let motct = get(params, "COMPASS_MOTCT").unwrap_or(0.0) as i64;
        Some(LoggedCalibration {
            name: format!("COMPASS_*{sfx} (instance {n})"),
            slot: n,
            device_id: Self::ardupilot_device_id(params, n).unwrap_or(0),
            offset_g: axes("OFS", 0.0).map(|v| -v * 1e-3),
            scale: s,
            rotation: IDENTITY,
            rotation_source: "applied before the calibration (the axes are the body's)".to_owned(),
            comp,
            comp_type: if motct == 2 { 2 } else { motct.min(1) },
            enabled: get(params, &format!("COMPASS_USE{sfx}")).is_none_or(|u| u != 0.0),
        })
    }

    /// Every slot of the parameters with a device.
    pub fn all(params: &BTreeMap<String, f64>) -> Vec<LoggedCalibration> {
        (0..4)
            .filter_map(|n| LoggedCalibration::from_params(params, n))
            .collect()
    }

    /// The battery current's share of the compensation, the `power` PX4 multiplies `COMP` by, for a current in A:
    /// kA for compensation types 2 and 3, nothing for the others.
    pub fn power(&self, current_a: f64) -> f64 {
        match self.comp_type {
            2 | 3 if current_a.is_finite() => current_a / 1000.0,
            _ => 0.0,
        }
    }

    /// The calibrated field in sensor axes (before the rotation into body axes), gauss: `S·(raw + power·COMP − OFF)`.
    pub fn apply_in_sensor_axes(&self, raw_g: [f64; 3], power: f64) -> [f64; 3] {
        let v = std::array::from_fn(|k| raw_g[k] + power * self.comp[k] - self.offset_g[k]);
        mat_vec(&self.scale, v)
    }

    /// The raw reading behind a logged calibrated one in body axes, gauss: `S⁻¹·Rᵀ·body − power·COMP + OFF`; `None`
    /// if `S` is singular.
    pub fn undo(&self, body_g: [f64; 3], power: f64) -> Option<[f64; 3]> {
        let s = Matrix3::from_fn(|r, c| self.scale[r][c]).try_inverse()?;
        let sensor = mat_t_vec(&self.rotation, body_g);
        let v = s * nalgebra::Vector3::from(sensor);
        Some(std::array::from_fn(|k| {
            v[k] - power * self.comp[k] + self.offset_g[k]
        }))
    }

    /// The slot in words, µT: offsets, scales, off-diagonals, rotation, compensation.
    pub fn describe(&self) -> String {
        let ut = |v: [f64; 3]| {
            let [x, y, z] = v.map(|g| g * 100.0);
            format!("{x:.2}, {y:.2}, {z:.2}")
        };
        let s = &self.scale;
        let comp = if self.comp_type == 0 || self.comp == [0.0; 3] {
            "no motor compensation".to_owned()
        } else {
            format!(
                "motor compensation (type {}) {:.4}, {:.4}, {:.4} G per unit",
                self.comp_type, self.comp[0], self.comp[1], self.comp[2]
            )
        };
        format!(
            "{name} ({id}{used}): offsets {off} µT, scales {:.4}, {:.4}, {:.4}, off-diagonals {:.4}, {:.4}, \
             {:.4}, rotation {rot}, {comp}",
            s[0][0],
            s[1][1],
            s[2][2],
            s[0][1],
            s[0][2],
            s[1][2],
            name = self.name,
            id = if self.device_id == 0 {
                "device unknown".to_owned()
            } else {
                format!("device {}", self.device_id)
            },
            used = if self.enabled { "" } else { ", disabled" },
            off = ut(self.offset_g),
            rot = self.rotation_source,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params() -> BTreeMap<String, f64> {
        [
            ("CAL_MAG1_ID", 396321.0),
            ("CAL_MAG1_XOFF", -0.07),
            ("CAL_MAG1_YOFF", -0.1),
            ("CAL_MAG1_ZOFF", 0.08),
            ("CAL_MAG1_XSCALE", 0.95),
            ("CAL_MAG1_YSCALE", 1.0),
            ("CAL_MAG1_ZSCALE", 1.05),
            ("CAL_MAG1_XODIAG", 0.002),
            ("CAL_MAG1_YODIAG", -0.04),
            ("CAL_MAG1_ZODIAG", -0.02),
            ("CAL_MAG1_ROT", -1.0),
            ("CAL_MAG1_XCOMP", 0.3),
            ("CAL_MAG1_YCOMP", -0.1),
            ("CAL_MAG1_ZCOMP", 0.5),
            ("CAL_MAG_COMP_TYP", 2.0),
            ("SENS_BOARD_ROT", 2.0),
        ]
        .into_iter()
        .map(|(k, v)| (k.to_owned(), v))
        .collect()
    }

    #[test]
    fn undo_inverts_what_px4_applies() {
        let cal = LoggedCalibration::from_params(&params(), 1).unwrap();
        assert!(cal.rotation_source.contains("internal"));
        let raw = [0.21, -0.05, 0.43];
        let power = cal.power(40.0);
        let body = mat_vec(&cal.rotation, cal.apply_in_sensor_axes(raw, power));
        let back = cal.undo(body, power).unwrap();
        for k in 0..3 {
            assert!((back[k] - raw[k]).abs() < 1e-12, "{back:?}");
        }
        assert!(LoggedCalibration::from_params(&params(), 0).is_none());
    }

    #[test]
    fn the_slot_reads_as_px4_lays_it_out() {
        let cal = LoggedCalibration::from_params(&params(), 1).unwrap();
        assert_eq!(cal.scale[0][1], 0.002);
        assert_eq!(cal.scale[2][0], -0.04);
        assert_eq!(cal.scale[2][1], -0.02);
        // Yaw 90: sensor x is body y.
        assert_eq!(mat_vec(&cal.rotation, [1.0, 0.0, 0.0]), [0.0, 1.0, 0.0]);
        assert!(cal.describe().contains("offsets -7.00, -10.00, 8.00 µT"));
    }
}
