//! Acceptance benchmark (issue 11, item 1): magcal's read + vector fit against a minimal parse of the same file, at
//! 10^4 to 10^7 rows, each fit checked against the truth the file was written with.
//!
//! `cargo bench --bench read_fit` writes, into a temporary directory (or `MAGCAL_BENCH_DIR`, where the files are
//! kept for other tools, e.g. `docs/bench/polars_numpy.py`), recordings of `t,mx,my,mz,temp,qw,qx,qy,qz` in which
//! every row has its own random attitude, with raw readings `A⁻¹·(R(q)ᵀ·F − b)` plus 0.1 µT of noise. For each size
//! it times, alternating, in this process:
//! - **magcal**: `read_to_calibrate` (the attitude turned into the expected field as the rows are read) + `calibrate`
//!   with the vector method and no diagnosis (noise floor, robust base fit, checks, coverage: what `magcal-fit
//!   --method vector --no-diagnose` reads and computes), and checks the fit: every
//!   entry of `A` within 1e-3 and of `b` within 0.05 µT of the truth, or the bench fails;
//! - **minimal parse**: the file read whole, cut at line ends into one piece per thread, every float parsed with
//!   `fast-float2` and summed, nothing kept.
//!
//! Then a fresh child process does magcal's read + fit once and reports its wall time and peak resident memory
//! (VmHWM). `MAGCAL_BENCH_ROWS=10000,100000` limits the sizes; `MAGCAL_BENCH_RUNS` sets the timed runs per size.

use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use magcal_app::calibrate::{calibrate, read_to_calibrate};
use magcal_app::field::ReferenceField;
use magcal_app::fit::{Fit, Method};
use magcal_calib::frames;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use rayon::prelude::*;

/// The truth every file is written with: `B = A·m + b`.
const A: [[f64; 3]; 3] = [
    [0.953, -0.020, 0.009],
    [0.015, 1.042, -0.012],
    [0.007, 0.011, 0.987],
];
const B_UT: [f64; 3] = [12.0, -30.0, 8.0];
const FIELD_NED_UT: [f64; 3] = [19.8, 1.2, 45.3];
const NOISE_UT: f64 = 0.1;
const CHILD_ENV: &str = "MAGCAL_BENCH_CHILD";

