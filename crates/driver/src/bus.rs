//! Register access over an I2C bus at one device address.

use embedded_hal::i2c::I2c;

use crate::Error;

/// How many status reads a driver makes while waiting for a self-clearing bit
/// or a done flag before it gives up with [`Error::Timeout`]. Each read is a
/// few dozen bit times (≥ 36 µs at 1 MHz), so this bounds the wait at tens of
/// milliseconds or more: longer than any reset or conversion here takes.
pub(crate) const MAX_POLLS: u16 = 1000;

/// An I2C bus and the 7-bit address of the chip on it.
#[derive(Debug)]
pub(crate) struct Bus<I2C> {
    pub(crate) i2c: I2C,
    pub(crate) address: u8,
}

impl<I2C: I2c> Bus<I2C> {
    /// Writes one register.
    pub(crate) fn write_reg(&mut self, reg: u8, value: u8) -> Result<(), Error<I2C::Error>> {
        self.i2c
            .write(self.address, &[reg, value])
            .map_err(Error::I2c)
    }

    /// Reads one register.
    pub(crate) fn read_reg(&mut self, reg: u8) -> Result<u8, Error<I2C::Error>> {
        let mut value = [0];
        self.read_regs(reg, &mut value)?;
        Ok(value[0])
    }

    /// Reads `buf.len()` bytes starting at sub-address `reg` in one transaction
    /// (the caller sets any auto-increment bit the chip needs).
    pub(crate) fn read_regs(&mut self, reg: u8, buf: &mut [u8]) -> Result<(), Error<I2C::Error>> {
        self.i2c
            .write_read(self.address, &[reg], buf)
            .map_err(Error::I2c)
    }

    /// Reads the one-byte identification register `reg` and checks it holds `expected` (a different value is
    /// [`Error::WrongId`] with both).
    pub(crate) fn expect_id(&mut self, reg: u8, expected: u8) -> Result<(), Error<I2C::Error>> {
        let found = self.read_reg(reg)?;
        if found != expected {
            return Err(Error::WrongId {
                expected: expected.into(),
                found: found.into(),
            });
        }
        Ok(())
    }

    /// Reads `reg` until `done` holds for its value, at most [`MAX_POLLS`] times.
    pub(crate) fn poll_until(
        &mut self,
        reg: u8,
        done: impl Fn(u8) -> bool,
    ) -> Result<(), Error<I2C::Error>> {
        for _ in 0..MAX_POLLS {
            if done(self.read_reg(reg)?) {
                return Ok(());
            }
        }
        Err(Error::Timeout)
    }
}
