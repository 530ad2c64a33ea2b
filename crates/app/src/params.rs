//! The parameters file (`--out params.toml`): the final model, written atomically, read back for `apply`.

use std::path::Path;

use magcal_calib::effects::{Need, Shape, Value};
use magcal_calib::{Effect, EffectId, Model};
use serde::{Deserialize, Serialize};

use crate::files::write_atomic;

/// The format line every parameters file carries.
pub const FORMAT: &str = "magcal-params v1";

/// A parameters file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ParamsFile {
    /// Always [`FORMAT`].
    pub format: String,
    /// `vector` or `scalar`.
    pub method: String,
    /// The sensor, from the recording's metadata.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sensor: Option<String>,
    /// The recording it was fitted on.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub recording: Option<String>,
    /// `B = A·B̂ + b`.
    pub calibration: LinearParams,
    /// The readings' unit, when they were not µT ([`crate::units`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub units: Option<UnitsParams>,
    /// Body-fixed corrections `apply` removes, in order: the sensor's (temperature, currents, non-linearity), never
    /// one recording's own (a drift or a step of the offset, tied to its clock: those stay in its report).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub corrections: Vec<Correction>,
    /// Comment lines written at the top of the file (what was left to the report, and why).
    #[serde(skip)]
    pub comments: Vec<String>,
}

/// What the readings were in, when not µT: `raw` in `B = A·raw + b` is in `readings`, and `b_ut` in `calibrated`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct UnitsParams {
    /// What one unit of the readings is: `counts` or `raw units`.
    pub readings: String,
    /// How many of them make a gauss, when a chip or unit said.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub per_gauss: Option<f64>,
    /// What the calibrated field (and so `b_ut`) is in: `uT`, or the readings' unit when no field magnitude was known.
    pub calibrated: String,
}

/// `A` and `b`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LinearParams {
    /// `A`, row-major.
    #[serde(rename = "A")]
    pub a: [[f64; 3]; 3],
    /// `b`, µT.
    pub b_ut: [f64; 3],
}

/// A body-fixed correction as written in the file: the effect's id and its parameters in its descriptor's order
/// ([`EffectId::descriptor`]), current channels by name, not index. In TOML and JSON it is a table: `id`, then each
/// parameter by its report name.
#[derive(Clone, Debug, PartialEq)]
pub struct Correction {
    /// The effect: body-fixed, and a property of the sensor (not an event of one recording).
    pub id: EffectId,
    /// Its parameters, each with its descriptor's name.
    pub params: Vec<(&'static str, CorrectionValue)>,
}

/// A correction's parameter as written in the file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum CorrectionValue {
    /// One number.
    Number(f64),
    /// Three numbers.
    Vector([f64; 3]),
    /// A current channel, by its column name.
    Channel(String),
}

/// Rows of numbers as TOML wrote them, each column padded so that the decimal points (or the ends of integers and
/// mantissas) line up and the next column starts at one place: `" 0.93,   0.0026, -0.012"`.
fn aligned(rows: &[Vec<&str>]) -> Vec<String> {
    let columns = rows.iter().map(Vec::len).max().unwrap_or(0);
    // Where a number's point is: before its '.' or exponent, or at its end.
    let point = |n: &str| n.find(['.', 'e', 'E']).unwrap_or(n.len());
    let column = |k: usize| rows.iter().filter_map(move |r| r.get(k).copied());
    let lead: Vec<usize> = (0..columns)
        .map(|k| column(k).map(point).max().unwrap_or(0))
        .collect();
    let width: Vec<usize> = (0..columns)
        .map(|k| {
            column(k)
                .map(|n| lead[k] - point(n) + n.chars().count())
                .max()
                .unwrap_or(0)
        })
        .collect();
    rows.iter()
        .map(|row| {
            let mut line = String::new();
            for (k, n) in row.iter().enumerate() {
                let cell = format!("{}{n}", " ".repeat(lead[k] - point(n)));
                if k + 1 < row.len() {
                    // Padded after the comma, so that the next column starts at one place.
                    let pad = width[k] - cell.chars().count();
                    line += &format!("{cell},{} ", " ".repeat(pad));
                } else {
                    line += &cell;
                }
            }
            line
        })
        .collect()
}

