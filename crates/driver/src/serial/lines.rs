//! Cutting a byte stream into lines.
//!
//! Firmware ends lines with `\r\n` (Arduino `println`), `\n` or a bare `\r`; all three are
//! accepted, and the empty lines they leave between two terminators are dropped. A line longer
//! than [`MAX_LINE_BYTES`] without a terminator is binary noise or a missed terminator: it is
//! reported once as [`Piece::Overlong`] and its bytes are dropped up to the next terminator, so a
//! stream of noise never grows the buffer.

/// Longest line kept, in bytes, terminator excluded. A MotionCal `Raw:` line is at most about
/// 70 bytes; a native CSV line with many `i_<name>` columns stays well below this.
pub const MAX_LINE_BYTES: usize = 1024;

/// What [`LineSplitter::next_piece`] hands out.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Piece {
    /// One complete line, without its terminator; never empty.
    Line(Vec<u8>),
    /// More than [`MAX_LINE_BYTES`] without a terminator; the bytes were dropped.
    Overlong,
}

/// Buffers received bytes and hands out complete lines.
#[derive(Clone, Debug, Default)]
pub struct LineSplitter {
    buf: Vec<u8>,
    /// Inside an overlong line: drop bytes up to the next terminator.
    discarding: bool,
}

fn is_terminator(byte: u8) -> bool {
    byte == b'\n' || byte == b'\r'
}

impl LineSplitter {
    /// An empty splitter.
    pub fn new() -> Self {
        Self::default()
    }

    /// Appends received bytes; complete lines are then taken with [`next_piece`](Self::next_piece).
    pub fn push(&mut self, bytes: &[u8]) {
        self.buf.extend_from_slice(bytes);
    }

    /// The next complete line (or overlong report), if the buffer holds one.
    pub fn next_piece(&mut self) -> Option<Piece> {
        loop {
            let Some(end) = self.buf.iter().position(|&b| is_terminator(b)) else {
                if self.buf.len() > MAX_LINE_BYTES {
                    self.buf.clear();
                    let first_report = !self.discarding;
                    self.discarding = true;
                    if first_report {
                        return Some(Piece::Overlong);
                    }
                }
                return None;
            };
            let line: Vec<u8> = self.buf.drain(..=end).take(end).collect();
            if std::mem::take(&mut self.discarding) || line.is_empty() {
                continue;
            }
            if line.len() > MAX_LINE_BYTES {
                return Some(Piece::Overlong);
            }
            return Some(Piece::Line(line));
        }
    }

    /// Drops the unterminated tail of the buffer (at a disconnect, or before discarding the
    /// port's input). Returns whether it held the start of a line, i.e. a truncated line was lost.
    pub fn take_partial(&mut self) -> bool {
        let had_partial = !self.buf.is_empty() && !self.discarding;
        self.buf.clear();
        self.discarding = false;
        had_partial
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn drain(splitter: &mut LineSplitter) -> Vec<Piece> {
        std::iter::from_fn(|| splitter.next_piece()).collect()
    }

    fn line(text: &str) -> Piece {
        Piece::Line(text.as_bytes().to_vec())
    }

    #[test]
    fn accepts_crlf_lf_and_cr_and_drops_empty_lines() {
        let mut s = LineSplitter::new();
        s.push(b"a,b\r\nc\nd\re\r\n\r\n\n");
        assert_eq!(
            drain(&mut s),
            vec![line("a,b"), line("c"), line("d"), line("e")]
        );
        assert!(!s.take_partial());
    }

    #[test]
    fn a_line_split_across_pushes_is_joined() {
        let mut s = LineSplitter::new();
        s.push(b"Raw:1,2,");
        assert_eq!(s.next_piece(), None);
        s.push(b"3\r\nRa");
        assert_eq!(drain(&mut s), vec![line("Raw:1,2,3")]);
        assert!(s.take_partial(), "\"Ra\" was pending");
        assert!(!s.take_partial());
    }

    #[test]
    fn overlong_noise_is_reported_once_and_dropped_up_to_the_next_terminator() {
        let mut s = LineSplitter::new();
        let noise = vec![b'x'; MAX_LINE_BYTES + 10];
        s.push(&noise);
        assert_eq!(drain(&mut s), vec![Piece::Overlong]);
        s.push(&noise);
        assert_eq!(
            drain(&mut s),
            vec![],
            "same overlong line, not reported again"
        );
        s.push(b"tail\nok\n");
        assert_eq!(drain(&mut s), vec![line("ok")]);
    }

    #[test]
    fn an_overlong_line_arriving_whole_is_reported() {
        let mut s = LineSplitter::new();
        let mut bytes = vec![b'y'; MAX_LINE_BYTES + 1];
        bytes.extend_from_slice(b"\nnext\n");
        s.push(&bytes);
        assert_eq!(drain(&mut s), vec![Piece::Overlong, line("next")]);
    }

    #[test]
    fn the_tail_of_an_overlong_line_is_not_a_partial_line() {
        let mut s = LineSplitter::new();
        s.push(&[b'z'; MAX_LINE_BYTES + 1]);
        assert_eq!(drain(&mut s), vec![Piece::Overlong]);
        s.push(b"zz");
        assert!(!s.take_partial());
    }
}
