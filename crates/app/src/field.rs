//! The world field a calibration is fitted against, and where it came from.

use magcal_recording::{Date, Location, Metadata};
use world_magnetic_model::GeomagneticField;
use world_magnetic_model::time::{Date as WmmDate, Month};
use world_magnetic_model::uom::si::angle::degree;
use world_magnetic_model::uom::si::f32::{Angle, Length};
use world_magnetic_model::uom::si::length::meter;
use world_magnetic_model::uom::si::magnetic_flux_density::microtesla;

/// The world field used by a fit.
#[derive(Clone, Debug, PartialEq)]
pub enum ReferenceField {
    /// A full NED vector, µT.
    Vector {
        /// N, E, D, µT.
        field_ned_ut: [f64; 3],
        /// Where it came from, in words.
        source: String,
    },
    /// Only the magnitude, µT (enough for the scalar method).
    Magnitude {
        /// |B|, µT.
        field_ut: f64,
        /// Where it came from, in words.
        source: String,
    },
    /// Nothing known: the scalar method then keeps the raw ellipsoid's mean radius.
    Unknown,
}

impl ReferenceField {
    /// The NED vector, if known.
    pub fn vector(&self) -> Option<[f64; 3]> {
        match self {
            ReferenceField::Vector { field_ned_ut, .. } => Some(*field_ned_ut),
            _ => None,
        }
    }

    /// The magnitude, if known.
    pub fn magnitude(&self) -> Option<f64> {
        match self {
            ReferenceField::Vector { field_ned_ut, .. } => {
                Some(magcal_calib::frames::norm(*field_ned_ut))
            }
            ReferenceField::Magnitude { field_ut, .. } => Some(*field_ut),
            ReferenceField::Unknown => None,
        }
    }

    /// Where it came from.
    pub fn source(&self) -> &str {
        match self {
            ReferenceField::Vector { source, .. } | ReferenceField::Magnitude { source, .. } => {
                source
            }
            ReferenceField::Unknown => "unknown",
        }
    }
}

/// What the user said about the field on the command line.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FieldArgs {
    /// `--field-ned N,E,D` (µT).
    pub field_ned_ut: Option<[f64; 3]>,
    /// `--location LAT,LON,ALT` and `--date YYYY-MM-DD` for the World Magnetic Model.
    pub location: Option<(Location, Date)>,
    /// `--field-ut F`: magnitude only (µT).
    pub field_ut: Option<f64>,
}

/// Why no field could be worked out.
#[derive(Debug, thiserror::Error)]
pub enum FieldError {
    /// The World Magnetic Model refused the place or date.
    #[error("World Magnetic Model at {lat}, {lon}, {alt} m on {date}: {why}")]
    Wmm {
        /// Latitude, degrees.
        lat: f64,
        /// Longitude, degrees.
        lon: f64,
        /// Altitude, m.
        alt: f64,
        /// Date.
        date: Date,
        /// What the model said.
        why: String,
    },
    /// A field given in numbers is no field a magnetometer here measures, in µT: given in another unit.
    #[error("the field given ({given_by}) is {magnitude_ut} µT{why}")]
    NotMicrotesla {
        /// Where it came from.
        given_by: String,
        /// Its magnitude as given, shortened.
        magnitude_ut: String,
        /// Why that is no field in µT, and the unit it most likely is in with the field in µT then.
        why: String,
    },
}

/// The least field magnitude taken as given in µT: below, it is in gauss, mT or tesla (the Earth's is 22–67 µT).
pub const FIELD_MIN_UT: f64 = 1.0;
/// The largest: the widest range of the chips this tool reads (the LIS2MDL's ±50 gauss). Above, it is in nT.
pub const FIELD_MAX_UT: f64 = 5000.0;

