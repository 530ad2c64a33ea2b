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
        .map_err(|e| format!("{s:?}: {e}"))?;
    v.try_into()
        .map_err(|_| format!("expected {N} comma-separated numbers, got {s:?}"))
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
            crate::record::tty::restore();
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

/// The process exit for a tool's result: the error chain on stderr, prefixed with the tool's name.
pub fn exit(tool: &str, result: anyhow::Result<()>) -> ExitCode {
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            crate::tellln!("{tool}: error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
