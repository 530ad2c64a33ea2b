//! Whether a file holds a recording, however it was saved: what the tools ask before an output would replace a
//! file. It reads the file's start as the reader does (any length of metadata, any line ends, a byte order mark),
//! UTF-16 decoded, and names a compressed file, whose content it cannot see.
//!
//! A file holds a recording when a line of its metadata block is the format's magic line, when its header row
//! names a column `mx` (with any separator the reader takes), or when it is a MotionCal board's `Raw:` lines saved
//! as they came: readings, in any case.

use std::fs::File;
use std::io::{self, BufRead, BufReader, Read};
use std::path::Path;

use crate::line_ends::LineEnds;
use crate::metadata::{MetaLine, classify_line};
use crate::read::{BOM, COMPRESSED};

/// What a file holds, as far as outputs are concerned.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Holds {
    /// No recording (or nothing: a missing or empty file).
    Other,
    /// A recording: its metadata pairs, and `Some("UTF-16")` when it is so encoded.
    Recording {
        /// The metadata `key: value` pairs, in order.
        pairs: Vec<(String, String)>,
        /// The text encoding, when not UTF-8.
        encoding: Option<&'static str>,
    },
    /// A compressed file (`gzip`, `bzip2`, `xz`, `zstd`, `zip`): it may hold a recording.
    Compressed(&'static str),
}

/// Lines longer than this are read no further (a header of many columns fits).
const MAX_LINE_BYTES: u64 = 1 << 20;

/// What the file at `path` holds. A file that cannot be opened (missing, unreadable) or is no regular file holds
/// [`Holds::Other`].
pub fn probe(path: &Path) -> Holds {
    if !std::fs::metadata(path).is_ok_and(|m| m.is_file()) {
        return Holds::Other;
    }
    File::open(path).map_or(Holds::Other, |f| probe_reader(f).unwrap_or(Holds::Other))
}

/// What the bytes `reader` gives hold (see [`probe`]).
pub fn probe_reader(reader: impl Read) -> io::Result<Holds> {
    let mut raw = BufReader::new(reader);
    let start = raw.fill_buf()?;
    if let Some((_, format)) = COMPRESSED.iter().find(|(m, _)| start.starts_with(m)) {
        return Ok(Holds::Compressed(format));
    }
    let big_endian = match start {
        [0xfe, 0xff, ..] => Some(true),
        [0xff, 0xfe, ..] => Some(false),
        _ => None,
    };
    match big_endian {
        Some(big) => {
            raw.consume(2);
            let text = Utf16 {
                inner: raw,
                big,
                pending: Vec::new(),
            };
            Ok(match probe_text(text)? {
                Holds::Recording { pairs, .. } => Holds::Recording {
                    pairs,
                    encoding: Some("UTF-16"),
                },
                other => other,
            })
        }
        None => probe_text(raw),
    }
}

/// What text holds: the metadata block's keys, then the header row.
fn probe_text(reader: impl Read) -> io::Result<Holds> {
    let mut input = BufReader::new(LineEnds::new(reader));
    let mut pairs = Vec::new();
    let mut magic = false;
    let mut line = Vec::new();
    let mut first = true;
    loop {
        line.clear();
        let n = (&mut input)
            .take(MAX_LINE_BYTES)
            .read_until(b'\n', &mut line)?;
        if n == 0 {
            return Ok(if magic {
                Holds::Recording {
                    pairs,
                    encoding: None,
                }
            } else {
                Holds::Other
            });
        }
        if first && line.starts_with(BOM) {
            line.drain(..BOM.len());
        }
        first = false;
        let text = line.trim_ascii();
        if text.is_empty() {
            continue;
        }
        if text.contains(&0) {
            return Ok(Holds::Other);
        }
        if !text.starts_with(b"#") {
            let recording = magic || header_reads(text);
            return Ok(if recording {
                Holds::Recording {
                    pairs,
                    encoding: None,
                }
            } else {
                Holds::Other
            });
        }
        match classify_line(&String::from_utf8_lossy(text)) {
            MetaLine::Magic(_) => magic = true,
            MetaLine::Pair(key, value) => pairs.push((key.to_owned(), value.to_owned())),
            MetaLine::Comment => {}
        }
        // A line cut at the cap: skip the rest of it.
        if n as u64 == MAX_LINE_BYTES && !line.ends_with(b"\n") {
            let mut rest = Vec::new();
            input.read_until(b'\n', &mut rest)?;
        }
    }
}

