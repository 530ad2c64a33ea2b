use embedded_hal_mock::eh1::i2c::{Mock, Transaction as T};

use super::*;
use crate::bus::MAX_POLLS;
use crate::test_support::{NACK, assert_close};

const ADDR: u8 = 0x1C;

fn driver(expectations: &[T]) -> Lis3mdl<Mock> {
    Lis3mdl::new(Mock::new(expectations))
}

fn finish(driver: Lis3mdl<Mock>) {
    driver.destroy().done();
}

#[test]
fn init_resets_then_starts_continuous_mode() {
    let mut mag = driver(&[
        T::write_read(ADDR, vec![0x0F], vec![0x3D]),
        T::write(ADDR, vec![0x21, 0x04]),
        T::write_read(ADDR, vec![0x21], vec![0x04]),
        T::write_read(ADDR, vec![0x21], vec![0x00]),
        // TEMP_EN | OM=UHP | DO=80 Hz
        T::write(ADDR, vec![0x20, 0xFC]),
        T::write(ADDR, vec![0x23, 0x0C]),
        T::write(ADDR, vec![0x21, 0x00]),
        T::write(ADDR, vec![0x24, 0x40]),
        T::write(ADDR, vec![0x22, 0x00]),
    ]);
    mag.init().unwrap();
    finish(mag);
}

#[test]
fn init_times_out_if_soft_reset_never_clears() {
    let mut expectations = vec![
        T::write_read(ADDR, vec![0x0F], vec![0x3D]),
        T::write(ADDR, vec![0x21, 0x04]),
    ];
    for _ in 0..MAX_POLLS {
        expectations.push(T::write_read(ADDR, vec![0x21], vec![0x04]));
    }
    let mut mag = driver(&expectations);
    assert_eq!(mag.init(), Err(Error::Timeout));
    finish(mag);
}

#[test]
fn wrong_id_reports_found_and_expected() {
    let mut mag = driver(&[T::write_read(ADDR, vec![0x0F], vec![0x33])]);
    assert_eq!(
        mag.init(),
        Err(Error::WrongId {
            expected: 0x3D,
            found: 0x33
        })
    );
    finish(mag);
}

#[test]
fn alternate_address_is_used() {
    let mut mag = Lis3mdl::with_address(
        Mock::new(&[T::write_read(0x1E, vec![0x0F], vec![0x3D])]),
        0x1E,
    );
    mag.identify().unwrap();
    finish(mag);
}

#[test]
fn range_selects_smallest_full_scale_that_fits() {
    let mut mag = driver(&[
        T::write(ADDR, vec![0x21, 0x20]),
        T::write(ADDR, vec![0x21, 0x60]),
        T::write(ADDR, vec![0x21, 0x00]),
    ]);
    assert_eq!(mag.set_range_ut(500.0), Ok(800.0));
    assert_eq!(mag.full_scale(), FullScale::G8);
    assert!((mag.lsb_ut() - 100.0 / 3421.0).abs() < 1e-9);
    assert_eq!(mag.set_range_ut(5000.0), Ok(1600.0));
    assert_eq!(mag.set_range_ut(60.0), Ok(400.0));
    assert_eq!(mag.set_range_ut(f32::NAN), Err(Error::InvalidConfig));
    assert_eq!(mag.set_range_ut(-1.0), Err(Error::InvalidConfig));
    finish(mag);
}

#[test]
fn rate_selects_nearest_and_fast_odr_sets_mode() {
    let mut mag = driver(&[
        // 300 Hz: FAST_ODR with OM = high performance
        T::write(ADDR, vec![0x20, 0xC2]),
        T::write(ADDR, vec![0x23, 0x08]),
        // 10 Hz keeps high performance
        T::write(ADDR, vec![0x20, 0xD0]),
        T::write(ADDR, vec![0x23, 0x08]),
        // low power at 10 Hz
        T::write(ADDR, vec![0x20, 0x90]),
        T::write(ADDR, vec![0x23, 0x00]),
    ]);
    assert_eq!(mag.set_rate_hz(290.0), Ok(300.0));
    assert_eq!(mag.operating_mode(), OperatingMode::HighPerformance);
    assert_eq!(
        mag.set_operating_mode(OperatingMode::LowPower),
        Err(Error::InvalidConfig)
    );
    assert_eq!(mag.set_rate_hz(12.0), Ok(10.0));
    mag.set_operating_mode(OperatingMode::LowPower).unwrap();
    assert_eq!(mag.data_rate(), DataRate::Hz10);
    assert_eq!(mag.set_rate_hz(0.0), Err(Error::InvalidConfig));
    finish(mag);
}

