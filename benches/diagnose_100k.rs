//! Acceptance benchmark: the base fit plus the diagnosis of a 100,000-sample recording under 2 s on the 2-core
//! machine. The recording carries every channel the catalogue can test (attitude, temperature, a current), so every
//! candidate is built and judged, and one effect is present so the selection runs a second round.
//!
//! `cargo bench --bench diagnose_100k` (the recording is read before timing: this measures the fit and diagnosis).

use std::time::Duration;

use criterion::Criterion;
use magcal_app::calibrate::calibrate;
use magcal_app::field::ReferenceField;
use magcal_app::fit::Method;
use magcal_calib::effects::EffectId;
use magcal_recording::Recording;
use magcal_sim::study::{random_effect, random_scenario, scale_to_rms};
use magcal_sim::{Trajectory, simulate};

const SAMPLES: f64 = 100_000.0;

fn main() {
    let mut s = random_scenario(7);
    s.sample_rate_hz = 100.0;
    s.trajectory = Trajectory::Tumble {
        duration_s: SAMPLES / s.sample_rate_hz,
        rate_rad_s: 1.0,
    };
    let e = scale_to_rms(
        &s,
        &random_effect(EffectId::TemperatureBias, &s, 7),
        0.5 * s.noise_ut[0],
    );
    s.effects = vec![e];
    let rec: Recording = simulate(&s).expect("valid scenario").recording;
    println!(
        "recording: {} samples, {} current channel(s), temperature, attitude",
        rec.len(),
        rec.currents.len()
    );
    let field = ReferenceField::Vector {
        field_ned_ut: s.field_ned_ut,
        source: "simulated".into(),
    };
    let once = calibrate(&rec, Method::Vector, field.clone(), true).expect("fits");
    let d = once.diagnosis.as_ref().expect("diagnosed");
    println!(
        "found: {:?}",
        d.effects
            .iter()
            .map(|e| e.effect.id().as_str())
            .collect::<Vec<_>>()
    );

    let mut c = Criterion::default()
        .sample_size(10)
        .measurement_time(Duration::from_secs(20))
        .configure_from_args();
    c.bench_function("base fit + diagnosis, 1e5 samples", |b| {
        b.iter(|| calibrate(&rec, Method::Vector, field.clone(), true).expect("fits"))
    });
    c.bench_function("base fit only, 1e5 samples", |b| {
        b.iter(|| calibrate(&rec, Method::Vector, field.clone(), false).expect("fits"))
    });
    c.final_summary();
}
