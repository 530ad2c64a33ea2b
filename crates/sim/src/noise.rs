//! The readings' random noise: Gaussian by default, or with heavier tails (Student's t) or rare one-sample spikes,
//! each scaled to the scenario's standard deviation per axis — what real chips show besides quantisation.

use rand::RngExt;
use rand_chacha::ChaCha8Rng;
use rand_distr::{ChiSquared, Distribution, StandardNormal};

/// The distribution of the readings' noise, scaled on each axis to the scenario's standard deviation.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum NoiseKind {
    /// Gaussian.
    #[default]
    Gaussian,
    /// Student's t with `dof` degrees of freedom (more than 2, so that it has a standard deviation): heavier tails.
    StudentT {
        /// Degrees of freedom.
        dof: f64,
    },
    /// Gaussian, and with probability `per_sample` a spike of `size_sigma` standard deviations on one axis of a
    /// sample (a random axis and sign).
    Spikes {
        /// Probability of a spike per sample.
        per_sample: f64,
        /// Its size, standard deviations.
        size_sigma: f64,
    },
}

impl NoiseKind {
    /// Why these parameters make no noise of this kind, if they do not.
    pub fn invalid(&self) -> Option<String> {
        match *self {
            NoiseKind::Gaussian => None,
            NoiseKind::StudentT { dof } => (!(dof > 2.0 && dof.is_finite()))
                .then(|| format!("Student's t needs more than 2 degrees of freedom, got {dof}")),
            NoiseKind::Spikes {
                per_sample,
                size_sigma,
            } => (!((0.0..=1.0).contains(&per_sample) && size_sigma.is_finite()))
                .then(|| format!("spikes need a probability from 0 to 1 and a finite size, got {per_sample} and {size_sigma}")),
        }
    }
}

/// The random draws of a simulation's noise stream.
pub(crate) struct NoiseSource {
    rng: ChaCha8Rng,
}

impl NoiseSource {
    pub(crate) fn new(rng: ChaCha8Rng) -> NoiseSource {
        NoiseSource { rng }
    }

    /// One standard normal draw.
    pub(crate) fn gauss(&mut self) -> f64 {
        StandardNormal.sample(&mut self.rng)
    }

    /// One sample's noise, µT, with standard deviations `sigma_ut` per axis.
    pub(crate) fn reading(&mut self, kind: NoiseKind, sigma_ut: [f64; 3]) -> [f64; 3] {
        match kind {
            NoiseKind::Gaussian => std::array::from_fn(|k| sigma_ut[k] * self.gauss()),
            NoiseKind::StudentT { dof } => std::array::from_fn(|k| {
                let z = self.gauss();
                let v: f64 = ChiSquared::new(dof).expect("checked").sample(&mut self.rng);
                sigma_ut[k] * z * ((dof - 2.0) / v).sqrt()
            }),
            NoiseKind::Spikes {
                per_sample,
                size_sigma,
            } => {
                let mut n: [f64; 3] = std::array::from_fn(|k| sigma_ut[k] * self.gauss());
                if self.rng.random_bool(per_sample) {
                    let k = self.rng.random_range(0..3);
                    let sign = if self.rng.random_bool(0.5) { 1.0 } else { -1.0 };
                    n[k] += sign * size_sigma * sigma_ut[k];
                }
                n
            }
        }
    }
}
