//! The lot: over the boards of one kind (their `chip`), the median and robust spread of each calibration parameter,
//! and the boards that stand out against it. A board whose offset is normal for its own fit but far from its
//! siblings' is the one with a magnet screw or a steel part beside the sensor: its own fit cannot tell, the lot can.
//!
//! The spread is the median absolute deviation scaled to a normal distribution's standard deviation
//! ([`MAD_TO_SIGMA`]), and a board's robust z for a parameter is its distance from the median in spreads: neither is
//! moved by the outliers themselves, as a mean and a standard deviation would be.

use serde::{Deserialize, Serialize};

use super::row::{LotMark, Row, RowFit};
use crate::verdict::Grade;

/// A board is an outlier when a parameter's robust z exceeds this. In a lot that is a normal population a board's
/// parameter goes beyond 5 spreads once in 1.7 million; over the [`PARAMETERS`] that is one board in about 200,000
/// flagged by chance, so a flagged board is worth looking at. (The usual 3.5 for robust z would flag a board in
/// 250 of a sound lot.) A magnet screw moves the offset by tens of µT, many lot spreads.
pub const OUTLIER_Z: f64 = 5.0;

/// Fewest boards of one kind graded good or usable for the lot to judge outliers: below it the spread is itself too
/// uncertain (about 40 % at 8 boards) to say what is far.
pub const MIN_BOARDS: usize = 10;

/// The median absolute deviation of a normal distribution times this is its standard deviation (1/Φ⁻¹(3/4)).
pub const MAD_TO_SIGMA: f64 = 1.482_602_218_505_602;

/// A parameter the lot compares.
#[derive(Clone, Copy, Debug)]
pub struct Parameter {
    /// Its column's name.
    pub name: &'static str,
    /// Its unit as printed (empty: none).
    pub unit: &'static str,
    /// Its value in a fit's row.
    pub get: fn(&RowFit) -> f64,
}

/// The parameters the lot compares.
pub const PARAMETERS: [Parameter; 8] = [
    Parameter {
        name: "offset_ut.x",
        unit: "µT",
        get: |f| f.offset_ut[0],
    },
    Parameter {
        name: "offset_ut.y",
        unit: "µT",
        get: |f| f.offset_ut[1],
    },
    Parameter {
        name: "offset_ut.z",
        unit: "µT",
        get: |f| f.offset_ut[2],
    },
    Parameter {
        name: "A.xx",
        unit: "",
        get: |f| f.a_diag[0],
    },
    Parameter {
        name: "A.yy",
        unit: "",
        get: |f| f.a_diag[1],
    },
    Parameter {
        name: "A.zz",
        unit: "",
        get: |f| f.a_diag[2],
    },
    Parameter {
        name: "A_offdiag_min",
        unit: "",
        get: |f| f.a_offdiag_min,
    },
    Parameter {
        name: "A_offdiag_max",
        unit: "",
        get: |f| f.a_offdiag_max,
    },
];

/// The boards of one kind.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Lot {
    /// The kind (empty: recordings that name none).
    pub chip: String,
    /// Boards of this kind graded good or usable: those the statistics are over.
    pub boards: usize,
    /// Boards of this kind in the table, fitted or not.
    pub rows: usize,
    /// Whether there were enough boards ([`MIN_BOARDS`]) to judge outliers.
    pub judged: bool,
    /// Each parameter's median and spread over the boards (none without boards).
    pub parameters: Vec<ParameterStats>,
    /// The boards beyond [`OUTLIER_Z`], one entry per parameter.
    pub outliers: Vec<Outlier>,
}

/// One parameter over a lot.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ParameterStats {
    /// The column's name.
    pub name: String,
    /// The median.
    pub median: f64,
    /// The robust spread: [`MAD_TO_SIGMA`] times the median absolute deviation.
    pub spread: f64,
}

/// A board's parameter far from its lot.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Outlier {
    /// The board.
    pub id: String,
    /// Its recording.
    pub file: String,
    /// The parameter's column name.
    pub parameter: String,
    /// The board's value.
    pub value: f64,
    /// Its robust z against the lot.
    pub z: f64,
}

/// The median of `x` (NaN for none); reorders `x`.
pub fn median(x: &mut [f64]) -> f64 {
    if x.is_empty() {
        return f64::NAN;
    }
    x.sort_by(f64::total_cmp);
    let n = x.len();
    if n % 2 == 1 {
        x[n / 2]
    } else {
        0.5 * (x[n / 2 - 1] + x[n / 2])
    }
}

/// The median and robust spread ([`MAD_TO_SIGMA`] × median absolute deviation) of `x`.
pub fn median_spread(x: &[f64]) -> (f64, f64) {
    let mut v = x.to_vec();
    let m = median(&mut v);
    let mut dev: Vec<f64> = x.iter().map(|xi| (xi - m).abs()).collect();
    (m, MAD_TO_SIGMA * median(&mut dev))
}

/// The lots of `rows` (by `chip`, in name order), each board's [`LotMark`] set on its row.
pub fn lots(rows: &mut [Row]) -> Vec<Lot> {
    let mut chips: Vec<String> = rows.iter().map(|r| r.chip.clone()).collect();
    chips.sort();
    chips.dedup();
    chips.into_iter().map(|chip| lot_of(rows, chip)).collect()
}

