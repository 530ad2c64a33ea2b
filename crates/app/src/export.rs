//! Parameters in other tools' conventions (`--export ardupilot|px4|c-header|json`).
//!
//! magcal's model is `B = A·B̂ + b` (µT). The others differ in sign, order and units:
//! - **ArduPilot** corrects `M·(raw + OFS)`, OFS in milligauss added *before* the symmetric matrix
//!   `M = [[DIA_X, ODI_X, ODI_Y], [ODI_X, DIA_Y, ODI_Z], [ODI_Y, ODI_Z, DIA_Z]]`; so `OFS = A⁻¹·b` (= −centre) in
//!   mGauss (1 µT = 10 mGauss).
//! - **PX4** corrects `R·S·(raw − OFF)`, OFF in gauss *subtracted*, `S` symmetric with XSCALE/YSCALE/ZSCALE on the
//!   diagonal and XODIAG (xy), YODIAG (xz), ZODIAG (yz); so `OFF = −A⁻¹·b` (= centre) in gauss (1 µT = 0.01 G).
//!
//! Both matrices are symmetric, and `A` from a vector fit is not (it includes the sensor's misalignment): `A` is split
//! as `A = R·S` (polar decomposition), `S` is exported and the rotation `R` is reported in a comment — set it as the
//! board orientation if it matters. The offsets are exact either way, since `A⁻¹·b = S⁻¹·R⁻¹·b` is what both apply.

use magcal_calib::Model;
use nalgebra::{Matrix3, Vector3};

/// An export format.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum ExportFormat {
    /// ArduPilot `.param` (COMPASS_OFS/DIA/ODI).
    Ardupilot,
    /// PX4 / QGroundControl `.params` (CAL_MAG0_*).
    Px4,
    /// A C header with `A` and `b`.
    CHeader,
    /// JSON with `A`, `b_ut` and the offset.
    Json,
}

/// `A = R·S`, `R` a rotation and `S` symmetric positive definite.
pub struct Polar {
    /// The rotation.
    pub rotation: Matrix3<f64>,
    /// The symmetric part.
    pub symmetric: Matrix3<f64>,
}

impl Polar {
    /// The polar decomposition of `a` (via its SVD `U·Σ·Vᵀ`: `R = U·Vᵀ`, `S = V·Σ·Vᵀ`).
    pub fn of(a: &[[f64; 3]; 3]) -> Polar {
        let m = Matrix3::from_fn(|j, k| a[j][k]);
        let svd = m.svd(true, true);
        let (u, v_t) = (svd.u.expect("u requested"), svd.v_t.expect("v_t requested"));
        let rotation = u * v_t;
        let symmetric = v_t.transpose() * Matrix3::from_diagonal(&svd.singular_values) * v_t;
        Polar {
            rotation,
            symmetric,
        }
    }

    /// The rotation's angle, degrees.
    pub fn angle_deg(&self) -> f64 {
        ((self.rotation.trace() - 1.0) / 2.0)
            .clamp(-1.0, 1.0)
            .acos()
            .to_degrees()
    }
}

