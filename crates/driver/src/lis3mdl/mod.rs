//! ST LIS3MDL: ±4/8/12/16 G, 16-bit, 0.625–80 Hz (155–1000 Hz in fast-ODR mode),
//! with a temperature sensor.
//!
//! Source: ST datasheet *LIS3MDL — Digital output magnetic sensor:
//! ultra-low-power, high-performance 3-axis magnetometer*, DocID024204 Rev 4
//! (May 2015): register map, bit positions, full scales and sensitivities
//! (6842/3421/2281/1711 LSB/G), output data rates (Table "Output data rate
//! configuration", fast ODR 1000/560/300/155 Hz for LP/MP/HP/UHP), the
//! sub-address auto-increment bit, and the temperature sensitivity (8 LSB/°C);
//! ST application note AN4602 Rev 1 for the temperature zero (0 LSB = 25 °C).
//!
//! Init: identify, `SOFT_RST` (polled until the chip clears it), then CTRL_REG1,
//! 2, 4, 5 (temperature on, block data update on) and finally CTRL_REG3 =
//! continuous conversion. Multi-byte reads set [`regs::AUTO_INCREMENT`]; the
//! temperature is read in its own transaction because a burst from OUT_X_L
//! wraps back to OUT_X_L after OUT_Z_H. The chip has no flag for a saturated
//! field in the data path: [`Magnetometer::read_ut`] returns `Saturated` when an
//! axis is within 1 % of the 16-bit output's ends (the field is past the range
//! and the output clipped).

pub mod regs;

#[cfg(test)]
mod tests;

use embedded_hal::i2c::I2c;

use crate::bus::Bus;
use crate::choose::{near_full_scale, nearest, range_at_least, scale};
use crate::{ChipInfo, ChipKind, Error, Magnetometer, UT_PER_GAUSS};

/// Full-scale range (CTRL_REG2 `FS[1:0]`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FullScale {
    /// ±4 G (±400 µT), 6842 LSB/G.
    G4,
    /// ±8 G (±800 µT), 3421 LSB/G.
    G8,
    /// ±12 G (±1200 µT), 2281 LSB/G.
    G12,
    /// ±16 G (±1600 µT), 1711 LSB/G.
    G16,
}

impl FullScale {
    /// Every full scale, ascending.
    pub const ALL: [FullScale; 4] = [FullScale::G4, FullScale::G8, FullScale::G12, FullScale::G16];

    /// The range in ± µT.
    pub const fn range_ut(self) -> f32 {
        match self {
            FullScale::G4 => 400.0,
            FullScale::G8 => 800.0,
            FullScale::G12 => 1200.0,
            FullScale::G16 => 1600.0,
        }
    }

    /// Sensitivity in LSB per gauss.
    pub const fn lsb_per_gauss(self) -> f32 {
        match self {
            FullScale::G4 => 6842.0,
            FullScale::G8 => 3421.0,
            FullScale::G12 => 2281.0,
            FullScale::G16 => 1711.0,
        }
    }

    /// Resolution in µT per LSB.
    pub fn lsb_ut(self) -> f32 {
        UT_PER_GAUSS / self.lsb_per_gauss()
    }

    const fn bits(self) -> u8 {
        match self {
            FullScale::G4 => 0b00,
            FullScale::G8 => 0b01,
            FullScale::G12 => 0b10,
            FullScale::G16 => 0b11,
        }
    }
}

/// Operating mode of the X/Y and Z axes (CTRL_REG1 OM, CTRL_REG4 OMZ): trades
/// current for noise, and fixes the rate in fast-ODR mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OperatingMode {
    /// Low-power (fast ODR 1000 Hz).
    LowPower,
    /// Medium performance (fast ODR 560 Hz).
    MediumPerformance,
    /// High performance (fast ODR 300 Hz).
    HighPerformance,
    /// Ultra-high performance, lowest noise (fast ODR 155 Hz).
    UltraHighPerformance,
}

