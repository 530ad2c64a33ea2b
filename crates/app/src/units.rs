//! The readings' unit. A recording holds µT, but a board that prints raw counts (a GY-271's QMC5883L, an HMC5883L
//! read by a sketch) gives readings whose radius about their centre is no Earth's field. With the field's magnitude
//! known, `A` maps them to µT whatever they are, so the calibrated field, `b` and the heading figures are µT; the
//! offset `−A⁻¹·b` stays in the readings' units. The autopilots' formats take the readings as their drivers make
//! them — the chip's counts turned into gauss by its datasheet's sensitivity — so they also need how many of the
//! readings' units make a gauss: a chip's counts per gauss from `--chip CHIP[:SETTING]` (the datasheet figures the
//! drivers in `magcal_driver` cite), or the unit the recording's metadata states.

use std::fmt;
use std::str::FromStr;

use magcal_driver::{ChipKind, hmc5883l, lis2mdl, lis3mdl, mmc5983ma, qmc5883l};
use magcal_recording::Metadata;

/// The range of the Earth's field at its surface, µT (the World Magnetic Model's extremes, rounded out).
pub const EARTH_FIELD_UT: (f64, f64) = (22.0, 67.0);

/// A sensor's gain is within 10–20 % of its datasheet's: readings whose scale, taken in a stated unit, puts the field
/// further than this factor (either way) from the one given are not in that unit (or the field is wrong).
pub const GAIN_TOLERANCE: f64 = 1.3;

/// Units per gauss of the units a recording's metadata or a serial board may state.
const UNITS_PER_GAUSS: [(&str, &str, f64); 4] = [
    ("µT", "microtesla", 100.0),
    ("gauss", "gauss", 1.0),
    ("mG", "milligauss", 1000.0),
    ("nT", "nanotesla", 100_000.0),
];

/// One setting of a chip (a range or a resolution) and its datasheet's sensitivity.
#[derive(Clone, Debug, PartialEq)]
pub struct Setting {
    /// As `--chip` takes it after the colon (`8g`, `18bit`).
    pub key: String,
    /// In words (`±8 G, 3000 LSB/G`).
    pub name: String,
    /// Counts per gauss.
    pub counts_per_gauss: f64,
}

/// `range_ut` as `--chip` names it: gauss without trailing zeros, and `g`.
fn range_key(range_ut: f32) -> String {
    format!("{}g", f64::from(range_ut) / 100.0)
}

/// A range setting.
fn range_setting(range_ut: f32, lsb_per_gauss: f32) -> Setting {
    Setting {
        key: range_key(range_ut),
        name: format!(
            "±{} G, {} LSB/G",
            f64::from(range_ut) / 100.0,
            lsb_per_gauss
        ),
        counts_per_gauss: f64::from(lsb_per_gauss),
    }
}

/// Every setting of `chip`, the one a sketch most likely uses first: the QMC5883L at ±8 G (its datasheet's example
/// configuration, CONTROL_1 = 0x1D, which the common libraries and magcal's driver use), the HMC5883L at ±1.3 G and
/// the LIS3MDL at ±4 G (their reset values), the MMC5983MA's 18-bit output. The sensitivities are the drivers',
/// each from its datasheet (cited in the driver's module).
pub fn settings(chip: ChipKind) -> Vec<Setting> {
    match chip {
        ChipKind::Qmc5883l => [qmc5883l::Range::G8, qmc5883l::Range::G2]
            .into_iter()
            .map(|r| range_setting(r.range_ut(), r.lsb_per_gauss()))
            .collect(),
        ChipKind::Hmc5883l => {
            let mut gains = hmc5883l::Gain::ALL.to_vec();
            gains.sort_by_key(|g| *g != hmc5883l::Gain::Ga1_3);
            gains
                .into_iter()
                .map(|g| range_setting(g.range_ut(), g.lsb_per_gauss()))
                .collect()
        }
        ChipKind::Lis3mdl => lis3mdl::FullScale::ALL
            .into_iter()
            .map(|s| range_setting(s.range_ut(), s.lsb_per_gauss()))
            .collect(),
        ChipKind::Lis2mdl => vec![Setting {
            key: "50g".to_owned(),
            name: "±50 G, 1.5 mG/LSB".to_owned(),
            counts_per_gauss: 100.0 / f64::from(lis2mdl::regs::LSB_UT),
        }],
        ChipKind::Mmc5983ma => [
            ("18bit", mmc5983ma::regs::COUNTS_PER_GAUSS_18),
            ("16bit", mmc5983ma::regs::COUNTS_PER_GAUSS_16),
        ]
        .into_iter()
        .map(|(key, counts)| Setting {
            key: key.to_owned(),
            name: format!("{} output, {counts} counts/G", key.replace("bit", "-bit")),
            counts_per_gauss: f64::from(counts),
        })
        .collect(),
    }
}

