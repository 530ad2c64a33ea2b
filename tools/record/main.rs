//! `magcal-record`: record a magnetometer while it is turned through a routine, into a magcal-recording v1 file.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context, bail};
use clap::Parser;
use magcal_app::cli::{WorldFieldOpts, exit, interrupt_flag, parse, parse_serial};
use magcal_app::device::{self, DeviceSpec, Fault, OpenOptions};
use magcal_app::field::resolve;
use magcal_app::outputs::{Guard, Replace};
use magcal_app::record::{
    RecordOptions, RecordSummary, Routine, Stop, device_metadata, record, sim_field_note, ui,
};
use magcal_app::source::sim::TruthFile;
use magcal_app::{sayln, tellln};

/// Record a magnetometer while you turn it, into a magcal-recording v1 file for magcal-fit.
///
/// DEVICES (--device):
///   sim[:CHIP]                      a simulated chip (the default: no hardware needed); a virtual hand performs
///                                   the routine
///   i2c:/dev/i2c-N:CHIP[@ADDR]      a chip on a Linux I2C bus, e.g. i2c:/dev/i2c-1:lis3mdl@0x1c
///   serial:PATH[:BAUD][:FORMAT]     a board streaming lines, 115200 baud unless given, e.g. serial:/dev/ttyACM0
///   mavlink:PATH[:BAUD][:ardupilot|px4]
///                                   a flight controller over MAVLink (115200 baud unless given; which autopilot
///                                   from its heartbeat unless named): its compass with the autopilot's own
///                                   calibration undone (the raw field, µT), its attitude, battery current
///                                   (i_battery) and IMU temperature, at --rate asked (the rate got is in the
///                                   metadata)
///   mavlink:udp:HOST:PORT[:ardupilot|px4]
///                                   the same over UDP (a simulator or a telemetry router): this machine's
///                                   HOST:PORT listened on, e.g. mavlink:udp:127.0.0.1:14550; another's, or a
///                                   port taken, sent to
///   CHIP is lis3mdl, lis2mdl, qmc5883l, hmc5883l or mmc5983ma.
///
/// SERIAL FORMATS (the FORMAT of serial:PATH[:BAUD][:FORMAT]):
///   motioncal         Raw:ax,ay,az,gx,gy,gz,mx,my,mz (MotionCal, Adafruit's calibration sketches; the default)
///   csv               magcal's native CSV: a header naming t,mx,my,mz[,temp,qw,qx,qy,qz,…], then data (µT)
///   adafruit          the Adafruit Unified Sensor examples: X: 12.34  Y: -5.67  Z: 40.10  uT
///   xyz               three numbers a line: x,y,z (commas, semicolons, tabs or spaces)
///   pattern=REGEX     any line: a regular expression with named groups mx, my, mz and optionally t (s) or
///                     t_ms (ms), temp (°C), qw, qx, qy, qz (the attitude, sensor to NED; recorded with the
///                     field); searched in each line (anchor it with ^…$); it takes the rest of the device
///                     string, so quote it for the shell
///   xyz and pattern= read µT unless told: add :unit=UNIT (uT, gauss, mG, nT) and/or :scale=K (each printed
///   number times K is in UNIT: raw counts). Examples:
///     serial:/dev/ttyUSB0:9600:xyz:scale=0.0917        HMC5883L counts at ±1.3 G (0.0917 µT each)
///     serial:/dev/ttyUSB0:xyz:unit=gauss:scale=0.0000833   QMC5883L counts at ±2 G (1/12000 G each)
///     'serial:/dev/ttyACM0:unit=gauss:pattern=^M (?P<mx>\S+) (?P<my>\S+) (?P<mz>\S+)$'
///   Lines that are no sample (banners, other chatter, half lines) are counted and skipped.
///
/// ROUTINES (--routine):
///   free    turn the sensor freely through every orientation; a live map shows which directions of the field
///           you have covered; recording stops at the target coverage (--coverage) or on Ctrl-C. Gives a scalar
///           (ellipsoid) calibration.
///   cube24  put the sensor in a non-magnetic cube jig and place it against a reference edge pointing north, in
///           the 24 poses the prompts name (face down, where the edge points); a pose is taken when the jig is
///           still for the dwell time (or when you press Enter). Each pose's attitude is recorded, which gives the
///           vector calibration (every component, misalignment included). Give the local field with --field-ned
///           or --location/--date.
///   motors  a bench motor test on a flight controller (mavlink:…): hold the vehicle still (props off or held
///           down) and raise the throttle slowly to full and back, twice, then blip it ten times (snap it up to
///           high and back after half a second, a second at idle between), yourself — magcal only reads, it never
///           arms the vehicle or commands its motors. The ramps give the coefficients, the blips the lag of the
///           field behind the current. The screen shows the battery current and the field's change since the
///           start; recording stops after two ramps up to 60 % of the highest current and back and ten blips that
///           rise to it within 0.3 s (or --max-duration, or Ctrl-C). magcal-fit then fits the current term alone
///           (µT per A per axis, and the lag) and the heading error it makes. A device without a current is
///           refused.
///
/// THE SCREEN (on a terminal):
///   the coverage map (the sphere of field directions, +Z half left, -Z half right, seen from outside: # covered by a
///   recorded sample, . not yet), MotionCal's quality figures of the samples updated live (gaps, variance, wobble,
///   fit error; MotionCal sends a calibration below 15, 4.5, 4 and 5 %; cube24 shows variance and fit error), a
///   warning while the field's magnitude departs from the rest (a magnet near), and a progress bar (coverage and
///   its target for free, poses for cube24). Keys typed are not echoed while it runs. The coverage is the one
///   magcal-fit reports for the same file.
///
/// WORKFLOW:
///   magcal-record --device i2c:/dev/i2c-1:lis3mdl --routine cube24 --location 52.2,0.1,20 --date 2026-11-21 \
///       --out rec.csv
///   magcal-fit rec.csv --out params.toml --report report.json
///   (or `magcal` for both in one command)
///
/// The file is written as you go (metadata first, rows as they are taken, at least every 0.25 s): if the recorder
/// is killed, the file still parses and holds all but the last moment; if the disk fills up, it holds whole lines
/// and parses. An existing file is never replaced without --force, and a file another recorder is writing is
/// refused. A device that fails (a bus that stays down after retries, a board that is unplugged or goes silent for
/// --idle-timeout, outputs that stop changing) ends the recording with an error; the file keeps what was recorded.
/// Ctrl-C ends the recording and keeps the file.
#[derive(Parser, Debug)]
#[command(version, verbatim_doc_comment)]
struct Args {
    /// The device: sim[:CHIP] | i2c:/dev/i2c-N:CHIP[@ADDR] | serial:PATH[:BAUD][:FORMAT] |
    /// mavlink:PATH[:BAUD][:ardupilot|px4], mavlink:udp:HOST:PORT[:ardupilot|px4] (see above).
    #[arg(long, default_value = "sim", value_name = "DEV")]
    device: String,
    /// The routine.
    #[arg(long, value_enum)]
    routine: Routine,
    /// The recording to write (a new file: an existing one is refused unless --force).
    #[arg(long, short, default_value = "recording.csv", value_name = "REC.csv")]
    out: PathBuf,
    /// Replace --out (the path itself: a link there, not the file it points to) and --truth if they exist; the old
    /// recording stays until the first sample of the new one is written.
    #[arg(long)]
    force: bool,
    /// The board's identifier (e.g. its serial number), written to the recording's metadata as `serial`: a batch's
    /// table (magcal-batch) names the board by it.
    #[arg(long, value_name = "ID", value_parser = parse_serial)]
    serial: Option<String>,
    /// The local field, written to the recording for the fit.
    #[command(flatten)]
    field: WorldFieldOpts,
    /// Unattended: never wait for Enter (poses are taken on stillness only). Implied for sim devices, whose
    /// virtual hand performs the routine.
    #[arg(long)]
    auto: bool,
    /// free: stop at this fraction of the sphere of field directions.
    #[arg(
        allow_negative_numbers = true,
        long,
        default_value_t = 0.9,
        value_name = "FRACTION"
    )]
    coverage: f64,
    /// Stop after this many seconds whatever happens.
    #[arg(
        allow_negative_numbers = true,
        long,
        default_value_t = 600.0,
        value_name = "S"
    )]
    max_duration: f64,
    /// cube24: how long each pose is held still and recorded, s.
    #[arg(
        allow_negative_numbers = true,
        long,
        default_value_t = 1.0,
        value_name = "S"
    )]
    dwell: f64,
    /// cube24: largest spread (standard deviation per axis over the dwell) that counts as still, µT.
    #[arg(
        allow_negative_numbers = true,
        long,
        default_value_t = 0.5,
        value_name = "UT"
    )]
    still_ut: f64,
    /// Output data rate to ask the chip for, Hz (the nearest it supports is used) [default: 100, or the nearest
    /// the chip offers, said only when asked for].
    #[arg(allow_negative_numbers = true, long, value_name = "HZ")]
    rate: Option<f64>,
    /// Full-scale range to ask the chip for, ± µT (the smallest that holds it).
    #[arg(allow_negative_numbers = true, long, value_name = "UT")]
    range_ut: Option<f64>,
    /// serial: no sample for this long ends the recording with an error naming the likely cause (a silent board,
    /// a wrong baud rate, a wrong protocol), s.
    #[arg(
        allow_negative_numbers = true,
        long,
        default_value_t = 5.0,
        value_name = "S"
    )]
    idle_timeout: f64,
    /// sim: seed of the simulated sensor (its errors) and of the noise.
    #[arg(long, default_value_t = 1, value_name = "N")]
    sim_seed: u64,
    /// sim: inject a fault (repeatable): nack@T:COUNT, drop@T, ignore-writes@T, stuck@T, magnet@T:DURATION:X,Y,Z
    /// (T in s of device time, field in µT).
    #[arg(long, value_name = "FAULT")]
    sim_fault: Vec<Fault>,
    /// sim: run at the pace of the wall clock (to watch it) instead of as fast as possible.
    #[arg(long)]
    realtime: bool,
    /// sim: the jig's edge (against which the cube poses are taken) points this many degrees east of true north
    /// (negative: west), as when it was lined up with a compass or by eye.
    #[arg(
        allow_negative_numbers = true,
        long,
        default_value_t = 0.0,
        value_name = "DEG"
    )]
    sim_jig_heading: f64,
    /// sim: write the simulated sensor's true A and b (TOML) here, to check a fit against (a new file, or
    /// with --force any file but a recording).
    #[arg(long, value_name = "TRUTH.toml")]
    truth: Option<PathBuf>,
}

