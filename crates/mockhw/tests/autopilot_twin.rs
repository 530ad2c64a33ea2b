//! The autopilot twin over an in-memory duplex, as a ground station sees it: its heartbeat names the autopilot; its
//! compass messages are the bench's raw field through its own calibration, in each autopilot's unit, so undoing its
//! parameters gives the raw field back; the battery current follows the profile, and the field follows the current
//! by the lag configured; its parameters are read, listed and set, and a value out of range is answered with the old
//! one; a write-back that meets a refusal leaves every parameter as it was. A lossy link loses the share of frames
//! configured; a reboot restarts the boot clock and the streams (at their defaults, or none until asked again) and
//! keeps the parameters.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::{self, JoinHandle};
use std::time::{Duration, Instant};

use magcal_autopilot::params::{read_all, write_all};
use magcal_autopilot::{
    Autopilot, Connection, MemoryPort, ParamError, Telemetry, duplex, telemetry,
};
use magcal_calib::Effect;
use magcal_mockhw::autopilot::{AutopilotTwin, CurrentProfile, TwinConfig, TwinReport};
use magcal_sim::SensorTruth;
use magcal_sim::bench::BenchConfig;
use nalgebra::{Matrix3, Vector3};

/// A sensor with soft and hard iron, a motor-current bias of (0.4, −0.2, 0.3) µT/A and a 20 ms lag.
fn bench(seed: u64) -> BenchConfig {
    let mut b = BenchConfig::ideal([19.0, 1.0, 45.0], seed);
    b.sensor = SensorTruth::mounted(
        [[1.08, 0.03, -0.02], [0.03, 0.94, 0.01], [-0.02, 0.01, 1.03]],
        [14.0, -9.0, 22.0],
        [0.0; 3],
    );
    b.noise_ut = [0.05; 3];
    b.effects = vec![
        Effect::CurrentBias {
            channel: 0,
            coef_ut_per_a: [0.4, -0.2, 0.3],
        },
        Effect::TimeLag { lag_s: 0.02 },
    ];
    b
}

struct Running {
    conn: Connection<MemoryPort>,
    stop: Arc<AtomicBool>,
    twin: JoinHandle<TwinReport>,
}

impl Running {
    fn finish(self) -> TwinReport {
        self.stop.store(true, Ordering::Relaxed);
        drop(self.conn);
        self.twin.join().unwrap()
    }
}

fn start(config: TwinConfig) -> Running {
    let (mut theirs, ours) = duplex();
    theirs.set_read_timeout(Duration::ZERO);
    let twin = AutopilotTwin::new(theirs, config).unwrap();
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    let twin = thread::spawn(move || twin.run(|| flag.load(Ordering::Relaxed)));
    Running {
        conn: Connection::new(ours, "twin"),
        stop,
        twin,
    }
}

fn config(autopilot: Autopilot, seed: u64) -> TwinConfig {
    let mut c = TwinConfig::new(autopilot, bench(seed));
    c.current = Some(CurrentProfile::ramps(2.0, 30.0, 4.0));
    c.speed = 20.0;
    c.values = match autopilot {
        Autopilot::ArduPilot => vec![
            ("COMPASS_OFS_X".into(), -120.0),
            ("COMPASS_OFS_Y".into(), 85.0),
            ("COMPASS_DIA_Y".into(), 1.04),
            ("COMPASS_ODI_Z".into(), -0.02),
            ("COMPASS_MOT_X".into(), -2.5),
            ("COMPASS_MOTCT".into(), 2.0),
        ],
        Autopilot::Px4 => vec![
            ("CAL_MAG0_XOFF".into(), 0.12),
            ("CAL_MAG0_ZOFF".into(), -0.2),
            ("CAL_MAG0_XSCALE".into(), 0.97),
            ("CAL_MAG0_YODIAG".into(), 0.015),
            ("CAL_MAG0_YCOMP".into(), 3.0),
            ("CAL_MAG_COMP_TYP".into(), 2.0),
        ],
    };
    c
}

fn param(values: &[(String, f64)], name: &str, default: f64) -> f64 {
    values
        .iter()
        .find(|(n, _)| n == name)
        .map_or(default, |v| v.1)
}

