//! The incremental writer: what is on disk after a flush, a crash, a drop or a finish.

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use magcal_recording::{CreateOptions, Layout, Metadata, Note, Recording, RecordingWriter, Sample};

fn layout() -> Layout {
    Layout {
        t: true,
        temp: true,
        quat: true,
        currents: vec!["i_motor".into()],
        extra: vec!["phase".into()],
        ..Layout::default()
    }
}

fn meta() -> Metadata {
    Metadata {
        sensor: Some("lis3mdl".into()),
        sample_rate_hz: Some(100.0),
        other: vec![("operator".into(), "bench 2".into())],
        ..Metadata::default()
    }
}

fn sample(i: usize) -> Sample {
    let a = i as f64 * 0.01;
    Sample {
        t_s: a,
        mag_ut: [40.0 * a.cos(), -40.0 * a.sin(), 30.0],
        temp_c: if i % 7 == 3 { f64::NAN } else { 23.5 },
        quat: [(a / 2.0).cos(), 0.0, 0.0, (a / 2.0).sin()],
        currents_a: vec![0.1 * i as f64],
        extra: vec![if i.is_multiple_of(2) {
            "up".into()
        } else {
            "down, slowly".into()
        }],
        ..Sample::default()
    }
}

fn read(path: &Path) -> Recording {
    Recording::read(path).unwrap_or_else(|e| panic!("{e}"))
}

#[test]
fn header_is_on_disk_at_creation() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rec.csv");
    let writer = RecordingWriter::create(&path, &meta(), &layout()).unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    assert_eq!(
        text,
        "# magcal-recording v1\n# sensor: lis3mdl\n# sample_rate_hz: 100\n# operator: bench 2\n\
         t,mx,my,mz,temp,qw,qx,qy,qz,i_motor,phase\n"
    );
    assert_eq!(writer.path(), path);
    writer.finish().unwrap();
}

#[test]
fn after_a_crash_the_file_holds_every_flushed_row() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rec.csv");
    let mut writer = RecordingWriter::create(&path, &meta(), &layout())
        .unwrap()
        .with_flush_interval(Duration::from_secs(3600));
    for i in 0..10 {
        writer.write_sample(&sample(i)).unwrap();
    }
    writer.flush().unwrap();
    for i in 10..15 {
        writer.write_sample(&sample(i)).unwrap();
    }
    assert_eq!(writer.rows(), 15);
    // A crash: no finish, no drop. Only what was flushed is there, and it parses.
    std::mem::forget(writer);
    let rec = read(&path);
    assert_eq!(rec.len(), 10);
    assert_eq!(rec.extra[0].values[1], "down, slowly");
    assert_eq!(rec.missing_counts().temp, Some(1));
}

#[test]
fn rows_are_flushed_when_the_interval_has_passed() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rec.csv");
    let mut writer = RecordingWriter::create(&path, &meta(), &layout())
        .unwrap()
        .with_flush_interval(Duration::from_millis(50));
    for i in 0..20 {
        writer.write_sample(&sample(i)).unwrap();
    }
    std::thread::sleep(Duration::from_millis(60));
    writer.write_sample(&sample(20)).unwrap();
    writer.write_sample(&sample(21)).unwrap();
    std::mem::forget(writer);
    assert_eq!(
        read(&path).len(),
        21,
        "the write after the interval flushed itself and all before it"
    );

    let path = dir.path().join("every.csv");
    let mut writer = RecordingWriter::create(&path, &meta(), &layout())
        .unwrap()
        .with_flush_interval(Duration::ZERO);
    for i in 0..5 {
        writer.write_sample(&sample(i)).unwrap();
        assert_eq!(read(&path).len(), i + 1);
    }
    std::mem::forget(writer);
}

#[test]
fn drop_and_finish_write_everything() {
    let dir = tempfile::tempdir().unwrap();
    let dropped = dir.path().join("dropped.csv");
    let mut writer = RecordingWriter::create(&dropped, &meta(), &layout()).unwrap();
    for i in 0..300 {
        writer.write_sample(&sample(i)).unwrap();
    }
    drop(writer);
    assert_eq!(read(&dropped).len(), 300);

    let finished = dir.path().join("finished.csv");
    let mut writer = RecordingWriter::create(&finished, &meta(), &layout()).unwrap();
    let mut expected = Recording::new(meta(), &layout()).unwrap();
    for i in 0..300 {
        writer.write_sample(&sample(i)).unwrap();
        expected.push(&sample(i)).unwrap();
    }
    writer.finish().unwrap();
    // The writer and Recording::write format rows the same way.
    let whole = dir.path().join("whole.csv");
    expected.write(&whole).unwrap();
    assert_eq!(
        std::fs::read_to_string(&finished).unwrap(),
        std::fs::read_to_string(&whole).unwrap()
    );
    assert_eq!(read(&finished).len(), 300);
}

