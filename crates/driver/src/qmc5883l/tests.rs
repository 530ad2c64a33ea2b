use embedded_hal_mock::eh1::i2c::{Mock, Transaction as T};

use super::*;
use crate::test_support::{NACK, assert_close};

const ADDR: u8 = 0x0D;

fn driver(expectations: &[T]) -> Qmc5883l<Mock> {
    Qmc5883l::new(Mock::new(expectations))
}

fn finish(driver: Qmc5883l<Mock>) {
    driver.destroy().done();
}

#[test]
fn init_writes_datasheet_sequence() {
    let mut mag = driver(&[
        T::write_read(ADDR, vec![0x0D], vec![0xFF]),
        T::write(ADDR, vec![0x0A, 0x00]),
        T::write(ADDR, vec![0x0B, 0x01]),
        // OSR 512, ±8 G, 200 Hz, continuous: the datasheet's 0x1D
        T::write(ADDR, vec![0x09, 0x1D]),
    ]);
    mag.init().unwrap();
    finish(mag);
}

#[test]
fn wrong_id_reports_found_and_expected() {
    let mut mag = driver(&[T::write_read(ADDR, vec![0x0D], vec![0x00])]);
    assert_eq!(
        mag.init(),
        Err(Error::WrongId {
            expected: 0xFF,
            found: 0x00
        })
    );
    finish(mag);
}

#[test]
fn range_rate_and_oversampling_rewrite_control_1() {
    let mut mag = driver(&[
        T::write(ADDR, vec![0x09, 0x0D]),
        T::write(ADDR, vec![0x09, 0x1D]),
        T::write(ADDR, vec![0x09, 0x15]),
        T::write(ADDR, vec![0x09, 0xD5]),
    ]);
    assert_eq!(mag.set_range_ut(150.0), Ok(200.0));
    assert!((mag.lsb_ut() - 100.0 / 12000.0).abs() < 1e-9);
    assert_eq!(mag.set_range_ut(1000.0), Ok(800.0));
    assert_eq!(mag.set_rate_hz(60.0), Ok(50.0));
    mag.set_oversampling(Oversampling::X64).unwrap();
    assert_eq!(mag.set_range_ut(0.0), Err(Error::InvalidConfig));
    assert_eq!(
        (mag.range(), mag.data_rate(), mag.oversampling()),
        (Range::G8, DataRate::Hz50, Oversampling::X64)
    );
    finish(mag);
}

#[test]
fn data_ready_follows_drdy() {
    let mut mag = driver(&[
        T::write_read(ADDR, vec![0x06], vec![0x04]),
        T::write_read(ADDR, vec![0x06], vec![0x01]),
    ]);
    assert_eq!(mag.data_ready(), Ok(false));
    assert_eq!(mag.data_ready(), Ok(true));
    finish(mag);
}

#[test]
fn read_scales_at_8_gauss() {
    let mut mag = driver(&[
        T::write_read(ADDR, vec![0x06], vec![0x00]),
        T::write_read(ADDR, vec![0x06], vec![0x01]),
        // x = 3000 (0x0BB8), y = -6000 (0xE890), z = 150 (0x0096)
        T::write_read(ADDR, vec![0x00], vec![0xB8, 0x0B, 0x90, 0xE8, 0x96, 0x00]),
    ]);
    assert_eq!(mag.read_ut(), Err(Error::NotReady));
    // 3000 LSB/G: 100 µT, -200 µT, 5 µT
    assert_close(mag.read_ut().unwrap(), [100.0, -200.0, 5.0], 1e-3);
    finish(mag);
}

#[test]
fn read_scales_at_2_gauss() {
    let mut mag = driver(&[
        T::write(ADDR, vec![0x09, 0x0D]),
        T::write_read(ADDR, vec![0x06], vec![0x05]),
        // x = 12000 (0x2EE0), y = -1, z = -12000 (0xD120)
        T::write_read(ADDR, vec![0x00], vec![0xE0, 0x2E, 0xFF, 0xFF, 0x20, 0xD1]),
    ]);
    mag.set_range(Range::G2).unwrap();
    assert_close(mag.read_ut().unwrap(), [100.0, -1.0 / 120.0, -100.0], 1e-4);
    finish(mag);
}

#[test]
fn overflow_consumes_sample_and_reports_saturated() {
    let mut mag = driver(&[
        T::write_read(ADDR, vec![0x06], vec![0x03]),
        T::write_read(ADDR, vec![0x00], vec![0xFF, 0x7F, 0x00, 0x00, 0x00, 0x80]),
    ]);
    assert_eq!(mag.read_ut(), Err(Error::Saturated));
    finish(mag);
}

#[test]
fn temperature_is_relative_only() {
    let mut mag = driver(&[
        T::write_read(ADDR, vec![0x07], vec![0xC4, 0x09]),
        T::write_read(ADDR, vec![0x07], vec![0x6A, 0xFF]),
    ]);
    assert_eq!(mag.temperature_c(), Ok(None));
    // 2500 / 100 = 25.0; -150 / 100 = -1.5 (uncalibrated zero)
    assert_eq!(mag.read_temperature_relative_c(), Ok(25.0));
    assert_eq!(mag.read_temperature_relative_c(), Ok(-1.5));
    assert!(!mag.info().has_temperature);
    finish(mag);
}

#[test]
fn nack_surfaces_as_i2c_error() {
    let mut mag = driver(&[
        T::write_read(ADDR, vec![0x0D], vec![0xFF]),
        T::write(ADDR, vec![0x0A, 0x00]).with_error(NACK),
    ]);
    assert_eq!(mag.init(), Err(Error::I2c(NACK)));
    finish(mag);
}
