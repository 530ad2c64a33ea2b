//! What the fuzz targets do with their input, shared with `tests/fuzz_corpus.rs`, which replays the committed corpus
//! on the stable toolchain. Each function panics only on a bug: an input that breaks a promise of the code under
//! test.

use magcal_app::calibrate::calibrate;
use magcal_app::export::{ExportFormat, export};
use magcal_app::field::{FieldArgs, resolve};
use magcal_app::fit::Method;
use magcal_app::params::ParamsFile;
use magcal_app::report::Report;
use magcal_app::summary::summary;
use magcal_app::verdict::{assess, target_model};
use magcal_recording::Recording;

/// The name the input stands under in messages.
const NAME: &str = "fuzz.csv";

/// Reads `data` as a recording. An error names the file and quotes at most a short, escaped excerpt; a recording
/// keeps the format's invariants.
pub fn reader(data: &[u8]) {
    match Recording::from_reader(NAME, data) {
        Ok(rec) => {
            assert!(!rec.is_empty());
            assert!(
                rec.mag_ut
                    .iter()
                    .flatten()
                    .all(|v| v.is_finite() && v.abs() <= 1e6)
            );
            if let Some(t) = &rec.t_s {
                assert_eq!(t.len(), rec.len());
                assert!(t.windows(2).all(|w| w[0] <= w[1]));
            }
        }
        Err(e) => {
            let msg = e.to_string();
            assert!(msg.starts_with(NAME), "{msg}");
            // The name, a position, a message and at most a few short excerpts.
            assert!(msg.len() < 600, "{} bytes: {msg}", msg.len());
            assert!(
                !msg.chars().any(|c| c.is_control()),
                "raw control characters: {msg:?}"
            );
        }
    }
}

/// Reads `data`, calibrates it as `magcal-fit` does (diagnosis included), and makes everything `magcal-fit` writes
/// from it: the summary, the JSON report, the parameters file (read back) and every export.
pub fn pipeline(data: &[u8]) {
    let Ok(rec) = Recording::from_reader(NAME, data) else {
        return;
    };
    let Ok(field) = resolve(&FieldArgs::default(), &rec.meta) else {
        return;
    };
    let Ok(cal) = calibrate(&rec, Method::Auto, field, true) else {
        return;
    };
    let assessment = assess(&cal, &rec, false);
    assert!(!summary(&cal, &assessment, NAME).is_empty());
    let channels: Vec<String> = rec.currents.iter().map(|c| c.name.clone()).collect();
    let json = Report::new(&cal, NAME, &channels)
        .with_assessment(&assessment)
        .to_json();
    assert!(json.starts_with('{'));
    let params = ParamsFile::of(&cal, &rec, NAME);
    let text = toml::to_string_pretty(&params).expect("a parameters file serialises");
    let back: ParamsFile = toml::from_str(&text).expect("a parameters file reads back");
    back.model(&channels).expect("its model rebuilds");
    for format in [
        ExportFormat::Ardupilot,
        ExportFormat::Px4,
        ExportFormat::CHeader,
        ExportFormat::Json,
    ] {
        let found = cal.diagnosis.as_ref().map_or(&[][..], |d| &d.effects[..]);
        assert!(!export(&target_model(&cal), format, found, &cal.units).is_empty());
    }
}
