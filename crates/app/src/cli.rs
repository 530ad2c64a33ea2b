//! Command-line pieces the tools share: lists of numbers, the world-field options, Ctrl-C, standard output, the exit.

use std::io::{self, Write};
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use magcal_recording::{Date, Location, Metadata};

use crate::field::FieldArgs;

/// Parses `N` comma-separated numbers (`"19.8, 1.2, 45.3"`).
pub fn parse_floats<const N: usize>(s: &str) -> Result<[f64; N], String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|x| x.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|e| format!("{}: {e}", excerpt(s)))?;
    v.try_into()
        .map_err(|_| format!("expected {N} comma-separated numbers, got {}", excerpt(s)))
}

/// A number as an error quotes it: as Rust writes it (`0.25`, `10000000`), or in scientific notation when that
/// would take many digits (`1e30`, `1e-9`, `1e-300`), never hundreds of them.
pub fn number(value: f64) -> String {
    let size = value.abs();
    if size >= 1e16 || (size > 0.0 && size < 1e-4) {
        format!("{value:e}")
    } else {
        value.to_string()
    }
}

/// At most this many characters of a user's argument are quoted in an error.
pub const EXCERPT_CHARS: usize = 40;

/// A short, escaped excerpt of a user's argument for an error: its first [`EXCERPT_CHARS`] characters (`…` when it
/// had more), quoted with control characters escaped, so that a long or hostile argument never floods the terminal
/// or writes escape sequences to it.
pub fn excerpt(text: &str) -> String {
    match text.char_indices().nth(EXCERPT_CHARS) {
        Some((end, _)) => format!("{:?}", format!("{}…", &text[..end])),
        None => format!("{text:?}"),
    }
}

/// Checks a board's identifier (`magcal-record --serial`): text a recording's metadata line can hold as it is —
/// not empty, no surrounding blanks, no control character, no trailing `,` or `;` (a spreadsheet's padding).
pub fn parse_serial(s: &str) -> Result<String, String> {
    let plain = !s.is_empty()
        && s.trim() == s
        && !s.ends_with([',', ';'])
        && !s.chars().any(char::is_control);
    if plain {
        Ok(s.to_owned())
    } else {
        Err(format!(
            "{s:?}: a serial is plain text on one line, without surrounding blanks or a trailing ',' or ';'"
        ))
    }
}

/// The local world field, given directly or by place and date for the World Magnetic Model.
#[derive(Clone, Debug, Default, clap::Args)]
pub struct WorldFieldOpts {
    /// The world field N,E,D in µT (overrides a recording's field_ned_ut).
    #[arg(long, value_name = "N,E,D", value_parser = parse_floats::<3>, allow_hyphen_values = true, conflicts_with = "location")]
    pub field_ned: Option<[f64; 3]>,
    /// Where you are, for the World Magnetic Model: latitude, longitude (degrees), altitude (m). Needs --date.
    #[arg(long, value_name = "LAT,LON,ALT", value_parser = parse_floats::<3>, allow_hyphen_values = true, requires = "date")]
    pub location: Option<[f64; 3]>,
    /// The date, for the World Magnetic Model, YYYY-MM-DD.
    #[arg(long, value_name = "YYYY-MM-DD", requires = "location")]
    pub date: Option<Date>,
}

impl WorldFieldOpts {
    /// The place and date, when both were given.
    pub fn place(&self) -> Option<(Location, Date)> {
        let [lat_deg, lon_deg, alt_m] = self.location?;
        Some((
            Location {
                lat_deg,
                lon_deg,
                alt_m,
            },
            self.date?,
        ))
    }

    /// What to resolve the field from, with a magnitude-only fallback `field_ut`.
    pub fn field_args(&self, field_ut: Option<f64>) -> FieldArgs {
        FieldArgs {
            field_ned_ut: self.field_ned,
            location: self.place(),
            field_ut,
        }
    }

