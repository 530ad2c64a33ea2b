use embedded_hal_mock::eh1::i2c::{Mock, Transaction as T};

use super::*;
use crate::test_support::{NACK, assert_close};

const ADDR: u8 = 0x1E;

fn driver(expectations: &[T]) -> Hmc5883l<Mock> {
    Hmc5883l::new(Mock::new(expectations))
}

fn finish(driver: Hmc5883l<Mock>) {
    driver.destroy().done();
}

fn init_sequence() -> Vec<T> {
    vec![
        T::write_read(ADDR, vec![0x0A], b"H43".to_vec()),
        // 8 samples averaged, 15 Hz, normal measurement
        T::write(ADDR, vec![0x00, 0x70]),
        // gain ±1.3 G
        T::write(ADDR, vec![0x01, 0x20]),
        T::write(ADDR, vec![0x02, 0x00]),
    ]
}

#[test]
fn init_writes_all_registers_and_starts_continuous_mode() {
    let mut mag = driver(&init_sequence());
    mag.init().unwrap();
    finish(mag);
}

#[test]
fn wrong_id_packs_the_three_bytes() {
    let mut mag = driver(&[T::write_read(ADDR, vec![0x0A], vec![0x48, 0x34, 0x34])]);
    assert_eq!(
        mag.init(),
        Err(Error::WrongId {
            expected: 0x48_34_33,
            found: 0x48_34_34
        })
    );
    finish(mag);
}

#[test]
fn first_sample_after_init_is_dropped_then_x_z_y_order_is_undone() {
    let mut expectations = init_sequence();
    expectations.extend([
        T::write_read(ADDR, vec![0x09], vec![0x01]),
        T::write_read(ADDR, vec![0x03], vec![0, 0, 0, 0, 0, 0]),
        T::write_read(ADDR, vec![0x09], vec![0x01]),
        // X = 1090 (0x0442), Z = -545 (0xFDDF), Y = 2047 (0x07FF), MSB first
        T::write_read(ADDR, vec![0x03], vec![0x04, 0x42, 0xFD, 0xDF, 0x07, 0xFF]),
    ]);
    let mut mag = driver(&expectations);
    mag.init().unwrap();
    assert_eq!(mag.read_ut(), Err(Error::NotReady));
    // 1090 LSB/G: x = 100 µT, y = 2047/10.9 = 187.7982 µT, z = -50 µT
    assert_close(mag.read_ut().unwrap(), [100.0, 187.7982, -50.0], 1e-3);
    finish(mag);
}

#[test]
fn overflow_value_is_saturated_not_a_field() {
    let mut mag = driver(&[
        T::write_read(ADDR, vec![0x09], vec![0x01]),
        // Z = -4096 (0xF000)
        T::write_read(ADDR, vec![0x03], vec![0x00, 0x10, 0xF0, 0x00, 0x00, 0x10]),
    ]);
    assert_eq!(mag.read_ut(), Err(Error::Saturated));
    finish(mag);
}

#[test]
fn data_ready_follows_rdy_not_lock() {
    let mut mag = driver(&[
        T::write_read(ADDR, vec![0x09], vec![0x02]),
        T::write_read(ADDR, vec![0x09], vec![0x03]),
        T::write_read(ADDR, vec![0x09], vec![0x00]),
    ]);
    assert_eq!(mag.data_ready(), Ok(false));
    assert_eq!(mag.data_ready(), Ok(true));
    assert_eq!(mag.read_ut(), Err(Error::NotReady));
    finish(mag);
}

#[test]
fn range_change_writes_gain_and_drops_one_sample() {
    let mut mag = driver(&[
        T::write(ADDR, vec![0x01, 0x60]),
        T::write(ADDR, vec![0x01, 0xE0]),
        T::write_read(ADDR, vec![0x09], vec![0x01]),
        T::write_read(ADDR, vec![0x03], vec![0x00, 0x17, 0, 0, 0, 0]),
        T::write_read(ADDR, vec![0x09], vec![0x01]),
        // X = 23 at 230 LSB/G = 10 µT, Z = -230 = -100 µT
        T::write_read(ADDR, vec![0x03], vec![0x00, 0x17, 0xFF, 0x1A, 0x00, 0x00]),
    ]);
    assert_eq!(mag.set_range_ut(200.0), Ok(250.0));
    assert_eq!(mag.gain(), Gain::Ga2_5);
    assert_eq!(mag.set_range_ut(1000.0), Ok(810.0));
    assert!((mag.lsb_ut() - 100.0 / 230.0).abs() < 1e-9);
    assert_eq!(mag.read_ut(), Err(Error::NotReady));
    assert_close(mag.read_ut().unwrap(), [10.0, 0.0, -100.0], 1e-3);
    assert_eq!(mag.set_range_ut(f32::INFINITY), Err(Error::InvalidConfig));
    finish(mag);
}

#[test]
fn rate_and_averaging_rewrite_config_a() {
    let mut mag = driver(&[
        T::write(ADDR, vec![0x00, 0x74]),
        T::write(ADDR, vec![0x00, 0x14]),
    ]);
    assert_eq!(mag.set_rate_hz(50.0), Ok(30.0));
    mag.set_averaging(Averaging::X1).unwrap();
    assert_eq!(mag.averaging(), Averaging::X1);
    assert_eq!(mag.data_rate(), DataRate::Hz30);
    finish(mag);
}

#[test]
fn no_temperature_sensor() {
    let mut mag = driver(&[]);
    assert_eq!(mag.temperature_c(), Ok(None));
    finish(mag);
}

#[test]
fn nack_surfaces_as_i2c_error() {
    let mut mag = driver(&[T::write_read(ADDR, vec![0x0A], vec![0, 0, 0]).with_error(NACK)]);
    assert_eq!(mag.identify(), Err(Error::I2c(NACK)));
    finish(mag);
}
