//! The seed paper's experiment, simulated: vector against scalar calibration of a misaligned sensor, and the paper's
//! 35 µT check in the form of its table.
//!
//! The sensor's own distortion is the inverse of the paper's `a`, `b` (so a perfect calibration in the sensor's axes
//! would return them), and it is mounted `mount_deg` off the reference axes. It tumbles in a 50 µT field with the
//! given noise; both methods are fitted; then the sensor sits with its reference axes on the world axes in a 35 µT
//! field along world z, and both calibrations are applied to its reading.

use magcal_calib::frames::{self, Mat3};
use magcal_calib::scalar::{self, ScalarFit, ScalarOptions};
use magcal_calib::vector::{self, VectorFit, VectorOptions};
use magcal_calib::{FitError, Inputs, noise};
use magcal_sim::{ChipModel, Scenario, SensorTruth, Trajectory, simulate};

use crate::export::Polar;

/// The seed paper's `a` (vector method, body-centre position).
pub const PAPER_A: Mat3 = [
    [0.4116, 0.0056, 0.0002],
    [-0.0004, 1.0129, 0.0004],
    [0.0005, -0.0001, 1.1823],
];
/// The seed paper's `b`, µT.
pub const PAPER_B_UT: [f64; 3] = [-4.2161, -8.4722, 1.2469];

/// The experiment's settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SeedExperiment {
    /// Mounting misalignment, degrees (about the axis [1, 2, 0.5], normalised).
    pub mount_deg: f64,
    /// Raw noise per axis, µT.
    pub noise_ut: f64,
    /// Recording length, s.
    pub duration_s: f64,
    /// Sample rate, Hz.
    pub rate_hz: f64,
    /// Seed.
    pub seed: u64,
}

impl Default for SeedExperiment {
    /// 3° off, 0.1 µT noise (a good bench magnetometer at moderate bandwidth), 2 minutes at 50 Hz.
    fn default() -> SeedExperiment {
        SeedExperiment {
            mount_deg: 3.0,
            noise_ut: 0.1,
            duration_s: 120.0,
            rate_hz: 50.0,
            seed: 2018,
        }
    }
}

/// The largest noise the experiment takes, µT: a fifth of its 50 µT field (beyond, the scalar fit fails to find
/// an ellipsoid).
pub const MAX_NOISE_UT: f64 = 10.0;
/// The largest misalignment, degrees, either way.
pub const MAX_MOUNT_DEG: f64 = 180.0;

impl SeedExperiment {
    /// Checks the settings against their ranges before anything is simulated.
    pub fn check(&self) -> Result<(), crate::device::BadOption> {
        use crate::device::within;
        within("--noise", self.noise_ut, 0.0, MAX_NOISE_UT, "µT")?;
        within(
            "--mount-deg",
            self.mount_deg,
            -MAX_MOUNT_DEG,
            MAX_MOUNT_DEG,
            "°",
        )
    }
}

/// What the experiment found.
#[derive(Clone, Debug, PartialEq)]
pub struct SeedComparison {
    /// The settings.
    pub experiment: SeedExperiment,
    /// The sensor's true calibration in the reference axes.
    pub truth: SensorTruth,
    /// Rotation angle between the sensor's and the reference's axes as a calibration sees it (polar decomposition
    /// of the true `A`), degrees.
    pub rotation_deg: f64,
    /// The raw reading in the 35 µT check.
    pub raw_ut: [f64; 3],
    /// The vector fit.
    pub vector: VectorFit,
    /// The scalar fit.
    pub scalar: ScalarFit,
    /// Vector-calibrated check reading, µT.
    pub vector_ut: [f64; 3],
    /// Its standard error from the fit's covariance, µT.
    pub vector_se_ut: [f64; 3],
    /// Scalar-calibrated check reading, µT.
    pub scalar_ut: [f64; 3],
}

/// The ideal reading in the check: 35 µT along world z, sensor reference axes on the world axes.
pub const CHECK_UT: [f64; 3] = [0.0, 0.0, 35.0];