    /// Writes the options into a recording's metadata, for the fit to use.
    pub fn write_metadata(&self, meta: &mut Metadata) {
        meta.field_ned_ut = self.field_ned;
        if let Some((loc, date)) = self.place() {
            meta.location = Some(loc);
            meta.date = Some(date);
        }
    }
}

/// Installs the Ctrl-C handler of a recording tool and returns the flag it sets. The first Ctrl-C sets it: the
/// recording stops at the next sample or within a fraction of a second, and the file is finished. A second one, should
/// the first go unheeded, exits at once with status 130 (the file keeps every row flushed so far, and parses), the
/// terminal's echo restored.
pub fn interrupt_flag(tool: &'static str) -> anyhow::Result<Arc<AtomicBool>> {
    let interrupt = Arc::new(AtomicBool::new(false));
    let flag = interrupt.clone();
    ctrlc::set_handler(move || {
        if flag.swap(true, Ordering::Relaxed) {
            crate::tty::restore();
            crate::tellln!(
                "{tool}: interrupted again: stopping now (the file keeps what was written)"
            );
            std::process::exit(130);
        }
    })
    .map_err(|e| anyhow::anyhow!("installing the Ctrl-C handler: {e}"))?;
    Ok(interrupt)
}

/// Writes to standard output. A reader that went away (`magcal-fit rec.csv | head -3`) ends the output, not the tool:
/// the recording goes on and the files asked for are still written, where `print!` would panic. Other failures (a
/// full disk behind a redirection) are errors.
pub fn say(text: std::fmt::Arguments<'_>) -> io::Result<()> {
    match io::stdout().lock().write_fmt(text) {
        Err(e) if e.kind() == io::ErrorKind::BrokenPipe => Ok(()),
        written => written,
    }
}

/// `print!` through [`say`]: `say!("{x}")?`.
#[macro_export]
macro_rules! say {
    ($($arg:tt)*) => {
        $crate::cli::say(format_args!($($arg)*))
    };
}

/// `println!` through [`say`]: `sayln!("{x}")?`.
#[macro_export]
macro_rules! sayln {
    ($($arg:tt)*) => {
        $crate::cli::say(format_args!("{}\n", format_args!($($arg)*)))
    };
}

/// Writes to standard error, where notes, warnings and errors go. Nothing is left to tell a failure to, so it is
/// ignored: a closed standard error (`magcal-fit … 2>&1 | head`) must not stop the tool before its files are written,
/// where `eprint!` would panic.
pub fn tell(text: std::fmt::Arguments<'_>) {
    let _ = io::stderr().lock().write_fmt(text);
}

/// `eprint!` through [`tell`].
#[macro_export]
macro_rules! tell {
    ($($arg:tt)*) => {
        $crate::cli::tell(format_args!($($arg)*))
    };
}

/// `eprintln!` through [`tell`].
#[macro_export]
macro_rules! tellln {
    ($($arg:tt)*) => {
        $crate::cli::tell(format_args!("{}\n", format_args!($($arg)*)))
    };
}

/// The process exit for a tool's result: the error chain on stderr, prefixed with the tool's name, with any long
/// command-line argument it quotes cut to a short excerpt ([`shortened`]).
pub fn exit(tool: &str, result: anyhow::Result<()>) -> ExitCode {
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            crate::tellln!("{tool}: error: {}", shortened(&format!("{e:#}")));
            ExitCode::FAILURE
        }
    }
}

/// Parses the command line as clap does, except that an error quotes a long argument as a short excerpt
/// ([`shortened`]), where clap would quote all of it (and a value parser's message, again).
pub fn parse<T: clap::Parser>() -> T {
    T::try_parse().unwrap_or_else(|e| {
        if !e.use_stderr() {
            // --help, --version.
            e.exit();
        }
        tell(format_args!("{}", shortened(&e.render().to_string())));
        std::process::exit(e.exit_code());
    })
}

