//! Fuzzes the recording reader: `cargo +nightly fuzz run reader`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| magcal_fuzz::reader(data));
