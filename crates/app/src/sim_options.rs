//! The ranges of `magcal-sim`'s numbers, checked before anything is simulated or allocated: a run of 0 samples, a
//! current switching every nanosecond (billions of switching times), NaN errors or negative noise are refused with
//! the range that makes sense, naming the option.

use magcal_sim::{CurrentProfile, NoiseKind};

use crate::cli::number;
use crate::device::{BadOption, MAX_RATE_HZ, within};
use crate::field::{FIELD_MAX_UT, FIELD_MIN_UT};

/// Most samples one run simulates: about 2 GB of memory while it runs.
pub const MAX_SAMPLES: f64 = 2e7;
/// Fewest samples one run simulates: fewer turn the sensor through too few directions to fit.
pub const MIN_SAMPLES: f64 = 100.0;
/// The slowest sample rate, Hz (the slowest chip's, 0.75 Hz, and below).
pub const MIN_RATE_HZ: f64 = 0.1;
/// The largest noise per axis, µT: twice the Earth's field.
pub const MAX_NOISE_UT: f64 = 100.0;
/// The largest gyro noise, rad/s.
pub const MAX_GYRO_NOISE_RAD_S: f64 = 10.0;
/// The largest soft-iron and scale error (relative): beyond, `A` may not be invertible.
pub const MAX_SOFT: f64 = 0.5;
/// The largest hard-iron offset per axis, µT (the widest chip range is ±4915 µT).
pub const MAX_HARD_UT: f64 = 5000.0;
/// The largest mounting misalignment, degrees.
pub const MAX_MOUNT_DEG: f64 = 180.0;
/// The largest temperature, its rise and its wobble, °C.
pub const MAX_TEMP_C: f64 = 1000.0;
/// The longest time constant or period, s.
pub const MAX_TIME_S: f64 = 1e7;

/// magcal-sim's numbers as given.
#[derive(Clone, Debug, PartialEq)]
pub struct SimNumbers<'a> {
    /// `--duration`, s.
    pub duration_s: f64,
    /// The sample rate: `--rate`, or the chip's, Hz.
    pub rate_hz: f64,
    /// `--noise`, µT.
    pub noise_ut: Option<f64>,
    /// `--gyro-noise`, rad/s.
    pub gyro_noise_rad_s: Option<f64>,
    /// `--errors`: soft (relative), hard (µT), mount (degrees).
    pub errors: [f64; 3],
    /// `--field-ned`, µT.
    pub field_ned_ut: Option<[f64; 3]>,
    /// `--temperature`: START, RISE, TAU, WOBBLE, PERIOD.
    pub temperature: Option<[f64; 5]>,
    /// `--current`.
    pub currents: &'a [CurrentProfile],
}

impl SimNumbers<'_> {
    /// Checks every number against its range; the first out of it is the error.
    pub fn check(&self) -> Result<(), BadOption> {
        self.check_length()?;
        if let Some(n) = self.noise_ut {
            within("--noise", n, 0.0, MAX_NOISE_UT, "µT")?;
        }
        if let Some(g) = self.gyro_noise_rad_s {
            within("--gyro-noise", g, 0.0, MAX_GYRO_NOISE_RAD_S, "rad/s")?;
        }
        let [soft, hard_ut, mount_deg] = self.errors;
        within("--errors SOFT", soft, 0.0, MAX_SOFT, "")?;
        within("--errors HARD", hard_ut, 0.0, MAX_HARD_UT, "µT")?;
        within("--errors MOUNT", mount_deg, 0.0, MAX_MOUNT_DEG, "°")?;
        if let Some(f) = self.field_ned_ut {
            let m = f.iter().map(|v| v * v).sum::<f64>().sqrt();
            within(
                "--field-ned (its magnitude)",
                m,
                FIELD_MIN_UT,
                FIELD_MAX_UT,
                "µT",
            )?;
        }
        if let Some([start_c, rise_c, tau_s, wobble_c, period_s]) = self.temperature {
            let max = MAX_TEMP_C;
            within("--temperature START", start_c, -max, max, "°C")?;
            within("--temperature RISE", rise_c, -max, max, "°C")?;
            within("--temperature WOBBLE", wobble_c, -max, max, "°C")?;
            within("--temperature TAU", tau_s, 1e-3, MAX_TIME_S, "s")?;
            within("--temperature PERIOD", period_s, 1e-3, MAX_TIME_S, "s")?;
        }
        for c in self.currents {
            self.check_current(c)?;
        }
        Ok(())
    }

    /// The run's length: a duration and rate that are numbers, then between [`MIN_SAMPLES`] and
    /// [`MAX_SAMPLES`] samples, at a rate from [`MIN_RATE_HZ`] to [`MAX_RATE_HZ`].
    fn check_length(&self) -> Result<(), BadOption> {
        let (duration_s, rate_hz) = (self.duration_s, self.rate_hz);
        if !(duration_s > 0.0 && duration_s.is_finite()) {
            return Err(BadOption(format!(
                "--duration must be a positive number of seconds, got {}",
                number(duration_s)
            )));
        }
        if !(rate_hz > 0.0 && rate_hz.is_finite()) {
            return Err(BadOption(format!(
                "--rate must be a positive number of Hz, got {}",
                number(rate_hz)
            )));
        }
        let samples = duration_s * rate_hz;
        let run = format!(
            "--duration {} s at {} Hz is {samples:.3e} samples",
            number(duration_s),
            number(rate_hz)
        );
        if samples > MAX_SAMPLES {
            return Err(BadOption(format!(
                "{run}: at most {MAX_SAMPLES:.0e} are simulated at once (shorten the run or lower the rate)"
            )));
        }
        if !(MIN_RATE_HZ..=MAX_RATE_HZ).contains(&rate_hz) {
            return Err(BadOption(format!(
                "--rate must be a number of Hz from {MIN_RATE_HZ} to {MAX_RATE_HZ}, got {}",
                number(rate_hz)
            )));
        }
        if samples < MIN_SAMPLES {
            return Err(BadOption(format!(
                "{run}: at least {MIN_SAMPLES} are simulated (a fit needs the sensor turned through many \
                 directions: lengthen the run or raise the rate)"
            )));
        }
        Ok(())
    }

    /// A current: a number of amperes within what a recording holds, switching no faster than the samples.
    fn check_current(&self, c: &CurrentProfile) -> Result<(), BadOption> {
        let option = format!("--current {}", crate::cli::excerpt(&c.name));
        let max_a = magcal_recording::limits::MAX_CURRENT_A;
        within(&format!("{option} ON_A"), c.on_a, -max_a, max_a, "A")?;
        let period_s = 1.0 / self.rate_hz;
        for (what, mean_s) in [("MEAN_ON_S", c.mean_on_s), ("MEAN_OFF_S", c.mean_off_s)] {
            if !(period_s..=MAX_TIME_S).contains(&mean_s) {
                return Err(BadOption(format!(
                    "{option} {what} {} s: must be a number from {} s (one sample period at {} Hz: a current \
                     switching faster is not sampled) to {MAX_TIME_S:e} s",
                    number(mean_s),
                    number(period_s),
                    number(self.rate_hz)
                )));
            }
        }
        Ok(())
    }
}

