use embedded_hal_mock::eh1::i2c::{Mock, Transaction as T};

use super::*;
use crate::test_support::{NACK, assert_close};

const ADDR: u8 = 0x1E;

fn driver(expectations: &[T]) -> Lis2mdl<Mock> {
    Lis2mdl::new(Mock::new(expectations))
}

fn finish(driver: Lis2mdl<Mock>) {
    driver.destroy().done();
}

#[test]
fn init_resets_then_starts_continuous_mode() {
    let mut mag = driver(&[
        T::write_read(ADDR, vec![0x4F], vec![0x40]),
        T::write(ADDR, vec![0x60, 0x20]),
        T::write_read(ADDR, vec![0x60], vec![0x20]),
        T::write_read(ADDR, vec![0x60], vec![0x03]),
        // OFF_CANC
        T::write(ADDR, vec![0x61, 0x02]),
        // BDU
        T::write(ADDR, vec![0x62, 0x10]),
        // COMP_TEMP_EN | ODR=100 Hz | continuous
        T::write(ADDR, vec![0x60, 0x8C]),
    ]);
    mag.init().unwrap();
    finish(mag);
}

#[test]
fn wrong_id_reports_found_and_expected() {
    let mut mag = driver(&[T::write_read(ADDR, vec![0x4F], vec![0x3D])]);
    assert_eq!(
        mag.identify(),
        Err(Error::WrongId {
            expected: 0x40,
            found: 0x3D
        })
    );
    finish(mag);
}

#[test]
fn range_is_fixed_and_needs_no_bus_traffic() {
    let mut mag = driver(&[]);
    assert_eq!(mag.set_range_ut(10.0), Ok(5000.0));
    assert_eq!(mag.set_range_ut(1e6), Ok(5000.0));
    assert_eq!(mag.set_range_ut(f32::NAN), Err(Error::InvalidConfig));
    assert_eq!(mag.lsb_ut(), 0.15);
    finish(mag);
}

#[test]
fn rate_and_power_mode_rewrite_cfg_reg_a() {
    let mut mag = driver(&[
        T::write(ADDR, vec![0x60, 0x88]),
        T::write(ADDR, vec![0x60, 0x8C]),
        T::write(ADDR, vec![0x60, 0x9C]),
        T::write(ADDR, vec![0x61, 0x04]),
    ]);
    assert_eq!(mag.set_rate_hz(45.0), Ok(50.0));
    assert_eq!(mag.set_rate_hz(1e6), Ok(100.0));
    mag.set_power_mode(PowerMode::LowPower).unwrap();
    mag.set_set_reset_mode(SetResetMode::SetAtPowerOnOnly)
        .unwrap();
    assert_eq!(mag.set_rate_hz(-5.0), Err(Error::InvalidConfig));
    assert_eq!(mag.data_rate(), DataRate::Hz100);
    finish(mag);
}

#[test]
fn data_ready_follows_zyxda() {
    let mut mag = driver(&[
        T::write_read(ADDR, vec![0x67], vec![0x00]),
        T::write_read(ADDR, vec![0x67], vec![0x0F]),
    ]);
    assert_eq!(mag.data_ready(), Ok(false));
    assert_eq!(mag.data_ready(), Ok(true));
    finish(mag);
}

#[test]
fn read_not_ready_then_scaled_sample() {
    let mut mag = driver(&[
        T::write_read(ADDR, vec![0x67], vec![0x80]),
        T::write_read(ADDR, vec![0x67], vec![0x08]),
        // x = 1000 (0x03E8), y = -1000 (0xFC18), z = -1 (0xFFFF); plain sub-address
        T::write_read(ADDR, vec![0x68], vec![0xE8, 0x03, 0x18, 0xFC, 0xFF, 0xFF]),
    ]);
    assert_eq!(mag.read_ut(), Err(Error::NotReady));
    // 1.5 mG/LSB = 0.15 µT/LSB
    assert_close(mag.read_ut().unwrap(), [150.0, -150.0, -0.15], 1e-4);
    finish(mag);
}

#[test]
fn a_clipped_output_is_saturated() {
    // y = 32767 (0x7FFF): past +49 G, or past what the offset registers leave of the range.
    let mut mag = driver(&[
        T::write_read(ADDR, vec![0x67], vec![0x08]),
        T::write_read(ADDR, vec![0x68], vec![0xE8, 0x03, 0xFF, 0x7F, 0xFF, 0xFF]),
    ]);
    assert_eq!(mag.read_ut(), Err(Error::Saturated));
    finish(mag);
}

#[test]
fn temperature_is_8_lsb_per_degree_around_25() {
    let mut mag = driver(&[
        T::write_read(ADDR, vec![0x6E], vec![0x28, 0x00]),
        T::write_read(ADDR, vec![0x6E], vec![0xD8, 0xFF]),
    ]);
    assert_eq!(mag.temperature_c(), Ok(Some(30.0)));
    assert_eq!(mag.temperature_c(), Ok(Some(20.0)));
    finish(mag);
}

#[test]
fn offset_write_and_read_back() {
    let mut mag = driver(&[
        // 25 µT → 166.7 → 167 (0x00A7); -30 µT → -200 (0xFF38); 0.07 µT → 0
        T::write(ADDR, vec![0x45, 0xA7, 0x00, 0x38, 0xFF, 0x00, 0x00]),
        T::write_read(ADDR, vec![0x45], vec![0xA7, 0x00, 0x38, 0xFF, 0x00, 0x00]),
    ]);
    mag.write_offset_ut([25.0, -30.0, 0.07]).unwrap();
    assert_close(mag.read_offset_ut().unwrap(), [25.05, -30.0, 0.0], 1e-4);
    finish(mag);
}

#[test]
fn offset_out_of_register_span_is_rejected_without_writing() {
    let mut mag = driver(&[]);
    assert_eq!(
        mag.write_offset_ut([0.0, 5000.0, 0.0]),
        Err(Error::InvalidConfig)
    );
    assert_eq!(
        mag.write_offset_ut([f32::NAN, 0.0, 0.0]),
        Err(Error::InvalidConfig)
    );
    finish(mag);
}

#[test]
fn nack_surfaces_as_i2c_error() {
    let mut mag = driver(&[
        T::write(ADDR, vec![0x45, 0, 0, 0, 0, 0, 0]).with_error(NACK),
        T::write_read(ADDR, vec![0x4F], vec![0x40]).with_error(NACK),
    ]);
    assert_eq!(mag.write_offset_ut([0.0; 3]), Err(Error::I2c(NACK)));
    assert_eq!(mag.init(), Err(Error::I2c(NACK)));
    finish(mag);
}
