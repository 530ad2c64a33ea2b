//! A simulated production lot for `magcal-batch`'s tests and benchmark: boards of one chip kind whose hard and soft
//! iron and noise spread as a population's, some with a magnet near the sensor (a hard iron far from their
//! siblings'), some files cut off while written, some boards not turned enough.
#![allow(dead_code, reason = "the tests and the benchmark use different parts")]

use std::path::{Path, PathBuf};

use magcal_sim::{ChipModel, Scenario, SensorTruth, Trajectory, simulate};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

/// What is wrong with a board, if anything.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// A sound board.
    Normal,
    /// A magnet near the sensor: its hard iron is [`MAGNET_UT`] further along one axis.
    MagnetNear,
    /// The file was cut off in the middle of a row.
    Truncated,
    /// Turned about one axis only (a turntable): the fit refuses it.
    NotRotated,
}

/// The lot's hard iron: the median board's, µT, raw axes.
pub const HARD_IRON_UT: [f64; 3] = [8.0, -12.0, 20.0];
/// Its spread over the boards (a standard deviation per axis), µT.
pub const HARD_IRON_SPREAD_UT: f64 = 5.0;
/// The spread of `A`'s diagonal (scale errors) over the boards.
pub const SCALE_SPREAD: f64 = 0.03;
/// The spread of the soft iron's off-diagonal elements.
pub const CROSS_SPREAD: f64 = 0.01;
/// The spread of the mounting misalignment about each axis, degrees.
pub const MOUNT_SPREAD_DEG: f64 = 1.0;
/// How far a magnet near the sensor moves the hard iron along one axis, µT (at least; up to twice).
pub const MAGNET_UT: f64 = 60.0;

/// One simulated board.
#[derive(Clone, Debug)]
pub struct Board {
    /// Its serial, as written to the recording's metadata.
    pub serial: String,
    /// Its recording.
    pub path: PathBuf,
    /// What is wrong with it.
    pub kind: Kind,
    /// Its true calibration.
    pub truth: SensorTruth,
    /// Its true hard iron in raw axes, `−A⁻¹·b`, µT.
    pub offset_ut: [f64; 3],
}

/// How a lot is made.
#[derive(Clone, Debug)]
pub struct LotSpec {
    /// Boards in all.
    pub boards: usize,
    /// Of which with a magnet near.
    pub magnets: usize,
    /// Of which with the file cut off.
    pub truncated: usize,
    /// Of which not turned enough.
    pub unrotated: usize,
    /// Samples per recording.
    pub samples: usize,
    /// The seed of every draw.
    pub seed: u64,
}

/// The chip every board of the lot carries.
pub const CHIP: &str = "lis3mdl";

/// Writes the lot's recordings into `dir` (`board-0000.csv`, …, serials `SN-0000`, …) and returns the boards. The
/// boards with something wrong are spread through the lot.
pub fn write_lot(dir: &Path, spec: &LotSpec) -> Vec<Board> {
    let chip = ChipModel::by_name(CHIP).expect("a known chip");
    let mut rng = ChaCha8Rng::seed_from_u64(spec.seed);
    let kinds = kinds(spec, &mut rng);
    let unit = Normal::new(0.0, 1.0).expect("a valid normal");
    let draw = |rng: &mut ChaCha8Rng, sd: f64| sd * unit.sample(rng);
    let mut boards = Vec::with_capacity(spec.boards);
    for (i, kind) in kinds.into_iter().enumerate() {
        let mut a = [[0.0; 3]; 3];
        for j in 0..3 {
            a[j][j] = 1.0 + draw(&mut rng, SCALE_SPREAD);
            for k in 0..j {
                let c = draw(&mut rng, CROSS_SPREAD);
                a[j][k] = c;
                a[k][j] = c;
            }
        }
        let mut offset_ut: [f64; 3] =
            std::array::from_fn(|k| HARD_IRON_UT[k] + draw(&mut rng, HARD_IRON_SPREAD_UT));
        if kind == Kind::MagnetNear {
            let axis = rng.random_range(0..3);
            let sign = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
            offset_ut[axis] += sign * MAGNET_UT * rng.random_range(1.0..2.0);
        }
        // B = A·raw + b with the raw offset h = −A⁻¹·b: in the sensor's own axes b_s = −a·h.
        let b_s: [f64; 3] =
            std::array::from_fn(|j| -(0..3).map(|k| a[j][k] * offset_ut[k]).sum::<f64>());
        let mount: [f64; 3] =
            std::array::from_fn(|_| draw(&mut rng, MOUNT_SPREAD_DEG.to_radians()));
        let truth = SensorTruth::mounted(a, b_s, mount);
        let duration_s = spec.samples as f64 / chip.rate_hz;
        let trajectory = match kind {
            Kind::NotRotated => Trajectory::Turntable {
                duration_s,
                rate_deg_s: 20.0,
                tilt_deg: 0.0,
            },
            _ => Trajectory::Tumble {
                duration_s,
                rate_rad_s: 1.0,
            },
        };
        let seed = spec.seed.wrapping_mul(1_000_003).wrapping_add(i as u64);
        let mut s = Scenario::new(&chip, trajectory, seed);
        s.sensor = truth;
        let noise = rng.random_range(0.8..1.3);
        s.noise_ut = chip.noise_ut.map(|n| n * noise);
        let mut run = simulate(&s).expect("the scenario simulates");
        let serial = format!("SN-{i:04}");
        run.recording.meta.serial = Some(serial.clone());
        let path = dir.join(format!("board-{i:04}.csv"));
        run.recording
            .write(&path)
            .expect("the recording is written");
        if kind == Kind::Truncated {
            cut_mid_row(&path);
        }
        boards.push(Board {
            serial,
            path,
            kind,
            truth,
            offset_ut,
        });
    }
    boards
}

/// The kinds of the lot's boards, those with something wrong at random places.
fn kinds(spec: &LotSpec, rng: &mut ChaCha8Rng) -> Vec<Kind> {
    let mut kinds = vec![Kind::Normal; spec.boards];
    let wrong = [
        (Kind::MagnetNear, spec.magnets),
        (Kind::Truncated, spec.truncated),
        (Kind::NotRotated, spec.unrotated),
    ];
    for (kind, count) in wrong {
        let mut placed = 0;
        while placed < count {
            let i = rng.random_range(0..spec.boards);
            if kinds[i] == Kind::Normal {
                kinds[i] = kind;
                placed += 1;
            }
        }
    }
    kinds
}

/// Cuts the file at `path` off in the middle of a row at about 60 % of its length, two characters into the row's
/// second field (a logger stopped mid-write).
fn cut_mid_row(path: &Path) {
    let mut bytes = std::fs::read(path).expect("the recording reads");
    let from = bytes.len() * 3 / 5;
    let row = from
        + bytes[from..]
            .iter()
            .position(|&b| b == b'\n')
            .expect("rows follow")
        + 1;
    let comma = row
        + bytes[row..]
            .iter()
            .position(|&b| b == b',')
            .expect("a row has fields");
    bytes.truncate(comma + 3);
    std::fs::write(path, bytes).expect("the recording is cut");
}
