//! The supported chips, by name.

use core::fmt;
use core::str::FromStr;

use crate::{ChipInfo, hmc5883l, lis2mdl, lis3mdl, mmc5983ma, qmc5883l};

/// One of the supported magnetometer chips.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ChipKind {
    /// ST LIS3MDL.
    Lis3mdl,
    /// ST LIS2MDL.
    Lis2mdl,
    /// QST QMC5883L.
    Qmc5883l,
    /// Honeywell HMC5883L.
    Hmc5883l,
    /// MEMSIC MMC5983MA.
    Mmc5983ma,
}

impl ChipKind {
    /// Every supported chip.
    pub const ALL: [ChipKind; 5] = [
        ChipKind::Lis3mdl,
        ChipKind::Lis2mdl,
        ChipKind::Qmc5883l,
        ChipKind::Hmc5883l,
        ChipKind::Mmc5983ma,
    ];

    /// The lower-case name [`FromStr`] accepts and [`Display`](fmt::Display) prints.
    pub const fn name(self) -> &'static str {
        match self {
            ChipKind::Lis3mdl => "lis3mdl",
            ChipKind::Lis2mdl => "lis2mdl",
            ChipKind::Qmc5883l => "qmc5883l",
            ChipKind::Hmc5883l => "hmc5883l",
            ChipKind::Mmc5983ma => "mmc5983ma",
        }
    }

    /// The 7-bit I2C address the driver uses unless told otherwise.
    pub const fn default_address(self) -> u8 {
        self.info().default_address
    }

    /// Static facts about the chip.
    pub const fn info(self) -> ChipInfo {
        match self {
            ChipKind::Lis3mdl => lis3mdl::INFO,
            ChipKind::Lis2mdl => lis2mdl::INFO,
            ChipKind::Qmc5883l => qmc5883l::INFO,
            ChipKind::Hmc5883l => hmc5883l::INFO,
            ChipKind::Mmc5983ma => mmc5983ma::INFO,
        }
    }
}

impl fmt::Display for ChipKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for ChipKind {
    type Err = UnknownChip;

    /// Parses a chip name, ignoring ASCII case (`"LIS3MDL"`, `"lis3mdl"`).
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        ChipKind::ALL
            .into_iter()
            .find(|kind| kind.name().eq_ignore_ascii_case(s.trim()))
            .ok_or(UnknownChip)
    }
}

/// The name given to [`ChipKind::from_str`] is not a supported chip.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct UnknownChip;

impl fmt::Display for UnknownChip {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("unknown chip; expected one of")?;
        for kind in ChipKind::ALL {
            write!(f, " {kind}")?;
        }
        Ok(())
    }
}

#[cfg(feature = "std")]
impl std::error::Error for UnknownChip {}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_ignore_case() {
        for kind in ChipKind::ALL {
            assert_eq!(kind.to_string().parse::<ChipKind>(), Ok(kind));
            assert_eq!(kind.info().kind, kind);
        }
        assert_eq!("LIS2MDL".parse::<ChipKind>(), Ok(ChipKind::Lis2mdl));
        assert_eq!(" qmc5883l ".parse::<ChipKind>(), Ok(ChipKind::Qmc5883l));
        assert_eq!("hmc5883".parse::<ChipKind>(), Err(UnknownChip));
        assert!(UnknownChip.to_string().contains("mmc5983ma"));
    }

    #[test]
    fn default_addresses_are_the_datasheet_ones() {
        assert_eq!(ChipKind::Lis3mdl.default_address(), 0x1C);
        assert_eq!(ChipKind::Lis2mdl.default_address(), 0x1E);
        assert_eq!(ChipKind::Qmc5883l.default_address(), 0x0D);
        assert_eq!(ChipKind::Hmc5883l.default_address(), 0x1E);
        assert_eq!(ChipKind::Mmc5983ma.default_address(), 0x30);
    }

    #[test]
    fn info_lists_are_ascending() {
        for kind in ChipKind::ALL {
            let info = kind.info();
            assert!(info.ranges_ut.windows(2).all(|w| w[0] < w[1]), "{kind}");
            assert!(info.rates_hz.windows(2).all(|w| w[0] < w[1]), "{kind}");
            assert_eq!(info.has_hard_iron_offset, kind == ChipKind::Lis2mdl);
        }
    }
}