/// The key of the first number in `v` that is not finite (`calibration.A[0][1]`), if any.
fn first_non_finite(v: &toml::Value, at: String) -> Option<String> {
    match v {
        toml::Value::Float(x) if !x.is_finite() => Some(at),
        toml::Value::Array(items) => items
            .iter()
            .enumerate()
            .find_map(|(i, x)| first_non_finite(x, format!("{at}[{i}]"))),
        toml::Value::Table(t) => t.iter().find_map(|(k, x)| {
            let key = if at.is_empty() {
                k.clone()
            } else {
                format!("{at}.{k}")
            };
            first_non_finite(x, key)
        }),
        _ => None,
    }
}

/// A parameters file that cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum ParamsError {
    /// Unreadable. The system's error is said in the message, not chained again as its source.
    #[error("{path}: cannot read: {why}")]
    Io {
        /// The file.
        path: String,
        /// Why.
        why: std::io::Error,
    },
    /// Not valid TOML of this format.
    #[error("{path}: {why}")]
    Format {
        /// The file.
        path: String,
        /// Why.
        why: String,
    },
    /// Not TOML, and its start is that of a recording (a `# magcal-recording` line or a header naming `mx`).
    #[error("{path}: looks like a recording, not a parameters file")]
    Recording {
        /// The file.
        path: String,
    },
}

impl Correction {
    /// The file form of a body-fixed effect; `channels` names the recording's current columns.
    pub fn from_effect(e: &Effect, channels: &[String]) -> Option<Correction> {
        if !e.id().is_correction() {
            return None;
        }
        let params = e
            .values()
            .map(|(spec, v)| {
                let v = match v {
                    Value::Number(x) => CorrectionValue::Number(x),
                    Value::Vector(x) => CorrectionValue::Vector(x),
                    Value::Channel(c) => CorrectionValue::Channel(channels.get(c)?.clone()),
                };
                Some((spec.name, v))
            })
            .collect::<Option<Vec<_>>>()?;
        Some(Correction { id: e.id(), params })
    }

    /// The effect, with current channels indexed into `channels`.
    fn to_effect(&self, channels: &[String]) -> Result<Effect, String> {
        let values = self
            .params
            .iter()
            .map(|(_, v)| match v {
                CorrectionValue::Number(x) => Ok(Value::Number(*x)),
                CorrectionValue::Vector(x) => Ok(Value::Vector(*x)),
                CorrectionValue::Channel(channel) => channels
                    .iter()
                    .position(|c| c == channel)
                    .map(Value::Channel)
                    .ok_or_else(|| format!("current channel {channel} is not among {channels:?}")),
            })
            .collect::<Result<Vec<Value>, String>>()?;
        Effect::from_values(self.id, &values)
            .ok_or_else(|| format!("the parameters of {} are not its own", self.id))
    }
}

impl Serialize for Correction {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeMap;
        let mut map = serializer.serialize_map(Some(1 + self.params.len()))?;
        map.serialize_entry("id", self.id.as_str())?;
        for (name, value) in &self.params {
            map.serialize_entry(name, value)?;
        }
        map.end()
    }
}