/// `field` if its magnitude can be a field in µT ([`FIELD_MIN_UT`]–[`FIELD_MAX_UT`]); otherwise the error that says
/// which unit it most likely is in (the one that puts it at the Earth's 22–67 µT).
fn in_microtesla(field: ReferenceField) -> Result<ReferenceField, FieldError> {
    let Some(m) = field.magnitude() else {
        return Ok(field);
    };
    if (FIELD_MIN_UT..=FIELD_MAX_UT).contains(&m) {
        return Ok(field);
    }
    let scaled = |k: f64, unit: &str| -> String {
        let shown = match &field {
            ReferenceField::Vector { field_ned_ut, .. } => {
                let [n, e, d] = field_ned_ut.map(|c| c * k);
                format!("{n:.2},{e:.2},{d:.2}")
            }
            _ => format!("{:.2}", m * k),
        };
        format!(" (in {unit}? then it is {shown} µT)")
    };
    let (magnitude_ut, why) = if m > FIELD_MAX_UT {
        (
            format!("{m:.0}"),
            format!(
                ", more than any magnetometer this tool reads measures ({FIELD_MAX_UT} µT): it must be in µT{}",
                scaled(1e-3, "nT")
            ),
        )
    } else if m == 0.0 {
        (
            "0".to_owned(),
            ": a field of zero cannot be fitted against; give the local field".to_owned(),
        )
    } else {
        let hint = if m >= 0.1 {
            scaled(100.0, "gauss")
        } else if m >= 0.01 {
            scaled(1000.0, "mT")
        } else if m < 1e-3 {
            scaled(1e6, "tesla")
        } else {
            String::new()
        };
        let shown = if m >= 1e-3 {
            format!("{m:.4}")
        } else {
            format!("{m:.3e}")
        };
        (
            shown,
            format!(", where the Earth's is 22–67 µT: it must be in µT{hint}"),
        )
    };
    Err(FieldError::NotMicrotesla {
        given_by: field.source().to_owned(),
        magnitude_ut,
        why,
    })
}

/// Resolves the field: the command line first (`--field-ned`, then `--location/--date`, then `--field-ut`), then the
/// recording's metadata (`field_ned_ut`, then `location` + `date`). A field given in another unit than µT is
/// refused ([`in_microtesla`]).
pub fn resolve(args: &FieldArgs, meta: &Metadata) -> Result<ReferenceField, FieldError> {
    in_microtesla(given(args, meta)?)
}

/// The field as given, before its unit is checked.
fn given(args: &FieldArgs, meta: &Metadata) -> Result<ReferenceField, FieldError> {
    if let Some(f) = args.field_ned_ut {
        return Ok(ReferenceField::Vector {
            field_ned_ut: f,
            source: "--field-ned".to_owned(),
        });
    }
    if let Some((loc, date)) = &args.location {
        return wmm(loc, date, "--location/--date");
    }
    if let Some(f) = args.field_ut {
        return Ok(ReferenceField::Magnitude {
            field_ut: f,
            source: "--field-ut".to_owned(),
        });
    }
    if let Some(f) = meta.field_ned_ut {
        return Ok(ReferenceField::Vector {
            field_ned_ut: f,
            source: "recording metadata field_ned_ut".to_owned(),
        });
    }
    if let (Some(loc), Some(date)) = (&meta.location, &meta.date) {
        return wmm(loc, date, "recording metadata location + date");
    }
    Ok(ReferenceField::Unknown)
}

