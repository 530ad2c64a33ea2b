//! MEMSIC MMC5983MA: ±8 G, 16-bit (4096 counts/G) or 18-bit (16384
//! counts/G) unsigned output around a null field, continuous mode at
//! 1–1000 Hz, temperature sensor, and SET/RESET magnetising pulses.
//!
//! Source: MEMSIC datasheet *MMC5983MA — Low Noise, High Accuracy 3-axis
//! Magnetic Sensor*, Rev A (formal release 4/3/2019): register map and bits,
//! the 18-bit assembly (Xout0 = `Xout[17:10]`, Xout1 = `Xout[9:2]`, XYZout2 bits
//! 7:6/5:4/3:2 = `X[1:0]`/`Y[1:0]`/`Z[1:0]`), sensitivities and null fields (32768 / 131072
//! counts), bandwidths and their measurement times (8/4/2/0.5 ms), continuous
//! rates (200 Hz needs BW ≥ 200 Hz, 1000 Hz needs BW = 800 Hz), the periodic
//! SET counts, the temperature (-75 °C at 0, about 0.8 °C/LSB), the status
//! bits (Meas_M_Done set at the end of a measurement and cleared by the next
//! command; writing 1 clears the interrupt) and the SET/RESET method:
//! measuring after SET and after RESET gives field = (set − reset)/2 and the
//! bridge offset (set + reset)/2.
//!
//! The four control registers are **write-only**, so the driver keeps their
//! settings (bandwidth, rate, Auto_SR_en) and writes whole values; every
//! command to Internal Control 0 carries the Auto_SR_en setting with it
//! (except inside [`Mmc5983ma::measure_set_reset`], which suspends it).
//!
//! Init: identify, write Internal Control 1 (bandwidth) and 3 (0), a SET
//! pulse (re-magnetises the sensor), clear the done flags, then Internal
//! Control 2 with the rate and continuous mode. The driver does not use
//! SW_RST: it needs a 10 ms wait the [`Magnetometer`] trait has no delay for,
//! and writing all four write-only control registers defines the same state.
//!
//! [`Magnetometer::read_ut`] checks Meas_M_Done, reads the sample and writes 1
//! to Meas_M_Done, so the next [`Magnetometer::data_ready`] means a new
//! sample. (The datasheet leaves how Meas_M_Done behaves in continuous mode
//! unclear; this is the driver's reading of it.) The driver keeps the chip in
//! continuous mode: the temperature and the SET/RESET measurement stop it for
//! their single measurements and restart it afterwards. The chip has no
//! saturation flag in the data path: `read_ut` returns `Saturated` when an axis
//! is within 1 % of the output's ends (the field is past ±8 G and the output
//! clipped).

pub mod regs;

#[cfg(test)]
mod tests;

use embedded_hal::delay::DelayNs;
use embedded_hal::i2c::I2c;

use crate::bus::Bus;
use crate::choose::{near_full_scale, nearest, scale};
use crate::{ChipInfo, ChipKind, Error, Magnetometer, UT_PER_GAUSS};

/// The one full-scale range, ± µT (±8 G).
pub const RANGE_UT: f32 = 800.0;

/// Output resolution: which registers are read and how they are scaled.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Resolution {
    /// 16 bits (Xout0/Xout1...), 4096 counts/G, null field 32768.
    Bits16,
    /// 18 bits (plus XYZout2), 16384 counts/G, null field 131072.
    Bits18,
}

impl Resolution {
    /// Resolution in µT per count.
    pub fn lsb_ut(self) -> f32 {
        UT_PER_GAUSS
            / match self {
                Resolution::Bits16 => regs::COUNTS_PER_GAUSS_16,
                Resolution::Bits18 => regs::COUNTS_PER_GAUSS_18,
            }
    }

    /// The output for zero field, in counts.
    pub const fn null_field(self) -> i32 {
        match self {
            Resolution::Bits16 => regs::NULL_FIELD_16,
            Resolution::Bits18 => regs::NULL_FIELD_18,
        }
    }

    /// Unsigned counts from the output registers starting at Xout0.
    fn decode(self, b: [u8; 7]) -> [i32; 3] {
        let word = |axis: usize| i32::from(b[2 * axis]) << 8 | i32::from(b[2 * axis + 1]);
        match self {
            Resolution::Bits16 => [word(0), word(1), word(2)],
            Resolution::Bits18 => {
                let low = |shift: u8| i32::from(b[6] >> shift & 0b11);
                [
                    word(0) << 2 | low(6),
                    word(1) << 2 | low(4),
                    word(2) << 2 | low(2),
                ]
            }
        }
    }