/// Parses `--noise-kind`: `gaussian`, `t:DOF` (Student's t with DOF degrees of freedom, more than 2) or
/// `spikes:PER_SAMPLE:SIGMAS` (Gaussian with, per sample with that probability, a spike of that many standard
/// deviations on one axis).
pub fn parse_noise_kind(text: &str) -> Result<NoiseKind, String> {
    let number = |x: &str| {
        x.trim()
            .parse::<f64>()
            .map_err(|_| format!("{}: not a number", crate::cli::excerpt(x)))
    };
    let kind = match text.trim().split(':').collect::<Vec<_>>()[..] {
        ["gaussian"] => NoiseKind::Gaussian,
        ["t", dof] => NoiseKind::StudentT { dof: number(dof)? },
        ["spikes", p, size] => NoiseKind::Spikes {
            per_sample: number(p)?,
            size_sigma: number(size)?,
        },
        _ => {
            return Err(format!(
                "{}: expected gaussian, t:DOF or spikes:PER_SAMPLE:SIGMAS",
                crate::cli::excerpt(text)
            ));
        }
    };
    match kind.invalid() {
        Some(why) => Err(why),
        None => Ok(kind),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ok() -> SimNumbers<'static> {
        SimNumbers {
            duration_s: 120.0,
            rate_hz: 80.0,
            noise_ut: None,
            gyro_noise_rad_s: None,
            errors: [0.1, 30.0, 3.0],
            field_ned_ut: None,
            temperature: None,
            currents: &[],
        }
    }

    #[test]
    fn numbers_out_of_their_range_are_refused_naming_the_option() {
        assert_eq!(ok().check(), Ok(()));
        let current = |on_a, mean_on_s, mean_off_s| CurrentProfile {
            name: "i_m".into(),
            on_a,
            mean_on_s,
            mean_off_s,
        };
        let zero_mean = [current(1.0, 0.0, 0.0)];
        let nano_mean = [current(1.0, 1e-9, 1e-9)];
        let nan_amps = [current(f64::NAN, 1.0, 1.0)];
        let cases: Vec<(SimNumbers, &str)> = vec![
            (
                SimNumbers {
                    rate_hz: 1e-300,
                    ..ok()
                },
                "--rate must be a number of Hz from 0.1 to 10000, got 1e-300",
            ),
            (
                SimNumbers {
                    duration_s: 1e-300,
                    ..ok()
                },
                "--duration 1e-300 s at 80 Hz is 8.000e-299 samples: at least 100",
            ),
            (
                SimNumbers {
                    noise_ut: Some(-1.0),
                    ..ok()
                },
                "--noise -1 µT: must be a number from 0 to 100 µT",
            ),
            (
                SimNumbers {
                    errors: [f64::NAN, 1.0, 1.0],
                    ..ok()
                },
                "--errors SOFT NaN",
            ),
            (
                SimNumbers {
                    errors: [0.1, f64::INFINITY, 1.0],
                    ..ok()
                },
                "--errors HARD inf",
            ),
            (
                SimNumbers {
                    errors: [0.1, 1.0, f64::NEG_INFINITY],
                    ..ok()
                },
                "--errors MOUNT -inf",
            ),
            (
                SimNumbers {
                    currents: &zero_mean,
                    ..ok()
                },
                "--current \"i_m\" MEAN_ON_S 0 s",
            ),
            (
                SimNumbers {
                    currents: &nano_mean,
                    ..ok()
                },
                "--current \"i_m\" MEAN_ON_S 1e-9 s: must be a number from 0.0125 s (one sample period at 80 Hz",
            ),
            (
                SimNumbers {
                    currents: &nan_amps,
                    ..ok()
                },
                "--current \"i_m\" ON_A NaN A",
            ),
            (
                SimNumbers {
                    field_ned_ut: Some([f64::NAN, 0.0, 0.0]),
                    ..ok()
                },
                "--field-ned (its magnitude) NaN µT",
            ),
        ];
        for (numbers, says) in cases {
            let e = numbers.check().unwrap_err().to_string();
            assert!(e.starts_with(says), "{says}: {e}");
            assert!(e.len() < 200, "{e}");
        }
    }
}
