//! ST LIS2MDL: ±50 G at a fixed 1.5 mG/LSB, 10/20/50/100 Hz, temperature
//! sensor, and hard-iron offset registers the chip subtracts itself.
//!
//! Source: ST datasheet *LIS2MDL — Digital output magnetic sensor:
//! ultra-low-power, high-performance 3-axis magnetometer*, DS12144 Rev 6:
//! register map and bits, 1.5 mG/LSB sensitivity, ODRs, the OFFSET_*_REG
//! description (two's complement at the output's 1.5 mG/LSB, acting on the
//! output "to delete the environmental offset", i.e. output = measured −
//! offset), temperature sensitivity 8 LSB/°C. The 25 °C zero of the
//! temperature is the one ST's reference conversion uses for this chip (the
//! datasheet gives only the sensitivity).
//!
//! Offset registers versus OFF_CANC: they are independent. OFF_CANC (CFG_REG_B)
//! chooses how the chip cancels its *own* bridge offset with set/reset pulses
//! ([`SetResetMode`]); the hard-iron registers are always subtracted, whatever
//! OFF_CANC says. `SOFT_RST` clears the offset registers, so write the offset
//! after [`Magnetometer::init`].
//!
//! Init: identify, `SOFT_RST` (polled until the chip clears it), CFG_REG_B
//! (set/reset mode), CFG_REG_C (block data update), then CFG_REG_A with
//! temperature compensation on and continuous mode. The chip auto-increments
//! the sub-address on multi-byte access by itself (no MSB flag); the
//! temperature is read in its own transaction. There is no saturation flag in
//! the data path: [`Magnetometer::read_ut`] returns `Saturated` when an axis is
//! within 1 % of the 16-bit output's ends (the field is past ±49 G, or past
//! what the offset registers leave of the range, and the output clipped).

pub mod regs;

#[cfg(test)]
mod tests;

use embedded_hal::i2c::I2c;

use crate::bus::Bus;
use crate::choose::{near_full_scale, nearest, round_to_i16, scale};
use crate::{ChipInfo, ChipKind, Error, HardIronOffset, Magnetometer};

/// The one full-scale range, ± µT (±50 G).
pub const RANGE_UT: f32 = 5000.0;

/// Output data rate (CFG_REG_A `ODR[1:0]`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DataRate {
    /// 10 Hz.
    Hz10,
    /// 20 Hz.
    Hz20,
    /// 50 Hz.
    Hz50,
    /// 100 Hz.
    Hz100,
}

impl DataRate {
    /// Every rate, ascending.
    pub const ALL: [DataRate; 4] = [
        DataRate::Hz10,
        DataRate::Hz20,
        DataRate::Hz50,
        DataRate::Hz100,
    ];

    /// The rate in Hz.
    pub const fn hz(self) -> f32 {
        match self {
            DataRate::Hz10 => 10.0,
            DataRate::Hz20 => 20.0,
            DataRate::Hz50 => 50.0,
            DataRate::Hz100 => 100.0,
        }
    }

    const fn bits(self) -> u8 {
        match self {
            DataRate::Hz10 => 0b00,
            DataRate::Hz20 => 0b01,
            DataRate::Hz50 => 0b10,
            DataRate::Hz100 => 0b11,
        }
    }
}

/// Power mode (CFG_REG_A LP).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PowerMode {
    /// High resolution (lower noise).
    HighResolution,
    /// Low power.
    LowPower,
}

/// How the chip cancels its own bridge offset (CFG_REG_B OFF_CANC and Set_FREQ).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SetResetMode {
    /// Set/reset pulses every ODR, offset cancellation on (OFF_CANC = 1).
    OffsetCancellation,
    /// A set pulse every 63 ODR, no cancellation (the chip's reset state).
    SetEvery63Odr,
    /// A set pulse only at power-on (Set_FREQ = 1).
    SetAtPowerOnOnly,
}

impl SetResetMode {
    const fn bits(self) -> u8 {
        match self {
            SetResetMode::OffsetCancellation => regs::CFG_B_OFF_CANC,
            SetResetMode::SetEvery63Odr => 0,
            SetResetMode::SetAtPowerOnOnly => regs::CFG_B_SET_FREQ,
        }
    }
}

const RANGES_UT: [f32; 1] = [RANGE_UT];

const RATES_HZ: [f32; 4] = [
    DataRate::Hz10.hz(),
    DataRate::Hz20.hz(),
    DataRate::Hz50.hz(),
    DataRate::Hz100.hz(),
];

/// Static facts about the LIS2MDL.
pub const INFO: ChipInfo = ChipInfo {
    kind: ChipKind::Lis2mdl,
    name: "LIS2MDL",
    vendor: "STMicroelectronics",
    default_address: regs::ADDRESS,
    ranges_ut: &RANGES_UT,
    rates_hz: &RATES_HZ,
    has_temperature: true,
    has_hard_iron_offset: true,
};

/// LIS2MDL driver. Defaults: 100 Hz, high resolution, offset cancellation on.
#[derive(Debug)]
pub struct Lis2mdl<I2C> {
    bus: Bus<I2C>,
    data_rate: DataRate,
    power_mode: PowerMode,
    set_reset: SetResetMode,
}

impl<I2C: I2c> Lis2mdl<I2C> {
    /// A driver at the default address `0x1E`; nothing is sent yet.
    pub fn new(i2c: I2C) -> Self {
        Self::with_address(i2c, regs::ADDRESS)
    }

    /// A driver at `address`; nothing is sent yet.
    pub fn with_address(i2c: I2C, address: u8) -> Self {
        Lis2mdl {
            bus: Bus { i2c, address },
            data_rate: DataRate::Hz100,
            power_mode: PowerMode::HighResolution,
            set_reset: SetResetMode::OffsetCancellation,
        }
    }

