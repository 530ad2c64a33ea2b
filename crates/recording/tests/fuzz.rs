//! The reader never panics: not on arbitrary bytes, not on mutated valid recordings. What it accepts obeys the
//! format's invariants and can be written and read back.

use magcal_recording::Recording;
use proptest::prelude::*;

const VALID: &str = "\
# magcal-recording v1
# sensor: lis3mdl
# sample_rate_hz: 100
# field_ned_ut: 19.8, 1.2, 45.3
# location: 52.5, 13.3, 40
# date: 2024-02-29
# units: uT
t,mx,my,mz,temp,qw,qx,qy,qz,rx,ry,rz,gx,gy,gz,i_motor,note
0.000,12.345,-3.210,40.120,23.5,1,0,0,0,1,2,3,0.1,0.2,0.3,0.5,a
0.010,12.346,-3.211,40.121,,0.6,0.8,0,0,nan,2,3,,,,,\"b,c\"
0.010,12.347,-3.212,40.122,23.6,nan,0,0,0,1,2,3,0.1,0.2,0.3,0.7,
";

/// Bytes that steer a mutation into the interesting parts of the grammar.
const INTERESTING: &[u8] = b",\n\r#:.-+e0123456789nNaAiIfF\" \t\xff\xef\xbb\xbftqxyzmw_v";

/// Checks what a successful read promises, then writes and reads the result back.
fn check_accepted(rec: &Recording) -> Result<(), TestCaseError> {
    let n = rec.len();
    prop_assert!(n > 0);
    prop_assert!(rec.mag_ut.iter().flatten().all(|v| v.is_finite()));
    if let Some(t) = &rec.t_s {
        prop_assert_eq!(t.len(), n);
        prop_assert!(t.iter().all(|v| v.is_finite()));
        prop_assert!(t.windows(2).all(|w| w[0] <= w[1]));
    }
    if let Some(q) = &rec.quat {
        prop_assert_eq!(q.len(), n);
        for q in q.iter().filter(|q| !q[0].is_nan()) {
            prop_assert!((q.iter().map(|v| v * v).sum::<f64>() - 1.0).abs() < 1e-9);
        }
    }
    prop_assert!(rec.currents.iter().all(|c| c.values.len() == n));
    prop_assert!(rec.extra.iter().all(|c| c.values.len() == n));
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("back.csv");
    rec.write(&path)
        .map_err(|e| TestCaseError::fail(format!("write: {e}")))?;
    let back =
        Recording::read(&path).map_err(|e| TestCaseError::fail(format!("read back: {e}")))?;
    prop_assert_eq!(back.len(), n);
    prop_assert_eq!(back.layout(), rec.layout());
    prop_assert_eq!(&back.meta, &rec.meta);
    prop_assert_eq!(back.missing_counts(), rec.missing_counts());
    prop_assert!(
        back.extra
            .iter()
            .zip(&rec.extra)
            .all(|(a, b)| a.values == b.values)
    );
    Ok(())
}

#[derive(Debug, Clone)]
enum Edit {
    Insert(usize, u8),
    Delete(usize),
    Replace(usize, u8),
    /// Copies a span of the text to another place (repeats lines, fields, columns).
    Copy(usize, usize, usize),
}

fn edit() -> impl Strategy<Value = Edit> {
    let byte = prop_oneof![3 => prop::sample::select(INTERESTING), 1 => any::<u8>()];
    prop_oneof![
        (any::<usize>(), byte.clone()).prop_map(|(i, b)| Edit::Insert(i, b)),
        any::<usize>().prop_map(Edit::Delete),
        (any::<usize>(), byte).prop_map(|(i, b)| Edit::Replace(i, b)),
        (any::<usize>(), 1..40usize, any::<usize>()).prop_map(|(i, len, j)| Edit::Copy(i, len, j)),
    ]
}

fn apply(text: &mut Vec<u8>, e: &Edit) {
    let n = text.len();
    match *e {
        Edit::Insert(i, b) => text.insert(i % (n + 1), b),
        Edit::Delete(i) if n > 0 => {
            text.remove(i % n);
        }
        Edit::Replace(i, b) if n > 0 => text[i % n] = b,
        Edit::Copy(i, len, j) if n > 0 => {
            let start = i % n;
            let span: Vec<u8> = text[start..(start + len).min(n)].to_vec();
            let at = j % (n + 1);
            text.splice(at..at, span);
        }
        _ => {}
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 2000, ..ProptestConfig::default() })]

    #[test]
    fn arbitrary_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..600)) {
        if let Ok(rec) = Recording::from_reader("fuzz.csv", &bytes[..]) {
            check_accepted(&rec)?;
        }
    }

    #[test]
    fn csv_like_bytes_never_panic(bytes in prop::collection::vec(prop::sample::select(INTERESTING), 0..300)) {
        let mut text = b"mx,my,mz\n".to_vec();
        text.extend(bytes);
        if let Ok(rec) = Recording::from_reader("fuzz.csv", &text[..]) {
            check_accepted(&rec)?;
        }
    }

    #[test]
    fn mutated_recordings_never_panic(edits in prop::collection::vec(edit(), 1..6)) {
        let mut text = VALID.as_bytes().to_vec();
        for e in &edits {
            apply(&mut text, e);
        }
        match Recording::from_reader("fuzz.csv", &text[..]) {
            Ok(rec) => check_accepted(&rec)?,
            Err(e) => {
                let msg = e.to_string();
                prop_assert!(msg.starts_with("fuzz.csv"), "{}", msg);
            }
        }
    }
}

#[test]
fn the_unmutated_recording_is_valid() {
    let rec = Recording::from_reader("valid.csv", VALID.as_bytes()).unwrap();
    assert_eq!(rec.len(), 3);
    check_accepted(&rec).unwrap();
}
