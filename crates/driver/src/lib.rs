//! Drivers for the three-axis magnetometers that magcal calibrates on the bench.
//!
//! Each chip lives in its own module with a datasheet-accurate register map
//! (`regs`), a small typed configuration API, the init sequence for continuous
//! measurement, scaling to microtesla and data-ready handling, all over
//! [`embedded_hal::i2c::I2c`] (embedded-hal 1.0) and without `std` or `alloc`:
//!
//! | module | chip | default address |
//! | --- | --- | --- |
//! | [`lis3mdl`] | ST LIS3MDL | `0x1C` (`0x1E` with SA1 high) |
//! | [`lis2mdl`] | ST LIS2MDL (hard-iron offset registers) | `0x1E` |
//! | [`qmc5883l`] | QST QMC5883L | `0x0D` |
//! | [`hmc5883l`] | Honeywell HMC5883L | `0x1E` |
//! | [`mmc5983ma`] | MEMSIC MMC5983MA (SET/RESET offset removal) | `0x30` |
//!
//! Every driver implements the uniform [`Magnetometer`] trait, so a recorder
//! can work with any of them; [`AnyMagnetometer`] picks one at run time from a
//! [`ChipKind`] (which parses from names such as `"lis3mdl"`). The LIS2MDL also
//! implements [`HardIronOffset`], the one chip here that can hold a calibration.
//!
//! Conventions: fields are in microtesla (µT) in the sensor's own axes, rates
//! in hertz, temperatures in degrees Celsius. A sample that is not ready yet is
//! `Err(Error::NotReady)`; a saturated sample is `Err(Error::Saturated)`; a bus
//! failure (such as a NACK) is `Err(Error::I2c(e))`. The drivers never retry:
//! retries belong to the caller.
//!
//! Features: `std` adds `std::error::Error` impls; `linux` adds the `linux`
//! module, a thin helper that opens `/dev/i2c-N`; `serial` adds the serial
//! stream readers.
#![cfg_attr(not(any(feature = "std", test)), no_std)]

mod any;
mod bus;
mod chip_kind;
mod choose;
mod error;
mod magnetometer;

pub mod hmc5883l;
pub mod lis2mdl;
pub mod lis3mdl;
pub mod mmc5983ma;
pub mod qmc5883l;

#[cfg(feature = "linux")]
pub mod linux;

#[cfg(feature = "serial")]
pub mod serial;

#[cfg(test)]
mod test_support;

pub use any::AnyMagnetometer;
pub use chip_kind::{ChipKind, UnknownChip};
pub use error::Error;
pub use hmc5883l::Hmc5883l;
pub use lis2mdl::Lis2mdl;
pub use lis3mdl::Lis3mdl;
pub use magnetometer::{ChipInfo, HardIronOffset, Magnetometer};
pub use mmc5983ma::Mmc5983ma;
pub use qmc5883l::Qmc5883l;

/// Microtesla per gauss (1 G = 100 µT), the unit conversion every datasheet here needs.
pub const UT_PER_GAUSS: f32 = 100.0;