impl OperatingMode {
    const fn bits(self) -> u8 {
        match self {
            OperatingMode::LowPower => 0b00,
            OperatingMode::MediumPerformance => 0b01,
            OperatingMode::HighPerformance => 0b10,
            OperatingMode::UltraHighPerformance => 0b11,
        }
    }
}

/// Output data rate (CTRL_REG1 `DO[2:0]`, or FAST_ODR with the mode it implies).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DataRate {
    /// 0.625 Hz.
    Hz0_625,
    /// 1.25 Hz.
    Hz1_25,
    /// 2.5 Hz.
    Hz2_5,
    /// 5 Hz.
    Hz5,
    /// 10 Hz.
    Hz10,
    /// 20 Hz.
    Hz20,
    /// 40 Hz.
    Hz40,
    /// 80 Hz.
    Hz80,
    /// 155 Hz: fast ODR in ultra-high-performance mode.
    Hz155,
    /// 300 Hz: fast ODR in high-performance mode.
    Hz300,
    /// 560 Hz: fast ODR in medium-performance mode.
    Hz560,
    /// 1000 Hz: fast ODR in low-power mode.
    Hz1000,
}

impl DataRate {
    /// Every rate, ascending.
    pub const ALL: [DataRate; 12] = [
        DataRate::Hz0_625,
        DataRate::Hz1_25,
        DataRate::Hz2_5,
        DataRate::Hz5,
        DataRate::Hz10,
        DataRate::Hz20,
        DataRate::Hz40,
        DataRate::Hz80,
        DataRate::Hz155,
        DataRate::Hz300,
        DataRate::Hz560,
        DataRate::Hz1000,
    ];

    /// The rate in Hz.
    pub const fn hz(self) -> f32 {
        match self {
            DataRate::Hz0_625 => 0.625,
            DataRate::Hz1_25 => 1.25,
            DataRate::Hz2_5 => 2.5,
            DataRate::Hz5 => 5.0,
            DataRate::Hz10 => 10.0,
            DataRate::Hz20 => 20.0,
            DataRate::Hz40 => 40.0,
            DataRate::Hz80 => 80.0,
            DataRate::Hz155 => 155.0,
            DataRate::Hz300 => 300.0,
            DataRate::Hz560 => 560.0,
            DataRate::Hz1000 => 1000.0,
        }
    }

    /// The operating mode a fast-ODR rate requires; `None` for DO rates.
    pub const fn fast_odr_mode(self) -> Option<OperatingMode> {
        match self {
            DataRate::Hz155 => Some(OperatingMode::UltraHighPerformance),
            DataRate::Hz300 => Some(OperatingMode::HighPerformance),
            DataRate::Hz560 => Some(OperatingMode::MediumPerformance),
            DataRate::Hz1000 => Some(OperatingMode::LowPower),
            _ => None,
        }
    }

    /// `DO[2:0]`; 000 for fast-ODR rates, where the datasheet ignores DO.
    const fn do_bits(self) -> u8 {
        match self {
            DataRate::Hz0_625 => 0b000,
            DataRate::Hz1_25 => 0b001,
            DataRate::Hz2_5 => 0b010,
            DataRate::Hz5 => 0b011,
            DataRate::Hz10 => 0b100,
            DataRate::Hz20 => 0b101,
            DataRate::Hz40 => 0b110,
            DataRate::Hz80 => 0b111,
            DataRate::Hz155 | DataRate::Hz300 | DataRate::Hz560 | DataRate::Hz1000 => 0b000,
        }
    }
}

const RANGES_UT: [f32; 4] = [
    FullScale::G4.range_ut(),
    FullScale::G8.range_ut(),
    FullScale::G12.range_ut(),
    FullScale::G16.range_ut(),
];

