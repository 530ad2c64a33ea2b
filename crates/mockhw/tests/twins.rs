//! The real drivers of `magcal-driver`, unchanged, against each chip's twin: identification, init, data rate,
//! scaling at every range, temperature, chip quirks, and every fault.

use std::cell::RefCell;
use std::rc::Rc;

use embedded_hal::delay::DelayNs;
use embedded_hal::i2c::{ErrorKind, NoAcknowledgeSource};
use magcal_driver::hmc5883l::Hmc5883l;
use magcal_driver::lis2mdl::Lis2mdl;
use magcal_driver::mmc5983ma::Mmc5983ma;
use magcal_driver::{AnyMagnetometer, ChipKind, Error, HardIronOffset, Magnetometer};
use magcal_mockhw::{Fault, SharedBench, SimChip, VirtualClock};
use magcal_sim::bench::{Bench, BenchConfig};
use magcal_sim::{SensorTruth, TemperatureProfile, cube24_poses};

const FIELD_NED_UT: [f64; 3] = [19.8, 1.2, 45.3];

/// A noise-free bench holding the sensor in cube pose `pose`, with a hard iron and a warm-up, and a clock.
fn bench(pose: usize) -> (SharedBench, VirtualClock) {
    let mut config = BenchConfig::ideal(FIELD_NED_UT, 5);
    config.sensor = SensorTruth::mounted(
        [[1.05, 0.02, 0.0], [0.01, 0.97, -0.02], [0.0, 0.03, 1.02]],
        [25.0, -12.0, 40.0],
        [0.01, -0.02, 0.03],
    );
    config.temperature = Some(TemperatureProfile {
        warmup_c: 4.0,
        tau_s: 2.0,
        ..TemperatureProfile::constant(21.0)
    });
    let mut b = Bench::new(config).unwrap();
    b.hand_mut().move_to(0.0, cube24_poses()[pose].quat, 0.0);
    (Rc::new(RefCell::new(b)), VirtualClock::new())
}

/// The bench's raw reading now (noise-free), µT.
fn truth_ut(bench: &SharedBench, clock: &VirtualClock) -> [f64; 3] {
    bench.borrow_mut().sample(clock.now_s()).clean_raw_ut
}

/// The next sample, polling every 0.5 ms of virtual time for at most 2 s.
fn next<M: Magnetometer<Error = Error<ErrorKind>>>(
    mag: &mut M,
    clock: &mut VirtualClock,
) -> Result<[f32; 3], Error<ErrorKind>> {
    for _ in 0..4000 {
        match mag.read_ut() {
            Err(Error::NotReady) => clock.delay_us(500),
            other => return other,
        }
    }
    panic!("no sample in 2 s of virtual time");
}

fn assert_near(got: [f32; 3], want: [f64; 3], tol: f64, what: &str) {
    for k in 0..3 {
        assert!(
            (f64::from(got[k]) - want[k]).abs() <= tol,
            "{what}: axis {k}: got {got:?}, want {want:?} ± {tol}"
        );
    }
}

fn driver(kind: ChipKind, pose: usize) -> (AnyMagnetometer<SimChip>, SharedBench, VirtualClock) {
    let (b, clock) = bench(pose);
    let chip = SimChip::new(kind, b.clone(), clock.clone());
    (AnyMagnetometer::new(kind, chip), b, clock)
}

#[test]
fn every_driver_inits_its_twin_and_reads_the_bench_field_at_every_range() {
    for kind in ChipKind::ALL {
        for pose in [0, 7, 13, 22] {
            let (mut mag, b, mut clock) = driver(kind, pose);
            mag.init().unwrap_or_else(|e| panic!("{kind}: init: {e}"));
            for &range in kind.info().ranges_ut {
                let applied = mag.set_range_ut(range).unwrap();
                assert_eq!(applied, range, "{kind}");
                // A sample from before a range change may still be waiting: take two.
                next(&mut mag, &mut clock).ok();
                let m = next(&mut mag, &mut clock).unwrap_or_else(|e| panic!("{kind}: {e}"));
                let lsb = f64::from(mag.lsb_ut());
                assert_near(
                    m,
                    truth_ut(&b, &clock),
                    0.51 * lsb + 1e-4,
                    &format!("{kind} at ±{range} µT"),
                );
            }
        }
    }
}

#[test]
fn every_twin_converts_at_the_rate_its_driver_chose() {
    for kind in ChipKind::ALL {
        for &rate in kind
            .info()
            .rates_hz
            .iter()
            .filter(|r| (5.0..=250.0).contains(*r))
        {
            let (mut mag, _, mut clock) = driver(kind, 3);
            mag.init().unwrap();
            assert_eq!(mag.set_rate_hz(rate).unwrap(), rate);
            let start = clock.now_s();
            let mut n = 0;
            while clock.now_s() - start < 2.0 {
                match mag.read_ut() {
                    Ok(_) => n += 1,
                    Err(Error::NotReady) => clock.delay_us(200),
                    Err(e) => panic!("{kind}: {e}"),
                }
            }
            let measured = f64::from(n) / 2.0;
            let rate = f64::from(rate);
            // The HMC5883L drops one stale sample after init.
            assert!(
                (measured - rate).abs() <= 1.0,
                "{kind}: {measured} Hz for {rate} Hz"
            );
        }
    }
}

