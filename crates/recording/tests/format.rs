//! What the reader accepts and what the writer writes: metadata, missing values, extra columns, CRLF, round trips.

use magcal_recording::{
    Date, Layout, Location, Metadata, MissingCounts, ReadErrorKind, Recording, Sample, SampleError,
};

fn parse(text: &str) -> Recording {
    Recording::from_reader("test.csv", text.as_bytes()).unwrap_or_else(|e| panic!("{e}"))
}

const SPEC_EXAMPLE: &str = "\
# magcal-recording v1
# sensor: lis3mdl
# sample_rate_hz: 100
# field_ned_ut: 19.8, 1.2, 45.3
t,mx,my,mz,temp,qw,qx,qy,qz
0.000,12.345,-3.210,40.120,23.5,1,0,0,0
";

/// Every kind of column, missing values of each kind, unknown metadata, text needing quotes.
const RICH: &str = "\
# magcal-recording v1
# units: uT
# sensor: lis3mdl on the bench
# sample_rate_hz: 142.857
# field_ned_ut: 19.8, 1.2, 45.3
# location: 52.51, 13.32, 50
# this line is a comment
# date: 2021-05-10
# routine: slow turns
# started: 2021-05-10T09:30:00+02:00
# field_source: WMM2020, at the bench
note,i_motor,gz,gy,gx,qz,qy,qx,qw,temp,mz,my,mx,t,rx,ry,rz,i_coil
first,0.5,0.01,0.02,0.03,0,0,0,1,23.5,40.12,-3.21,12.345,0.000,1,2,3,0.1
\"with, comma\",,nan,0.02,0.03,0.6,0.8,0,0,NaN,40.12,-3.21,12.345,0.010,1,2,3,
\"say \"\"hi\"\"\",0.7,0.01,0.02,0.03,,0.8,0,0,23.6,40.12,-3.21,12.345,0.010,NAN,2,3,0.2
,0.7,0.01,0.02,0.03,0.5,0.5,0.5,0.5,23.6,41,-3,12,0.02,-nan,,,0.2
";

#[test]
fn the_spec_example_reads() {
    let rec = parse(SPEC_EXAMPLE);
    assert_eq!(rec.len(), 1);
    assert_eq!(rec.meta.sensor.as_deref(), Some("lis3mdl"));
    assert_eq!(rec.meta.sample_rate_hz, Some(100.0));
    assert_eq!(rec.meta.field_ned_ut, Some([19.8, 1.2, 45.3]));
    assert_eq!(rec.t_s, Some(vec![0.0]));
    assert_eq!(rec.mag_ut, [[12.345, -3.21, 40.12]]);
    assert_eq!(rec.temp_c, Some(vec![23.5]));
    assert_eq!(rec.quat, Some(vec![[1.0, 0.0, 0.0, 0.0]]));
    assert!(
        rec.ref_ut.is_none()
            && rec.gyro_rad_s.is_none()
            && rec.currents.is_empty()
            && rec.extra.is_empty()
    );
}

#[test]
fn metadata_typed_and_unknown_keys_in_order() {
    let rec = parse(RICH);
    let m = &rec.meta;
    assert_eq!(m.sensor.as_deref(), Some("lis3mdl on the bench"));
    assert_eq!(m.sample_rate_hz, Some(142.857));
    assert_eq!(
        m.location,
        Some(Location {
            lat_deg: 52.51,
            lon_deg: 13.32,
            alt_m: 50.0
        })
    );
    assert_eq!(
        m.date,
        Some(Date {
            year: 2021,
            month: 5,
            day: 10
        })
    );
    assert_eq!(m.routine.as_deref(), Some("slow turns"));
    assert_eq!(m.started.as_deref(), Some("2021-05-10T09:30:00+02:00"));
    assert_eq!(
        m.other,
        [
            ("units".to_owned(), "uT".to_owned()),
            (
                "field_source".to_owned(),
                "WMM2020, at the bench".to_owned()
            )
        ]
    );
}

