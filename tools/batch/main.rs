//! `magcal-batch`: fit a folder of recordings, one table out, with pass/fail per board and the lot's outliers.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::bail;
use clap::Parser;
use magcal_app::batch::{BatchOptions, FitOptions, run, screen};
use magcal_app::cli::{WorldFieldOpts, exit};
use magcal_app::fit::Method;
use magcal_app::say;
use magcal_app::verdict::Grade;

/// Fit every recording of a lot — a folder of them, files, or quoted patterns — and write one table: a row per
/// recording with the board (its `serial` metadata, else the file's name), the verdict, the heading error left,
/// the offset and its standard error, A's diagonal and off-diagonal extremes, the residual against the noise, the
/// coverage, the diagnosis's findings, and for a file that was not fitted, why.
///
/// Then the lot: over the boards of one kind (the `chip` metadata, else `sensor`), the median and robust spread of
/// each parameter, and the boards far from their siblings (robust z above 5) — a board whose offset is fine for its
/// own fit but far from the others' has a magnet or a steel screw near the sensor.
///
/// Recordings are fitted as magcal-fit fits them, several at a time. With --out the table is written as the batch
/// goes: a batch that was stopped (even killed) and is run again with the same --out fits only the recordings not in
/// the table yet, or changed since.
///
/// Example: magcal-batch lot7/ --out lot7.csv --json lot7.json --require usable
#[derive(Parser, Debug)]
#[command(version)]
struct Args {
    /// Recordings, folders of them (their *.csv files, sub-folders included), or quoted patterns ('lot7/*.csv').
    #[arg(required = true, value_name = "DIR|FILE|GLOB")]
    inputs: Vec<PathBuf>,
    /// The table (CSV), written as the batch goes; a batch is resumed from it.
    #[arg(long, value_name = "TABLE.csv")]
    out: Option<PathBuf>,
    /// The table and the lot statistics as JSON.
    #[arg(long, value_name = "TABLE.json")]
    json: Option<PathBuf>,
    /// Exit non-zero unless every board's verdict is at least this (good or usable); the boards that fall short are
    /// listed.
    #[arg(long, value_enum, value_name = "GRADE")]
    require: Option<Grade>,
    /// Recordings fitted at once (default: one per core).
    #[arg(long, short, value_name = "N")]
    jobs: Option<usize>,
    /// Calibration method.
    #[arg(long, value_enum, default_value_t = Method::Auto)]
    method: Method,
    /// Skip the diagnosis (what physics the 12-parameter model leaves out): several times faster.
    #[arg(long)]
    no_diagnose: bool,
    /// The world field for every recording (otherwise each recording's metadata says it).
    #[command(flatten)]
    field: WorldFieldOpts,
    /// Field magnitude in µT, for the scalar method (as magcal-fit's --field-ut).
    #[arg(allow_negative_numbers = true, long, value_name = "UT")]
    field_ut: Option<f64>,
    /// No progress bar.
    #[arg(long)]
    quiet: bool,
}

fn main() -> ExitCode {
    exit("magcal-batch", main_inner(Args::parse()))
}

fn main_inner(args: Args) -> anyhow::Result<()> {
    if let Some(f) = args.field_ut
        && !(f > 0.0 && f.is_finite())
    {
        bail!("--field-ut must be a positive number of µT, got {f}");
    }
    let jobs = match args.jobs {
        Some(0) => bail!("--jobs 0: at least one recording must be fitted at a time"),
        Some(n) => n,
        None => std::thread::available_parallelism().map_or(1, |n| n.get()),
    };
    let opts = BatchOptions {
        inputs: args.inputs,
        fit: FitOptions {
            method: args.method,
            diagnose: !args.no_diagnose,
            field: args.field.field_args(args.field_ut),
        },
        out: args.out,
        json: args.json,
        jobs,
        progress: !args.quiet,
    };
    let batch = run(&opts)?;
    say!("{}", screen::summary(&batch, args.require))?;
    if let Some(required) = args.require {
        let short = screen::falling_short(&batch, required);
        if !short.is_empty() {
            const NAMED: usize = 10;
            let mut ids: Vec<&str> = short.iter().take(NAMED).map(|r| r.id.as_str()).collect();
            if short.len() > NAMED {
                ids.push("…");
            }
            bail!(
                "--require {}: {} of {} boards fall short (listed above): {}",
                required.name(),
                short.len(),
                batch.rows.len(),
                ids.join(", ")
            );
        }
    }
    Ok(())
}
