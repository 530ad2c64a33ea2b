//! A production line: a folder of recordings in, one table out (`magcal-batch`). Every recording is fitted by the
//! one workflow every tool uses ([`fit_file`]), several at a time; each gives a row ([`row`]): the board, its
//! verdict, what the fit found, or why the file was not fitted — a failing file is a row, never the end of the
//! batch. Then the lot ([`lot`]): per kind of board, each parameter's median and robust spread, and the boards far
//! from their siblings. The table is a CSV and a JSON, both written atomically; the CSV is also the batch's journal
//! ([`table`]), so a batch killed midway and run again with the same `--out` fits only what is not in it yet.
//!
//! Memory stays bounded whatever the count: `jobs` workers each hold one recording, dropped before the next, and
//! a row is a few hundred bytes.

pub mod inputs;
pub mod lot;
pub mod row;
pub mod screen;
pub mod table;

use std::collections::HashMap;
use std::io::IsTerminal as _;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::mpsc;
use std::time::Instant;

use anyhow::bail;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use serde::{Deserialize, Serialize};

use crate::field::FieldArgs;
use crate::fit::Method;
use crate::outputs::{Guard, Replace};
use crate::verdict::{GOOD_DEG, USABLE_DEG};
use crate::workflow::{FitRequest, fit_file};
use lot::Lot;
use row::Row;

/// How each recording is fitted: the same for the whole batch.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FitOptions {
    /// The method.
    pub method: Method,
    /// Whether to diagnose what the base model leaves out.
    pub diagnose: bool,
    /// The world field from the command line (else each recording's metadata says it).
    pub field: FieldArgs,
}

impl FitOptions {
    /// The options as `magcal-fit` takes them on its command line (`--method auto --no-diagnose`): each row keeps
    /// them, so that a batch is resumed with the options it was started with.
    pub fn describe(&self) -> String {
        let mut out = format!("--method {}", self.method.as_str());
        if !self.diagnose {
            out.push_str(" --no-diagnose");
        }
        if let Some([n, e, d]) = self.field.field_ned_ut {
            out.push_str(&format!(" --field-ned {n},{e},{d}"));
        }
        if let Some((loc, date)) = self.field.location {
            out.push_str(&format!(
                " --location {},{},{} --date {date}",
                loc.lat_deg, loc.lon_deg, loc.alt_m
            ));
        }
        if let Some(f) = self.field.field_ut {
            out.push_str(&format!(" --field-ut {f}"));
        }
        out
    }
}

/// What a batch is asked to do.
#[derive(Clone, Debug)]
pub struct BatchOptions {
    /// Recordings, folders of them, or glob patterns ([`inputs::recordings`]).
    pub inputs: Vec<PathBuf>,
    /// How each is fitted.
    pub fit: FitOptions,
    /// The table (CSV): written as the batch goes, and resumed from.
    pub out: Option<PathBuf>,
    /// The table and the lot as JSON.
    pub json: Option<PathBuf>,
    /// Recordings fitted at once (each fit also uses every core for its own parts).
    pub jobs: usize,
    /// Show a progress bar (on standard error, when it is a terminal).
    pub progress: bool,
}

/// A finished batch.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Batch {
    /// The fit options every row was made with.
    pub fit_options: String,
    /// The verdict's gates, degrees of heading error left: good, usable.
    pub gates_deg: [f64; 2],
    /// The robust z beyond which a board is an outlier against its lot ([`lot::OUTLIER_Z`]).
    pub outlier_z: f64,
    /// Recordings fitted in this run.
    pub fitted_now: usize,
    /// Rows kept from the table as it was (their recordings unchanged).
    pub kept: usize,
    /// Recordings fitted at once.
    pub jobs: usize,
    /// This run's wall time, s.
    pub elapsed_s: f64,
    /// The rows: those kept from an earlier run for recordings not named this time first, then this run's in the
    /// order named.
    pub rows: Vec<Row>,
    /// The lots, by kind.
    pub lots: Vec<Lot>,
}

/// Runs a batch: finds the recordings, takes the rows already in `--out` for those unchanged, fits the rest
/// `jobs` at a time (appending each row to `--out` as it comes), then works out the lot and writes the table and
/// the JSON.
pub fn run(opts: &BatchOptions) -> anyhow::Result<Batch> {
    let start = Instant::now();
    Guard::new("magcal-batch")
        .file("--out", opts.out.as_deref(), Replace::Products)
        .file("--json", opts.json.as_deref(), Replace::Products)
        .check()?;
    let output_paths: Vec<&Path> = [&opts.out, &opts.json]
        .into_iter()
        .filter_map(|p| p.as_deref())
        .collect();
    let recordings = inputs::recordings(&opts.inputs, &output_paths)?;
    let fit_options = opts.fit.describe();
    let Earlier {
        mut slots,
        others,
        kept,
    } = earlier(opts, &recordings, &fit_options)?;
    let mut journal = match &opts.out {
        Some(path) => Some(table::Journal::open(
            path,
            &others
                .iter()
                .chain(slots.iter().flatten())
                .cloned()
                .collect::<Vec<_>>(),
        )?),
        None => None,
    };
    let todo: Vec<usize> = (0..slots.len()).filter(|&i| slots[i].is_none()).collect();
    let jobs = opts.jobs.clamp(1, todo.len().max(1));
    let bar = progress_bar(opts.progress, recordings.len(), kept);
    let written = fit_all(opts, &recordings, &fit_options, &todo, jobs, |i, row| {
        if let Some(journal) = &mut journal {
            journal.append(&row)?;
        }
        bar.inc(1);
        slots[i] = Some(row);
        Ok(())
    });
    bar.finish_and_clear();
    written?;

    let mut rows = others;
    rows.extend(slots.into_iter().flatten());
    let lots = lot::lots(&mut rows);
    let batch = Batch {
        fit_options,
        gates_deg: [GOOD_DEG, USABLE_DEG],
        outlier_z: lot::OUTLIER_Z,
        fitted_now: todo.len(),
        kept,
        jobs,
        elapsed_s: start.elapsed().as_secs_f64(),
        rows,
        lots,
    };
    if let Some(path) = &opts.out {
        table::write_csv(path, &batch.rows)?;
    }
    if let Some(path) = &opts.json {
        table::write_json(path, &batch)?;
    }
    Ok(batch)
}