#[test]
fn columns_in_any_order_missing_values_and_extra_text() {
    let rec = parse(RICH);
    assert_eq!(rec.len(), 4);
    assert_eq!(
        rec.t_s,
        Some(vec![0.0, 0.01, 0.01, 0.02]),
        "equal timestamps are allowed"
    );
    assert_eq!(rec.mag_ut[3], [12.0, -3.0, 41.0]);
    let temp = rec.temp_c.as_ref().unwrap();
    assert!(temp[1].is_nan() && temp[2] == 23.6);
    // qw,qx,qy,qz = (1,0,0,0), (0,0,0.8,0.6), missing (qz empty), (0.5,0.5,0.5,0.5)
    let quat = rec.quat.as_ref().unwrap();
    assert_eq!(quat[0], [1.0, 0.0, 0.0, 0.0]);
    assert_eq!(quat[1], [0.0, 0.0, 0.8, 0.6]);
    assert!(
        quat[2].iter().all(|v| v.is_nan()),
        "a group with one missing field is missing as a whole"
    );
    assert_eq!(quat[3], [0.5; 4]);
    let reference = rec.ref_ut.as_ref().unwrap();
    assert_eq!(reference[0], [1.0, 2.0, 3.0]);
    assert!(reference[2].iter().all(|v| v.is_nan()) && reference[3].iter().all(|v| v.is_nan()));
    let gyro = rec.gyro_rad_s.as_ref().unwrap();
    assert_eq!(gyro[0], [0.03, 0.02, 0.01]);
    assert!(gyro[1].iter().all(|v| v.is_nan()));
    let names: Vec<&str> = rec.currents.iter().map(|c| c.name.as_str()).collect();
    assert_eq!(names, ["i_motor", "i_coil"]);
    assert!(rec.currents[0].values[1].is_nan() && rec.currents[1].values[1].is_nan());
    assert_eq!(rec.currents[1].values[3], 0.2);
    assert_eq!(rec.extra.len(), 1);
    assert_eq!(rec.extra[0].name, "note");
    assert_eq!(
        rec.extra[0].values,
        ["first", "with, comma", "say \"hi\"", ""]
    );

    assert_eq!(
        rec.missing_counts(),
        MissingCounts {
            rows: 4,
            temp: Some(1),
            quat: Some(1),
            reference: Some(2),
            gyro: Some(1),
            currents: vec![("i_motor".into(), 1), ("i_coil".into(), 1)],
        }
    );
    let layout = rec.layout();
    assert!(layout.t && layout.temp && layout.quat && layout.reference && layout.gyro);
    assert_eq!(layout.currents, ["i_motor", "i_coil"]);
    assert_eq!(layout.extra, ["note"]);

    let row = rec.row(2);
    assert_eq!(row.index(), 2);
    assert_eq!(row.t_s, 0.01);
    assert_eq!(row.currents_a().collect::<Vec<_>>(), [0.7, 0.2]);
    assert_eq!(row.extra().collect::<Vec<_>>(), ["say \"hi\""]);
    assert_eq!(row.to_sample().extra, ["say \"hi\""]);
    assert_eq!(rec.rows().len(), 4);
}

