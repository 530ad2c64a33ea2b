//! Data rows on both cores: the file after the header is read in large blocks; each block is cut at line ends into
//! pieces that are parsed in parallel (each into its own columns, reused from block to block), then appended in file
//! order. Errors are those of a sequential reader, in its order: the first problem by line wins, and whether `t` goes
//! backwards across two pieces is checked when they are joined. A block with a quote in it, and everything after,
//! goes to the `csv` crate (quoted fields may hold separators and line ends), which starts there as a sequential
//! reader would be at that line.

use std::io::{self, Read};

use csv::{ByteRecord, ReaderBuilder, Terminator};
use rayon::prelude::*;

use crate::error::ReadErrorKind;
use crate::layout::Layout;
use crate::metadata::Metadata;
use crate::read::AttitudeToReference;
use crate::recording::Recording;
use crate::rows::{RowParser, RowProblem, SplitLine, TimeLink};

/// How the data are cut for the threads.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Split {
    /// Bytes read at a time (a block ends at its last line end; the rest goes to the next one).
    pub block_bytes: usize,
    /// Bytes below which a block is parsed on the calling thread alone.
    pub piece_bytes: usize,
    /// Every row through the `csv` crate on one thread: the sequential reader the tests compare with.
    pub sequential: bool,
    /// The file's size, when known: after the first block the columns are reserved for the rows the rest of it
    /// holds at the first block's bytes a row (no copies as they grow, and little room to spare).
    pub size_bytes: Option<u64>,
}

impl Split {
    /// 4 MiB blocks (memory stays at the columns plus about two blocks: the text and its parsed rows), pieces of at
    /// least 256 KiB.
    pub(crate) const DEFAULT: Split = Split {
        block_bytes: 4 << 20,
        piece_bytes: 256 << 10,
        sequential: false,
        size_bytes: None,
    };
}

/// A problem at a 1-based line of the file, in a column if it is in one field.
#[derive(Debug)]
pub(crate) struct LineProblem {
    pub line: u64,
    pub column: Option<usize>,
    pub kind: ReadErrorKind,
    /// A short row that is the file's last line and has no line end: the file was cut off while it was written.
    pub cut_off: bool,
}

impl LineProblem {
    /// A problem that is not a cut-off last row.
    fn at(line: u64, column: Option<usize>, kind: ReadErrorKind) -> LineProblem {
        LineProblem {
            line,
            column,
            kind,
            cut_off: false,
        }
    }
}

/// Everything the rows need to know of the header.
#[derive(Clone, Copy)]
pub(crate) struct Rows<'h> {
    pub parser: RowParser<'h>,
    pub separator: u8,
    pub layout: &'h Layout,
    /// The 0-based column of `t`, if any (where a `t` going backwards across pieces is reported).
    pub time_column: Option<usize>,
    /// Turns the quaternions into the expected field as the rows are appended (`out` then has `ref_ut` and no
    /// `quat`).
    pub to_reference: Option<AttitudeToReference<'h>>,
    /// `out` keeps other columns than the file has ([`crate::ReadOptions`]): rows are then always parsed with the
    /// file's layout, checked alike, and appended in batches.
    pub reshaped: bool,
}

/// What the join needs to know of a piece (its rows are in a buffer of their own).
struct Piece {
    /// Lines in the piece (line ends, and a last line without one), when it has no problem.
    lines: u64,
    time: TimeLink,
    /// The 0-based line (in the piece) of the row that set `time.first_unchecked_s`.
    first_line: u64,
    problem: Option<(u64, RowProblem)>,
}

