//! One recording's row of the table: which board, its verdict, what the fit found, and why a file was not fitted.
//! The figures are taken from the JSON report ([`Report`]) the same fit gives `magcal-fit --report`, under the
//! report's own names (`offset_ut`, `offset_se_ut`, `A`, `rms_ut`, `noise_floor_ut`, `sphere_fraction`,
//! `left_worst_deg`, `grade`), so that a board's row and its report agree to the digit.
//!
//! In the CSV a vector is a column per component (`offset_ut.x`) and `A` is its diagonal (`A.xx`) and the extremes
//! of its off-diagonal elements; lists are joined by spaces. Numbers are written in the shortest form that reads
//! back exactly, so a table read back (to resume a batch) holds the same numbers.

use std::path::Path;
use std::time::UNIX_EPOCH;

use anyhow::{Context, bail};
use magcal_recording::{Metadata, Recording};
use serde::{Deserialize, Serialize};

use crate::report::Report;
use crate::verdict::Grade;
use crate::workflow::{Fitted, NotFitted};

/// The grade of a file that was not fitted (unread, or refused by the fit).
pub const FAILED: &str = "failed";

/// One recording's row.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Row {
    /// The board: the recording's `serial` metadata, else the file's name without its extension.
    pub id: String,
    /// The kind of board the lot statistics group it with: the recording's `chip` metadata, else its `sensor`
    /// (the chip's name, as magcal-record and magcal-sim write it); empty when neither is there.
    pub chip: String,
    /// `good`, `usable` or `redo` (the verdict's grade), or [`FAILED`].
    pub grade: String,
    /// The verdict's reason, or why the file was not fitted.
    pub reason: String,
    /// The one thing to do next.
    pub todo: String,
    /// The fit's figures; absent for a file not fitted.
    pub fit: Option<RowFit>,
    /// How the board stands against its lot; absent until the lot is complete, and for a file not fitted.
    pub lot: Option<LotMark>,
    /// The recording, as found.
    pub file: String,
    /// Its size, bytes: with `modified_ns`, how a resumed batch tells a recording changed since its row.
    pub file_bytes: u64,
    /// Its modification time, ns since 1970 (0 if the system gives none).
    pub modified_ns: u64,
    /// The options the fit was made with ([`crate::batch::FitOptions::describe`]).
    pub fit_options: String,
}

/// What the fit found, under the JSON report's names.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RowFit {
    /// `vector` or `scalar`.
    pub method: String,
    /// The heading error the calibration leaves at its worst heading, degrees (absent without the local field's
    /// direction).
    pub left_worst_deg: Option<f64>,
    /// The heading error of the raw readings at their worst heading, degrees.
    pub before_worst_deg: Option<f64>,
    /// The hard-iron offset in raw units, `−A⁻¹·b`, µT.
    pub offset_ut: [f64; 3],
    /// Its standard errors, µT.
    pub offset_se_ut: [f64; 3],
    /// `A`'s diagonal.
    #[serde(rename = "A_diag")]
    pub a_diag: [f64; 3],
    /// The smallest of `A`'s off-diagonal elements.
    #[serde(rename = "A_offdiag_min")]
    pub a_offdiag_min: f64,
    /// The largest of `A`'s off-diagonal elements.
    #[serde(rename = "A_offdiag_max")]
    pub a_offdiag_max: f64,
    /// The final model's residual RMS, per axis (vector) or of |B| (scalar), µT.
    pub rms_ut: f64,
    /// The noise floor it compares with, µT.
    pub noise_floor_ut: f64,
    /// The share of the sphere of field directions the recording visited.
    pub sphere_fraction: f64,
    /// Samples the robust base fit left out as grossly off.
    pub excluded: usize,
    /// The ids of the effects the diagnosis found and modelled (`temperature_bias`, …).
    pub effects: Vec<String>,
    /// Whether the diagnosis ran (without it, `effects` is empty for want of looking).
    pub diagnosed: bool,
}

/// A board against its lot ([`crate::batch::lot`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LotMark {
    /// The largest robust z of its parameters against the lot's (absent when its lot is too small to say).
    pub z_max: Option<f64>,
    /// The parameters beyond [`crate::batch::lot::OUTLIER_Z`], with their z (`offset_ut.x z=+9.3`).
    pub outliers: Vec<String>,
}

