//! ArduPilot DataFlash logs (`.bin`), read by their self-describing `FMT` messages: every message is `0xA3 0x95`,
//! a type byte and its fields, laid out as the `FMT` message of that type says (name, length, format characters,
//! column names). No crate reads these reliably and is kept up, so this is a small reader of the format. From it:
//! `MAG` (each compass, ArduPilot's calibration applied, body axes, mGauss), `ATT` (roll, pitch, yaw), `BAT` (the
//! current), `GPS` (fix, place, GPS week and milliseconds) and `PARM` (the `COMPASS_*` calibration).

use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use crate::calibration::LoggedCalibration;
use crate::series::Series;
use crate::{FlightLog, GpsFix, LogError, MagStream};

/// A message's first two bytes.
const HEAD: [u8; 2] = [0xA3, 0x95];
/// The type of `FMT` messages.
const FMT_TYPE: u8 = 128;
/// An `FMT` message's length: header, type, length, name (4), format (16), columns (64).
const FMT_LENGTH: usize = 89;

/// One message type as its `FMT` declares it.
#[derive(Debug, Clone)]
struct Format {
    name: String,
    length: usize,
    kinds: Vec<u8>,
    columns: Vec<String>,
}

/// A field's size in bytes, for a format character.
fn size(kind: u8) -> Option<usize> {
    Some(match kind {
        b'b' | b'B' | b'M' => 1,
        b'h' | b'H' | b'c' | b'C' => 2,
        b'i' | b'I' | b'f' | b'e' | b'E' | b'L' | b'n' => 4,
        b'd' | b'q' | b'Q' => 8,
        b'N' => 16,
        b'Z' | b'a' => 64,
        _ => return None,
    })
}

/// A field as a number (scaled: `c`, `C`, `e`, `E` by 0.01, `L` by 1e-7) or, for text, NaN.
fn number(kind: u8, b: &[u8]) -> f64 {
    let f = |n: usize| -> [u8; 8] {
        let mut a = [0u8; 8];
        a[..n].copy_from_slice(&b[..n]);
        a
    };
    match kind {
        b'b' => f64::from(b[0] as i8),
        b'B' | b'M' => f64::from(b[0]),
        b'h' => f64::from(i16::from_le_bytes([b[0], b[1]])),
        b'H' => f64::from(u16::from_le_bytes([b[0], b[1]])),
        b'c' => f64::from(i16::from_le_bytes([b[0], b[1]])) * 0.01,
        b'C' => f64::from(u16::from_le_bytes([b[0], b[1]])) * 0.01,
        b'i' => f64::from(i32::from_le_bytes([b[0], b[1], b[2], b[3]])),
        b'I' => f64::from(u32::from_le_bytes([b[0], b[1], b[2], b[3]])),
        b'e' => f64::from(i32::from_le_bytes([b[0], b[1], b[2], b[3]])) * 0.01,
        b'E' => f64::from(u32::from_le_bytes([b[0], b[1], b[2], b[3]])) * 0.01,
        b'L' => f64::from(i32::from_le_bytes([b[0], b[1], b[2], b[3]])) * 1e-7,
        b'f' => f64::from(f32::from_le_bytes([b[0], b[1], b[2], b[3]])),
        b'd' => f64::from_le_bytes(f(8)),
        b'q' => i64::from_le_bytes(f(8)) as f64,
        b'Q' => u64::from_le_bytes(f(8)) as f64,
        _ => f64::NAN,
    }
}

/// Text of a `n`, `N` or `Z` field, up to its first NUL.
fn text(b: &[u8]) -> String {
    let end = b.iter().position(|c| *c == 0).unwrap_or(b.len());
    String::from_utf8_lossy(&b[..end]).trim().to_owned()
}

/// An `FMT` message's body (after the header and type), if it declares a format magcal can lay out.
fn parse_fmt(body: &[u8]) -> Option<(u8, Format)> {
    let (kind, length) = (body[0], usize::from(body[1]));
    let name = text(&body[2..6]);
    let kinds: Vec<u8> = body[6..22]
        .iter()
        .copied()
        .take_while(|c| *c != 0)
        .collect();
    let columns: Vec<String> = text(&body[22..86]).split(',').map(str::to_owned).collect();
    let total: usize = kinds.iter().map(|k| size(*k)).sum::<Option<usize>>()?;
    (total + 3 == length && columns.len() == kinds.len()).then_some((
        kind,
        Format {
            name,
            length,
            kinds,
            columns,
        },
    ))
}

/// The messages of a log, as columns by name (the wanted ones), and the parameters.
#[derive(Default)]
struct Columns {
    tables: BTreeMap<String, BTreeMap<String, Vec<f64>>>,
    params: BTreeMap<String, f64>,
    messages: usize,
    skipped: usize,
}

