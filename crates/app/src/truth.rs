//! The truth a fit of a simulated recording should find, as both simulators write it (`magcal-sim --truth`,
//! `magcal-record --device sim --truth`): one TOML layout, so that a check reads either.

use std::path::Path;

use magcal_sim::Scenario;
use serde::{Deserialize, Serialize};

use crate::files::write_atomic;

/// The format line of a truth file.
pub const TRUTH_FORMAT: &str = "magcal-sim-truth v1";

/// What a fit of a simulated recording should find.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TruthFile {
    /// Always [`TRUTH_FORMAT`].
    pub format: String,
    /// The simulated chip.
    pub chip: String,
    /// The seed the sensor was drawn from.
    pub seed: u64,
    /// The bench's world field, NED, µT.
    pub field_ned_ut: [f64; 3],
    /// True `A` of `B = A·raw + b` (reference axes: for the cube routine, the jig's).
    #[serde(rename = "A")]
    pub a: [[f64; 3]; 3],
    /// True `b`, µT.
    pub b_ut: [f64; 3],
    /// The hard-iron offset in the sensor's raw axes, `−A⁻¹·b`, µT.
    pub offset_ut: [f64; 3],
    /// The white noise per raw axis, µT.
    pub noise_ut: [f64; 3],
    /// Physics the 12-parameter model leaves out, injected, as `--effect` specs.
    pub effects: Vec<String>,
}

impl TruthFile {
    /// The truth of a scenario, with its effects written as specs.
    pub fn of_scenario(s: &Scenario, effects: Vec<String>) -> TruthFile {
        TruthFile {
            format: TRUTH_FORMAT.to_owned(),
            chip: s.sensor_name.clone(),
            seed: s.seed,
            field_ned_ut: s.field_ned_ut,
            a: s.sensor.a,
            b_ut: s.sensor.b_ut,
            offset_ut: magcal_calib::scalar::centre(&s.sensor.a, s.sensor.b_ut),
            noise_ut: s.noise_ut,
            effects,
        }
    }

    /// Writes it as TOML, atomically.
    pub fn write(&self, path: &Path) -> std::io::Result<()> {
        let text = toml::to_string(self).map_err(std::io::Error::other)?;
        write_atomic(path, text.as_bytes())
    }

    /// Reads one back.
    pub fn read(path: &Path) -> anyhow::Result<TruthFile> {
        use anyhow::Context as _;
        let text =
            std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        let t: TruthFile =
            toml::from_str(&text).with_context(|| format!("parsing {}", path.display()))?;
        anyhow::ensure!(
            t.format == TRUTH_FORMAT,
            "{}: format {:?}, expected {TRUTH_FORMAT:?}",
            path.display(),
            t.format
        );
        Ok(t)
    }
}