/// The raw field (µT) behind what the autopilot sent (µT), by its parameters, at `current_a`.
fn undo(
    autopilot: Autopilot,
    values: &[(String, f64)],
    sent_ut: [f64; 3],
    current_a: f64,
) -> [f64; 3] {
    let p = |n: &str, d: f64| param(values, n, d);
    let (names, scale) = match autopilot {
        Autopilot::ArduPilot => (["COMPASS_DIA_", "COMPASS_ODI_"], 10.0),
        Autopilot::Px4 => (["CAL_MAG0_", "CAL_MAG0_"], 0.01),
    };
    let (d, o): (Vec<f64>, Vec<f64>) = match autopilot {
        Autopilot::ArduPilot => (
            ["X", "Y", "Z"]
                .iter()
                .map(|a| p(&format!("{}{a}", names[0]), 1.0))
                .collect(),
            ["X", "Y", "Z"]
                .iter()
                .map(|a| p(&format!("{}{a}", names[1]), 0.0))
                .collect(),
        ),
        Autopilot::Px4 => (
            ["X", "Y", "Z"]
                .iter()
                .map(|a| p(&format!("CAL_MAG0_{a}SCALE"), 1.0))
                .collect(),
            ["X", "Y", "Z"]
                .iter()
                .map(|a| p(&format!("CAL_MAG0_{a}ODIAG"), 0.0))
                .collect(),
        ),
    };
    let m = Matrix3::new(d[0], o[0], o[1], o[0], d[1], o[2], o[1], o[2], d[2]);
    let f = Vector3::from(sent_ut) * scale;
    let raw = match autopilot {
        Autopilot::ArduPilot => {
            let mot = Vector3::new(
                p("COMPASS_MOT_X", 0.0),
                p("COMPASS_MOT_Y", 0.0),
                p("COMPASS_MOT_Z", 0.0),
            );
            let ofs = Vector3::new(
                p("COMPASS_OFS_X", 0.0),
                p("COMPASS_OFS_Y", 0.0),
                p("COMPASS_OFS_Z", 0.0),
            );
            m.try_inverse().unwrap() * (f - mot * current_a) - ofs
        }
        Autopilot::Px4 => {
            let comp = Vector3::new(
                p("CAL_MAG0_XCOMP", 0.0),
                p("CAL_MAG0_YCOMP", 0.0),
                p("CAL_MAG0_ZCOMP", 0.0),
            );
            let off = Vector3::new(
                p("CAL_MAG0_XOFF", 0.0),
                p("CAL_MAG0_YOFF", 0.0),
                p("CAL_MAG0_ZOFF", 0.0),
            );
            m.try_inverse().unwrap() * f + off - comp * (current_a / 1000.0)
        }
    };
    let raw = raw / scale;
    [raw.x, raw.y, raw.z]
}

#[test]
fn each_autopilot_sends_its_compass_through_its_own_calibration_in_its_own_unit() {
    for autopilot in [Autopilot::ArduPilot, Autopilot::Px4] {
        let cfg = config(autopilot, 11);
        let values = cfg.values.clone();
        let mut run = start(cfg);
        assert_eq!(
            run.conn
                .wait_heartbeat(Duration::from_secs(2), None)
                .unwrap(),
            autopilot
        );
        let (mut mags, mut currents, mut attitudes) = (Vec::new(), Vec::new(), Vec::new());
        let mut pending: std::collections::VecDeque<_> = run.conn.backlog.drain(..).collect();
        let deadline = Instant::now() + Duration::from_secs(20);
        while currents.len() < 300 {
            let (_, msg) = match pending.pop_front() {
                Some(m) => m,
                None => run
                    .conn
                    .next_message(deadline)
                    .unwrap()
                    .expect("telemetry arrives"),
            };
            match telemetry(&msg) {
                Some(Telemetry::Mag {
                    field_ut,
                    instance: 0,
                    ..
                }) => mags.push(field_ut),
                Some(Telemetry::Current { current_a }) => currents.push(current_a),
                Some(Telemetry::Attitude { q, .. }) => attitudes.push(q),
                _ => {}
            }
        }
        let report = run.finish();
        // Sent in mGauss integers (ArduPilot) or f32 gauss (PX4).
        let rounding_ut = match autopilot {
            Autopilot::ArduPilot => 0.05 + 1e-9,
            Autopilot::Px4 => 1e-4,
        };
        let mut worst_raw = 0.0f64;
        for (k, got) in mags.iter().enumerate() {
            let sent = &report.sent[k];
            for j in 0..3 {
                assert!(
                    (got[j] - sent.sent_ut[j]).abs() <= rounding_ut,
                    "{autopilot} {k}: {got:?} {sent:?}"
                );
            }
            let raw = undo(autopilot, &values, *got, sent.current_a);
            for j in 0..3 {
                worst_raw = worst_raw.max((raw[j] - sent.raw_ut[j]).abs());
            }
            assert!((attitudes[k][0] - sent.quat[0]).abs() < 1e-6);
            assert!((currents[k] - sent.current_a).abs() <= 0.005 + 1e-9);
        }
        assert!(
            worst_raw < 0.06,
            "{autopilot}: undoing its parameters gives the raw field to {worst_raw} µT"
        );
        // The current went through its profile: the bias it makes is in the raw field.
        let (lo, hi) = currents
            .iter()
            .fold((f64::MAX, f64::MIN), |(l, h), c| (l.min(*c), h.max(*c)));
        assert!(lo < 3.0 && hi > 29.0, "{lo} {hi}");
    }
}

