//! `magcal-fit`: fit a calibration to a recording, report it, write the parameters.

use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context, bail};
use clap::Parser;
use magcal_app::cli::{WorldFieldOpts, exit, parse};
use magcal_app::device::DeviceSpec;
use magcal_app::export::{ExportFormat, export, mirror_refusal, refusal, warnings};
use magcal_app::files::write_atomic;
use magcal_app::fit::Method;
use magcal_app::flight::LogOptions;
use magcal_app::howto::{Target, how_to_apply};
use magcal_app::motors::{MotorsRequest, fit_motors_file, is_motors_recording};
use magcal_app::outputs::{Guard, Replace};
use magcal_app::params::ParamsFile;
use magcal_app::plots::{PLOT_FILES, not_written, write_plots, write_readings_plot};
use magcal_app::report::Report;
use magcal_app::summary::summary_with_report;
use magcal_app::units::ChipOption;
use magcal_app::verdict::{Grade, target_model};
use magcal_app::workflow::{FitRequest, Fitted, NotFitted, fit_file};
use magcal_app::writeback::{write_back_autopilot, write_back_calibration};
use magcal_app::{say, tell, tellln};

/// Fit a magnetometer calibration to a recording, say how far off a compass would be before and after, and write it out.
///
/// The calibration is B = A·raw + b. The summary opens with the heading error (degrees) the raw readings have and the
/// calibration leaves, and a verdict — good, usable or redo — with the reason and what to do; --require good makes
/// anything less exit non-zero (the report and plots are still written, the parameters and exports are not).
///
/// With an attitude reference in the recording (qw..qz plus the world field, or rx,ry,rz) the vector method of the
/// seed paper fits every component; without one, the scalar (ellipsoid) method fits the magnitude only. The
/// diagnosis then looks for the physics the 12-parameter model leaves out (temperature, currents, a timing lag,
/// drifts, a wrong reference field, non-linearity, a step, a transient magnet), models what it finds, and shows
/// the fit improve on held-out data.
///
/// Workflow: magcal-record (or magcal-sim) writes the recording, magcal-fit fits it.
///
/// A bench motor test (a recording whose metadata says routine: motors, from magcal-record --routine motors) is no
/// calibration: the vehicle was held still. Its fit is the current term alone — the field's change per amp of the
/// battery current on each axis (current_bias, µT/A, with standard errors), the lag if the data identify one, and
/// the heading error it makes at hover and at full current — with --params PARAMS.toml (a rotation recording's fit)
/// applied first for calibrated µT/A. --report writes it as JSON; --export ardupilot|px4 writes the motor
/// compensation (COMPASS_MOT_* with COMPASS_MOTCT 2; CAL_MAG0_*COMP with CAL_MAG_COMP_TYP 2), and --write-to
/// mavlink:… with --undo-out UNDO.param sets it in the flight controller, as a calibration's write-back does.
///
/// With --write-to DEV the fitted parameters also go to the device, after the files are written, and are verified:
/// serial:PATH[:BAUD] gets MotionCal's calibration packet, confirmed by the firmware's Cal1:/Cal2:
/// echo; i2c:/dev/i2c-N:lis2mdl[@ADDR] (or sim:lis2mdl) gets the hard-iron offset in its offset registers, read back.
/// The other chips have no place for a calibration: that is an error, and the parameters file is the way.
/// mavlink:PATH[:BAUD][:ardupilot|px4] (or mavlink:udp:HOST:PORT) is a flight controller: the --export ardupilot|px4 parameters for the
/// autopilot its heartbeat names, its previous values saved first to an undo file (--undo-out, by default next to
/// --out), each parameter confirmed and read back; a refused one sets back what was written and exits non-zero.
#[derive(Parser, Debug)]
#[command(version)]
struct Args {
    /// The recording (magcal-recording v1 CSV), or a PX4 flight log (.ulg): its magnetometer with the logged
    /// calibration undone, the attitude, the battery current, the place and date of its GPS fix.
    recording: PathBuf,
    /// For a flight log: the magnetometer to fit, by its number in the list printed (default: the one the autopilot
    /// used).
    #[arg(long, value_name = "N")]
    mag: Option<usize>,
    /// Calibration method.
    #[arg(long, value_enum, default_value_t = Method::Auto)]
    method: Method,
    /// The world field (otherwise the recording's metadata says it).
    #[command(flatten)]
    field: WorldFieldOpts,
    /// Field magnitude in µT, for the scalar method: it replaces a field vector from the recording's metadata (so
    /// only |B| is fitted); --field-ned replaces the vector instead.
    #[arg(allow_negative_numbers = true, long, value_name = "UT")]
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
    /// Write the calibration to this device and verify it: serial:PATH[:BAUD] (MotionCal packet,
    /// confirmed by the echo), i2c:/dev/i2c-N:lis2mdl[@ADDR] / sim:lis2mdl (offset registers, read back) or
    /// mavlink:PATH[:BAUD][:ardupilot|px4] or mavlink:udp:HOST:PORT[:ardupilot|px4] (a flight controller's
    /// compass parameters, set and read back).
    #[arg(long, value_name = "DEV")]
    write_to: Option<DeviceSpec>,
    /// With --write-to mavlink:…: where the autopilot's previous values go, as a parameter file it can load to undo
    /// the write-back (default: next to --out, PARAMS.undo.param); never replaces a file.
    #[arg(long, value_name = "UNDO.param", requires = "write_to")]
    undo_out: Option<PathBuf>,
    /// Skip the diagnosis (what physics the 12-parameter model leaves out).
    #[arg(long)]
    no_diagnose: bool,
    /// Write SVG plots into this directory (created if needed): the readings before and after (ellipsoid and
    /// sphere), the heading error against heading, the residual against time and over the field directions (and
    /// against the blamed channel).
    #[arg(long, value_name = "DIR")]
    plots: Option<PathBuf>,
    /// Exit non-zero unless the verdict is at least this (good or usable); the parameters file, exports and
    /// write-back are then skipped.
    #[arg(long, value_enum, value_name = "GRADE")]
    require: Option<Grade>,
    /// The chip whose raw counts the readings are, for a board that prints counts instead of µT: CHIP[:SETTING],
    /// e.g. qmc5883l (±8 G, 3000 LSB/G, or qmc5883l:2g, 12000), hmc5883l (±1.3 G, 1090 LSB/G, or hmc5883l:0.88g …
    /// 8.1g), lis3mdl (4g … 16g), lis2mdl, mmc5983ma (18bit or 16bit). The autopilot exports need it to convert
    /// counts to gauss as their drivers do; with the field known, the setting that fits it is taken unless stated.
    #[arg(long, value_name = "CHIP[:SETTING]")]
    chip: Option<ChipOption>,
    /// For a bench motor test (routine: motors): the sensor's calibration, fitted from a rotation recording, applied
    /// before the current term is fitted, so that it is in calibrated µT/A.
    #[arg(long, value_name = "PARAMS.toml")]
    params: Option<PathBuf>,
}

