//! HMC5883L register map, from the Honeywell datasheet "3-Axis Digital Compass
//! IC HMC5883L", Form #900405 Rev E (February 2013), "Registers".

/// 7-bit I2C address (0x3C write / 0x3D read).
pub const ADDRESS: u8 = 0x1E;

/// Configuration register A: samples averaged, output rate, measurement mode.
pub const CONFIG_A: u8 = 0x00;
/// Configuration register B: gain.
pub const CONFIG_B: u8 = 0x01;
/// Mode register.
pub const MODE: u8 = 0x02;
/// Data output X MSB. The data registers run X, **Z**, Y, each big-endian
/// two's complement in -2048..=2047, or [`OVERFLOW`] on overflow.
pub const DATA_X_MSB: u8 = 0x03;
/// Data output X LSB.
pub const DATA_X_LSB: u8 = 0x04;
/// Data output Z MSB.
pub const DATA_Z_MSB: u8 = 0x05;
/// Data output Z LSB.
pub const DATA_Z_LSB: u8 = 0x06;
/// Data output Y MSB.
pub const DATA_Y_MSB: u8 = 0x07;
/// Data output Y LSB.
pub const DATA_Y_LSB: u8 = 0x08;
/// Status register: LOCK, RDY.
pub const STATUS: u8 = 0x09;
/// Identification register A, reads `'H'`.
pub const ID_A: u8 = 0x0A;
/// Identification register B, reads `'4'`.
pub const ID_B: u8 = 0x0B;
/// Identification register C, reads `'3'`.
pub const ID_C: u8 = 0x0C;
/// The identification registers' contents.
pub const ID_VALUE: [u8; 3] = *b"H43";

/// CONFIG_A `MA[1:0]` position: 1, 2, 4 or 8 samples averaged.
pub const CONFIG_A_MA_SHIFT: u8 = 5;
/// CONFIG_A `DO[2:0]` position: output rate.
pub const CONFIG_A_DO_SHIFT: u8 = 2;
/// CONFIG_A `MS[1:0]` = 00: normal measurement (no bias).
pub const CONFIG_A_MS_NORMAL: u8 = 0b00;
/// CONFIG_A `MS[1:0]` = 01: positive bias (self-test).
pub const CONFIG_A_MS_POSITIVE_BIAS: u8 = 0b01;
/// CONFIG_A `MS[1:0]` = 10: negative bias (self-test).
pub const CONFIG_A_MS_NEGATIVE_BIAS: u8 = 0b10;
/// CONFIG_B `GN[2:0]` position: gain.
pub const CONFIG_B_GN_SHIFT: u8 = 5;
/// MODE HS: 3400 kHz high-speed I2C.
pub const MODE_HS: u8 = 1 << 7;
/// MODE `MD[1:0]` = 00: continuous measurement.
pub const MODE_CONTINUOUS: u8 = 0b00;
/// MODE `MD[1:0]` = 01: single measurement (the reset value).
pub const MODE_SINGLE: u8 = 0b01;
/// MODE `MD[1:0]` = 10: idle.
pub const MODE_IDLE: u8 = 0b10;
/// STATUS LOCK: some but not all data registers read; outputs locked.
pub const STATUS_LOCK: u8 = 1 << 1;
/// STATUS RDY: all six data registers written.
pub const STATUS_RDY: u8 = 1 << 0;

/// The value a data register holds when its channel over- or underflowed.
pub const OVERFLOW: i16 = -4096;