impl Rows<'_> {
    /// Reads the data rows of `input`, whose first line is line `first_line` of the file, into `out`.
    pub(crate) fn read(
        &self,
        mut input: impl Read,
        first_line: u64,
        out: &mut Recording,
        split: Split,
    ) -> Result<(), Result<LineProblem, io::Error>> {
        let mut block = Vec::new();
        let mut line = first_line;
        let mut time = TimeLink::default();
        let mut pieces: Vec<Recording> = Vec::new();
        let mut want = split.block_bytes;
        loop {
            let end = fill(&mut input, &mut block, want).map_err(Err)?;
            if memchr::memchr(b'"', &block).is_some() {
                let rest = io::Cursor::new(block).chain(input);
                return self.quoted(
                    &mut csv_reader(rest, self.separator),
                    (line - 1, false),
                    out,
                    time,
                );
            }
            // Up to the last line end, or all of it at the end of the file.
            let cut = if end {
                block.len()
            } else {
                memchr::memrchr(b'\n', &block).map_or(0, |i| i + 1)
            };
            let first = line == first_line;
            let parsed = self.parse_block(&block[..cut], line, out, &mut time, &mut pieces, split);
            line = parsed.map_err(|e| e.map(|p| cut_off_at_end(p, line, &block, end)))?;
            if end {
                return Ok(());
            }
            if let Some(size) = split.size_bytes.filter(|_| first && cut > 0) {
                let per_byte = out.mag_ut.len() as f64 / cut as f64;
                let rest = size.saturating_sub(cut as u64) as f64;
                reserve(out, (RESERVE_MARGIN * rest * per_byte) as usize);
            }
            // A line longer than a block: read on until it ends.
            want = if cut == 0 {
                2 * block.len()
            } else {
                split.block_bytes
            };
            block.drain(..cut);
        }
    }

    /// Parses whole lines in pieces on the threads, joins them into `out`; returns the line after the block.
    fn parse_block(
        &self,
        block: &[u8],
        first_line: u64,
        out: &mut Recording,
        time: &mut TimeLink,
        spare: &mut Vec<Recording>,
        split: Split,
    ) -> Result<u64, Result<LineProblem, io::Error>> {
        let bounds = piece_bounds(block, split.piece_bytes, rayon::current_num_threads());
        while spare.len() < bounds.len() - 1 {
            spare.push(Recording::empty(Metadata::default(), self.layout));
        }
        let buffers = &mut spare[..bounds.len() - 1];
        let pieces: Vec<Piece> = if buffers.len() == 1 {
            vec![self.parse_piece(block, &mut buffers[0])]
        } else {
            buffers
                .par_iter_mut()
                .enumerate()
                .map(|(k, rows)| self.parse_piece(&block[bounds[k]..bounds[k + 1]], rows))
                .collect()
        };
        // The pieces are checked in file order; those before the first problem are appended, column by column on
        // the threads (the copy is most of a join's time).
        let mut line = first_line;
        let mut problem = None;
        let mut accepted = 0;
        for mut piece in pieces {
            if let Err(p) = self.link(&mut piece, line, time) {
                problem = Some(p);
                break;
            }
            line += piece.lines;
            accepted += 1;
        }
        append(out, &buffers[..accepted]);
        buffers.iter_mut().for_each(clear);
        match problem {
            Some(p) => Err(Ok(p)),
            None => Ok(line),
        }
    }

    /// Parses the lines of one piece into `rows` until the first problem.
    fn parse_piece(&self, text: &[u8], rows: &mut Recording) -> Piece {
        let mut fields = SplitLine::default();
        let mut time = TimeLink::default();
        let (mut first_line, mut problem) = (0, None);
        let mut lines = 0u64;
        let mut rest = text;
        while !rest.is_empty() {
            let (line, next) = match memchr::memchr(b'\n', rest) {
                Some(i) => (&rest[..i], &rest[i + 1..]),
                None => (rest, &rest[rest.len()..]),
            };
            rest = next;
            if !line.is_empty() {
                let unchecked = time.first_unchecked_s.is_none();
                let result = if self
                    .parser
                    .push_plain(line, self.separator, rows, &mut time)
                {
                    Ok(())
                } else {
                    fields.split(line, self.separator);
                    self.parser.push(&fields, rows, &mut time)
                };
                if unchecked && time.first_unchecked_s.is_some() {
                    first_line = lines;
                }
                if let Err(p) = result {
                    problem = Some((lines, p));
                    break;
                }
            }
            lines += 1;
        }
        // On the piece's thread.
        self.turn_attitude(rows);
        Piece {
            lines,
            time,
            first_line,
            problem,
        }
    }

    /// With [`Rows::to_reference`], the expected field of `rows`' quaternions (the file's layout) into their
    /// `ref_ut`, which [`append`] takes.
    fn turn_attitude(&self, rows: &mut Recording) {
        if let Some(turn) = self.to_reference {
            let quat = rows.quat.as_ref().expect("the file's layout");
            let turned = rows.ref_ut.get_or_insert_with(Vec::new);
            turned.clear();
            turned.extend(quat.iter().map(|q| turn(*q)));
        }
    }

    /// Checks a piece as a sequential reader would have, before its rows are appended: its first row against the
    /// last row before it, then its own first problem, if any; carries the time on.
    fn link(&self, piece: &mut Piece, line: u64, time: &mut TimeLink) -> Result<(), LineProblem> {
        if let (Some(previous_s), Some(t_s)) = (time.previous_s, piece.time.first_unchecked_s)
            && t_s < previous_s
        {
            let kind = ReadErrorKind::TimeBackwards { previous_s, t_s };
            let at = line + piece.first_line;
            return Err(LineProblem::at(at, self.time_column, kind));
        }
        if let Some((at, (column, kind))) = piece.problem.take() {
            return Err(LineProblem::at(line + at, column, kind));
        }
        if piece.time.previous_s.is_some() {
            time.previous_s = piece.time.previous_s;
        }
        Ok(())
    }

    /// The rows of a csv reader, between rows, into `out`. `header_line` is the line of the header if the reader
    /// has read it; otherwise the reader starts at the line after `header_line`, and counts lines as if it had read
    /// a one-line header (so that the lines it names are those of a reader that started at the header).
    pub(crate) fn quoted<R: Read>(
        &self,
        csv: &mut csv::Reader<Terminated<R>>,
        (header_line, header_read): (u64, bool),
        out: &mut Recording,
        mut time: TimeLink,
    ) -> Result<(), Result<LineProblem, io::Error>> {
        let mut record = ByteRecord::new();
        let mut batch = self
            .reshaped
            .then(|| Recording::empty(Metadata::default(), self.layout));
        while csv
            .read_byte_record(&mut record)
            .map_err(|e| Err(e.into()))?
        {
            let rows = batch.as_mut().unwrap_or(&mut *out);
            if let Err((column, kind)) = self.parser.push(&record, rows, &mut time) {
                // The row's first line: the csv reader has counted the row's own '\n' and any inside quotes.
                let breaks_inside =
                    record.as_slice().iter().filter(|b| **b == b'\n').count() as u64;
                let position = csv.position().line() + u64::from(!header_read);
                let line = header_line + position.saturating_sub(2 + breaks_inside);
                let mut problem = LineProblem::at(line, column, kind);
                problem.cut_off =
                    is_short(&problem.kind) && last_without_line_end(csv, &mut record);
                return Err(Ok(problem));
            }
            if let Some(rows) = &mut batch
                && rows.mag_ut.len() >= QUOTED_BATCH_ROWS
            {
                self.turn_attitude(rows);
                append(out, std::slice::from_ref(rows));
                clear(rows);
            }
        }
        if let Some(rows) = &mut batch {
            self.turn_attitude(rows);
            append(out, std::slice::from_ref(rows));
        }
        Ok(())
    }
}

