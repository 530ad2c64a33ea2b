//! `magcal`: the bench calibration workflow in one command: record, fit, report.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context, bail};
use clap::Parser;
use magcal_app::cli::{WorldFieldOpts, exit, interrupt_flag, parse};
use magcal_app::device::{self, DeviceSpec, OpenOptions};
use magcal_app::fit::{Calibration, Fit, Method};
use magcal_app::outputs::{Guard, Replace};
use magcal_app::params::ParamsFile;
use magcal_app::record::{
    RecordOptions, Routine, Stop, device_metadata, record, sim_field_note, ui,
};
use magcal_app::report::Report;
use magcal_app::source::sim::TruthFile;
use magcal_app::summary::summary_with_report;
use magcal_app::workflow::{FitRequest, Fitted, NotFitted, fit_file};
use magcal_app::{say, sayln, tellln};

/// The bench calibration workflow in one command: record the magnetometer through a routine, fit the calibration
/// B = A·raw + b, print the summary, and write MAGCAL-OUT/recording.csv, params.toml and report.json.
///
/// With no arguments it runs on a simulated LIS3MDL (no hardware needed): a virtual hand puts it through the 24
/// poses of a cube jig, and the fit is compared with the simulated sensor's true errors.
///
/// With a real chip, turned by hand (the free routine, the default for a real device: no jig needed):
///   magcal --device i2c:/dev/i2c-1:lis3mdl --location 52.2,0.1,20 --date 2026-11-21
///   magcal --device serial:/dev/ttyACM0
/// With a non-magnetic cube jig against an edge on a known heading (the vector calibration):
///   magcal --device i2c:/dev/i2c-1:lis3mdl --routine cube24 --location 52.2,0.1,20 --date 2026-11-21
///
/// Devices: sim[:CHIP] | i2c:/dev/i2c-N:CHIP[@ADDR] | serial:PATH[:BAUD][:FORMAT], CHIP one of lis3mdl, lis2mdl,
/// qmc5883l, hmc5883l, mmc5983ma, FORMAT one of motioncal, csv, adafruit, xyz, pattern=REGEX (magcal-record --help
/// says more). The separate tools (magcal-record, magcal-fit) offer every option.
#[derive(Parser, Debug)]
#[command(version, verbatim_doc_comment)]
struct Args {
    /// The device: sim[:CHIP] | i2c:/dev/i2c-N:CHIP[@ADDR] | serial:PATH[:BAUD][:FORMAT].
    #[arg(long, default_value = "sim", value_name = "DEV")]
    device: DeviceSpec,
    /// The routine: free (turn it by hand: scalar calibration) or cube24 (a cube jig on a known heading: vector
    /// calibration; needs the local field for real devices) [default: free for a real device, cube24 for sim, whose
    /// bench has its jig].
    #[arg(long, value_enum)]
    routine: Option<Routine>,
    /// Where the recording, parameters and report go.
    #[arg(long, default_value = "magcal-out", value_name = "DIR")]
    out_dir: PathBuf,
    /// Replace a recording already in the output directory (otherwise it is refused, and kept).
    #[arg(long)]
    force: bool,
    /// The local field (for real devices; a simulated bench knows its own).
    #[command(flatten)]
    field: WorldFieldOpts,
    /// sim: seed of the simulated sensor.
    #[arg(long, default_value_t = 1, value_name = "N")]
    sim_seed: u64,
}

/// The option that names magcal's output, said when a recording there is refused.
const OUT_DIR: &str = "--out-dir";
/// The fit's outputs in the folder.
const PARAMS: &str = "params.toml";
const REPORT: &str = "report.json";

fn main() -> ExitCode {
    exit("magcal", run(parse()))
}