/// A chip whose raw counts the readings are (`--chip CHIP[:SETTING]`), with its setting if stated.
#[derive(Clone, Debug, PartialEq)]
pub struct ChipOption {
    /// The chip.
    pub chip: ChipKind,
    /// The setting, when stated (otherwise the one that fits the field, or the usual one: [`settings`]).
    pub setting: Option<Setting>,
}

/// A `--chip` value that does not parse.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("--chip {text:?}: {why}")]
pub struct ChipOptionError {
    /// What was given.
    pub text: String,
    /// What is wrong, and what would do.
    pub why: String,
}

impl FromStr for ChipOption {
    type Err = ChipOptionError;

    fn from_str(text: &str) -> Result<ChipOption, ChipOptionError> {
        let (name, key) = match text.split_once(':') {
            Some((n, k)) => (n, Some(k)),
            None => (text, None),
        };
        let bad = |why: String| ChipOptionError {
            text: text.to_owned(),
            why,
        };
        let chip: ChipKind = name.parse().map_err(|e| bad(format!("{e}")))?;
        let all = settings(chip);
        let setting = match key {
            None => None,
            Some(k) => {
                let wanted = k.trim().to_lowercase().replace([' ', '±'], "");
                let found = all.iter().find(|s| s.key == wanted).cloned();
                Some(found.ok_or_else(|| {
                    let keys: Vec<String> = all
                        .iter()
                        .map(|s| format!("{chip}:{} ({})", s.key, s.name))
                        .collect();
                    bad(format!(
                        "the {chip} has no setting {k:?}; it has {}",
                        keys.join(", ")
                    ))
                })?)
            }
        };
        Ok(ChipOption { chip, setting })
    }
}

impl fmt::Display for ChipOption {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.setting {
            Some(s) => write!(f, "{}:{}", self.chip, s.key),
            None => write!(f, "{}", self.chip),
        }
    }
}

/// How many of the readings' units make a gauss, and where that comes from.
#[derive(Clone, Debug, PartialEq)]
pub struct PerGauss {
    /// Units per gauss.
    pub per_gauss: f64,
    /// What one unit is called: `counts` for a chip's, the unit's symbol otherwise.
    pub unit: String,
    /// Where it comes from, in words (`--chip QMC5883L: ±8 G, 3000 LSB/G`).
    pub source: String,
    /// Whether it was stated (a `units:` line, a setting given with `--chip`) rather than picked among a chip's
    /// settings: a stated unit that puts the field far off is warned about; a picked one is not taken.
    pub stated: bool,
}

/// Readings that are not µT.
#[derive(Clone, Debug, PartialEq)]
pub struct RawUnits {
    /// The readings' median radius about the fitted centre, in their units.
    pub radius: f64,
    /// The field's magnitude `A` maps them to, µT, when it is known (otherwise the calibrated field is in the
    /// readings' units: the sphere keeps their mean radius).
    pub field_ut: Option<f64>,
    /// How many of them make a gauss, when a chip or a unit says.
    pub scale: Option<PerGauss>,
    /// The field's magnitude over what the readings read in that unit (known field and scale): 1 for a sensor at
    /// its datasheet's sensitivity.
    pub gain: Option<f64>,
    /// Another setting of the stated chip that puts the field within [`GAIN_TOLERANCE`] when the stated one does
    /// not: the readings were taken at that one.
    pub better: Option<String>,
    /// Chips' settings and units the radius is close to (within a factor 1.5 of an Earth's field), for the user to
    /// recognise, when no scale is known.
    pub near: Vec<String>,
}

