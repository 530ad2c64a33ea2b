//! Linux I2C buses (`/dev/i2c-N`) through linux-embedded-hal: open a bus and
//! hand it to a driver. Nothing more; the drivers do the rest.

pub use linux_embedded_hal::i2cdev::linux::LinuxI2CError;
pub use linux_embedded_hal::{I2CError, I2cdev};

use crate::{AnyMagnetometer, ChipKind};

/// A driver for any supported chip on a Linux I2C bus.
pub type LinuxMagnetometer = AnyMagnetometer<I2cdev>;

/// The device path of bus `bus`: `/dev/i2c-{bus}`.
pub fn bus_path(bus: u32) -> String {
    format!("/dev/i2c-{bus}")
}

/// Opens `/dev/i2c-{bus}`.
pub fn open_bus(bus: u32) -> Result<I2cdev, LinuxI2CError> {
    I2cdev::new(bus_path(bus))
}

/// Opens `/dev/i2c-{bus}` and wraps it in a driver for `kind` at `address`
/// (the chip's default address if `None`). Nothing is sent to the chip yet:
/// call [`crate::Magnetometer::init`].
pub fn open(
    kind: ChipKind,
    bus: u32,
    address: Option<u8>,
) -> Result<LinuxMagnetometer, LinuxI2CError> {
    let i2c = open_bus(bus)?;
    Ok(AnyMagnetometer::with_address(
        kind,
        i2c,
        address.unwrap_or(kind.default_address()),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bus_path_is_dev_i2c_n() {
        assert_eq!(bus_path(1), "/dev/i2c-1");
    }

    #[test]
    fn missing_bus_is_an_error() {
        assert!(open(ChipKind::Lis3mdl, 4_000_000, None).is_err());
    }
}
