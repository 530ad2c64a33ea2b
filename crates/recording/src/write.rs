//! Writing: a whole recording at once ([`Recording::write`], atomic) or row by row ([`RecordingWriter`],
//! crash-safe).
//!
//! Numbers are written in fixed-point notation with these decimals, so that read → write → read keeps every
//! value to well below what the instruments resolve: `t` 6 (1 µs), µT values 6 (1 pT), `temp` 3 (1 m°C),
//! quaternion components 9 (they are written normalised), rad/s 6 (1 µrad/s), A 6 (1 µA). Metadata numbers are
//! written in the shortest form that reads back exactly. Missing values are written as empty fields.

use std::fmt::Write as _;
use std::fs::{self, File, OpenOptions, TryLockError};
use std::io::{self, Seek, SeekFrom, Write as _};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use crate::atomic::{self, Staged, Temp};
use crate::layout::{Flags, Layout};
use crate::metadata::{MAGIC, Metadata};
use crate::recording::Recording;
use crate::sample::{Core, Sample, check_row};

/// Decimals written for `t`, s.
pub const T_DECIMALS: usize = 6;
/// Decimals written for field values (`mx..mz`, `rx..rz`), µT.
pub const UT_DECIMALS: usize = 6;
/// Decimals written for `temp`, °C.
pub const TEMP_DECIMALS: usize = 3;
/// Decimals written for quaternion components.
pub const QUAT_DECIMALS: usize = 9;
/// Decimals written for `gx..gz`, rad/s.
pub const GYRO_DECIMALS: usize = 6;
/// Decimals written for currents, A.
pub const CURRENT_DECIMALS: usize = 6;

/// How often [`RecordingWriter`] writes buffered rows to the file by default.
pub const DEFAULT_FLUSH_INTERVAL: Duration = Duration::from_millis(500);

/// Buffered rows are written out when they reach this size, whatever the flush interval.
const MAX_BUFFERED_BYTES: usize = 1 << 20;

/// Appends the metadata block and the header row. Each note's value is padded with blanks to its width; the byte
/// offset of each note's value in `out` is returned, in order.
fn push_header(out: &mut String, meta: &Metadata, layout: &Layout, notes: &[Note]) -> Vec<u64> {
    out.push_str(MAGIC);
    out.push('\n');
    for (key, value) in meta.pairs() {
        if value.is_empty() {
            let _ = writeln!(out, "# {key}:");
        } else {
            let _ = writeln!(out, "# {key}: {value}");
        }
    }
    let mut offsets = Vec::with_capacity(notes.len());
    for note in notes {
        let _ = write!(out, "# {}: ", note.key);
        offsets.push(out.len() as u64);
        let _ = writeln!(out, "{:<width$}", note.value, width = note.width);
    }
    let header_start = out.len();
    for name in layout.column_names() {
        push_text(out, name);
    }
    // Every name was pushed with a leading comma; the first one has none.
    out.remove(header_start);
    out.push('\n');
    offsets
}

/// Appends `,` and a number with `decimals` decimals, or nothing after the comma when it is NaN (missing).
fn push_number(out: &mut String, value: f64, decimals: usize) {
    out.push(',');
    if !value.is_nan() {
        let _ = write!(out, "{value:.decimals$}");
    }
}

/// Appends `,` and a text field, quoted as CSV when it holds a comma, a quote or a line break.
fn push_text(out: &mut String, text: &str) {
    out.push(',');
    if text.contains([',', '"', '\r', '\n']) {
        out.push('"');
        out.push_str(&text.replace('"', "\"\""));
        out.push('"');
    } else {
        out.push_str(text);
    }
}

/// Appends one data row (already checked by [`check_row`]) and its line break.
fn push_row<'e>(
    out: &mut String,
    flags: Flags,
    core: &Core,
    currents_a: impl Iterator<Item = f64>,
    extra: impl Iterator<Item = &'e str>,
) {
    let start = out.len();
    if flags.t {
        push_number(out, core.t_s, T_DECIMALS);
    }
    core.mag_ut
        .iter()
        .for_each(|v| push_number(out, *v, UT_DECIMALS));
    if flags.temp {
        push_number(out, core.temp_c, TEMP_DECIMALS);
    }
    if flags.quat {
        core.quat
            .iter()
            .for_each(|v| push_number(out, *v, QUAT_DECIMALS));
    }
    if flags.reference {
        core.ref_ut
            .iter()
            .for_each(|v| push_number(out, *v, UT_DECIMALS));
    }
    if flags.gyro {
        core.gyro_rad_s
            .iter()
            .for_each(|v| push_number(out, *v, GYRO_DECIMALS));
    }
    currents_a.for_each(|v| push_number(out, v, CURRENT_DECIMALS));
    extra.for_each(|v| push_text(out, v));
    // Every field was pushed with a leading comma; the row's first one has none.
    out.remove(start);
    out.push('\n');
}

