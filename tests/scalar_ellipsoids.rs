//! Acceptance: the scalar solver on simulated ellipsoids (hard iron up to 50 µT, soft iron up to 20 %) fits |B| to the
//! noise, and a planar rotation is refused with a message that names the unobserved axis.

mod common;

use magcal_app::calibrate::calibrate;
use magcal_app::field::ReferenceField;
use magcal_app::fit::Method;
use magcal_calib::frames;
use magcal_sim::{
    AttitudeOutput, ChipModel, Scenario, SensorTruth, Trajectory, simulate, stream_rng,
};

#[test]
fn the_magnitude_residual_sits_at_the_noise_for_strong_distortions() {
    let chip = ChipModel::by_name("lis3mdl").unwrap();
    for seed in 0..12 {
        let mut s = Scenario::new(
            &chip,
            Trajectory::Tumble {
                duration_s: 90.0,
                rate_rad_s: 1.0,
            },
            seed,
        );
        s.sensor = SensorTruth::random(0.2, 50.0, 2.0, &mut stream_rng(seed, 16));
        s.attitude = AttitudeOutput::None;
        let sigma = 0.05 + 0.05 * seed as f64;
        s.noise_ut = [sigma; 3];
        let run = simulate(&s).unwrap();
        let field = ReferenceField::Magnitude {
            field_ut: frames::norm(s.field_ned_ut),
            source: "test".into(),
        };
        let cal = calibrate(&run.recording, Method::Scalar, field, false).unwrap();
        // The noise of |B| is the calibrated noise A·n projected on the field direction.
        let a = s.sensor.a;
        let radial2: f64 = run
            .truth
            .field_ut
            .iter()
            .map(|b| {
                let u = frames::scale(*b, 1.0 / frames::norm(*b));
                let au = frames::mat_t_vec(&a, u);
                sigma * sigma * frames::dot(au, au)
            })
            .sum::<f64>()
            / run.truth.field_ut.len() as f64;
        // Quantisation at the chip's LSB adds LSB²/12 per axis.
        let expected = (radial2 + chip.lsb_ut.powi(2) / 12.0).sqrt();
        let ratio = cal.residual_rms_ut / expected;
        assert!(
            (ratio - 1.0).abs() < 0.1,
            "seed {seed}: residual {} vs noise {expected}",
            cal.residual_rms_ut
        );
        let floor_ratio = cal.residual_rms_ut / cal.noise_floor_ut;
        assert!(
            (floor_ratio - 1.0).abs() < 0.1,
            "seed {seed}: residual {} vs measured floor {}",
            cal.residual_rms_ut,
            cal.noise_floor_ut
        );
    }
}

#[test]
fn a_planar_rotation_is_refused_naming_the_axis_and_how_to_rotate() {
    let dir = tempfile::tempdir().unwrap();
    let rec = common::simulate(
        dir.path(),
        "turntable.csv",
        &[
            "--routine",
            "turntable",
            "--duration",
            "30",
            "--errors",
            "0.05,20,1",
            "--reference",
            "none",
        ],
    );
    let params = dir.path().join("params.toml");
    for method in ["scalar", "auto"] {
        let out = common::magcal_fit(&[
            rec.to_str().unwrap(),
            "--method",
            method,
            "--out",
            params.to_str().unwrap(),
        ]);
        assert!(!out.status.success());
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            err.contains("planar rotation") && err.contains("≈ +Z") && !err.contains("two centres"),
            "{err}"
        );
        assert!(
            err.contains("tip the sensor") || err.contains("cube24"),
            "{err}"
        );
        assert!(
            !params.exists(),
            "no parameters may be written for a refused fit"
        );
    }
}
