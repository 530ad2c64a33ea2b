//! QST QMC5883L: ±2 G (12000 LSB/G) or ±8 G (3000 LSB/G), 10/50/100/200 Hz,
//! with an overflow flag and a relative-only temperature.
//!
//! Source: QST datasheet *QMC5883L — 3-Axis Magnetic Sensor*, version 1.0
//! (QMC5883L-Datasheet-1.0): register map and bits, sensitivities, the
//! recommended SET/RESET period (0x0B = 0x01), the status flags (DRDY cleared
//! by reading any data register; OVL when an axis leaves ±32767; DOR when a
//! sample was skipped), chip id 0x0D = 0xFF, and the temperature ("about
//! 100 LSB/°C", gain factory-calibrated, offset not compensated: relative only).
//!
//! Init: identify, then write every writable register: CONTROL_2 = 0 (its
//! reset value: no roll-over, interrupt pin enabled), SET/RESET period 0x01,
//! CONTROL_1 with the configuration and continuous mode. The driver does not
//! use SOFT_RST: the datasheet gives no completion flag or settle time for it,
//! and after writing all three registers the state is the same.
//!
//! [`Magnetometer::temperature_c`] returns `None` because the chip cannot give
//! an absolute temperature; [`Qmc5883l::read_temperature_relative_c`] gives the
//! uncalibrated value for differences.

pub mod regs;

#[cfg(test)]
mod tests;

use embedded_hal::i2c::I2c;

use crate::bus::Bus;
use crate::choose::{nearest, range_at_least, scale};
use crate::{ChipInfo, ChipKind, Error, Magnetometer, UT_PER_GAUSS};

/// Full-scale range (CONTROL_1 RNG).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Range {
    /// ±2 G (±200 µT), 12000 LSB/G.
    G2,
    /// ±8 G (±800 µT), 3000 LSB/G.
    G8,
}

impl Range {
    /// Every range, ascending.
    pub const ALL: [Range; 2] = [Range::G2, Range::G8];

    /// The range in ± µT.
    pub const fn range_ut(self) -> f32 {
        match self {
            Range::G2 => 200.0,
            Range::G8 => 800.0,
        }
    }

    /// Sensitivity in LSB per gauss.
    pub const fn lsb_per_gauss(self) -> f32 {
        match self {
            Range::G2 => 12000.0,
            Range::G8 => 3000.0,
        }
    }

    /// Resolution in µT per LSB.
    pub fn lsb_ut(self) -> f32 {
        UT_PER_GAUSS / self.lsb_per_gauss()
    }

    const fn bits(self) -> u8 {
        match self {
            Range::G2 => 0b00,
            Range::G8 => 0b01,
        }
    }
}

/// Output data rate (CONTROL_1 ODR).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DataRate {
    /// 10 Hz.
    Hz10,
    /// 50 Hz.
    Hz50,
    /// 100 Hz.
    Hz100,
    /// 200 Hz.
    Hz200,
}

impl DataRate {
    /// Every rate, ascending.
    pub const ALL: [DataRate; 4] = [
        DataRate::Hz10,
        DataRate::Hz50,
        DataRate::Hz100,
        DataRate::Hz200,
    ];

    /// The rate in Hz.
    pub const fn hz(self) -> f32 {
        match self {
            DataRate::Hz10 => 10.0,
            DataRate::Hz50 => 50.0,
            DataRate::Hz100 => 100.0,
            DataRate::Hz200 => 200.0,
        }
    }

    const fn bits(self) -> u8 {
        match self {
            DataRate::Hz10 => 0b00,
            DataRate::Hz50 => 0b01,
            DataRate::Hz100 => 0b10,
            DataRate::Hz200 => 0b11,
        }
    }
}

/// Over-sample ratio (CONTROL_1 OSR): larger is less noise, more current.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Oversampling {
    /// 512.
    X512,
    /// 256.
    X256,
    /// 128.
    X128,
    /// 64.
    X64,
}

impl Oversampling {
    const fn bits(self) -> u8 {
        match self {
            Oversampling::X512 => 0b00,
            Oversampling::X256 => 0b01,
            Oversampling::X128 => 0b10,
            Oversampling::X64 => 0b11,
        }
    }
}

const RANGES_UT: [f32; 2] = [Range::G2.range_ut(), Range::G8.range_ut()];

const RATES_HZ: [f32; 4] = [
    DataRate::Hz10.hz(),
    DataRate::Hz50.hz(),
    DataRate::Hz100.hz(),
    DataRate::Hz200.hz(),
];

/// Static facts about the QMC5883L.
pub const INFO: ChipInfo = ChipInfo {
    kind: ChipKind::Qmc5883l,
    name: "QMC5883L",
    vendor: "QST",
    default_address: regs::ADDRESS,
    ranges_ut: &RANGES_UT,
    rates_hz: &RATES_HZ,
    has_temperature: false,
    has_hard_iron_offset: false,
};

/// QMC5883L driver. Defaults are the datasheet's example (CONTROL_1 = 0x1D):
/// ±8 G, 200 Hz, over-sample ratio 512.
#[derive(Debug)]
pub struct Qmc5883l<I2C> {
    bus: Bus<I2C>,
    range: Range,
    data_rate: DataRate,
    oversampling: Oversampling,
}

impl<I2C: I2c> Qmc5883l<I2C> {
    /// A driver at the chip's address `0x0D`; nothing is sent yet.
    pub fn new(i2c: I2C) -> Self {
        Self::with_address(i2c, regs::ADDRESS)
    }