impl<'de> Deserialize<'de> for Correction {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Correction, D::Error> {
        use serde::de::Error;
        let mut table =
            std::collections::BTreeMap::<String, CorrectionValue>::deserialize(deserializer)?;
        let id = match table.remove("id") {
            Some(CorrectionValue::Channel(id)) => id,
            _ => return Err(D::Error::custom("a correction needs its `id` (a text)")),
        };
        let corrections = || {
            EffectId::ALL
                .into_iter()
                .filter(|id| id.is_correction())
                .map(EffectId::as_str)
                .collect::<Vec<_>>()
                .join(", ")
        };
        let id = EffectId::parse(&id)
            .filter(|id| id.is_correction())
            .ok_or_else(|| {
                D::Error::custom(format!(
                    "`{id}` is no correction a parameters file holds; they are {}",
                    corrections()
                ))
            })?;
        let specs = id.descriptor().params;
        let names = || specs.iter().map(|p| p.name).collect::<Vec<_>>().join(", ");
        if let Some(unknown) = table
            .keys()
            .find(|k| !specs.iter().any(|p| p.name == k.as_str()))
        {
            return Err(D::Error::custom(format!(
                "{id} has no parameter `{unknown}`; it takes {}",
                names()
            )));
        }
        let params = specs
            .iter()
            .map(|spec| {
                let value = table.remove(spec.name).ok_or_else(|| {
                    D::Error::custom(format!("{id} needs `{}` ({})", spec.name, names()))
                })?;
                let fits = matches!(
                    (spec.shape, &value),
                    (Shape::Number, CorrectionValue::Number(_))
                        | (Shape::Vector, CorrectionValue::Vector(_))
                        | (Shape::Channel, CorrectionValue::Channel(_))
                );
                if !fits {
                    return Err(D::Error::custom(format!(
                        "{id}'s `{}` must be {}",
                        spec.name,
                        match spec.shape {
                            Shape::Number => "a number",
                            Shape::Vector => "three numbers",
                            Shape::Channel => "a current column's name",
                        }
                    )));
                }
                Ok((spec.name, value))
            })
            .collect::<Result<Vec<_>, D::Error>>()?;
        Ok(Correction { id, params })
    }
}

impl ParamsFile {
    /// The file form of a model.
    pub fn new(method: &str, model: &Model, channels: &[String]) -> ParamsFile {
        ParamsFile {
            format: FORMAT.to_owned(),
            method: method.to_owned(),
            sensor: None,
            recording: None,
            calibration: LinearParams {
                a: model.a,
                b_ut: model.b_ut,
            },
            units: None,
            corrections: model
                .corrections()
                .filter_map(|e| Correction::from_effect(e, channels))
                .collect(),
            comments: Vec::new(),
        }
    }

    /// The parameters file of a calibration of `rec` (named `recording` in the file): the sensor's model — the final
    /// model less what belongs to this recording alone ([`sensor_model`]), said in a comment.
    pub fn of(
        cal: &crate::fit::Calibration,
        rec: &magcal_recording::Recording,
        recording: &str,
    ) -> ParamsFile {
        let channels: Vec<String> = rec.currents.iter().map(|c| c.name.clone()).collect();
        let (model, comments) = sensor_model(&cal.model());
        let mut params = ParamsFile::new(cal.method().as_str(), &model, &channels);
        params.sensor = rec.meta.sensor.clone();
        params.recording = Some(recording.to_owned());
        params.comments = comments;
        params.units = cal.units.raw().map(|r| UnitsParams {
            readings: cal.units.raw_label(),
            per_gauss: r.scale.as_ref().map(|s| s.per_gauss),
            calibrated: if cal.units.calibrated_ut() {
                "uT".to_owned()
            } else {
                cal.units.raw_label()
            },
        });
        params
    }

    /// The model, with current corrections indexed into `channels` (the `i_<name>` columns `apply` will be given).
    pub fn model(&self, channels: &[String]) -> Result<Model, String> {
        let mut model = Model::linear(self.calibration.a, self.calibration.b_ut);
        for c in &self.corrections {
            model
                .add_correction(c.to_effect(channels)?)
                .map_err(|e| e.to_string())?;
        }
        Ok(model)
    }

    /// The file's text: a comment, then TOML with `A` a row a line, its columns lined up on the decimal point. The
    /// numbers are TOML's own (the shortest that reads back the same): only spaces are added.
    pub fn text(&self) -> Result<String, toml::ser::Error> {
        let mut out = "# magcal calibration parameters: B = A·raw + b − Σ corrections\n".to_owned();
        for c in &self.comments {
            out += &format!("# {c}\n");
        }
        for line in toml::to_string(self)?.lines() {
            match line.strip_prefix("A = [[") {
                Some(rows) => {
                    out += "A = [\n";
                    let rows: Vec<Vec<&str>> = rows
                        .trim_end_matches("]]")
                        .split("], [")
                        .map(|row| row.split(", ").collect())
                        .collect();
                    for row in aligned(&rows) {
                        out += &format!("    [{row}],\n");
                    }
                    out += "]\n";
                }
                None => {
                    out += line;
                    out.push('\n');
                }
            }
        }
        Ok(out)
    }

