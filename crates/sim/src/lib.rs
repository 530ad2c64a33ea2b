//! The physics forward model of a magnetometer on the bench, shared with the fitter.
//!
//! A [`Scenario`] says what is simulated: the world field (NED), an attitude [`Trajectory`] (smooth random tumble,
//! the 24 static poses of a cube jig, a single-axis turntable), the sensor's true calibration ([`SensorTruth`]: soft
//! and hard iron, mounting misalignment), the effects from [`magcal_calib::effects`] it suffers, temperature and
//! current channels, white noise and quantisation to the chip's LSB. [`simulate`] turns it into a
//! [`magcal_recording::Recording`], deterministically from the scenario's seed.
//!
//! [`bench`](mod@bench) is the same physics sampled at any time, for simulated chips: a virtual hand turns the sensor as a
//! recorder asks. [`ulog`] and [`dataflash`] write a simulated flight as a PX4 ULog or an ArduPilot DataFlash log.
//!
//! The sensor model is the calibration model run backwards: with the true `A`, `b` and effects `δ`,
//! the raw reading is `B̂ = A⁻¹·(B + Σδ − b) + noise`, quantised.

pub mod bench;
pub mod chips;
pub mod dataflash;
mod environment;
mod noise;
mod scenario;
mod sensor;
pub mod study;
mod trajectory;
pub mod ulog;

pub use chips::ChipModel;
pub use environment::{CurrentProfile, TemperatureProfile};
pub use noise::NoiseKind;
pub use scenario::{AttitudeOutput, Scenario, SimError, SimRun, Truth, simulate};
pub use sensor::SensorTruth;
pub use trajectory::{CubePose, Pose, Trajectory, cube24_poses};

/// An RNG for one independent stream of a seed, so that changing one part of a scenario leaves the random draws of the
/// others as they were. [`simulate`] uses streams 1 (trajectory), 2 (environment) and 3 (noise); callers drawing
/// other parts of a scenario from the same seed (a random sensor, say) use stream 0 or streams from 16 up.
pub fn stream_rng(seed: u64, stream: u64) -> rand_chacha::ChaCha8Rng {
    use rand::SeedableRng;
    rand_chacha::ChaCha8Rng::seed_from_u64(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ stream)
}
