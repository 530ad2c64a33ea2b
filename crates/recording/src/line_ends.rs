//! Line endings as the reader sees them: `\r\n` (Windows), `\r` alone (classic Mac OS, some loggers) and `\n` all
//! become `\n`, in one streaming pass, so that lines are counted the same whatever ended them.

use std::io::{self, Read};

/// A reader that turns `\r\n` and lone `\r` into `\n`.
#[derive(Debug)]
pub(crate) struct LineEnds<R> {
    inner: R,
    /// The last byte passed on was a `\r` (turned into `\n`): a `\n` right after it belongs to the same line end.
    after_cr: bool,
}

impl<R: Read> LineEnds<R> {
    pub(crate) fn new(inner: R) -> LineEnds<R> {
        LineEnds {
            inner,
            after_cr: false,
        }
    }
}

impl<R: Read> Read for LineEnds<R> {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        loop {
            let n = self.inner.read(buf)?;
            if n == 0 {
                return Ok(0);
            }
            let chunk = &mut buf[..n];
            // Most files have no CR at all: pass them through untouched.
            if !self.after_cr && !chunk.contains(&b'\r') {
                return Ok(n);
            }
            let mut kept = 0;
            for i in 0..n {
                let b = chunk[i];
                if b == b'\n' && self.after_cr {
                    self.after_cr = false;
                    continue;
                }
                self.after_cr = b == b'\r';
                chunk[kept] = if self.after_cr { b'\n' } else { b };
                kept += 1;
            }
            // A chunk that was a single '\n' ending a CRLF split across reads gives nothing: read on.
            if kept > 0 {
                return Ok(kept);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Reads `input` through [`LineEnds`] in chunks of `chunk` bytes.
    fn through(input: &[u8], chunk: usize) -> Vec<u8> {
        struct Chunks<'a>(&'a [u8], usize);
        impl Read for Chunks<'_> {
            fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
                let n = self.0.len().min(self.1).min(buf.len());
                buf[..n].copy_from_slice(&self.0[..n]);
                self.0 = &self.0[n..];
                Ok(n)
            }
        }
        let mut out = Vec::new();
        LineEnds::new(Chunks(input, chunk))
            .read_to_end(&mut out)
            .unwrap();
        out
    }

    #[test]
    fn every_line_end_becomes_one_newline_whatever_the_chunks() {
        let input = b"a\r\nb\rc\nd\r\r\ne\r";
        for chunk in 1..=input.len() {
            assert_eq!(
                through(input, chunk),
                b"a\nb\nc\nd\n\ne\n",
                "chunks of {chunk}"
            );
        }
        assert_eq!(through(b"plain\nlines\n", 4), b"plain\nlines\n");
    }
}
