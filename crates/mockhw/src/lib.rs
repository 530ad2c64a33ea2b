//! Register-level simulated twins of the chips magcal drives, fed by the simulator's physics, with fault injection.
//!
//! A [`SimChip`] implements [`embedded_hal::i2c::I2c`] and behaves like the named chip on its bus: identification
//! registers, reset values, control registers that select range, output data rate and mode, data-ready and
//! overrun flags, output registers in the chip's own encoding (endianness, axis order, null field, overflow
//! markers), temperature outputs, and chip quirks the drivers must handle (the HMC5883L's stale first sample after
//! a gain change, the MMC5983MA's write-only control registers and SET/RESET polarity). The real drivers of
//! [`magcal_driver`] run against it unchanged.
//!
//! What the chip measures comes from a [`magcal_sim::bench::Bench`]: the world field in the sensor's axes at the
//! attitude the bench's virtual hand holds, through the sensor's true errors, plus effects, noise and temperature.
//! The twin asks for it at the times its output data rate says a conversion finishes, on a [`VirtualClock`] that
//! bus traffic and delays advance, then quantises it to its LSB at the configured range and clips it to its range.
//!
//! Faults ([`Fault`]): NACKs, a dropped bus, ignored writes, stuck outputs, and a magnet that saturates the chip.
//!
//! [`autopilot`] is an ArduPilot or PX4 flight controller over MAVLink on the same bench: its calibration applied to
//! the compass it streams, its parameters read and set.
//!
//! [`firmware`] holds the same idea for serial boards: firmware that streams MotionCal `Raw:` lines from a bench and
//! takes calibration packets.
//!
//! ```
//! use std::cell::RefCell;
//! use std::rc::Rc;
//!
//! use magcal_driver::{AnyMagnetometer, ChipKind, Magnetometer};
//! use magcal_mockhw::{SimChip, VirtualClock};
//! use magcal_sim::bench::{Bench, BenchConfig};
//!
//! let bench = Rc::new(RefCell::new(Bench::new(BenchConfig::ideal([20.0, 0.0, 45.0], 1))?));
//! let mut clock = VirtualClock::new();
//! let chip = SimChip::new(ChipKind::Lis3mdl, bench, clock.clone());
//! let mut mag = AnyMagnetometer::new(ChipKind::Lis3mdl, chip);
//! mag.init().expect("the twin answers like a LIS3MDL");
//! let field_ut = loop {
//!     match mag.read_ut() {
//!         Ok(m) => break m,
//!         Err(magcal_driver::Error::NotReady) => embedded_hal::delay::DelayNs::delay_ms(&mut clock, 5),
//!         Err(e) => panic!("{e}"),
//!     }
//! };
//! let magnitude = field_ut.iter().map(|v| v * v).sum::<f32>().sqrt();
//! assert!((magnitude - 49.2).abs() < 0.1);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod autopilot;
mod bus;
pub mod clock;
pub mod fault;
pub mod firmware;
mod hmc5883l;
mod lis2mdl;
mod lis3mdl;
mod mmc5983ma;
mod qmc5883l;
mod sampling;

pub use bus::{DEFAULT_BUS_HZ, SimChip};
pub use clock::VirtualClock;
pub use fault::{Fault, FaultSyntax};
pub use sampling::SharedBench;
