//! A simulated flight written as an ArduPilot DataFlash log (`.bin`): self-describing `FMT` messages, then `PARM`
//! (the `COMPASS_*` calibration the simulated autopilot holds), `MAG` (the compass field with that calibration
//! applied, as ArduPilot logs it: mGauss, body axes), `ATT` (roll, pitch, yaw), `BAT` (the current) and `GPS` (a
//! fix, GPS week and milliseconds), from a simulated [`Recording`] whose sensor axes are the body's. Written from the
//! format's description, to test readers on files whose truth is known.

use std::io::{self, Write};

use magcal_recording::Recording;

/// The `COMPASS_*` calibration of compass 0 (ArduPilot applies `M·(raw + OFS)`, mGauss, `M` symmetric from the
/// diagonals and off-diagonals).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DataflashCompass {
    /// `COMPASS_OFS_X/Y/Z`, mGauss.
    pub ofs_mgauss: [f64; 3],
    /// `COMPASS_DIA_X/Y/Z`.
    pub dia: [f64; 3],
    /// `COMPASS_ODI_X/Y/Z`.
    pub odi: [f64; 3],
}

impl DataflashCompass {
    /// No calibration.
    pub const NONE: DataflashCompass = DataflashCompass {
        ofs_mgauss: [0.0; 3],
        dia: [1.0; 3],
        odi: [0.0; 3],
    };

    /// `M·(raw + OFS)`, mGauss.
    pub fn apply(&self, raw_mgauss: [f64; 3]) -> [f64; 3] {
        let v: [f64; 3] = std::array::from_fn(|k| raw_mgauss[k] + self.ofs_mgauss[k]);
        let (d, o) = (self.dia, self.odi);
        [
            d[0] * v[0] + o[0] * v[1] + o[1] * v[2],
            o[0] * v[0] + d[1] * v[1] + o[2] * v[2],
            o[1] * v[0] + o[2] * v[1] + d[2] * v[2],
        ]
    }
}

/// What the simulated log holds besides the recording's rows.
#[derive(Clone, Debug, PartialEq)]
pub struct DataflashSetup {
    /// The compass calibration in the parameters, applied to what `MAG` logs.
    pub compass: DataflashCompass,
    /// The GPS fix: latitude, longitude (degrees), altitude (m).
    pub location: [f64; 3],
    /// GPS week and milliseconds of the week at the recording's t = 0.
    pub gps_week_ms: (u16, u32),
    /// Write `MAG`.
    pub mag: bool,
    /// Write `ATT`.
    pub attitude: bool,
}

impl Default for DataflashSetup {
    /// No calibration, a fix at Zurich on 2025-06-01 (GPS week 2369), every message.
    fn default() -> DataflashSetup {
        DataflashSetup {
            compass: DataflashCompass::NONE,
            location: [47.3566, 8.5189, 430.0],
            gps_week_ms: (2369, 18_000),
            mag: true,
            attitude: true,
        }
    }
}

/// The messages written: type, name, format characters, columns.
const FORMATS: [(u8, &str, &str, &str); 6] = [
    (128, "FMT", "BBnNZ", "Type,Length,Name,Format,Columns"),
    (64, "PARM", "QNf", "TimeUS,Name,Value"),
    (
        65,
        "MAG",
        "QBhhhhhh",
        "TimeUS,I,MagX,MagY,MagZ,OfsX,OfsY,OfsZ",
    ),
    (66, "ATT", "QccC", "TimeUS,Roll,Pitch,Yaw"),
    (67, "BAT", "QBf", "TimeUS,Inst,Curr"),
    (68, "GPS", "QBBIHLLf", "TimeUS,I,Status,GMS,GWk,Lat,Lng,Alt"),
];

/// A fixed-width text field.
fn padded(text: &str, n: usize) -> Vec<u8> {
    let mut b = text.as_bytes().to_vec();
    b.resize(n, 0);
    b
}

/// One message: header, type, body.
fn message(w: &mut impl Write, kind: u8, body: &[u8]) -> io::Result<()> {
    w.write_all(&[0xA3, 0x95, kind])?;
    w.write_all(body)
}

/// The body length of a format.
fn body_length(format: &str) -> usize {
    format
        .bytes()
        .map(|c| match c {
            b'B' => 1,
            b'h' | b'c' | b'C' | b'H' => 2,
            b'f' | b'I' | b'L' | b'n' => 4,
            b'Q' => 8,
            b'N' => 16,
            _ => 64,
        })
        .sum()
}