    /// How many output bytes to read from Xout0.
    const fn len(self) -> usize {
        match self {
            Resolution::Bits16 => 6,
            Resolution::Bits18 => 7,
        }
    }
}

/// Filter bandwidth (Internal Control 1 `BW[1:0]`); sets the measurement time.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Bandwidth {
    /// 100 Hz, 8 ms per measurement (lowest noise).
    Hz100,
    /// 200 Hz, 4 ms.
    Hz200,
    /// 400 Hz, 2 ms.
    Hz400,
    /// 800 Hz, 0.5 ms.
    Hz800,
}

impl Bandwidth {
    /// Every bandwidth, from the slowest (quietest) up.
    pub const ALL: [Bandwidth; 4] = [
        Bandwidth::Hz100,
        Bandwidth::Hz200,
        Bandwidth::Hz400,
        Bandwidth::Hz800,
    ];

    /// Duration of one measurement, µs.
    pub const fn measurement_time_us(self) -> u32 {
        match self {
            Bandwidth::Hz100 => 8000,
            Bandwidth::Hz200 => 4000,
            Bandwidth::Hz400 => 2000,
            Bandwidth::Hz800 => 500,
        }
    }

    /// Whether a measurement fits in one period of `rate`.
    pub const fn supports(self, rate: ContinuousRate) -> bool {
        self.measurement_time_us() <= rate.period_us()
    }

    const fn bits(self) -> u8 {
        match self {
            Bandwidth::Hz100 => 0b00,
            Bandwidth::Hz200 => 0b01,
            Bandwidth::Hz400 => 0b10,
            Bandwidth::Hz800 => 0b11,
        }
    }
}

/// Continuous-mode rate (Internal Control 2 `Cm_freq[2:0]`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ContinuousRate {
    /// 1 Hz.
    Hz1,
    /// 10 Hz.
    Hz10,
    /// 20 Hz.
    Hz20,
    /// 50 Hz.
    Hz50,
    /// 100 Hz.
    Hz100,
    /// 200 Hz (bandwidth 200 Hz or more).
    Hz200,
    /// 1000 Hz (bandwidth 800 Hz).
    Hz1000,
}

impl ContinuousRate {
    /// Every rate, ascending.
    pub const ALL: [ContinuousRate; 7] = [
        ContinuousRate::Hz1,
        ContinuousRate::Hz10,
        ContinuousRate::Hz20,
        ContinuousRate::Hz50,
        ContinuousRate::Hz100,
        ContinuousRate::Hz200,
        ContinuousRate::Hz1000,
    ];

    /// The rate in Hz.
    pub const fn hz(self) -> f32 {
        match self {
            ContinuousRate::Hz1 => 1.0,
            ContinuousRate::Hz10 => 10.0,
            ContinuousRate::Hz20 => 20.0,
            ContinuousRate::Hz50 => 50.0,
            ContinuousRate::Hz100 => 100.0,
            ContinuousRate::Hz200 => 200.0,
            ContinuousRate::Hz1000 => 1000.0,
        }
    }

    /// The sample period, µs.
    pub const fn period_us(self) -> u32 {
        match self {
            ContinuousRate::Hz1 => 1_000_000,
            ContinuousRate::Hz10 => 100_000,
            ContinuousRate::Hz20 => 50_000,
            ContinuousRate::Hz50 => 20_000,
            ContinuousRate::Hz100 => 10_000,
            ContinuousRate::Hz200 => 5_000,
            ContinuousRate::Hz1000 => 1_000,
        }
    }

    const fn bits(self) -> u8 {
        match self {
            ContinuousRate::Hz1 => 0b001,
            ContinuousRate::Hz10 => 0b010,
            ContinuousRate::Hz20 => 0b011,
            ContinuousRate::Hz50 => 0b100,
            ContinuousRate::Hz100 => 0b101,
            ContinuousRate::Hz200 => 0b110,
            ContinuousRate::Hz1000 => 0b111,
        }
    }
}

/// How many measurements between automatic SET pulses (Internal Control 2 Prd_set).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SetPeriod {
    /// Every measurement.
    Every1,
    /// Every 25 measurements.
    Every25,
    /// Every 75 measurements.
    Every75,
    /// Every 100 measurements.
    Every100,
    /// Every 250 measurements.
    Every250,
    /// Every 500 measurements.
    Every500,
    /// Every 1000 measurements.
    Every1000,
    /// Every 2000 measurements.
    Every2000,
}