fn main() {
    if let Ok(path) = std::env::var(CHILD_ENV) {
        let start = Instant::now();
        let (a, b) = read_and_fit(Path::new(&path));
        let seconds = start.elapsed().as_secs_f64();
        check(&a, &b);
        println!("{seconds} {}", peak_rss_mb());
        return;
    }
    let sizes: Vec<usize> = std::env::var("MAGCAL_BENCH_ROWS")
        .map(|s| {
            s.split(',')
                .map(|v| v.trim().parse().expect("row counts"))
                .collect()
        })
        .unwrap_or_else(|_| vec![10_000, 100_000, 1_000_000, 10_000_000]);
    let temp = tempfile::tempdir().expect("a temporary directory");
    let dir =
        std::env::var("MAGCAL_BENCH_DIR").map_or_else(|_| temp.path().to_owned(), PathBuf::from);
    std::fs::create_dir_all(&dir).expect("bench directory");
    println!(
        "{} threads; files in {}",
        rayon::current_num_threads(),
        dir.display()
    );
    println!(
        "| rows | file MB | magcal read + vector fit, s (median) | minimal parse, s (median) | ratio | child process: \
         wall s, peak MB, bytes/row |"
    );
    println!("|---|---|---|---|---|---|");
    let mut per_row = Vec::new();
    for &n in &sizes {
        let path = dir.join(format!("independent-{n}.csv"));
        if std::fs::metadata(&path).map(|m| m.len()).unwrap_or(0) == 0 {
            write_file(&path, n);
        }
        let bytes = std::fs::metadata(&path).expect("written").len();
        let runs: usize = std::env::var("MAGCAL_BENCH_RUNS")
            .ok()
            .and_then(|s| s.parse().ok())
            .unwrap_or(if n >= 10_000_000 { 3 } else { 7 });
        let (mut ours, mut minimal) = (Vec::new(), Vec::new());
        for _ in 0..runs {
            let start = Instant::now();
            let sum = minimal_parse(&path);
            minimal.push(start.elapsed().as_secs_f64());
            assert!(sum.is_finite());
            let start = Instant::now();
            let (a, b) = read_and_fit(&path);
            ours.push(start.elapsed().as_secs_f64());
            check(&a, &b);
        }
        let (ours, minimal) = (median(&mut ours), median(&mut minimal));
        let out = std::process::Command::new(std::env::current_exe().expect("own path"))
            .env(CHILD_ENV, &path)
            .output()
            .expect("re-run self");
        assert!(
            out.status.success(),
            "child: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let report = String::from_utf8_lossy(&out.stdout);
        let mut words = report
            .split_whitespace()
            .map(|w| w.parse::<f64>().expect("child figures"));
        let (wall, peak) = (words.next().expect("wall"), words.next().expect("peak"));
        println!(
            "| {n} | {:.1} | {ours:.4} | {minimal:.4} | {:.2} | {wall:.3}, {peak:.0}, {:.0} |",
            bytes as f64 / 1e6,
            ours / minimal,
            peak * 1e6 / n as f64
        );
        per_row.push((n, ours));
    }
    for w in per_row.windows(2) {
        let ((n0, t0), (n1, t1)) = (w[0], w[1]);
        println!(
            "{n0} → {n1} rows: time × {:.2} for rows × {:.0}",
            t1 / t0,
            n1 as f64 / n0 as f64
        );
    }
}

/// magcal's read + vector fit without diagnosis, as `magcal-fit --method vector --no-diagnose` does them; returns
/// the fitted `A` and `b`.
fn read_and_fit(path: &Path) -> ([[f64; 3]; 3], [f64; 3]) {
    let (rec, field) = read_to_calibrate(path, Method::Vector, false, |meta| {
        Ok(ReferenceField::Vector {
            field_ned_ut: meta.field_ned_ut.expect("written with a field"),
            source: "metadata".into(),
        })
    })
    .expect("the bench recording parses");
    let cal = calibrate(&rec, Method::Vector, field, false).expect("fits");
    match cal.fit {
        Fit::Vector(v) => (v.a, v.b_ut),
        Fit::Scalar(_) => panic!("the vector method was asked for"),
    }
}

/// Fails unless the fit is the truth: `A` within 1e-3, `b` within 0.05 µT.
fn check(a: &[[f64; 3]; 3], b: &[f64; 3]) {
    for j in 0..3 {
        for k in 0..3 {
            assert!((a[j][k] - A[j][k]).abs() <= 1e-3, "A = {a:?}, truth {A:?}");
        }
        assert!((b[j] - B_UT[j]).abs() <= 0.05, "b = {b:?}, truth {B_UT:?}");
    }
}

/// Every float of the file parsed with `fast-float2` and summed, on all threads, nothing kept.
fn minimal_parse(path: &Path) -> f64 {
    let bytes = std::fs::read(path).expect("readable");
    let header = bytes
        .split(|b| *b == b'\n')
        .take_while(|l| l.starts_with(b"#"))
        .map(|l| l.len() + 1)
        .sum::<usize>();
    let data = &bytes[header..];
    let data = &data[memchr::memchr(b'\n', data).map_or(data.len(), |i| i + 1)..];
    let pieces = rayon::current_num_threads();
    let mut bounds = vec![0];
    for k in 1..pieces {
        let at = k * data.len() / pieces;
        bounds.push(memchr::memchr(b'\n', &data[at..]).map_or(data.len(), |i| at + i + 1));
    }
    bounds.push(data.len());
    bounds
        .par_windows(2)
        .map(|w| {
            data[w[0]..w[1]]
                .split(|b| *b == b'\n' || *b == b',')
                .filter(|f| !f.is_empty())
                .map(|f| fast_float2::parse::<f64, _>(f).expect("a number"))
                .sum::<f64>()
        })
        .sum()
}

/// Writes `n` rows with an independent random attitude each, streamed (in parallel blocks, in order).
fn write_file(path: &Path, n: usize) {
    let inv = nalgebra::Matrix3::from_fn(|j, k| A[j][k])
        .try_inverse()
        .expect("invertible");
    let mut file = std::io::BufWriter::new(std::fs::File::create(path).expect("writable"));
    writeln!(
        file,
        "# magcal-recording v1\n# sensor: bench\n# sample_rate_hz: 100\n# field_ned_ut: {}, {}, {}\n\
         t,mx,my,mz,temp,qw,qx,qy,qz",
        FIELD_NED_UT[0], FIELD_NED_UT[1], FIELD_NED_UT[2]
    )
    .expect("writable");
    const BLOCK: usize = 100_000;
    let blocks = n.div_ceil(BLOCK);
    for group in (0..blocks).collect::<Vec<_>>().chunks(8) {
        let texts: Vec<Vec<u8>> = group
            .par_iter()
            .map(|&block| {
                let mut rng = ChaCha8Rng::seed_from_u64(block as u64);
                let normal = Normal::new(0.0, 1.0).expect("unit normal");
                let mut text = Vec::with_capacity(BLOCK * 100);
                for i in block * BLOCK..((block + 1) * BLOCK).min(n) {
                    let q: [f64; 4] = std::array::from_fn(|_| normal.sample(&mut rng));
                    let norm = q.iter().map(|v| v * v).sum::<f64>().sqrt();
                    let q = q.map(|v| ((v / norm) * 1e6).round() / 1e6);
                    let expected = frames::expected_sensor_field(q, FIELD_NED_UT);
                    let m =
                        inv * (nalgebra::Vector3::from(expected) - nalgebra::Vector3::from(B_UT));
                    let m = m.map(|v| v + NOISE_UT * normal.sample(&mut rng));
                    writeln!(
                        text,
                        "{:.2},{:.3},{:.3},{:.3},{:.1},{:.6},{:.6},{:.6},{:.6}",
                        i as f64 * 0.01,
                        m[0],
                        m[1],
                        m[2],
                        23.5 + 0.5 * normal.sample(&mut rng),
                        q[0],
                        q[1],
                        q[2],
                        q[3]
                    )
                    .expect("in memory");
                }
                text
            })
            .collect();
        for t in texts {
            file.write_all(&t).expect("writable");
        }
    }
    file.flush().expect("writable");
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
