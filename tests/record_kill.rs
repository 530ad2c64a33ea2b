//! Acceptance: kill -9 at random moments of every routine. Each killed recorder's file parses, is the start of what
//! an uninterrupted recording of the same simulated bench writes, and lacks at most the last 0.5 s of it.
//!
//! Slow (a whole routine in real time, 20 recorders at once per routine): `#[ignore]`d, run by CI in release:
//! `cargo test --release --test record_kill -- --ignored --nocapture`.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use magcal_recording::{ReadErrorKind, Recording};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Kills per routine.
const KILLS: usize = 20;
/// The most a killed recorder may lose, s.
const MAX_LOSS_S: f64 = 0.5;

fn recorder(routine: &str, out: &Path, paced: bool) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_magcal-record"));
    c.args(["--device", "sim:lis3mdl", "--routine", routine, "--out"])
        .arg(out)
        .stdout(Stdio::null())
        .stderr(Stdio::null());
    if paced {
        c.arg("--realtime");
    }
    c
}

/// The rows of a recording, as comparable text.
fn rows(rec: &Recording) -> Vec<String> {
    rec.rows()
        .map(|r| format!("{:?} {:?} {:?} {:?}", r.t_s, r.mag_ut, r.temp_c, r.quat))
        .collect()
}

/// Kills a paced recorder of `routine` at each of `moments_s` (wall time after its start) and returns, per kill,
/// the moment and the loss bound in s: the recorder's clock at the kill is at most the wall time since it was
/// started, so what the file lacks of the reference up to then bounds what was lost.
fn kill_study(
    routine: &str,
    reference: &Recording,
    moments_s: &[f64],
    dir: &Path,
) -> Vec<(f64, f64)> {
    let paths: Vec<PathBuf> = (0..moments_s.len())
        .map(|i| dir.join(format!("{routine}-{i}.csv")))
        .collect();
    let mut children: Vec<_> = paths
        .iter()
        .map(|p| (recorder(routine, p, true).spawn().unwrap(), Instant::now()))
        .collect();
    let mut order: Vec<usize> = (0..moments_s.len()).collect();
    order.sort_by(|a, b| moments_s[*a].total_cmp(&moments_s[*b]));
    let mut wall_at_kill = vec![0.0; moments_s.len()];
    for i in order {
        let (child, started) = &mut children[i];
        let at = *started + Duration::from_secs_f64(moments_s[i]);
        if let Some(wait) = at.checked_duration_since(Instant::now()) {
            std::thread::sleep(wait);
        }
        child.kill().unwrap(); // SIGKILL
        wall_at_kill[i] = started.elapsed().as_secs_f64();
        child.wait().unwrap();
    }
    let reference_rows = rows(reference);
    let t_ref = reference.t_s.as_ref().unwrap();
    paths
        .iter()
        .zip(&wall_at_kill)
        .zip(moments_s)
        .map(|((path, &wall_s), &moment_s)| {
            let kept = match Recording::read(path) {
                Ok(rec) => rows(&rec),
                // Killed before its first row reached the file: the header alone is a valid start.
                Err(e) if matches!(e.kind(), ReadErrorKind::NoData) => Vec::new(),
                Err(e) => panic!("{routine} killed at {moment_s:.2} s: the file does not parse: {e}"),
            };
            assert!(
                kept.len() <= reference_rows.len() && kept[..] == reference_rows[..kept.len()],
                "{routine} killed at {moment_s:.2} s: the file is not the start of the uninterrupted recording"
            );
            let loss_s = t_ref.get(kept.len()).map_or(0.0, |t| (wall_s - t).max(0.0));
            (moment_s, loss_s)
        })
        .collect()
}

#[test]
#[ignore = "slow (real-time routines); run in release with --ignored --nocapture"]
fn kill_9_at_random_moments_of_every_routine_loses_at_most_half_a_second() {
    let dir = tempfile::tempdir().unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(8);
    for routine in ["free", "cube24"] {
        let reference_path = dir.path().join(format!("{routine}-reference.csv"));
        assert!(
            recorder(routine, &reference_path, false)
                .status()
                .unwrap()
                .success()
        );
        let reference = Recording::read(&reference_path).unwrap();
        let duration_s = *reference.t_s.as_ref().unwrap().last().unwrap();
        let moments: Vec<f64> = (0..KILLS)
            .map(|_| rng.random_range(0.5..duration_s))
            .collect();
        let mut results = kill_study(routine, &reference, &moments, dir.path());
        results.sort_by(|a, b| a.1.total_cmp(&b.1));
        let losses: Vec<f64> = results.iter().map(|r| r.1).collect();
        println!(
            "{routine}: {KILLS} kills over {duration_s:.1} s; loss bound median {:.3} s, max {:.3} s (at {:.2} s)",
            losses[KILLS / 2],
            losses[KILLS - 1],
            results[KILLS - 1].0
        );
        for (moment_s, loss_s) in &results {
            assert!(
                *loss_s <= MAX_LOSS_S,
                "{routine} killed at {moment_s:.2} s lost up to {loss_s:.3} s"
            );
        }
    }
}