    /// Writes the file atomically.
    pub fn write(&self, path: &Path) -> std::io::Result<()> {
        let text = self.text().map_err(std::io::Error::other)?;
        write_atomic(path, text.as_bytes())
    }

    /// Reads a file.
    pub fn read(path: &Path) -> Result<ParamsFile, ParamsError> {
        let name = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|why| ParamsError::Io {
            path: name.clone(),
            why,
        })?;
        let file: ParamsFile = toml::from_str(&text).map_err(|e| {
            if crate::files::looks_like_recording(&text) {
                ParamsError::Recording { path: name.clone() }
            } else {
                ParamsError::Format {
                    path: name.clone(),
                    why: e.to_string(),
                }
            }
        })?;
        if file.format != FORMAT {
            return Err(ParamsError::Format {
                path: name,
                why: format!("format is {:?}, expected {FORMAT:?}", file.format),
            });
        }
        file.usable()
            .map_err(|why| ParamsError::Format { path: name, why })?;
        Ok(file)
    }

    /// Why the parameters cannot calibrate anything, if they cannot: a method other than `vector` or `scalar`, a
    /// number that is not finite (named by its key), or an `A` with no usable inverse.
    fn usable(&self) -> Result<(), String> {
        if !["vector", "scalar"].contains(&self.method.as_str()) {
            return Err(format!(
                "method is {:?}, expected \"vector\" or \"scalar\"",
                self.method
            ));
        }
        let value = toml::Value::try_from(self).map_err(|e| e.to_string())?;
        if let Some(key) = first_non_finite(&value, String::new()) {
            return Err(format!(
                "{key} is not a finite number: every number in a parameters file must be"
            ));
        }
        let a = nalgebra::Matrix3::from_fn(|j, k| self.calibration.a[j][k]);
        let sv = a.singular_values();
        // NaN (an overflow) is no inverse either.
        let invertible = sv.min() > 1e-3 * sv.max();
        if !invertible {
            return Err(format!(
                "calibration.A has no usable inverse (singular values {:.3e}–{:.3e}): it maps the readings onto \
                 less than three dimensions, which no calibration does",
                sv.min(),
                sv.max()
            ));
        }
        Ok(())
    }
}

/// The sensor's model of a final `model`: without the corrections that belong to the recording it was fitted on
/// (those its descriptor needs the recording's clock for: a drift of the offset, a step), which another recording's
/// clock would apply wrongly. A step's offset after it is kept (the state the sensor was left in); a drift's `b` is
/// already the offset at the recording's mean time. Returns the model and a comment line per correction left out.
pub fn sensor_model(model: &Model) -> (Model, Vec<String>) {
    let mut kept = Model::linear(model.a, model.b_ut);
    let mut comments = Vec::new();
    for e in model.corrections() {
        let of_this_recording = e.id().descriptor().needs.contains(&Need::Time);
        if !of_this_recording {
            // A correction the model held is one it can hold again.
            let _ = kept.add_correction(*e);
            continue;
        }
        let state = match *e {
            Effect::BiasStep { t_s, step_ut } => {
                kept.b_ut = std::array::from_fn(|k| kept.b_ut[k] - step_ut[k]);
                format!("b is the offset after its step at {t_s:.1} s")
            }
            Effect::BiasDrift { t_ref_s, .. } => {
                format!("b is the offset at its middle, {t_ref_s:.1} s")
            }
            _ => "b is as fitted with it".to_owned(),
        };
        comments.push(format!(
            "{} of the recording it was fitted on is not here (tied to that recording's clock, see its report): \
             {state}",
            e.id()
        ));
    }
    (kept, comments)
}

