//! What a line stream held: samples, echoes, headers, comments, and garbage counted by kind.

use std::fmt;

/// Why a line was skipped. Garbage is never fatal: it is counted and the stream goes on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum GarbageKind {
    /// Bytes that are not printable ASCII (line noise, a baud-rate mismatch, binary output).
    Binary,
    /// More than [`MAX_LINE_BYTES`](super::lines::MAX_LINE_BYTES) bytes without a line end.
    Overlong,
    /// An unterminated line cut off by a disconnect, or dropped when the input was discarded.
    Truncated,
    /// A line of a known form with the wrong number of fields (a half line, two lines run together).
    FieldCount,
    /// A field that should be a number is not one (or is not finite, or out of its type's range).
    BadNumber,
    /// A native CSV data line before any header line: the header was missed.
    NoHeader,
    /// A native CSV header that names `mx,my,mz` but is unusable (unknown, duplicate or
    /// incomplete column groups), or differs from the header already in force.
    BadHeader,
    /// Text of no form this protocol knows: other firmware chatter (`Uni:` lines, start-up
    /// banners, "Wrote calibration"), or a line cut at its start.
    Unrecognized,
    /// A sample whose values are beyond what a recording holds ([`magcal_recording::limits`]: a
    /// field over 10⁶ µT, a quaternion far from unit length): a line that lost bytes.
    OutOfRange,
}

impl GarbageKind {
    /// Every kind, in a fixed order.
    pub const ALL: [GarbageKind; 9] = [
        GarbageKind::Binary,
        GarbageKind::Overlong,
        GarbageKind::Truncated,
        GarbageKind::FieldCount,
        GarbageKind::BadNumber,
        GarbageKind::NoHeader,
        GarbageKind::BadHeader,
        GarbageKind::Unrecognized,
        GarbageKind::OutOfRange,
    ];

    /// A short snake_case name, for logs and summaries.
    pub fn name(self) -> &'static str {
        match self {
            GarbageKind::Binary => "binary",
            GarbageKind::Overlong => "overlong",
            GarbageKind::Truncated => "truncated",
            GarbageKind::FieldCount => "field_count",
            GarbageKind::BadNumber => "bad_number",
            GarbageKind::NoHeader => "no_header",
            GarbageKind::BadHeader => "bad_header",
            GarbageKind::Unrecognized => "unrecognized",
            GarbageKind::OutOfRange => "out_of_range",
        }
    }
}

impl fmt::Display for GarbageKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Skipped lines, one counter per [`GarbageKind`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct GarbageCounts {
    counts: [u64; GarbageKind::ALL.len()],
}

impl GarbageCounts {
    /// Counts one more line of `kind`.
    pub fn add(&mut self, kind: GarbageKind) {
        self.counts[kind as usize] += 1;
    }

    /// How many lines of `kind` were skipped.
    pub fn get(&self, kind: GarbageKind) -> u64 {
        self.counts[kind as usize]
    }

    /// How many lines were skipped in all.
    pub fn total(&self) -> u64 {
        self.counts.iter().sum()
    }

    /// The non-zero counters, as `(kind, count)`.
    pub fn nonzero(&self) -> impl Iterator<Item = (GarbageKind, u64)> + '_ {
        GarbageKind::ALL
            .into_iter()
            .map(|kind| (kind, self.get(kind)))
            .filter(|&(_, n)| n > 0)
    }
}

impl fmt::Display for GarbageCounts {
    /// `none`, or e.g. `binary 2, field_count 1`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let mut any = false;
        for (kind, n) in self.nonzero() {
            write!(f, "{}{kind} {n}", if any { ", " } else { "" })?;
            any = true;
        }
        if !any {
            f.write_str("none")?;
        }
        Ok(())
    }
}

/// Counters of a line stream. Every non-empty line is counted once in `lines` and once in exactly
/// one of the other fields, so `lines == samples + echoes + headers + comments + garbage.total()`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LineCounts {
    /// Non-empty lines seen (garbage included).
    pub lines: u64,
    /// Lines that gave a sample.
    pub samples: u64,
    /// Well-formed MotionCal calibration echoes (`Cal1:`, `Cal2:`).
    pub echoes: u64,
    /// Native CSV header lines (the first, and identical repeats after a firmware reset).
    pub headers: u64,
    /// Native CSV comment lines (`# ...`, metadata included).
    pub comments: u64,
    /// Skipped lines, by kind.
    pub garbage: GarbageCounts,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_by_kind_and_in_total() {
        let mut g = GarbageCounts::default();
        assert_eq!(g.to_string(), "none");
        g.add(GarbageKind::Binary);
        g.add(GarbageKind::Unrecognized);
        g.add(GarbageKind::Binary);
        assert_eq!(g.get(GarbageKind::Binary), 2);
        assert_eq!(g.get(GarbageKind::FieldCount), 0);
        assert_eq!(g.total(), 3);
        assert_eq!(g.to_string(), "binary 2, unrecognized 1");
    }

    #[test]
    fn kinds_index_their_own_counter() {
        for (i, kind) in GarbageKind::ALL.into_iter().enumerate() {
            assert_eq!(kind as usize, i);
        }
    }
}