/// Runs the experiment.
pub fn run(exp: &SeedExperiment) -> Result<SeedComparison, FitError> {
    let axis = {
        let v = [1.0, 2.0, 0.5];
        frames::scale(v, exp.mount_deg.to_radians() / frames::norm(v))
    };
    // The paper's a, b are the sensor's own calibration (in its axes); its distortion is their inverse.
    let truth = SensorTruth::mounted(PAPER_A, PAPER_B_UT, axis);
    let chip = ChipModel::by_name("lis3mdl").expect("known chip");
    let mut s = Scenario::new(
        &chip,
        Trajectory::Tumble {
            duration_s: exp.duration_s,
            rate_rad_s: 1.0,
        },
        exp.seed,
    );
    s.sample_rate_hz = exp.rate_hz;
    s.field_ned_ut = frames::field_from_angles(2.0, 62.0, 50.0);
    s.sensor = truth;
    s.noise_ut = [exp.noise_ut; 3];
    s.lsb_ut = None;
    s.temperature = None;
    let run = simulate(&s).expect("a valid scenario");
    let rec = &run.recording;
    let expected: Vec<[f64; 3]> = rec
        .quat
        .as_ref()
        .expect("the scenario records the attitude")
        .iter()
        .map(|q| frames::expected_sensor_field(*q, s.field_ned_ut))
        .collect();
    let floor = noise::estimate(&rec.mag_ut, Some(&expected));
    let vector = vector::fit(
        &rec.mag_ut,
        &expected,
        &VectorOptions {
            raw_noise_var_ut2: floor.floor_ut.map(|f| f * f),
            ..Default::default()
        },
    )?;
    let scalar = scalar::fit(
        &rec.mag_ut,
        &ScalarOptions {
            field_ut: Some(50.0),
            ..Default::default()
        },
    )?;
    let raw_ut = truth.forward()(CHECK_UT);
    Ok(SeedComparison {
        experiment: *exp,
        truth,
        rotation_deg: Polar::of(&truth.a).angle_deg(),
        raw_ut,
        vector_ut: vector.model().apply(raw_ut, &Inputs::NONE),
        vector_se_ut: vector.field_se_ut(raw_ut),
        scalar_ut: scalar.model().apply(raw_ut, &Inputs::NONE),
        vector,
        scalar,
    })
}

/// The comparison in the form of the paper's table.
pub fn table(c: &SeedComparison) -> String {
    let e = &c.experiment;
    let mut out = format!(
        "Seed paper experiment, simulated: sensor distortion = inverse of the paper's a, b; mounted {:.1}° off the \
         reference axes;\n{:.0} s of tumbling at {:.0} Hz in a 50 µT field, noise {:.2} µT per axis (seed {}).\n\
         Check: reference axes on the world axes, 35 µT along world z (ideal reading 0, 0, 35).\n\n",
        e.mount_deg, e.duration_s, e.rate_hz, e.noise_ut, e.seed
    );
    out += "| component | ideal | measured (raw) | vector-calibrated | scalar-calibrated |\n";
    out += "|---|---|---|---|---|\n";
    for (k, name) in ["Bx", "By", "Bz"].iter().enumerate() {
        out += &format!(
            "| {name} | {:.0} | {:.4} | {:.4} ± {:.4} | {:.4} |\n",
            CHECK_UT[k], c.raw_ut[k], c.vector_ut[k], c.vector_se_ut[k], c.scalar_ut[k]
        );
    }
    out += &format!(
        "| \\|B\\| | 35 | {:.4} | {:.4} | {:.4} |\n\n",
        frames::norm(c.raw_ut),
        frames::norm(c.vector_ut),
        frames::norm(c.scalar_ut)
    );
    let err = |v: [f64; 3]| frames::norm(frames::sub(v, CHECK_UT));
    out += &format!(
        "Component error: vector {:.4} µT, scalar {:.4} µT. The scalar method cannot see the {:.2}° rotation between \
         sensor and reference axes;\n|B|·angle = {:.3} µT is the component error it must leave.\n",
        err(c.vector_ut),
        err(c.scalar_ut),
        c.rotation_deg,
        35.0 * c.rotation_deg.to_radians()
    );
    out
}
