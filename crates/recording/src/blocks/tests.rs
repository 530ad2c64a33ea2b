//! The parallel reader against the sequential one (every row through the `csv` crate on one thread) on the same
//! files: identical columns, identical first error. Small blocks and pieces put the cuts everywhere, so that rows,
//! errors and a `t` going backwards land on both sides of them.

use proptest::prelude::*;
use rand::{Rng, RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::Split;
use crate::read::{ReadOptions, read_split};

/// The sequential reader.
const SEQUENTIAL: Split = Split {
    block_bytes: 8 << 20,
    piece_bytes: 256 << 10,
    sequential: true,
    size_bytes: None,
};

/// Cuts from a few bytes (a piece per line or less) to the default.
const SPLITS: [Split; 5] = [
    Split {
        block_bytes: 1,
        piece_bytes: 1,
        sequential: false,
        size_bytes: None,
    },
    // A size hint (true or not) only reserves room.
    Split {
        block_bytes: 97,
        piece_bytes: 13,
        sequential: false,
        size_bytes: Some(1 << 20),
    },
    Split {
        block_bytes: 600,
        piece_bytes: 50,
        sequential: false,
        size_bytes: None,
    },
    Split {
        block_bytes: 4096,
        piece_bytes: 300,
        sequential: false,
        size_bytes: Some(10),
    },
    Split::DEFAULT,
];

/// What a read gives, as text: every column's values (`{:?}` of a float is exact) or the error with its place.
fn outcome(text: &[u8], split: Split) -> String {
    match read_split("rec.csv", text, split, ReadOptions::default()) {
        Ok(rec) => format!("{rec:?}"),
        Err(e) => format!("error {} at {:?} {:?}", e, e.line(), e.column()),
    }
}

fn assert_same(text: &[u8]) {
    let want = outcome(text, SEQUENTIAL);
    for split in SPLITS {
        let got = outcome(text, split);
        assert!(
            got == want,
            "{split:?} on {:?}:\nparallel:   {}\nsequential: {}",
            String::from_utf8_lossy(text),
            &got[..got.len().min(600)],
            &want[..want.len().min(600)]
        );
    }
}

/// A valid row at time `t`.
fn row(rng: &mut impl Rng, t: f64) -> String {
    let q: [f64; 4] = std::array::from_fn(|_| rng.random_range(-1.0..1.0));
    let norm = q.iter().map(|v| v * v).sum::<f64>().sqrt();
    format!(
        "{t:.3},{:.3},{:.4},{:e},{:.1},{:.6},{:.6},{:.6},{:.6},{:.2},note{}",
        rng.random_range(-60.0..60.0),
        rng.random_range(-60.0..60.0),
        rng.random_range(-60.0..60.0),
        rng.random_range(15.0..30.0),
        q[0] / norm,
        q[1] / norm,
        q[2] / norm,
        q[3] / norm,
        rng.random_range(0.0..2.0),
        rng.random_range(0..1000),
    )
}

/// A file of `n` rows with blank lines, and `errors` broken rows of assorted kinds at random places.
fn file(seed: u64, n: usize, errors: usize, line_end: &str) -> Vec<u8> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut lines = vec![
        "# magcal-recording v1".to_owned(),
        "# sensor: test".to_owned(),
        "t,mx,my,mz,temp,qw,qx,qy,qz,i_coil,note".to_owned(),
    ];
    for i in 0..n {
        lines.push(row(&mut rng, i as f64 * 0.01));
        if rng.random_bool(0.05) {
            lines.push(String::new());
        }
    }
    for _ in 0..errors {
        let at = rng.random_range(3..lines.len());
        let field = |k: usize, value: &str| {
            let mut fields: Vec<&str> = lines[at].split(',').collect();
            if k < fields.len() {
                fields[k] = value;
            }
            fields.join(",")
        };
        let broken = match rng.random_range(0..9) {
            0 => field(2, "1.2.3"),
            1 => format!("{},extra", lines[at]),
            2 => lines[at]
                .rsplit_once(',')
                .map_or(String::new(), |(a, _)| a.to_owned()),
            3 => field(0, "0.000"),
            4 => field(1, ""),
            5 => "# late: metadata".to_owned(),
            6 => field(4, "inf"),
            7 => field(5, "0.5"),
            _ => field(10, "\"quoted, note\""),
        };
        lines[at] = broken;
    }
    let mut text = lines.join(line_end);
    if rng.random_bool(0.5) {
        text.push_str(line_end);
    }
    text.into_bytes()
}

