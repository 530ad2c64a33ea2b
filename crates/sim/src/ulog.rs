//! A simulated flight written as a PX4 ULog file: what PX4's logger writes for a calibration — the raw magnetometer
//! (`sensor_mag`, gauss, with a device id), optionally the calibrated one (`vehicle_magnetometer`, the slot applied),
//! the attitude (`vehicle_attitude`, body → NED), the battery current (`battery_status`), a GPS fix with the UTC
//! time (`vehicle_gps_position`) and the `CAL_MAG0_*` parameters — from a simulated [`Recording`], so that flight-log
//! readers are tested on files whose truth is known. The format is written from its specification (a header, then
//! length-prefixed messages: flag bits, formats, parameters, subscriptions and data, little-endian, packed).

use std::io::{self, Write};

use magcal_recording::Recording;

/// The calibration slot `CAL_MAG0_*` the simulated autopilot holds (sensor axes, gauss): PX4 applies
/// `S·(raw − offset)` with `S` symmetric (scales on the diagonal, `XODIAG` at (0,1), `YODIAG` at (0,2), `ZODIAG` at
/// (1,2)); the rotation is none (`CAL_MAG0_ROT` = 0, an external magnetometer).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UlogSlot {
    /// `CAL_MAG0_{X,Y,Z}OFF`, gauss.
    pub offset_g: [f64; 3],
    /// `CAL_MAG0_{X,Y,Z}SCALE`.
    pub scale: [f64; 3],
    /// `CAL_MAG0_{X,Y,Z}ODIAG`.
    pub offdiag: [f64; 3],
}

impl UlogSlot {
    /// No calibration: zero offsets, unit scales.
    pub const NONE: UlogSlot = UlogSlot {
        offset_g: [0.0; 3],
        scale: [1.0; 3],
        offdiag: [0.0; 3],
    };

    /// `S·(raw − offset)`, gauss.
    pub fn apply(&self, raw_g: [f64; 3]) -> [f64; 3] {
        let v: [f64; 3] = std::array::from_fn(|k| raw_g[k] - self.offset_g[k]);
        let (d, o) = (self.scale, self.offdiag);
        [
            d[0] * v[0] + o[0] * v[1] + o[1] * v[2],
            o[0] * v[0] + d[1] * v[1] + o[2] * v[2],
            o[1] * v[0] + o[2] * v[1] + d[2] * v[2],
        ]
    }
}

/// What the simulated log holds besides the recording's rows.
#[derive(Clone, Debug, PartialEq)]
pub struct UlogSetup {
    /// The magnetometer's device id (`sensor_mag.device_id`, `CAL_MAG0_ID`).
    pub device_id: u32,
    /// The calibration slot in the parameters.
    pub slot: UlogSlot,
    /// Where the GPS has its fix: latitude, longitude (degrees), altitude (m).
    pub location: [f64; 3],
    /// UTC at the recording's t = 0, µs since 1970.
    pub utc_start_us: u64,
    /// Write `sensor_mag` (the raw magnetometer).
    pub raw_mag: bool,
    /// Write `vehicle_magnetometer` (the slot applied).
    pub calibrated_mag: bool,
    /// Write `vehicle_attitude`.
    pub attitude: bool,
    /// Write `vehicle_gps_position` once a second, with a 3-D fix.
    pub gps: bool,
}

impl Default for UlogSetup {
    /// Device 396809 (an IST8310 on I2C), no calibration, a fix at Zurich on 2025-06-01, every topic.
    fn default() -> UlogSetup {
        UlogSetup {
            device_id: 396_809,
            slot: UlogSlot::NONE,
            location: [47.3566, 8.5189, 430.0],
            utc_start_us: 1_748_736_000_000_000,
            raw_mag: true,
            calibrated_mag: false,
            attitude: true,
            gps: true,
        }
    }
}

/// The autopilot's time at the recording's t = 0, µs (it booted a second earlier).
const BOOT_US: u64 = 1_000_000;

/// ULog's message formats, as PX4 declares them (the fields a calibration reads).
const FORMATS: [(&str, &str); 5] = [
    (
        "sensor_mag",
        "uint64_t timestamp;uint64_t timestamp_sample;uint32_t device_id;float x;float y;float z;float temperature;\
         uint32_t error_count;",
    ),
    (
        "vehicle_magnetometer",
        "uint64_t timestamp;uint64_t timestamp_sample;uint32_t device_id;float[3] magnetometer_ga;\
         uint8_t calibration_count;",
    ),
    (
        "vehicle_attitude",
        "uint64_t timestamp;uint64_t timestamp_sample;float[4] q;",
    ),
    (
        "battery_status",
        "uint64_t timestamp;float voltage_v;float current_a;",
    ),
    (
        "vehicle_gps_position",
        "uint64_t timestamp;uint64_t time_utc_usec;double latitude_deg;double longitude_deg;double altitude_msl_m;\
         uint8_t fix_type;",
    ),
];

/// One message: its size, its type, its bytes.
fn message(w: &mut impl Write, kind: u8, body: &[u8]) -> io::Result<()> {
    let size =
        u16::try_from(body.len()).map_err(|_| io::Error::other("a ULog message over 64 KiB"))?;
    w.write_all(&size.to_le_bytes())?;
    w.write_all(&[kind])?;
    w.write_all(body)
}