#[test]
fn temperature_comes_from_the_bench_where_the_chip_has_a_sensor() {
    for kind in ChipKind::ALL {
        let (mut mag, b, mut clock) = driver(kind, 0);
        mag.init().unwrap();
        clock.delay_ms(3000);
        next(&mut mag, &mut clock).unwrap();
        let t = mag.temperature_c().unwrap();
        let want = b.borrow().temperature_c(clock.now_s());
        match (kind.info().has_temperature, t) {
            (true, Some(t)) => {
                let resolution = if kind == ChipKind::Mmc5983ma {
                    0.8
                } else {
                    0.125
                };
                assert!(
                    (f64::from(t) - want).abs() <= resolution / 2.0 + 0.01,
                    "{kind}: {t} °C vs {want}"
                );
            }
            (false, None) => {}
            other => panic!("{kind}: {other:?}"),
        }
        // The MMC5983MA's temperature measurement stops and restarts continuous mode: sampling goes on.
        next(&mut mag, &mut clock).unwrap();
    }
}

#[test]
fn the_qmc5883l_temperature_is_relative_only() {
    let (b, mut clock) = bench(0);
    let mut mag =
        magcal_driver::Qmc5883l::new(SimChip::new(ChipKind::Qmc5883l, b.clone(), clock.clone()));
    mag.init().unwrap();
    next(&mut mag, &mut clock).unwrap();
    let t0 = mag.read_temperature_relative_c().unwrap();
    let want0 = b.borrow().temperature_c(clock.now_s());
    clock.delay_ms(5000);
    next(&mut mag, &mut clock).unwrap();
    let t1 = mag.read_temperature_relative_c().unwrap();
    let want1 = b.borrow().temperature_c(clock.now_s());
    assert!(
        (f64::from(t1 - t0) - (want1 - want0)).abs() < 0.02,
        "{t0} → {t1}"
    );
    assert!(
        (f64::from(t0) - want0).abs() > 1.0,
        "the zero is uncalibrated"
    );
}

#[test]
fn a_wrong_chip_or_address_is_told_apart() {
    // An HMC5883L answers at the LIS2MDL's address: the LIS2MDL driver finds the wrong id.
    let (b, clock) = bench(0);
    let mut mag = Lis2mdl::new(SimChip::new(ChipKind::Hmc5883l, b.clone(), clock.clone()));
    assert!(matches!(
        mag.init(),
        Err(Error::WrongId { expected: 0x40, .. })
    ));
    // Nobody at the address: a NACK.
    let chip = SimChip::new(ChipKind::Lis3mdl, b, clock).with_address(0x1E);
    let mut mag = AnyMagnetometer::new(ChipKind::Lis3mdl, chip);
    assert_eq!(
        mag.init(),
        Err(Error::I2c(ErrorKind::NoAcknowledge(
            NoAcknowledgeSource::Address
        )))
    );
    let mut mag = AnyMagnetometer::with_address(ChipKind::Lis3mdl, mag.destroy(), 0x1E);
    mag.init().unwrap();
}

#[test]
fn nacks_fail_transactions_then_the_bus_recovers_and_a_dropped_bus_does_not() {
    for kind in ChipKind::ALL {
        let (mut mag, b, mut clock) = driver(kind, 2);
        mag.init().unwrap();
        let chip_now = clock.now_s();
        let mut chip = mag.destroy();
        chip.inject(Fault::Nack {
            at_s: chip_now + 0.1,
            count: 3,
        });
        chip.inject(Fault::DropBus {
            at_s: chip_now + 1.0,
        });
        let mut mag = AnyMagnetometer::new(kind, chip);
        next(&mut mag, &mut clock).unwrap();
        clock.delay_ms(100);
        let nack = Error::I2c(ErrorKind::NoAcknowledge(NoAcknowledgeSource::Address));
        for _ in 0..3 {
            assert_eq!(mag.read_ut(), Err(nack), "{kind}");
        }
        assert_near(
            next(&mut mag, &mut clock).unwrap(),
            truth_ut(&b, &clock),
            0.51 * f64::from(mag.lsb_ut()) + 1e-4,
            "after NACKs",
        );
        clock.delay_ms(1000);
        for _ in 0..10 {
            assert_eq!(mag.read_ut(), Err(nack), "{kind}: dropped bus");
        }
    }
}