#[test]
fn valid_files_give_the_same_columns() {
    for seed in 0..20 {
        for line_end in ["\n", "\r\n", "\r"] {
            let text = file(seed, 200, 0, line_end);
            assert!(outcome(&text, SEQUENTIAL).starts_with("Recording"));
            assert_same(&text);
        }
    }
}

#[test]
fn files_with_errors_in_several_chunks_give_the_same_first_error() {
    for seed in 0..300 {
        let text = file(seed, 150, 1 + seed as usize % 6, "\n");
        assert_same(&text);
    }
}

#[test]
fn time_going_backwards_at_every_row_is_found_where_a_sequential_reader_finds_it() {
    // Every place `t` can go back, with the cuts of a few bytes: on a piece's first row, in a piece, after blank
    // lines, on a row that also has a bad quaternion (t is checked first).
    let rows: Vec<String> = (0..40).map(|i| format!("{}.0,1,2,3,1,0,0,0", i)).collect();
    for back in 2..rows.len() {
        for bad_quat in [false, true] {
            let mut lines = rows.clone();
            lines[back] = format!("0.5,1,2,3,{},0,0,0", if bad_quat { "2" } else { "1" });
            lines.insert(back, String::new());
            let text = format!("t,mx,my,mz,qw,qx,qy,qz\n{}\n", lines.join("\n"));
            assert!(outcome(text.as_bytes(), SEQUENTIAL).starts_with("error"));
            assert_same(text.as_bytes());
        }
    }
}

#[test]
fn a_quote_after_many_blocks_hands_the_rest_to_the_csv_reader() {
    let mut text = String::from("t,mx,my,mz,note\n");
    for i in 0..300 {
        text.push_str(&format!("{i},1,2,3,n\n"));
    }
    text.push_str("300,1,2,3,\"two\nlines, one row\"\n301,1,2,3,ok\n302,1,x,3,bad\n");
    assert!(outcome(text.as_bytes(), SEQUENTIAL).contains("rec.csv:305:3 (my)"));
    assert_same(text.as_bytes());
}

#[test]
fn a_row_the_fast_path_gives_up_late_is_read_once() {
    // The fast path has appended `i_coil` and `note` when it meets the space before 20 and hands the row over.
    let text = "mx,my,mz,i_coil,note,temp\n1,2,3,0.5,hi, 20\n4,5,6,0.7,ho,21\n";
    let rec = read_split(
        "rec.csv",
        text.as_bytes(),
        Split::DEFAULT,
        ReadOptions::default(),
    )
    .expect("valid");
    assert_eq!(rec.currents[0].values, [0.5, 0.7]);
    assert_eq!(rec.extra[0].values, ["hi", "ho"]);
    assert_eq!(rec.temp_c, Some(vec![20.0, 21.0]));
    assert_same(text.as_bytes());
}

/// A stand-in for the attitude turned into an expected field: any function of all four components.
fn turn(q: [f64; 4]) -> [f64; 3] {
    [q[0] * q[1] + q[2], q[3] - q[0], q[1] * q[2] * q[3]]
}

/// The plain read with the quaternions turned afterwards (and the temperature or the attitude dropped, if asked),
/// or its error, as text.
fn turned_after(text: &[u8], skip_temperature: bool, skip_attitude: bool) -> String {
    match read_split("rec.csv", text, SEQUENTIAL, ReadOptions::default()) {
        Ok(mut rec) => {
            if skip_attitude {
                rec.quat = None;
                rec.ref_ut = None;
            }
            if rec.ref_ut.is_none()
                && let Some(q) = rec.quat.take()
            {
                rec.ref_ut = Some(q.into_iter().map(turn).collect());
            }
            if skip_temperature {
                rec.temp_c = None;
            }
            format!("{rec:?}")
        }
        Err(e) => format!("error {} at {:?} {:?}", e, e.line(), e.column()),
    }
}