/// Roll, pitch, yaw (degrees, yaw 0–360) of a quaternion (body → NED).
fn euler_deg(q: [f64; 4]) -> [f64; 3] {
    let [w, x, y, z] = q;
    let roll = (2.0 * (w * x + y * z)).atan2(1.0 - 2.0 * (x * x + y * y));
    let pitch = (2.0 * (w * y - z * x)).clamp(-1.0, 1.0).asin();
    let yaw = (2.0 * (w * z + x * y)).atan2(1.0 - 2.0 * (y * y + z * z));
    [
        roll.to_degrees(),
        pitch.to_degrees(),
        yaw.to_degrees().rem_euclid(360.0),
    ]
}

/// The definitions and the parameters.
fn header(w: &mut impl Write, setup: &DataflashSetup) -> io::Result<()> {
    for (kind, name, format, columns) in FORMATS {
        let mut b = vec![kind, (3 + body_length(format)) as u8];
        b.extend(padded(name, 4));
        b.extend(padded(format, 16));
        b.extend(padded(columns, 64));
        message(w, 128, &b)?;
    }
    let c = &setup.compass;
    let mut params = vec![
        ("COMPASS_MOTCT".to_owned(), 0.0),
        ("COMPASS_USE".to_owned(), 1.0),
    ];
    for (k, axis) in ["X", "Y", "Z"].iter().enumerate() {
        params.push((format!("COMPASS_OFS_{axis}"), c.ofs_mgauss[k]));
        params.push((format!("COMPASS_DIA_{axis}"), c.dia[k]));
        params.push((format!("COMPASS_ODI_{axis}"), c.odi[k]));
    }
    for (name, value) in params {
        let mut b = 0u64.to_le_bytes().to_vec();
        b.extend(padded(&name, 16));
        b.extend((value as f32).to_le_bytes());
        message(w, 64, &b)?;
    }
    Ok(())
}

/// Writes `rec` (time, raw field in µT in body axes, quaternions body → NED, its first current channel as the
/// battery's) as an ArduPilot DataFlash log with `setup`; the field is logged in whole mGauss, the attitude in
/// centidegrees, as ArduPilot does.
pub fn write_dataflash(
    rec: &Recording,
    setup: &DataflashSetup,
    w: &mut impl Write,
) -> io::Result<()> {
    let t = rec
        .t_s
        .as_ref()
        .ok_or_else(|| io::Error::other("a DataFlash log needs the recording's time (t column)"))?;
    header(w, setup)?;
    let mut next_gps_s = 0.0;
    for i in 0..rec.len() {
        let t_us = 1_000_000 + (t[i] * 1e6).round() as u64;
        let mut b = t_us.to_le_bytes().to_vec();
        if setup.mag {
            let field = setup.compass.apply(rec.mag_ut[i].map(|v| v * 10.0));
            b.push(0);
            for v in field.into_iter().chain(setup.compass.ofs_mgauss) {
                b.extend((v.round() as i16).to_le_bytes());
            }
            message(w, 65, &b)?;
        }
        if let (true, Some(q)) = (setup.attitude, rec.quat.as_ref().map(|q| q[i]))
            && q.iter().all(|v| v.is_finite())
        {
            let [roll, pitch, yaw] = euler_deg(q);
            let mut b = t_us.to_le_bytes().to_vec();
            b.extend(((roll * 100.0).round() as i16).to_le_bytes());
            b.extend(((pitch * 100.0).round() as i16).to_le_bytes());
            b.extend((((yaw * 100.0).round() as u32 % 36_000) as u16).to_le_bytes());
            message(w, 66, &b)?;
        }
        if let Some(current) = rec.currents.first().map(|c| c.values[i]) {
            let mut b = t_us.to_le_bytes().to_vec();
            b.push(0);
            b.extend((current as f32).to_le_bytes());
            message(w, 67, &b)?;
        }
        if t[i] >= next_gps_s {
            next_gps_s = t[i] + 0.2;
            let (week, ms0) = setup.gps_week_ms;
            let mut b = t_us.to_le_bytes().to_vec();
            b.extend([0, 3]);
            b.extend((ms0 + (t[i] * 1000.0).round() as u32).to_le_bytes());
            b.extend(week.to_le_bytes());
            for deg in [setup.location[0], setup.location[1]] {
                b.extend(((deg * 1e7).round() as i32).to_le_bytes());
            }
            b.extend((setup.location[2] as f32).to_le_bytes());
            message(w, 68, &b)?;
        }
    }
    Ok(())
}
