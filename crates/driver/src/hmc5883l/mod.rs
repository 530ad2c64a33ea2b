//! Honeywell HMC5883L: eight gains from ±0.88 G to ±8.1 G, 12-bit output,
//! 0.75–75 Hz, no temperature sensor.
//!
//! Source: Honeywell datasheet *3-Axis Digital Compass IC HMC5883L*, Form
//! #900405 Rev E (February 2013): register list and bits, the X, Z, Y order
//! of the MSB-first data registers, identification `'H' '4' '3'`, gains
//! 1370/1090/820/660/440/390/330/230 LSB/G, output rates (Table "Data Output
//! Rates"), the overflow value -4096, the LOCK/RDY status bits, the note that
//! "the very first measurement after a gain change maintains the same gain as
//! the previous setting", and the example init (CRA 0x70: 8 samples averaged,
//! 15 Hz).
//!
//! Init: identify, then write every writable register: CONFIG_A, CONFIG_B
//! and MODE = continuous (the chip has no reset command). Because the first
//! sample after a gain change still uses the old gain, the driver drops one
//! sample after [`Magnetometer::init`] and after every gain change:
//! [`Magnetometer::read_ut`] reads it (so the chip moves on) and returns
//! `Err(NotReady)`. All six data bytes are read in one transaction, as the
//! data registers stay locked until all six have been read.

pub mod regs;

#[cfg(test)]
mod tests;

use embedded_hal::i2c::I2c;

use crate::bus::Bus;
use crate::choose::{nearest, range_at_least, scale};
use crate::{ChipInfo, ChipKind, Error, Magnetometer, UT_PER_GAUSS};

/// Gain (CONFIG_B `GN[2:0]`), named by the datasheet's recommended field range.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Gain {
    /// ±0.88 G, 1370 LSB/G.
    Ga0_88,
    /// ±1.3 G, 1090 LSB/G (the reset value).
    Ga1_3,
    /// ±1.9 G, 820 LSB/G.
    Ga1_9,
    /// ±2.5 G, 660 LSB/G.
    Ga2_5,
    /// ±4.0 G, 440 LSB/G.
    Ga4_0,
    /// ±4.7 G, 390 LSB/G.
    Ga4_7,
    /// ±5.6 G, 330 LSB/G.
    Ga5_6,
    /// ±8.1 G, 230 LSB/G.
    Ga8_1,
}

impl Gain {
    /// Every gain, by ascending range.
    pub const ALL: [Gain; 8] = [
        Gain::Ga0_88,
        Gain::Ga1_3,
        Gain::Ga1_9,
        Gain::Ga2_5,
        Gain::Ga4_0,
        Gain::Ga4_7,
        Gain::Ga5_6,
        Gain::Ga8_1,
    ];

    /// The recommended field range in ± µT.
    pub const fn range_ut(self) -> f32 {
        match self {
            Gain::Ga0_88 => 88.0,
            Gain::Ga1_3 => 130.0,
            Gain::Ga1_9 => 190.0,
            Gain::Ga2_5 => 250.0,
            Gain::Ga4_0 => 400.0,
            Gain::Ga4_7 => 470.0,
            Gain::Ga5_6 => 560.0,
            Gain::Ga8_1 => 810.0,
        }
    }

    /// Sensitivity in LSB per gauss.
    pub const fn lsb_per_gauss(self) -> f32 {
        match self {
            Gain::Ga0_88 => 1370.0,
            Gain::Ga1_3 => 1090.0,
            Gain::Ga1_9 => 820.0,
            Gain::Ga2_5 => 660.0,
            Gain::Ga4_0 => 440.0,
            Gain::Ga4_7 => 390.0,
            Gain::Ga5_6 => 330.0,
            Gain::Ga8_1 => 230.0,
        }
    }

    /// Resolution in µT per LSB.
    pub fn lsb_ut(self) -> f32 {
        UT_PER_GAUSS / self.lsb_per_gauss()
    }

    const fn bits(self) -> u8 {
        match self {
            Gain::Ga0_88 => 0,
            Gain::Ga1_3 => 1,
            Gain::Ga1_9 => 2,
            Gain::Ga2_5 => 3,
            Gain::Ga4_0 => 4,
            Gain::Ga4_7 => 5,
            Gain::Ga5_6 => 6,
            Gain::Ga8_1 => 7,
        }
    }
}