/// The rows a batch takes from its table as it was.
struct Earlier {
    /// Per recording named, its row when the table has one for it and it is unchanged since.
    slots: Vec<Option<Row>>,
    /// The rows of recordings not named this time, in their order.
    others: Vec<Row>,
    /// Rows kept for recordings named.
    kept: usize,
}

/// The rows already in `--out`: kept for recordings unchanged since, fitted again otherwise; refused when they were
/// fitted with other options.
fn earlier(
    opts: &BatchOptions,
    recordings: &[PathBuf],
    fit_options: &str,
) -> anyhow::Result<Earlier> {
    let earlier = match &opts.out {
        Some(path) => table::read(path)?,
        None => Vec::new(),
    };
    if let Some(row) = earlier.iter().find(|r| r.fit_options != fit_options) {
        bail!(
            "{}: its rows were fitted with `{}`, and this run asks for `{fit_options}`: run with the options it was \
             started with to complete it, or name another --out for a new table",
            opts.out
                .as_deref()
                .map_or(String::new(), |p| p.display().to_string()),
            row.fit_options
        );
    }
    let key = |file: &Path| std::fs::canonicalize(file).unwrap_or_else(|_| file.to_owned());
    let mut by_file: HashMap<PathBuf, Row> = earlier
        .iter()
        .map(|r| (key(Path::new(&r.file)), r.clone()))
        .collect();
    let slots: Vec<Option<Row>> = recordings
        .iter()
        .map(|p| {
            by_file
                .remove(&key(p))
                .filter(|r| (r.file_bytes, r.modified_ns) == row::stamp(p))
        })
        .collect();
    let kept = slots.iter().filter(|s| s.is_some()).count();
    let others: Vec<Row> = earlier
        .into_iter()
        .filter(|r| by_file.remove(&key(Path::new(&r.file))).is_some())
        .collect();
    Ok(Earlier {
        slots,
        others,
        kept,
    })
}

/// Fits the recordings `todo` (indices into `recordings`) on `jobs` worker threads, each holding one recording at a
/// time, and hands each row to `done` on this thread as it comes; the first error of `done` stops the workers.
fn fit_all(
    opts: &BatchOptions,
    recordings: &[PathBuf],
    fit_options: &str,
    todo: &[usize],
    jobs: usize,
    mut done: impl FnMut(usize, Row) -> anyhow::Result<()>,
) -> anyhow::Result<()> {
    let request = FitRequest {
        method: opts.fit.method,
        diagnose: opts.fit.diagnose,
        field: &opts.fit.field,
        linear_only: false,
        chip: None,
        log: Default::default(),
    };
    let next = AtomicUsize::new(0);
    let stop = AtomicBool::new(false);
    let (tx, rx) = mpsc::channel::<(usize, Row)>();
    std::thread::scope(|s| {
        for _ in 0..jobs {
            let tx = tx.clone();
            let (next, stop, request) = (&next, &stop, &request);
            s.spawn(move || {
                while !stop.load(Ordering::Relaxed) {
                    let Some(&i) = todo.get(next.fetch_add(1, Ordering::Relaxed)) else {
                        break;
                    };
                    let row = fit_one(&recordings[i], request, fit_options);
                    if tx.send((i, row)).is_err() {
                        break;
                    }
                }
            });
        }
        drop(tx);
        for (i, row) in rx {
            if let Err(e) = done(i, row) {
                stop.store(true, Ordering::Relaxed);
                return Err(e);
            }
        }
        Ok(())
    })
}

/// Fits one recording into its row; a panic in the fit (a fault of magcal's) is a row too.
fn fit_one(path: &Path, request: &FitRequest<'_>, fit_options: &str) -> Row {
    let fitted = catch_unwind(AssertUnwindSafe(|| {
        Row::new(path, &fit_file(path, request), fit_options)
    }));
    fitted.unwrap_or_else(|panic| {
        let message = panic
            .downcast_ref::<&str>()
            .map(|s| (*s).to_owned())
            .or_else(|| panic.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "a panic without a message".to_owned());
        Row::panicked(path, &message, fit_options)
    })
}

/// The progress bar: on standard error when it is a terminal and `show`, hidden otherwise.
fn progress_bar(show: bool, total: usize, done: usize) -> ProgressBar {
    let target = if show && std::io::stderr().is_terminal() {
        ProgressDrawTarget::stderr()
    } else {
        ProgressDrawTarget::hidden()
    };
    let bar = ProgressBar::with_draw_target(Some(total as u64), target);
    bar.set_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} recordings, {elapsed} ({eta} left)")
            .expect("a valid template"),
    );
    bar.set_position(done as u64);
    bar
}
