//! Fuzzes read + calibrate + report + exports: `cargo +nightly fuzz run pipeline`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| magcal_fuzz::pipeline(data));
