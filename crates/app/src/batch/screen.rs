//! What a batch says on screen: the count by grade, each lot's medians and spreads with the boards far from it, and
//! the boards that fall short with the reason — what a production engineer reads before the table.

use std::collections::BTreeMap;
use std::fmt::Write as _;

use super::Batch;
use super::lot::{Lot, MIN_BOARDS, PARAMETERS, Parameter};
use super::row::{FAILED, Row};
use crate::verdict::Grade;

/// The boards of `batch` that fall short of `required` (files not fitted included), in table order.
pub fn falling_short(batch: &Batch, required: Grade) -> Vec<&Row> {
    batch.rows.iter().filter(|r| !r.meets(required)).collect()
}

/// The summary of `batch`; with `required`, the boards below it are listed (else those graded redo or failed).
pub fn summary(batch: &Batch, required: Option<Grade>) -> String {
    let mut out = String::new();
    let count = |grade: &str| batch.rows.iter().filter(|r| r.grade == grade).count();
    let _ = writeln!(
        out,
        "{} recordings ({} fitted now, {} rows kept from the table; {} at a time, {:.1} s): {} good, {} usable, {} \
         redo, {} {FAILED}",
        batch.rows.len(),
        batch.fitted_now,
        batch.kept,
        batch.jobs,
        batch.elapsed_s,
        count("good"),
        count("usable"),
        count("redo"),
        count(FAILED),
    );
    for lot in &batch.lots {
        out.push('\n');
        lot_summary(&mut out, lot, batch.outlier_z);
    }
    let short: Vec<&Row> = match required {
        Some(required) => falling_short(batch, required),
        None => batch
            .rows
            .iter()
            .filter(|r| !r.meets(Grade::Usable))
            .collect(),
    };
    if !short.is_empty() {
        let below = required.map_or("usable".to_owned(), |g| g.name().to_owned());
        let _ = writeln!(out, "\n{} below {below}:", boards(short.len()));
        for row in short {
            let _ = writeln!(
                out,
                "  {} ({}) {}: {}\n    to do: {}",
                row.id, row.file, row.grade, row.reason, row.todo
            );
        }
    }
    let mut ids: BTreeMap<&str, Vec<&str>> = BTreeMap::new();
    for row in &batch.rows {
        ids.entry(&row.id).or_default().push(&row.file);
    }
    for (id, files) in ids.iter().filter(|(_, f)| f.len() > 1) {
        let _ = writeln!(
            out,
            "\nnote: {} recordings name the board {id}: {} (a board recorded twice, or a serial given twice)",
            files.len(),
            files.join(", ")
        );
    }
    out
}

/// `n board` or `n boards`.
fn boards(n: usize) -> String {
    if n == 1 {
        "1 board".to_owned()
    } else {
        format!("{n} boards")
    }
}

/// A lot's medians and spreads, and its outliers.
fn lot_summary(out: &mut String, lot: &Lot, outlier_z: f64) {
    let chip = if lot.chip.is_empty() {
        "of no named chip"
    } else {
        &lot.chip
    };
    let _ = writeln!(
        out,
        "lot {chip}: {} graded good or usable ({} in the table){}",
        boards(lot.boards),
        lot.rows,
        if lot.boards == 0 {
            ""
        } else {
            "; median ± robust spread:"
        }
    );
    if lot.boards == 0 {
        return;
    }
    for (stats, &Parameter { name, unit, .. }) in lot.parameters.iter().zip(&PARAMETERS) {
        let decimals = if unit.is_empty() { 4 } else { 2 };
        let _ = writeln!(
            out,
            "  {name:<14} {:>10.decimals$} ± {:.decimals$}{}{unit}",
            stats.median,
            stats.spread,
            if unit.is_empty() { "" } else { " " },
        );
    }
    if !lot.judged {
        let _ = writeln!(
            out,
            "  too few boards to judge outliers (at least {MIN_BOARDS} graded good or usable)"
        );
    } else if lot.outliers.is_empty() {
        let _ = writeln!(
            out,
            "  no board far from the lot (robust z above {outlier_z})"
        );
    } else {
        let mut ids: Vec<&str> = lot.outliers.iter().map(|o| o.id.as_str()).collect();
        ids.dedup();
        let _ = writeln!(
            out,
            "  {} far from the lot (robust z above {outlier_z}): its own fit may be sound, but the board differs \
             from its siblings — a magnet, a steel screw or a different part near the sensor:",
            boards(ids.len())
        );
        for o in &lot.outliers {
            let Some((stats, &Parameter { unit, .. })) = lot
                .parameters
                .iter()
                .zip(&PARAMETERS)
                .find(|(p, _)| p.name == o.parameter)
            else {
                continue;
            };
            let decimals = if unit.is_empty() { 4 } else { 2 };
            let _ = writeln!(
                out,
                "    {} ({}): {} = {:.decimals$}{}{unit} (lot {:.decimals$} ± {:.decimals$}), z {:+.1}",
                o.id,
                o.file,
                o.parameter,
                o.value,
                if unit.is_empty() { "" } else { " " },
                stats.median,
                stats.spread,
                o.z
            );
        }
    }
}
