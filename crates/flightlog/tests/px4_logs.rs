//! The real PX4 logs in `../shared/data/flight/px4-ulog/` (its README says what each holds): every magnetometer
//! found with its logged calibration, and that calibration, as read, turning the raw stream into what the autopilot
//! logged after it.

use std::path::PathBuf;

use magcal_calib::frames::{add, mat_vec, norm, sub};
use magcal_flightlog::{FlightLog, Instance, ulog};

fn log(name: &str) -> FlightLog {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/flight/px4-ulog")
        .join(name);
    ulog::read(&path).unwrap_or_else(|e| panic!("{e}"))
}

#[test]
fn esc_status_log_has_one_calibrated_magnetometer_with_cal_mag0() {
    let log = log("esc_status_log.ulg");
    assert_eq!(log.mags.len(), 1);
    let m = &log.mags[0];
    assert_eq!(
        (m.topic, m.instance, m.calibrated),
        ("vehicle_magnetometer", 0, true)
    );
    assert_eq!(m.field_g.len(), 117);
    let cal = m
        .calibration
        .as_ref()
        .expect("CAL_MAG0 is the only slot enabled");
    assert_eq!((cal.slot, cal.device_id), (0, 396809));
    assert!(
        (cal.offset_g[0] + 0.01912352).abs() < 1e-7,
        "{:?}",
        cal.offset_g
    );
    assert!((cal.scale[2][2] - 1.0387299).abs() < 1e-6);
    assert!(cal.rotation_source.contains("external"));
    assert_eq!(log.hardware.as_deref(), Some("PX4_FMU_V3"));
    let fix = log.first_fix().expect("a GPS fix");
    assert!(
        (fix.lat_deg - 47.357).abs() < 0.01 && (fix.lon_deg - 8.519).abs() < 0.01,
        "{fix:?}"
    );
    let current = log.current_a.as_ref().expect("battery current");
    let max = current.values.iter().copied().fold(0.0, f64::max);
    assert!((73.0..75.0).contains(&max), "{max}");
    // The recording: raw field undone, the place and date of the fix, the current as a channel.
    let fr = log.recording(None).unwrap();
    assert_eq!(fr.rec.len(), 117);
    assert_eq!(fr.rec.currents[0].name, "i_battery");
    assert_eq!(
        fr.rec.meta.date.map(|d| d.to_string()).as_deref(),
        Some("2019-05-13")
    );
    // The raw field and the logged one differ by the logged calibration only.
    let logged = fr.logged_ut.as_ref().unwrap();
    let body = mat_vec(&cal.rotation, logged[10]);
    let as_logged = m.field_g.values[10].map(|g| g * 100.0);
    assert!(norm(sub(body, as_logged)) < 1e-9, "{body:?} {as_logged:?}");
}

#[test]
fn quadrotor_local_has_two_raw_magnetometers_each_with_its_slot() {
    let log = log("quadrotor_local.ulg");
    let names: Vec<String> = log.mags.iter().map(|m| m.name()).collect();
    assert_eq!(
        names,
        [
            "sensor_mag[0], device 396809",
            "sensor_mag[1], device 396321",
            "vehicle_magnetometer[0], device 396809"
        ]
    );
    let slots: Vec<u8> = log
        .mags
        .iter()
        .map(|m| m.calibration.as_ref().unwrap().slot)
        .collect();
    assert_eq!(slots, [0, 1, 0]);
    let c0 = log.mags[0].calibration.as_ref().unwrap();
    assert!(
        (c0.scale[1][2] + 0.25131145).abs() < 1e-7,
        "ZODIAG at (1,2): {:?}",
        c0.scale
    );
    assert!(
        log.mags[1]
            .calibration
            .as_ref()
            .unwrap()
            .rotation_source
            .contains("internal")
    );
    assert!(!log.mags[1].calibration.as_ref().unwrap().enabled);
    // The magnetometer the autopilot used (the highest CAL_MAGn_PRIO), raw.
    assert_eq!(log.default_instance(), Some(0));
    assert!(log.first_fix().is_none(), "no GPS fix in this log");
    // This magnetometer's driver logs no temperature (NaN): the recording has no temp column.
    assert!(
        log.mags[0]
            .temp_c
            .as_ref()
            .unwrap()
            .iter()
            .all(|t| t.is_nan())
    );
    assert!(log.recording(None).unwrap().rec.temp_c.is_none());
}