#[test]
fn create_fails_on_an_unwritable_path_or_an_unwritable_layout() {
    let dir = tempfile::tempdir().unwrap();
    let missing_dir = dir.path().join("no/such/dir/rec.csv");
    assert!(RecordingWriter::create(&missing_dir, &meta(), &layout()).is_err());
    assert!(
        RecordingWriter::create(dir.path(), &meta(), &layout()).is_err(),
        "a directory is not writable as a file"
    );

    let path = dir.path().join("rec.csv");
    let clash = Layout {
        extra: vec!["temp".into()],
        ..Layout::default()
    };
    let err = RecordingWriter::create(&path, &meta(), &clash).unwrap_err();
    assert_eq!(err.kind(), std::io::ErrorKind::InvalidInput);
    let bad_meta = Metadata {
        routine: Some("two\nlines".into()),
        ..Metadata::default()
    };
    assert!(RecordingWriter::create(&path, &bad_meta, &layout()).is_err());
    assert!(
        !path.exists(),
        "nothing is created when the header is refused"
    );
}

#[test]
fn samples_breaking_the_format_are_refused_and_the_file_stays_readable() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rec.csv");
    let mut writer = RecordingWriter::create(&path, &meta(), &layout()).unwrap();
    writer.write_sample(&sample(5)).unwrap();
    let refused = [
        sample(4), // t backwards
        Sample {
            mag_ut: [1.0, f64::NAN, 2.0],
            ..sample(6)
        }, // missing field
        Sample {
            quat: [0.5, 0.0, 0.0, 0.0],
            ..sample(6)
        }, // not unit
        Sample {
            currents_a: vec![],
            ..sample(6)
        }, // wrong count
        Sample {
            extra: vec![],
            ..sample(6)
        }, // wrong count
        Sample {
            temp_c: f64::INFINITY,
            ..sample(6)
        }, // infinite
    ];
    for s in &refused {
        let err = writer.write_sample(s).unwrap_err();
        assert_eq!(err.kind(), std::io::ErrorKind::InvalidInput, "{s:?}");
    }
    writer.write_sample(&sample(5)).unwrap();
    writer.finish().unwrap();
    assert_eq!(read(&path).len(), 2);
}

/// Set in the child process of [`a_killed_recorder_leaves_a_readable_file`]: the path to write to.
const CHILD_ENV: &str = "MAGCAL_RECORDING_TEST_KILLED_WRITER";

#[test]
fn a_killed_recorder_leaves_a_readable_file() {
    if let Some(path) = std::env::var_os(CHILD_ENV) {
        // The child: record until killed (or give up after 20 s).
        let mut writer = RecordingWriter::create(Path::new(&path), &meta(), &layout())
            .unwrap()
            .with_flush_interval(Duration::from_millis(20));
        let start = Instant::now();
        let mut i = 0;
        while start.elapsed() < Duration::from_secs(20) {
            writer.write_sample(&sample(i)).unwrap();
            i += 1;
            std::thread::sleep(Duration::from_micros(200));
        }
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("killed.csv");
    let mut child = Command::new(std::env::current_exe().unwrap())
        .args([
            "a_killed_recorder_leaves_a_readable_file",
            "--exact",
            "--test-threads=1",
        ])
        .env(CHILD_ENV, &path)
        .stdout(Stdio::null())
        .spawn()
        .unwrap();
    let deadline = Instant::now() + Duration::from_secs(15);
    let lines = || {
        std::fs::read(&path)
            .map(|b| b.iter().filter(|c| **c == b'\n').count())
            .unwrap_or(0)
    };
    while lines() < 500 && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(10));
    }
    child.kill().unwrap(); // SIGKILL: no destructor, no flush.
    child.wait().unwrap();
    let rec = read(&path);
    assert!(rec.len() >= 400, "only {} rows", rec.len());
    let t = rec.t_s.as_ref().unwrap();
    assert!(
        t.iter()
            .enumerate()
            .all(|(i, t)| (t - i as f64 * 0.01).abs() < 1e-9),
        "rows in order, none lost"
    );
}

#[test]
fn create_new_never_replaces_a_file_and_create_does() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rec.csv");
    std::fs::write(&path, "precious").unwrap();
    let err = RecordingWriter::create_new(&path, &meta(), &layout()).unwrap_err();
    assert_eq!(err.kind(), std::io::ErrorKind::AlreadyExists);
    assert_eq!(std::fs::read_to_string(&path).unwrap(), "precious");
    let mut w = RecordingWriter::create(&path, &meta(), &layout()).unwrap();
    w.write_sample(&sample(0)).unwrap();
    w.finish().unwrap();
    assert_eq!(read(&path).len(), 1);
}

