//! magcal-driver (skeleton: being written).
#![cfg_attr(not(feature = "std"), no_std)]

#[cfg(feature = "serial")]
pub mod serial;