const RATES_HZ: [f32; 12] = [
    DataRate::Hz0_625.hz(),
    DataRate::Hz1_25.hz(),
    DataRate::Hz2_5.hz(),
    DataRate::Hz5.hz(),
    DataRate::Hz10.hz(),
    DataRate::Hz20.hz(),
    DataRate::Hz40.hz(),
    DataRate::Hz80.hz(),
    DataRate::Hz155.hz(),
    DataRate::Hz300.hz(),
    DataRate::Hz560.hz(),
    DataRate::Hz1000.hz(),
];

/// Static facts about the LIS3MDL.
pub const INFO: ChipInfo = ChipInfo {
    kind: ChipKind::Lis3mdl,
    name: "LIS3MDL",
    vendor: "STMicroelectronics",
    default_address: regs::ADDRESS_SA1_LOW,
    ranges_ut: &RANGES_UT,
    rates_hz: &RATES_HZ,
    has_temperature: true,
    has_hard_iron_offset: false,
};

/// LIS3MDL driver. Defaults: ±4 G, 80 Hz, ultra-high-performance mode.
#[derive(Debug)]
pub struct Lis3mdl<I2C> {
    bus: Bus<I2C>,
    full_scale: FullScale,
    data_rate: DataRate,
    mode: OperatingMode,
}

impl<I2C: I2c> Lis3mdl<I2C> {
    /// A driver at the default address (SDO/SA1 low, `0x1C`); nothing is sent yet.
    pub fn new(i2c: I2C) -> Self {
        Self::with_address(i2c, regs::ADDRESS_SA1_LOW)
    }

    /// A driver at `address` (`0x1E` with SDO/SA1 high); nothing is sent yet.
    pub fn with_address(i2c: I2C, address: u8) -> Self {
        Lis3mdl {
            bus: Bus { i2c, address },
            full_scale: FullScale::G4,
            data_rate: DataRate::Hz80,
            mode: OperatingMode::UltraHighPerformance,
        }
    }

    /// Gives the bus back.
    pub fn destroy(self) -> I2C {
        self.bus.i2c
    }

    /// The current full scale.
    pub fn full_scale(&self) -> FullScale {
        self.full_scale
    }

    /// The current output data rate.
    pub fn data_rate(&self) -> DataRate {
        self.data_rate
    }

    /// The current operating mode.
    pub fn operating_mode(&self) -> OperatingMode {
        self.mode
    }

    /// Sets the full scale (writes CTRL_REG2).
    pub fn set_full_scale(&mut self, full_scale: FullScale) -> Result<(), Error<I2C::Error>> {
        self.bus
            .write_reg(regs::CTRL_REG2, full_scale.bits() << regs::CTRL2_FS_SHIFT)?;
        self.full_scale = full_scale;
        Ok(())
    }

    /// Sets the output data rate (writes CTRL_REG1 and CTRL_REG4). A fast-ODR
    /// rate (155–1000 Hz) also sets the operating mode it requires, which stays
    /// selected when a DO rate is chosen later.
    pub fn set_data_rate(&mut self, data_rate: DataRate) -> Result<(), Error<I2C::Error>> {
        let mode = data_rate.fast_odr_mode().unwrap_or(self.mode);
        self.write_rate_and_mode(data_rate, mode)
    }

    /// Sets the operating mode (writes CTRL_REG1 and CTRL_REG4).
    /// `Err(InvalidConfig)` while a fast-ODR rate is selected with another
    /// mode, since there the rate fixes the mode.
    pub fn set_operating_mode(&mut self, mode: OperatingMode) -> Result<(), Error<I2C::Error>> {
        if self.data_rate.fast_odr_mode().is_some_and(|m| m != mode) {
            return Err(Error::InvalidConfig);
        }
        self.write_rate_and_mode(self.data_rate, mode)
    }

    fn write_rate_and_mode(
        &mut self,
        data_rate: DataRate,
        mode: OperatingMode,
    ) -> Result<(), Error<I2C::Error>> {
        self.bus
            .write_reg(regs::CTRL_REG1, ctrl_reg1(data_rate, mode))?;
        self.bus
            .write_reg(regs::CTRL_REG4, mode.bits() << regs::CTRL4_OMZ_SHIFT)?;
        self.data_rate = data_rate;
        self.mode = mode;
        Ok(())
    }
}