fn invalid_input(e: impl std::error::Error + Send + Sync + 'static) -> io::Error {
    io::Error::new(io::ErrorKind::InvalidInput, e)
}

impl Recording {
    /// Writes the whole recording to `path` atomically ([`crate::atomic::replace`]: a temporary file in the same
    /// folder, synced, then renamed over `path`, which keeps its mode; a file another process holds the lock of is
    /// not replaced). Fails with [`io::ErrorKind::InvalidInput`] (and leaves `path` alone) if the recording breaks
    /// the rules of the format (see [`crate::SampleError`], [`crate::HeaderError`]), e.g. after its public fields
    /// were edited by hand.
    pub fn write(&self, path: &Path) -> io::Result<()> {
        let layout = self.layout();
        self.meta
            .check()
            .map_err(|e| invalid_input(crate::HeaderError(e)))?;
        layout
            .check()
            .map_err(|e| invalid_input(crate::HeaderError(e)))?;
        self.check_lengths()
            .map_err(|e| io::Error::new(io::ErrorKind::InvalidInput, e))?;
        atomic::replace(path, |file| self.write_rows(file, &layout))
    }

    /// Writes the recording to an open file.
    fn write_rows(&self, file: &mut File, layout: &Layout) -> io::Result<()> {
        let mut buf = String::with_capacity(2 * BLOCK_BYTES);
        push_header(&mut buf, &self.meta, layout, &[]);
        let flags = self.flags();
        let mut previous_t_s = None;
        for row in self.rows() {
            let names = self.currents.iter().map(|c| c.name.as_str());
            let core = check_row(
                flags,
                previous_t_s,
                &row.core(),
                row.currents_a(),
                names,
                self.extra.len(),
                self.extra.len(),
            )
            .map_err(|e| {
                io::Error::new(
                    io::ErrorKind::InvalidInput,
                    format!("row {}: {e}", row.index()),
                )
            })?;
            previous_t_s = Some(core.t_s);
            push_row(&mut buf, flags, &core, row.currents_a(), row.extra());
            if buf.len() >= BLOCK_BYTES {
                file.write_all(buf.as_bytes())?;
                buf.clear();
            }
        }
        file.write_all(buf.as_bytes())
    }
}

/// Size of the blocks [`Recording::write`] hands to the OS.
const BLOCK_BYTES: usize = 256 * 1024;

/// A metadata line the writer can rewrite while it records ([`RecordingWriter::set_note`]), e.g. how many segments
/// the time of a recording has so far: the line is written with its value padded with blanks to `width` bytes, and
/// later values are written over it in place.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Note {
    /// The metadata key (an unknown key: not one of the typed ones, not in the metadata already).
    pub key: String,
    /// The value written at creation.
    pub value: String,
    /// Room for values, bytes.
    pub width: usize,
}

/// How [`RecordingWriter::create_with`] creates its file.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct CreateOptions {
    /// Replace an existing file: the recording is written to a temporary file beside it, which replaces it (the
    /// path itself: a link there is replaced, not the file it points to) once the first row reaches it, so that a
    /// device that gives no sample leaves the old file as it was; meanwhile the old file's lock is held. Otherwise
    /// an existing file is an error of kind [`io::ErrorKind::AlreadyExists`] and is left alone.
    pub overwrite: bool,
    /// Metadata lines to rewrite while recording, written after the metadata.
    pub notes: Vec<Note>,
}