#[test]
fn quaternions_turned_while_reading_are_those_turned_after_it() {
    let mut texts: Vec<Vec<u8>> = (0..20)
        .map(|seed| file(seed, 150, seed as usize % 3, "\n"))
        .collect();
    // Rows without an attitude, a file with quotes (the csv reader's batches), and a file that has its own expected
    // field, whose quaternions stay as they are.
    texts.push(
        b"t,mx,my,mz,temp,qw,qx,qy,qz\n0,1,2,3,20,1,0,0,0\n1,1,2,3,,,,,\n2,1,2,3,21,0,1,0,0\n"
            .to_vec(),
    );
    let mut quoted = String::from("t,mx,my,mz,temp,qw,qx,qy,qz,note\n");
    for i in 0..40_000 {
        quoted.push_str(&format!("{i},1,2,3,20,0.6,0,0.8,0,\"n, {i}\"\n"));
    }
    texts.push(quoted.into_bytes());
    texts.push(b"t,mx,my,mz,qw,qx,qy,qz,rx,ry,rz\n0,1,2,3,1,0,0,0,4,5,6\n".to_vec());
    for (skip_temperature, skip_attitude) in [(false, false), (true, false), (true, true)] {
        let options = ReadOptions {
            attitude_to_reference: Some(&turn),
            skip_temperature,
            skip_attitude,
        };
        for text in &texts {
            let want = turned_after(text, skip_temperature, skip_attitude);
            for split in SPLITS.iter().copied().chain([SEQUENTIAL]) {
                let got = match read_split("rec.csv", &text[..], split, options) {
                    Ok(rec) => format!("{rec:?}"),
                    Err(e) => format!("error {} at {:?} {:?}", e, e.line(), e.column()),
                };
                assert!(
                    got == want,
                    "{split:?}: {}\nwant {}",
                    &got[..got.len().min(400)],
                    &want[..want.len().min(400)]
                );
            }
        }
    }
}

/// Bytes that steer a mutation into the interesting parts of the grammar.
const INTERESTING: &[u8] = b",\n\r#.-+e0123456789nNaAiIfF\" \t\xff";

proptest! {
    #![proptest_config(ProptestConfig { cases: 500, ..ProptestConfig::default() })]

    #[test]
    fn mutated_files_read_alike(
        seed in 0..50u64,
        edits in prop::collection::vec((any::<usize>(), prop::sample::select(INTERESTING), 0..3u8), 1..8),
    ) {
        let mut text = file(seed, 40, 0, "\n");
        for (at, byte, what) in edits {
            let at = at % (text.len() + 1);
            match what {
                0 => text.insert(at, byte),
                1 if at < text.len() => { text.remove(at); }
                _ if at < text.len() => text[at] = byte,
                _ => {}
            }
        }
        let want = outcome(&text, SEQUENTIAL);
        for split in SPLITS {
            prop_assert_eq!(&outcome(&text, split), &want, "{:?}", split);
        }
    }
}

#[test]
fn a_short_last_row_without_a_line_end_is_said_to_be_cut_off_by_every_reader() {
    let cut = crate::error::CUT_OFF;
    let header = "# magcal-recording v1\nt,mx,my,mz,note\n";
    let rows: String = (0..300).map(|i| format!("{i},1,2,3,n\n")).collect();
    for (tail, cut_off) in [
        ("300,1,", true),
        ("300,1,2,3,\"a\"\n301,1", true),
        ("300,1,\n", false),
        ("300,1,\r", false),
        ("300,1,\n \n", false),
        ("300,1,\n301,1,2,3,n", false),
    ] {
        let text = format!("{header}{rows}{tail}");
        assert_same(text.as_bytes());
        let said = outcome(text.as_bytes(), SEQUENTIAL);
        assert!(said.starts_with("error rec.csv:"), "{tail:?}: {said}");
        assert!(said.contains("short row"), "{tail:?}: {said}");
        assert_eq!(said.contains(cut), cut_off, "{tail:?}: {said}");
    }
    // A quote in the header: the csv reader reads it all.
    let text = b"t,mx,my,\"mz\"\n0,1,2,3\n0.1,1";
    let said = outcome(text, Split::DEFAULT);
    assert!(
        said.contains(&format!(
            "rec.csv:3: short row: 2 fields, the header has 4; {cut} at"
        )),
        "{said}"
    );
}
