use embedded_hal_mock::eh1::delay::{CheckedDelay, Transaction as D};
use embedded_hal_mock::eh1::i2c::{Mock, Transaction as T};

use super::*;
use crate::bus::MAX_POLLS;
use crate::test_support::{NACK, assert_close};

const ADDR: u8 = 0x30;
const LSB18: f32 = 100.0 / 16384.0;

fn driver(expectations: &[T]) -> Mmc5983ma<Mock> {
    Mmc5983ma::new(Mock::new(expectations))
}

fn finish(driver: Mmc5983ma<Mock>) {
    driver.destroy().done();
}

/// The seven output bytes for unsigned 18-bit counts.
fn bytes18(counts: [u32; 3]) -> Vec<u8> {
    let mut b: Vec<u8> = counts
        .iter()
        .flat_map(|c| [(c >> 10) as u8, (c >> 2) as u8])
        .collect();
    b.push((counts[0] as u8 & 3) << 6 | (counts[1] as u8 & 3) << 4 | (counts[2] as u8 & 3) << 2);
    b
}

#[test]
fn init_sets_then_starts_continuous_mode() {
    let mut mag = driver(&[
        T::write_read(ADDR, vec![0x2F], vec![0x30]),
        // bandwidth 100 Hz, control 3 cleared
        T::write(ADDR, vec![0x0A, 0x00]),
        T::write(ADDR, vec![0x0C, 0x00]),
        // SET pulse
        T::write(ADDR, vec![0x09, 0x08]),
        // clear Meas_M_Done and Meas_T_Done
        T::write(ADDR, vec![0x08, 0x03]),
        // Cmm_en | Cm_freq = 100 Hz
        T::write(ADDR, vec![0x0B, 0x0D]),
    ]);
    mag.init().unwrap();
    finish(mag);
}

#[test]
fn wrong_id_reports_found_and_expected() {
    let mut mag = driver(&[T::write_read(ADDR, vec![0x2F], vec![0x00])]);
    assert_eq!(
        mag.init(),
        Err(Error::WrongId {
            expected: 0x30,
            found: 0x00
        })
    );
    finish(mag);
}

#[test]
fn range_is_fixed_and_needs_no_bus_traffic() {
    let mut mag = driver(&[]);
    assert_eq!(mag.set_range_ut(50.0), Ok(800.0));
    assert_eq!(mag.set_range_ut(0.0), Err(Error::InvalidConfig));
    assert_eq!(mag.lsb_ut(), LSB18);
    mag.set_resolution(Resolution::Bits16);
    assert_eq!(mag.lsb_ut(), 100.0 / 4096.0);
    finish(mag);
}

#[test]
fn rate_raises_bandwidth_when_the_measurement_would_not_fit() {
    let mut mag = driver(&[
        // 200 Hz needs BW 200 Hz (4 ms ≤ 5 ms)
        T::write(ADDR, vec![0x0A, 0x01]),
        T::write(ADDR, vec![0x0B, 0x0E]),
        // 1000 Hz needs BW 800 Hz
        T::write(ADDR, vec![0x0A, 0x03]),
        T::write(ADDR, vec![0x0B, 0x0F]),
        // 1 Hz keeps BW 800 Hz
        T::write(ADDR, vec![0x0A, 0x03]),
        T::write(ADDR, vec![0x0B, 0x09]),
        T::write(ADDR, vec![0x0A, 0x00]),
    ]);
    assert_eq!(mag.set_rate_hz(180.0), Ok(200.0));
    assert_eq!(mag.bandwidth(), Bandwidth::Hz200);
    assert_eq!(mag.set_rate_hz(5000.0), Ok(1000.0));
    assert_eq!(mag.bandwidth(), Bandwidth::Hz800);
    assert_eq!(
        mag.set_bandwidth(Bandwidth::Hz100),
        Err(Error::InvalidConfig)
    );
    assert_eq!(mag.set_rate_hz(0.5), Ok(1.0));
    mag.set_bandwidth(Bandwidth::Hz100).unwrap();
    assert_eq!(mag.set_rate_hz(f32::NAN), Err(Error::InvalidConfig));
    finish(mag);
}