/// The lot of kind `chip`, its boards' marks set.
fn lot_of(rows: &mut [Row], chip: String) -> Lot {
    let members: Vec<usize> = (0..rows.len()).filter(|&i| rows[i].chip == chip).collect();
    let graded: Vec<&RowFit> = members
        .iter()
        .filter(|&&i| rows[i].meets(Grade::Usable))
        .filter_map(|&i| rows[i].fit.as_ref())
        .collect();
    let boards = graded.len();
    // No boards, no statistics (rather than NaNs).
    let parameters: Vec<ParameterStats> = PARAMETERS
        [..if boards == 0 { 0 } else { PARAMETERS.len() }]
        .iter()
        .map(|p| {
            let values: Vec<f64> = graded.iter().map(|f| (p.get)(f)).collect();
            let (median, spread) = median_spread(&values);
            ParameterStats {
                name: p.name.to_owned(),
                median,
                spread,
            }
        })
        .collect();
    let judged = boards >= MIN_BOARDS;
    let mut outliers = Vec::new();
    for &i in &members {
        let row = &mut rows[i];
        let Some(fit) = &row.fit else {
            row.lot = None;
            continue;
        };
        let mut mark = LotMark {
            z_max: None,
            outliers: Vec::new(),
        };
        if judged {
            for (stats, p) in parameters.iter().zip(&PARAMETERS) {
                if stats.spread.is_nan() || stats.spread <= 0.0 {
                    continue;
                }
                let (name, value) = (p.name, (p.get)(fit));
                let z = (value - stats.median) / stats.spread;
                if mark.z_max.is_none_or(|m: f64| z.abs() > m) {
                    mark.z_max = Some(z.abs());
                }
                if z.abs() > OUTLIER_Z {
                    mark.outliers.push(format!("{name} z={z:+.1}"));
                    outliers.push(Outlier {
                        id: row.id.clone(),
                        file: row.file.clone(),
                        parameter: name.to_owned(),
                        value,
                        z,
                    });
                }
            }
        }
        row.lot = Some(mark);
    }
    Lot {
        chip,
        boards,
        rows: members.len(),
        judged,
        parameters,
        outliers,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::batch::row::FAILED;

    fn board(id: usize, offset_x: f64) -> Row {
        Row {
            id: format!("b{id}"),
            chip: "lis3mdl".into(),
            grade: "good".into(),
            reason: String::new(),
            todo: String::new(),
            fit: Some(RowFit {
                method: "vector".into(),
                left_worst_deg: Some(0.3),
                before_worst_deg: Some(20.0),
                offset_ut: [offset_x, 0.1 * id as f64, -3.0],
                offset_se_ut: [0.01; 3],
                a_diag: [1.0 + 0.001 * id as f64, 1.0, 1.0],
                a_offdiag_min: -0.01,
                a_offdiag_max: 0.01 + 0.0001 * id as f64,
                rms_ut: 0.3,
                noise_floor_ut: 0.3,
                sphere_fraction: 0.9,
                excluded: 0,
                effects: Vec::new(),
                diagnosed: true,
            }),
            lot: None,
            file: format!("b{id}.csv"),
            file_bytes: 1,
            modified_ns: 1,
            fit_options: String::new(),
        }
    }

    #[test]
    fn median_and_spread_are_robust() {
        assert_eq!(median(&mut [3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&mut [4.0, 1.0, 2.0, 3.0]), 2.5);
        assert!(median(&mut []).is_nan());
        let (m, s) = median_spread(&[1.0, 2.0, 3.0, 4.0, 1000.0]);
        assert_eq!(m, 3.0);
        assert!((s - MAD_TO_SIGMA).abs() < 1e-12, "{s}");
    }

    #[test]
    fn the_board_far_from_its_siblings_is_flagged_and_only_it() {
        let mut rows: Vec<Row> = (0..20).map(|i| board(i, 10.0 + (i % 5) as f64)).collect();
        rows[7].fit.as_mut().unwrap().offset_ut[0] = 80.0;
        rows.push(Row {
            grade: FAILED.into(),
            fit: None,
            ..board(99, 0.0)
        });
        let mut other = board(50, 500.0);
        other.chip = "qmc5883l".into();
        rows.push(other);
        let lots = lots(&mut rows);
        assert_eq!(lots.len(), 2);
        let lis = &lots[0];
        assert_eq!(
            (lis.chip.as_str(), lis.boards, lis.rows),
            ("lis3mdl", 20, 21)
        );
        assert!(lis.judged);
        assert_eq!(lis.outliers.len(), 1, "{:?}", lis.outliers);
        assert_eq!(lis.outliers[0].id, "b7");
        assert_eq!(lis.outliers[0].parameter, "offset_ut.x");
        assert!(rows[7].lot.as_ref().unwrap().outliers[0].starts_with("offset_ut.x z=+"));
        assert!(rows[20].lot.is_none());
        let qmc = &lots[1];
        assert!(!qmc.judged && qmc.outliers.is_empty());
        assert_eq!(rows[21].lot.as_ref().unwrap().z_max, None);
    }
}
