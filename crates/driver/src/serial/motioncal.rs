//! Lines printed by MotionCal-compatible firmware.
//!
//! PJRC's MotionCal reads `Raw:ax,ay,az,gx,gy,gz,mx,my,mz` lines of integers. Its scale factors
//! (`imuread.h`: `G_PER_COUNT`, `DEG_PER_SEC_PER_COUNT`, `UT_PER_COUNT`; used in `rawdata.c`)
//! fix the units, and Adafruit's calibration sketches print accordingly
//! (`int(accel_m_s2 * 8192 / 9.8)`, `int(gyro_rad_s * SENSORS_RADS_TO_DPS * 16)`,
//! `int(mag_ut * 10)`):
//!
//! | fields | count | unit |
//! |---|---|---|
//! | `ax,ay,az` | 1/8192 g | [`ACCEL_G_PER_COUNT`] |
//! | `gx,gy,gz` | 1/16 °/s | [`GYRO_DPS_PER_COUNT`] |
//! | `mx,my,mz` | 0.1 µT | [`MAG_UT_PER_COUNT`] |
//!
//! After receiving a calibration packet (see [`packet`](super::packet)) the same firmware prints
//! what it holds, which MotionCal compares with what it sent:
//!
//! - `Cal1:` 10 values — accelerometer zero-g offsets (3), gyro zero-rate offsets (3), hard-iron
//!   offsets (3, µT), field magnitude (µT); Adafruit's sketches print them with 3 decimals.
//! - `Cal2:` 9 values — the soft-iron matrix, row-major; printed with 4 decimals.
//!
//! MotionCal keeps the counts as `int16_t`; this parser accepts any `i32` so that sketches for
//! ±16 g accelerometers, whose counts overflow 16 bits, still stream.

use super::counts::GarbageKind;
use super::sample::Sample;

/// Accelerometer scale of `Raw:` lines (g per count), MotionCal's `G_PER_COUNT`.
pub const ACCEL_G_PER_COUNT: f64 = 1.0 / 8192.0;
/// Gyro scale of `Raw:` lines (°/s per count), MotionCal's `DEG_PER_SEC_PER_COUNT`.
pub const GYRO_DPS_PER_COUNT: f64 = 1.0 / 16.0;
/// Magnetometer scale of `Raw:` lines (µT per count), MotionCal's `UT_PER_COUNT`.
pub const MAG_UT_PER_COUNT: f64 = 0.1;

const RAW_PREFIX: &str = "Raw:";
const CAL1_PREFIX: &str = "Cal1:";
const CAL2_PREFIX: &str = "Cal2:";

/// Number of values on a `Cal1:` line.
pub const CAL1_LEN: usize = 10;
/// Number of values on a `Cal2:` line.
pub const CAL2_LEN: usize = 9;

/// The integers of one `Raw:` line, in the line's order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RawCounts {
    /// `ax,ay,az` (1/8192 g).
    pub accel: [i32; 3],
    /// `gx,gy,gz` (1/16 °/s).
    pub gyro: [i32; 3],
    /// `mx,my,mz` (0.1 µT).
    pub mag: [i32; 3],
}

fn scale(counts: [i32; 3], unit: f64) -> [f64; 3] {
    counts.map(|c| f64::from(c) * unit)
}

impl RawCounts {
    /// Specific force (g).
    pub fn accel_g(&self) -> [f64; 3] {
        scale(self.accel, ACCEL_G_PER_COUNT)
    }

    /// Angular rate (°/s).
    pub fn gyro_dps(&self) -> [f64; 3] {
        scale(self.gyro, GYRO_DPS_PER_COUNT)
    }

    /// Angular rate (rad/s).
    pub fn gyro_rad_s(&self) -> [f64; 3] {
        scale(self.gyro, GYRO_DPS_PER_COUNT.to_radians())
    }

    /// Magnetic field (µT).
    pub fn mag_ut(&self) -> [f64; 3] {
        scale(self.mag, MAG_UT_PER_COUNT)
    }

    /// The line as a [`Sample`] (field, specific force, angular rate).
    pub fn to_sample(&self) -> Sample {
        Sample {
            accel_g: Some(self.accel_g()),
            gyro_rad_s: Some(self.gyro_rad_s()),
            ..Sample::mag_only(self.mag_ut())
        }
    }
}

/// A decimal number as the firmware printed it, with the resolution of its last digit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PrintedValue {
    /// The value.
    pub value: f64,
    /// One unit of the last printed digit: `0.001` for `-3.350`, `1` for `45`, `1e-5` for `1.5e-4`.
    /// A correctly rounded print is within half of this of the true value.
    pub resolution: f64,
}

impl Default for PrintedValue {
    /// Zero, printed as an integer.
    fn default() -> Self {
        PrintedValue {
            value: 0.0,
            resolution: 1.0,
        }
    }
}