#[test]
fn parameters_are_listed_read_and_set_and_a_value_out_of_range_is_answered_with_the_old_one() {
    for autopilot in [Autopilot::ArduPilot, Autopilot::Px4] {
        let mut cfg = config(autopilot, 12);
        cfg.stream = true;
        let (ofs, typ) = match autopilot {
            Autopilot::ArduPilot => ("COMPASS_OFS_X", "COMPASS_MOTCT"),
            Autopilot::Px4 => ("CAL_MAG0_XOFF", "CAL_MAG_COMP_TYP"),
        };
        let before = param(&cfg.values, ofs, 0.0);
        cfg.ranges = vec![(ofs.to_owned(), -500.0, 500.0)];
        let mut run = start(cfg);
        run.conn
            .wait_heartbeat(Duration::from_secs(2), None)
            .unwrap();
        let all = run.conn.list_params().unwrap();
        assert_eq!(all.len(), 15, "{all:?}");
        assert!(
            all.iter()
                .enumerate()
                .all(|(i, p)| usize::from(p.index) == i && p.count == 15)
        );
        let held = run.conn.read_param(ofs).unwrap();
        assert_eq!(held.value as f32, before as f32);
        // An integer parameter travels in each autopilot's encoding and comes back as the number.
        assert_eq!(run.conn.read_param(typ).unwrap().value, 2.0);
        let set = run.conn.set_param(typ, 0.0, held_kind(&all, typ)).unwrap();
        assert_eq!(set.value, 0.0);
        let set = run.conn.set_param(ofs, 0.25, held.kind).unwrap();
        assert_eq!(set.value, f64::from(0.25f32));
        let refused = run.conn.set_param(ofs, 900.0, held.kind).unwrap();
        assert_eq!(
            refused.value, 0.25,
            "{autopilot}: answered with the old value"
        );
        let err = run.conn.read_param("NO_SUCH_PARAM").unwrap_err();
        assert!(matches!(err, ParamError::NoAnswer { .. }), "{err}");
        let report = run.finish();
        assert_eq!((report.sets_taken, report.sets_refused), (2, 1));
        assert_eq!(report.param(ofs), Some(0.25));
        assert_eq!(report.unknown_names.len(), 3, "three tries");
    }
}

fn held_kind(
    all: &[magcal_autopilot::ParamValue],
    name: &str,
) -> mavlink::dialects::common::MavParamType {
    all.iter().find(|p| p.name == name).unwrap().kind
}

#[test]
fn a_write_back_that_meets_a_refusal_leaves_the_previous_values() {
    for autopilot in [Autopilot::ArduPilot, Autopilot::Px4] {
        let mut cfg = config(autopilot, 13);
        let names: Vec<&str> = match autopilot {
            Autopilot::ArduPilot => vec![
                "COMPASS_OFS_X",
                "COMPASS_OFS_Y",
                "COMPASS_DIA_X",
                "COMPASS_DIA_Y",
            ],
            Autopilot::Px4 => vec![
                "CAL_MAG0_XOFF",
                "CAL_MAG0_YOFF",
                "CAL_MAG0_XSCALE",
                "CAL_MAG0_YSCALE",
            ],
        };
        // The third is refused: its range is narrowed below the value written.
        cfg.ranges = vec![(names[2].to_owned(), 0.5, 1.01)];
        let mut run = start(cfg);
        run.conn
            .wait_heartbeat(Duration::from_secs(2), None)
            .unwrap();
        let before_all = run.conn.list_params().unwrap();
        let previous = read_all(&mut run.conn, &names).unwrap();
        let wanted: Vec<(String, f64)> = names
            .iter()
            .zip([0.07, -0.05, 1.1, 0.98])
            .map(|(n, v)| ((*n).to_owned(), v))
            .collect();
        let err = write_all(&mut run.conn, &wanted, &previous).unwrap_err();
        assert_eq!(err.param, names[2]);
        assert!(err.why.contains("refused 1.1"), "{err}");
        assert_eq!(err.restored, names[..2]);
        let text = err.to_string();
        assert!(
            text.contains("the autopilot keeps its previous values"),
            "{text}"
        );
        let after_all = run.conn.list_params().unwrap();
        assert_eq!(after_all, before_all);
        // Without the refusal it goes through, and reads back what was written.
        let ok: Vec<(String, f64)> = wanted
            .iter()
            .map(|(n, v)| (n.clone(), v.min(1.0)))
            .collect();
        let back = write_all(&mut run.conn, &ok, &previous).unwrap();
        for ((_, v), b) in ok.iter().zip(&back) {
            assert_eq!(b.value, f64::from(*v as f32));
        }
        run.finish();
    }
}