/// The readings' unit.
#[derive(Clone, Debug, Default, PartialEq)]
pub enum Units {
    /// µT, as the format says.
    #[default]
    Microtesla,
    /// Another unit (raw counts, gauss …).
    Raw(RawUnits),
}

/// One candidate unit for the readings.
fn candidates_of(chip: ChipKind, only: Option<&Setting>, how: &str) -> Vec<PerGauss> {
    let stated = only.is_some();
    let all = match only {
        Some(s) => vec![s.clone()],
        None => settings(chip),
    };
    all.into_iter()
        .map(|s| PerGauss {
            per_gauss: s.counts_per_gauss,
            unit: "counts".to_owned(),
            source: format!("{how} {}: {}", chip.info().name, s.name),
            stated,
        })
        .collect()
}

/// The unit a metadata `units:` line states, if it is one of [`UNITS_PER_GAUSS`].
fn stated_unit(meta: &Metadata) -> Option<PerGauss> {
    let (_, unit) = meta
        .other
        .iter()
        .find(|(k, _)| k.eq_ignore_ascii_case("units"))?;
    let said = unit.trim().to_lowercase().replace('μ', "µ");
    let (symbol, _, per_gauss) = UNITS_PER_GAUSS.iter().find(|(symbol, word, _)| {
        said == symbol.to_lowercase()
            || said == *word
            || (*symbol == "µT" && said == "ut")
            || (*symbol == "gauss" && said == "g")
    })?;
    Some(PerGauss {
        per_gauss: *per_gauss,
        unit: "raw units".to_owned(),
        source: format!(
            "the recording's metadata calls them {symbol}: units: {}",
            unit.trim()
        ),
        stated: true,
    })
}

/// The chip a metadata `sensor:` line names first (`qmc5883l (GY-63, …)`).
fn sensor_chip(meta: &Metadata) -> Option<ChipKind> {
    let sensor = meta.sensor.as_deref()?;
    let first = sensor.split(|c: char| !c.is_ascii_alphanumeric()).next()?;
    first.parse().ok()
}

/// `ln` of a gain, the distance from 1 either way.
fn off_by(gain: f64) -> f64 {
    gain.ln().abs()
}

impl Units {
    /// The readings' unit: µT unless `raw_not_ut` (their median radius `radius` about the fitted centre is no Earth's
    /// field); then how many make a gauss, from `chip` (`--chip`; without a setting, its settings and the unit the
    /// metadata states), else the recording's metadata (a `units:` line, a chip named by `sensor:`). With the
    /// field's magnitude `field_ut` known, the candidate that puts the readings nearest it is taken; without, the
    /// chip's stated or usual setting, else the unit.
    pub fn resolve(
        raw_not_ut: bool,
        radius: f64,
        field_ut: Option<f64>,
        meta: &Metadata,
        chip: Option<&ChipOption>,
    ) -> Units {
        if !raw_not_ut {
            return Units::Microtesla;
        }
        // A stated setting is taken at its word; a chip without one may also be read in the unit the metadata
        // states (counts already scaled by a sketch).
        let candidates: Vec<PerGauss> = match chip {
            Some(c) if c.setting.is_some() => candidates_of(c.chip, c.setting.as_ref(), "--chip"),
            Some(c) => candidates_of(c.chip, None, "--chip")
                .into_iter()
                .chain(stated_unit(meta))
                .collect(),
            None => stated_unit(meta)
                .into_iter()
                .chain(
                    sensor_chip(meta)
                        .map(|k| candidates_of(k, None, "the recording's sensor,"))
                        .unwrap_or_default(),
                )
                .collect(),
        };
        let gain_of = |p: &PerGauss| field_ut.map(|f| f * p.per_gauss / (100.0 * radius));
        let scale = match field_ut {
            Some(_) => candidates
                .iter()
                .min_by(|a, b| {
                    off_by(gain_of(a).unwrap_or(f64::NAN))
                        .total_cmp(&off_by(gain_of(b).unwrap_or(f64::NAN)))
                })
                .cloned(),
            None => candidates.first().cloned(),
        };
        let gain = scale.as_ref().and_then(gain_of);
        // A stated setting that does not fit while another of the same chip does: the readings were taken at that.
        let better = match (chip, gain) {
            (Some(c), Some(g)) if c.setting.is_some() && off_by(g) > GAIN_TOLERANCE.ln() => {
                candidates_of(c.chip, None, "")
                    .into_iter()
                    .zip(settings(c.chip))
                    .find(|(p, _)| gain_of(p).is_some_and(|g| off_by(g) <= GAIN_TOLERANCE.ln()))
                    .map(|(_, s)| format!("{}:{} ({})", c.chip, s.key, s.name))
            }
            _ => None,
        };
        let near = if scale.is_none() {
            near_scales(radius)
        } else {
            Vec::new()
        };
        Units::Raw(RawUnits {
            radius,
            field_ut,
            scale,
            gain,
            better,
            near,
        })
    }

