//! PX4 ULog files, read with the `px4-ulog` crate (its streaming parser keeps the valid prefix of a truncated or
//! corrupt log and says how it ended): the magnetometer topics (`sensor_mag`, the driver's output before the
//! calibration; `vehicle_magnetometer`, after it, in body axes), `vehicle_attitude`, `battery_status`,
//! `vehicle_gps_position` (or `sensor_gps`), the parameters and the hardware's name.

use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use px4_ulog::stream_parser::model::{Completeness, FlattenedFieldType, FlattenedFormat};
use px4_ulog::stream_parser::{
    Message, ParameterMessage, SimpleCallbackResult, read_file_with_simple_callback,
};

use crate::calibration::LoggedCalibration;
use crate::series::Series;
use crate::{FlightLog, GpsFix, LogError, MagStream};

/// The fields read of each topic; the others are skipped.
const WANTED: [(&str, &[&str]); 7] = [
    (
        "sensor_mag",
        &[
            "timestamp",
            "timestamp_sample",
            "device_id",
            "x",
            "y",
            "z",
            "temperature",
        ],
    ),
    (
        "vehicle_magnetometer",
        &[
            "timestamp",
            "timestamp_sample",
            "device_id",
            "magnetometer_ga[0]",
            "magnetometer_ga[1]",
            "magnetometer_ga[2]",
        ],
    ),
    (
        "vehicle_attitude",
        &[
            "timestamp",
            "timestamp_sample",
            "q[0]",
            "q[1]",
            "q[2]",
            "q[3]",
        ],
    ),
    ("battery_status", &["timestamp", "current_a"]),
    (
        "magnetometer_bias_estimate",
        &[
            "timestamp",
            "bias_x[0]",
            "bias_x[1]",
            "bias_x[2]",
            "bias_x[3]",
            "bias_y[0]",
            "bias_y[1]",
            "bias_y[2]",
            "bias_y[3]",
            "bias_z[0]",
            "bias_z[1]",
            "bias_z[2]",
            "bias_z[3]",
            "valid[0]",
            "valid[1]",
            "valid[2]",
            "valid[3]",
        ],
    ),
    ("vehicle_gps_position", GPS_FIELDS),
    ("sensor_gps", GPS_FIELDS),
];

/// GPS fields, old (integers, 1e-7 degrees and mm) and new (degrees and m).
const GPS_FIELDS: &[&str] = &[
    "timestamp",
    "time_utc_usec",
    "fix_type",
    "lat",
    "lon",
    "alt",
    "latitude_deg",
    "longitude_deg",
    "altitude_msl_m",
];

/// One topic instance's wanted columns, by field name.
type Columns = BTreeMap<String, Vec<f64>>;

/// The value of a field at `offset` of a message's bytes, as f64; `None` past the end.
fn decode(data: &[u8], offset: usize, kind: &FlattenedFieldType) -> Option<f64> {
    fn bytes<const N: usize>(data: &[u8], offset: usize) -> Option<[u8; N]> {
        data.get(offset..offset + N)?.try_into().ok()
    }
    use FlattenedFieldType as T;
    Some(match kind {
        T::Int8 => i8::from_le_bytes(bytes(data, offset)?) as f64,
        T::UInt8 | T::Bool | T::Char => u8::from_le_bytes(bytes(data, offset)?) as f64,
        T::Int16 => i16::from_le_bytes(bytes(data, offset)?) as f64,
        T::UInt16 => u16::from_le_bytes(bytes(data, offset)?) as f64,
        T::Int32 => i32::from_le_bytes(bytes(data, offset)?) as f64,
        T::UInt32 => u32::from_le_bytes(bytes(data, offset)?) as f64,
        T::Int64 => i64::from_le_bytes(bytes(data, offset)?) as f64,
        T::UInt64 => u64::from_le_bytes(bytes(data, offset)?) as f64,
        T::Float => f32::from_le_bytes(bytes(data, offset)?) as f64,
        T::Double => f64::from_le_bytes(bytes(data, offset)?),
    })
}