impl PrintedValue {
    /// Parses a decimal number (optional sign, digits, optional fraction and exponent).
    /// `nan`, `inf` and Arduino's `ovf` are not numbers here.
    pub fn parse(text: &str) -> Option<PrintedValue> {
        let text = text.trim();
        let (mantissa, exponent) = match text.find(['e', 'E']) {
            Some(at) => (&text[..at], text[at + 1..].parse::<i32>().ok()?),
            None => (text, 0),
        };
        let digits = mantissa.strip_prefix(['+', '-']).unwrap_or(mantissa);
        let (int_part, frac_part) = digits.split_once('.').unwrap_or((digits, ""));
        let all_digits = |s: &str| s.bytes().all(|b| b.is_ascii_digit());
        if int_part.len() + frac_part.len() == 0 || !all_digits(int_part) || !all_digits(frac_part)
        {
            return None;
        }
        let value: f64 = text.parse().ok()?;
        if !value.is_finite() {
            return None;
        }
        let decimals = i32::try_from(frac_part.len()).ok()?;
        Some(PrintedValue {
            value,
            resolution: 10f64.powi(exponent - decimals),
        })
    }
}

/// Which calibration echo a line is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum EchoKind {
    /// `Cal1:` offsets and field magnitude.
    Cal1,
    /// `Cal2:` soft-iron matrix.
    Cal2,
}

impl EchoKind {
    /// The line prefix, `Cal1:` or `Cal2:`.
    pub fn prefix(self) -> &'static str {
        match self {
            EchoKind::Cal1 => CAL1_PREFIX,
            EchoKind::Cal2 => CAL2_PREFIX,
        }
    }

    /// 0 for `Cal1`, 1 for `Cal2`: an index for per-kind state.
    pub(crate) fn index(self) -> usize {
        match self {
            EchoKind::Cal1 => 0,
            EchoKind::Cal2 => 1,
        }
    }

    /// The echo kind a line claims to be by its prefix, well-formed or not.
    pub fn of_line(line: &str) -> Option<EchoKind> {
        [EchoKind::Cal1, EchoKind::Cal2]
            .into_iter()
            .find(|kind| line.starts_with(kind.prefix()))
    }
}

/// A well-formed calibration echo.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Echo {
    /// `Cal1:` accel offsets (3), gyro offsets (3), hard iron (3, µT), field (µT).
    Cal1([PrintedValue; CAL1_LEN]),
    /// `Cal2:` soft-iron matrix, row-major.
    Cal2([PrintedValue; CAL2_LEN]),
}

impl Echo {
    /// `Cal1` or `Cal2`.
    pub fn kind(&self) -> EchoKind {
        match self {
            Echo::Cal1(_) => EchoKind::Cal1,
            Echo::Cal2(_) => EchoKind::Cal2,
        }
    }

    /// The printed values, in line order.
    pub fn values(&self) -> &[PrintedValue] {
        match self {
            Echo::Cal1(values) => values,
            Echo::Cal2(values) => values,
        }
    }
}

/// A line MotionCal understands.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum MotionCalLine {
    /// A `Raw:` sensor line.
    Raw(RawCounts),
    /// A `Cal1:` or `Cal2:` calibration echo.
    Echo(Echo),
}

/// Splits `body` at commas into exactly `N` fields parsed by `parse`; the field count is checked
/// first.
fn fields<T: Copy + Default, const N: usize>(
    body: &str,
    parse: impl Fn(&str) -> Option<T>,
) -> Result<[T; N], GarbageKind> {
    if body.split(',').count() != N {
        return Err(GarbageKind::FieldCount);
    }
    let mut out = [T::default(); N];
    for (slot, field) in out.iter_mut().zip(body.split(',')) {
        *slot = parse(field).ok_or(GarbageKind::BadNumber)?;
    }
    Ok(out)
}

/// Parses one line (without its terminator). A line that is none of `Raw:`, `Cal1:`, `Cal2:` is
/// [`GarbageKind::Unrecognized`]; a known prefix with the wrong number of fields is
/// [`GarbageKind::FieldCount`]; a field that is not a number is [`GarbageKind::BadNumber`]
/// (a wrong count wins over a bad field, so two lines run together count as a field-count error).
pub fn parse_line(line: &str) -> Result<MotionCalLine, GarbageKind> {
    if let Some((_, echo)) = parse_echo(line) {
        return echo.map(MotionCalLine::Echo);
    }
    let body = line
        .strip_prefix(RAW_PREFIX)
        .ok_or(GarbageKind::Unrecognized)?;
    let v: [i32; 9] = fields(body, |f| f.trim().parse().ok())?;
    Ok(MotionCalLine::Raw(RawCounts {
        accel: [v[0], v[1], v[2]],
        gyro: [v[3], v[4], v[5]],
        mag: [v[6], v[7], v[8]],
    }))
}