    /// The readings that are not µT, if they are not.
    pub fn raw(&self) -> Option<&RawUnits> {
        match self {
            Units::Microtesla => None,
            Units::Raw(r) => Some(r),
        }
    }

    /// What one of the readings' units is called: `µT`, `counts`, `units`.
    pub fn raw_label(&self) -> String {
        match self {
            Units::Microtesla => "µT".to_owned(),
            Units::Raw(r) => r
                .scale
                .as_ref()
                .map_or("raw units".to_owned(), |s| s.unit.clone()),
        }
    }

    /// What the calibrated field is in: µT, or the readings' units when no field magnitude was known.
    pub fn calibrated_label(&self) -> String {
        match self {
            Units::Raw(r) if r.field_ut.is_none() => self.raw_label(),
            _ => "µT".to_owned(),
        }
    }

    /// Whether the calibrated field (`b`, the residual, the noise) is in µT.
    pub fn calibrated_ut(&self) -> bool {
        !matches!(self, Units::Raw(r) if r.field_ut.is_none())
    }

    /// The readings' units per gauss and the calibrated field's, for the formats that take gauss or milligauss: µT
    /// is 100 a gauss; `None` for readings whose scale no chip or unit states.
    pub fn per_gauss(&self) -> Option<(f64, f64)> {
        match self {
            Units::Microtesla => Some((100.0, 100.0)),
            Units::Raw(r) => {
                let raw = r.scale.as_ref()?.per_gauss;
                Some((raw, if r.field_ut.is_some() { 100.0 } else { raw }))
            }
        }
    }

    /// Whether what is said of the unit is a warning (the user must act: no field to scale to, or a stated unit
    /// that puts the field far from the one given) rather than a note.
    pub fn is_warning(&self) -> bool {
        match self {
            Units::Microtesla => false,
            Units::Raw(r) => {
                r.field_ut.is_none() || r.gain.is_some_and(|g| off_by(g) > GAIN_TOLERANCE.ln())
            }
        }
    }

    /// Why an autopilot's format (which takes gauss or milligauss) cannot be written, if it cannot: no chip or unit
    /// states the readings' scale, or the stated setting of the chip does not fit the field while another does.
    pub fn autopilot_refusal(&self) -> Option<String> {
        let r = self.raw()?;
        if let Some(better) = &r.better {
            return Some(format!(
                "the readings are not this setting's counts: with it the field would read {:.2} times the one given, \
                 and {better} fits; the autopilot's driver converts the chip's counts by its own setting, so the \
                 offsets would be off by as much. Give --chip {}",
                r.gain.unwrap_or(f64::NAN),
                better.split(' ').next().unwrap_or_default()
            ));
        }
        match (&r.scale, r.gain) {
            (None, _) => Some(
                "the readings are not µT, and an autopilot takes milligauss or gauss as its driver makes them from \
                 the chip's counts: say which chip and setting made them, --chip CHIP[:SETTING] (e.g. --chip \
                 hmc5883l, --chip qmc5883l:8g; magcal-fit --help lists them), and fit again. The C header and the \
                 JSON need no scale"
                    .to_owned(),
            ),
            (Some(s), Some(g)) if !s.stated && off_by(g) > GAIN_TOLERANCE.ln() => Some(format!(
                "the readings are not µT, nor the counts of any setting of the chip: the nearest ({}) puts the field \
                 {:.2} times off, where a sensor's gain is within 10–20 % of its datasheet's. Say what made them, \
                 --chip CHIP:SETTING, and fit again",
                s.source,
                g.max(1.0 / g)
            )),
            _ => None,
        }
    }