/// PX4's `R·S·(raw − OFF) − bias` on the raw `sensor_mag` gives `vehicle_magnetometer` (an average of the raw
/// samples between two publications, at other times than the logged raw samples): the slot is read as PX4 applies
/// it — offsets, scales, off-diagonals in their places, the rotation — and the estimator's bias with it. The two
/// agree to 1.1 µT RMS (single noisy raw samples against averages of about seven, half a second apart); without the
/// estimator's bias they would differ by 4.1 µT.
#[test]
fn the_logged_calibration_turns_sensor_mag_into_vehicle_magnetometer() {
    let log = log("quadrotor_local.ulg");
    let (raw, calibrated) = (&log.mags[0], &log.mags[2]);
    let cal = raw.calibration.as_ref().unwrap();
    let bias = calibrated
        .estimator_bias_g
        .as_ref()
        .expect("the estimator's bias for device 396809");
    let mean = |v: &mut dyn Iterator<Item = [f64; 3]>| {
        let (mut s, mut n) = ([0.0; 3], 0.0);
        for x in v {
            s = add(s, x);
            n += 1.0;
        }
        s.map(|c| 100.0 * c / n)
    };
    // At each raw sample's time, the calibrated stream interpolated between its two publications around it.
    let (mut with, mut without, mut n) = (0.0, 0.0, 0.0);
    for (t, v) in raw.field_g.t_us.iter().zip(&raw.field_g.values) {
        let Some(logged) = calibrated.field_g.at(*t, 1_000_000) else {
            continue;
        };
        let b = bias.held_at(*t).unwrap_or([0.0; 3]);
        let applied = mat_vec(&cal.rotation, cal.apply_in_sensor_axes(*v, 0.0));
        with += norm(sub(sub(applied, b), logged)).powi(2) * 1e4;
        without += norm(sub(applied, logged)).powi(2) * 1e4;
        n += 1.0;
    }
    let (with, without) = ((with / n).sqrt(), (without / n).sqrt());
    assert!(
        n > 80.0 && with < 1.5 && without > 3.0,
        "RMS {with} µT, without the bias {without} µT"
    );
    let held = bias.held_at(u64::MAX).unwrap();
    assert!(norm(held) * 100.0 > 3.0, "{held:?}");
    // Undone (bias included), the calibrated stream gives the raw field back on average (over other samples).
    let undone = log.recording(Some(Instance(2))).unwrap();
    let direct = log.recording(Some(Instance(0))).unwrap();
    let (u, d) = (
        mean(&mut undone.rec.mag_ut.iter().map(|m| m.map(|c| c / 100.0))),
        mean(&mut direct.rec.mag_ut.iter().map(|m| m.map(|c| c / 100.0))),
    );
    assert!(norm(sub(u, d)) < 1.0, "{u:?} {d:?}");
}

/// A log cut short or with bytes changed is read up to the damage and says so, or refused with the file named —
/// never a panic: every cut at 97 places, and 200 single bytes overwritten in the data section.
#[test]
fn cut_or_damaged_logs_are_read_up_to_the_damage_or_refused_clearly() {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/flight/px4-ulog/esc_status_log.ulg");
    let bytes = std::fs::read(&path).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let damaged = dir.path().join("damaged.ulg");
    let check = |data: &[u8]| match ulog::read(&damaged).map(|_| ()) {
        Ok(()) => {}
        Err(e) => {
            let text = e.to_string();
            assert!(text.starts_with(&damaged.display().to_string()), "{text}");
            let _ = data;
        }
    };
    for k in 1..98 {
        let cut = bytes.len() * k / 98;
        std::fs::write(&damaged, &bytes[..cut]).unwrap();
        check(&bytes[..cut]);
    }
    // Cut in the data section: the log is read, with a note that it ends early.
    std::fs::write(&damaged, &bytes[..bytes.len() * 3 / 4 + 7]).unwrap();
    let log = ulog::read(&damaged).unwrap();
    assert!(
        log.notes
            .iter()
            .any(|n| n.contains("ends partway") || n.contains("corrupt record")),
        "{:?}",
        log.notes
    );
    assert!(log.mags[0].field_g.len() < 117 && log.mags[0].field_g.len() > 50);
    let mut state = 0x2545_f491_4f6c_dd1du64;
    for _ in 0..200 {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        let mut copy = bytes.clone();
        let at = 20_000 + (state as usize) % (bytes.len() - 20_000);
        copy[at] = (state >> 32) as u8;
        std::fs::write(&damaged, &copy).unwrap();
        check(&copy);
    }
    // Not a ULog file at all, and an empty one.
    for (content, want) in [
        (
            &b"t,mx,my,mz\n0,1,2,3\n"[..],
            "does not start with ULog's magic bytes",
        ),
        (&b""[..], "the file is empty"),
        (&bytes[..300], "ends before its data section"),
    ] {
        std::fs::write(&damaged, content).unwrap();
        let err = ulog::read(&damaged).unwrap_err().to_string();
        assert!(
            err.contains(want) && err.starts_with(&damaged.display().to_string()),
            "{err}"
        );
    }
    let missing = dir.path().join("missing.ulg");
    let err = ulog::read(&missing).unwrap_err().to_string();
    assert!(err.contains("cannot be read"), "{err}");
}
