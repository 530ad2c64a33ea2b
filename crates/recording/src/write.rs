//! Writing: a whole recording at once ([`Recording::write`], atomic) or row by row ([`RecordingWriter`],
//! crash-safe).
//!
//! Numbers are written in fixed-point notation with these decimals, so that read → write → read keeps every
//! value to well below what the instruments resolve: `t` 6 (1 µs), µT values 6 (1 pT), `temp` 3 (1 m°C),
//! quaternion components 9 (they are written normalised), rad/s 6 (1 µrad/s), A 6 (1 µA). Metadata numbers are
//! written in the shortest form that reads back exactly. Missing values are written as empty fields.

use std::fmt::Write as _;
use std::fs::{self, File, OpenOptions};
use std::io::{self, Write as _};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

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

/// Appends the metadata block and the header row.
fn push_header(out: &mut String, meta: &Metadata, layout: &Layout) {
    out.push_str(MAGIC);
    out.push('\n');
    for (key, value) in meta.pairs() {
        if value.is_empty() {
            let _ = writeln!(out, "# {key}:");
        } else {
            let _ = writeln!(out, "# {key}: {value}");
        }
    }
    let header_start = out.len();
    for name in layout.column_names() {
        push_text(out, name);
    }
    // Every name was pushed with a leading comma; the first one has none.
    out.remove(header_start);
    out.push('\n');
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

/// Distinguishes temporary files of one process.
static TEMP_COUNTER: AtomicU64 = AtomicU64::new(0);

impl Recording {
    /// Writes the whole recording to `path` atomically: to a temporary file in the same directory, synced, then
    /// renamed over `path`. Fails with [`io::ErrorKind::InvalidInput`] (and leaves `path` alone) if the
    /// recording breaks the rules of the format (see [`crate::SampleError`], [`crate::HeaderError`]), e.g. after
    /// its public fields were edited by hand.
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
        let file_name = path
            .file_name()
            .ok_or_else(|| io::Error::new(io::ErrorKind::InvalidInput, "the path names no file"))?;
        let dir = match path.parent() {
            Some(dir) if !dir.as_os_str().is_empty() => dir,
            _ => Path::new("."),
        };
        let n = TEMP_COUNTER.fetch_add(1, Ordering::Relaxed);
        let temp = dir.join(format!(
            ".{}.{}.{n}.tmp",
            file_name.to_string_lossy(),
            std::process::id()
        ));
        let result = self
            .write_new(&temp, &layout)
            .and_then(|()| fs::rename(&temp, path));
        if result.is_err() {
            let _ = fs::remove_file(&temp);
        }
        result?;
        // Make the rename itself durable; directories cannot be opened for this on every platform.
        if let Ok(d) = File::open(dir) {
            let _ = d.sync_all();
        }
        Ok(())
    }

    /// Writes the recording to a new file and syncs it.
    fn write_new(&self, path: &Path, layout: &Layout) -> io::Result<()> {
        let mut file = OpenOptions::new().write(true).create_new(true).open(path)?;
        let mut buf = String::with_capacity(2 * BLOCK_BYTES);
        push_header(&mut buf, &self.meta, layout);
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
        file.write_all(buf.as_bytes())?;
        file.sync_all()
    }
}

/// Size of the blocks [`Recording::write`] hands to the OS.
const BLOCK_BYTES: usize = 256 * 1024;

/// Incremental, crash-safe writer of a recording.
///
/// The metadata and header are written and flushed by [`RecordingWriter::create`]. Rows are checked (as
/// [`Recording::push`] does) and buffered; whole lines are handed to the OS whenever a call to
/// [`RecordingWriter::write_sample`] finds the last flush at least `flush_interval` ago (default
/// [`DEFAULT_FLUSH_INTERVAL`]), when 1 MiB is buffered, and on [`RecordingWriter::flush`],
/// [`RecordingWriter::finish`] and drop. So if the process is killed, the file parses and holds every row written
/// before the last flush. Flushing is driven by these calls: a caller that stops writing samples for a while
/// should call [`RecordingWriter::flush`]. Only [`RecordingWriter::finish`] syncs to disk (power-loss safety).
#[derive(Debug)]
pub struct RecordingWriter {
    file: File,
    path: PathBuf,
    layout: Layout,
    buf: String,
    flush_interval: Duration,
    last_flush: Instant,
    previous_t_s: Option<f64>,
    rows: u64,
    /// Set when writing to the file failed: what is in the file is then unknown, so nothing more is written.
    failed: bool,
}

impl RecordingWriter {
    /// Creates (or truncates) the file at `path` and writes the metadata and header row. Fails before anything is
    /// recorded if the path cannot be written, or with [`io::ErrorKind::InvalidInput`] if the metadata or layout
    /// would not read back as themselves (see [`crate::HeaderError`]).
    pub fn create(path: &Path, meta: &Metadata, layout: &Layout) -> io::Result<RecordingWriter> {
        meta.check()
            .map_err(|e| invalid_input(crate::HeaderError(e)))?;
        layout
            .check()
            .map_err(|e| invalid_input(crate::HeaderError(e)))?;
        let mut file = File::create(path)?;
        let mut header = String::new();
        push_header(&mut header, meta, layout);
        file.write_all(header.as_bytes())?;
        file.flush()?;
        Ok(RecordingWriter {
            file,
            path: path.to_owned(),
            layout: layout.clone(),
            buf: String::new(),
            flush_interval: DEFAULT_FLUSH_INTERVAL,
            last_flush: Instant::now(),
            previous_t_s: None,
            rows: 0,
            failed: false,
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
        self.rows += 1;
        if self.last_flush.elapsed() >= self.flush_interval || self.buf.len() >= MAX_BUFFERED_BYTES
        {
            self.flush()?;
        }
        Ok(())
    }

    /// Writes all buffered rows (whole lines) to the file.
    pub fn flush(&mut self) -> io::Result<()> {
        self.check_not_failed()?;
        if !self.buf.is_empty() {
            if let Err(e) = self.file.write_all(self.buf.as_bytes()) {
                self.failed = true;
                return Err(e);
            }
            self.buf.clear();
        }
        self.last_flush = Instant::now();
        Ok(())
    }

    /// Writes all buffered rows and syncs the file to disk.
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