#[test]
fn data_ready_follows_zyxda() {
    let mut mag = driver(&[
        T::write_read(ADDR, vec![0x27], vec![0x07]),
        T::write_read(ADDR, vec![0x27], vec![0x08]),
    ]);
    assert_eq!(mag.data_ready(), Ok(false));
    assert_eq!(mag.data_ready(), Ok(true));
    finish(mag);
}

#[test]
fn read_not_ready_consumes_nothing() {
    let mut mag = driver(&[T::write_read(ADDR, vec![0x27], vec![0x00])]);
    assert_eq!(mag.read_ut(), Err(Error::NotReady));
    finish(mag);
}

#[test]
fn read_scales_signed_counts_at_4_gauss() {
    let mut mag = driver(&[
        T::write_read(ADDR, vec![0x27], vec![0x08]),
        // x = 6842 (0x1ABA), y = -3421 (0xF2A3), z = -27368 (0x9518)
        T::write_read(ADDR, vec![0xA8], vec![0xBA, 0x1A, 0xA3, 0xF2, 0x18, 0x95]),
    ]);
    // 6842 / 6842 G = 100 µT; -3421 / 6842 G = -50 µT; -27368 / 6842 G = -400 µT (the full scale)
    assert_close(mag.read_ut().unwrap(), [100.0, -50.0, -400.0], 1e-3);
    finish(mag);
}

#[test]
fn an_output_at_the_end_of_its_range_is_saturated() {
    // The edges of "near full scale": 1 % of the half span (327 counts) from either end.
    for (z, saturated) in [
        ([0x00, 0x80], true),  // -32768: clipped
        ([0x47, 0x81], true),  // -32441
        ([0x48, 0x81], false), // -32440
        ([0xFF, 0x7F], true),  // 32767: clipped
        ([0xB8, 0x7E], true),  // 32440
        ([0xB7, 0x7E], false), // 32439
    ] {
        let mut mag = driver(&[
            T::write_read(ADDR, vec![0x27], vec![0x08]),
            T::write_read(ADDR, vec![0xA8], vec![0, 0, 0, 0, z[0], z[1]]),
        ]);
        let read = mag.read_ut();
        assert_eq!(read == Err(Error::Saturated), saturated, "{z:x?}: {read:?}");
        finish(mag);
    }
}

#[test]
fn read_scales_at_16_gauss() {
    let mut mag = driver(&[
        T::write(ADDR, vec![0x21, 0x60]),
        T::write_read(ADDR, vec![0x27], vec![0x08]),
        // x = 1711, y = -1711, z = 0
        T::write_read(ADDR, vec![0xA8], vec![0xAF, 0x06, 0x51, 0xF9, 0x00, 0x00]),
    ]);
    mag.set_full_scale(FullScale::G16).unwrap();
    assert_close(mag.read_ut().unwrap(), [100.0, -100.0, 0.0], 1e-3);
    finish(mag);
}

#[test]
fn temperature_is_8_lsb_per_degree_around_25() {
    let mut mag = driver(&[
        T::write_read(ADDR, vec![0xAE], vec![0x50, 0x00]),
        T::write_read(ADDR, vec![0xAE], vec![0xF0, 0xFF]),
    ]);
    // 80 / 8 + 25 = 35 °C; -16 / 8 + 25 = 23 °C
    assert_eq!(mag.temperature_c(), Ok(Some(35.0)));
    assert_eq!(mag.temperature_c(), Ok(Some(23.0)));
    finish(mag);
}

#[test]
fn nack_surfaces_as_i2c_error() {
    let mut mag = driver(&[
        T::write_read(ADDR, vec![0x27], vec![0x00]).with_error(NACK),
        T::write(ADDR, vec![0x21, 0x20]).with_error(NACK),
    ]);
    assert_eq!(mag.read_ut(), Err(Error::I2c(NACK)));
    assert_eq!(mag.set_range_ut(800.0), Err(Error::I2c(NACK)));
    // a failed write leaves the configuration unchanged
    assert_eq!(mag.full_scale(), FullScale::G4);
    finish(mag);
}
