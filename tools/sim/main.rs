//! `magcal-sim`: write a simulated magcal-recording v1 file.

use std::path::PathBuf;

use anyhow::{Context, bail};
use clap::{Parser, ValueEnum};
use magcal_sim::{
    AttitudeOutput, ChipModel, Scenario, SensorTruth, TemperatureProfile, Trajectory, simulate,
};

/// Write a simulated recording (magcal-recording v1) of a magnetometer turned on the bench.
///
/// The sensor's true calibration, the effects injected and the seed go to the recording's metadata comments and,
/// with --truth, to a TOML file, so a fit can be checked against them.
#[derive(Parser, Debug)]
#[command(version, about)]
struct Args {
    /// Output recording.
    #[arg(long, short)]
    out: PathBuf,
    /// Chip to simulate (resolution, noise, temperature sensor, rate).
    #[arg(long, default_value = "lis3mdl")]
    chip: String,
    /// Attitude trajectory.
    #[arg(long, value_enum, default_value_t = Routine::Tumble)]
    routine: Routine,
    /// Length of the tumble or turntable run, s.
    #[arg(long, default_value_t = 120.0)]
    duration: f64,
    /// Sample rate, Hz (default: the chip's).
    #[arg(long)]
    rate: Option<f64>,
    /// Seed of every random draw.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// World field N,E,D in µT.
    #[arg(long, value_parser = parse3, allow_hyphen_values = true)]
    field_ned: Option<[f64; 3]>,
    /// White noise per axis, µT (default: the chip's).
    #[arg(long)]
    noise: Option<f64>,
    /// Random sensor errors: soft iron (relative), hard iron (µT), misalignment (degrees).
    #[arg(long, value_parser = parse3, default_value = "0.1,30,3")]
    errors: [f64; 3],
    /// Attitude reference recorded.
    #[arg(long, value_enum, default_value_t = Reference::Quaternion)]
    reference: Reference,
    /// Record a gyro with this noise, rad/s.
    #[arg(long)]
    gyro_noise: Option<f64>,
    /// Temperature: warm-up from START by RISE °C with time constant TAU s.
    #[arg(long, value_parser = parse3)]
    warmup: Option<[f64; 3]>,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum Routine {
    /// Smooth random tumble through all orientations.
    Tumble,
    /// The 24 static poses of a cube jig (2 s each).
    Cube24,
    /// A single-axis turntable (refused by the fitter: planar rotation).
    Turntable,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum Reference {
    /// qw,qx,qy,qz plus field_ned_ut in the metadata.
    Quaternion,
    /// rx,ry,rz (expected field in sensor axes).
    Field,
    /// None (scalar calibration only).
    None,
}

fn parse3(s: &str) -> Result<[f64; 3], String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|x| x.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|e| e.to_string())?;
    v.try_into()
        .map_err(|_| format!("expected three comma-separated numbers, got {s:?}"))
}

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    let Some(chip) = ChipModel::by_name(&args.chip) else {
        bail!(
            "unknown chip {:?}: use one of lis3mdl, lis2mdl, qmc5883l, hmc5883l, mmc5983ma",
            args.chip
        );
    };
    let trajectory = match args.routine {
        Routine::Tumble => Trajectory::Tumble {
            duration_s: args.duration,
            rate_rad_s: 1.0,
        },
        Routine::Cube24 => Trajectory::Cube24 {
            dwell_s: 2.0,
            transition_s: 3.0,
        },
        Routine::Turntable => Trajectory::Turntable {
            duration_s: args.duration,
            rate_deg_s: 20.0,
            tilt_deg: 0.0,
        },
    };
    let mut s = Scenario::new(&chip, trajectory, args.seed);
    if let Some(r) = args.rate {
        s.sample_rate_hz = r;
    }
    if let Some(f) = args.field_ned {
        s.field_ned_ut = f;
    }
    if let Some(n) = args.noise {
        s.noise_ut = [n; 3];
    }
    let [soft, hard, mount] = args.errors;
    s.sensor = SensorTruth::random(soft, hard, mount, &mut magcal_sim::stream_rng(args.seed, 0));
    s.attitude = match args.reference {
        Reference::Quaternion => AttitudeOutput::Quaternion,
        Reference::Field => AttitudeOutput::ReferenceField,
        Reference::None => AttitudeOutput::None,
    };
    s.gyro_noise_rad_s = args.gyro_noise;
    if let Some([start, rise, tau]) = args.warmup {
        s.temperature = Some(TemperatureProfile {
            warmup_c: rise,
            tau_s: tau,
            ..TemperatureProfile::constant(start)
        });
    }
    let mut run = simulate(&s)?;
    let a = s.sensor.a;
    run.recording.meta.other.push((
        "truth".to_owned(),
        format!("A = {a:?}, b_ut = {:?}", s.sensor.b_ut),
    ));
    run.recording
        .write(&args.out)
        .with_context(|| format!("writing {}", args.out.display()))?;
    eprintln!(
        "wrote {} samples to {}",
        run.recording.len(),
        args.out.display()
    );
    Ok(())
}