/// Rows of a file with quotes parsed before they are appended, when the recording keeps other columns than the file.
const QUOTED_BATCH_ROWS: usize = 1 << 14;

/// Whether a problem is a short row (which, on the file's last line without a line end, is a file cut off).
fn is_short(kind: &ReadErrorKind) -> bool {
    matches!(kind, ReadErrorKind::ShortRow { .. })
}

/// `problem` of the block that starts at line `first_line`, marked cut off if it is a short row on the block's last
/// line, the block is the file's `end` and does not end with a line end.
fn cut_off_at_end(
    mut problem: LineProblem,
    first_line: u64,
    block: &[u8],
    end: bool,
) -> LineProblem {
    problem.cut_off = end
        && is_short(&problem.kind)
        && block.last().is_some_and(|b| *b != b'\n')
        && problem.line == first_line + memchr::memchr_iter(b'\n', block).count() as u64;
    problem
}

/// After a row of `csv`: whether it was the last and the input had no line end after it (the csv reader reads on
/// into `record`).
fn last_without_line_end<R: Read>(
    csv: &mut csv::Reader<Terminated<R>>,
    record: &mut ByteRecord,
) -> bool {
    matches!(csv.read_byte_record(record), Ok(false)) && !csv.get_ref().ended_with_line_end
}

/// The input followed by one '\n' (so that every row ends with one), noting whether the input's own last byte was
/// one.
pub(crate) struct Terminated<R> {
    input: R,
    /// The input's last byte so far was a '\n' (true for an empty input).
    ended_with_line_end: bool,
    /// The input has ended.
    input_done: bool,
    /// The added '\n' has been read.
    done: bool,
}

impl<R: Read> Terminated<R> {
    fn new(input: R) -> Terminated<R> {
        Terminated {
            input,
            ended_with_line_end: true,
            input_done: false,
            done: false,
        }
    }
}

impl<R: Read> Read for Terminated<R> {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        if buf.is_empty() || self.done {
            return Ok(0);
        }
        if !self.input_done {
            let n = self.input.read(buf)?;
            if n > 0 {
                self.ended_with_line_end = buf[n - 1] == b'\n';
                return Ok(n);
            }
            self.input_done = true;
        }
        buf[0] = b'\n';
        self.done = true;
        Ok(1)
    }
}

/// A csv reader of `input` with a '\n' added ([`Terminated`]), rows separated by `separator` and ended by '\n' only
/// (every line end is one by now): every row ends with a '\n', so that the reader's line count after a row is one
/// past the row's last line.
pub(crate) fn csv_reader<R: Read>(input: R, separator: u8) -> csv::Reader<Terminated<R>> {
    ReaderBuilder::new()
        .has_headers(false)
        .flexible(true)
        .delimiter(separator)
        .terminator(Terminator::Any(b'\n'))
        .buffer_capacity(256 << 10)
        .from_reader(Terminated::new(input))
}