#[test]
fn stuck_outputs_repeat_while_data_ready_goes_on() {
    for kind in ChipKind::ALL {
        let (b, mut clock) = bench(1);
        b.borrow_mut().hand_mut().tumble(0.0, 1.0);
        let mut chip = SimChip::new(kind, b, clock.clone());
        chip.inject(Fault::StuckData { at_s: 0.5 });
        let mut mag = AnyMagnetometer::new(kind, chip);
        mag.init().unwrap();
        let mut before = Vec::new();
        while clock.now_s() < 0.45 {
            before.push(next(&mut mag, &mut clock).unwrap());
        }
        assert!(before.windows(2).any(|w| w[0] != w[1]), "{kind}: moving");
        clock.delay_ms(100);
        let stuck: Vec<[f32; 3]> = (0..20)
            .map(|_| next(&mut mag, &mut clock).unwrap())
            .collect();
        assert!(stuck.windows(2).all(|w| w[0] == w[1]), "{kind}: {stuck:?}");
    }
}

#[test]
fn a_magnet_saturates_each_chip_in_its_own_way() {
    for kind in ChipKind::ALL {
        let (mut mag, _, mut clock) = driver(kind, 0);
        mag.init().unwrap();
        let range = kind.info().ranges_ut[0];
        mag.set_range_ut(range).unwrap();
        next(&mut mag, &mut clock).ok();
        next(&mut mag, &mut clock).unwrap();
        let mut chip = mag.destroy();
        let at_s = clock.now_s();
        chip.inject(Fault::Magnet {
            at_s,
            duration_s: 1.0,
            field_ut: [3.0 * f64::from(range), 0.0, 0.0],
        });
        let mut mag = AnyMagnetometer::new(kind, chip);
        // QMC5883L and HMC5883L flag it; the others clip their outputs at the end of the scale, which the drivers
        // take as saturation: the sample is refused either way.
        let r = next(&mut mag, &mut clock);
        assert_eq!(r, Err(Error::Saturated), "{kind}");
        clock.delay_ms(1200);
        next(&mut mag, &mut clock).ok();
        assert!(
            next(&mut mag, &mut clock).is_ok(),
            "{kind}: the magnet is gone"
        );
    }
}

#[test]
fn the_lis2mdl_subtracts_its_offset_registers_and_reset_clears_them() {
    let (b, mut clock) = bench(4);
    let mut mag = Lis2mdl::new(SimChip::new(ChipKind::Lis2mdl, b.clone(), clock.clone()));
    mag.init().unwrap();
    let offset = [30.0, -45.15, 12.3];
    mag.write_offset_ut(offset).unwrap();
    let back = mag.read_offset_ut().unwrap();
    assert_near(back, offset.map(f64::from), 0.075, "read back");
    next(&mut mag, &mut clock).ok();
    let m = next(&mut mag, &mut clock).unwrap();
    let want: [f64; 3] = std::array::from_fn(|k| truth_ut(&b, &clock)[k] - f64::from(back[k]));
    assert_near(m, want, 0.151, "offset subtracted");
    mag.init().unwrap();
    assert_eq!(mag.read_offset_ut().unwrap(), [0.0; 3]);
    // A chip that ignores writes keeps its old offset: a read-back shows it.
    let mut chip = mag.destroy();
    chip.inject(Fault::IgnoreWrites { at_s: 0.0 });
    let mut mag = Lis2mdl::new(chip);
    mag.write_offset_ut(offset).unwrap();
    assert_eq!(mag.read_offset_ut().unwrap(), [0.0; 3]);
}

#[test]
fn the_hmc5883l_drops_the_sample_taken_at_the_old_gain() {
    let (b, mut clock) = bench(9);
    let mut mag = Hmc5883l::new(SimChip::new(ChipKind::Hmc5883l, b.clone(), clock.clone()));
    mag.init().unwrap();
    for range in [88.0, 810.0, 130.0] {
        mag.set_range_ut(range).unwrap();
        let m = next(&mut mag, &mut clock).unwrap();
        assert_near(
            m,
            truth_ut(&b, &clock),
            0.51 * f64::from(mag.lsb_ut()),
            "first sample kept",
        );
    }
}

#[test]
fn the_mmc5983ma_set_reset_measurement_splits_field_and_bridge_offset() {
    let (b, mut clock) = bench(15);
    let bridge = [3.0, -1.5, 0.75];
    let chip = SimChip::new(ChipKind::Mmc5983ma, b.clone(), clock.clone())
        .with_bridge_offset_ut(bridge)
        .unwrap();
    let mut mag = Mmc5983ma::new(chip);
    mag.init().unwrap();
    let plain = next(&mut mag, &mut clock).unwrap();
    let truth = truth_ut(&b, &clock);
    assert_near(
        plain,
        std::array::from_fn(|k| truth[k] + bridge[k]),
        0.01,
        "after SET",
    );
    let s = mag.measure_set_reset(&mut clock).unwrap();
    assert_near(s.field_ut, truth, 0.01, "field");
    assert_near(s.offset_ut, bridge, 0.01, "bridge offset");
    assert!(
        SimChip::new(ChipKind::Lis3mdl, b, clock)
            .with_bridge_offset_ut(bridge)
            .is_none()
    );
}