fn main() -> ExitCode {
    exit("magcal-record", run(parse()))
}

fn run(args: Args) -> anyhow::Result<()> {
    let spec: DeviceSpec = args.device.parse()?;
    let routine = args.routine;
    if !spec.is_sim()
        && (args.truth.is_some()
            || !args.sim_fault.is_empty()
            || args.realtime
            || args.sim_jig_heading != 0.0)
    {
        bail!(
            "--truth, --sim-fault, --sim-jig-heading and --realtime are for sim devices, not {spec}"
        );
    }
    let mut opts = RecordOptions::new(routine, args.out.clone());
    opts.force = args.force;
    opts.auto = args.auto || spec.is_sim();
    opts.target_coverage = args.coverage;
    opts.max_duration_s = args.max_duration;
    opts.dwell_s = args.dwell;
    opts.still_ut = args.still_ut;
    let open = OpenOptions {
        rate_hz: args.rate.unwrap_or(OpenOptions::default().rate_hz),
        range_ut: args.range_ut,
        sim_seed: args.sim_seed,
        sim_faults: args.sim_fault.clone(),
        sim_paced: args.realtime,
        sim_jig_heading_deg: args.sim_jig_heading,
        idle_timeout_s: args.idle_timeout,
    };
    // Everything is checked before anything is opened or written.
    opts.check()?;
    open.check(&spec)?;
    Guard::new("magcal-record")
        .force(args.force)
        .file("--out", Some(&args.out), Replace::Recording)
        .file("--truth", args.truth.as_deref(), Replace::New)
        .check()?;
    args.field.write_metadata(&mut opts.meta);
    opts.meta.serial = args.serial.clone();
    opts.meta = device_metadata(&spec, args.sim_seed, opts.meta);
    // A field given in another unit than µT is refused before anything is opened, as the fit would refuse it.
    resolve(&args.field.field_args(None), &opts.meta)?;
    if let Some(note) = sim_field_note(&spec, &opts.meta) {
        tellln!("{note}");
    }
    if let DeviceSpec::Sim { chip } = spec {
        if let Some(path) = &args.truth {
            TruthFile::of(chip, args.sim_seed)
                .write(path)
                .with_context(|| format!("writing the truth {}", path.display()))?;
        }
    } else if opts.meta.field_ned_ut.is_none() && opts.meta.location.is_none() {
        tellln!(
            "note: no --field-ned or --location/--date: the fit will need the local field (magcal-fit --field-ned \
             or --location/--date){}",
            match routine {
                Routine::Cube24 => " for the vector method",
                Routine::Free => " for an absolute scale",
                Routine::Motors => " for the heading error the motors make",
            }
        );
    }
    let interrupt = interrupt_flag("magcal-record")?;
    if let Some(note) = spec.unit_note() {
        tellln!("{note}");
    }
    let mut source = device::open(&spec, &open)?;
    // What the device asked for, got and undid (a flight controller's streams and calibration), as written to the
    // recording's metadata.
    for (key, value) in source.metadata() {
        tellln!("{spec}: {key}: {value}");
    }
    // Said only of a rate asked for: without --rate, the chip's nearest to the default is no news.
    if let (Some(asked), Some(rate_hz)) = (args.rate, source.rate_hz())
        && (rate_hz - asked).abs() > 0.01 * asked
    {
        tellln!(
            "note: asked for {asked} Hz; the nearest the {} offers is {rate_hz} Hz",
            source.sensor()
        );
    }
    let mut ui = ui::for_stdout(opts.auto, routine);
    sayln!("recording {spec} to {}", args.out.display())?;
    let summary = record(source.as_mut(), &opts, ui.as_mut(), &interrupt)?;
    print_summary(&summary, &opts)?;
    Ok(())
}

