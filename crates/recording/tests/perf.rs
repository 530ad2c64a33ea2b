//! Read time and peak memory for a synthetic 1,000,000-row recording. Ignored by default; run with
//! `cargo test -p magcal-recording --release --test perf -- --ignored --nocapture`.

use std::fmt::Write as _;
use std::io::Write as _;
use std::time::Instant;

use magcal_recording::Recording;

/// Peak resident memory of this process so far (Linux), MiB.
fn peak_rss_mib() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib / 1024.0)
}

/// A 1e6-row file with columns t,mx,my,mz,temp,qw,qx,qy,qz, written with few digits as a bench logger would
/// (about 60 MB), streamed to disk so that writing it does not raise the peak memory.
fn write_synthetic(path: &std::path::Path, rows: usize) {
    let mut file = std::io::BufWriter::new(std::fs::File::create(path).unwrap());
    writeln!(
        file,
        "# magcal-recording v1\n# sensor: synthetic\n# sample_rate_hz: 100"
    )
    .unwrap();
    writeln!(file, "t,mx,my,mz,temp,qw,qx,qy,qz").unwrap();
    let mut line = String::new();
    for i in 0..rows {
        let a = i as f64 * 1e-3;
        let (s, c) = (0.5 * a).sin_cos();
        line.clear();
        writeln!(
            line,
            "{:.3},{:.3},{:.3},{:.3},{:.1},{:.6},{:.6},{:.6},{:.6}",
            i as f64 * 0.01,
            40.0 * a.cos(),
            -40.0 * a.sin(),
            30.0 + a.sin(),
            23.5 + 0.1 * a.sin(),
            c,
            s * 0.6,
            s * 0.8,
            0.0
        )
        .unwrap();
        file.write_all(line.as_bytes()).unwrap();
    }
    file.flush().unwrap();
}

#[test]
#[ignore = "timing; run in release with --ignored --nocapture"]
fn read_one_million_rows() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("big.csv");
    let rows = 1_000_000;
    write_synthetic(&path, rows);
    let bytes = std::fs::metadata(&path).unwrap().len();
    let before = peak_rss_mib();
    let mut best = f64::INFINITY;
    for _ in 0..3 {
        let start = Instant::now();
        let rec = Recording::read(&path).unwrap();
        best = best.min(start.elapsed().as_secs_f64());
        assert_eq!(rec.len(), rows);
        assert_eq!(rec.missing_counts().quat, Some(0));
    }
    println!(
        "read {rows} rows, {:.1} MB: best of 3 {:.3} s ({:.0} MB/s); peak RSS before {:?} MiB, after {:?} MiB",
        bytes as f64 / 1e6,
        best,
        bytes as f64 / 1e6 / best,
        before,
        peak_rss_mib()
    );

    // The same rows as written by this crate (more digits, larger file).
    let rec = Recording::read(&path).unwrap();
    let ours = dir.path().join("ours.csv");
    let start = Instant::now();
    rec.write(&ours).unwrap();
    let write_s = start.elapsed().as_secs_f64();
    drop(rec);
    let start = Instant::now();
    let back = Recording::read(&ours).unwrap();
    println!(
        "written by Recording::write: {:.1} MB in {write_s:.3} s; read back in {:.3} s",
        std::fs::metadata(&ours).unwrap().len() as f64 / 1e6,
        start.elapsed().as_secs_f64()
    );
    assert_eq!(back.len(), rows);
}