/// The World Magnetic Model's field at a place and date (NED, µT; north is true north).
pub fn wmm(loc: &Location, date: &Date, via: &str) -> Result<ReferenceField, FieldError> {
    let err = |why: String| FieldError::Wmm {
        lat: loc.lat_deg,
        lon: loc.lon_deg,
        alt: loc.alt_m,
        date: *date,
        why,
    };
    let month = Month::try_from(date.month).map_err(|e| err(e.to_string()))?;
    let day =
        WmmDate::from_calendar_date(date.year, month, date.day).map_err(|e| err(e.to_string()))?;
    let g = GeomagneticField::new(
        Length::new::<meter>(loc.alt_m as f32),
        Angle::new::<degree>(loc.lat_deg as f32),
        Angle::new::<degree>(loc.lon_deg as f32),
        day,
    )
    .map_err(|e| err(e.to_string()))?;
    let field_ned_ut = [g.x(), g.y(), g.z()].map(|c| f64::from(c.get::<microtesla>()));
    Ok(ReferenceField::Vector {
        field_ned_ut,
        source: format!(
            "World Magnetic Model ({via}: {}, {}, {} m, {date})",
            loc.lat_deg, loc.lon_deg, loc.alt_m
        ),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_wmm_gives_a_plausible_field_for_berlin() {
        let loc = Location {
            lat_deg: 52.51,
            lon_deg: 13.32,
            alt_m: 50.0,
        };
        let date: Date = "2021-05-10".parse().unwrap();
        let f = wmm(&loc, &date, "test").unwrap();
        let v = f.vector().unwrap();
        // Berlin: ~17.5 µT north, ~1.4 µT east, ~46.5 µT down, |B| ≈ 49.8 µT.
        assert!(
            (v[0] - 17.5).abs() < 1.5 && v[1].abs() < 3.0 && (v[2] - 46.5).abs() < 1.5,
            "{v:?}"
        );
    }

    #[test]
    fn a_date_outside_the_model_is_a_clear_error() {
        let loc = Location {
            lat_deg: 45.19,
            lon_deg: 5.73,
            alt_m: 200.0,
        };
        let date: Date = "2016-06-02".parse().unwrap();
        let msg = wmm(&loc, &date, "test").unwrap_err().to_string();
        assert!(
            msg.contains("2016-06-02") && msg.contains("World Magnetic Model"),
            "{msg}"
        );
    }

    #[test]
    fn the_command_line_wins_over_the_metadata() {
        let meta = Metadata {
            field_ned_ut: Some([1.0, 2.0, 3.0]),
            ..Metadata::default()
        };
        let args = FieldArgs {
            field_ned_ut: Some([20.0, 0.0, 40.0]),
            ..FieldArgs::default()
        };
        assert_eq!(
            resolve(&args, &meta).unwrap().vector(),
            Some([20.0, 0.0, 40.0])
        );
        assert_eq!(
            resolve(&FieldArgs::default(), &meta).unwrap().vector(),
            Some([1.0, 2.0, 3.0])
        );
        assert_eq!(
            resolve(&FieldArgs::default(), &Metadata::default()).unwrap(),
            ReferenceField::Unknown
        );
    }

    #[test]
    fn a_field_given_in_another_unit_is_refused_saying_which() {
        let given = |f: [f64; 3]| {
            let args = FieldArgs {
                field_ned_ut: Some(f),
                ..FieldArgs::default()
            };
            resolve(&args, &Metadata::default()).map_err(|e| e.to_string())
        };
        let nt = given([19_800.0, 1_200.0, 45_300.0]).unwrap_err();
        assert!(nt.contains("in nT? then it is 19.80,1.20,45.30 µT"), "{nt}");
        let gauss = given([0.198, 0.012, 0.453]).unwrap_err();
        assert!(
            gauss.contains("in gauss? then it is 19.80,1.20,45.30 µT"),
            "{gauss}"
        );
        let tesla = given([19.8e-6, 1.2e-6, 45.3e-6]).unwrap_err();
        assert!(
            tesla.contains("in tesla? then it is 19.80,1.20,45.30 µT"),
            "{tesla}"
        );
        let mt = given([0.0198, 0.0012, 0.0453]).unwrap_err();
        assert!(mt.contains("in mT? then it is 19.80,1.20,45.30 µT"), "{mt}");
        let zero = given([0.0; 3]).unwrap_err();
        assert!(zero.contains("a field of zero"), "{zero}");
        // µT, the Earth's or a coil's, up to the widest range of the chips read.
        for f in [
            [19.8, 1.2, 45.3],
            [0.0, 0.0, FIELD_MIN_UT],
            [FIELD_MAX_UT, 0.0, 0.0],
        ] {
            assert!(given(f).is_ok(), "{f:?}");
        }
        // The metadata's field and a magnitude alone alike, named by where they came from.
        let meta = Metadata {
            field_ned_ut: Some([19_800.0, 1_200.0, 45_300.0]),
            ..Metadata::default()
        };
        let from_meta = resolve(&FieldArgs::default(), &meta)
            .unwrap_err()
            .to_string();
        assert!(
            from_meta.contains("recording metadata field_ned_ut"),
            "{from_meta}"
        );
        let magnitude = FieldArgs {
            field_ut: Some(49_000.0),
            ..FieldArgs::default()
        };
        let msg = resolve(&magnitude, &Metadata::default())
            .unwrap_err()
            .to_string();
        assert!(
            msg.contains("(--field-ut)") && msg.contains("then it is 49.00 µT"),
            "{msg}"
        );
    }
}