fn main() -> ExitCode {
    exit("magcal-fit", run(parse()))
}

/// Where a write-back to a flight controller saves its previous values: --undo-out, or next to --out; `None` for
/// other devices. A flight controller without either is an error.
fn undo_path(args: &Args) -> anyhow::Result<Option<PathBuf>> {
    if !matches!(args.write_to, Some(DeviceSpec::Mavlink { .. })) {
        if args.undo_out.is_some() {
            bail!(
                "--undo-out is for --write-to mavlink:…, whose previous parameter values it holds"
            );
        }
        return Ok(None);
    }
    let path = match (&args.undo_out, &args.out) {
        (Some(path), _) => path.clone(),
        (None, Some(out)) => out.with_extension("undo.param"),
        (None, None) => bail!(
            "--write-to mavlink:… saves the autopilot's previous values to an undo file first, next to the \
             parameters file: give --out PARAMS.toml (or --undo-out UNDO.param); nothing was read or written"
        ),
    };
    Ok(Some(path))
}

/// An undo file is never replaced: it may hold the autopilot's values from before an earlier write-back. (Checked
/// after the guard, which says first when the path holds a recording or an input.)
fn undo_is_new(undo: Option<&std::path::Path>) -> anyhow::Result<()> {
    if let Some(path) = undo
        && std::fs::symlink_metadata(path).is_ok()
    {
        bail!(
            "--undo-out {}: the file exists, and may hold the autopilot's values from before an earlier write-back: \
             move it, or name another with --undo-out; nothing was read or written",
            path.display()
        );
    }
    Ok(())
}