#[test]
fn crlf_no_magic_blank_lines_bom_and_blanks_around_fields() {
    let lf = parse(RICH);
    let crlf = parse(&RICH.replace('\n', "\r\n"));
    assert_eq!(format!("{lf:?}"), format!("{crlf:?}"), "CRLF reads as LF");

    let hand_made = "\u{feff}\n# sensor: by hand\n\n mx , my , mz \n 1 , 2 , 3 \n\n4,5,6";
    let rec = parse(hand_made);
    assert_eq!(rec.mag_ut, [[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]);
    assert_eq!(rec.meta.sensor.as_deref(), Some("by hand"));
    assert!(rec.t_s.is_none());
    let bare = parse("mx,my,mz\n1,2,3");
    assert_eq!(bare.meta, Metadata::default());
    assert_eq!(bare.len(), 1);
}

fn assert_close(a: &Recording, b: &Recording) {
    assert_eq!(a.meta, b.meta);
    assert_eq!(a.layout(), b.layout());
    assert_eq!(a.len(), b.len());
    let close = |x: f64, y: f64, tol: f64| (x.is_nan() && y.is_nan()) || (x - y).abs() <= tol;
    for (ra, rb) in a.rows().zip(b.rows()) {
        let i = ra.index();
        assert!(close(ra.t_s, rb.t_s, 5e-7), "t row {i}");
        assert!(close(ra.temp_c, rb.temp_c, 5e-4), "temp row {i}");
        let pairs = ra
            .mag_ut
            .iter()
            .chain(&ra.ref_ut)
            .zip(rb.mag_ut.iter().chain(&rb.ref_ut));
        assert!(
            pairs.clone().all(|(x, y)| close(*x, *y, 5e-7)),
            "field row {i}"
        );
        assert!(
            ra.gyro_rad_s
                .iter()
                .zip(&rb.gyro_rad_s)
                .all(|(x, y)| close(*x, *y, 5e-7)),
            "gyro row {i}"
        );
        assert!(
            ra.quat
                .iter()
                .zip(&rb.quat)
                .all(|(x, y)| close(*x, *y, 2e-9)),
            "quat row {i}"
        );
        assert!(
            ra.currents_a()
                .zip(rb.currents_a())
                .all(|(x, y)| close(x, y, 5e-7)),
            "currents row {i}"
        );
        assert!(ra.extra().eq(rb.extra()), "extra row {i}");
    }
}

#[test]
fn read_write_read_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let first = parse(RICH);
    let path = dir.path().join("rich.csv");
    first.write(&path).unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(
        text.starts_with("# magcal-recording v1\n# sensor: lis3mdl on the bench\n"),
        "{text}"
    );
    assert!(
        text.contains("\n# units: uT\n# field_source: WMM2020, at the bench\n"),
        "{text}"
    );
    assert!(
        text.contains("\nt,mx,my,mz,temp,qw,qx,qy,qz,rx,ry,rz,gx,gy,gz,i_motor,i_coil,note\n"),
        "fixed column order: {text}"
    );
    assert!(
        text.contains(",\"with, comma\"\n") && text.contains(",\"say \"\"hi\"\"\"\n"),
        "{text}"
    );
    assert!(
        text.contains("\n0.010000,12.345000,-3.210000,40.120000,,0.000000000,0.000000000,"),
        "{text}"
    );
    let second = Recording::read(&path).unwrap();
    assert_close(&first, &second);

    // Written again, the file is byte for byte the same.
    let again = dir.path().join("again.csv");
    second.write(&again).unwrap();
    assert_eq!(std::fs::read_to_string(&again).unwrap(), text);
    let leftovers: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .filter(|n| n != "rich.csv" && n != "again.csv")
        .collect();
    assert!(leftovers.is_empty(), "temporary files left: {leftovers:?}");
}

#[test]
fn write_replaces_atomically_and_refuses_broken_recordings() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rec.csv");
    parse(SPEC_EXAMPLE).write(&path).unwrap();
    let good = std::fs::read(&path).unwrap();

    let mut broken = parse(SPEC_EXAMPLE);
    broken.mag_ut[0][1] = f64::NAN;
    let err = broken.write(&path).unwrap_err();
    assert_eq!(err.kind(), std::io::ErrorKind::InvalidInput);
    let mut uneven = parse(SPEC_EXAMPLE);
    uneven.temp_c.as_mut().unwrap().push(1.0);
    assert_eq!(
        uneven.write(&path).unwrap_err().kind(),
        std::io::ErrorKind::InvalidInput
    );
    let mut bad_meta = parse(SPEC_EXAMPLE);
    bad_meta.meta.other.push(("sensor".into(), "again".into()));
    assert_eq!(
        bad_meta.write(&path).unwrap_err().kind(),
        std::io::ErrorKind::InvalidInput
    );
    assert_eq!(
        std::fs::read(&path).unwrap(),
        good,
        "a refused write leaves the file alone"
    );
    assert_eq!(
        std::fs::read_dir(dir.path()).unwrap().count(),
        1,
        "no temporary file left"
    );

    assert!(
        parse(SPEC_EXAMPLE)
            .write(&dir.path().join("no/such/dir/rec.csv"))
            .is_err()
    );
}