impl Row {
    /// The row of the recording at `path` fitted (or not) with `fit_options`.
    pub fn new(path: &Path, result: &Result<Fitted, NotFitted>, fit_options: &str) -> Row {
        let (file_bytes, modified_ns) = stamp(path);
        let name = path.display().to_string();
        let mut row = Row {
            id: String::new(),
            chip: String::new(),
            grade: FAILED.to_owned(),
            reason: String::new(),
            todo: String::new(),
            fit: None,
            lot: None,
            file: name.clone(),
            file_bytes,
            modified_ns,
            fit_options: fit_options.to_owned(),
        };
        let meta = match result {
            Ok(Fitted {
                rec,
                cal,
                assessment,
            }) => {
                let channels: Vec<String> = rec.currents.iter().map(|c| c.name.clone()).collect();
                let report = Report::new(cal, &name, &channels).with_assessment(assessment);
                let verdict = report.verdict.as_ref().expect("with_assessment sets it");
                row.grade.clone_from(&verdict.grade);
                row.reason.clone_from(&verdict.reason);
                row.todo.clone_from(&verdict.todo);
                row.fit = Some(RowFit::of(&report));
                Some(rec.meta.clone())
            }
            Err(NotFitted::Unread(e)) => {
                row.reason = format!("not read: {e:#}");
                row.todo = "mend the file as the reason says, or record the board again".to_owned();
                // The metadata may still name the board (a file cut off has its header).
                Recording::read_metadata(path).ok()
            }
            Err(NotFitted::Refused { rec, error }) => {
                row.reason = format!("cannot calibrate: {error}");
                row.todo = "record the board again as the reason says".to_owned();
                Some(rec.meta.clone())
            }
        };
        row.id = meta
            .as_ref()
            .and_then(|m| m.serial.clone())
            .unwrap_or_else(|| file_stem(path));
        row.chip = meta.as_ref().map(chip_of).unwrap_or_default();
        row
    }

    /// The row of a file whose fit panicked: a fault of magcal's, said as such, so the batch goes on.
    pub fn panicked(path: &Path, message: &str, fit_options: &str) -> Row {
        let mut row = Row::new(
            path,
            &Err(NotFitted::Unread(anyhow::anyhow!("{message}"))),
            fit_options,
        );
        row.reason = format!("magcal failed on this file (a fault of magcal's): {message}");
        row.todo = "report it with the file attached; the other boards are not affected".to_owned();
        row
    }

    /// The grade, `None` for a file not fitted.
    pub fn grade(&self) -> Option<Grade> {
        match self.grade.as_str() {
            "good" => Some(Grade::Good),
            "usable" => Some(Grade::Usable),
            "redo" => Some(Grade::Redo),
            _ => None,
        }
    }

    /// Whether the row meets `required` (a file not fitted meets nothing).
    pub fn meets(&self, required: Grade) -> bool {
        self.grade().is_some_and(|g| g >= required)
    }
}

impl RowFit {
    /// The figures of a fit's report.
    fn of(report: &Report) -> RowFit {
        let a = report.calibration.a;
        let off_diagonal =
            (0..3).flat_map(|j| (0..3).filter(move |&k| k != j).map(move |k| a[j][k]));
        RowFit {
            method: report.method.clone(),
            left_worst_deg: report.heading.as_ref().map(|h| h.left_worst_deg),
            before_worst_deg: report.heading.as_ref().map(|h| h.before_worst_deg),
            offset_ut: report.calibration.offset_ut,
            offset_se_ut: report.calibration.offset_se_ut,
            a_diag: [a[0][0], a[1][1], a[2][2]],
            a_offdiag_min: off_diagonal.clone().fold(f64::INFINITY, f64::min),
            a_offdiag_max: off_diagonal.fold(f64::NEG_INFINITY, f64::max),
            rms_ut: report.residual.rms_ut,
            noise_floor_ut: report.residual.noise_floor_ut,
            sphere_fraction: report.coverage.sphere_fraction,
            excluded: report.samples.excluded,
            effects: report
                .diagnosis
                .as_ref()
                .map(|d| d.effects.iter().map(|e| e.id.clone()).collect())
                .unwrap_or_default(),
            diagnosed: report.diagnosis.is_some(),
        }
    }
}

/// The kind of board: the `chip` metadata key, else `sensor`.
fn chip_of(meta: &Metadata) -> String {
    meta.other
        .iter()
        .find(|(k, _)| k == "chip")
        .map(|(_, v)| v.clone())
        .or_else(|| meta.sensor.clone())
        .unwrap_or_default()
}

