//! The unit of the field values a line prints, as a device string names it: `unit=gauss`, `scale=0.0917`.
//!
//! A printed value `v` is the field `v × scale` in `unit`: `unit=gauss` reads gauss, `scale=0.0917` reads raw counts
//! of 0.0917 µT each (an HMC5883L at ±1.3 G), and `unit=gauss:scale=0.00083333` counts of 1/12000 G (a QMC5883L at
//! ±2 G). Without either, values are µT.

use std::fmt;
use std::str::FromStr;

/// A unit of magnetic flux density.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum MagUnit {
    /// Microtesla, the unit of magcal's recordings.
    #[default]
    Microtesla,
    /// Gauss (1 G = 100 µT).
    Gauss,
    /// Milligauss (1 mG = 0.1 µT).
    Milligauss,
    /// Nanotesla (1 nT = 0.001 µT).
    Nanotesla,
}

impl MagUnit {
    /// Microtesla per unit.
    pub fn ut_per_unit(self) -> f64 {
        match self {
            MagUnit::Microtesla => 1.0,
            MagUnit::Gauss => 100.0,
            MagUnit::Milligauss => 0.1,
            MagUnit::Nanotesla => 0.001,
        }
    }

    /// The name device strings use: `uT`, `gauss`, `mG`, `nT`.
    pub fn name(self) -> &'static str {
        match self {
            MagUnit::Microtesla => "uT",
            MagUnit::Gauss => "gauss",
            MagUnit::Milligauss => "mG",
            MagUnit::Nanotesla => "nT",
        }
    }
}

impl fmt::Display for MagUnit {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// The names a unit may be given by, in any case.
pub const UNIT_NAMES: &str = "uT (µT, microtesla), gauss (G), mG (milligauss), nT (nanotesla)";

impl FromStr for MagUnit {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.to_lowercase().as_str() {
            "ut" | "µt" | "microtesla" => Ok(MagUnit::Microtesla),
            "gauss" | "g" => Ok(MagUnit::Gauss),
            "mg" | "mgauss" | "milligauss" => Ok(MagUnit::Milligauss),
            "nt" | "nanotesla" => Ok(MagUnit::Nanotesla),
            _ => Err(format!("unknown unit {s:?} (expected {UNIT_NAMES})")),
        }
    }
}

/// How printed field values become µT: `value × scale` is in `unit`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ValueScale {
    /// The unit of `value × scale`.
    pub unit: MagUnit,
    /// The factor a printed value is multiplied by (1 unless the values are raw counts); finite and positive.
    pub scale: f64,
    /// Whether the device string stated the unit or the scale (µT is otherwise an assumption).
    pub stated: bool,
}

impl Default for ValueScale {
    /// µT as printed, not stated.
    fn default() -> Self {
        ValueScale {
            unit: MagUnit::Microtesla,
            scale: 1.0,
            stated: false,
        }
    }
}

impl ValueScale {
    /// Microtesla per printed unit.
    pub fn ut_per_value(&self) -> f64 {
        self.scale * self.unit.ut_per_unit()
    }

    /// Parses a `scale=` value: a finite number > 0.
    pub fn parse_scale(text: &str) -> Result<f64, String> {
        text.parse::<f64>()
            .ok()
            .filter(|s| s.is_finite() && *s > 0.0)
            .ok_or_else(|| {
                format!(
                    "scale {text:?} is not a number > 0 (it multiplies each printed value: the unit per count)"
                )
            })
    }

    /// The device-string options that give this scale (`:unit=gauss:scale=0.5`), empty when none was stated.
    pub fn options(&self) -> String {
        let mut out = String::new();
        if self.unit != MagUnit::Microtesla || (self.stated && self.scale == 1.0) {
            out += &format!(":unit={}", self.unit);
        }
        if self.scale != 1.0 {
            out += &format!(":scale={}", self.scale);
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn units_by_any_name_and_their_factors() {
        for (name, unit, ut) in [
            ("uT", MagUnit::Microtesla, 1.0),
            ("µT", MagUnit::Microtesla, 1.0),
            ("GAUSS", MagUnit::Gauss, 100.0),
            ("G", MagUnit::Gauss, 100.0),
            ("mG", MagUnit::Milligauss, 0.1),
            ("milligauss", MagUnit::Milligauss, 0.1),
            ("nT", MagUnit::Nanotesla, 0.001),
        ] {
            let parsed: MagUnit = name.parse().unwrap();
            assert_eq!((parsed, parsed.ut_per_unit()), (unit, ut), "{name}");
            assert_eq!(parsed.name().parse::<MagUnit>(), Ok(parsed));
        }
        let e = "tesla".parse::<MagUnit>().unwrap_err();
        assert!(
            e.contains("unknown unit \"tesla\"") && e.contains("gauss"),
            "{e}"
        );
    }

    #[test]
    fn a_scale_is_a_positive_number_and_counts_times_scale_are_in_the_unit() {
        assert_eq!(ValueScale::parse_scale("0.0917"), Ok(0.0917));
        for bad in ["0", "-1", "nan", "inf", "x", ""] {
            assert!(ValueScale::parse_scale(bad).is_err(), "{bad}");
        }
        let qmc = ValueScale {
            unit: MagUnit::Gauss,
            scale: 1.0 / 12000.0,
            stated: true,
        };
        assert!((12000.0 * qmc.ut_per_value() - 100.0).abs() < 1e-9);
        assert_eq!(ValueScale::default().options(), "");
        let stated = |unit, scale| ValueScale {
            unit,
            scale,
            stated: true,
        };
        assert_eq!(
            stated(MagUnit::Milligauss, 2.5).options(),
            ":unit=mG:scale=2.5"
        );
        assert_eq!(stated(MagUnit::Microtesla, 1.0).options(), ":unit=uT");
        assert_eq!(stated(MagUnit::Microtesla, 0.15).options(), ":scale=0.15");
    }
}
