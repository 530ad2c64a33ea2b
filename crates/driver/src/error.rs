//! The one error type shared by every chip driver.

use core::fmt;

/// What can go wrong talking to a magnetometer; `E` is the I2C bus error.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Error<E> {
    /// The bus reported an error (for example a NACK); passed through untouched.
    I2c(E),
    /// The identification register(s) did not hold the chip's value: probably
    /// another chip at this address, or none. Multi-byte ids (HMC5883L
    /// `'H' '4' '3'`) are packed big-endian, first register in the high byte.
    WrongId {
        /// The value the datasheet gives.
        expected: u32,
        /// The value read from the chip.
        found: u32,
    },
    /// No new sample yet (the data-ready flag is clear, or the driver dropped a
    /// sample it knows to be stale); poll again later. Nothing was lost.
    NotReady,
    /// The chip flagged the field as outside its measurement range on at least
    /// one axis; the sample is not a field value. Use a larger range.
    Saturated,
    /// A request the chip cannot honour: a non-finite or non-positive range or
    /// rate, an offset outside the register's span, or a setting that conflicts
    /// with another one (see the method's documentation).
    InvalidConfig,
    /// A self-clearing bit or a measurement-done flag did not change within the
    /// driver's bounded number of status reads.
    Timeout,
    /// The chip has no such capability (for example hard-iron offset registers).
    Unsupported,
}

impl<E: fmt::Debug> fmt::Display for Error<E> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::I2c(e) => write!(f, "I2C bus error: {e:?}"),
            Error::WrongId { expected, found } => {
                write!(f, "wrong chip id: expected {expected:#x}, found {found:#x}")
            }
            Error::NotReady => f.write_str("no new sample ready"),
            Error::Saturated => f.write_str("field outside the measurement range (saturated)"),
            Error::InvalidConfig => f.write_str("configuration not supported by the chip"),
            Error::Timeout => f.write_str("chip did not complete the operation in time"),
            Error::Unsupported => f.write_str("operation not supported by this chip"),
        }
    }
}

#[cfg(feature = "std")]
impl<E: fmt::Debug> std::error::Error for Error<E> {}