/// Which wanted fields a format has: (name, offset, type).
fn selection(format: &FlattenedFormat) -> Vec<(String, usize, FlattenedFieldType)> {
    let Some((_, wanted)) = WANTED.iter().find(|(t, _)| *t == format.message_name) else {
        return Vec::new();
    };
    format
        .fields
        .iter()
        .filter(|f| wanted.contains(&f.flattened_field_name.as_str()))
        .map(|f| {
            (
                f.flattened_field_name.clone(),
                f.offset as usize,
                f.field_type.clone(),
            )
        })
        .collect()
}

/// What the parser delivered, before it is made sense of.
#[derive(Default)]
struct Raw {
    topics: BTreeMap<(String, u8), Columns>,
    params: BTreeMap<String, f64>,
    changed: Vec<String>,
    hardware: Option<String>,
    data_messages: usize,
}

impl Raw {
    fn message(
        &mut self,
        m: &Message,
        cache: &mut HashMap<u16, Vec<(String, usize, FlattenedFieldType)>>,
    ) {
        match m {
            Message::Data(d) => {
                self.data_messages += 1;
                let chosen = cache
                    .entry(d.msg_id)
                    .or_insert_with(|| selection(d.flattened_format));
                if chosen.is_empty() {
                    return;
                }
                let key = (d.flattened_format.message_name.clone(), d.multi_id.value());
                let columns = self.topics.entry(key).or_default();
                for (name, offset, kind) in chosen.iter() {
                    let value = decode(d.data, *offset, kind).unwrap_or(f64::NAN);
                    columns.entry(name.clone()).or_default().push(value);
                }
            }
            Message::ParameterMessage(p) => {
                let (name, value, initial) = match p {
                    ParameterMessage::Float(n, v, stage) => (*n, *v as f64, stage),
                    ParameterMessage::Int32(n, v, stage) => (*n, *v as f64, stage),
                };
                let initial = matches!(initial, px4_ulog::stream_parser::LogStage::Definitions);
                if initial || !self.params.contains_key(name) {
                    self.params.insert(name.to_owned(), value);
                } else if name.starts_with("CAL_MAG") && self.params.get(name) != Some(&value) {
                    self.changed.push(name.to_owned());
                }
            }
            Message::InfoMessage(i) if i.key == "ver_hw" => {
                let text = String::from_utf8_lossy(i.value);
                self.hardware = Some(text.trim_end_matches('\0').to_owned());
            }
            _ => {}
        }
    }
}

/// Reads a PX4 ULog file.
pub fn read(path: &Path) -> Result<FlightLog, LogError> {
    let file = path.display().to_string();
    let Some(path_str) = path.to_str() else {
        return Err(LogError::Io {
            file,
            source: std::io::Error::other("the path is not UTF-8; rename the file"),
        });
    };
    check_magic(path, &file)?;
    let mut raw = Raw::default();
    let mut cache = HashMap::new();
    let completeness = read_file_with_simple_callback(path_str, &mut |m: &Message| {
        raw.message(m, &mut cache);
        SimpleCallbackResult::KeepReading
    })
    .map_err(|e| match e.kind() {
        std::io::ErrorKind::Other
        | std::io::ErrorKind::InvalidData
        | std::io::ErrorKind::UnexpectedEof => LogError::Corrupt {
            file: file.clone(),
            detail: e.to_string(),
        },
        _ => LogError::Io {
            file: file.clone(),
            source: e,
        },
    })?;
    if raw.data_messages == 0 {
        let detail = if completeness.is_incomplete() {
            "it ends before its data section: it was cut off while being written or copied"
        } else {
            "it holds no logged data"
        };
        return Err(LogError::Corrupt {
            file,
            detail: detail.to_owned(),
        });
    }
    let mut notes = Vec::new();
    match completeness {
        Completeness::Complete => {}
        Completeness::Truncated => notes.push(
            "the log ends partway through a record (cut off, e.g. by a power loss): what came before is used"
                .to_owned(),
        ),
        Completeness::MalformedRecord(why) => notes.push(format!(
            "the log has a corrupt record ({}): what came before it is used",
            why.chars().take(120).collect::<String>()
        )),
    }
    if !raw.changed.is_empty() {
        raw.changed.sort();
        raw.changed.dedup();
        notes.push(format!(
            "the calibration changed during the log ({}): the values at its start are used",
            raw.changed.join(", ")
        ));
    }
    assemble(file, raw, notes)
}