/// `text` without terminal escape sequences (`ESC [ … letter`) and other control characters.
fn without_escapes(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut chars = text.chars().peekable();
    while let Some(c) = chars.next() {
        if c == '\u{1b}' && chars.peek() == Some(&'[') {
            chars.next();
            while chars.next().is_some_and(|c| !('@'..='~').contains(&c)) {}
        } else if !c.is_control() {
            out.push(c);
        }
    }
    out
}

/// The longest line of an error message shown whole: a message longer than this quotes something it should not.
const MAX_ERROR_LINE_CHARS: usize = 2000;

/// An argument longer than this, bytes, is no path (Linux's `PATH_MAX`): an error quotes an excerpt of it.
const MAX_PATH_BYTES: usize = 4096;

/// `message` with every command-line argument it quotes that is longer than a path can be ([`MAX_PATH_BYTES`]) or
/// holds control characters (whole, after an `=`, or a piece between `:`, `;`, `=` and `,`), as is or escaped,
/// replaced by a short, escaped excerpt, and any line still over [`MAX_ERROR_LINE_CHARS`] characters cut. Paths, which
/// errors name, are left whole.
pub fn shortened(message: &str) -> String {
    let mut pieces: Vec<String> = Vec::new();
    for arg in std::env::args_os().skip(1) {
        let arg = arg.to_string_lossy().into_owned();
        pieces.extend(arg.split([':', ';', '=', ',']).map(str::to_owned));
        if let Some((_, value)) = arg.split_once('=') {
            pieces.push(value.to_owned());
        }
        pieces.push(arg);
    }
    // clap drops escape sequences from what it quotes.
    let plain: Vec<String> = pieces.iter().map(|p| without_escapes(p)).collect();
    pieces.extend(plain);
    pieces.retain(|p| p.len() > MAX_PATH_BYTES || p.chars().any(char::is_control));
    // The longest first, so that a piece is not cut out of an argument before the argument itself.
    pieces.sort_by_key(|p| std::cmp::Reverse(p.len()));
    let mut out = message.to_owned();
    for piece in &pieces {
        let short = excerpt(piece);
        out = out.replace(&format!("{piece:?}"), &short);
        out = out.replace(&format!("'{piece}'"), &short);
        out = out.replace(piece.as_str(), &short);
    }
    out.lines()
        .map(|line| match line.char_indices().nth(MAX_ERROR_LINE_CHARS) {
            Some((end, _)) => format!(
                "{}… ({} characters more)",
                &line[..end],
                line[end..].chars().count()
            ),
            None => line.to_owned(),
        })
        .collect::<Vec<_>>()
        .join("\n")
        + if message.ends_with('\n') { "\n" } else { "" }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_and_arguments_are_quoted_short() {
        assert_eq!(number(0.25), "0.25");
        assert_eq!(number(1e12), "1000000000000");
        assert_eq!(number(1e30), "1e30");
        assert_eq!(number(-1e-300), "-1e-300");
        assert_eq!(number(f64::NAN), "NaN");
        assert_eq!(excerpt("ab\u{1b}[2J"), "\"ab\\u{1b}[2J\"");
        let long = "x".repeat(100_000);
        assert_eq!(excerpt(&long), format!("\"{}…\"", "x".repeat(40)));
        assert_eq!(without_escapes("a\u{1b}[2Jb\u{7}c"), "abc");
    }

    #[test]
    fn numbers_lists_say_what_is_wrong() {
        assert_eq!(parse_floats::<3>("19.8, 1.2,45.3"), Ok([19.8, 1.2, 45.3]));
        assert!(parse_floats::<3>("1,2").unwrap_err().contains("expected 3"));
        assert!(parse_floats::<2>("1,x").unwrap_err().contains("\"1,x\""));
    }

    #[test]
    fn a_serial_is_plain_text_on_one_line() {
        assert_eq!(
            parse_serial("SN-0042 rev B"),
            Ok("SN-0042 rev B".to_owned())
        );
        for bad in ["", " SN", "SN\n2", "SN,"] {
            assert!(parse_serial(bad).is_err(), "{bad:?}");
        }
    }
}
