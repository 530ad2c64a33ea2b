//! `magcal-fit`: fit a calibration to a recording, report it, write the parameters.

use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context, bail};
use clap::{Parser, ValueEnum};
use magcal_app::calibrate::{Method, calibrate};
use magcal_app::device::DeviceSpec;
use magcal_app::export::{ExportFormat, export};
use magcal_app::field::{FieldArgs, resolve};
use magcal_app::files::write_atomic;
use magcal_app::params::ParamsFile;
use magcal_app::plots::write_plots;
use magcal_app::report::Report;
use magcal_app::summary::summary;
use magcal_app::writeback::write_back_calibration;
use magcal_recording::{Date, Location, Recording};

/// Fit a magnetometer calibration B = A·raw + b to a recording (magcal-recording v1), print a summary, and write the
/// report, the parameters file and exports.
///
/// With an attitude reference in the recording (qw..qz plus the world field, or rx,ry,rz) the vector method of the
/// seed paper fits every component; without one, the scalar (ellipsoid) method fits the magnitude only.
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
    #[arg(long, value_enum, default_value_t = MethodArg::Auto)]
    method: MethodArg,
    /// World field N,E,D in µT (overrides the recording's field_ned_ut).
    #[arg(long, value_name = "N,E,D", value_parser = parse3, allow_hyphen_values = true, conflicts_with = "location")]
    field_ned: Option<[f64; 3]>,
    /// Place for the World Magnetic Model: latitude, longitude (degrees), altitude (m). Needs --date.
    #[arg(long, value_name = "LAT,LON,ALT", value_parser = parse3, allow_hyphen_values = true, requires = "date")]
    location: Option<[f64; 3]>,
    /// Date for the World Magnetic Model, YYYY-MM-DD.
    #[arg(long, value_name = "YYYY-MM-DD", requires = "location")]
    date: Option<Date>,
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
    export: Option<ExportArg>,
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
    /// Write SVG plots of the diagnosis here: residual against time before and after, against the blamed channel,
    /// and over the sphere of field directions.
    #[arg(long, value_name = "DIR", conflicts_with = "no_diagnose")]
    plots: Option<PathBuf>,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum MethodArg {
    /// Vector when the recording has an attitude reference, scalar otherwise.
    Auto,
    /// The seed paper's vector method.
    Vector,
    /// Ellipsoid fit (constant |B|).
    Scalar,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum ExportArg {
    /// ArduPilot .param: COMPASS_OFS_*, COMPASS_DIA_*, COMPASS_ODI_*.
    Ardupilot,
    /// PX4 / QGroundControl .params: CAL_MAG0_*.
    Px4,
    /// C header with A and b.
    CHeader,
    /// JSON with A, b and the offset.
    Json,
}

fn parse3(s: &str) -> Result<[f64; 3], String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|x| x.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|e| format!("{s:?}: {e}"))?;
    v.try_into()
        .map_err(|_| format!("expected three comma-separated numbers, got {s:?}"))
}

fn main() -> ExitCode {
    match run(Args::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("magcal-fit: error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn run(args: Args) -> anyhow::Result<()> {
    let rec = Recording::read(&args.recording)?;
    let name = args.recording.display().to_string();
    let field_args = FieldArgs {
        field_ned_ut: args.field_ned,
        location: args
            .location
            .zip(args.date)
            .map(|([lat_deg, lon_deg, alt_m], d)| {
                (
                    Location {
                        lat_deg,
                        lon_deg,
                        alt_m,
                    },
                    d,
                )
            }),
        field_ut: args.field_ut,
    };
    if let Some(f) = args.field_ut
        && !(f > 0.0 && f.is_finite())
    {
        bail!("--field-ut must be a positive number of µT, got {f}");
    }
    let field = resolve(&field_args, &rec.meta)?;
    let method = match args.method {
        MethodArg::Auto => Method::Auto,
        MethodArg::Vector => Method::Vector,
        MethodArg::Scalar => Method::Scalar,
    };
    let cal = calibrate(&rec, method, field, !args.no_diagnose)
        .with_context(|| format!("{name}: cannot calibrate"))?;
    let channels: Vec<String> = rec.currents.iter().map(|c| c.name.clone()).collect();

    let text = summary(&cal, &name);
    let export_to_stdout = args.export.is_some() && args.export_out.is_none();
    if export_to_stdout {
        eprint!("{text}");
    } else {
        print!("{text}");
    }
    if let Some(path) = &args.report {
        let report = Report::new(&cal, &name, &channels);
        write_atomic(path, report.to_json().as_bytes())
            .with_context(|| format!("writing the report {}", path.display()))?;
    }
    if let (Some(dir), Some(d)) = (&args.plots, &cal.diagnosis) {
        for path in write_plots(dir, d)? {
            eprintln!("wrote {}", path.display());
        }
    }
    let model = cal.model();
    if let Some(path) = &args.out {
        let mut params = ParamsFile::new(cal.method().as_str(), &model, &channels);
        params.sensor = rec.meta.sensor.clone();
        params.recording = Some(name.clone());
        params
            .write(path)
            .with_context(|| format!("writing the parameters {}", path.display()))?;
    }
    if let Some(format) = args.export {
        let format = match format {
            ExportArg::Ardupilot => ExportFormat::Ardupilot,
            ExportArg::Px4 => ExportFormat::Px4,
            ExportArg::CHeader => ExportFormat::CHeader,
            ExportArg::Json => ExportFormat::Json,
        };
        let text = export(&model, format);
        match &args.export_out {
            Some(path) => write_atomic(path, text.as_bytes())
                .with_context(|| format!("writing {}", path.display()))?,
            None => std::io::stdout().write_all(text.as_bytes())?,
        }
    }
    if let Some(device) = &args.write_to {
        for line in write_back_calibration(device, &cal)? {
            if export_to_stdout {
                eprintln!("{line}");
            } else {
                println!("{line}");
            }
        }
    }
    Ok(())
}