/// ULog's first bytes: `ULog`, then 0x01 0x12 0x35.
const MAGIC: [u8; 7] = *b"ULog\x01\x12\x35";

/// Refuses a file that cannot be opened, is empty or does not start with ULog's magic bytes.
fn check_magic(path: &Path, file: &str) -> Result<(), LogError> {
    use std::io::Read;
    let io = |source| LogError::Io {
        file: file.to_owned(),
        source,
    };
    let mut head = Vec::with_capacity(16);
    std::fs::File::open(path)
        .map_err(io)?
        .take(16)
        .read_to_end(&mut head)
        .map_err(io)?;
    let detail = if head.is_empty() {
        "the file is empty"
    } else if !head.starts_with(&MAGIC) {
        "it does not start with ULog's magic bytes"
    } else if head.len() < 16 {
        "it ends inside its 16-byte header"
    } else {
        return Ok(());
    };
    Err(LogError::Corrupt {
        file: file.to_owned(),
        detail: detail.to_owned(),
    })
}

/// A column by name, if the topic has it.
fn column<'a>(c: &'a Columns, name: &str) -> Option<&'a [f64]> {
    c.get(name).map(Vec::as_slice)
}

/// The time of each sample: `timestamp_sample` where logged, else `timestamp`.
fn times(c: &Columns) -> Vec<u64> {
    let t = column(c, "timestamp_sample")
        .filter(|t| t.iter().all(|v| *v > 0.0))
        .or_else(|| column(c, "timestamp"))
        .unwrap_or(&[]);
    t.iter().map(|v| *v as u64).collect()
}

/// Makes sense of what the parser delivered.
fn assemble(file: String, raw: Raw, notes: Vec<String>) -> Result<FlightLog, LogError> {
    let mags = magnetometers(&raw);
    if mags.is_empty() {
        return Err(LogError::NoMagnetometer { file });
    }
    let attitude = attitude(&raw);
    if attitude.is_empty() {
        return Err(LogError::NoAttitude { file });
    }
    let current_a = raw
        .topics
        .get(&("battery_status".to_owned(), 0))
        .and_then(|c| {
            let mut s = Series::default();
            for (t, i) in times(c).into_iter().zip(column(c, "current_a")?) {
                // PX4 logs −1 where no current is measured.
                if i.is_finite() && *i >= 0.0 {
                    s.push(t, *i);
                }
            }
            (!s.is_empty()).then_some(s)
        });
    Ok(FlightLog {
        file,
        hardware: raw.hardware.clone(),
        mags,
        attitude,
        current_a,
        gps: gps(&raw),
        params: raw.params,
        notes,
    })
}

/// Every magnetometer stream, each with its logged calibration.
fn magnetometers(raw: &Raw) -> Vec<MagStream> {
    let slots = LoggedCalibration::all(&raw.params);
    let mut mags = Vec::new();
    for (topic, fields, calibrated) in [
        ("sensor_mag", ["x", "y", "z"], false),
        (
            "vehicle_magnetometer",
            [
                "magnetometer_ga[0]",
                "magnetometer_ga[1]",
                "magnetometer_ga[2]",
            ],
            true,
        ),
    ] {
        for ((name, instance), c) in &raw.topics {
            if name != topic {
                continue;
            }
            let (Some(x), Some(y), Some(z)) = (
                column(c, fields[0]),
                column(c, fields[1]),
                column(c, fields[2]),
            ) else {
                continue;
            };
            let device_id = column(c, "device_id")
                .and_then(|d| d.iter().rev().find(|v| **v != 0.0))
                .map(|v| *v as u32);
            let mut field_g = Series::default();
            let mut temps = Vec::new();
            let temp = column(c, "temperature");
            for (i, t) in times(c).into_iter().enumerate() {
                let v = [x[i], y[i], z[i]];
                if v.iter().all(|v| v.is_finite()) && field_g.t_us.last().is_none_or(|l| t >= *l) {
                    field_g.push(t, v);
                    temps.push(temp.map_or(f64::NAN, |c| c[i]));
                }
            }
            if field_g.is_empty() {
                continue;
            }
            // Without a device id (old logs' vehicle_magnetometer), the only slot enabled is the one applied.
            let calibration = match device_id {
                Some(id) => slots.iter().find(|s| s.device_id == id).cloned(),
                None => {
                    let enabled: Vec<_> = slots.iter().filter(|s| s.enabled).collect();
                    (enabled.len() == 1).then(|| enabled[0].clone())
                }
            };
            mags.push(MagStream {
                instance: *instance,
                topic,
                device_id: device_id.or(calibration.as_ref().map(|c| c.device_id)),
                calibrated,
                field_g,
                temp_c: temp.is_some().then_some(temps),
                calibration,
                estimator_bias_g: None,
            });
        }
    }
    for i in 0..mags.len() {
        if mags[i].calibrated {
            // The estimator's bias is indexed as the raw streams are (the uORB instance of sensor_mag).
            let index = mags
                .iter()
                .find(|m| {
                    !m.calibrated && m.device_id.is_some() && m.device_id == mags[i].device_id
                })
                .map(|m| m.instance);
            mags[i].estimator_bias_g = index.and_then(|k| estimator_bias(raw, k));
        }
    }
    mags
}