#[test]
fn a_second_writer_on_the_same_file_is_refused_before_it_changes_anything() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rec.csv");
    let mut first = RecordingWriter::create_new(&path, &meta(), &layout()).unwrap();
    for i in 0..5 {
        first.write_sample(&sample(i)).unwrap();
    }
    first.flush().unwrap();
    let err = RecordingWriter::create(&path, &meta(), &layout()).unwrap_err();
    assert_eq!(err.kind(), std::io::ErrorKind::WouldBlock, "{err}");
    assert!(
        err.to_string().contains("being written by another process"),
        "{err}"
    );
    first.write_sample(&sample(5)).unwrap();
    first.finish().unwrap();
    assert_eq!(read(&path).len(), 6, "the first writer's file is intact");
    // The lock goes with the writer.
    RecordingWriter::create(&path, &meta(), &layout()).unwrap();
}

#[test]
fn notes_are_rewritten_in_place_and_read_as_metadata() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rec.csv");
    let opts = CreateOptions {
        overwrite: false,
        notes: vec![Note {
            key: "segments".into(),
            value: "1".into(),
            width: 40,
        }],
    };
    let mut w = RecordingWriter::create_with(&path, &meta(), &layout(), &opts).unwrap();
    for i in 0..3 {
        w.write_sample(&sample(i)).unwrap();
    }
    w.flush().unwrap();
    assert_eq!(
        read(&path).meta.other.last(),
        Some(&("segments".into(), "1".into()))
    );
    w.set_note("segments", "2 (a restart at t = 0.02 s)")
        .unwrap();
    assert!(w.set_note("segments", &"x".repeat(41)).is_err(), "too wide");
    assert!(w.set_note("other", "1").is_err(), "not a note");
    for i in 3..6 {
        w.write_sample(&sample(i)).unwrap();
    }
    w.finish().unwrap();
    let rec = read(&path);
    assert_eq!(rec.len(), 6);
    assert_eq!(
        rec.meta.other.last(),
        Some(&("segments".into(), "2 (a restart at t = 0.02 s)".into()))
    );
    let bad = CreateOptions {
        overwrite: true,
        notes: vec![Note {
            key: "sensor".into(),
            value: "x".into(),
            width: 4,
        }],
    };
    let err = RecordingWriter::create_with(&path, &meta(), &layout(), &bad).unwrap_err();
    assert_eq!(err.kind(), std::io::ErrorKind::InvalidInput);
    assert_eq!(read(&path).len(), 6, "refused before the file was touched");
}

#[test]
fn a_replaced_file_stays_until_the_first_row_and_a_link_is_replaced_itself() {
    let dir = tempfile::tempdir().unwrap();
    let files = |d: &Path| std::fs::read_dir(d).unwrap().count();
    let path = dir.path().join("rec.csv");
    std::fs::write(&path, "precious").unwrap();
    // No row: the old file stays, and no temporary file remains.
    let w = RecordingWriter::create(&path, &meta(), &layout()).unwrap();
    assert!(w.replacing());
    w.finish().unwrap();
    assert_eq!(std::fs::read_to_string(&path).unwrap(), "precious");
    assert_eq!(files(dir.path()), 1);
    // The first row replaces it. (The lock the first writer held may linger for a moment in a child process another
    // test forks, until it execs: try again briefly.)
    let mut w = (0..100)
        .find_map(|_| {
            RecordingWriter::create(&path, &meta(), &layout())
                .inspect_err(|e| {
                    assert_eq!(e.kind(), std::io::ErrorKind::WouldBlock, "{e}");
                    std::thread::sleep(Duration::from_millis(10));
                })
                .ok()
        })
        .expect("the lock is released")
        .with_flush_interval(Duration::ZERO);
    assert_eq!(std::fs::read_to_string(&path).unwrap(), "precious");
    w.write_sample(&sample(0)).unwrap();
    assert!(!w.replacing());
    assert_eq!(read(&path).len(), 1);
    w.write_sample(&sample(1)).unwrap();
    w.finish().unwrap();
    assert_eq!(read(&path).len(), 2);
    // A symbolic link and a hard link: the name given is replaced, the other names keep their bytes.
    let kept = dir.path().join("kept.csv");
    std::fs::write(&kept, "kept").unwrap();
    let symbolic = dir.path().join("symbolic.csv");
    std::os::unix::fs::symlink(&kept, &symbolic).unwrap();
    let hard = dir.path().join("hard.csv");
    std::fs::hard_link(&kept, &hard).unwrap();
    for link in [&symbolic, &hard] {
        let mut w = RecordingWriter::create(link, &meta(), &layout()).unwrap();
        w.write_sample(&sample(0)).unwrap();
        w.finish().unwrap();
        assert_eq!(read(link).len(), 1);
        assert_eq!(std::fs::read_to_string(&kept).unwrap(), "kept");
    }
    assert!(!std::fs::symlink_metadata(&symbolic).unwrap().is_symlink());
    assert_eq!(files(dir.path()), 4);
}
