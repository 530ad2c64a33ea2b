//! `magcal-apply`: calibrate a recording with a parameters file and say how well the parameters fit it.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context, bail};
use clap::Parser;
use magcal_app::cli::{WorldFieldOpts, exit, parse};
use magcal_app::outputs::{Guard, Replace};
use magcal_app::summary::check_summary;
use magcal_app::verdict::Grade;
use magcal_app::workflow::{Checked, check_file};
use magcal_app::{say, sayln};

/// Check a calibration on another recording: apply a parameters file (magcal-fit --out) and say how well it fits.
///
/// Record the sensor a second time (magcal-record), then run magcal-apply PARAMS.toml SECOND.csv: it applies
/// B = A·raw + b (and the file's corrections) to every reading and prints the residual against the recording's
/// reference — the attitude and the world field, or the field magnitude — beside the sensor's noise measured from
/// the recording, the heading error measured sample by sample when there is an attitude reference, the heading
/// error over 360 level headings, and a verdict (good, usable, redo). --out writes the calibrated recording.
#[derive(Parser, Debug)]
#[command(version)]
struct Args {
    /// The parameters file (magcal-fit --out).
    params: PathBuf,
    /// The recording to calibrate (magcal-recording v1).
    recording: PathBuf,
    /// The world field (otherwise the recording's metadata says it).
    #[command(flatten)]
    field: WorldFieldOpts,
    /// Field magnitude in µT: |B| is checked against it (it replaces a field vector from the recording's
    /// metadata; --field-ned replaces the vector instead).
    #[arg(allow_negative_numbers = true, long, value_name = "UT")]
    field_ut: Option<f64>,
    /// Write the calibrated recording here (mx,my,mz replaced by the calibrated field).
    #[arg(long, value_name = "OUT.csv")]
    out: Option<PathBuf>,
    /// Exit non-zero unless the verdict is at least this (good or usable).
    #[arg(long, value_enum, value_name = "GRADE")]
    require: Option<Grade>,
}

fn main() -> ExitCode {
    exit("magcal-apply", run(parse()))
}

fn run(args: Args) -> anyhow::Result<()> {
    // Neither input is ever overwritten, nor any recording but a calibrated copy, before anything is read.
    Guard::new("magcal-apply")
        .input("<PARAMS>", &args.params)
        .input("<RECORDING>", &args.recording)
        .file(
            "--out",
            args.out.as_deref(),
            Replace::Remakes("calibrated_with", ""),
        )
        .check()?;
    let Checked {
        params,
        rec,
        field,
        check: c,
    } = check_file(
        &args.params,
        &args.recording,
        &args.field.field_args(args.field_ut),
    )?;
    let name = args.recording.display().to_string();
    say!("{}", check_summary(&c, &params, &field, &name))?;
    if let Some(path) = &args.out {
        let bad = c
            .calibrated_ut
            .iter()
            .filter(|m| !m.iter().all(|v| v.is_finite()))
            .count();
        if bad > 0 {
            bail!(
                "{bad} rows cannot be calibrated (a channel a correction needs is missing there): not writing {}",
                path.display()
            );
        }
        let mut out = rec.clone();
        out.mag_ut = c.calibrated_ut.clone();
        out.meta.other.push((
            "calibrated_with".to_owned(),
            args.params.display().to_string(),
        ));
        out.write(path)
            .with_context(|| format!("writing {}", path.display()))?;
        sayln!("wrote {}", path.display())?;
    }
    let grade = c.verdict.grade;
    if let Some(required) = args.require
        && grade < required
    {
        bail!(
            "the verdict is {}, and --require {} was given",
            grade.name(),
            required.name()
        );
    }
    Ok(())
}