impl SetPeriod {
    const fn bits(self) -> u8 {
        match self {
            SetPeriod::Every1 => 0b000,
            SetPeriod::Every25 => 0b001,
            SetPeriod::Every75 => 0b010,
            SetPeriod::Every100 => 0b011,
            SetPeriod::Every250 => 0b100,
            SetPeriod::Every500 => 0b101,
            SetPeriod::Every1000 => 0b110,
            SetPeriod::Every2000 => 0b111,
        }
    }
}

/// The chip's own SET/RESET handling in continuous mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AutoSetReset {
    /// None: only the SET at init and [`Mmc5983ma::measure_set_reset`].
    Off,
    /// Auto_SR_en: the chip's automatic set/reset.
    On,
    /// Auto_SR_en with En_prd_set: a SET pulse every so many measurements.
    PeriodicSet(SetPeriod),
}

/// The result of [`Mmc5983ma::measure_set_reset`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SetResetSample {
    /// The field with the bridge offset removed, (set − reset)/2, µT.
    pub field_ut: [f32; 3],
    /// The bridge offset, (set + reset)/2 minus the nominal null field, µT.
    pub offset_ut: [f32; 3],
}

const RANGES_UT: [f32; 1] = [RANGE_UT];

const RATES_HZ: [f32; 7] = [
    ContinuousRate::Hz1.hz(),
    ContinuousRate::Hz10.hz(),
    ContinuousRate::Hz20.hz(),
    ContinuousRate::Hz50.hz(),
    ContinuousRate::Hz100.hz(),
    ContinuousRate::Hz200.hz(),
    ContinuousRate::Hz1000.hz(),
];

/// Static facts about the MMC5983MA.
pub const INFO: ChipInfo = ChipInfo {
    kind: ChipKind::Mmc5983ma,
    name: "MMC5983MA",
    vendor: "MEMSIC",
    default_address: regs::ADDRESS,
    ranges_ut: &RANGES_UT,
    rates_hz: &RATES_HZ,
    has_temperature: true,
    has_hard_iron_offset: false,
};

/// MMC5983MA driver. Defaults: 18 bits, bandwidth 100 Hz, 100 Hz continuous,
/// automatic set/reset off.
#[derive(Debug)]
pub struct Mmc5983ma<I2C> {
    bus: Bus<I2C>,
    resolution: Resolution,
    bandwidth: Bandwidth,
    rate: ContinuousRate,
    auto_set_reset: AutoSetReset,
}

impl<I2C: I2c> Mmc5983ma<I2C> {
    /// A driver at the chip's address `0x30`; nothing is sent yet.
    pub fn new(i2c: I2C) -> Self {
        Self::with_address(i2c, regs::ADDRESS)
    }

    /// A driver at `address` (for address translators); nothing is sent yet.
    pub fn with_address(i2c: I2C, address: u8) -> Self {
        Mmc5983ma {
            bus: Bus { i2c, address },
            resolution: Resolution::Bits18,
            bandwidth: Bandwidth::Hz100,
            rate: ContinuousRate::Hz100,
            auto_set_reset: AutoSetReset::Off,
        }
    }

    /// Gives the bus back.
    pub fn destroy(self) -> I2C {
        self.bus.i2c
    }

    /// The current resolution.
    pub fn resolution(&self) -> Resolution {
        self.resolution
    }

    /// The current bandwidth.
    pub fn bandwidth(&self) -> Bandwidth {
        self.bandwidth
    }

    /// The current continuous rate.
    pub fn continuous_rate(&self) -> ContinuousRate {
        self.rate
    }

    /// The current automatic SET/RESET setting.
    pub fn auto_set_reset(&self) -> AutoSetReset {
        self.auto_set_reset
    }

    /// Chooses 16- or 18-bit output (no bus traffic: it changes which
    /// registers are read and how they are scaled).
    pub fn set_resolution(&mut self, resolution: Resolution) {
        self.resolution = resolution;
    }

    /// Sets the bandwidth (writes Internal Control 1). `Err(InvalidConfig)` if
    /// a measurement at that bandwidth would not fit in the current rate's period.
    pub fn set_bandwidth(&mut self, bandwidth: Bandwidth) -> Result<(), Error<I2C::Error>> {
        if !bandwidth.supports(self.rate) {
            return Err(Error::InvalidConfig);
        }
        self.bus.write_reg(regs::CONTROL_1, bandwidth.bits())?;
        self.bandwidth = bandwidth;
        Ok(())
    }