fn print_summary(s: &RecordSummary, opts: &RecordOptions) -> std::io::Result<()> {
    let why = match s.stop {
        Stop::Coverage => "coverage target reached",
        Stop::AllPoses => "all 24 poses taken",
        Stop::Ramps => "throttle ramps made, and the blips",
        Stop::Interrupted => "interrupted",
        Stop::MaxDuration => "longest duration reached",
    };
    sayln!(
        "recorded {} samples in {:.1} s to {} ({why}); coverage {:.0} % of the sphere{}",
        s.samples,
        s.duration_s,
        s.path.display(),
        100.0 * s.coverage,
        if s.poses > 0 {
            format!(", {} poses", s.poses)
        } else if opts.routine == Routine::Motors {
            format!(", {} throttle ramps, {} blips", s.ramps, s.blips)
        } else {
            String::new()
        }
    )?;
    if s.saturated > 0 {
        sayln!("saturated samples (not recorded): {}", s.saturated)?;
    }
    if s.disturbed > 0 {
        sayln!(
            "samples whose field magnitude departed from the rest's (a magnet or iron nearby? recorded, kept out of \
             the coverage map): {}",
            s.disturbed
        )?;
    }
    if !s.clock_restarts.is_empty() {
        sayln!(
            "the device's clock restarted {} times; the file's metadata lists the segments",
            s.clock_restarts.len()
        )?;
    }
    if let Some(l) = s.link_loss.filter(|l| l.lost > 0) {
        sayln!(
            "the link lost {} of the autopilot's {} frames ({:.1} %, by gaps in its sequence numbers): the              recording has gaps there (noted in its metadata); a cable, a faster baud rate or a slower stream rate              loses fewer",
            l.lost,
            l.received + l.lost,
            100.0 * l.share()
        )?;
    }
    if let Some(g) = &s.garbage {
        sayln!("{g}")?;
    }
    if s.untouched {
        sayln!(
            "no sample was recorded: {} was left as it was",
            s.path.display()
        )?;
        return Ok(());
    }
    match s.shortfall(opts) {
        Some(short) => sayln!(
            "{short}; magcal-fit {} says what it lacks",
            s.path.display()
        ),
        None => sayln!("next: magcal-fit {}", s.path.display()),
    }
}