/// CTRL_REG1 for a rate and mode, with the temperature sensor on.
fn ctrl_reg1(data_rate: DataRate, mode: OperatingMode) -> u8 {
    let fast = if data_rate.fast_odr_mode().is_some() {
        regs::CTRL1_FAST_ODR
    } else {
        0
    };
    regs::CTRL1_TEMP_EN
        | mode.bits() << regs::CTRL1_OM_SHIFT
        | data_rate.do_bits() << regs::CTRL1_DO_SHIFT
        | fast
}

impl<I2C: I2c> Magnetometer for Lis3mdl<I2C> {
    type Error = Error<I2C::Error>;

    fn identify(&mut self) -> Result<(), Self::Error> {
        self.bus.expect_id(regs::WHO_AM_I, regs::WHO_AM_I_VALUE)
    }

    fn init(&mut self) -> Result<(), Self::Error> {
        self.identify()?;
        self.bus.write_reg(regs::CTRL_REG2, regs::CTRL2_SOFT_RST)?;
        self.bus
            .poll_until(regs::CTRL_REG2, |v| v & regs::CTRL2_SOFT_RST == 0)?;
        self.write_rate_and_mode(self.data_rate, self.mode)?;
        self.set_full_scale(self.full_scale)?;
        self.bus.write_reg(regs::CTRL_REG5, regs::CTRL5_BDU)?;
        self.bus
            .write_reg(regs::CTRL_REG3, regs::CTRL3_MD_CONTINUOUS)
    }

    fn set_range_ut(&mut self, full_scale_ut: f32) -> Result<f32, Self::Error> {
        let full_scale = range_at_least(&FullScale::ALL, FullScale::range_ut, full_scale_ut)
            .ok_or(Error::InvalidConfig)?;
        self.set_full_scale(full_scale)?;
        Ok(full_scale.range_ut())
    }

    fn set_rate_hz(&mut self, rate_hz: f32) -> Result<f32, Self::Error> {
        let rate = nearest(&DataRate::ALL, DataRate::hz, rate_hz).ok_or(Error::InvalidConfig)?;
        self.set_data_rate(rate)?;
        Ok(rate.hz())
    }

    fn data_ready(&mut self) -> Result<bool, Self::Error> {
        Ok(self.bus.read_reg(regs::STATUS_REG)? & regs::STATUS_ZYXDA != 0)
    }

    fn read_ut(&mut self) -> Result<[f32; 3], Self::Error> {
        if !self.data_ready()? {
            return Err(Error::NotReady);
        }
        let mut b = [0; 6];
        self.bus
            .read_regs(regs::OUT_X_L | regs::AUTO_INCREMENT, &mut b)?;
        let counts = [
            i16::from_le_bytes([b[0], b[1]]).into(),
            i16::from_le_bytes([b[2], b[3]]).into(),
            i16::from_le_bytes([b[4], b[5]]).into(),
        ];
        if near_full_scale(counts, i16::MIN.into(), i16::MAX.into()) {
            return Err(Error::Saturated);
        }
        Ok(scale(counts, self.lsb_ut()))
    }

    fn temperature_c(&mut self) -> Result<Option<f32>, Self::Error> {
        let mut b = [0; 2];
        self.bus
            .read_regs(regs::TEMP_OUT_L | regs::AUTO_INCREMENT, &mut b)?;
        let raw = f32::from(i16::from_le_bytes(b));
        Ok(Some(raw / regs::TEMP_LSB_PER_C + regs::TEMP_ZERO_C))
    }

    fn lsb_ut(&self) -> f32 {
        self.full_scale.lsb_ut()
    }

    fn info(&self) -> ChipInfo {
        INFO
    }
}