    /// Sets the continuous rate (writes Internal Control 1 and 2), raising the
    /// bandwidth to the slowest one whose measurement fits the period if the
    /// current one does not.
    pub fn set_continuous_rate(&mut self, rate: ContinuousRate) -> Result<(), Error<I2C::Error>> {
        let bandwidth = if self.bandwidth.supports(rate) {
            self.bandwidth
        } else {
            Bandwidth::ALL
                .into_iter()
                .find(|bw| bw.supports(rate))
                .unwrap_or(Bandwidth::Hz800)
        };
        self.bus.write_reg(regs::CONTROL_1, bandwidth.bits())?;
        self.bandwidth = bandwidth;
        self.bus
            .write_reg(regs::CONTROL_2, control_2(rate, self.auto_set_reset, true))?;
        self.rate = rate;
        Ok(())
    }

    /// Sets the chip's automatic SET/RESET (writes Internal Control 0 and 2).
    pub fn set_auto_set_reset(&mut self, mode: AutoSetReset) -> Result<(), Error<I2C::Error>> {
        self.bus
            .write_reg(regs::CONTROL_0, control_0_settings(mode))?;
        self.bus
            .write_reg(regs::CONTROL_2, control_2(self.rate, mode, true))?;
        self.auto_set_reset = mode;
        Ok(())
    }

    /// The offset-removing measurement: stops continuous mode, SET pulse,
    /// one measurement, RESET pulse, one measurement, then restarts continuous
    /// mode (and Auto_SR_en, which is off during the two measurements so the
    /// chip cannot re-magnetise between them). Waits 500 µs after each pulse
    /// and one measurement time before polling Meas_M_Done. After an error the
    /// chip may be left out of continuous mode: call [`Magnetometer::init`].
    pub fn measure_set_reset(
        &mut self,
        delay: &mut impl DelayNs,
    ) -> Result<SetResetSample, Error<I2C::Error>> {
        self.stop_continuous()?;
        let set = self.single_measurement(regs::CONTROL_0_SET, delay)?;
        let reset = self.single_measurement(regs::CONTROL_0_RESET, delay)?;
        if self.auto_set_reset != AutoSetReset::Off {
            self.bus
                .write_reg(regs::CONTROL_0, control_0_settings(self.auto_set_reset))?;
        }
        self.start_continuous()?;
        let lsb_ut = self.lsb_ut();
        let null = self.resolution.null_field() as f32;
        let mut sample = SetResetSample {
            field_ut: [0.0; 3],
            offset_ut: [0.0; 3],
        };
        for axis in 0..3 {
            let (s, r) = (set[axis] as f32, reset[axis] as f32);
            sample.field_ut[axis] = (s - r) / 2.0 * lsb_ut;
            sample.offset_ut[axis] = ((s + r) / 2.0 - null) * lsb_ut;
        }
        Ok(sample)
    }

    /// Magnetising `pulse`, then one on-demand measurement: unsigned counts.
    fn single_measurement(
        &mut self,
        pulse: u8,
        delay: &mut impl DelayNs,
    ) -> Result<[i32; 3], Error<I2C::Error>> {
        self.bus.write_reg(regs::CONTROL_0, pulse)?;
        delay.delay_us(regs::SET_RESET_WAIT_US);
        self.bus.write_reg(regs::CONTROL_0, regs::CONTROL_0_TM_M)?;
        delay.delay_us(self.bandwidth.measurement_time_us());
        self.bus
            .poll_until(regs::STATUS, |s| s & regs::STATUS_MEAS_M_DONE != 0)?;
        self.read_counts()
    }

    /// Reads the output registers and clears Meas_M_Done: unsigned counts.
    fn read_counts(&mut self) -> Result<[i32; 3], Error<I2C::Error>> {
        let mut b = [0; 7];
        let len = self.resolution.len();
        self.bus.read_regs(regs::XOUT0, &mut b[..len])?;
        self.bus.write_reg(regs::STATUS, regs::STATUS_MEAS_M_DONE)?;
        Ok(self.resolution.decode(b))
    }

    fn stop_continuous(&mut self) -> Result<(), Error<I2C::Error>> {
        let value = control_2(self.rate, self.auto_set_reset, false);
        self.bus.write_reg(regs::CONTROL_2, value)
    }

