//! The table on disk. While a batch runs the CSV is its journal: each row is appended whole, in one write, and
//! flushed as its recording is done, so that a batch killed at any point (even `kill -9`) leaves every finished row
//! and at most one cut-off line. A re-run reads the table back ([`read`]), drops a cut-off last line, rewrites the
//! rest atomically ([`Journal::open`]) and appends only the recordings not yet in it. At the end the whole table,
//! with the lot's columns filled in, replaces the journal atomically ([`write_csv`]), and the JSON is written
//! atomically beside it ([`write_json`]).

use std::fs::{File, OpenOptions};
use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use serde::Serialize;

use super::row::{COLUMNS, Row};
use crate::files::write_atomic;

/// The rows of the table at `path` (none if it does not exist yet), without a last line cut off by a killed batch.
pub fn read(path: &Path) -> anyhow::Result<Vec<Row>> {
    let bytes = match std::fs::read(path) {
        Ok(b) => b,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => return Err(e).with_context(|| format!("{}: cannot read", path.display())),
    };
    if bytes.is_empty() {
        return Ok(Vec::new());
    }
    let name = path.display();
    let mut reader = csv::ReaderBuilder::new()
        .flexible(true)
        .from_reader(&bytes[..]);
    let header = reader
        .headers()
        .with_context(|| format!("{name}: cannot read its first line"))?
        .clone();
    if !header.iter().eq(COLUMNS) {
        bail!(
            "{name} is not a table of magcal-batch (its first line is not the table's header): name another --out, \
             or move that file away"
        );
    }
    // Whole rows end with a line end: a last line without one, or one that does not read (cut after a line end
    // inside a quoted field), was cut off by a killed batch, and its recording is fitted again.
    let cut_off = !bytes.ends_with(b"\n");
    let mut rows = Vec::new();
    let mut records = reader.records().peekable();
    while let Some(record) = records.next() {
        let last = records.peek().is_none();
        let parsed = record
            .map_err(anyhow::Error::from)
            .and_then(|r| Row::from_csv(&r));
        match parsed {
            _ if last && cut_off => break,
            Ok(row) => rows.push(row),
            Err(_) if last => break,
            Err(e) => bail!(
                "{name}: a damaged row ({e:#}) after {} good ones: remove that line (its recording is then fitted \
                 again), or name another --out",
                rows.len()
            ),
        }
    }
    Ok(rows)
}

/// The CSV text of a header and `rows`.
fn csv_bytes<'a>(header: bool, rows: impl IntoIterator<Item = &'a Row>) -> Vec<u8> {
    let mut writer = csv::WriterBuilder::new()
        .terminator(csv::Terminator::Any(b'\n'))
        .from_writer(Vec::new());
    if header {
        writer.write_record(COLUMNS).expect("writes to memory");
    }
    for row in rows {
        writer.write_record(row.to_csv()).expect("writes to memory");
    }
    writer.into_inner().expect("writes to memory")
}

/// Writes the table, header and `rows`, atomically.
pub fn write_csv(path: &Path, rows: &[Row]) -> anyhow::Result<()> {
    write_atomic(path, &csv_bytes(true, rows))
        .with_context(|| format!("writing the table {}", path.display()))
}

/// Writes `doc` as pretty JSON, atomically.
pub fn write_json(path: &Path, doc: &impl Serialize) -> anyhow::Result<()> {
    let text = serde_json::to_string_pretty(doc).expect("a table is plain data");
    write_atomic(path, text.as_bytes()).with_context(|| format!("writing {}", path.display()))
}

/// The table while a batch runs: rows appended whole and flushed one by one.
#[derive(Debug)]
pub struct Journal {
    path: PathBuf,
    file: File,
}

impl Journal {
    /// Rewrites the table at `path` atomically with `rows` (what a previous run left, whole), and opens it to append.
    pub fn open(path: &Path, rows: &[Row]) -> anyhow::Result<Journal> {
        write_csv(path, rows)?;
        let file = OpenOptions::new()
            .append(true)
            .open(path)
            .with_context(|| format!("{}: cannot open to append rows", path.display()))?;
        Ok(Journal {
            path: path.to_owned(),
            file,
        })
    }

    /// Appends `row` in one write.
    pub fn append(&mut self, row: &Row) -> anyhow::Result<()> {
        self.file
            .write_all(&csv_bytes(false, [row]))
            .and_then(|()| self.file.flush())
            .with_context(|| format!("appending a row to {}", self.path.display()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::batch::row::FAILED;

    fn row(i: usize) -> Row {
        Row {
            id: format!("board {i}, \"rev B\"\nsecond line"),
            chip: "lis3mdl".into(),
            grade: FAILED.into(),
            reason: "not read: cut off".into(),
            todo: "record again".into(),
            fit: None,
            lot: None,
            file: format!("lot/{i}.csv"),
            file_bytes: 10,
            modified_ns: 20,
            fit_options: "--method auto".into(),
        }
    }

    #[test]
    fn a_journal_cut_anywhere_reads_back_its_whole_rows() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("table.csv");
        let mut journal = Journal::open(&path, &[row(0)]).unwrap();
        let mut ends = vec![std::fs::metadata(&path).unwrap().len() as usize];
        for i in 1..3 {
            journal.append(&row(i)).unwrap();
            ends.push(std::fs::metadata(&path).unwrap().len() as usize);
        }
        drop(journal);
        let full = std::fs::read(&path).unwrap();
        let whole = [row(0), row(1), row(2)];
        assert_eq!(read(&path).unwrap(), whole);
        let header_len = full.iter().position(|&b| b == b'\n').unwrap() + 1;
        for cut in header_len..full.len() {
            std::fs::write(&path, &full[..cut]).unwrap();
            let rows = read(&path).unwrap();
            let complete = ends.iter().filter(|&&e| e <= cut).count();
            assert_eq!(rows, whole[..complete], "cut at {cut}");
        }
        std::fs::write(&path, b"t,mx,my,mz\n1,2,3,4\n").unwrap();
        let e = read(&path).unwrap_err();
        assert!(e.to_string().contains("not a table of magcal-batch"), "{e}");
        assert!(read(&dir.path().join("none.csv")).unwrap().is_empty());
    }
}