/// Output rate in continuous mode (CONFIG_A `DO[2:0]`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DataRate {
    /// 0.75 Hz.
    Hz0_75,
    /// 1.5 Hz.
    Hz1_5,
    /// 3 Hz.
    Hz3,
    /// 7.5 Hz.
    Hz7_5,
    /// 15 Hz (the reset value).
    Hz15,
    /// 30 Hz.
    Hz30,
    /// 75 Hz.
    Hz75,
}

impl DataRate {
    /// Every rate, ascending.
    pub const ALL: [DataRate; 7] = [
        DataRate::Hz0_75,
        DataRate::Hz1_5,
        DataRate::Hz3,
        DataRate::Hz7_5,
        DataRate::Hz15,
        DataRate::Hz30,
        DataRate::Hz75,
    ];

    /// The rate in Hz.
    pub const fn hz(self) -> f32 {
        match self {
            DataRate::Hz0_75 => 0.75,
            DataRate::Hz1_5 => 1.5,
            DataRate::Hz3 => 3.0,
            DataRate::Hz7_5 => 7.5,
            DataRate::Hz15 => 15.0,
            DataRate::Hz30 => 30.0,
            DataRate::Hz75 => 75.0,
        }
    }

    const fn bits(self) -> u8 {
        match self {
            DataRate::Hz0_75 => 0,
            DataRate::Hz1_5 => 1,
            DataRate::Hz3 => 2,
            DataRate::Hz7_5 => 3,
            DataRate::Hz15 => 4,
            DataRate::Hz30 => 5,
            DataRate::Hz75 => 6,
        }
    }
}

/// Samples averaged per output (CONFIG_A `MA[1:0]`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Averaging {
    /// 1 sample.
    X1,
    /// 2 samples.
    X2,
    /// 4 samples.
    X4,
    /// 8 samples.
    X8,
}

impl Averaging {
    const fn bits(self) -> u8 {
        match self {
            Averaging::X1 => 0b00,
            Averaging::X2 => 0b01,
            Averaging::X4 => 0b10,
            Averaging::X8 => 0b11,
        }
    }
}

const RANGES_UT: [f32; 8] = [
    Gain::Ga0_88.range_ut(),
    Gain::Ga1_3.range_ut(),
    Gain::Ga1_9.range_ut(),
    Gain::Ga2_5.range_ut(),
    Gain::Ga4_0.range_ut(),
    Gain::Ga4_7.range_ut(),
    Gain::Ga5_6.range_ut(),
    Gain::Ga8_1.range_ut(),
];

const RATES_HZ: [f32; 7] = [
    DataRate::Hz0_75.hz(),
    DataRate::Hz1_5.hz(),
    DataRate::Hz3.hz(),
    DataRate::Hz7_5.hz(),
    DataRate::Hz15.hz(),
    DataRate::Hz30.hz(),
    DataRate::Hz75.hz(),
];

/// Static facts about the HMC5883L.
pub const INFO: ChipInfo = ChipInfo {
    kind: ChipKind::Hmc5883l,
    name: "HMC5883L",
    vendor: "Honeywell",
    default_address: regs::ADDRESS,
    ranges_ut: &RANGES_UT,
    rates_hz: &RATES_HZ,
    has_temperature: false,
    has_hard_iron_offset: false,
};

/// HMC5883L driver. Defaults: ±1.3 G, 15 Hz, 8 samples averaged.
#[derive(Debug)]
pub struct Hmc5883l<I2C> {
    bus: Bus<I2C>,
    gain: Gain,
    data_rate: DataRate,
    averaging: Averaging,
    stale_samples: u8,
}

impl<I2C: I2c> Hmc5883l<I2C> {
    /// A driver at the chip's address `0x1E`; nothing is sent yet.
    pub fn new(i2c: I2C) -> Self {
        Self::with_address(i2c, regs::ADDRESS)
    }

    /// A driver at `address` (for address translators); nothing is sent yet.
    pub fn with_address(i2c: I2C, address: u8) -> Self {
        Hmc5883l {
            bus: Bus { i2c, address },
            gain: Gain::Ga1_3,
            data_rate: DataRate::Hz15,
            averaging: Averaging::X8,
            stale_samples: 0,
        }
    }

    /// Gives the bus back.
    pub fn destroy(self) -> I2C {
        self.bus.i2c
    }

    /// The current gain.
    pub fn gain(&self) -> Gain {
        self.gain
    }

    /// The current output rate.
    pub fn data_rate(&self) -> DataRate {
        self.data_rate
    }

    /// The current averaging.
    pub fn averaging(&self) -> Averaging {
        self.averaging
    }