    /// What is said of readings that are not µT, in the summary (a warning or a note, [`Units::is_warning`]):
    /// their radius, what `A` makes of them, and how many make a gauss.
    pub fn statement(&self) -> Option<String> {
        let r = self.raw()?;
        let (low, high) = EARTH_FIELD_UT;
        let unit = self.raw_label();
        let like = if r.near.is_empty() {
            String::new()
        } else {
            format!(" (they look like {})", r.near.join(", or "))
        };
        let mut out = format!(
            "the raw readings are not in µT: they lie {:.1} {unit} from their centre, where the Earth's field is \
             {low:.0}–{high:.0} µT{like}. ",
            r.radius
        );
        match r.field_ut {
            Some(f) => {
                out += &format!(
                    "A maps them to µT — multiplying them by {:.4} on average, to the field's {f:.2} µT — so the \
                 calibrated field, b, the residual and the heading figures are µT, and the offset −A⁻¹b is in \
                 {unit}. ",
                    f / r.radius
                )
            }
            None => {
                out += &format!(
                    "No field magnitude was given, so the calibrated field — b, the residual, the noise — is in {unit} \
                 too (the sphere keeps their mean radius): a heading needs only its direction, and the C header and \
                 the JSON carry it as it is; give --field-ut, --field-ned or --location/--date to have A map them \
                 to µT. "
                )
            }
        }
        match (&r.scale, r.gain) {
            (Some(s), Some(g)) if !s.stated && off_by(g) > GAIN_TOLERANCE.ln() => out += &format!(
                "Nor are they a chip's counts: the nearest setting ({}) puts the field {:.2} times off, where a \
                 sensor's gain is within 10–20 % of its datasheet's; the autopilot exports need what made them: \
                 --chip CHIP:SETTING",
                s.source,
                g.max(1.0 / g)
            ),
            (Some(s), Some(g)) if off_by(g) > GAIN_TOLERANCE.ln() => out += &format!(
                "{} of them make a gauss ({}), but then the sensor reads the field {:.2} times too {}: a sensor's \
                 gain is within 10–20 % of its datasheet's, so {}",
                number(s.per_gauss),
                s.source,
                g.max(1.0 / g),
                if g > 1.0 { "weak" } else { "strong" },
                match &r.better {
                    Some(b) => format!("the readings were taken at {b}: give --chip with it"),
                    None => "either the field given is not the one where it was recorded, or the readings \
                             are not what that says (a range set by the sketch, another chip): the autopilot \
                             files carry the factor in their matrix, and are right only if the autopilot reads the \
                             chip as the recording did"
                        .to_owned(),
                }
            ),
            (Some(s), _) => out += &format!(
                "{} of them make a gauss ({}): the autopilot exports use that",
                number(s.per_gauss),
                s.source
            ),
            (None, _) => out += "The autopilot exports (ArduPilot, PX4) also need how many make a gauss: say which \
                                 chip and setting made them, --chip CHIP[:SETTING] (e.g. --chip hmc5883l, --chip \
                                 qmc5883l:8g)",
        }
        Some(out)
    }
}

/// A number without trailing zeros (`12000`, `666.667`).
fn number(x: f64) -> String {
    let s = format!("{x:.3}");
    s.trim_end_matches('0').trim_end_matches('.').to_owned()
}