/// The file's name without its extension.
fn file_stem(path: &Path) -> String {
    path.file_stem()
        .unwrap_or(path.as_os_str())
        .to_string_lossy()
        .into_owned()
}

/// A file's size (bytes) and modification time (ns since 1970), zero where the system gives none.
pub fn stamp(path: &Path) -> (u64, u64) {
    let Ok(meta) = std::fs::metadata(path) else {
        return (0, 0);
    };
    let modified_ns = meta
        .modified()
        .ok()
        .and_then(|m| m.duration_since(UNIX_EPOCH).ok())
        .map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX));
    (meta.len(), modified_ns)
}

/// The CSV's columns, in order.
pub const COLUMNS: [&str; 30] = [
    "id",
    "chip",
    "grade",
    "left_worst_deg",
    "before_worst_deg",
    "offset_ut.x",
    "offset_ut.y",
    "offset_ut.z",
    "offset_se_ut.x",
    "offset_se_ut.y",
    "offset_se_ut.z",
    "A.xx",
    "A.yy",
    "A.zz",
    "A_offdiag_min",
    "A_offdiag_max",
    "rms_ut",
    "noise_floor_ut",
    "sphere_fraction",
    "excluded",
    "effects",
    "lot_z_max",
    "lot_outliers",
    "method",
    "reason",
    "todo",
    "file",
    "file_bytes",
    "modified_ns",
    "fit_options",
];

/// Where `diagnosed` goes in the CSV: `effects` holds `-` when the diagnosis did not run (nothing looked for), and
/// is empty when it ran and found nothing.
const NOT_DIAGNOSED: &str = "-";

/// A number as a CSV field: the shortest form that reads back exactly; empty for none.
fn num(x: Option<f64>) -> String {
    x.map_or_else(String::new, |x| x.to_string())
}

impl Row {
    /// The row as CSV fields, in [`COLUMNS`] order.
    pub fn to_csv(&self) -> Vec<String> {
        let f = self.fit.as_ref();
        let v = |get: fn(&RowFit) -> f64| num(f.map(get));
        let mut out = vec![self.id.clone(), self.chip.clone(), self.grade.clone()];
        out.push(num(f.and_then(|f| f.left_worst_deg)));
        out.push(num(f.and_then(|f| f.before_worst_deg)));
        for k in 0..3 {
            out.push(num(f.map(|f| f.offset_ut[k])));
        }
        for k in 0..3 {
            out.push(num(f.map(|f| f.offset_se_ut[k])));
        }
        for k in 0..3 {
            out.push(num(f.map(|f| f.a_diag[k])));
        }
        out.push(v(|f| f.a_offdiag_min));
        out.push(v(|f| f.a_offdiag_max));
        out.push(v(|f| f.rms_ut));
        out.push(v(|f| f.noise_floor_ut));
        out.push(v(|f| f.sphere_fraction));
        out.push(f.map_or_else(String::new, |f| f.excluded.to_string()));
        out.push(f.map_or_else(String::new, |f| {
            if f.diagnosed {
                f.effects.join(" ")
            } else {
                NOT_DIAGNOSED.to_owned()
            }
        }));
        out.push(num(self.lot.as_ref().and_then(|l| l.z_max)));
        out.push(
            self.lot
                .as_ref()
                .map_or_else(String::new, |l| l.outliers.join("; ")),
        );
        out.push(f.map_or_else(String::new, |f| f.method.clone()));
        out.extend([
            self.reason.clone(),
            self.todo.clone(),
            self.file.clone(),
            self.file_bytes.to_string(),
            self.modified_ns.to_string(),
            self.fit_options.clone(),
        ]);
        debug_assert_eq!(out.len(), COLUMNS.len());
        out
    }

