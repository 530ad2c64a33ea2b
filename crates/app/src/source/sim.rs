//! The `sim` device: a chip twin on a simulated bench, with a realistic sensor drawn from a seed, so that a test (or
//! a curious user) can rebuild the truth a fit should find.

use std::cell::RefCell;
use std::rc::Rc;

use magcal_driver::{AnyMagnetometer, ChipKind};
use magcal_mockhw::{Fault, SimChip, VirtualClock};
use magcal_sim::bench::{Bench, BenchConfig};
use magcal_sim::{ChipModel, SensorTruth, TemperatureProfile, stream_rng};

use super::clock::SimClock;
use super::{ChipSource, SourceError};
pub use crate::truth::{TRUTH_FORMAT, TruthFile};

/// The world field of the simulated bench, NED, µT (a mid-latitude field of 49.45 µT).
pub const FIELD_NED_UT: [f64; 3] = [19.8, 1.2, 45.3];
/// Soft iron and scale errors of the simulated sensor: up to ±4 % on the diagonal (±1 % off it).
pub const SOFT_IRON: f64 = 0.04;
/// Hard iron of the simulated sensor: up to ±40 µT per axis.
pub const HARD_IRON_UT: f64 = 40.0;
/// Mounting misalignment of the simulated sensor: up to 3° about a random axis.
pub const MOUNT_DEG: f64 = 3.0;
/// The random stream the sensor is drawn from (the bench itself uses streams 1 and 3).
const SENSOR_STREAM: u64 = 16;

/// The bench of `sim:CHIP` with seed `seed`: the sensor drawn from the seed, the chip's datasheet noise, a slow
/// warm-up from 23 °C to 26 °C.
pub fn bench_config(chip: ChipKind, seed: u64) -> BenchConfig {
    let model =
        ChipModel::by_name(chip.name()).expect("every supported chip has a simulation model");
    BenchConfig {
        field_ned_ut: FIELD_NED_UT,
        sensor: SensorTruth::random(
            SOFT_IRON,
            HARD_IRON_UT,
            MOUNT_DEG,
            &mut stream_rng(seed, SENSOR_STREAM),
        ),
        effects: Vec::new(),
        temperature: Some(TemperatureProfile {
            warmup_c: 3.0,
            tau_s: 300.0,
            ..TemperatureProfile::constant(23.0)
        }),
        noise_ut: model.noise_ut,
        seed,
        reference_heading_deg: 0.0,
    }
}

/// Opens `sim:CHIP`: the chip's twin on its bench, with `faults`, driven by the real driver. `paced` keeps the
/// virtual time to the wall clock; otherwise it runs as fast as it can. The jig's edge points `jig_heading_deg` east
/// of true north (the cube poses are against it).
pub fn open(
    chip: ChipKind,
    seed: u64,
    faults: &[Fault],
    paced: bool,
    rate_hz: f64,
    range_ut: Option<f64>,
    jig_heading_deg: f64,
) -> Result<ChipSource<AnyMagnetometer<SimChip>, SimClock>, SourceError> {
    let device = format!("sim:{chip}");
    let config = BenchConfig {
        reference_heading_deg: jig_heading_deg,
        ..bench_config(chip, seed)
    };
    let bench = Bench::new(config).map_err(|e| SourceError::Chip {
        device: device.clone(),
        error: e.to_string(),
    })?;
    let bench = Rc::new(RefCell::new(bench));
    let clock = VirtualClock::new();
    let mut twin = SimChip::new(chip, bench.clone(), clock.clone());
    for f in faults {
        twin.inject(*f);
    }
    let clock = if paced {
        SimClock::paced(clock)
    } else {
        SimClock::fast(clock)
    };
    let source = ChipSource::start(
        device,
        AnyMagnetometer::new(chip, twin),
        clock,
        rate_hz,
        range_ut,
    )?;
    Ok(source.with_bench(bench))
}

impl TruthFile {
    /// The truth of `sim:CHIP` with `seed`.
    pub fn of(chip: ChipKind, seed: u64) -> TruthFile {
        let config = bench_config(chip, seed);
        let s = config.sensor;
        TruthFile {
            format: TRUTH_FORMAT.to_owned(),
            chip: chip.to_string(),
            seed,
            field_ned_ut: config.field_ned_ut,
            a: s.a,
            b_ut: s.b_ut,
            offset_ut: magcal_calib::scalar::centre(&s.a, s.b_ut),
            noise_ut: config.noise_ut,
            effects: Vec::new(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_truth_is_realistic_reproducible_and_round_trips() {
        for chip in ChipKind::ALL {
            let t = TruthFile::of(chip, 3);
            assert_eq!(t, TruthFile::of(chip, 3));
            assert!(t.b_ut.iter().all(|b| b.abs() <= 1.1 * HARD_IRON_UT));
            assert!(
                t.b_ut.iter().any(|b| b.abs() > 5.0),
                "hard iron of tens of µT: {:?}",
                t.b_ut
            );
            for j in 0..3 {
                assert!((t.a[j][j] - 1.0).abs() < 0.1, "{:?}", t.a);
            }
        }
        assert_ne!(
            TruthFile::of(ChipKind::Lis3mdl, 3).a,
            TruthFile::of(ChipKind::Lis3mdl, 4).a
        );
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("truth.toml");
        let t = TruthFile::of(ChipKind::Mmc5983ma, 9);
        t.write(&path).unwrap();
        assert_eq!(TruthFile::read(&path).unwrap(), t);
    }
}