/// The chips' settings and units whose scale would make readings of this radius an Earth's field (its geometric
/// middle within a factor 1.5), named.
fn near_scales(radius: f64) -> Vec<String> {
    let (low, high) = EARTH_FIELD_UT;
    let wanted_per_gauss = 100.0 * radius / (low * high).sqrt();
    let chips = ChipKind::ALL.into_iter().flat_map(|chip| {
        settings(chip).into_iter().map(move |s| {
            (
                format!("{} counts at {}", chip.info().name, s.name),
                s.counts_per_gauss,
            )
        })
    });
    let units = UNITS_PER_GAUSS
        .iter()
        .map(|(_, word, per_gauss)| ((*word).to_owned(), *per_gauss));
    chips
        .chain(units)
        .filter(|(_, per_gauss)| off_by(per_gauss / wanted_per_gauss) < 1.5f64.ln())
        .map(|(name, _)| name)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chips_and_settings_parse_and_name_what_they_have() {
        let q: ChipOption = "qmc5883l".parse().unwrap();
        assert_eq!((q.chip, q.setting.clone()), (ChipKind::Qmc5883l, None));
        assert_eq!(settings(ChipKind::Qmc5883l)[0].counts_per_gauss, 3000.0);
        let q: ChipOption = "QMC5883L:2G".parse().unwrap();
        assert_eq!(q.setting.unwrap().counts_per_gauss, 12000.0);
        let h: ChipOption = "hmc5883l:1.3g".parse().unwrap();
        assert_eq!(h.to_string(), "hmc5883l:1.3g");
        assert_eq!(settings(ChipKind::Hmc5883l)[0].counts_per_gauss, 1090.0);
        let m: ChipOption = "mmc5983ma:16bit".parse().unwrap();
        assert_eq!(m.setting.unwrap().counts_per_gauss, 4096.0);
        let e = "qmc5883l:4g".parse::<ChipOption>().unwrap_err().to_string();
        assert!(
            e.contains("has no setting \"4g\"") && e.contains("qmc5883l:8g (±8 G, 3000 LSB/G)"),
            "{e}"
        );
        let e = "hmc".parse::<ChipOption>().unwrap_err().to_string();
        assert!(e.contains("unknown chip"), "{e}");
    }

    #[test]
    fn the_setting_that_fits_the_field_is_taken_and_a_wrong_one_named() {
        let meta = Metadata::default();
        // QMC5883L counts at ±8 G in a 48 µT field: radius 1440 counts.
        let chip: ChipOption = "qmc5883l".parse().unwrap();
        let u = Units::resolve(true, 1440.0, Some(48.0), &meta, Some(&chip));
        assert_eq!(u.per_gauss(), Some((3000.0, 100.0)));
        assert!(!u.is_warning() && u.autopilot_refusal().is_none(), "{u:?}");
        // Stated as ±2 G: the field would read 4 times too weak; ±8 G is named, and the autopilots refused.
        let chip: ChipOption = "qmc5883l:2g".parse().unwrap();
        let u = Units::resolve(true, 1440.0, Some(48.0), &meta, Some(&chip));
        assert!(u.is_warning());
        let why = u.autopilot_refusal().unwrap();
        assert!(why.contains("Give --chip qmc5883l:8g"), "{why}");
        // No chip, no field: raw units, no scale; the radius is named as close to HMC5883L counts.
        let u = Units::resolve(true, 480.0, None, &meta, None);
        assert_eq!(u.per_gauss(), None);
        assert_eq!(u.calibrated_label(), "raw units");
        let said = u.statement().unwrap();
        assert!(
            said.contains("not in µT") && said.contains("HMC5883L counts at ±1.3 G"),
            "{said}"
        );
        assert!(u.autopilot_refusal().unwrap().contains("--chip"));
        // µT readings: nothing said.
        let u = Units::resolve(false, 48.0, Some(48.0), &meta, None);
        assert_eq!((u.statement(), u.per_gauss()), (None, Some((100.0, 100.0))));
    }

    #[test]
    fn the_metadata_states_the_unit_or_the_chip() {
        let mut meta = Metadata {
            sensor: Some("qmc5883l (GY-63, +-2 G)".to_owned()),
            ..Metadata::default()
        };
        // Counts at ±2 G in a 23 µT field: radius 2760.
        let u = Units::resolve(true, 2760.0, Some(23.0), &meta, None);
        assert_eq!(u.per_gauss(), Some((12000.0, 100.0)));
        assert_eq!(u.raw_label(), "counts");
        meta.other.push(("units".to_owned(), "uT".to_owned()));
        // Stated µT whose radius puts the field 2.3 times off: taken as µT, with a warning.
        let u = Units::resolve(true, 10.0, Some(23.0), &meta, None);
        assert_eq!(u.per_gauss(), Some((100.0, 100.0)));
        assert!(u.is_warning() && u.autopilot_refusal().is_none());
        assert!(
            u.statement().unwrap().contains("2.30 times too weak"),
            "{u:?}"
        );
    }
}