/// The message types read, and the parameters' type.
const WANTED: [&str; 5] = ["MAG", "ATT", "BAT", "GPS", "CURR"];

impl Columns {
    fn add(&mut self, format: &Format, body: &[u8]) {
        self.messages += 1;
        let mut at = 0;
        let mut fields = Vec::with_capacity(format.kinds.len());
        for kind in &format.kinds {
            let n = size(*kind).unwrap_or(0);
            fields.push(&body[at..at + n]);
            at += n;
        }
        if format.name == "PARM" {
            let name = format.columns.iter().position(|c| c == "Name");
            let value = format.columns.iter().position(|c| c == "Value");
            if let (Some(n), Some(v)) = (name, value) {
                self.params
                    .entry(text(fields[n]))
                    .or_insert(number(format.kinds[v], fields[v]));
            }
            return;
        }
        if !WANTED.contains(&format.name.as_str()) {
            return;
        }
        let table = self.tables.entry(format.name.clone()).or_default();
        for ((column, kind), field) in format.columns.iter().zip(&format.kinds).zip(fields) {
            table
                .entry(column.clone())
                .or_default()
                .push(number(*kind, field));
        }
    }
}

/// Reads the messages of a DataFlash log: formats first met, then the messages they lay out; bytes that start no
/// known message are skipped (counted) until the next `0xA3 0x95`.
fn scan(bytes: &[u8]) -> (Columns, bool) {
    let mut formats: HashMap<u8, Format> = HashMap::new();
    let mut out = Columns::default();
    let mut at = 0;
    let mut cut = false;
    while at + 3 <= bytes.len() {
        if bytes[at..at + 2] != HEAD {
            out.skipped += 1;
            at += 1;
            continue;
        }
        let kind = bytes[at + 2];
        let length = if kind == FMT_TYPE {
            FMT_LENGTH
        } else {
            formats.get(&kind).map_or(0, |f| f.length)
        };
        if length == 0 {
            out.skipped += 1;
            at += 1;
            continue;
        }
        let Some(message) = bytes.get(at..at + length) else {
            cut = true;
            break;
        };
        if kind == FMT_TYPE {
            if let Some((k, f)) = parse_fmt(&message[3..]) {
                formats.insert(k, f);
            }
        } else {
            out.add(&formats[&kind], &message[3..]);
        }
        at += length;
    }
    (out, cut)
}

/// Reads an ArduPilot DataFlash log.
pub fn read(path: &Path) -> Result<FlightLog, LogError> {
    let file = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|source| LogError::Io {
        file: file.clone(),
        source,
    })?;
    let (columns, cut) = scan(&bytes);
    if columns.messages == 0 {
        let detail = if bytes.is_empty() {
            "the file is empty".to_owned()
        } else {
            format!(
                "no DataFlash message in its {} bytes (no FMT-declared 0xA3 0x95 message)",
                bytes.len()
            )
        };
        return Err(LogError::Corrupt { file, detail });
    }
    let mut notes = Vec::new();
    if cut {
        notes.push(
            "the log ends partway through a message (cut off): what came before is used".to_owned(),
        );
    }
    if columns.skipped > 0 {
        notes.push(format!(
            "{} bytes that start no message were skipped (damage)",
            columns.skipped
        ));
    }
    assemble(file, columns, notes)
}

/// A table's column.
fn col<'a>(c: &'a BTreeMap<String, Vec<f64>>, name: &str) -> Option<&'a [f64]> {
    c.get(name).map(Vec::as_slice)
}

/// The quaternion (body → NED) of roll, pitch, yaw in degrees (yaw applied last).
fn euler_quat(roll: f64, pitch: f64, yaw: f64) -> [f64; 4] {
    let (sr, cr) = (0.5 * roll.to_radians()).sin_cos();
    let (sp, cp) = (0.5 * pitch.to_radians()).sin_cos();
    let (sy, cy) = (0.5 * yaw.to_radians()).sin_cos();
    [
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    ]
}

/// GPS week and milliseconds of the week as UTC µs since 1970 (18 leap seconds, as since 2017).
fn gps_utc_us(week: f64, ms: f64) -> u64 {
    const GPS_EPOCH_S: f64 = 315_964_800.0;
    ((GPS_EPOCH_S + week * 604_800.0 + ms * 1e-3 - 18.0) * 1e6).max(0.0) as u64
}