    /// The row a CSV record of [`COLUMNS`] holds.
    pub fn from_csv(record: &csv::StringRecord) -> anyhow::Result<Row> {
        if record.len() != COLUMNS.len() {
            bail!(
                "{} fields where the table has {} columns",
                record.len(),
                COLUMNS.len()
            );
        }
        let field = |i: usize| &record[i];
        let number = |i: usize| -> anyhow::Result<Option<f64>> {
            let text = field(i);
            if text.is_empty() {
                return Ok(None);
            }
            let x: f64 = text
                .parse()
                .with_context(|| format!("{}: {text:?} is not a number", COLUMNS[i]))?;
            Ok(Some(x))
        };
        let integer = |i: usize| -> anyhow::Result<u64> {
            field(i)
                .parse()
                .with_context(|| format!("{}: {:?} is not a whole number", COLUMNS[i], field(i)))
        };
        let required = |i: usize| -> anyhow::Result<f64> {
            number(i)?.with_context(|| format!("{}: empty in a fitted row", COLUMNS[i]))
        };
        let triple = |start: usize| -> anyhow::Result<[f64; 3]> {
            Ok([required(start)?, required(start + 1)?, required(start + 2)?])
        };
        let grade = field(2).to_owned();
        if !matches!(grade.as_str(), "good" | "usable" | "redo" | FAILED) {
            bail!("grade: {grade:?} is none of good, usable, redo, {FAILED}");
        }
        let fit = if grade == FAILED {
            None
        } else {
            let effects = field(20);
            Some(RowFit {
                method: field(23).to_owned(),
                left_worst_deg: number(3)?,
                before_worst_deg: number(4)?,
                offset_ut: triple(5)?,
                offset_se_ut: triple(8)?,
                a_diag: triple(11)?,
                a_offdiag_min: required(14)?,
                a_offdiag_max: required(15)?,
                rms_ut: required(16)?,
                noise_floor_ut: required(17)?,
                sphere_fraction: required(18)?,
                excluded: usize::try_from(integer(19)?)?,
                effects: effects
                    .split_whitespace()
                    .filter(|e| *e != NOT_DIAGNOSED)
                    .map(str::to_owned)
                    .collect(),
                diagnosed: effects != NOT_DIAGNOSED,
            })
        };
        Ok(Row {
            id: field(0).to_owned(),
            chip: field(1).to_owned(),
            grade,
            reason: field(24).to_owned(),
            todo: field(25).to_owned(),
            fit,
            lot: None,
            file: field(26).to_owned(),
            file_bytes: integer(27)?,
            modified_ns: integer(28)?,
            fit_options: field(29).to_owned(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fitted_row() -> Row {
        Row {
            id: "SN-1, rev \"B\"".into(),
            chip: "lis3mdl".into(),
            grade: "good".into(),
            reason: "0.4° left".into(),
            todo: "check it".into(),
            fit: Some(RowFit {
                method: "vector".into(),
                left_worst_deg: Some(0.123_456_789_012_345_67),
                before_worst_deg: None,
                offset_ut: [1.0 / 3.0, -2e-17, 40.0],
                offset_se_ut: [0.01, 0.02, 0.03],
                a_diag: [1.01, 0.99, 1.0],
                a_offdiag_min: -0.02,
                a_offdiag_max: 0.03,
                rms_ut: 0.4,
                noise_floor_ut: 0.39,
                sphere_fraction: 0.97,
                excluded: 12,
                effects: vec!["temperature_bias".into(), "time_lag".into()],
                diagnosed: true,
            }),
            lot: None,
            file: "lot/b 1.csv".into(),
            file_bytes: 123,
            modified_ns: 1_700_000_000_123_456_789,
            fit_options: "--method auto".into(),
        }
    }

    fn round_trip(row: &Row) -> Row {
        let record = csv::StringRecord::from(row.to_csv());
        Row::from_csv(&record).unwrap()
    }

    #[test]
    fn a_row_reads_back_from_its_csv_to_the_digit() {
        let row = fitted_row();
        assert_eq!(round_trip(&row), row);
        let mut undiagnosed = fitted_row();
        let fit = undiagnosed.fit.as_mut().unwrap();
        fit.effects.clear();
        fit.diagnosed = false;
        assert_eq!(round_trip(&undiagnosed), undiagnosed);
        let mut none_found = fitted_row();
        none_found.fit.as_mut().unwrap().effects.clear();
        assert_eq!(round_trip(&none_found), none_found);
        let failed = Row {
            grade: FAILED.into(),
            fit: None,
            ..fitted_row()
        };
        assert_eq!(round_trip(&failed), failed);
    }

    #[test]
    fn a_bad_field_is_named() {
        let mut fields = fitted_row().to_csv();
        fields[16] = "x".into();
        let e = Row::from_csv(&csv::StringRecord::from(fields)).unwrap_err();
        assert!(e.to_string().contains("rms_ut"), "{e}");
        let e = Row::from_csv(&csv::StringRecord::from(vec!["a", "b"])).unwrap_err();
        assert!(e.to_string().contains("2 fields"), "{e}");
    }
}