/// The bias PX4's magnetometer bias estimator published for raw stream `k`, valid values only.
fn estimator_bias(raw: &Raw, k: u8) -> Option<Series<[f64; 3]>> {
    let c = raw
        .topics
        .get(&("magnetometer_bias_estimate".to_owned(), 0))?;
    let axis = |a: &str| column(c, &format!("bias_{a}[{k}]"));
    let (x, y, z, valid) = (
        axis("x")?,
        axis("y")?,
        axis("z")?,
        column(c, &format!("valid[{k}]"))?,
    );
    let mut s = Series::default();
    for (i, t) in times(c).into_iter().enumerate() {
        if valid[i] != 0.0 && [x[i], y[i], z[i]].iter().all(|v| v.is_finite()) {
            s.push(t, [x[i], y[i], z[i]]);
        }
    }
    (!s.is_empty()).then_some(s)
}

/// The attitude (body into NED), the valid unit quaternions only.
fn attitude(raw: &Raw) -> Series<[f64; 4]> {
    let mut s = Series::default();
    let Some(c) = raw.topics.get(&("vehicle_attitude".to_owned(), 0)) else {
        return s;
    };
    let q: Vec<&[f64]> = (0..4)
        .filter_map(|k| column(c, &format!("q[{k}]")))
        .collect();
    if q.len() != 4 {
        return s;
    }
    for (i, t) in times(c).into_iter().enumerate() {
        let v = [q[0][i], q[1][i], q[2][i], q[3][i]];
        let n = v.iter().map(|x| x * x).sum::<f64>().sqrt();
        if n.is_finite() && (n - 1.0).abs() < 0.01 {
            s.push(t, v.map(|x| x / n));
        }
    }
    s
}

/// Every GPS sample, from `vehicle_gps_position` or else `sensor_gps`, instance 0.
fn gps(raw: &Raw) -> Vec<GpsFix> {
    let c = ["vehicle_gps_position", "sensor_gps"]
        .iter()
        .find_map(|t| raw.topics.get(&((*t).to_owned(), 0)));
    let Some(c) = c else {
        return Vec::new();
    };
    let get = |name: &str, i: usize| column(c, name).map_or(f64::NAN, |v| v[i]);
    let n = column(c, "timestamp").map_or(0, <[f64]>::len);
    (0..n)
        .map(|i| {
            let (lat, lon, alt) = if column(c, "latitude_deg").is_some() {
                (
                    get("latitude_deg", i),
                    get("longitude_deg", i),
                    get("altitude_msl_m", i),
                )
            } else {
                (
                    get("lat", i) * 1e-7,
                    get("lon", i) * 1e-7,
                    get("alt", i) * 1e-3,
                )
            };
            GpsFix {
                t_us: get("timestamp", i) as u64,
                lat_deg: lat,
                lon_deg: lon,
                alt_m: alt,
                utc_us: get("time_utc_usec", i).max(0.0) as u64,
                fix_type: get("fix_type", i).max(0.0) as u8,
            }
        })
        .filter(|g| g.lat_deg.is_finite() && g.lon_deg.is_finite())
        .collect()
}