/// Reads from `input` until `buf` holds at least `want` bytes or the input ends; returns whether it ended.
fn fill(input: &mut impl Read, buf: &mut Vec<u8>, want: usize) -> io::Result<bool> {
    if buf.len() >= want {
        return Ok(false);
    }
    let need = want - buf.len();
    let got = input.by_ref().take(need as u64).read_to_end(buf)?;
    Ok(got < need)
}

/// Where to cut a block into pieces for `threads` threads: offsets just after line ends, first 0 and last the
/// block's length; one piece for a small block.
fn piece_bounds(block: &[u8], piece_bytes: usize, threads: usize) -> Vec<usize> {
    let pieces = (block.len() / piece_bytes.max(1)).clamp(1, 4 * threads.max(1));
    let mut bounds = vec![0];
    for k in 1..pieces {
        let target = (k * block.len() / pieces).max(*bounds.last().unwrap_or(&0));
        match memchr::memchr(b'\n', &block[target..]) {
            Some(i) if target + i + 1 < block.len() => bounds.push(target + i + 1),
            _ => break,
        }
    }
    bounds.push(block.len());
    bounds.dedup();
    if bounds.len() == 1 {
        bounds.push(0);
    }
    bounds
}

/// Appends the rows of `pieces` (the file's layout), in order, to `out`: the columns on the threads, the largest
/// apart. With the attitude turned ([`Rows::turn_attitude`]), `out` has no quaternions and takes the pieces'
/// expected field.
fn append(out: &mut Recording, pieces: &[Recording]) {
    fn extend<T: Clone>(
        out: &mut Vec<T>,
        pieces: &[Recording],
        column: impl Fn(&Recording) -> &Vec<T>,
    ) {
        out.reserve(pieces.iter().map(|p| column(p).len()).sum());
        for p in pieces {
            out.extend_from_slice(column(p));
        }
    }
    fn extend_some<T: Clone>(
        out: &mut Option<Vec<T>>,
        pieces: &[Recording],
        column: impl Fn(&Recording) -> &Option<Vec<T>>,
    ) {
        if let Some(out) = out {
            extend(out, pieces, |p| {
                column(p).as_ref().expect("the same layout")
            });
        }
    }
    let Recording {
        mag_ut,
        t_s,
        temp_c,
        quat,
        ref_ut,
        gyro_rad_s,
        currents,
        extra,
        ..
    } = out;
    rayon::join(
        || extend(mag_ut, pieces, |p| &p.mag_ut),
        || {
            rayon::join(
                || {
                    // With the attitude turned, the pieces hold the expected field, and `out` no quaternions.
                    extend_some(quat, pieces, |p| &p.quat);
                    extend_some(ref_ut, pieces, |p| &p.ref_ut);
                },
                || {
                    extend_some(t_s, pieces, |p| &p.t_s);
                    extend_some(temp_c, pieces, |p| &p.temp_c);
                    extend_some(gyro_rad_s, pieces, |p| &p.gyro_rad_s);
                    for (j, o) in currents.iter_mut().enumerate() {
                        extend(&mut o.values, pieces, |p| &p.currents[j].values);
                    }
                    for (j, o) in extra.iter_mut().enumerate() {
                        extend(&mut o.values, pieces, |p| &p.extra[j].values);
                    }
                },
            )
        },
    );
}

/// The rows reserved for the rest of a file of known size, per row its first block holds at the same bytes a row:
/// numbers tend to grow longer further on (time), not shorter.
const RESERVE_MARGIN: f64 = 1.02;

/// Reserves room for `rows` more rows in every column of `out`.
fn reserve(out: &mut Recording, rows: usize) {
    fn some<T>(c: &mut Option<Vec<T>>, rows: usize) {
        if let Some(c) = c {
            c.reserve_exact(rows);
        }
    }
    out.mag_ut.reserve_exact(rows);
    some(&mut out.t_s, rows);
    some(&mut out.temp_c, rows);
    some(&mut out.quat, rows);
    some(&mut out.ref_ut, rows);
    some(&mut out.gyro_rad_s, rows);
    out.currents
        .iter_mut()
        .for_each(|c| c.values.reserve_exact(rows));
    out.extra
        .iter_mut()
        .for_each(|c| c.values.reserve_exact(rows));
}

/// Empties every column, keeping its memory.
fn clear(rows: &mut Recording) {
    fn clear<T>(c: &mut Option<Vec<T>>) {
        if let Some(c) = c {
            c.clear();
        }
    }
    rows.mag_ut.clear();
    clear(&mut rows.t_s);
    clear(&mut rows.temp_c);
    clear(&mut rows.quat);
    clear(&mut rows.ref_ut);
    clear(&mut rows.gyro_rad_s);
    rows.currents.iter_mut().for_each(|c| c.values.clear());
    rows.extra.iter_mut().for_each(|c| c.values.clear());
}

#[cfg(test)]
mod tests;
