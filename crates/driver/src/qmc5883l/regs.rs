//! QMC5883L register map, from the QST datasheet "QMC5883L" version 1.0
//! (file QMC5883L-Datasheet-1.0), section 9 ("Register Map").

/// 7-bit I2C address (fixed).
pub const ADDRESS: u8 = 0x0D;

/// Data output X LSB; X, Y, Z follow as little-endian two's-complement pairs up to 0x05.
pub const DATA_X_LSB: u8 = 0x00;
/// Data output X MSB.
pub const DATA_X_MSB: u8 = 0x01;
/// Data output Y LSB.
pub const DATA_Y_LSB: u8 = 0x02;
/// Data output Y MSB.
pub const DATA_Y_MSB: u8 = 0x03;
/// Data output Z LSB.
pub const DATA_Z_LSB: u8 = 0x04;
/// Data output Z MSB.
pub const DATA_Z_MSB: u8 = 0x05;
/// Status: DRDY, OVL, DOR.
pub const STATUS: u8 = 0x06;
/// Temperature LSB; with 0x08 a little-endian two's-complement value.
pub const TOUT_LSB: u8 = 0x07;
/// Temperature MSB.
pub const TOUT_MSB: u8 = 0x08;
/// Control register 1: OSR, RNG, ODR, MODE.
pub const CONTROL_1: u8 = 0x09;
/// Control register 2: SOFT_RST, ROL_PNT, INT_ENB.
pub const CONTROL_2: u8 = 0x0A;
/// SET/RESET period register (FBR).
pub const SET_RESET_PERIOD: u8 = 0x0B;
/// Chip id register, reads [`CHIP_ID_VALUE`].
pub const CHIP_ID: u8 = 0x0D;
/// The chip id value.
pub const CHIP_ID_VALUE: u8 = 0xFF;

/// The SET/RESET period the datasheet recommends writing.
pub const SET_RESET_PERIOD_RECOMMENDED: u8 = 0x01;

/// STATUS DRDY: all three axes ready; cleared by reading any data register.
pub const STATUS_DRDY: u8 = 1 << 0;
/// STATUS OVL: an axis is out of range (outputs saturate at -32768/32767).
pub const STATUS_OVL: u8 = 1 << 1;
/// STATUS DOR: a sample was skipped (not read) in continuous mode.
pub const STATUS_DOR: u8 = 1 << 2;
/// CONTROL_1 `OSR[1:0]` position: over-sample ratio 512/256/128/64.
pub const CONTROL_1_OSR_SHIFT: u8 = 6;
/// CONTROL_1 `RNG[1:0]` position: ±2 G / ±8 G.
pub const CONTROL_1_RNG_SHIFT: u8 = 4;
/// CONTROL_1 `ODR[1:0]` position: 10/50/100/200 Hz.
pub const CONTROL_1_ODR_SHIFT: u8 = 2;
/// CONTROL_1 MODE = 00: standby.
pub const CONTROL_1_MODE_STANDBY: u8 = 0b00;
/// CONTROL_1 MODE = 01: continuous.
pub const CONTROL_1_MODE_CONTINUOUS: u8 = 0b01;
/// CONTROL_2 SOFT_RST: restore every register's default.
pub const CONTROL_2_SOFT_RST: u8 = 1 << 7;
/// CONTROL_2 ROL_PNT: pointer roll-over over 0x00–0x06.
pub const CONTROL_2_ROL_PNT: u8 = 1 << 6;
/// CONTROL_2 INT_ENB: 1 disables the DRDY interrupt pin (0 enables it).
pub const CONTROL_2_INT_ENB: u8 = 1 << 0;

/// Temperature coefficient, LSB per °C ("about 100"); the offset is not
/// calibrated, so only differences are meaningful.
pub const TEMP_LSB_PER_C: f32 = 100.0;