#[cfg(test)]
mod tests {
    use super::*;
    use magcal_calib::Inputs;

    #[test]
    fn a_model_with_corrections_round_trips_and_applies_the_same() {
        let mut model = Model::linear(
            [[1.1, 0.01, 0.0], [0.0, 0.9, 0.02], [0.01, 0.0, 1.05]],
            [3.0, -4.0, 5.0],
        );
        model
            .add_correction(Effect::TemperatureBias {
                coef_ut_per_c: [0.3, 0.0, -0.1],
                t_ref_c: 24.0,
            })
            .unwrap();
        model
            .add_correction(Effect::CurrentBias {
                channel: 1,
                coef_ut_per_a: [2.0, 1.0, 0.0],
            })
            .unwrap();
        let channels = vec!["i_led".to_owned(), "i_motor".to_owned()];
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("p.toml");
        ParamsFile::new("vector", &model, &channels)
            .write(&path)
            .unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(
            text.contains("id = \"current_bias\"") && text.contains("channel = \"i_motor\""),
            "{text}"
        );
        // Read back with the channels in another order: the correction follows the name.
        let back = ParamsFile::read(&path)
            .unwrap()
            .model(&["i_motor".to_owned(), "i_led".to_owned()])
            .unwrap();
        let raw = [20.0, -10.0, 35.0];
        let a = model.apply(
            raw,
            &Inputs {
                t_s: 0.0,
                temp_c: 30.0,
                currents_a: &[0.1, 0.5],
            },
        );
        let b = back.apply(
            raw,
            &Inputs {
                t_s: 0.0,
                temp_c: 30.0,
                currents_a: &[0.5, 0.1],
            },
        );
        assert_eq!(a, b);
    }

    /// Issue 34: the file reads well — `A`'s rows line up, column by column, on the decimal point — and still reads
    /// back as the same file, every number to the bit, under the same field names.
    #[test]
    fn the_file_lines_up_a_and_reads_back_the_same() {
        let mut model = Model::linear(
            [
                [
                    0.9317201600471624,
                    0.002634932566067484,
                    -0.012264064464047347,
                ],
                [-0.008597066586786176, 10.96487, 3e-20],
                [-118.8046019774989, 0.016369089304823, 1.0],
            ],
            [-12.502591359646123, 3.8620966490806716, 10.855107522360353],
        );
        model
            .add_correction(Effect::TemperatureBias {
                coef_ut_per_c: [0.019957735016566, 0.0415, -0.0594717438],
                t_ref_c: 25.73,
            })
            .unwrap();
        let mut file = ParamsFile::new("vector", &model, &[]);
        file.sensor = Some("lis3mdl".to_owned());
        let text = file.text().unwrap();
        let rows: Vec<&str> = text
            .lines()
            .skip_while(|l| *l != "A = [")
            .skip(1)
            .take(3)
            .collect();
        assert!(rows.iter().all(|r| r.starts_with("    [")), "{text}");
        // Each column's points at one place: where each number's integer part ends, per row.
        let points = |r: &str| -> Vec<usize> {
            let mut at = 0;
            let mut out = Vec::new();
            for cell in r.split(',') {
                let number = cell.trim_start().trim_start_matches('[');
                if !number.trim().is_empty() {
                    let start = at + cell.len() - number.len();
                    out.push(start + number.find(['.', 'e', 'E', ']']).unwrap_or(number.len()));
                }
                at += cell.len() + 1;
            }
            out
        };
        let columns: Vec<Vec<usize>> = rows.iter().map(|r| points(r)).collect();
        assert!(
            columns.iter().all(|c| c.len() == 3 && *c == columns[0]),
            "{columns:?}\n{text}"
        );
        // The same file back, with the field names it always had.
        let back: ParamsFile = toml::from_str(&text).unwrap();
        assert_eq!(back, file);
        let value: toml::Value = toml::from_str(&text).unwrap();
        let keys: Vec<&String> = value.as_table().unwrap().keys().collect();
        assert_eq!(
            keys,
            ["calibration", "corrections", "format", "method", "sensor"]
        );
        let cal: Vec<&String> = value["calibration"].as_table().unwrap().keys().collect();
        assert_eq!(cal, ["A", "b_ut"]);
        assert_eq!(
            value["corrections"][0]
                .as_table()
                .unwrap()
                .keys()
                .collect::<Vec<_>>(),
            ["coef_ut_per_c", "id", "t_ref_c"]
        );
    }

