//! `magcal-sim`: write a simulated magcal-recording v1 file.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context, bail};
use clap::{Parser, ValueEnum};
use magcal_app::cli::{excerpt, exit, parse, parse_floats};
use magcal_app::device::within;
use magcal_app::effect_spec::{self, Defaults};
use magcal_app::outputs::{Guard, Replace};
use magcal_app::sim_options::{MAX_NOISE_UT, SimNumbers, parse_noise_kind};
use magcal_app::tellln;
use magcal_app::truth::TruthFile;
use magcal_calib::effects::EffectId;
use magcal_sim::study;
use magcal_sim::{
    AttitudeOutput, ChipModel, CurrentProfile, NoiseKind, Scenario, SensorTruth,
    TemperatureProfile, Trajectory, simulate, stream_rng,
};

/// Write a simulated recording (magcal-recording v1) of a magnetometer turned on the bench.
///
/// The sensor's errors are drawn from --seed; --effect injects physics the 12-parameter model leaves out (the
/// catalogue of magcal-fit's diagnosis). --truth writes what a fit should find.
#[derive(Parser, Debug)]
#[command(version)]
struct Args {
    /// Output recording (a new file, or one magcal-sim made: no other recording is replaced).
    #[arg(long, short, value_name = "REC.csv")]
    out: PathBuf,
    /// Chip to simulate (resolution, noise, temperature sensor, rate): lis3mdl, lis2mdl, qmc5883l, hmc5883l,
    /// mmc5983ma.
    #[arg(long, default_value = "lis3mdl")]
    chip: String,
    /// Attitude trajectory.
    #[arg(long, value_enum, default_value_t = Routine::Tumble)]
    routine: Routine,
    /// Length of the tumble or turntable run, s.
    #[arg(allow_negative_numbers = true, long, default_value_t = 120.0)]
    duration: f64,
    /// Sample rate, Hz (default: the chip's).
    #[arg(allow_negative_numbers = true, long)]
    rate: Option<f64>,
    /// Seed of every random draw.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// World field N,E,D in µT.
    #[arg(long, value_name = "N,E,D", value_parser = parse_floats::<3>, allow_hyphen_values = true)]
    field_ned: Option<[f64; 3]>,
    /// White noise per axis, µT (default: the chip's).
    #[arg(allow_negative_numbers = true, long)]
    noise: Option<f64>,
    /// The noise's distribution, scaled to --noise: gaussian, t:DOF (Student's t, heavier tails) or
    /// spikes:PER_SAMPLE:SIGMAS (Gaussian and a one-sample spike of SIGMAS standard deviations with that probability).
    #[arg(long, value_name = "KIND", value_parser = parse_noise_kind, default_value = "gaussian")]
    noise_kind: NoiseKind,
    /// Random sensor errors: soft iron (relative), hard iron (µT), misalignment (degrees).
    #[arg(long, value_name = "SOFT,HARD,MOUNT", value_parser = parse_floats::<3>, default_value = "0.1,30,3")]
    errors: [f64; 3],
    /// Attitude reference recorded.
    #[arg(long, value_enum, default_value_t = Reference::Quaternion)]
    reference: Reference,
    /// Record a gyro with this noise, rad/s.
    #[arg(allow_negative_numbers = true, long)]
    gyro_noise: Option<f64>,
    /// Temperature: START °C warming by RISE °C with time constant TAU s, wobbling by WOBBLE °C with period
    /// PERIOD s.
    #[arg(long, value_name = "START,RISE,TAU,WOBBLE,PERIOD", value_parser = parse_floats::<5>)]
    temperature: Option<[f64; 5]>,
    /// A current channel switching on and off at random: NAME:ON_A,MEAN_ON_S,MEAN_OFF_S (repeatable).
    #[arg(long, value_name = "NAME:ON_A,MEAN_ON_S,MEAN_OFF_S", value_parser = parse_current)]
    current: Vec<CurrentProfile>,
    /// Inject an effect: ID:NAME=V[,V,V][;NAME=V…] with the report's names, e.g.
    /// "time_lag:lag_s=0.01" or "temperature_bias:coef_ut_per_c=0.05,0,0" (repeatable).
    #[arg(long, value_name = "SPEC")]
    effect: Vec<String>,
    /// Inject an effect of the catalogue in a random physical shape (drawn from --seed), scaled to SIZE µT RMS per
    /// axis over the recording: ID:SIZE (repeatable).
    #[arg(long, value_name = "ID:SIZE_UT")]
    effect_rms: Vec<String>,
    /// Where the attitude reference's north (a cube jig's edge, a capture volume's axes) points, degrees east of
    /// true north (negative: west): the attitude is recorded against it, the sensor turns in the true field.
    #[arg(
        allow_negative_numbers = true,
        long,
        default_value_t = 0.0,
        value_name = "DEG"
    )]
    reference_heading: f64,
    /// Write the truth (A, b, noise, effects as specs) to this TOML file.
    #[arg(long, value_name = "TRUTH.toml")]
    truth: Option<PathBuf>,
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