/// Whether a header row names a column `mx` (any case, quoted or not, whatever separates the columns), or is a
/// MotionCal `Raw:` line.
fn header_reads(header: &[u8]) -> bool {
    header.starts_with(b"Raw:")
        || header
            .split(|b| matches!(b, b',' | b';' | b'\t'))
            .map(|f| f.trim_ascii())
            .map(|f| f.strip_prefix(b"\"").unwrap_or(f))
            .map(|f| f.strip_suffix(b"\"").unwrap_or(f))
            .any(|f| f.trim_ascii().eq_ignore_ascii_case(b"mx"))
}

/// UTF-16 text as UTF-8 bytes (unpaired surrogates become U+FFFD).
struct Utf16<R> {
    inner: R,
    big: bool,
    pending: Vec<u8>,
}

impl<R: BufRead> Read for Utf16<R> {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        while self.pending.is_empty() {
            let mut units = Vec::new();
            let mut pair = [0u8; 2];
            for _ in 0..2048 {
                match self.inner.read_exact(&mut pair) {
                    Ok(()) => units.push(if self.big {
                        u16::from_be_bytes(pair)
                    } else {
                        u16::from_le_bytes(pair)
                    }),
                    Err(e) if e.kind() == io::ErrorKind::UnexpectedEof => break,
                    Err(e) => return Err(e),
                }
            }
            if units.is_empty() {
                return Ok(0);
            }
            let text: String = char::decode_utf16(units)
                .map(|c| c.unwrap_or(char::REPLACEMENT_CHARACTER))
                .collect();
            self.pending = text.into_bytes();
        }
        let n = buf.len().min(self.pending.len());
        buf[..n].copy_from_slice(&self.pending[..n]);
        self.pending.drain(..n);
        Ok(n)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn holds(bytes: &[u8]) -> Holds {
        probe_reader(bytes).unwrap()
    }

    fn is_recording(bytes: &[u8]) -> bool {
        matches!(holds(bytes), Holds::Recording { .. })
    }

    fn utf16(text: &str, big: bool) -> Vec<u8> {
        let mut out = if big {
            vec![0xfe, 0xff]
        } else {
            vec![0xff, 0xfe]
        };
        for u in text.encode_utf16() {
            out.extend(if big {
                u.to_be_bytes()
            } else {
                u.to_le_bytes()
            });
        }
        out
    }

    #[test]
    fn recordings_are_found_however_they_were_saved() {
        let plain = "# magcal-recording v1\n# simulated: yes\nt,mx,my,mz\n0,1,2,3\n";
        assert_eq!(
            holds(plain.as_bytes()),
            Holds::Recording {
                pairs: vec![("simulated".into(), "yes".into())],
                encoding: None
            }
        );
        let long_metadata = format!("{}t,mx,my,mz\n0,1,2,3\n", "# note: x\n".repeat(20_000));
        assert!(long_metadata.len() > 64 << 10);
        assert!(is_recording(long_metadata.as_bytes()));
        for text in [
            "t;MX;MY;MZ\r0;1;2;3\r",
            "\u{feff}t,mx,my,mz\r\n",
            "\"t\",\"mx\",\"my\",\"mz\"\n",
            "# magcal-recording v1\n",
            "Raw:1,2,3,4,5,6,7,8,9\n",
            "time\tmx\tmy\tmz\n",
        ] {
            assert!(is_recording(text.as_bytes()), "{text:?}");
        }
        for big in [false, true] {
            assert_eq!(
                holds(&utf16(plain, big)),
                Holds::Recording {
                    pairs: vec![("simulated".into(), "yes".into())],
                    encoding: Some("UTF-16")
                }
            );
        }
        assert_eq!(holds(b"\x1f\x8b\x08\x00rest"), Holds::Compressed("gzip"));
    }

    #[test]
    fn other_files_are_not_recordings() {
        for text in [
            "",
            "format = \"magcal-params v1\"\n[calibration]\nA = [[1,0,0]]\n",
            "{\"report\": 1}\n",
            "COMPASS_OFS_X 1.0\n",
            "<svg xmlns=\"http://www.w3.org/2000/svg\"></svg>\n",
            "a,b,c\n1,2,3\n",
            "\0\0binary",
        ] {
            assert_eq!(holds(text.as_bytes()), Holds::Other, "{text:?}");
        }
    }
}
