//! Acceptance benchmark (issue 36, item 2): a batch of 1000 simulated recordings of 6000 samples each (a LIS3MDL lot:
//! hard and soft iron and noise spread, 25 boards with a magnet near, 15 files cut off, 10 boards not rotated
//! enough), fitted as `magcal-batch` fits them — two at a time, the table written as a CSV journal and a JSON — each
//! run in a fresh process, its wall time and peak resident memory (VmHWM) measured there. Target: under 30 s and
//! 200 MB without the diagnosis; the figure with it is reported.
//!
//! `cargo bench --bench batch`. The lot (about 235 MB of recordings) is simulated once and cached in Cargo's target
//! temporary directory, so runs read it from the page cache. Each case runs `MAGCAL_BENCH_RUNS` times (3 by
//! default), alternating; medians are reported. Every run's table is checked: a row per recording, the 25 failures
//! and the 25 outliers.

#[path = "../tests/lot/mod.rs"]
mod lot;

use std::path::{Path, PathBuf};
use std::time::Instant;

use lot::{LotSpec, write_lot};
use magcal_app::batch::{BatchOptions, FitOptions, run};

const CHILD_ENV: &str = "MAGCAL_BENCH_BATCH_CHILD";

const SPEC: LotSpec = LotSpec {
    boards: 1000,
    magnets: 25,
    truncated: 15,
    unrotated: 10,
    samples: 6000,
    seed: 2036,
};

/// Recordings fitted at once: one per core of the 2-core development machine.
const JOBS: usize = 2;

fn main() {
    if let Ok(spec) = std::env::var(CHILD_ENV) {
        let (diagnose, dir) = spec.split_once(' ').expect("diagnosis and folder");
        child(diagnose == "diagnose", Path::new(dir));
        return;
    }
    let runs: usize = std::env::var("MAGCAL_BENCH_RUNS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(3);
    let dir = lot_dir();
    let cases = [("no diagnosis", false), ("with the diagnosis", true)];
    let mut results: Vec<(Vec<f64>, Vec<f64>)> = vec![Default::default(); cases.len()];
    for _ in 0..runs {
        for (&(_, diagnose), (walls, peaks)) in cases.iter().zip(&mut results) {
            let out = std::process::Command::new(std::env::current_exe().expect("the bench"))
                .env(
                    CHILD_ENV,
                    format!(
                        "{} {}",
                        if diagnose { "diagnose" } else { "base" },
                        dir.display()
                    ),
                )
                .output()
                .expect("the child runs");
            assert!(
                out.status.success(),
                "{}",
                String::from_utf8_lossy(&out.stderr)
            );
            let text = String::from_utf8_lossy(&out.stdout);
            let mut fields = text.split_whitespace().map(|f| f.parse::<f64>().unwrap());
            walls.push(fields.next().unwrap());
            peaks.push(fields.next().unwrap());
        }
    }
    println!(
        "batch of {} recordings x {} samples, {JOBS} at a time, median of {runs} runs (each a fresh process):",
        SPEC.boards, SPEC.samples
    );
    for ((name, _), (walls, peaks)) in cases.iter().zip(&mut results) {
        let per_file_ms = 1e3 * median(walls) / SPEC.boards as f64;
        println!(
            "  {name:<20} wall {:>6.1} s ({per_file_ms:.1} ms a recording; runs {}), peak memory {:>5.0} MB",
            median(walls),
            walls
                .iter()
                .map(|w| format!("{w:.1}"))
                .collect::<Vec<_>>()
                .join(", "),
            median(peaks)
        );
    }
}

/// One run: the batch, checked, then its wall time and peak memory on standard output.
fn child(diagnose: bool, dir: &Path) {
    let out = tempfile::tempdir().expect("a temporary folder");
    let opts = BatchOptions {
        inputs: vec![dir.to_owned()],
        fit: FitOptions {
            diagnose,
            ..FitOptions::default()
        },
        out: Some(out.path().join("table.csv")),
        json: Some(out.path().join("table.json")),
        jobs: JOBS,
        progress: false,
    };
    let start = Instant::now();
    let batch = run(&opts).expect("the batch runs");
    let wall_s = start.elapsed().as_secs_f64();
    assert_eq!(batch.rows.len(), SPEC.boards);
    let failed = batch.rows.iter().filter(|r| r.fit.is_none()).count();
    assert_eq!(failed, SPEC.truncated + SPEC.unrotated);
    let flagged = batch.lots[0]
        .outliers
        .iter()
        .map(|o| &o.id)
        .collect::<std::collections::HashSet<_>>()
        .len();
    assert_eq!(flagged, SPEC.magnets);
    println!("{wall_s} {}", peak_rss_mb());
}

/// The lot's folder, simulated on first use.
fn lot_dir() -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!(
        "batch-lot-{}x{}-{}",
        SPEC.boards, SPEC.samples, SPEC.seed
    ));
    let done = dir.join(".complete");
    if !done.exists() {
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("the lot's folder");
        let start = Instant::now();
        write_lot(&dir, &SPEC);
        std::fs::write(&done, b"").expect("the marker");
        println!(
            "simulated the lot in {:.0} s: {}",
            start.elapsed().as_secs_f64(),
            dir.display()
        );
    }
    dir
}

fn median(x: &mut [f64]) -> f64 {
    x.sort_by(f64::total_cmp);
    x[x.len() / 2]
}

/// This process's peak resident memory, MB.
fn peak_rss_mb() -> f64 {
    let status = std::fs::read_to_string("/proc/self/status").expect("Linux /proc");
    let kb: f64 = status
        .lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
        .expect("VmHWM in /proc/self/status");
    kb * 1024.0 / 1e6
}