/// The model in another tool's format. Only the linear part can be exported; body-fixed corrections are listed in a
/// comment where the format has comments. `fitted_without` is the number of corrections of the final model this
/// `A` and `b` were fitted without (see [`crate::verdict::target_model`]), said in the same comment.
pub fn export(model: &Model, format: ExportFormat, fitted_without: usize) -> String {
    let a = Matrix3::from_fn(|j, k| model.a[j][k]);
    let centre = -(a.try_inverse().unwrap_or_else(Matrix3::zeros) * Vector3::from(model.b_ut));
    let polar = Polar::of(&model.a);
    let s = polar.symmetric;
    let dropped = model.corrections().count();
    let mut notes = vec![format!(
        "misalignment rotation of {:.3} deg left out (the target's matrix is symmetric)",
        polar.angle_deg()
    )];
    if dropped > 0 {
        notes.push(format!(
            "{dropped} body-fixed correction(s) left out (the target has no place for them)"
        ));
    } else if fitted_without > 0 {
        notes.push(format!(
            "A and b fitted without the {fitted_without} body-fixed correction(s) the parameters file holds (the \
             target has no place for them)"
        ));
    }
    let dropped = dropped + fitted_without;
    match format {
        ExportFormat::Ardupilot => {
            let mut out = String::from(
                "# magcal calibration for ArduPilot: corrected = M·(raw + OFS), OFS in mGauss\n",
            );
            for n in &notes {
                out += &format!("# {n}\n");
            }
            let ofs = -centre * 10.0;
            for (k, axis) in ["X", "Y", "Z"].iter().enumerate() {
                out += &format!("COMPASS_OFS_{axis},{:.3}\n", ofs[k]);
            }
            for (k, axis) in ["X", "Y", "Z"].iter().enumerate() {
                out += &format!("COMPASS_DIA_{axis},{:.6}\n", s[(k, k)]);
            }
            for (name, (r, c)) in [("X", (0, 1)), ("Y", (0, 2)), ("Z", (1, 2))] {
                out += &format!("COMPASS_ODI_{name},{:.6}\n", s[(r, c)]);
            }
            out
        }
        ExportFormat::Px4 => {
            let mut out = String::from(
                "# magcal calibration for PX4 (QGroundControl .params): corrected = S·(raw − OFF), OFF in gauss\n",
            );
            for n in &notes {
                out += &format!("# {n}\n");
            }
            out += "# Vehicle-Id\tComponent-Id\tName\tValue\tType\n";
            let mut param =
                |name: &str, v: f64| out += &format!("1\t1\tCAL_MAG0_{name}\t{v:.9}\t9\n");
            for (k, axis) in ["X", "Y", "Z"].iter().enumerate() {
                param(&format!("{axis}OFF"), centre[k] / 100.0);
            }
            for (k, axis) in ["X", "Y", "Z"].iter().enumerate() {
                param(&format!("{axis}SCALE"), s[(k, k)]);
            }
            for (name, (r, c)) in [("X", (0, 1)), ("Y", (0, 2)), ("Z", (1, 2))] {
                param(&format!("{name}ODIAG"), s[(r, c)]);
            }
            out
        }
        ExportFormat::CHeader => {
            let mut out = String::from(
                "/* magcal calibration: B = A * raw + b (microtesla, sensor axes). */\n#ifndef MAGCAL_CALIBRATION_H\n#define MAGCAL_CALIBRATION_H\n\n",
            );
            if dropped > 0 {
                out += &format!("/* {} */\n", notes[1]);
            }
            out += "static const float MAGCAL_A[3][3] = {\n";
            for row in &model.a {
                out += &format!(
                    "    {{ {:.9}f, {:.9}f, {:.9}f }},\n",
                    row[0], row[1], row[2]
                );
            }
            let b = model.b_ut;
            out += &format!(
                "}};\nstatic const float MAGCAL_B_UT[3] = {{ {:.6}f, {:.6}f, {:.6}f }};\n\n",
                b[0], b[1], b[2]
            );
            out += "#endif /* MAGCAL_CALIBRATION_H */\n";
            out
        }
        ExportFormat::Json => {
            let value = serde_json::json!({
                "model": "B = A*raw + b (uT, sensor axes)",
                "A": model.a,
                "b_ut": model.b_ut,
                "offset_ut": [centre.x, centre.y, centre.z],
                "notes": if dropped > 0 { vec![notes[1].clone()] } else { vec![] },
            });
            serde_json::to_string_pretty(&value).expect("plain data") + "\n"
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn value(text: &str, name: &str) -> f64 {
        text.lines()
            .find_map(|l| {
                let f: Vec<&str> = l.split([',', '\t']).collect();
                f.iter()
                    .position(|x| *x == name)
                    .map(|i| f[i + 1].parse().unwrap())
            })
            .unwrap_or_else(|| panic!("{name} not in\n{text}"))
    }

    fn skewed_model() -> (Model, Matrix3<f64>) {
        let s = Matrix3::new(1.1, 0.02, -0.01, 0.02, 0.95, 0.03, -0.01, 0.03, 1.05);
        let r = nalgebra::Rotation3::from_euler_angles(0.02, -0.01, 0.03).into_inner();
        let a = r * s;
        (
            Model::linear(
                std::array::from_fn(|j| std::array::from_fn(|k| a[(j, k)])),
                [12.0, -7.0, 30.0],
            ),
            s,
        )
    }

    /// Each format's own correction of a raw reading must give our calibrated field (up to the dropped rotation).
    #[test]
    fn ardupilot_and_px4_reproduce_our_correction_in_their_convention() {
        let (model, s) = skewed_model();
        let raw = Vector3::new(25.0, -40.0, 10.0);
        let ours = {
            let b = model.apply([raw.x, raw.y, raw.z], &magcal_calib::Inputs::NONE);
            Polar::of(&model.a).rotation.transpose() * Vector3::from(b)
        };
        let ap = export(&model, ExportFormat::Ardupilot, 0);
        let ofs = Vector3::new(
            value(&ap, "COMPASS_OFS_X"),
            value(&ap, "COMPASS_OFS_Y"),
            value(&ap, "COMPASS_OFS_Z"),
        );
        let m = Matrix3::new(
            value(&ap, "COMPASS_DIA_X"),
            value(&ap, "COMPASS_ODI_X"),
            value(&ap, "COMPASS_ODI_Y"),
            value(&ap, "COMPASS_ODI_X"),
            value(&ap, "COMPASS_DIA_Y"),
            value(&ap, "COMPASS_ODI_Z"),
            value(&ap, "COMPASS_ODI_Y"),
            value(&ap, "COMPASS_ODI_Z"),
            value(&ap, "COMPASS_DIA_Z"),
        );
        let ap_mg = m * (raw * 10.0 + ofs);
        assert!((ap_mg / 10.0 - ours).norm() < 1e-3, "{ap_mg} vs {ours}");
        assert!((m - s).norm() < 1e-5);

        let px = export(&model, ExportFormat::Px4, 0);
        let off = Vector3::new(
            value(&px, "CAL_MAG0_XOFF"),
            value(&px, "CAL_MAG0_YOFF"),
            value(&px, "CAL_MAG0_ZOFF"),
        );
        let sp = Matrix3::new(
            value(&px, "CAL_MAG0_XSCALE"),
            value(&px, "CAL_MAG0_XODIAG"),
            value(&px, "CAL_MAG0_YODIAG"),
            value(&px, "CAL_MAG0_XODIAG"),
            value(&px, "CAL_MAG0_YSCALE"),
            value(&px, "CAL_MAG0_ZODIAG"),
            value(&px, "CAL_MAG0_YODIAG"),
            value(&px, "CAL_MAG0_ZODIAG"),
            value(&px, "CAL_MAG0_ZSCALE"),
        );
        let px_g = sp * (raw / 100.0 - off);
        assert!((px_g * 100.0 - ours).norm() < 1e-4, "{px_g} vs {ours}");
        assert!(px.contains("misalignment rotation of"));
    }

    #[test]
    fn polar_decomposition_recovers_the_parts() {
        let (model, s) = skewed_model();
        let p = Polar::of(&model.a);
        assert!((p.symmetric - s).norm() < 1e-12);
        assert!((p.rotation.determinant() - 1.0).abs() < 1e-12);
        assert!(
            p.angle_deg() > 1.0 && p.angle_deg() < 3.0,
            "{}",
            p.angle_deg()
        );
    }

    #[test]
    fn the_c_header_and_json_carry_a_and_b() {
        let (model, _) = skewed_model();
        let h = export(&model, ExportFormat::CHeader, 2);
        assert!(h.contains("MAGCAL_A[3][3]") && h.contains("12.000000f"));
        assert!(
            h.contains("fitted without the 2 body-fixed correction(s)"),
            "{h}"
        );
        let j: serde_json::Value =
            serde_json::from_str(&export(&model, ExportFormat::Json, 0)).unwrap();
        assert_eq!(j["b_ut"][2].as_f64(), Some(30.0));
    }
}
