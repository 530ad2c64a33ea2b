//! The largest magnitudes a recording holds, per kind of value. Beyond them a number is a mistake (a wrong unit, an
//! overflow, a corrupted field), not a measurement, and it would overflow the sums of squares the fits make: the
//! reader refuses it naming the row and column, and the writer refuses to write it.

/// Field values (`mx..mz`, `rx..rz`, `field_ned_ut`), µT: 1 T, far beyond any magnetometer (a field in nT fits).
pub const MAX_FIELD_UT: f64 = 1e6;
/// Time `t`, s: about 3000 years (Unix timestamps fit).
pub const MAX_T_S: f64 = 1e11;
/// Temperature `temp`, °C.
pub const MAX_TEMP_C: f64 = 1e4;
/// Angular rate `gx..gz`, rad/s.
pub const MAX_GYRO_RAD_S: f64 = 1e4;
/// Currents `i_<name>`, A.
pub const MAX_CURRENT_A: f64 = 1e6;
/// The `sample_rate_hz` metadata value, Hz.
pub const MAX_SAMPLE_RATE_HZ: f64 = 1e9;

/// How far from 1 the norm of a quaternion (`qw..qz`) may be before it is refused.
pub const QUAT_NORM_TOLERANCE: f64 = 0.01;

/// Columns in the header row: a recording has a few dozen; a file with more is something else, and is refused
/// before its names take memory.
pub const MAX_COLUMNS: usize = 10_000;

/// A limit and the unit it is in, for messages.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Limit {
    pub max: f64,
    pub unit: &'static str,
    /// What a number beyond it most likely is, for the message ("" when nothing is likely).
    pub hint: &'static str,
}

pub(crate) const FIELD: Limit = Limit {
    max: MAX_FIELD_UT,
    unit: "µT",
    hint: "",
};
pub(crate) const TIME: Limit = Limit {
    max: MAX_T_S,
    unit: "s",
    hint: "; t is in seconds: a timestamp in milliseconds or nanoseconds divided by 1000 or 10⁹ is one",
};
pub(crate) const TEMP: Limit = Limit {
    max: MAX_TEMP_C,
    unit: "°C",
    hint: "",
};
pub(crate) const GYRO: Limit = Limit {
    max: MAX_GYRO_RAD_S,
    unit: "rad/s",
    hint: "",
};
pub(crate) const CURRENT: Limit = Limit {
    max: MAX_CURRENT_A,
    unit: "A",
    hint: "",
};

impl Limit {
    /// Whether a finite `value` is beyond the limit (NaN, a missing value, is not).
    pub(crate) fn exceeded_by(self, value: f64) -> bool {
        value.abs() > self.max
    }
}

/// No limit beyond being finite (quaternion components: their norm is checked instead).
pub(crate) const UNBOUNDED: Limit = Limit {
    max: f64::MAX,
    unit: "",
    hint: "",
};