/// Incremental, crash-safe writer of a recording.
///
/// The metadata and header are written and flushed when it is created; it holds an exclusive lock on the file
/// ([`File::try_lock`]) as long as it lives, so a second writer on the same path is refused (with
/// [`io::ErrorKind::WouldBlock`]) before it changes anything. Rows are checked (as [`Recording::push`] does) and
/// buffered; whole lines are handed to the OS whenever a call to [`RecordingWriter::write_sample`] or
/// [`RecordingWriter::flush_if_due`] finds the last flush at least `flush_interval` ago (default
/// [`DEFAULT_FLUSH_INTERVAL`]), when 1 MiB is buffered, and on [`RecordingWriter::flush`],
/// [`RecordingWriter::finish`] and drop. So if the process is killed, the file parses and holds every row written
/// before the last flush. If a write fails (a full disk), the part of it that reached the file is cut off again, so
/// the file still ends with a whole line and parses; [`RecordingWriter::rows_in_file`] says how many rows it holds.
/// Only [`RecordingWriter::finish`] syncs to disk (power-loss safety). An existing file it replaces
/// ([`CreateOptions::overwrite`]) stays as it was until the first row is in the new one.
#[derive(Debug)]
pub struct RecordingWriter {
    file: File,
    path: PathBuf,
    layout: Layout,
    buf: String,
    flush_interval: Duration,
    last_flush: Instant,
    previous_t_s: Option<f64>,
    /// Rows accepted.
    rows: u64,
    /// Rows whole in the file.
    rows_in_file: u64,
    /// Where each buffered row ends in the buffer (a row may span lines: quoted line breaks).
    row_ends: Vec<usize>,
    /// Bytes whole in the file (header and rows): where a failed write is cut back to.
    file_len: u64,
    /// Each note's key, the offset of its value in the file, and its width.
    notes: Vec<(String, u64, usize)>,
    /// Set when writing to the file failed: what is in the file is then unknown, so nothing more is written.
    failed: bool,
    /// While the file is a temporary one that will replace an existing file: what renames it, and the existing
    /// file's lock.
    replacing: Option<(Staged, Option<File>)>,
}

/// `e` with what it means, when it is a full disk or a reached file size limit.
fn with_reason(e: io::Error) -> io::Error {
    match atomic::storage_reason(&e) {
        Some(why) => io::Error::new(e.kind(), format!("{e} ({why})")),
        None => e,
    }
}

/// Opens `path` for a writer, new, and locks it.
fn open_locked(path: &Path) -> io::Result<File> {
    let file = OpenOptions::new().write(true).create_new(true).open(path)?;
    match file.try_lock() {
        Ok(()) => {}
        Err(TryLockError::WouldBlock) => return Err(atomic::busy(path)),
        // Some file systems have no locks: write without one.
        Err(TryLockError::Error(e)) if e.kind() == io::ErrorKind::Unsupported => {}
        Err(TryLockError::Error(e)) => return Err(e),
    }
    Ok(file)
}

/// Takes the lock of the existing file at `path` (a regular file, links followed), refusing one another process
/// holds; `None` for what has no lock to take (a link to nothing, a file system without locks).
fn hold_existing(path: &Path) -> io::Result<Option<File>> {
    match fs::metadata(path) {
        Ok(m) if m.is_dir() => {
            return Err(io::Error::new(
                io::ErrorKind::IsADirectory,
                format!("{} is a folder", path.display()),
            ));
        }
        Ok(m) if m.is_file() => {}
        _ => return Ok(None),
    }
    let file = File::open(path)?;
    match file.try_lock() {
        Ok(()) => Ok(Some(file)),
        Err(TryLockError::WouldBlock) => Err(atomic::busy(path)),
        Err(TryLockError::Error(e)) if e.kind() == io::ErrorKind::Unsupported => Ok(None),
        Err(TryLockError::Error(e)) => Err(e),
    }
}

impl RecordingWriter {
    /// Creates (or replaces) the file at `path`, locks it and writes the metadata and header row; the same as
    /// [`RecordingWriter::create_with`] with `overwrite`.
    pub fn create(path: &Path, meta: &Metadata, layout: &Layout) -> io::Result<RecordingWriter> {
        let opts = CreateOptions {
            overwrite: true,
            ..CreateOptions::default()
        };
        RecordingWriter::create_with(path, meta, layout, &opts)
    }

    /// Creates the file at `path`, which must not exist yet, locks it and writes the metadata and header row.
    pub fn create_new(
        path: &Path,
        meta: &Metadata,
        layout: &Layout,
    ) -> io::Result<RecordingWriter> {
        RecordingWriter::create_with(path, meta, layout, &CreateOptions::default())
    }