/// Makes sense of the columns.
fn assemble(file: String, c: Columns, notes: Vec<String>) -> Result<FlightLog, LogError> {
    let empty = BTreeMap::new();
    let table = |name: &str| c.tables.get(name).unwrap_or(&empty);
    let mags = magnetometers(table("MAG"), &c.params);
    if mags.is_empty() {
        return Err(LogError::NoMagnetometer { file });
    }
    let att = table("ATT");
    let mut attitude = Series::default();
    if let (Some(t), Some(r), Some(p), Some(y)) = (
        col(att, "TimeUS"),
        col(att, "Roll"),
        col(att, "Pitch"),
        col(att, "Yaw"),
    ) {
        for i in 0..t.len() {
            attitude.push(t[i] as u64, euler_quat(r[i], p[i], y[i]));
        }
    }
    if attitude.is_empty() {
        return Err(LogError::NoAttitude { file });
    }
    let mut current = Series::default();
    for (name, inst) in [("BAT", "Inst"), ("CURR", "Inst")] {
        let b = table(name);
        if let (Some(t), Some(i)) = (col(b, "TimeUS"), col(b, "Curr")) {
            let instance = col(b, inst);
            for k in 0..t.len() {
                if instance.is_none_or(|n| n[k] == 0.0) && i[k].is_finite() {
                    current.push(t[k] as u64, i[k]);
                }
            }
        }
    }
    let g = table("GPS");
    let gps = match (
        col(g, "TimeUS"),
        col(g, "Status"),
        col(g, "Lat"),
        col(g, "Lng"),
    ) {
        (Some(t), Some(s), Some(lat), Some(lon)) => (0..t.len())
            .map(|i| GpsFix {
                t_us: t[i] as u64,
                lat_deg: lat[i],
                lon_deg: lon[i],
                alt_m: col(g, "Alt").map_or(0.0, |a| a[i]),
                utc_us: match (col(g, "GWk"), col(g, "GMS")) {
                    (Some(w), Some(ms)) if w[i] > 0.0 => gps_utc_us(w[i], ms[i]),
                    _ => 0,
                },
                fix_type: s[i] as u8,
            })
            .collect(),
        _ => Vec::new(),
    };
    Ok(FlightLog {
        file,
        hardware: None,
        mags,
        attitude,
        current_a: (!current.is_empty()).then_some(current),
        gps,
        params: c.params,
        notes,
    })
}

/// Every compass of the `MAG` messages (instance column `I`), each with its `COMPASS_*` calibration.
fn magnetometers(m: &BTreeMap<String, Vec<f64>>, params: &BTreeMap<String, f64>) -> Vec<MagStream> {
    let (Some(t), Some(x), Some(y), Some(z)) = (
        col(m, "TimeUS"),
        col(m, "MagX"),
        col(m, "MagY"),
        col(m, "MagZ"),
    ) else {
        return Vec::new();
    };
    let instance = col(m, "I");
    let mut by_instance: BTreeMap<u8, Series<[f64; 3]>> = BTreeMap::new();
    for i in 0..t.len() {
        let n = instance.map_or(0, |v| v[i] as u8);
        // mGauss to gauss, as PX4's topics are.
        by_instance
            .entry(n)
            .or_default()
            .push(t[i] as u64, [x[i], y[i], z[i]].map(|v| v * 1e-3));
    }
    by_instance
        .into_iter()
        .map(|(n, field_g)| MagStream {
            instance: n,
            topic: "MAG",
            device_id: LoggedCalibration::ardupilot_device_id(params, n),
            calibrated: true,
            field_g,
            temp_c: None,
            calibration: LoggedCalibration::from_ardupilot(params, n),
            estimator_bias_g: None,
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gps_time_and_euler_angles() {
        // GPS week 2369 began on Sunday 2025-06-01 00:00:18 UTC (18 leap seconds).
        let utc = gps_utc_us(2369.0, 18_000.0);
        assert_eq!(
            crate::recording::utc_date(utc)
                .map(|d| d.to_string())
                .as_deref(),
            Some("2025-06-01")
        );
        let q = euler_quat(0.0, 0.0, 90.0);
        assert!(
            (q[0] - 0.5f64.sqrt()).abs() < 1e-12 && (q[3] - 0.5f64.sqrt()).abs() < 1e-12,
            "{q:?}"
        );
    }

    #[test]
    fn arbitrary_bytes_with_message_heads_never_panic() {
        let mut state = 0x9E37_79B9_7F4A_7C15u64;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        for _ in 0..200 {
            let n = (next() % 4000) as usize;
            let mut bytes: Vec<u8> = (0..n).map(|_| next() as u8).collect();
            for _ in 0..n / 20 {
                let at = (next() as usize) % n.max(1);
                if at + 3 < n {
                    bytes[at..at + 3].copy_from_slice(&[
                        0xA3,
                        0x95,
                        if next() % 2 == 0 { 128 } else { 64 },
                    ]);
                }
            }
            let _ = scan(&bytes);
        }
    }
}
