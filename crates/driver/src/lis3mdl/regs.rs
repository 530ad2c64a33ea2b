//! LIS3MDL register map, from the ST datasheet DocID024204 Rev 4 (May 2015),
//! "Register mapping" and "Register description".

/// 7-bit I2C address with SDO/SA1 tied low (`0011100b`).
pub const ADDRESS_SA1_LOW: u8 = 0x1C;
/// 7-bit I2C address with SDO/SA1 tied high (`0011110b`).
pub const ADDRESS_SA1_HIGH: u8 = 0x1E;
/// Set in the sub-address to auto-increment over a multi-byte read
/// (datasheet, I2C operation: to read multiple bytes "SUB(7) must be equal to 1").
pub const AUTO_INCREMENT: u8 = 0x80;

/// WHO_AM_I, reads [`WHO_AM_I_VALUE`].
pub const WHO_AM_I: u8 = 0x0F;
/// The device identification value.
pub const WHO_AM_I_VALUE: u8 = 0x3D;
/// CTRL_REG1: temperature enable, X/Y operating mode, output data rate, fast ODR, self-test.
pub const CTRL_REG1: u8 = 0x20;
/// CTRL_REG2: full scale, reboot, soft reset.
pub const CTRL_REG2: u8 = 0x21;
/// CTRL_REG3: low-power, SPI mode, measurement mode.
pub const CTRL_REG3: u8 = 0x22;
/// CTRL_REG4: Z-axis operating mode, endianness.
pub const CTRL_REG4: u8 = 0x23;
/// CTRL_REG5: fast read, block data update.
pub const CTRL_REG5: u8 = 0x24;
/// STATUS_REG: data-available and overrun flags.
pub const STATUS_REG: u8 = 0x27;
/// OUT_X_L; X, Y, Z follow as little-endian two's-complement pairs up to 0x2D.
pub const OUT_X_L: u8 = 0x28;
/// OUT_X_H.
pub const OUT_X_H: u8 = 0x29;
/// OUT_Y_L.
pub const OUT_Y_L: u8 = 0x2A;
/// OUT_Y_H.
pub const OUT_Y_H: u8 = 0x2B;
/// OUT_Z_L.
pub const OUT_Z_L: u8 = 0x2C;
/// OUT_Z_H.
pub const OUT_Z_H: u8 = 0x2D;
/// TEMP_OUT_L; with TEMP_OUT_H a little-endian two's-complement temperature.
pub const TEMP_OUT_L: u8 = 0x2E;
/// TEMP_OUT_H.
pub const TEMP_OUT_H: u8 = 0x2F;
/// INT_CFG: interrupt configuration.
pub const INT_CFG: u8 = 0x30;
/// INT_SRC: interrupt source (includes MROI, measurement range overflow).
pub const INT_SRC: u8 = 0x31;
/// INT_THS_L: interrupt threshold, low byte.
pub const INT_THS_L: u8 = 0x32;
/// INT_THS_H: interrupt threshold, high byte.
pub const INT_THS_H: u8 = 0x33;

/// CTRL_REG1 TEMP_EN: temperature sensor enable.
pub const CTRL1_TEMP_EN: u8 = 1 << 7;
/// CTRL_REG1 `OM[1:0]` position (X/Y operating mode).
pub const CTRL1_OM_SHIFT: u8 = 5;
/// CTRL_REG1 `DO[2:0]` position (output data rate).
pub const CTRL1_DO_SHIFT: u8 = 2;
/// CTRL_REG1 FAST_ODR: rates above 80 Hz, set by the operating mode.
pub const CTRL1_FAST_ODR: u8 = 1 << 1;
/// CTRL_REG1 ST: self-test enable.
pub const CTRL1_ST: u8 = 1 << 0;
/// CTRL_REG2 `FS[1:0]` position (full scale).
pub const CTRL2_FS_SHIFT: u8 = 5;
/// CTRL_REG2 REBOOT: reload the trimming memory.
pub const CTRL2_REBOOT: u8 = 1 << 3;
/// CTRL_REG2 SOFT_RST: reset configuration and user registers; self-clearing.
pub const CTRL2_SOFT_RST: u8 = 1 << 2;
/// CTRL_REG3 LP: low-power mode (ODR forced to 0.625 Hz).
pub const CTRL3_LP: u8 = 1 << 5;
/// CTRL_REG3 SIM: SPI 3-wire.
pub const CTRL3_SIM: u8 = 1 << 2;
/// CTRL_REG3 `MD[1:0]` = 00: continuous conversion.
pub const CTRL3_MD_CONTINUOUS: u8 = 0b00;
/// CTRL_REG3 `MD[1:0]` = 01: single conversion.
pub const CTRL3_MD_SINGLE: u8 = 0b01;
/// CTRL_REG3 `MD[1:0]` = 11: power-down (the reset value).
pub const CTRL3_MD_POWER_DOWN: u8 = 0b11;
/// CTRL_REG4 `OMZ[1:0]` position (Z-axis operating mode).
pub const CTRL4_OMZ_SHIFT: u8 = 2;
/// CTRL_REG4 BLE: big-endian data.
pub const CTRL4_BLE: u8 = 1 << 1;
/// CTRL_REG5 FAST_READ: read high bytes only.
pub const CTRL5_FAST_READ: u8 = 1 << 7;
/// CTRL_REG5 BDU: output registers not updated until both bytes are read.
pub const CTRL5_BDU: u8 = 1 << 6;
/// STATUS_REG ZYXOR: X, Y and Z data overrun.
pub const STATUS_ZYXOR: u8 = 1 << 7;
/// STATUS_REG ZYXDA: new X, Y and Z data available.
pub const STATUS_ZYXDA: u8 = 1 << 3;

/// Temperature sensitivity, LSB per °C (datasheet, temperature sensor characteristics).
pub const TEMP_LSB_PER_C: f32 = 8.0;
/// Temperature at output 0 (application note AN4602 Rev 1: 0 LSB means 25 °C).
pub const TEMP_ZERO_C: f32 = 25.0;
