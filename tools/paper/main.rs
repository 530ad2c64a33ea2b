//! `magcal-paper`: the seed paper's experiment, simulated, printed in the form of its table.

use std::process::ExitCode;

use clap::Parser;
use magcal_app::cli::{exit, parse};
use magcal_app::say;
use magcal_app::seed::{SeedExperiment, run, table};

/// Simulate the seed paper's experiment (a sensor whose distortion is the inverse of the paper's a, b, mounted a few
/// degrees off the reference axes) and print vector against scalar calibration in the form of the paper's table.
#[derive(Parser, Debug)]
#[command(version)]
struct Args {
    /// Mounting misalignment, degrees (−180 to 180).
    #[arg(allow_negative_numbers = true, long, default_value_t = SeedExperiment::default().mount_deg)]
    mount_deg: f64,
    /// Raw noise per axis, µT (0 to 10: the experiment's field is 50 µT).
    #[arg(allow_negative_numbers = true, long, default_value_t = SeedExperiment::default().noise_ut)]
    noise: f64,
    /// Seed.
    #[arg(long, default_value_t = SeedExperiment::default().seed)]
    seed: u64,
}

fn main() -> ExitCode {
    exit("magcal-paper", paper(parse()))
}

fn paper(args: Args) -> anyhow::Result<()> {
    let exp = SeedExperiment {
        mount_deg: args.mount_deg,
        noise_ut: args.noise,
        seed: args.seed,
        ..SeedExperiment::default()
    };
    exp.check()?;
    say!("{}", table(&run(&exp)?))?;
    Ok(())
}
