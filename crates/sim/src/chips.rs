//! What the simulator needs to know of each supported chip: its resolution, noise, temperature sensor and rates.
//!
//! Figures are the datasheets' typical values at the range magcal configures by default.

/// One chip's simulation figures.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ChipModel {
    /// Name as in `--device sim:CHIP` and the recording's `sensor` metadata.
    pub name: &'static str,
    /// One LSB at the default range, µT.
    pub lsb_ut: f64,
    /// RMS noise per axis, µT.
    pub noise_ut: [f64; 3],
    /// One LSB of the temperature output, °C, if the chip has a usable temperature sensor.
    pub temp_lsb_c: Option<f64>,
    /// Default output rate, Hz.
    pub rate_hz: f64,
}

/// The chips magcal drives, as simulated.
pub const CHIPS: [ChipModel; 5] = [
    // ST LIS3MDL, ±4 gauss: 6842 LSB/gauss; RMS noise 3.2 / 3.2 / 4.1 mgauss (ultra-high-performance mode).
    ChipModel {
        name: "lis3mdl",
        lsb_ut: 100.0 / 6842.0,
        noise_ut: [0.32, 0.32, 0.41],
        temp_lsb_c: Some(0.125),
        rate_hz: 80.0,
    },
    // ST LIS2MDL: 1.5 mgauss/LSB; RMS noise 3 mgauss (high resolution, offset cancellation on).
    ChipModel {
        name: "lis2mdl",
        lsb_ut: 0.15,
        noise_ut: [0.3, 0.3, 0.3],
        temp_lsb_c: Some(0.125),
        rate_hz: 100.0,
    },
    // QST QMC5883L, ±2 gauss: 12000 LSB/gauss; field resolution 2 mgauss. Its temperature output is relative only.
    ChipModel {
        name: "qmc5883l",
        lsb_ut: 100.0 / 12000.0,
        noise_ut: [0.2, 0.2, 0.2],
        temp_lsb_c: None,
        rate_hz: 100.0,
    },
    // Honeywell HMC5883L, gain 1090 LSB/gauss; noise floor 2 mgauss. No temperature sensor.
    ChipModel {
        name: "hmc5883l",
        lsb_ut: 100.0 / 1090.0,
        noise_ut: [0.2, 0.2, 0.2],
        temp_lsb_c: None,
        rate_hz: 75.0,
    },
    // MEMSIC MMC5983MA, 18-bit: 16384 counts/gauss; RMS noise 0.4 mgauss at 100 Hz bandwidth; Tout 0.8 °C/LSB.
    ChipModel {
        name: "mmc5983ma",
        lsb_ut: 100.0 / 16384.0,
        noise_ut: [0.04, 0.04, 0.04],
        temp_lsb_c: Some(0.8),
        rate_hz: 100.0,
    },
];

impl ChipModel {
    /// The chip of that name (`lis3mdl`, `lis2mdl`, `qmc5883l`, `hmc5883l`, `mmc5983ma`).
    pub fn by_name(name: &str) -> Option<ChipModel> {
        CHIPS
            .into_iter()
            .find(|c| c.name.eq_ignore_ascii_case(name))
    }
}