    /// Gives the bus back.
    pub fn destroy(self) -> I2C {
        self.bus.i2c
    }

    /// The current output data rate.
    pub fn data_rate(&self) -> DataRate {
        self.data_rate
    }

    /// The current power mode.
    pub fn power_mode(&self) -> PowerMode {
        self.power_mode
    }

    /// The current set/reset (offset cancellation) mode.
    pub fn set_reset_mode(&self) -> SetResetMode {
        self.set_reset
    }

    /// Sets the output data rate (writes CFG_REG_A, keeping continuous mode).
    pub fn set_data_rate(&mut self, data_rate: DataRate) -> Result<(), Error<I2C::Error>> {
        self.bus
            .write_reg(regs::CFG_REG_A, cfg_reg_a(data_rate, self.power_mode))?;
        self.data_rate = data_rate;
        Ok(())
    }

    /// Sets the power mode (writes CFG_REG_A, keeping continuous mode).
    pub fn set_power_mode(&mut self, power_mode: PowerMode) -> Result<(), Error<I2C::Error>> {
        self.bus
            .write_reg(regs::CFG_REG_A, cfg_reg_a(self.data_rate, power_mode))?;
        self.power_mode = power_mode;
        Ok(())
    }

    /// Sets how the chip cancels its own bridge offset (writes CFG_REG_B).
    pub fn set_set_reset_mode(&mut self, mode: SetResetMode) -> Result<(), Error<I2C::Error>> {
        self.bus.write_reg(regs::CFG_REG_B, mode.bits())?;
        self.set_reset = mode;
        Ok(())
    }
}

/// CFG_REG_A for continuous mode with temperature compensation on.
fn cfg_reg_a(data_rate: DataRate, power_mode: PowerMode) -> u8 {
    let lp = match power_mode {
        PowerMode::HighResolution => 0,
        PowerMode::LowPower => regs::CFG_A_LP,
    };
    regs::CFG_A_COMP_TEMP_EN
        | lp
        | data_rate.bits() << regs::CFG_A_ODR_SHIFT
        | regs::CFG_A_MD_CONTINUOUS
}

/// Three little-endian i16 words.
fn words(b: [u8; 6]) -> [i16; 3] {
    [
        i16::from_le_bytes([b[0], b[1]]),
        i16::from_le_bytes([b[2], b[3]]),
        i16::from_le_bytes([b[4], b[5]]),
    ]
}

impl<I2C: I2c> Magnetometer for Lis2mdl<I2C> {
    type Error = Error<I2C::Error>;

    fn identify(&mut self) -> Result<(), Self::Error> {
        self.bus.expect_id(regs::WHO_AM_I, regs::WHO_AM_I_VALUE)
    }

    fn init(&mut self) -> Result<(), Self::Error> {
        self.identify()?;
        self.bus.write_reg(regs::CFG_REG_A, regs::CFG_A_SOFT_RST)?;
        self.bus
            .poll_until(regs::CFG_REG_A, |v| v & regs::CFG_A_SOFT_RST == 0)?;
        self.set_set_reset_mode(self.set_reset)?;
        self.bus.write_reg(regs::CFG_REG_C, regs::CFG_C_BDU)?;
        self.set_data_rate(self.data_rate)
    }

    fn set_range_ut(&mut self, full_scale_ut: f32) -> Result<f32, Self::Error> {
        if !(full_scale_ut.is_finite() && full_scale_ut > 0.0) {
            return Err(Error::InvalidConfig);
        }
        Ok(RANGE_UT)
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
        self.bus.read_regs(regs::OUTX_L_REG, &mut b)?;
        let counts = words(b).map(i32::from);
        if near_full_scale(counts, i16::MIN.into(), i16::MAX.into()) {
            return Err(Error::Saturated);
        }
        Ok(scale(counts, regs::LSB_UT))
    }

    fn temperature_c(&mut self) -> Result<Option<f32>, Self::Error> {
        let mut b = [0; 2];
        self.bus.read_regs(regs::TEMP_OUT_L_REG, &mut b)?;
        let raw = f32::from(i16::from_le_bytes(b));
        Ok(Some(raw / regs::TEMP_LSB_PER_C + regs::TEMP_ZERO_C))
    }

    fn lsb_ut(&self) -> f32 {
        regs::LSB_UT
    }

    fn info(&self) -> ChipInfo {
        INFO
    }
}

impl<I2C: I2c> HardIronOffset for Lis2mdl<I2C> {
    /// Writes OFFSET_X_REG_L..OFFSET_Z_REG_H in one transaction, each axis
    /// rounded to the nearest 0.15 µT; `Err(InvalidConfig)` (nothing written)
    /// if an axis is not finite or beyond ±4915.2 µT.
    fn write_offset_ut(&mut self, offset_ut: [f32; 3]) -> Result<(), Self::Error> {
        let mut counts = [0i16; 3];
        for (count, ut) in counts.iter_mut().zip(offset_ut) {
            *count = round_to_i16(ut / regs::LSB_UT).ok_or(Error::InvalidConfig)?;
        }
        let [x, y, z] = counts.map(i16::to_le_bytes);
        let frame = [regs::OFFSET_X_REG_L, x[0], x[1], y[0], y[1], z[0], z[1]];
        self.bus
            .i2c
            .write(self.bus.address, &frame)
            .map_err(Error::I2c)
    }

    fn read_offset_ut(&mut self) -> Result<[f32; 3], Self::Error> {
        let mut b = [0; 6];
        self.bus.read_regs(regs::OFFSET_X_REG_L, &mut b)?;
        Ok(scale(words(b).map(i32::from), regs::LSB_UT))
    }
}