    /// Sets the gain (writes CONFIG_B); the next sample is dropped (see the
    /// module documentation).
    pub fn set_gain(&mut self, gain: Gain) -> Result<(), Error<I2C::Error>> {
        self.bus
            .write_reg(regs::CONFIG_B, gain.bits() << regs::CONFIG_B_GN_SHIFT)?;
        self.gain = gain;
        self.stale_samples = 1;
        Ok(())
    }

    /// Sets the output rate (writes CONFIG_A).
    pub fn set_data_rate(&mut self, data_rate: DataRate) -> Result<(), Error<I2C::Error>> {
        self.write_config_a(data_rate, self.averaging)
    }

    /// Sets the number of samples averaged per output (writes CONFIG_A).
    pub fn set_averaging(&mut self, averaging: Averaging) -> Result<(), Error<I2C::Error>> {
        self.write_config_a(self.data_rate, averaging)
    }

    fn write_config_a(
        &mut self,
        data_rate: DataRate,
        averaging: Averaging,
    ) -> Result<(), Error<I2C::Error>> {
        let value = averaging.bits() << regs::CONFIG_A_MA_SHIFT
            | data_rate.bits() << regs::CONFIG_A_DO_SHIFT
            | regs::CONFIG_A_MS_NORMAL;
        self.bus.write_reg(regs::CONFIG_A, value)?;
        self.data_rate = data_rate;
        self.averaging = averaging;
        Ok(())
    }
}

impl<I2C: I2c> Magnetometer for Hmc5883l<I2C> {
    type Error = Error<I2C::Error>;

    fn identify(&mut self) -> Result<(), Self::Error> {
        let mut found = [0; 3];
        self.bus.read_regs(regs::ID_A, &mut found)?;
        if found != regs::ID_VALUE {
            let pack = |id: [u8; 3]| u32::from_be_bytes([0, id[0], id[1], id[2]]);
            return Err(Error::WrongId {
                expected: pack(regs::ID_VALUE),
                found: pack(found),
            });
        }
        Ok(())
    }

    fn init(&mut self) -> Result<(), Self::Error> {
        self.identify()?;
        self.write_config_a(self.data_rate, self.averaging)?;
        self.set_gain(self.gain)?;
        self.bus.write_reg(regs::MODE, regs::MODE_CONTINUOUS)
    }

    fn set_range_ut(&mut self, full_scale_ut: f32) -> Result<f32, Self::Error> {
        let gain = range_at_least(&Gain::ALL, Gain::range_ut, full_scale_ut)
            .ok_or(Error::InvalidConfig)?;
        self.set_gain(gain)?;
        Ok(gain.range_ut())
    }

    fn set_rate_hz(&mut self, rate_hz: f32) -> Result<f32, Self::Error> {
        let rate = nearest(&DataRate::ALL, DataRate::hz, rate_hz).ok_or(Error::InvalidConfig)?;
        self.set_data_rate(rate)?;
        Ok(rate.hz())
    }

    fn data_ready(&mut self) -> Result<bool, Self::Error> {
        Ok(self.bus.read_reg(regs::STATUS)? & regs::STATUS_RDY != 0)
    }

    /// Reads STATUS, then (if RDY) the six data bytes X, Z, Y. A sample taken
    /// at a previous gain is consumed and reported as `Err(NotReady)`; a
    /// channel holding -4096 (overflow) makes it `Err(Saturated)`.
    fn read_ut(&mut self) -> Result<[f32; 3], Self::Error> {
        if !self.data_ready()? {
            return Err(Error::NotReady);
        }
        let mut b = [0; 6];
        self.bus.read_regs(regs::DATA_X_MSB, &mut b)?;
        if self.stale_samples > 0 {
            self.stale_samples -= 1;
            return Err(Error::NotReady);
        }
        let x = i16::from_be_bytes([b[0], b[1]]);
        let z = i16::from_be_bytes([b[2], b[3]]);
        let y = i16::from_be_bytes([b[4], b[5]]);
        if [x, y, z].contains(&regs::OVERFLOW) {
            return Err(Error::Saturated);
        }
        Ok(scale([x, y, z].map(i32::from), self.lsb_ut()))
    }

    /// Always `None`: the HMC5883L has no temperature sensor.
    fn temperature_c(&mut self) -> Result<Option<f32>, Self::Error> {
        Ok(None)
    }

    fn lsb_ut(&self) -> f32 {
        self.gain.lsb_ut()
    }

    fn info(&self) -> ChipInfo {
        INFO
    }
}