fn run(args: Args) -> anyhow::Result<()> {
    let rec_path = args.out_dir.join("recording.csv");
    let routine = args
        .routine
        .unwrap_or_else(|| Routine::default_for(&args.device));
    if routine == Routine::Motors {
        bail!(
            "--routine motors: a bench motor test gives the current term alone, not a calibration; record it with \
             magcal-record --routine motors and fit it with magcal-fit (nothing was recorded)"
        );
    }
    let mut opts = RecordOptions::new(routine, rec_path.clone());
    opts.force = args.force;
    opts.auto = args.device.is_sim();
    // The fit's outputs of an earlier run are not replaced unasked either (its recording may be gone).
    let dir = Some(args.out_dir.as_path());
    Guard::new("magcal")
        .force(args.force)
        .folder(OUT_DIR, dir, &["recording.csv"], Replace::Recording)
        .folder(OUT_DIR, dir, &[PARAMS, REPORT], Replace::New)
        .check()?;
    std::fs::create_dir_all(&args.out_dir)
        .with_context(|| format!("creating {}", args.out_dir.display()))?;

    // Record.
    args.field.write_metadata(&mut opts.meta);
    opts.meta = device_metadata(&args.device, args.sim_seed, opts.meta);
    if let Some(note) = sim_field_note(&args.device, &opts.meta) {
        tellln!("{note}");
    }
    let open = OpenOptions {
        sim_seed: args.sim_seed,
        ..OpenOptions::default()
    };
    let interrupt = interrupt_flag("magcal")?;
    if let Some(note) = args.device.unit_note() {
        tellln!("{note}");
    }
    let mut source = device::open(&args.device, &open)?;
    let mut ui = ui::for_stdout(opts.auto, routine);
    sayln!(
        "magcal: recording {} ({} routine{}) to {}",
        args.device,
        routine.name(),
        match (args.routine, routine) {
            // A motors routine is only ever asked for, and refused above.
            (Some(_), _) | (None, Routine::Motors) => "",
            (None, Routine::Free) =>
                ", the default for a real device: turn it by hand through every direction; --routine cube24 with a \
                 cube jig",
            (None, Routine::Cube24) => ", the simulated bench's jig",
        },
        rec_path.display()
    )?;
    let recorded = record(source.as_mut(), &opts, ui.as_mut(), &interrupt)
        .map_err(|e| e.for_option(OUT_DIR))?;
    sayln!(
        "recorded {} samples in {:.1} s of device time{}",
        recorded.samples,
        recorded.duration_s,
        match recorded.stop {
            Stop::Interrupted => " (interrupted)",
            Stop::MaxDuration => " (longest duration reached)",
            Stop::Coverage | Stop::AllPoses | Stop::Ramps => "",
        }
    )?;
    let short = recorded.shortfall(&opts);
    if recorded.stop == Stop::Interrupted {
        match short {
            Some(short) => bail!(
                "interrupted: the recording {} is kept, but {short}",
                rec_path.display()
            ),
            None => bail!(
                "interrupted: the recording {} is kept; fit it with magcal-fit",
                rec_path.display()
            ),
        }
    }
    if let Some(short) = short {
        tellln!("warning: {short}");
    }

    // Fit.
    let name = rec_path.display().to_string();
    let request = FitRequest {
        method: Method::Auto,
        diagnose: true,
        field: &args.field.field_args(None),
        linear_only: false,
        chip: None,
        log: Default::default(),
    };
    let Fitted {
        rec,
        cal,
        assessment,
    } = match fit_file(&rec_path, &request) {
        Ok(fitted) => fitted,
        Err(NotFitted::Unread(e)) => return Err(e),
        Err(NotFitted::Refused { error, .. }) => {
            return Err(error).with_context(|| format!("{name}: cannot calibrate"));
        }
    };
    let report_path = args.out_dir.join(REPORT);
    say!(
        "\n{}",
        summary_with_report(&cal, &assessment, &name, Some(&report_path))
    )?;
    let channels: Vec<String> = rec.currents.iter().map(|c| c.name.clone()).collect();
    Report::new(&cal, &name, &channels)
        .with_assessment(&assessment)
        .write(&report_path)?;
    let params_path = args.out_dir.join(PARAMS);
    let params = ParamsFile::of(&cal, &rec, &name);
    params
        .write(&params_path)
        .with_context(|| format!("writing {}", params_path.display()))?;
    for c in &params.comments {
        tellln!("note: {}: {c}", params_path.display());
    }
    if let Some(other) = routine.what_the_other_adds() {
        sayln!("note: {other}")?;
    }
    if let DeviceSpec::Sim { chip } = args.device {
        sayln!("{}", truth_check(&cal, &TruthFile::of(chip, args.sim_seed)))?;
    }
    sayln!(
        "wrote {}, {}, {}",
        rec_path.display(),
        params_path.display(),
        report_path.display()
    )?;
    Ok(())
}

/// A vector fit's entries within this many standard errors of the truth pass the check…
const TRUTH_SE: f64 = 3.0;
/// …and a scalar fit's gains within this fraction of the true ones.
const TRUTH_GAIN: f64 = 0.01;

/// How far the fit is from the simulated sensor's truth.
fn truth_check(cal: &Calibration, truth: &TruthFile) -> String {
    let model = cal.model();
    match &cal.fit {
        Fit::Vector(_) => {
            let (a_se, b_se) = cal.standard_errors();
            let mut worst = 0.0f64;
            for j in 0..3 {
                for k in 0..3 {
                    worst = worst.max((model.a[j][k] - truth.a[j][k]).abs() / a_se[j][k]);
                }
                worst = worst.max((model.b_ut[j] - truth.b_ut[j]).abs() / b_se[j]);
            }
            if worst <= TRUTH_SE {
                format!(
                    "simulated truth check: every entry of A and b is within {worst:.2} standard errors of the \
                     simulated sensor's true value"
                )
            } else {
                format!(
                    "simulated truth check FAILED: an entry of A or b is {worst:.1} standard errors from the \
                     simulated sensor's true value (more than {TRUTH_SE}): the fit is wrong for this sensor"
                )
            }
        }
        Fit::Scalar(s) => {
            let c = s.centre_ut();
            let err = (0..3)
                .map(|k| (c[k] - truth.offset_ut[k]).powi(2))
                .sum::<f64>()
                .sqrt();
            // The scalar method sees A up to a rotation: its gains (singular values) against the truth's.
            let gains = |a: &[[f64; 3]; 3]| {
                let mut sv: Vec<f64> = nalgebra::Matrix3::from_fn(|j, k| a[j][k])
                    .singular_values()
                    .iter()
                    .copied()
                    .collect();
                sv.sort_by(f64::total_cmp);
                sv
            };
            let gain_err = gains(&model.a)
                .iter()
                .zip(gains(&truth.a))
                .map(|(g, t)| (g / t - 1.0).abs())
                .fold(0.0, f64::max);
            format!(
                "simulated truth check{}: the hard-iron offset is {err:.3} µT from the simulated sensor's, its gains \
                 within {:.2} % of the true ones (the scalar method cannot see the misalignment)",
                if gain_err > TRUTH_GAIN { " FAILED" } else { "" },
                100.0 * gain_err
            )
        }
    }
}