    /// Creates the file at `path` as `opts` say, locks it and writes the metadata, the notes and the header row.
    /// Fails before anything is recorded if the path cannot be written, exists (without `overwrite`) or is locked by
    /// another writer, or with [`io::ErrorKind::InvalidInput`] if the metadata, notes or layout would not read back
    /// as themselves (see [`crate::HeaderError`]).
    pub fn create_with(
        path: &Path,
        meta: &Metadata,
        layout: &Layout,
        opts: &CreateOptions,
    ) -> io::Result<RecordingWriter> {
        let mut with_notes = meta.clone();
        for note in &opts.notes {
            if note.value.len() > note.width {
                return Err(invalid_input(crate::HeaderError(format!(
                    "note {:?}: value {:?} is wider than its {} bytes",
                    note.key, note.value, note.width
                ))));
            }
            with_notes
                .other
                .push((note.key.clone(), note.value.clone()));
        }
        with_notes
            .check()
            .map_err(|e| invalid_input(crate::HeaderError(e)))?;
        layout
            .check()
            .map_err(|e| invalid_input(crate::HeaderError(e)))?;
        let replaces = opts.overwrite && fs::symlink_metadata(path).is_ok();
        let (mut file, replacing) = if replaces {
            let held = hold_existing(path)?;
            let (file, staged) = Temp::beside(path)?.into_parts();
            (file, Some((staged, held)))
        } else {
            (open_locked(path)?, None)
        };
        let mut header = String::new();
        let offsets = push_header(&mut header, meta, layout, &opts.notes);
        if let Err(e) = file
            .write_all(header.as_bytes())
            .and_then(|()| file.flush())
        {
            // Nothing was recorded: leave no half header behind (a new file goes; a temporary one goes with its
            // `Staged`, and the file it would have replaced stays).
            if !replaces {
                drop(file);
                let _ = fs::remove_file(path);
            }
            return Err(with_reason(e));
        }
        Ok(RecordingWriter {
            file,
            path: path.to_owned(),
            layout: layout.clone(),
            buf: String::new(),
            flush_interval: DEFAULT_FLUSH_INTERVAL,
            last_flush: Instant::now(),
            previous_t_s: None,
            rows: 0,
            rows_in_file: 0,
            row_ends: Vec::new(),
            file_len: header.len() as u64,
            notes: opts
                .notes
                .iter()
                .zip(offsets)
                .map(|(n, at)| (n.key.clone(), at, n.width))
                .collect(),
            failed: false,
            replacing,
        })
    }

    /// Sets how often buffered rows are written out (zero: after every row).
    pub fn with_flush_interval(mut self, interval: Duration) -> RecordingWriter {
        self.flush_interval = interval;
        self
    }

    /// The file being written.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Rows accepted so far (buffered or written).
    pub fn rows(&self) -> u64 {
        self.rows
    }

    /// Rows whole in the file so far: what a reader finds there now (after a failed write too).
    pub fn rows_in_file(&self) -> u64 {
        self.rows_in_file
    }

    /// Rewrites the value of a note given at creation, in place. The value must fit the note's width and be a valid
    /// metadata value (no control characters, no surrounding blanks); `InvalidInput` otherwise, and for an unknown
    /// key.
    pub fn set_note(&mut self, key: &str, value: &str) -> io::Result<()> {
        self.check_not_failed()?;
        let Some(&(_, at, width)) = self.notes.iter().find(|(k, _, _)| k == key) else {
            return Err(invalid_input(crate::HeaderError(format!(
                "no note {key:?}"
            ))));
        };
        let probe = Metadata {
            other: vec![(key.to_owned(), value.to_owned())],
            ..Metadata::default()
        };
        probe
            .check()
            .map_err(|e| invalid_input(crate::HeaderError(e)))?;
        if value.len() > width {
            return Err(invalid_input(crate::HeaderError(format!(
                "note {key:?}: value {value:?} is wider than its {width} bytes"
            ))));
        }
        let padded = format!("{value:<width$}");
        let result = self
            .file
            .seek(SeekFrom::Start(at))
            .and_then(|_| self.file.write_all(padded.as_bytes()))
            .and_then(|()| self.file.seek(SeekFrom::Start(self.file_len)).map(drop));
        if result.is_err() {
            self.failed = true;
        }
        result
    }