    fn start_continuous(&mut self) -> Result<(), Error<I2C::Error>> {
        let value = control_2(self.rate, self.auto_set_reset, true);
        self.bus.write_reg(regs::CONTROL_2, value)
    }
}

/// Internal Control 2 for a rate and SET/RESET mode, continuous or not.
fn control_2(rate: ContinuousRate, mode: AutoSetReset, continuous: bool) -> u8 {
    let periodic = match mode {
        AutoSetReset::PeriodicSet(period) => {
            regs::CONTROL_2_EN_PRD_SET | period.bits() << regs::CONTROL_2_PRD_SET_SHIFT
        }
        AutoSetReset::Off | AutoSetReset::On => 0,
    };
    let cmm = if continuous {
        regs::CONTROL_2_CMM_EN
    } else {
        0
    };
    periodic | cmm | rate.bits()
}

/// The setting bits of Internal Control 0 (the rest are commands).
fn control_0_settings(mode: AutoSetReset) -> u8 {
    match mode {
        AutoSetReset::Off => 0,
        AutoSetReset::On | AutoSetReset::PeriodicSet(_) => regs::CONTROL_0_AUTO_SR_EN,
    }
}

impl<I2C: I2c> Magnetometer for Mmc5983ma<I2C> {
    type Error = Error<I2C::Error>;

    fn identify(&mut self) -> Result<(), Self::Error> {
        self.bus.expect_id(regs::PRODUCT_ID, regs::PRODUCT_ID_VALUE)
    }

    fn init(&mut self) -> Result<(), Self::Error> {
        self.identify()?;
        self.bus.write_reg(regs::CONTROL_1, self.bandwidth.bits())?;
        self.bus.write_reg(regs::CONTROL_3, 0)?;
        let settings = control_0_settings(self.auto_set_reset);
        self.bus
            .write_reg(regs::CONTROL_0, regs::CONTROL_0_SET | settings)?;
        self.bus.write_reg(
            regs::STATUS,
            regs::STATUS_MEAS_M_DONE | regs::STATUS_MEAS_T_DONE,
        )?;
        self.start_continuous()
    }

    fn set_range_ut(&mut self, full_scale_ut: f32) -> Result<f32, Self::Error> {
        if !(full_scale_ut.is_finite() && full_scale_ut > 0.0) {
            return Err(Error::InvalidConfig);
        }
        Ok(RANGE_UT)
    }

    fn set_rate_hz(&mut self, rate_hz: f32) -> Result<f32, Self::Error> {
        let rate = nearest(&ContinuousRate::ALL, ContinuousRate::hz, rate_hz)
            .ok_or(Error::InvalidConfig)?;
        self.set_continuous_rate(rate)?;
        Ok(rate.hz())
    }

    fn data_ready(&mut self) -> Result<bool, Self::Error> {
        Ok(self.bus.read_reg(regs::STATUS)? & regs::STATUS_MEAS_M_DONE != 0)
    }

    fn read_ut(&mut self) -> Result<[f32; 3], Self::Error> {
        if !self.data_ready()? {
            return Err(Error::NotReady);
        }
        let null = self.resolution.null_field();
        let counts = self.read_counts()?.map(|c| c - null);
        if near_full_scale(counts, -null, null - 1) {
            return Err(Error::Saturated);
        }
        Ok(scale(counts, self.lsb_ut()))
    }

    /// Stops continuous mode, takes one temperature measurement (TM_T), waits
    /// for Meas_T_Done with bounded polling, reads Tout and restarts.
    fn temperature_c(&mut self) -> Result<Option<f32>, Self::Error> {
        self.stop_continuous()?;
        let settings = control_0_settings(self.auto_set_reset);
        self.bus
            .write_reg(regs::CONTROL_0, regs::CONTROL_0_TM_T | settings)?;
        self.bus
            .poll_until(regs::STATUS, |s| s & regs::STATUS_MEAS_T_DONE != 0)?;
        let raw = self.bus.read_reg(regs::TOUT)?;
        self.bus.write_reg(regs::STATUS, regs::STATUS_MEAS_T_DONE)?;
        self.start_continuous()?;
        Ok(Some(
            regs::TEMP_ZERO_C + f32::from(raw) * regs::TEMP_C_PER_LSB,
        ))
    }

    fn lsb_ut(&self) -> f32 {
        self.resolution.lsb_ut()
    }

    fn info(&self) -> ChipInfo {
        INFO
    }
}
