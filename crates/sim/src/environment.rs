//! Temperature and current channels: what the bench does besides turning the sensor.

use rand::RngExt;

/// The sensor's temperature over the recording: a warm-up towards a plateau plus a slow oscillation (air
/// conditioning cycling), `T(t) = start + warmup·(1 − e^(−t/τ)) + wobble·sin(2πt/period + phase)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TemperatureProfile {
    /// Temperature at t = 0, °C.
    pub start_c: f64,
    /// Rise towards the plateau, °C.
    pub warmup_c: f64,
    /// Time constant of the warm-up, s.
    pub tau_s: f64,
    /// Amplitude of the oscillation, °C.
    pub wobble_c: f64,
    /// Period of the oscillation, s.
    pub wobble_period_s: f64,
    /// Phase of the oscillation, rad.
    pub wobble_phase_rad: f64,
}

impl TemperatureProfile {
    /// A constant temperature.
    pub fn constant(c: f64) -> TemperatureProfile {
        TemperatureProfile {
            start_c: c,
            warmup_c: 0.0,
            tau_s: 1.0,
            wobble_c: 0.0,
            wobble_period_s: 1.0,
            wobble_phase_rad: 0.0,
        }
    }

    /// The temperature at `t_s`, °C.
    pub fn at(&self, t_s: f64) -> f64 {
        self.start_c
            + self.warmup_c * (1.0 - (-t_s / self.tau_s).exp())
            + self.wobble_c
                * (std::f64::consts::TAU * t_s / self.wobble_period_s + self.wobble_phase_rad).sin()
    }
}

/// A current that switches on and off at random (a motor, heater or LED): a telegraph signal with exponentially
/// distributed on and off times.
#[derive(Clone, Debug, PartialEq)]
pub struct CurrentProfile {
    /// Column name, `i_<name>`.
    pub name: String,
    /// Current when on, A.
    pub on_a: f64,
    /// Mean time on, s.
    pub mean_on_s: f64,
    /// Mean time off, s.
    pub mean_off_s: f64,
}

impl CurrentProfile {
    /// The switching times over `[0, duration_s]`, starting off: `[on, off, on, …]`.
    pub(crate) fn switch_times(&self, duration_s: f64, rng: &mut impl RngExt) -> Vec<f64> {
        let mut times = Vec::new();
        let mut t = 0.0;
        let mut on = false;
        while t < duration_s {
            let mean = if on { self.mean_on_s } else { self.mean_off_s };
            // Exponential draw by inversion; 1 − u avoids ln(0).
            t += -mean * (1.0 - rng.random::<f64>()).ln();
            times.push(t);
            on = !on;
        }
        times
    }

    /// The current at `t_s` given the switching times.
    pub(crate) fn at(&self, switches: &[f64], t_s: f64) -> f64 {
        let passed = switches.partition_point(|s| *s <= t_s);
        if passed % 2 == 1 { self.on_a } else { 0.0 }
    }
}