    /// Checks and buffers one row; writes the buffer out if the flush interval has passed. A sample that breaks
    /// the rules of the format (see [`crate::SampleError`]) is refused with [`io::ErrorKind::InvalidInput`] and
    /// nothing is written; after a failed write to the file every call fails.
    pub fn write_sample(&mut self, s: &Sample) -> io::Result<()> {
        self.check_not_failed()?;
        let names = self.layout.currents.iter().map(String::as_str);
        let core = check_row(
            self.layout.flags(),
            self.previous_t_s,
            &s.core(),
            s.currents_a.iter().copied(),
            names,
            s.extra.len(),
            self.layout.extra.len(),
        )
        .map_err(invalid_input)?;
        if self.layout.t {
            self.previous_t_s = Some(core.t_s);
        }
        push_row(
            &mut self.buf,
            self.layout.flags(),
            &core,
            s.currents_a.iter().copied(),
            s.extra.iter().map(String::as_str),
        );
        self.row_ends.push(self.buf.len());
        self.rows += 1;
        if self.buf.len() >= MAX_BUFFERED_BYTES {
            self.flush()
        } else {
            self.flush_if_due()
        }
    }

    /// Writes the buffered rows out if the last flush is at least the flush interval ago (for callers that may go
    /// a while without a sample to write).
    pub fn flush_if_due(&mut self) -> io::Result<()> {
        if self.last_flush.elapsed() >= self.flush_interval {
            self.flush()?;
        }
        Ok(())
    }

    /// Writes all buffered rows to the file. If that fails, the file is cut back to the last whole row that
    /// reached it. The first rows to reach the file make it replace the file it replaces.
    pub fn flush(&mut self) -> io::Result<()> {
        self.check_not_failed()?;
        let written = self.write_buffer();
        let settled = self.settle();
        written.and(settled)
    }

    /// Writes the buffer out; on failure cuts the file back to its whole rows.
    fn write_buffer(&mut self) -> io::Result<()> {
        let bytes = self.buf.as_bytes();
        let mut written = 0;
        while written < bytes.len() {
            let error = match self.file.write(&bytes[written..]) {
                Ok(0) => io::Error::from(io::ErrorKind::WriteZero),
                Ok(n) => {
                    written += n;
                    continue;
                }
                Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                Err(e) => e,
            };
            self.failed = true;
            let whole_rows = self.row_ends.partition_point(|end| *end <= written);
            let whole_bytes = whole_rows.checked_sub(1).map_or(0, |i| self.row_ends[i]);
            self.file_len += whole_bytes as u64;
            self.rows_in_file += whole_rows as u64;
            let _ = self.file.set_len(self.file_len);
            return Err(with_reason(error));
        }
        self.file_len += bytes.len() as u64;
        self.rows_in_file = self.rows;
        self.buf.clear();
        self.row_ends.clear();
        self.last_flush = Instant::now();
        Ok(())
    }

    /// Once rows are in a temporary file, renames it over the file it replaces. If that fails, the temporary file
    /// is kept, and the error names it.
    fn settle(&mut self) -> io::Result<()> {
        if self.rows_in_file == 0 {
            return Ok(());
        }
        let Some((staged, held)) = self.replacing.take() else {
            return Ok(());
        };
        let temp = staged.temp_path().map(Path::to_owned);
        staged.persist_or_keep(held).map_err(|e| {
            self.failed = true;
            io::Error::new(
                e.kind(),
                format!(
                    "{} could not be replaced ({e}); the {} rows recorded are in {}",
                    self.path.display(),
                    self.rows_in_file,
                    temp.as_deref().unwrap_or(Path::new("?")).display()
                ),
            )
        })
    }

    /// Whether the file at the path is still the one this writer replaces ([`CreateOptions::overwrite`]): no row
    /// has reached the new one yet.
    pub fn replacing(&self) -> bool {
        self.replacing.is_some()
    }

    /// Writes all buffered rows and syncs the file to disk. A writer that replaces a file and got no row leaves that
    /// file as it was.
    pub fn finish(mut self) -> io::Result<()> {
        self.flush()?;
        self.file.sync_all()
    }

    fn check_not_failed(&self) -> io::Result<()> {
        if self.failed {
            return Err(io::Error::other(format!(
                "an earlier write to {} failed",
                self.path.display()
            )));
        }
        Ok(())
    }
}

impl Drop for RecordingWriter {
    /// Writes the buffered rows; errors are ignored here (call [`RecordingWriter::finish`] to see them).
    fn drop(&mut self) {
        if !self.failed {
            let _ = self.flush();
        }
    }
}
