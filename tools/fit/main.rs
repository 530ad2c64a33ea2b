//! `magcal-fit`: fit a calibration to a recording, report it, write the parameters.

use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context, bail};
use clap::Parser;
use magcal_app::calibrate::{Method, calibrate};
use magcal_app::cli::{WorldFieldOpts, exit};
use magcal_app::device::DeviceSpec;
use magcal_app::export::{ExportFormat, export};
use magcal_app::field::resolve;
use magcal_app::files::{check_outputs, write_atomic};
use magcal_app::params::ParamsFile;
use magcal_app::plots::write_plots;
use magcal_app::report::Report;
use magcal_app::summary::summary;
use magcal_app::writeback::write_back_calibration;
use magcal_recording::Recording;

/// Fit a magnetometer calibration B = A·raw + b to a recording (magcal-recording v1), diagnose what the model leaves
/// out, print a summary, and write the report, the parameters file and exports.
///
/// With an attitude reference in the recording (qw..qz plus the world field, or rx,ry,rz) the vector method of the
/// seed paper fits every component; without one, the scalar (ellipsoid) method fits the magnitude only. The
/// diagnosis then looks for the physics the 12-parameter model leaves out (temperature, currents, a timing lag,
/// drifts, a wrong reference field, non-linearity, a step, a transient magnet), models what it finds, and shows
/// the fit improve on held-out data.
///
/// Workflow: magcal-record (or magcal-sim) writes the recording, magcal-fit fits it.
///
/// With --write-to DEV the fitted parameters also go to the device, after the files are written, and are verified:
/// serial:PATH[:BAUD][:motioncal|csv] gets MotionCal's calibration packet, confirmed by the firmware's Cal1:/Cal2:
/// echo; i2c:/dev/i2c-N:lis2mdl[@ADDR] (or sim:lis2mdl) gets the hard-iron offset in its offset registers, read back.
/// The other chips have no place for a calibration: that is an error, and the parameters file is the way.
#[derive(Parser, Debug)]
#[command(version, about, long_about)]
struct Args {
    /// The recording (magcal-recording v1 CSV).
    recording: PathBuf,
    /// Calibration method.
    #[arg(long, value_enum, default_value_t = Method::Auto)]
    method: Method,
    /// The world field (otherwise the recording's metadata says it).
    #[command(flatten)]
    field: WorldFieldOpts,
    /// Field magnitude in µT (scalar method; ignored when a field vector is known).
    #[arg(long, value_name = "UT")]
    field_ut: Option<f64>,
    /// Write the parameters file (TOML) here, atomically.
    #[arg(long, value_name = "PARAMS.toml")]
    out: Option<PathBuf>,
    /// Write the JSON report here.
    #[arg(long, value_name = "REPORT.json")]
    report: Option<PathBuf>,
    /// Export the parameters in another tool's convention (to stdout, or to --export-out).
    #[arg(long, value_enum)]
    export: Option<ExportFormat>,
    /// Where to write the export (default: stdout, with the summary moved to stderr).
    #[arg(long, value_name = "PATH", requires = "export")]
    export_out: Option<PathBuf>,
    /// Write the calibration to this device and verify it: serial:PATH[:BAUD][:motioncal|csv] (MotionCal packet,
    /// confirmed by the echo) or i2c:/dev/i2c-N:lis2mdl[@ADDR] / sim:lis2mdl (offset registers, read back).
    #[arg(long, value_name = "DEV")]
    write_to: Option<DeviceSpec>,
    /// Skip the diagnosis (what physics the 12-parameter model leaves out).
    #[arg(long)]
    no_diagnose: bool,
    /// Write SVG plots of the diagnosis into this directory (created if needed): residual against time before and
    /// after, against the blamed channel, and over the sphere of field directions.
    #[arg(long, value_name = "DIR", conflicts_with = "no_diagnose")]
    plots: Option<PathBuf>,
}

fn main() -> ExitCode {
    exit("magcal-fit", run(Args::parse()))
}

/// Refuses outputs that would overwrite the recording or each other, or plots into a file's place, before anything
/// is read or written.
fn check_paths(args: &Args) -> anyhow::Result<()> {
    let mut outputs: Vec<(&str, &std::path::Path)> = Vec::new();
    let named = [
        ("--out", &args.out),
        ("--report", &args.report),
        ("--export-out", &args.export_out),
        ("--plots", &args.plots),
    ];
    for (flag, path) in named {
        if let Some(path) = path {
            outputs.push((flag, path));
        }
    }
    check_outputs(&args.recording, &outputs)?;
    if let Some(dir) = &args.plots
        && dir.exists()
        && !dir.is_dir()
    {
        bail!(
            "--plots {}: a file is there, and --plots names a directory (the plots are written into it); nothing \
             was written",
            dir.display()
        );
    }
    Ok(())
}

fn run(args: Args) -> anyhow::Result<()> {
    check_paths(&args)?;
    let rec = Recording::read(&args.recording)?;
    let name = args.recording.display().to_string();
    if let Some(f) = args.field_ut
        && !(f > 0.0 && f.is_finite())
    {
        bail!("--field-ut must be a positive number of µT, got {f}");
    }
    let field = resolve(&args.field.field_args(args.field_ut), &rec.meta)?;
    let cal = calibrate(&rec, args.method, field, !args.no_diagnose)
        .with_context(|| format!("{name}: cannot calibrate"))?;

    // With the export on stdout, everything else goes to stderr.
    let export_to_stdout = args.export.is_some() && args.export_out.is_none();
    let say = |text: &str| {
        if export_to_stdout {
            eprint!("{text}");
        } else {
            print!("{text}");
        }
    };
    say(&summary(&cal, &name));
    if let Some(path) = &args.report {
        let channels: Vec<String> = rec.currents.iter().map(|c| c.name.clone()).collect();
        Report::new(&cal, &name, &channels).write(path)?;
    }
    if let (Some(dir), Some(d)) = (&args.plots, &cal.diagnosis) {
        for path in write_plots(dir, d)? {
            eprintln!("wrote {}", path.display());
        }
    }
    if let Some(path) = &args.out {
        ParamsFile::of(&cal, &rec, &name)
            .write(path)
            .with_context(|| format!("writing the parameters {}", path.display()))?;
    }
    if let Some(format) = args.export {
        let text = export(&cal.model(), format);
        match &args.export_out {
            Some(path) => write_atomic(path, text.as_bytes())
                .with_context(|| format!("writing {}", path.display()))?,
            None => std::io::stdout().write_all(text.as_bytes())?,
        }
    }
    if let Some(device) = &args.write_to {
        for line in write_back_calibration(device, &cal)? {
            say(&format!("{line}\n"));
        }
    }
    Ok(())
}