    /// A driver at `address` (for address translators); nothing is sent yet.
    pub fn with_address(i2c: I2C, address: u8) -> Self {
        Qmc5883l {
            bus: Bus { i2c, address },
            range: Range::G8,
            data_rate: DataRate::Hz200,
            oversampling: Oversampling::X512,
        }
    }

    /// Gives the bus back.
    pub fn destroy(self) -> I2C {
        self.bus.i2c
    }

    /// The current range.
    pub fn range(&self) -> Range {
        self.range
    }

    /// The current output data rate.
    pub fn data_rate(&self) -> DataRate {
        self.data_rate
    }

    /// The current over-sample ratio.
    pub fn oversampling(&self) -> Oversampling {
        self.oversampling
    }

    /// Sets the range (writes CONTROL_1, keeping continuous mode).
    pub fn set_range(&mut self, range: Range) -> Result<(), Error<I2C::Error>> {
        self.write_control_1(range, self.data_rate, self.oversampling)
    }

    /// Sets the output data rate (writes CONTROL_1, keeping continuous mode).
    pub fn set_data_rate(&mut self, data_rate: DataRate) -> Result<(), Error<I2C::Error>> {
        self.write_control_1(self.range, data_rate, self.oversampling)
    }

    /// Sets the over-sample ratio (writes CONTROL_1, keeping continuous mode).
    pub fn set_oversampling(
        &mut self,
        oversampling: Oversampling,
    ) -> Result<(), Error<I2C::Error>> {
        self.write_control_1(self.range, self.data_rate, oversampling)
    }

    /// The die temperature with an uncalibrated zero, in °C: only the
    /// difference between two readings is meaningful (about 100 LSB/°C).
    pub fn read_temperature_relative_c(&mut self) -> Result<f32, Error<I2C::Error>> {
        let mut b = [0; 2];
        self.bus.read_regs(regs::TOUT_LSB, &mut b)?;
        Ok(f32::from(i16::from_le_bytes(b)) / regs::TEMP_LSB_PER_C)
    }

    fn write_control_1(
        &mut self,
        range: Range,
        data_rate: DataRate,
        oversampling: Oversampling,
    ) -> Result<(), Error<I2C::Error>> {
        let value = oversampling.bits() << regs::CONTROL_1_OSR_SHIFT
            | range.bits() << regs::CONTROL_1_RNG_SHIFT
            | data_rate.bits() << regs::CONTROL_1_ODR_SHIFT
            | regs::CONTROL_1_MODE_CONTINUOUS;
        self.bus.write_reg(regs::CONTROL_1, value)?;
        self.range = range;
        self.data_rate = data_rate;
        self.oversampling = oversampling;
        Ok(())
    }
}

impl<I2C: I2c> Magnetometer for Qmc5883l<I2C> {
    type Error = Error<I2C::Error>;

    fn identify(&mut self) -> Result<(), Self::Error> {
        self.bus.expect_id(regs::CHIP_ID, regs::CHIP_ID_VALUE)
    }

    fn init(&mut self) -> Result<(), Self::Error> {
        self.identify()?;
        self.bus.write_reg(regs::CONTROL_2, 0)?;
        self.bus
            .write_reg(regs::SET_RESET_PERIOD, regs::SET_RESET_PERIOD_RECOMMENDED)?;
        self.write_control_1(self.range, self.data_rate, self.oversampling)
    }

    fn set_range_ut(&mut self, full_scale_ut: f32) -> Result<f32, Self::Error> {
        let range = range_at_least(&Range::ALL, Range::range_ut, full_scale_ut)
            .ok_or(Error::InvalidConfig)?;
        self.set_range(range)?;
        Ok(range.range_ut())
    }

    fn set_rate_hz(&mut self, rate_hz: f32) -> Result<f32, Self::Error> {
        let rate = nearest(&DataRate::ALL, DataRate::hz, rate_hz).ok_or(Error::InvalidConfig)?;
        self.set_data_rate(rate)?;
        Ok(rate.hz())
    }

    fn data_ready(&mut self) -> Result<bool, Self::Error> {
        Ok(self.bus.read_reg(regs::STATUS)? & regs::STATUS_DRDY != 0)
    }

    /// Reads STATUS, then (if DRDY) the six data bytes, which clears DRDY. With
    /// OVL set the sample is consumed and reported as `Err(Saturated)`.
    fn read_ut(&mut self) -> Result<[f32; 3], Self::Error> {
        let status = self.bus.read_reg(regs::STATUS)?;
        if status & regs::STATUS_DRDY == 0 {
            return Err(Error::NotReady);
        }
        let mut b = [0; 6];
        self.bus.read_regs(regs::DATA_X_LSB, &mut b)?;
        if status & regs::STATUS_OVL != 0 {
            return Err(Error::Saturated);
        }
        let counts = [
            i16::from_le_bytes([b[0], b[1]]).into(),
            i16::from_le_bytes([b[2], b[3]]).into(),
            i16::from_le_bytes([b[4], b[5]]).into(),
        ];
        Ok(scale(counts, self.lsb_ut()))
    }

    /// Always `None`: the chip's temperature offset is not calibrated (see
    /// [`Qmc5883l::read_temperature_relative_c`]).
    fn temperature_c(&mut self) -> Result<Option<f32>, Self::Error> {
        Ok(None)
    }

    fn lsb_ut(&self) -> f32 {
        self.range.lsb_ut()
    }

    fn info(&self) -> ChipInfo {
        INFO
    }
}