    #[test]
    fn a_recording_given_as_parameters_is_named_as_one() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("rec.csv");
        for text in [
            "# magcal-recording v1\n# sensor: x\nt,mx,my,mz\n0,1,2,3\n",
            "t,MX,my,mz\n0,1,2,3\n",
            "# sensor: x\n\nt;mx;my;mz\n0;1;2;3\n",
        ] {
            std::fs::write(&path, text).unwrap();
            let err = ParamsFile::read(&path).unwrap_err();
            assert!(
                matches!(err, ParamsError::Recording { .. }),
                "{text:?}: {err}"
            );
            assert!(
                err.to_string()
                    .ends_with("rec.csv: looks like a recording, not a parameters file"),
                "{err}"
            );
        }
        std::fs::write(&path, "format = \"magcal-params v1\"\nmx my\n").unwrap();
        let err = ParamsFile::read(&path).unwrap_err();
        assert!(matches!(err, ParamsError::Format { .. }), "{err}");
    }

    #[test]
    fn a_wrong_format_or_unknown_channel_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("p.toml");
        std::fs::write(&path, "format = \"other\"\nmethod = \"x\"\n[calibration]\nA = [[1,0,0],[0,1,0],[0,0,1]]\nb_ut = [0,0,0]\n").unwrap();
        assert!(
            ParamsFile::read(&path)
                .unwrap_err()
                .to_string()
                .contains("expected")
        );
        let mut model = Model::linear(magcal_calib::frames::IDENTITY, [0.0; 3]);
        model
            .add_correction(Effect::CurrentBias {
                channel: 0,
                coef_ut_per_a: [1.0; 3],
            })
            .unwrap();
        let file = ParamsFile::new("vector", &model, &["i_a".to_owned()]);
        assert!(file.model(&["i_b".to_owned()]).unwrap_err().contains("i_a"));
    }

    #[test]
    fn a_correction_is_read_by_its_descriptor_and_what_is_wrong_is_said() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("p.toml");
        let head = "format = \"magcal-params v1\"\nmethod = \"vector\"\n[calibration]\n\
                    A = [[1,0,0],[0,1,0],[0,0,1]]\nb_ut = [0,0,0]\n[[corrections]]\n";
        let read = |body: &str| {
            std::fs::write(&path, format!("{head}{body}")).unwrap();
            ParamsFile::read(&path)
        };
        let file = read("id = \"bias_drift\"\nrate_ut_per_s = [0.1, 0, 0]\nt_ref_s = 3\n").unwrap();
        assert_eq!(
            file.model(&[]).unwrap().corrections().next(),
            Some(&Effect::BiasDrift {
                rate_ut_per_s: [0.1, 0.0, 0.0],
                t_ref_s: 3.0
            })
        );
        for (body, said) in [
            (
                "id = \"time_lag\"\nlag_s = 0.01\n",
                "is no correction a parameters file holds",
            ),
            (
                "id = \"bias_drift\"\nrate = [0.1, 0, 0]\nt_ref_s = 3\n",
                "has no parameter `rate`",
            ),
            (
                "id = \"bias_drift\"\nrate_ut_per_s = [0.1, 0, 0]\n",
                "needs `t_ref_s`",
            ),
            (
                "id = \"bias_drift\"\nrate_ut_per_s = 1\nt_ref_s = 3\n",
                "must be three numbers",
            ),
            ("rate_ut_per_s = [0.1, 0, 0]\n", "needs its `id`"),
        ] {
            let err = read(body).unwrap_err().to_string();
            assert!(err.contains(said), "{body}: {err}");
        }
    }
}