/// Fits a bench motor test: the current term alone (see the tool's help), its summary, `--report` and
/// `--export ardupilot|px4`; the options of a calibration are refused.
fn run_motors(args: &Args) -> anyhow::Result<()> {
    let name = args.recording.display().to_string();
    for (given, option) in [
        (args.out.is_some(), "--out"),
        (args.plots.is_some(), "--plots"),
        (args.require.is_some(), "--require"),
        (args.chip.is_some(), "--chip"),
        (args.mag.is_some(), "--mag"),
        (args.field_ut.is_some(), "--field-ut"),
        (args.method != Method::Auto, "--method"),
        (args.no_diagnose, "--no-diagnose"),
    ] {
        if given {
            bail!(
                "{option} does not apply to {name}: it is a bench motor test (routine: motors), whose fit is the \
                 current term alone, not a calibration (--report, --export ardupilot|px4 and --write-to mavlink:… \
                 carry it)"
            );
        }
    }
    let undo = match (&args.write_to, &args.undo_out) {
        (Some(DeviceSpec::Mavlink { .. }), Some(path)) => Some(path.as_path()),
        (Some(DeviceSpec::Mavlink { .. }), None) => bail!(
            "--write-to mavlink:… saves the autopilot's previous values to an undo file first: give --undo-out \
             UNDO.param; nothing was read or written"
        ),
        (Some(device), _) => bail!(
            "--write-to {device}: a bench motor test's current term goes to a flight controller only \
             (mavlink:PATH[:BAUD] or mavlink:udp:HOST:PORT); nothing was read or written"
        ),
        (None, Some(_)) => bail!(
            "--undo-out is for --write-to mavlink:…, whose previous parameter values it holds"
        ),
        (None, None) => None,
    };
    let mut guard = Guard::new("magcal-fit").input("<RECORDING>", &args.recording);
    if let Some(params) = &args.params {
        guard = guard.input("--params", params);
    }
    guard
        .file("--report", args.report.as_deref(), Replace::Products)
        .file(
            "--export-out",
            args.export_out.as_deref(),
            Replace::Products,
        )
        .file("--undo-out", undo, Replace::Products)
        .check()?;
    undo_is_new(undo)?;
    let field_args = args.field.field_args(None);
    let fitted = fit_motors_file(
        &args.recording,
        &MotorsRequest {
            field: &field_args,
            params: args.params.as_deref(),
        },
    )?;
    let export = args
        .export
        .map(|format| fitted.export(format))
        .transpose()
        .map_err(|why| anyhow::anyhow!("{name}: not exported: {why}"))?;
    let summary = fitted.summary(&name);
    if args.export.is_some() && args.export_out.is_none() {
        tell!("{summary}");
    } else {
        say!("{summary}")?;
    }
    if let Some(path) = &args.report {
        let text = serde_json::to_string_pretty(&fitted.report(&name))? + "\n";
        write_atomic(path, text.as_bytes())
            .with_context(|| format!("writing the report {}", path.display()))?;
    }
    if let Some(text) = export {
        match &args.export_out {
            Some(path) => write_atomic(path, text.as_bytes())
                .with_context(|| format!("writing {}", path.display()))?,
            None => std::io::stdout().write_all(text.as_bytes())?,
        }
    }
    if let (Some(device), Some(undo)) = (&args.write_to, undo) {
        for line in fitted.write_back(device, undo)? {
            tellln!("{line}");
        }
    }
    Ok(())
}

/// Refuses outputs that would overwrite the recording, each other or another recording, files that cannot be made
/// (a missing folder, a folder's name), or plots into a file's place, before anything is read or written.
fn check_paths(args: &Args, undo: Option<&std::path::Path>) -> anyhow::Result<()> {
    Ok(Guard::new("magcal-fit")
        .input("<RECORDING>", &args.recording)
        .file("--out", args.out.as_deref(), Replace::Products)
        .file("--report", args.report.as_deref(), Replace::Products)
        .file(
            "--export-out",
            args.export_out.as_deref(),
            Replace::Products,
        )
        .folder(
            "--plots",
            args.plots.as_deref(),
            &PLOT_FILES,
            Replace::Products,
        )
        .file("--undo-out", undo, Replace::Products)
        .check()?)
}