/// Parses a line that starts with `Cal1:` or `Cal2:`; `None` for any other line. The kind comes
/// with the result, so a garbled echo is still known for what it claims to be.
pub fn parse_echo(line: &str) -> Option<(EchoKind, Result<Echo, GarbageKind>)> {
    let kind = EchoKind::of_line(line)?;
    let body = &line[kind.prefix().len()..];
    let echo = match kind {
        EchoKind::Cal1 => fields(body, PrintedValue::parse).map(Echo::Cal1),
        EchoKind::Cal2 => fields(body, PrintedValue::parse).map(Echo::Cal2),
    };
    Some((kind, echo))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn raw(line: &str) -> RawCounts {
        match parse_line(line) {
            Ok(MotionCalLine::Raw(counts)) => counts,
            other => panic!("{line:?} gave {other:?}"),
        }
    }

    #[test]
    fn raw_line_units() {
        let r = raw("Raw:8192,-4096,0,16,-32,0,123,-456,7");
        assert_eq!(r.accel_g(), [1.0, -0.5, 0.0]);
        assert_eq!(r.gyro_dps(), [1.0, -2.0, 0.0]);
        assert!((r.gyro_rad_s()[0] - 1f64.to_radians()).abs() < 1e-15);
        let mag = r.mag_ut();
        assert!((mag[0] - 12.3).abs() < 1e-12 && (mag[1] + 45.6).abs() < 1e-12);
        let s = r.to_sample();
        assert_eq!(s.mag_ut, mag);
        assert_eq!(s.accel_g, Some([1.0, -0.5, 0.0]));
        assert_eq!(s.t_s, None);
        assert!(s.inputs.is_empty());
    }

    #[test]
    fn raw_counts_beyond_int16_are_kept() {
        assert_eq!(raw("Raw:40000,0,0,0,0,0,1,2,3").accel[0], 40000);
    }

    #[test]
    fn malformed_lines_are_classified() {
        let cases = [
            ("Raw:1,2,3,4", GarbageKind::FieldCount),
            ("Raw:1,2,3,4,5,6,7,8,9,10", GarbageKind::FieldCount),
            ("Raw:1,2,3Raw:1,2,3,4,5,6,7,8,9", GarbageKind::FieldCount),
            ("Raw:1,2,3,4,5,6,7,8,x", GarbageKind::BadNumber),
            ("Raw:1,2,3,4,5,6,7,8,", GarbageKind::BadNumber),
            ("Raw:1.5,2,3,4,5,6,7,8,9", GarbageKind::BadNumber),
            ("Raw:99999999999,2,3,4,5,6,7,8,9", GarbageKind::BadNumber),
            (
                "Uni:0.01,0.02,9.81,0.0000,0.0000,0.0000,12.30,-45.60,0.70",
                GarbageKind::Unrecognized,
            ),
            ("4,5,6,7,8,9", GarbageKind::Unrecognized),
            ("Wrote calibration", GarbageKind::Unrecognized),
            ("Cal1:0.000,0.000", GarbageKind::FieldCount),
            ("Cal2:1,0,0,0,1,0,0,0,nan", GarbageKind::BadNumber),
            ("Cal2:1,0,0,0,1,0,0,0,ovf", GarbageKind::BadNumber),
        ];
        for (line, kind) in cases {
            assert_eq!(parse_line(line), Err(kind), "{line:?}");
        }
    }

    #[test]
    fn echoes_keep_their_printed_resolution() {
        let line = "Cal1:0.000,0.000,0.000,0.050,-0.010,-0.010,-3.350,-0.740,-40.790,45.000";
        let Ok(MotionCalLine::Echo(echo)) = parse_line(line) else {
            panic!("not an echo");
        };
        assert_eq!(echo.kind(), EchoKind::Cal1);
        assert_eq!(echo.values()[6].value, -3.35);
        assert!((echo.values()[6].resolution - 1e-3).abs() < 1e-18);
        let line = "Cal2:0.9650,0.0180,0.0100,0.0180,0.9600,0.0030,0.0100,0.0030,1.0800";
        let Ok(MotionCalLine::Echo(Echo::Cal2(values))) = parse_line(line) else {
            panic!("not a Cal2 echo");
        };
        assert_eq!(values[8].value, 1.08);
        assert!((values[8].resolution - 1e-4).abs() < 1e-18);
    }

    #[test]
    fn printed_values() {
        let p = |s| PrintedValue::parse(s).map(|p| (p.value, p.resolution));
        assert_eq!(p("45"), Some((45.0, 1.0)));
        assert_eq!(p("-0.5"), Some((-0.5, 0.1)));
        assert_eq!(p("+.25"), Some((0.25, 0.01)));
        assert_eq!(p("2."), Some((2.0, 1.0)));
        let (v, r) = p("1.5e-4").unwrap();
        assert!((v - 1.5e-4).abs() < 1e-18 && (r - 1e-5).abs() < 1e-20);
        for bad in [
            "", "-", ".", "nan", "inf", "ovf", "1,0", "0x10", "1e", "--1", "1.2.3",
        ] {
            assert_eq!(p(bad), None, "{bad:?}");
        }
    }

    #[test]
    fn echo_kind_by_prefix() {
        assert_eq!(EchoKind::of_line("Cal1:garbled"), Some(EchoKind::Cal1));
        assert_eq!(EchoKind::of_line("Cal2:"), Some(EchoKind::Cal2));
        assert_eq!(EchoKind::of_line("Raw:1"), None);
    }
}
