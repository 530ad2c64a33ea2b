//! LIS2MDL register map, from the ST datasheet DS12144 Rev 6, "Register
//! mapping" and "Register description".

/// 7-bit I2C address (`0011110b`; 0x3C write / 0x3D read).
pub const ADDRESS: u8 = 0x1E;

/// OFFSET_X_REG_L: hard-iron offset X, low byte. The six offset registers are
/// three little-endian two's-complement words at the output's 1.5 mG/LSB; the
/// chip subtracts them from the output data ("These values act on the magnetic
/// output data value in order to delete the environmental offset").
pub const OFFSET_X_REG_L: u8 = 0x45;
/// OFFSET_X_REG_H.
pub const OFFSET_X_REG_H: u8 = 0x46;
/// OFFSET_Y_REG_L.
pub const OFFSET_Y_REG_L: u8 = 0x47;
/// OFFSET_Y_REG_H.
pub const OFFSET_Y_REG_H: u8 = 0x48;
/// OFFSET_Z_REG_L.
pub const OFFSET_Z_REG_L: u8 = 0x49;
/// OFFSET_Z_REG_H.
pub const OFFSET_Z_REG_H: u8 = 0x4A;
/// WHO_AM_I, reads [`WHO_AM_I_VALUE`].
pub const WHO_AM_I: u8 = 0x4F;
/// The device identification value.
pub const WHO_AM_I_VALUE: u8 = 0x40;
/// CFG_REG_A: temperature compensation, reboot, soft reset, low power, ODR, mode.
pub const CFG_REG_A: u8 = 0x60;
/// CFG_REG_B: offset cancellation (set/reset), low-pass filter.
pub const CFG_REG_B: u8 = 0x61;
/// CFG_REG_C: interface, block data update, data-ready pin.
pub const CFG_REG_C: u8 = 0x62;
/// INT_CTRL_REG: interrupt generator configuration.
pub const INT_CTRL_REG: u8 = 0x63;
/// INT_SOURCE_REG: interrupt source (includes MROI, measurement range overflow).
pub const INT_SOURCE_REG: u8 = 0x64;
/// INT_THS_L_REG: interrupt threshold, low byte.
pub const INT_THS_L_REG: u8 = 0x65;
/// INT_THS_H_REG: interrupt threshold, high byte.
pub const INT_THS_H_REG: u8 = 0x66;
/// STATUS_REG: data-available and overrun flags.
pub const STATUS_REG: u8 = 0x67;
/// OUTX_L_REG; X, Y, Z follow as little-endian two's-complement pairs up to 0x6D.
pub const OUTX_L_REG: u8 = 0x68;
/// OUTX_H_REG.
pub const OUTX_H_REG: u8 = 0x69;
/// OUTY_L_REG.
pub const OUTY_L_REG: u8 = 0x6A;
/// OUTY_H_REG.
pub const OUTY_H_REG: u8 = 0x6B;
/// OUTZ_L_REG.
pub const OUTZ_L_REG: u8 = 0x6C;
/// OUTZ_H_REG.
pub const OUTZ_H_REG: u8 = 0x6D;
/// TEMP_OUT_L_REG; with TEMP_OUT_H_REG a little-endian two's-complement temperature.
pub const TEMP_OUT_L_REG: u8 = 0x6E;
/// TEMP_OUT_H_REG.
pub const TEMP_OUT_H_REG: u8 = 0x6F;

/// CFG_REG_A COMP_TEMP_EN: temperature compensation; the datasheet asks for it set.
pub const CFG_A_COMP_TEMP_EN: u8 = 1 << 7;
/// CFG_REG_A REBOOT: reload the trimming memory.
pub const CFG_A_REBOOT: u8 = 1 << 6;
/// CFG_REG_A SOFT_RST: reset configuration and user registers (offsets
/// included); self-clearing.
pub const CFG_A_SOFT_RST: u8 = 1 << 5;
/// CFG_REG_A LP: low-power mode (0 = high resolution).
pub const CFG_A_LP: u8 = 1 << 4;
/// CFG_REG_A `ODR[1:0]` position: 10/20/50/100 Hz.
pub const CFG_A_ODR_SHIFT: u8 = 2;
/// CFG_REG_A `MD[1:0]` = 00: continuous mode.
pub const CFG_A_MD_CONTINUOUS: u8 = 0b00;
/// CFG_REG_A `MD[1:0]` = 01: single mode.
pub const CFG_A_MD_SINGLE: u8 = 0b01;
/// CFG_REG_A `MD[1:0]` = 11: idle (the reset value).
pub const CFG_A_MD_IDLE: u8 = 0b11;
/// CFG_REG_B OFF_CANC_ONE_SHOT: offset cancellation in single mode.
pub const CFG_B_OFF_CANC_ONE_SHOT: u8 = 1 << 4;
/// CFG_REG_B INT_on_DataOFF: interrupt checks data after hard-iron correction.
pub const CFG_B_INT_ON_DATAOFF: u8 = 1 << 3;
/// CFG_REG_B Set_FREQ: set pulse only at power-on (0: every 63 ODR).
pub const CFG_B_SET_FREQ: u8 = 1 << 2;
/// CFG_REG_B OFF_CANC: offset cancellation (set/reset pulses every ODR).
pub const CFG_B_OFF_CANC: u8 = 1 << 1;
/// CFG_REG_B LPF: digital low-pass filter (bandwidth ODR/4 instead of ODR/2).
pub const CFG_B_LPF: u8 = 1 << 0;
/// CFG_REG_C INT_on_PIN.
pub const CFG_C_INT_ON_PIN: u8 = 1 << 6;
/// CFG_REG_C I2C_DIS: disable the I2C interface.
pub const CFG_C_I2C_DIS: u8 = 1 << 5;
/// CFG_REG_C BDU: block data update.
pub const CFG_C_BDU: u8 = 1 << 4;
/// CFG_REG_C BLE: big-endian data.
pub const CFG_C_BLE: u8 = 1 << 3;
/// CFG_REG_C 4WSPI: 4-wire SPI.
pub const CFG_C_4WSPI: u8 = 1 << 2;
/// CFG_REG_C Self_test.
pub const CFG_C_SELF_TEST: u8 = 1 << 1;
/// CFG_REG_C DRDY_on_PIN.
pub const CFG_C_DRDY_ON_PIN: u8 = 1 << 0;
/// STATUS_REG Zyxor: X, Y and Z data overrun.
pub const STATUS_ZYXOR: u8 = 1 << 7;
/// STATUS_REG Zyxda: new X, Y and Z data available.
pub const STATUS_ZYXDA: u8 = 1 << 3;

/// Output and offset sensitivity: 1.5 mG/LSB = 0.15 µT/LSB.
pub const LSB_UT: f32 = 0.15;
/// Temperature sensitivity, LSB per °C.
pub const TEMP_LSB_PER_C: f32 = 8.0;
/// Temperature at output 0, °C (ST's reference conversion for this chip).
pub const TEMP_ZERO_C: f32 = 25.0;