#[test]
fn periodic_set_writes_control_0_and_2() {
    let mut mag = driver(&[
        // Auto_SR_en
        T::write(ADDR, vec![0x09, 0x20]),
        // En_prd_set | Prd_set = 100 (011) | Cmm_en | 100 Hz
        T::write(ADDR, vec![0x0B, 0xBD]),
        T::write(ADDR, vec![0x09, 0x00]),
        T::write(ADDR, vec![0x0B, 0x0D]),
    ]);
    mag.set_auto_set_reset(AutoSetReset::PeriodicSet(SetPeriod::Every100))
        .unwrap();
    mag.set_auto_set_reset(AutoSetReset::Off).unwrap();
    finish(mag);
}

#[test]
fn data_ready_follows_meas_m_done() {
    let mut mag = driver(&[
        T::write_read(ADDR, vec![0x08], vec![0x10]),
        T::write_read(ADDR, vec![0x08], vec![0x11]),
    ]);
    assert_eq!(mag.data_ready(), Ok(false));
    assert_eq!(mag.data_ready(), Ok(true));
    finish(mag);
}

#[test]
fn read_assembles_18_bit_counts_around_null() {
    let mut mag = driver(&[
        T::write_read(ADDR, vec![0x08], vec![0x10]),
        T::write_read(ADDR, vec![0x08], vec![0x11]),
        // x = 147456 = null + 16384 → [0x90, 0x00, x1:0 = 00]
        // y = 122877 = null - 8195  → [0x77, 0xFF, y1:0 = 01]
        // z = 131074 = null + 2     → [0x80, 0x00, z1:0 = 10]
        T::write_read(
            ADDR,
            vec![0x00],
            vec![0x90, 0x00, 0x77, 0xFF, 0x80, 0x00, 0x18],
        ),
        T::write(ADDR, vec![0x08, 0x01]),
    ]);
    assert_eq!(mag.read_ut(), Err(Error::NotReady));
    // 16384 counts/G: 100 µT, -8195/163.84 = -50.01831 µT, 2/163.84 = 0.012207 µT
    assert_close(mag.read_ut().unwrap(), [100.0, -50.01831, 0.012207], 1e-4);
    finish(mag);
}

#[test]
fn a_clipped_18_bit_output_is_saturated() {
    // x = 0 (null - 131072: past -8 G), y and z at null.
    let mut mag = driver(&[
        T::write_read(ADDR, vec![0x08], vec![0x01]),
        T::write_read(
            ADDR,
            vec![0x00],
            vec![0x00, 0x00, 0x80, 0x00, 0x80, 0x00, 0x00],
        ),
        T::write(ADDR, vec![0x08, 0x01]),
    ]);
    assert_eq!(mag.read_ut(), Err(Error::Saturated));
    finish(mag);
}

#[test]
fn read_16_bit_counts_skip_xyzout2() {
    let mut mag = driver(&[
        T::write_read(ADDR, vec![0x08], vec![0x01]),
        // x = 36864 = null + 4096, y = 30720 = null - 2048, z = 32768
        T::write_read(ADDR, vec![0x00], vec![0x90, 0x00, 0x78, 0x00, 0x80, 0x00]),
        T::write(ADDR, vec![0x08, 0x01]),
    ]);
    mag.set_resolution(Resolution::Bits16);
    assert_close(mag.read_ut().unwrap(), [100.0, -50.0, 0.0], 1e-4);
    finish(mag);
}