/// A `key_len, key, value` body (info and parameter messages).
fn keyed(key: &str, value: &[u8]) -> Vec<u8> {
    let mut b = vec![key.len() as u8];
    b.extend_from_slice(key.as_bytes());
    b.extend_from_slice(value);
    b
}

/// The definitions: header, flag bits, hardware, formats, parameters.
fn definitions(w: &mut impl Write, setup: &UlogSetup) -> io::Result<()> {
    w.write_all(b"ULog\x01\x12\x35")?;
    w.write_all(&[1])?;
    w.write_all(&0u64.to_le_bytes())?;
    message(w, b'B', &[0; 40])?;
    message(w, b'I', &keyed("char[9] ver_hw", b"MAGCALSIM"))?;
    for (name, fields) in FORMATS {
        message(w, b'F', format!("{name}:{fields}").as_bytes())?;
    }
    let s = &setup.slot;
    let id = i32::from_le_bytes(setup.device_id.to_le_bytes());
    let ints = [
        ("CAL_MAG0_ID", id),
        ("CAL_MAG0_ROT", 0),
        ("CAL_MAG0_PRIO", 75),
        ("SENS_BOARD_ROT", 0),
    ];
    for (name, value) in ints {
        message(
            w,
            b'P',
            &keyed(&format!("int32_t {name}"), &value.to_le_bytes()),
        )?;
    }
    for (k, axis) in ["X", "Y", "Z"].iter().enumerate() {
        for (kind, value) in [
            ("OFF", s.offset_g[k]),
            ("SCALE", s.scale[k]),
            ("ODIAG", s.offdiag[k]),
        ] {
            let key = format!("float CAL_MAG0_{axis}{kind}");
            message(w, b'P', &keyed(&key, &(value as f32).to_le_bytes()))?;
        }
    }
    Ok(())
}

/// A data message's body: the message id, then the fields.
struct Data(Vec<u8>);

impl Data {
    fn new(id: u16, t_us: u64) -> Data {
        let mut b = id.to_le_bytes().to_vec();
        b.extend_from_slice(&t_us.to_le_bytes());
        Data(b)
    }
    fn u64(mut self, v: u64) -> Data {
        self.0.extend_from_slice(&v.to_le_bytes());
        self
    }
    fn u32(mut self, v: u32) -> Data {
        self.0.extend_from_slice(&v.to_le_bytes());
        self
    }
    fn u8(mut self, v: u8) -> Data {
        self.0.push(v);
        self
    }
    fn f32s(mut self, v: &[f64]) -> Data {
        for x in v {
            self.0.extend_from_slice(&(*x as f32).to_le_bytes());
        }
        self
    }
    fn f64s(mut self, v: &[f64]) -> Data {
        for x in v {
            self.0.extend_from_slice(&x.to_le_bytes());
        }
        self
    }
}

/// Writes `rec` (time, raw field in µT, quaternions sensor → NED, its first current channel as the battery's, its
/// temperature) as a PX4 ULog with `setup`. Rows without a quaternion get no attitude message.
pub fn write_ulog(rec: &Recording, setup: &UlogSetup, w: &mut impl Write) -> io::Result<()> {
    let t = rec
        .t_s
        .as_ref()
        .ok_or_else(|| io::Error::other("a ULog needs the recording's time (t column)"))?;
    definitions(w, setup)?;
    let wanted = [
        setup.raw_mag,
        setup.calibrated_mag,
        setup.attitude,
        !rec.currents.is_empty(),
        setup.gps,
    ];
    for (id, (name, _)) in FORMATS.iter().enumerate().filter(|(i, _)| wanted[*i]) {
        let mut b = vec![0u8];
        b.extend_from_slice(&(id as u16).to_le_bytes());
        b.extend_from_slice(name.as_bytes());
        message(w, b'A', &b)?;
    }
    let mut next_gps_s = 0.0;
    for i in 0..rec.len() {
        let t_us = BOOT_US + (t[i] * 1e6).round() as u64;
        let raw_g = rec.mag_ut[i].map(|v| v / 100.0);
        if setup.raw_mag {
            let temp = rec.temp_c.as_ref().map_or(f64::NAN, |c| c[i]);
            let d = Data::new(0, t_us)
                .u64(t_us)
                .u32(setup.device_id)
                .f32s(&raw_g)
                .f32s(&[temp])
                .u32(0);
            message(w, b'D', &d.0)?;
        }
        if setup.calibrated_mag {
            let d = Data::new(1, t_us)
                .u64(t_us)
                .u32(setup.device_id)
                .f32s(&setup.slot.apply(raw_g))
                .u8(1);
            message(w, b'D', &d.0)?;
        }
        if let (true, Some(q)) = (setup.attitude, rec.quat.as_ref().map(|q| q[i]))
            && q.iter().all(|v| v.is_finite())
        {
            message(w, b'D', &Data::new(2, t_us).u64(t_us).f32s(&q).0)?;
        }
        if let Some(current) = rec.currents.first().map(|c| c.values[i]) {
            message(w, b'D', &Data::new(3, t_us).f32s(&[16.0, current]).0)?;
        }
        if setup.gps && t[i] >= next_gps_s {
            next_gps_s = t[i] + 1.0;
            let utc = setup.utc_start_us + (t[i] * 1e6).round() as u64;
            let d = Data::new(4, t_us).u64(utc).f64s(&setup.location).u8(3);
            message(w, b'D', &d.0)?;
        }
    }
    Ok(())
}
