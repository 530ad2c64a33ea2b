//! A driver for any supported chip, chosen at run time.

use embedded_hal::i2c::I2c;

use crate::{
    ChipInfo, ChipKind, Error, HardIronOffset, Hmc5883l, Lis2mdl, Lis3mdl, Magnetometer, Mmc5983ma,
    Qmc5883l,
};

/// One of the chip drivers, so a tool can pick the chip by name at run time.
#[derive(Debug)]
pub enum AnyMagnetometer<I2C> {
    /// ST LIS3MDL.
    Lis3mdl(Lis3mdl<I2C>),
    /// ST LIS2MDL.
    Lis2mdl(Lis2mdl<I2C>),
    /// QST QMC5883L.
    Qmc5883l(Qmc5883l<I2C>),
    /// Honeywell HMC5883L.
    Hmc5883l(Hmc5883l<I2C>),
    /// MEMSIC MMC5983MA.
    Mmc5983ma(Mmc5983ma<I2C>),
}

/// Runs `$body` with `$m` bound to the inner driver, whatever the chip.
macro_rules! each {
    ($any:expr, $m:ident => $body:expr) => {
        match $any {
            AnyMagnetometer::Lis3mdl($m) => $body,
            AnyMagnetometer::Lis2mdl($m) => $body,
            AnyMagnetometer::Qmc5883l($m) => $body,
            AnyMagnetometer::Hmc5883l($m) => $body,
            AnyMagnetometer::Mmc5983ma($m) => $body,
        }
    };
}

impl<I2C: I2c> AnyMagnetometer<I2C> {
    /// A driver for `kind` at its default address; nothing is sent yet.
    pub fn new(kind: ChipKind, i2c: I2C) -> Self {
        Self::with_address(kind, i2c, kind.default_address())
    }

    /// A driver for `kind` at `address`; nothing is sent yet.
    pub fn with_address(kind: ChipKind, i2c: I2C, address: u8) -> Self {
        match kind {
            ChipKind::Lis3mdl => AnyMagnetometer::Lis3mdl(Lis3mdl::with_address(i2c, address)),
            ChipKind::Lis2mdl => AnyMagnetometer::Lis2mdl(Lis2mdl::with_address(i2c, address)),
            ChipKind::Qmc5883l => AnyMagnetometer::Qmc5883l(Qmc5883l::with_address(i2c, address)),
            ChipKind::Hmc5883l => AnyMagnetometer::Hmc5883l(Hmc5883l::with_address(i2c, address)),
            ChipKind::Mmc5983ma => {
                AnyMagnetometer::Mmc5983ma(Mmc5983ma::with_address(i2c, address))
            }
        }
    }

    /// Which chip this drives.
    pub fn kind(&self) -> ChipKind {
        each!(self, m => m.info().kind)
    }

    /// Gives the bus back.
    pub fn destroy(self) -> I2C {
        each!(self, m => m.destroy())
    }
}

impl<I2C: I2c> Magnetometer for AnyMagnetometer<I2C> {
    type Error = Error<I2C::Error>;

    fn identify(&mut self) -> Result<(), Self::Error> {
        each!(self, m => m.identify())
    }

    fn init(&mut self) -> Result<(), Self::Error> {
        each!(self, m => m.init())
    }

    fn set_range_ut(&mut self, full_scale_ut: f32) -> Result<f32, Self::Error> {
        each!(self, m => m.set_range_ut(full_scale_ut))
    }

    fn set_rate_hz(&mut self, rate_hz: f32) -> Result<f32, Self::Error> {
        each!(self, m => m.set_rate_hz(rate_hz))
    }

    fn data_ready(&mut self) -> Result<bool, Self::Error> {
        each!(self, m => m.data_ready())
    }

    fn read_ut(&mut self) -> Result<[f32; 3], Self::Error> {
        each!(self, m => m.read_ut())
    }

    fn temperature_c(&mut self) -> Result<Option<f32>, Self::Error> {
        each!(self, m => m.temperature_c())
    }

    fn lsb_ut(&self) -> f32 {
        each!(self, m => m.lsb_ut())
    }

    fn info(&self) -> ChipInfo {
        each!(self, m => m.info())
    }
}

impl<I2C: I2c> HardIronOffset for AnyMagnetometer<I2C> {
    /// Delegates to the LIS2MDL; `Err(Unsupported)` for the other chips
    /// (see [`ChipInfo::has_hard_iron_offset`]).
    fn write_offset_ut(&mut self, offset_ut: [f32; 3]) -> Result<(), Self::Error> {
        match self {
            AnyMagnetometer::Lis2mdl(m) => m.write_offset_ut(offset_ut),
            _ => Err(Error::Unsupported),
        }
    }

    /// Delegates to the LIS2MDL; `Err(Unsupported)` for the other chips.
    fn read_offset_ut(&mut self) -> Result<[f32; 3], Self::Error> {
        match self {
            AnyMagnetometer::Lis2mdl(m) => m.read_offset_ut(),
            _ => Err(Error::Unsupported),
        }
    }
}

#[cfg(test)]
mod tests {
    use embedded_hal_mock::eh1::i2c::{Mock, Transaction as T};

    use super::*;

    #[test]
    fn picks_the_chip_and_its_default_address_by_name() {
        for kind in ChipKind::ALL {
            let mut mag = AnyMagnetometer::new(kind, Mock::new(&[]));
            assert_eq!(mag.kind(), kind);
            assert_eq!(mag.info(), kind.info());
            assert!(mag.lsb_ut() > 0.0);
            let supports_offset = kind.info().has_hard_iron_offset;
            if !supports_offset {
                assert_eq!(mag.write_offset_ut([1.0; 3]), Err(Error::Unsupported));
                assert_eq!(mag.read_offset_ut(), Err(Error::Unsupported));
            }
            mag.destroy().done();
        }
    }

    #[test]
    fn dispatches_to_the_chosen_driver() {
        let kind: ChipKind = "qmc5883l".parse().unwrap();
        let mut mag = AnyMagnetometer::with_address(
            kind,
            Mock::new(&[
                T::write_read(0x2D, vec![0x0D], vec![0xFF]),
                T::write_read(0x2D, vec![0x06], vec![0x01]),
                T::write_read(0x2D, vec![0x00], vec![0xB8, 0x0B, 0, 0, 0, 0]),
            ]),
            0x2D,
        );
        mag.identify().unwrap();
        crate::test_support::assert_close(mag.read_ut().unwrap(), [100.0, 0.0, 0.0], 1e-4);
        mag.destroy().done();
    }

    #[test]
    fn offset_reaches_the_lis2mdl() {
        let mut mag = AnyMagnetometer::new(
            ChipKind::Lis2mdl,
            Mock::new(&[T::write(0x1E, vec![0x45, 0x64, 0, 0, 0, 0, 0])]),
        );
        mag.write_offset_ut([15.0, 0.0, 0.0]).unwrap();
        mag.destroy().done();
    }
}