#[test]
fn set_reset_measurement_separates_field_and_offset() {
    // offset +100, -200, 0 counts; field +16384, -8192, +4 counts
    let set = [147_556, 122_680, 131_076];
    let reset = [114_788, 139_064, 131_068];
    let mut mag = driver(&[
        // stop continuous mode
        T::write(ADDR, vec![0x0B, 0x05]),
        T::write(ADDR, vec![0x09, 0x08]),
        T::write(ADDR, vec![0x09, 0x01]),
        T::write_read(ADDR, vec![0x08], vec![0x00]),
        T::write_read(ADDR, vec![0x08], vec![0x01]),
        T::write_read(ADDR, vec![0x00], bytes18(set)),
        T::write(ADDR, vec![0x08, 0x01]),
        T::write(ADDR, vec![0x09, 0x10]),
        T::write(ADDR, vec![0x09, 0x01]),
        T::write_read(ADDR, vec![0x08], vec![0x01]),
        T::write_read(ADDR, vec![0x00], bytes18(reset)),
        T::write(ADDR, vec![0x08, 0x01]),
        // restart continuous mode
        T::write(ADDR, vec![0x0B, 0x0D]),
    ]);
    let mut delay = CheckedDelay::new(&[
        D::delay_us(500),
        D::delay_us(8000),
        D::delay_us(500),
        D::delay_us(8000),
    ]);
    let sample = mag.measure_set_reset(&mut delay).unwrap();
    assert_close(
        sample.field_ut,
        [16384.0 * LSB18, -8192.0 * LSB18, 4.0 * LSB18],
        1e-5,
    );
    assert_close(sample.field_ut, [100.0, -50.0, 0.024414], 1e-4);
    assert_close(sample.offset_ut, [100.0 * LSB18, -200.0 * LSB18, 0.0], 1e-5);
    delay.done();
    finish(mag);
}

#[test]
fn set_reset_measurement_suspends_auto_set_reset() {
    let counts = [131_072; 3];
    let mut mag = driver(&[
        T::write(ADDR, vec![0x09, 0x20]),
        T::write(ADDR, vec![0x0B, 0x0D]),
        T::write(ADDR, vec![0x0B, 0x05]),
        // pulses and TM_M without Auto_SR_en
        T::write(ADDR, vec![0x09, 0x08]),
        T::write(ADDR, vec![0x09, 0x01]),
        T::write_read(ADDR, vec![0x08], vec![0x01]),
        T::write_read(ADDR, vec![0x00], bytes18(counts)),
        T::write(ADDR, vec![0x08, 0x01]),
        T::write(ADDR, vec![0x09, 0x10]),
        T::write(ADDR, vec![0x09, 0x01]),
        T::write_read(ADDR, vec![0x08], vec![0x01]),
        T::write_read(ADDR, vec![0x00], bytes18(counts)),
        T::write(ADDR, vec![0x08, 0x01]),
        // Auto_SR_en restored, then continuous mode
        T::write(ADDR, vec![0x09, 0x20]),
        T::write(ADDR, vec![0x0B, 0x0D]),
    ]);
    mag.set_auto_set_reset(AutoSetReset::On).unwrap();
    let mut delay = embedded_hal_mock::eh1::delay::NoopDelay::new();
    let sample = mag.measure_set_reset(&mut delay).unwrap();
    assert_eq!(sample.field_ut, [0.0; 3]);
    assert_eq!(sample.offset_ut, [0.0; 3]);
    finish(mag);
}

#[test]
fn temperature_is_minus_75_plus_0_8_per_lsb() {
    let mut mag = driver(&[
        T::write(ADDR, vec![0x0B, 0x05]),
        T::write(ADDR, vec![0x09, 0x02]),
        T::write_read(ADDR, vec![0x08], vec![0x00]),
        T::write_read(ADDR, vec![0x08], vec![0x02]),
        T::write_read(ADDR, vec![0x07], vec![125]),
        T::write(ADDR, vec![0x08, 0x02]),
        T::write(ADDR, vec![0x0B, 0x0D]),
    ]);
    // -75 + 125 × 0.8 = 25 °C
    let t = mag.temperature_c().unwrap().unwrap();
    assert!((t - 25.0).abs() < 1e-4, "{t}");
    finish(mag);
}

#[test]
fn temperature_times_out_if_never_done() {
    let mut expectations = vec![
        T::write(ADDR, vec![0x0B, 0x05]),
        T::write(ADDR, vec![0x09, 0x02]),
    ];
    for _ in 0..MAX_POLLS {
        expectations.push(T::write_read(ADDR, vec![0x08], vec![0x01]));
    }
    let mut mag = driver(&expectations);
    assert_eq!(mag.temperature_c(), Err(Error::Timeout));
    finish(mag);
}

#[test]
fn nack_surfaces_as_i2c_error() {
    let mut mag = driver(&[T::write(ADDR, vec![0x0B, 0x05]).with_error(NACK)]);
    let mut delay = CheckedDelay::new(&[]);
    assert_eq!(mag.measure_set_reset(&mut delay), Err(Error::I2c(NACK)));
    delay.done();
    finish(mag);
}
