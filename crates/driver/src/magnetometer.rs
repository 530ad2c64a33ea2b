//! The uniform interface every chip driver implements.

use crate::ChipKind;

/// A three-axis magnetometer in continuous measurement, seen uniformly.
///
/// Typical use: [`init`](Self::init) once, optionally
/// [`set_range_ut`](Self::set_range_ut) / [`set_rate_hz`](Self::set_rate_hz),
/// then call [`read_ut`](Self::read_ut) at or above the output data rate and
/// skip `Err(NotReady)`.
pub trait Magnetometer {
    /// The error type (for the chip drivers here, [`crate::Error`] over the bus error).
    type Error;

    /// Reads the identification register(s); a mismatch is a `WrongId` error
    /// carrying what was found and what was expected.
    fn identify(&mut self) -> Result<(), Self::Error>;

    /// Identifies the chip, resets it (where the chip offers a reset the
    /// driver can confirm) and writes the init sequence that starts continuous
    /// measurement with the driver's current configuration.
    fn init(&mut self) -> Result<(), Self::Error>;

    /// Selects the smallest supported full-scale range at or above
    /// `full_scale_ut` (or the largest one if none is) and returns the range
    /// applied, in µT. Chips with a single range return it without bus traffic.
    fn set_range_ut(&mut self, full_scale_ut: f32) -> Result<f32, Self::Error>;

    /// Selects the supported output data rate nearest `rate_hz` (the lower on a
    /// tie) and returns it, in Hz.
    fn set_rate_hz(&mut self, rate_hz: f32) -> Result<f32, Self::Error>;

    /// Whether a new sample is waiting (reads the chip's status register).
    fn data_ready(&mut self) -> Result<bool, Self::Error>;

    /// One sample in µT, in the sensor's own axes. Checks data-ready first:
    /// `Err(NotReady)` when there is no new sample (nothing is consumed then),
    /// `Err(Saturated)` when the chip flags the field as out of range.
    fn read_ut(&mut self) -> Result<[f32; 3], Self::Error>;

    /// The die temperature in °C, or `None` where the chip has no temperature
    /// sensor with a calibrated zero.
    fn temperature_c(&mut self) -> Result<Option<f32>, Self::Error>;

    /// The field resolution at the current configuration: µT per count.
    fn lsb_ut(&self) -> f32;

    /// Static facts about the chip.
    fn info(&self) -> ChipInfo;
}

/// A magnetometer that can store a hard-iron offset and subtract it itself.
pub trait HardIronOffset: Magnetometer {
    /// Writes the offset (µT per axis) the chip subtracts from every sample,
    /// rounded to the register's resolution.
    fn write_offset_ut(&mut self, offset_ut: [f32; 3]) -> Result<(), Self::Error>;

    /// Reads back the offset the chip holds, in µT.
    fn read_offset_ut(&mut self) -> Result<[f32; 3], Self::Error>;
}

/// Static facts about a supported chip.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ChipInfo {
    /// Which chip.
    pub kind: ChipKind,
    /// Part number as the vendor writes it, e.g. `"LIS3MDL"`.
    pub name: &'static str,
    /// The vendor.
    pub vendor: &'static str,
    /// The 7-bit I2C address the driver uses unless told otherwise.
    pub default_address: u8,
    /// Supported full-scale ranges (± µT), ascending.
    pub ranges_ut: &'static [f32],
    /// Supported continuous output data rates (Hz), ascending.
    pub rates_hz: &'static [f32],
    /// Whether [`Magnetometer::temperature_c`] can return a value.
    pub has_temperature: bool,
    /// Whether the chip implements [`HardIronOffset`].
    pub has_hard_iron_offset: bool,
}
