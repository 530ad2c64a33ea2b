//! MMC5983MA register map, from the MEMSIC datasheet "MMC5983MA" Rev A
//! (formal release 4/3/2019), "Register Map" and "Register Details".

/// 7-bit I2C address (`0110000b`).
pub const ADDRESS: u8 = 0x30;

/// Xout0: `Xout[17:10]`.
pub const XOUT0: u8 = 0x00;
/// Xout1: `Xout[9:2]`.
pub const XOUT1: u8 = 0x01;
/// Yout0: `Yout[17:10]`.
pub const YOUT0: u8 = 0x02;
/// Yout1: `Yout[9:2]`.
pub const YOUT1: u8 = 0x03;
/// Zout0: `Zout[17:10]`.
pub const ZOUT0: u8 = 0x04;
/// Zout1: `Zout[9:2]`.
pub const ZOUT1: u8 = 0x05;
/// XYZout2: `Xout[1:0]` in bits 7:6, `Yout[1:0]` in 5:4, `Zout[1:0]` in 3:2.
pub const XYZOUT2: u8 = 0x06;
/// Tout: temperature, unsigned.
pub const TOUT: u8 = 0x07;
/// Status: OTP_Read_Done, Meas_T_Done, Meas_M_Done. Writing 1 to a done bit
/// clears the corresponding interrupt.
pub const STATUS: u8 = 0x08;
/// Internal Control 0 (write-only): TM_M, TM_T, INT_meas_done_en, SET,
/// RESET, Auto_SR_en, OTP_Read.
pub const CONTROL_0: u8 = 0x09;
/// Internal Control 1 (write-only): `BW[1:0]`, X/YZ inhibit, SW_RST.
pub const CONTROL_1: u8 = 0x0A;
/// Internal Control 2 (write-only): `Cm_freq[2:0]`, Cmm_en, `Prd_set[2:0]`, En_prd_set.
pub const CONTROL_2: u8 = 0x0B;
/// Internal Control 3 (write-only): St_enp, St_enm, Spi_3w.
pub const CONTROL_3: u8 = 0x0C;
/// Product ID 1, reads [`PRODUCT_ID_VALUE`].
pub const PRODUCT_ID: u8 = 0x2F;
/// The product id value.
pub const PRODUCT_ID_VALUE: u8 = 0x30;

/// Status OTP_Read_Done: the chip has read its OTP memory.
pub const STATUS_OTP_READ_DONE: u8 = 1 << 4;
/// Status Meas_T_Done: temperature measurement complete.
pub const STATUS_MEAS_T_DONE: u8 = 1 << 1;
/// Status Meas_M_Done: magnetic measurement complete.
pub const STATUS_MEAS_M_DONE: u8 = 1 << 0;
/// Control 0 OTP_Read: re-read OTP.
pub const CONTROL_0_OTP_READ: u8 = 1 << 6;
/// Control 0 Auto_SR_en: automatic set/reset.
pub const CONTROL_0_AUTO_SR_EN: u8 = 1 << 5;
/// Control 0 RESET: reverse magnetising pulse; self-clearing.
pub const CONTROL_0_RESET: u8 = 1 << 4;
/// Control 0 SET: forward magnetising pulse; self-clearing.
pub const CONTROL_0_SET: u8 = 1 << 3;
/// Control 0 INT_meas_done_en: interrupt on measurement done.
pub const CONTROL_0_INT_MEAS_DONE_EN: u8 = 1 << 2;
/// Control 0 TM_T: take one temperature measurement; self-clearing.
pub const CONTROL_0_TM_T: u8 = 1 << 1;
/// Control 0 TM_M: take one magnetic measurement; self-clearing.
pub const CONTROL_0_TM_M: u8 = 1 << 0;
/// Control 1 SW_RST: software reset (10 ms power-on time).
pub const CONTROL_1_SW_RST: u8 = 1 << 7;
/// Control 1 YZ-inhibit (two bits).
pub const CONTROL_1_YZ_INHIBIT: u8 = 0b11 << 3;
/// Control 1 X-inhibit.
pub const CONTROL_1_X_INHIBIT: u8 = 1 << 2;
/// Control 2 En_prd_set: periodic SET (needs Auto_SR_en and Cmm_en).
pub const CONTROL_2_EN_PRD_SET: u8 = 1 << 7;
/// Control 2 `Prd_set[2:0]` position: one SET every 1/25/75/100/250/500/1000/2000 samples.
pub const CONTROL_2_PRD_SET_SHIFT: u8 = 4;
/// Control 2 Cmm_en: continuous measurement mode.
pub const CONTROL_2_CMM_EN: u8 = 1 << 3;
/// Control 3 Spi_3w.
pub const CONTROL_3_SPI_3W: u8 = 1 << 6;
/// Control 3 St_enm: self-test current, negative.
pub const CONTROL_3_ST_ENM: u8 = 1 << 2;
/// Control 3 St_enp: self-test current, positive.
pub const CONTROL_3_ST_ENP: u8 = 1 << 1;

/// Sensitivity in 16-bit operation, counts per gauss.
pub const COUNTS_PER_GAUSS_16: f32 = 4096.0;
/// Null-field output in 16-bit operation, counts.
pub const NULL_FIELD_16: i32 = 32768;
/// Sensitivity in 18-bit operation, counts per gauss.
pub const COUNTS_PER_GAUSS_18: f32 = 16384.0;
/// Null-field output in 18-bit operation, counts.
pub const NULL_FIELD_18: i32 = 131_072;
/// Temperature at Tout = 0, °C.
pub const TEMP_ZERO_C: f32 = -75.0;
/// Temperature step, °C per LSB ("about 0.8").
pub const TEMP_C_PER_LSB: f32 = 0.8;
/// How long the driver waits after a SET or RESET pulse, µs. The datasheet
/// gives a 500 ns pulse; 500 µs is the margin MEMSIC's sample code uses.
pub const SET_RESET_WAIT_US: u32 = 500;