#[test]
fn a_twin_that_awaits_requests_streams_only_what_is_asked_at_the_rate_asked_capped_at_its_own() {
    for autopilot in [Autopilot::ArduPilot, Autopilot::Px4] {
        let mut c = config(autopilot, 7);
        c.await_request = true;
        c.rate_hz = 50.0;
        let mut run = start(c);
        run.conn
            .wait_heartbeat(Duration::from_secs(5), None)
            .unwrap();
        // Heartbeats only, until asked.
        let quiet_until = Instant::now() + Duration::from_millis(300);
        while let Some((_, m)) = run.conn.next_message(quiet_until).unwrap() {
            assert!(telemetry(&m).is_none(), "{autopilot}: sent {m:?} unasked");
        }
        let messages = magcal_autopilot::streams::recording_messages(autopilot);
        let answers = run.conn.request_streams(&messages, 20.0).unwrap();
        assert!(
            answers.iter().all(
                |a| a.result == Some(mavlink::dialects::common::MavResult::MAV_RESULT_ACCEPTED)
            ),
            "{answers:?}"
        );
        // Half a second of wall time: 10 s of bench time at the twin's speed.
        let until = Instant::now() + Duration::from_millis(500);
        while run.conn.next_message(until).unwrap().is_some() {}
        let report = run.finish();
        let sent = &report.sent;
        assert!(sent.len() >= 5, "{autopilot}: {}", sent.len());
        let span = sent[sent.len() - 1].t_s - sent[0].t_s;
        let rate = (sent.len() - 1) as f64 / span;
        assert!((rate - 20.0).abs() < 1.5, "{autopilot}: {rate} Hz");
        assert!(
            report
                .requests
                .iter()
                .any(|r| r.contains("at 20 Hz (asked 20 Hz)")),
            "{:?}",
            report.requests
        );
    }
}

/// A held, noise-free, ideal sensor whose field follows the current 40 ms late: each raw reading is the constant
/// field plus `k·I(t − 40 ms)` to rounding, while the current sent is `I(t)`.
#[test]
fn the_field_follows_the_current_by_the_lag() {
    let profile = CurrentProfile::ramps(2.0, 30.0, 1.0);
    let coef = [0.4, -0.2, 0.3];
    let mut bench = BenchConfig::ideal([19.0, 1.0, 45.0], 5);
    bench.effects = vec![Effect::CurrentBias {
        channel: 0,
        coef_ut_per_a: coef,
    }];
    let mut c = TwinConfig::new(Autopilot::Px4, bench);
    c.current = Some(profile);
    c.current_lag_s = 0.04;
    c.held = true;
    c.speed = 20.0;
    let run = start(c);
    thread::sleep(Duration::from_millis(100));
    let sent = run.finish().sent;
    assert!(sent.len() >= 50, "{}", sent.len());
    // The field at zero current, by the first reading; then the largest difference of a reading from it and `k·I`,
    // with the current of 40 ms before or of now.
    let worst = |i_a: fn(&CurrentProfile, f64) -> f64| -> f64 {
        let b0: [f64; 3] =
            std::array::from_fn(|j| sent[0].raw_ut[j] - coef[j] * i_a(&profile, sent[0].t_s));
        sent.iter()
            .flat_map(|s| (0..3).map(move |j| (s, j)))
            .map(|(s, j)| (s.raw_ut[j] - b0[j] - coef[j] * i_a(&profile, s.t_s)).abs())
            .fold(0.0, f64::max)
    };
    let lagged = worst(|p, t| p.at(t - 0.04));
    let present = worst(|p, t| p.at(t));
    assert!(lagged < 1e-9, "{lagged} µT from k·I(t − lag)");
    assert!(present > 1.0, "{present} µT from k·I(t)");
    for s in &sent {
        assert_eq!(s.current_a, profile.at(s.t_s));
    }
}