fn run(args: Args) -> anyhow::Result<()> {
    if is_motors_recording(&args.recording) {
        return run_motors(&args);
    }
    if args.params.is_some() {
        bail!(
            "--params is for a bench motor test (a recording of magcal-record --routine motors), and {} is not one; \
             to check parameters on a recording, use magcal-apply PARAMS.toml RECORDING",
            args.recording.display()
        );
    }
    let undo = undo_path(&args)?;
    check_paths(&args, undo.as_deref())?;
    undo_is_new(undo.as_deref())?;
    let name = args.recording.display().to_string();
    if let Some(f) = args.field_ut
        && !(f > 0.0 && f.is_finite())
    {
        bail!("--field-ut must be a positive number of µT, got {f}");
    }
    let field_args = args.field.field_args(args.field_ut);
    let request = FitRequest {
        method: args.method,
        diagnose: !args.no_diagnose,
        field: &field_args,
        linear_only: args.export.is_some() || args.write_to.is_some(),
        chip: args.chip.clone(),
        log: LogOptions { mag: args.mag },
    };
    let Fitted {
        rec,
        cal,
        assessment,
    } = match fit_file(&args.recording, &request) {
        Ok(fitted) => fitted,
        Err(NotFitted::Unread(e)) => return Err(e),
        Err(NotFitted::Refused { rec, error }) => {
            // A refused fit still shows its readings: a recording that did not turn enough is plain to see.
            if let Some(dir) = &args.plots {
                tellln!("wrote {}", write_readings_plot(dir, &rec)?.display());
            }
            return Err(error).with_context(|| format!("{name}: cannot calibrate"));
        }
    };

    // With the export on stdout, everything else goes to stderr.
    let export_to_stdout = args.export.is_some() && args.export_out.is_none();
    let say = |text: &str| {
        if export_to_stdout {
            tell!("{text}");
            Ok(())
        } else {
            say!("{text}")
        }
    };
    say(&summary_with_report(
        &cal,
        &assessment,
        &name,
        args.report.as_deref(),
    ))?;
    if let Some(path) = &args.report {
        let channels: Vec<String> = rec.currents.iter().map(|c| c.name.clone()).collect();
        Report::new(&cal, &name, &channels)
            .with_assessment(&assessment)
            .write(path)?;
    }
    if let Some(dir) = &args.plots {
        for path in write_plots(dir, &cal, &rec, &assessment)? {
            tellln!("wrote {}", path.display());
        }
        for why in not_written(&cal, &rec, &assessment) {
            tellln!("{why}");
        }
    }
    let grade = assessment.verdict.grade;
    if let Some(required) = args.require
        && grade < required
    {
        bail!(
            "the verdict is {}, and --require {} was given: no parameters file, export or write-back",
            grade.name(),
            required.name()
        );
    }
    if let Some(path) = &args.out {
        let params = ParamsFile::of(&cal, &rec, &name);
        params
            .write(path)
            .with_context(|| format!("writing the parameters {}", path.display()))?;
        for c in &params.comments {
            tellln!("note: {}: {c}", path.display());
        }
    }
    // Exports and devices hold A and b only: the base fit when the final model has corrections.
    let target = target_model(&cal);
    if cal.raw_not_ut
        && let Some(device) = &args.write_to
    {
        bail!(
            "{name}: not written to {device}: the raw readings are not µT (said above), and a device takes its offset \
             in µT; record through the device's own unit (a serial board's :unit= or :scale=, or an I2C chip, which \
             magcal reads in µT) and fit that"
        );
    }
    if cal.reference_doubtful() && (args.export.is_some() || args.write_to.is_some()) {
        bail!(
            "{name}: not exported or written: the readings do not fit the attitude reference as given (the WARNING \
             above), so A and b are not a calibration; fix the reference and fit again"
        );
    }
    let found = cal.diagnosis.as_ref().map_or(&[][..], |d| &d.effects[..]);
    if let Some(format) = args.export {
        if let Some(why) = refusal(&target, format, &cal.units) {
            bail!("{name}: not exported: {why}");
        }
        for warning in warnings(&target, format, &cal.units) {
            say(&format!("  WARNING: {warning}\n"))?;
        }
        let text = export(&target, format, found, &cal.units);
        match &args.export_out {
            Some(path) => write_atomic(path, text.as_bytes())
                .with_context(|| format!("writing {}", path.display()))?,
            None => std::io::stdout().write_all(text.as_bytes())?,
        }
    }
    if let Some(device) = &args.write_to {
        if let (DeviceSpec::Serial(_), Some(why)) = (device, mirror_refusal(&target)) {
            bail!("{name}: not written to {device}: {why}");
        }
        let lines = match (device, &undo) {
            (DeviceSpec::Mavlink { .. }, Some(undo)) => write_back_autopilot(device, &cal, undo)?,
            _ => write_back_calibration(device, &cal, rec.meta.sensor.as_deref())?,
        };
        for line in lines {
            say(&format!("{line}\n"))?;
        }
    }
    let where_to = match (&args.write_to, args.export) {
        (Some(device), _) => Target::Device(device),
        (None, Some(format)) => Target::Export {
            format,
            path: args.export_out.as_deref(),
        },
        (None, None) => Target::None,
    };
    // A fit against a doubtful reference is no calibration: nothing to put to use.
    if !cal.reference_doubtful() {
        say(&format!(
            "\n{}",
            how_to_apply(where_to, args.out.as_deref(), found, &cal.units)
        ))?;
    }
    Ok(())
}
