//! Magnetometer calibration: the model and its `apply` path, the effects catalogue, and (with `std`) the solvers.
//!
//! The model is the seed paper's `B = A·B̂ + b` (raw reading `B̂` in sensor axes, calibrated field `B`, both µT),
//! optionally extended by body-fixed effects (temperature, currents, drift, …) that `apply` removes. Every effect is
//! defined once, in [`effects`], as the perturbation it adds to the calibrated field; the simulator injects it with
//! that definition and the fitter estimates it with the same one.
//!
//! Without the default `std` feature only [`frames`], [`effects`] and [`model`] are compiled (no heap, no I/O), so a
//! firmware can apply a calibration. With `std`: the vector solver (paper eqs. 2–4), the scalar (ellipsoid) solver,
//! coverage checks, the coverage of the sphere of directions (one definition for recorder and fit) and the
//! noise-floor estimate. Nothing in this crate reads or writes files.
#![cfg_attr(not(feature = "std"), no_std)]

pub mod effects;
pub mod frames;
pub mod model;

#[cfg(feature = "std")]
mod chunks;
#[cfg(feature = "std")]
pub mod convention;
#[cfg(feature = "std")]
pub mod coverage;
#[cfg(feature = "std")]
pub mod diagnosis;
#[cfg(feature = "std")]
pub mod directions;
#[cfg(feature = "std")]
mod error;
#[cfg(feature = "std")]
pub mod faults;
#[cfg(feature = "std")]
pub mod fit;
#[cfg(feature = "std")]
pub mod noise;
#[cfg(feature = "std")]
pub mod reference_heading;
#[cfg(feature = "std")]
pub mod robust;
#[cfg(feature = "std")]
pub mod scalar;
#[cfg(feature = "std")]
mod scan;
#[cfg(feature = "std")]
pub mod sphere;
#[cfg(feature = "std")]
pub mod vector;

pub use effects::{Context, Effect, EffectId, Frame, WorldContext};
#[cfg(feature = "std")]
pub use error::FitError;
pub use model::{Inputs, Model};