#[test]
fn built_in_memory_with_push() {
    let layout = Layout {
        t: true,
        quat: true,
        gyro: true,
        currents: vec!["i_coil".into()],
        extra: vec!["phase".into()],
        ..Layout::default()
    };
    let meta = Metadata {
        sensor: Some("sim".into()),
        date: Some("2024-02-29".parse().unwrap()),
        other: vec![("seed".into(), "42".into())],
        ..Metadata::default()
    };
    let mut rec = Recording::new(meta, &layout).unwrap();
    for i in 0..100 {
        let a = f64::from(i) * 0.1;
        let s = Sample {
            t_s: f64::from(i) * 0.01,
            mag_ut: [40.0 * a.cos(), 40.0 * a.sin(), 30.0],
            quat: [1.004 * (a / 2.0).cos(), 0.0, 0.0, 1.004 * (a / 2.0).sin()],
            gyro_rad_s: if i % 10 == 3 {
                [f64::NAN, 0.0, 0.0]
            } else {
                [0.0, 0.0, 10.0]
            },
            temp_c: 99.0, // not in the layout: ignored
            currents_a: vec![if i % 2 == 0 { 0.25 } else { f64::NAN }],
            extra: vec![format!("p{i}")],
            ..Sample::default()
        };
        rec.push(&s).unwrap();
    }
    let q = rec.quat.as_ref().unwrap()[7];
    assert!(
        (q.iter().map(|v| v * v).sum::<f64>() - 1.0).abs() < 1e-12,
        "stored normalised"
    );
    assert_eq!(rec.missing_counts().gyro, Some(10));
    assert_eq!(rec.missing_counts().currents, [("i_coil".to_owned(), 50)]);
    assert!(rec.temp_c.is_none());

    let late = Sample {
        t_s: 0.5,
        mag_ut: [1.0; 3],
        currents_a: vec![0.0],
        extra: vec![String::new()],
        ..Sample::default()
    };
    assert!(matches!(
        rec.push(&late),
        Err(SampleError::TimeBackwards { .. })
    ));
    assert_eq!(rec.len(), 100, "a refused sample is not stored");

    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("sim.csv");
    rec.write(&path).unwrap();
    assert_close(&rec, &Recording::read(&path).unwrap());

    // Every column keeps the same rows.
    let mut odd = rec.clone();
    odd.retain_rows(&(0..100).map(|i| i % 2 == 1).collect::<Vec<_>>());
    assert_eq!(odd.len(), 50);
    for (k, row) in odd.rows().enumerate() {
        // (Debug: NaN marks the missing values, and NaN ≠ NaN.)
        let want = rec.row(2 * k + 1).to_sample();
        assert_eq!(format!("{:?}", row.to_sample()), format!("{want:?}"));
    }

    assert!(
        Recording::new(
            Metadata::default(),
            &Layout {
                currents: vec!["motor".into()],
                ..Layout::default()
            }
        )
        .is_err()
    );
    let bad_date = Metadata {
        date: Some(Date {
            year: 2021,
            month: 2,
            day: 30,
        }),
        ..Metadata::default()
    };
    assert!(Recording::new(bad_date, &Layout::default()).is_err());
}

#[test]
fn unknown_columns_named_like_currents_or_empty_prefix() {
    let rec = parse("mx,my,mz,i_,ix,current\n1,2,3,a,b,c\n");
    assert!(rec.currents.is_empty());
    let names: Vec<&str> = rec.extra.iter().map(|c| c.name.as_str()).collect();
    assert_eq!(names, ["i_", "ix", "current"]);
}

#[test]
fn not_a_recording_is_refused_by_its_header() {
    let err = Recording::from_reader("hardiron.csv", &b"t,bx,by,bz\n0.5,55.7,-61.3,412.1\n"[..])
        .unwrap_err();
    assert!(matches!(err.kind(), ReadErrorKind::MissingColumn("mx")));
}
