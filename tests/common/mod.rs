//! Helpers shared by the integration tests.
#![allow(dead_code, reason = "each test binary uses a different subset")]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// A recording from a physical sensor in the shared data folder (`../shared/data/real/` from the repository).
pub fn real(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data/real")
        .join(rel)
}

/// Records `dir/rec.csv` from a simulated device with `magcal-record` (panics with stderr if it fails).
pub fn sim_recording(dir: &Path, device: &str, routine: &str) -> PathBuf {
    let path = dir.join("rec.csv");
    let out = Command::new(env!("CARGO_BIN_EXE_magcal-record"))
        .args(["--device", device, "--routine", routine, "--out"])
        .arg(&path)
        .output()
        .expect("magcal-record runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    path
}

/// Runs `magcal-sim` with these arguments, writing to `out`.
pub fn magcal_sim(args: &[&str], out: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_magcal-sim"))
        .args(args)
        .arg("--out")
        .arg(out)
        .output()
        .expect("magcal-sim runs")
}

/// Simulates `dir/name` with `magcal-sim` and these arguments (panics with stderr if it fails).
pub fn simulate(dir: &Path, name: &str, args: &[&str]) -> PathBuf {
    let path = dir.join(name);
    let out = magcal_sim(args, &path);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    path
}

/// Runs `magcal-fit` with these arguments.
pub fn magcal_fit(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_magcal-fit"))
        .args(args)
        .output()
        .expect("magcal-fit runs")
}

/// Runs `magcal-apply PARAMS REC` with these further arguments.
pub fn magcal_apply(params: &Path, rec: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_magcal-apply"))
        .arg(params)
        .arg(rec)
        .args(args)
        .output()
        .expect("magcal-apply runs")
}

/// Runs `magcal-fit REC --report TMP` and returns the report as JSON (panics with stderr if it fails).
pub fn fit_report(rec: &Path, extra: &[&str]) -> serde_json::Value {
    let dir = tempfile::tempdir().unwrap();
    let report = dir.path().join("report.json");
    let mut args = vec![rec.to_str().unwrap(), "--report", report.to_str().unwrap()];
    args.extend_from_slice(extra);
    let out = magcal_fit(&args);
    assert!(
        out.status.success(),
        "magcal-fit {args:?} failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap()
}

/// A JSON array of numbers as a Vec.
pub fn floats(v: &serde_json::Value) -> Vec<f64> {
    v.as_array()
        .unwrap_or_else(|| panic!("not an array: {v}"))
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

/// A JSON 3×3 matrix.
pub fn matrix(v: &serde_json::Value) -> [[f64; 3]; 3] {
    let rows: Vec<Vec<f64>> = v.as_array().unwrap().iter().map(floats).collect();
    std::array::from_fn(|j| std::array::from_fn(|k| rows[j][k]))
}

/// Runs `f(seed)` for seeds 1..=`seeds` on every core, each seed once (the statistics studies).
pub fn for_each_seed(seeds: u64, f: impl Fn(u64) + Sync) {
    let next = std::sync::atomic::AtomicU64::new(1);
    std::thread::scope(|scope| {
        for _ in 0..std::thread::available_parallelism().map_or(2, |n| n.get()) {
            scope.spawn(|| {
                loop {
                    let seed = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                    if seed > seeds {
                        break;
                    }
                    f(seed);
                }
            });
        }
    });
}

/// The ids of the effects a `magcal-fit` report's diagnosis found, in its order.
pub fn effect_ids(report: &serde_json::Value) -> Vec<&str> {
    report["diagnosis"]["effects"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e["id"].as_str().unwrap())
        .collect()
}