fn parse_current(s: &str) -> Result<CurrentProfile, String> {
    let (name, rest) = s
        .split_once(':')
        .ok_or_else(|| format!("{}: expected NAME:ON_A,MEAN_ON_S,MEAN_OFF_S", excerpt(s)))?;
    let [on_a, mean_on_s, mean_off_s] = parse_floats::<3>(rest)?;
    let name = if name.starts_with("i_") {
        name.to_owned()
    } else {
        format!("i_{name}")
    };
    Ok(CurrentProfile {
        name,
        on_a,
        mean_on_s,
        mean_off_s,
    })
}

fn main() -> ExitCode {
    exit("magcal-sim", run(parse()))
}

fn run(args: Args) -> anyhow::Result<()> {
    Guard::new("magcal-sim")
        .file(
            "--out",
            Some(&args.out),
            Replace::Remakes("simulated", "magcal-sim"),
        )
        .file("--truth", args.truth.as_deref(), Replace::Products)
        .check()?;
    let Some(chip) = ChipModel::by_name(&args.chip) else {
        bail!(
            "unknown chip {}: use one of lis3mdl, lis2mdl, qmc5883l, hmc5883l, mmc5983ma",
            excerpt(&args.chip)
        );
    };
    // Every number in its range before anything is simulated or allocated.
    SimNumbers {
        duration_s: args.duration,
        rate_hz: args.rate.unwrap_or(chip.rate_hz),
        noise_ut: args.noise,
        gyro_noise_rad_s: args.gyro_noise,
        errors: args.errors,
        field_ned_ut: args.field_ned,
        temperature: args.temperature,
        currents: &args.current,
    }
    .check()?;
    within(
        "--reference-heading",
        args.reference_heading,
        -180.0,
        180.0,
        "°",
    )?;
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
    s.noise_kind = args.noise_kind;
    let [soft, hard, mount] = args.errors;
    s.sensor = SensorTruth::random(soft, hard, mount, &mut stream_rng(args.seed, 0));
    s.attitude = match args.reference {
        Reference::Quaternion => AttitudeOutput::Quaternion,
        Reference::Field => AttitudeOutput::ReferenceField,
        Reference::None => AttitudeOutput::None,
    };
    s.gyro_noise_rad_s = args.gyro_noise;
    s.reference_heading_deg = args.reference_heading;
    if let Some([start_c, warmup_c, tau_s, wobble_c, wobble_period_s]) = args.temperature {
        s.temperature = Some(TemperatureProfile {
            start_c,
            warmup_c,
            tau_s,
            wobble_c,
            wobble_period_s,
            wobble_phase_rad: 0.0,
        });
        s.temp_lsb_c = s.temp_lsb_c.or(Some(0.01));
    }
    s.currents = args.current;
    let names: Vec<String> = s.currents.iter().map(|c| c.name.clone()).collect();
    let defaults = Defaults {
        t_ref_c: s.temperature.map_or(25.0, |t| t.start_c),
        field_drift_t_ref_s: study::duration_s(&s) / 2.0,
        currents: &names,
    };
    s.effects = args
        .effect
        .iter()
        .map(|e| effect_spec::parse(e, &defaults))
        .collect::<Result<_, _>>()?;
    for spec in &args.effect_rms {
        let (id, size) = spec
            .split_once(':')
            .with_context(|| format!("--effect-rms {}: expected ID:SIZE_UT", excerpt(spec)))?;
        let id = EffectId::parse(id).with_context(|| {
            format!(
                "--effect-rms {}: unknown effect {}",
                excerpt(spec),
                excerpt(id)
            )
        })?;
        let size: f64 = size
            .parse()
            .ok()
            .filter(|v: &f64| (0.0..=MAX_NOISE_UT).contains(v))
            .with_context(|| {
                format!(
                    "--effect-rms {}: {} is not a size in µT from 0 to {MAX_NOISE_UT}",
                    excerpt(spec),
                    excerpt(size)
                )
            })?;
        let shape = study::random_effect(id, &s, args.seed);
        let effect = study::scale_to_rms(&s, &shape, size);
        if !effect.params().0.iter().all(|v| v.is_finite()) {
            anyhow::bail!(
                "--effect-rms {}: {} does not change the readings of this bench, so it cannot be scaled to {size} µT \
                 (temperature effects need --temperature, current effects --current)",
                excerpt(spec),
                id.as_str()
            );
        }
        s.effects.push(effect);
    }
    let run = simulate(&s)?;
    run.recording
        .write(&args.out)
        .with_context(|| format!("writing {}", args.out.display()))?;
    if let Some(path) = &args.truth {
        let effects: Vec<String> = s
            .effects
            .iter()
            .map(|e| effect_spec::format(e, &names))
            .collect();
        TruthFile::of_scenario(&s, effects)
            .write(path)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    tellln!(
        "wrote {} samples to {}",
        run.recording.len(),
        args.out.display()
    );
    Ok(())
}
