//! Acceptance benchmark (issue 11, item 3): whole runs on simulated recordings, each in a fresh process, wall time
//! and peak resident memory (VmHWM):
//! - read + vector base fit + diagnosis at 10^5 and 10^6 samples (targets: under 0.2 s; under 1 s and 300 MB);
//! - read + scalar fit without diagnosis at 10^6 samples (target: under 0.3 s);
//! - read + vector base fit without diagnosis at 10^6, for comparison.
//!
//! `cargo bench --bench pipeline`. The recordings (a LIS3MDL tumbling at 1 rad/s, 100 Hz, temperature and attitude
//! quaternions) are simulated once and cached in Cargo's target temporary directory. Each case runs
//! `MAGCAL_BENCH_RUNS` times (5 by default), alternating between cases; medians are reported.

use std::path::{Path, PathBuf};
use std::time::Instant;

use magcal_app::calibrate::{calibrate, read_to_calibrate};
use magcal_app::field::ReferenceField;
use magcal_app::fit::Method;
use magcal_recording::Recording;
use magcal_sim::{ChipModel, Scenario, Trajectory, simulate};

const CHILD_ENV: &str = "MAGCAL_BENCH_PIPELINE_CHILD";

/// One measured case: rows, method, diagnosis.
#[derive(Clone, Copy)]
struct Case {
    rows: usize,
    method: Method,
    diagnose: bool,
}

const CASES: [Case; 4] = [
    Case {
        rows: 100_000,
        method: Method::Vector,
        diagnose: true,
    },
    Case {
        rows: 1_000_000,
        method: Method::Vector,
        diagnose: true,
    },
    Case {
        rows: 1_000_000,
        method: Method::Scalar,
        diagnose: false,
    },
    Case {
        rows: 1_000_000,
        method: Method::Vector,
        diagnose: false,
    },
];

fn main() {
    if let Ok(spec) = std::env::var(CHILD_ENV) {
        let mut parts = spec.splitn(3, ' ');
        let method = match parts.next() {
            Some("scalar") => Method::Scalar,
            _ => Method::Vector,
        };
        let diagnose = parts.next() == Some("diagnose");
        let path = PathBuf::from(parts.next().expect("a path"));
        let start = Instant::now();
        let effects = run(&path, method, diagnose);
        println!(
            "{} {} {effects}",
            start.elapsed().as_secs_f64(),
            peak_rss_mb()
        );
        return;
    }
    let runs: usize = std::env::var("MAGCAL_BENCH_RUNS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(5);
    let mut results: Vec<(Vec<f64>, Vec<f64>, String)> = vec![Default::default(); CASES.len()];
    for _ in 0..runs {
        for (case, result) in CASES.iter().zip(&mut results) {
            let path = recording(case.rows);
            let spec = format!(
                "{} {} {}",
                case.method.as_str(),
                if case.diagnose { "diagnose" } else { "no" },
                path.display()
            );
            let out = std::process::Command::new(std::env::current_exe().expect("own path"))
                .env(CHILD_ENV, spec)
                .output()
                .expect("re-run self");
            assert!(
                out.status.success(),
                "child: {}",
                String::from_utf8_lossy(&out.stderr)
            );
            let report = String::from_utf8_lossy(&out.stdout).into_owned();
            let mut words = report.split_whitespace();
            let mut number = || {
                words
                    .next()
                    .and_then(|w| w.parse::<f64>().ok())
                    .expect("figures")
            };
            result.0.push(number());
            result.1.push(number());
            result.2 = words.collect::<Vec<_>>().join(" ");
        }
    }
    println!("| rows | method | diagnosis | wall s (median of {runs}) | peak MB | effects found |");
    println!("|---|---|---|---|---|---|");
    for (case, (mut wall, mut peak, effects)) in CASES.iter().zip(results) {
        println!(
            "| {} | {} | {} | {:.3} | {:.0} | {} |",
            case.rows,
            case.method.as_str(),
            if case.diagnose { "yes" } else { "no" },
            median(&mut wall),
            median(&mut peak),
            if case.diagnose {
                effects.as_str()
            } else {
                "—"
            }
        );
    }
}

/// Reads and calibrates; returns the effects the diagnosis found, in words.
fn run(path: &Path, method: Method, diagnose: bool) -> String {
    // Read as `magcal-fit` reads it for the job.
    let (rec, field) = read_to_calibrate(path, method, diagnose, |meta| {
        Ok(ReferenceField::Vector {
            field_ned_ut: meta.field_ned_ut.expect("simulated with a field"),
            source: "metadata".into(),
        })
    })
    .expect("the bench recording parses");
    let cal = calibrate(&rec, method, field, diagnose).expect("fits");
    match &cal.diagnosis {
        Some(d) if d.effects.is_empty() => "none".into(),
        Some(d) => d
            .effects
            .iter()
            .map(|e| e.effect.id().as_str())
            .collect::<Vec<_>>()
            .join(","),
        None => "-".into(),
    }
}

/// The simulated recording of `rows` samples, cached.
fn recording(rows: usize) -> PathBuf {
    let path = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("bench-tumble-{rows}.csv"));
    if Recording::read(&path).is_ok_and(|r| r.len() == rows) {
        return path;
    }
    let chip = ChipModel::by_name("lis3mdl").expect("known chip");
    let mut s = Scenario::new(
        &chip,
        Trajectory::Tumble {
            duration_s: rows as f64 / 100.0,
            rate_rad_s: 1.0,
        },
        1,
    );
    s.sample_rate_hz = 100.0;
    let run = simulate(&s).expect("valid scenario");
    assert_eq!(run.recording.len(), rows);
    run.recording.write(&path).expect("writable target dir");
    path
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Peak resident memory of this process (VmHWM), MB.
fn peak_rss_mb() -> f64 {
    let status = std::fs::read_to_string("/proc/self/status").expect("Linux /proc");
    let kb: f64 = status
        .lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
        .expect("VmHWM in /proc/self/status");
    kb * 1024.0 / 1e6
}