/// 20 % of the frames lost: the compass messages that arrive are those the twin put on the port, and about a fifth
/// of the 50 Hz grid is missing.
#[test]
fn a_lossy_link_loses_the_share_of_frames_configured() {
    let mut c = config(Autopilot::ArduPilot, 8);
    c.rate_hz = 50.0;
    c.loss = 0.2;
    c.loss_seed = 3;
    let mut run = start(c);
    let mut got = Vec::new();
    let until = Instant::now() + Duration::from_millis(500);
    while let Some((_, m)) = run.conn.next_message(until).unwrap() {
        if let Some(Telemetry::Mag { t_s, .. }) = telemetry(&m) {
            got.push(t_s);
        }
    }
    let report = run.finish();
    assert!(report.frames_lost > 0);
    let on_grid = ((got[got.len() - 1] - got[0]) * 50.0).round() + 1.0;
    let lost = 1.0 - got.len() as f64 / on_grid;
    assert!((lost - 0.2).abs() < 0.07, "{lost:.3} of {on_grid} lost");
    for t in &got {
        assert!(
            report.sent.iter().any(|s| (s.t_s - t).abs() < 1e-5),
            "{t} was not sent"
        );
    }
}

/// A reboot at 4 s: the compass's time starts again, after `BOOT_S` of silence; the streams come back by themselves at
/// the default rate, or, awaiting requests, only when asked again; a parameter set before it is kept.
#[test]
fn a_reboot_restarts_the_clock_and_the_streams_and_keeps_the_parameters() {
    for await_request in [false, true] {
        let mut c = config(Autopilot::ArduPilot, 9);
        c.rate_hz = 50.0;
        c.await_request = await_request;
        c.reboot_at_s = Some(4.0);
        let mut run = start(c);
        run.conn
            .wait_heartbeat(Duration::from_secs(5), None)
            .unwrap();
        let messages = magcal_autopilot::streams::recording_messages(Autopilot::ArduPilot);
        run.conn.request_streams(&messages, 50.0).unwrap();
        let kind = mavlink::dialects::common::MavParamType::MAV_PARAM_TYPE_REAL32;
        run.conn.set_param("COMPASS_OFS_X", 10.0, kind).unwrap();
        // Until 0.5 s of wall time: 10 s of bench time.
        let listen = |conn: &mut Connection<MemoryPort>, ms: u64| {
            let (mut times, mut heartbeats) = (Vec::new(), 0);
            let until = Instant::now() + Duration::from_millis(ms);
            while let Some((_, m)) = conn.next_message(until).unwrap() {
                match (telemetry(&m), &m) {
                    (Some(Telemetry::Mag { t_s, .. }), _) => times.push(t_s),
                    (_, mavlink::dialects::common::MavMessage::HEARTBEAT(_)) => heartbeats += 1,
                    _ => {}
                }
            }
            (times, heartbeats)
        };
        let (times, heartbeats) = listen(&mut run.conn, 500);
        let back = times.windows(2).position(|w| w[1] < w[0]);
        if await_request {
            // Silent after the reboot (heartbeats only), until asked again.
            assert_eq!(back, None, "{times:?}");
            assert!(
                times[times.len() - 1] <= 4.0 && heartbeats >= 4,
                "{heartbeats}"
            );
            run.conn.request_streams(&messages, 50.0).unwrap();
        }
        let (after, _) = if await_request {
            listen(&mut run.conn, 200)
        } else {
            (times[back.expect("the clock went back") + 1..].to_vec(), 0)
        };
        let rate = (after.len() - 1) as f64 / (after[after.len() - 1] - after[0]);
        assert!((rate - 50.0).abs() < 3.0, "{await_request}: {rate} Hz");
        let kept = run.conn.read_param("COMPASS_OFS_X").unwrap().value;
        assert_eq!(kept, 10.0, "{await_request}");
        let report = run.finish();
        let reboot_s = report.rebooted_at_s.unwrap();
        assert!((reboot_s - 4.0).abs() < 0.03, "{reboot_s}");
        // The time sent after it counts from the reboot, from when it came back at the earliest.
        assert!(
            after[0] >= magcal_mockhw::autopilot::BOOT_S - 1e-5,
            "{after:?}"
        );
        for t in &after {
            assert!(
                report
                    .sent
                    .iter()
                    .any(|s| (s.t_s - reboot_s - t).abs() < 1e-5),
                "{await_request}: {t} is not the time since the reboot"
            );
        }
    }
}
