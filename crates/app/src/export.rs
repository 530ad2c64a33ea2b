//! Parameters in other tools' conventions (`--export ardupilot|px4|c-header|json`).
//!
//! magcal's model is `B = A·B̂ + b` (µT). The others differ in sign, order and units:
//! - **ArduPilot** corrects `M·(raw + OFS)`, OFS in milligauss added *before* the symmetric matrix
//!   `M = [[DIA_X, ODI_X, ODI_Y], [ODI_X, DIA_Y, ODI_Z], [ODI_Y, ODI_Z, DIA_Z]]`; so `OFS = A⁻¹·b` (= −centre) in
//!   mGauss (1 µT = 10 mGauss).
//! - **PX4** corrects `R·S·(raw − OFF)`, OFF in gauss *subtracted*, `S` symmetric with XSCALE/YSCALE/ZSCALE on the
//!   diagonal and XODIAG (xy), YODIAG (xz), ZODIAG (yz); so `OFF = −A⁻¹·b` (= centre) in gauss (1 µT = 0.01 G).
//!
//! Both matrices are symmetric, and `A` from a vector fit is not (it includes the sensor's misalignment): `A` is split
//! as `A = R·S` (polar decomposition), `S` is exported and the rotation `R` is reported in a comment — set it as the
//! board orientation if it matters. The offsets are exact either way, since `A⁻¹·b = S⁻¹·R⁻¹·b` is what both apply.
//!
//! Readings that are not µT ([`Units`]) are converted with how many of their units make a gauss: ArduPilot's driver
//! gives milligauss and PX4's gauss, each from the chip's counts by its datasheet's sensitivity. With `k` raw units
//! and `c` calibrated units a gauss (both 100 for µT), ArduPilot's `M = (k/c)·S` and `OFS = (1000/k)·A⁻¹·b`, PX4's
//! `S·k/c` and `OFF = −A⁻¹·b/k`. The C header and the JSON carry `A` and `b` as they are, labelled.
//!
//! Every effect the diagnosis found is named in the output with its size and parameters, and why the target does not
//! carry it ([`left_out_lines`]): the same lines go to the terminal ([`crate::howto`]).

use magcal_calib::diagnosis::FoundEffect;
use magcal_calib::{EffectId, Frame, Model};
use nalgebra::{Matrix3, Vector3};

use crate::units::Units;

/// An export format.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum ExportFormat {
    /// ArduPilot `.param` (COMPASS_OFS/DIA/ODI).
    Ardupilot,
    /// PX4 / QGroundControl `.params` (CAL_MAG0_*).
    Px4,
    /// A C header with `A` and `b`.
    CHeader,
    /// JSON with `A`, `b_ut` and the offset.
    Json,
}

/// Where the calibration goes, for saying what it cannot hold.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Holder {
    /// An export format.
    Format(ExportFormat),
    /// A MotionCal-style board written with `--write-to serial:…`.
    Board,
    /// A chip's offset registers written with `--write-to`.
    Chip,
    /// A flight controller's parameters written with `--write-to mavlink:…`.
    Autopilot,
}

impl Holder {
    /// What the target holds.
    fn holds(self) -> &'static str {
        match self {
            Holder::Format(ExportFormat::Ardupilot) => {
                "ArduPilot's COMPASS_* parameters hold an offset (OFS), a symmetric matrix (DIA, ODI) and a field \
                 per amp of the battery current or per throttle (MOT, MOTCT)"
            }
            Holder::Format(ExportFormat::Px4) => {
                "PX4's CAL_MAG0_* parameters hold an offset (OFF), a symmetric matrix (SCALE, ODIAG) and a field \
                 per kA of a battery's current or per throttle (COMP, with CAL_MAG_COMP_TYP)"
            }
            Holder::Format(ExportFormat::CHeader) => "the header holds A and b only",
            Holder::Format(ExportFormat::Json) => "the JSON's A and b_ut are the linear model only",
            Holder::Board => {
                "MotionCal's calibration packet holds an offset, a symmetric matrix and the field magnitude"
            }
            Holder::Chip => "the chip's offset registers hold an offset only",
            Holder::Autopilot => {
                "the autopilot's compass parameters hold an offset, a symmetric matrix and a field per amp of the \
                 battery current (ArduPilot's COMPASS_MOT, PX4's CAL_MAG0_*COMP)"
            }
        }
    }
}

/// Why `holder` does not carry the found effect `e`.
fn why_not(e: &FoundEffect, holder: Holder) -> String {
    let id = e.effect.id();
    let channel = e.channel.as_deref().unwrap_or("the current channel");
    let fitted_without = "these A and b were fitted without it, and the compensation is only right with A and b \
                          fitted with it";
    match (id, holder) {
        _ if id.is_transient() => {
            "an event of this recording, not of the sensor: nothing to carry over".to_owned()
        }
        _ if id.frame() == Frame::Timing => {
            "timing between the magnetometer and the attitude reference, not the sensor's readings: nothing to \
             carry over"
                .to_owned()
        }
        _ if id.frame() == Frame::World => {
            "the world field, not the sensor: nothing to carry over".to_owned()
        }
        (EffectId::CurrentBias, Holder::Format(ExportFormat::Ardupilot)) => format!(
            "not written: COMPASS_MOT_X/Y/Z with COMPASS_MOTCT 2 hold a field per amp of the battery monitor's \
             current (if {channel} is that current), but {fitted_without} (ArduPilot's compassmot, or magcal-record \
             --routine motors and its magcal-fit --export, measures it on the vehicle); the parameters file (--out) \
             keeps it"
        ),
        (EffectId::CurrentBias, Holder::Format(ExportFormat::Px4)) => format!(
            "not written: CAL_MAG0_XCOMP/YCOMP/ZCOMP with CAL_MAG_COMP_TYP current-based hold a field per kA of a \
             battery's current (if {channel} is that current), but {fitted_without} (magcal-record --routine motors \
             and its magcal-fit --export measure it on the vehicle); the parameters file (--out) keeps it"
        ),
        (EffectId::CurrentBias, Holder::Autopilot) => format!(
            "not written: the autopilot's current compensation holds a field per amp of the battery monitor's current \
             (if {channel} is that current), but {fitted_without}; the parameters file (--out) keeps it"
        ),
        _ => "no place for it there; the parameters file (--out) keeps it".to_owned(),
    }
}

/// One line per effect the diagnosis `found` (in the order found), naming it with its size on the recording, what it
/// is, and why `holder` does not carry it: `left out:` for the sensor's corrections, `not a correction:` for the
/// rest. Empty when nothing was found.
pub fn left_out_lines(found: &[FoundEffect], holder: Holder) -> Vec<String> {
    if found.is_empty() {
        return Vec::new();
    }
    let mut lines = vec![format!("what the target holds: {}", holder.holds())];
    for e in found {
        lines.push(format!(
            "{} {}, {:.3} µT RMS per axis on this recording: {}; {}",
            if e.effect.id().is_correction() {
                "left out:"
            } else {
                "not a correction:"
            },
            e.effect.id(),
            e.size_ut,
            e.what,
            why_not(e, holder)
        ));
    }
    lines
}

/// A rotation a symmetric target leaves out is worth a warning above this angle, degrees: the heading error it leaves
/// unless the board's orientation takes it.
const ROTATION_WARN_DEG: f64 = 3.0;

/// Whether `format` holds only a symmetric matrix (the rotation of `A = R·S` is left out).
fn symmetric_only(format: ExportFormat) -> bool {
    matches!(format, ExportFormat::Ardupilot | ExportFormat::Px4)
}

/// Why `model` cannot go to `format` at all: see [`mirror_refusal`]; and for the autopilots, readings whose scale
/// to gauss is not known ([`Units::autopilot_refusal`]).
pub fn refusal(model: &Model, format: ExportFormat, units: &Units) -> Option<String> {
    if symmetric_only(format)
        && let Some(why) = units.autopilot_refusal()
    {
        return Some(why);
    }
    mirror_refusal(model).filter(|_| symmetric_only(format))
}

/// Why `model` cannot go to a target that holds a symmetric matrix (ArduPilot, PX4, a MotionCal-style board): its
/// `A` mirrors the axes (a negative determinant), which neither a symmetric matrix nor a board rotation can hold.
pub fn mirror_refusal(model: &Model) -> Option<String> {
    let det = Matrix3::from_fn(|j, k| model.a[j][k]).determinant();
    (det < 0.0).then(|| {
        "A mirrors the axes (two swapped or one reversed): the target's symmetric matrix cannot undo that, and a \
         board orientation is a rotation. Fix the axis map (the wiring or the driver's), record again and fit that; \
         --export json or c-header carry the whole A"
            .to_owned()
    })
}

/// ArduPilot's default `COMPASS_OFFS_MAX`, mGauss: larger offsets fail its pre-arm check.
const ARDUPILOT_OFFS_MAX_MGAUSS: f64 = 1800.0;

/// What the user must know before loading `model` into `format`: the rotation a symmetric target leaves out, when
/// above [`ROTATION_WARN_DEG`]; ArduPilot's offset limit, when the offsets exceed it.
pub fn warnings(model: &Model, format: ExportFormat, units: &Units) -> Vec<String> {
    let mut out = Vec::new();
    let angle = Polar::of(&model.a).angle_deg();
    if symmetric_only(format) && angle > ROTATION_WARN_DEG {
        out.push(format!(
            "the export leaves out a rotation of {angle:.1}° between the sensor's axes and the attitude \
             reference's (its matrix is symmetric): unless the target's orientation setting (ArduPilot's \
             COMPASS_ORIENT or AHRS_ORIENTATION, PX4's CAL_MAG0_ROT or SENS_BOARD_ROT) takes that rotation, headings \
             will be off by up to {angle:.0}°"
        ));
    }
    if format == ExportFormat::Ardupilot {
        out.extend(ardupilot_offset_limit(model, units));
    }
    out
}

/// Milligauss per unit of the readings (10 for µT), when known.
fn mgauss_per_raw(units: &Units) -> Option<f64> {
    units.per_gauss().map(|(raw, _)| 1000.0 / raw)
}

/// When an offset exceeds ArduPilot's default `COMPASS_OFFS_MAX`, what to do about it.
fn ardupilot_offset_limit(model: &Model, units: &Units) -> Option<String> {
    let per_raw = mgauss_per_raw(units)?;
    let largest_mgauss = per_raw * offset_ut(model).iter().fold(0.0f64, |m, v| m.max(v.abs()));
    (largest_mgauss >= ARDUPILOT_OFFS_MAX_MGAUSS).then(|| {
        format!(
            "an offset of {largest_mgauss:.0} mGauss is beyond ArduPilot's default COMPASS_OFFS_MAX of \
             {ARDUPILOT_OFFS_MAX_MGAUSS:.0}: it refuses to arm (\"Compass offsets too high\") unless that is raised \
             above it — or move the sensor away from what magnetises it"
        )
    })
}

/// The hard-iron offset `−A⁻¹·b` of `model`, in the readings' units (zeros if `A` has no inverse).
fn offset_ut(model: &Model) -> [f64; 3] {
    let a = Matrix3::from_fn(|j, k| model.a[j][k]);
    let c = -(a.try_inverse().unwrap_or_else(Matrix3::zeros) * Vector3::from(model.b_ut));
    [c[0], c[1], c[2]]
}

/// `A = R·S`, `R` a rotation and `S` symmetric positive definite.
pub struct Polar {
    /// The rotation.
    pub rotation: Matrix3<f64>,
    /// The symmetric part.
    pub symmetric: Matrix3<f64>,
}

impl Polar {
    /// The polar decomposition of `a` (via its SVD `U·Σ·Vᵀ`: `R = U·Vᵀ`, `S = V·Σ·Vᵀ`).
    pub fn of(a: &[[f64; 3]; 3]) -> Polar {
        let m = Matrix3::from_fn(|j, k| a[j][k]);
        let svd = m.svd(true, true);
        let (u, v_t) = (svd.u.expect("u requested"), svd.v_t.expect("v_t requested"));
        let rotation = u * v_t;
        let symmetric = v_t.transpose() * Matrix3::from_diagonal(&svd.singular_values) * v_t;
        Polar {
            rotation,
            symmetric,
        }
    }

    /// The rotation's angle, degrees.
    pub fn angle_deg(&self) -> f64 {
        ((self.rotation.trace() - 1.0) / 2.0)
            .clamp(-1.0, 1.0)
            .acos()
            .to_degrees()
    }
}

/// The model in another tool's format. Only the linear part can be exported; body-fixed corrections are counted in a
/// comment (the JSON's `notes`). `found` are the effects the diagnosis found: each is named in comments (the JSON's
/// `left_out`, in full) with why the format does not carry it ([`left_out_lines`]); when `model` has no corrections,
/// its `A` and `b` are taken to be fitted without those of `found` (see [`crate::verdict::target_model`]). `units`
/// are the readings' ([`Units`]): an autopilot's format needs their scale to gauss (see [`refusal`]; without it the
/// µT one is taken).
pub fn export(model: &Model, format: ExportFormat, found: &[FoundEffect], units: &Units) -> String {
    let fitted_without = if model.corrections().count() > 0 {
        0
    } else {
        found
            .iter()
            .filter(|e| e.effect.id().is_correction())
            .count()
    };
    let named = left_out_lines(found, Holder::Format(format));
    let polar = Polar::of(&model.a);
    let dropped = model.corrections().count();
    let mut notes = vec![format!(
        "misalignment rotation of {:.3} deg left out (the target's matrix is symmetric)",
        polar.angle_deg()
    )];
    if dropped > 0 {
        notes.push(format!(
            "{dropped} body-fixed correction(s) left out (the target has no place for them)"
        ));
    } else if fitted_without > 0 {
        notes.push(format!(
            "A and b fitted without the {fitted_without} body-fixed correction(s) the parameters file holds (the \
             target has no place for them)"
        ));
    }
    let corrections_note = (dropped + fitted_without > 0).then(|| notes[1].clone());
    match format {
        ExportFormat::Ardupilot => {
            let mut out = String::from(
                "# magcal calibration for ArduPilot: corrected = M·(raw + OFS), OFS in mGauss\n",
            );
            for n in notes
                .iter()
                .chain(units_comment(units).iter())
                .chain(&named)
                .chain(&ardupilot_offset_limit(model, units))
            {
                out += &format!("# {n}\n");
            }
            out + &ardupilot_values(model, units)
        }
        ExportFormat::Px4 => {
            let mut out = String::from(
                "# magcal calibration for PX4 (QGroundControl .params): corrected = S·(raw − OFF), OFF in gauss\n",
            );
            for n in notes
                .iter()
                .chain(units_comment(units).iter())
                .chain(&named)
            {
                out += &format!("# {n}\n");
            }
            out + &px4_values(model, units)
        }
        ExportFormat::CHeader => c_header(model, units, corrections_note.as_deref(), &named),
        ExportFormat::Json => json(model, format, found, units, corrections_note),
    }
}

/// How the readings were taken to be scaled, for an autopilot's file, when they are not µT.
fn units_comment(units: &Units) -> Option<String> {
    let r = units.raw()?;
    let s = r.scale.as_ref()?;
    Some(format!(
        "the readings were {}, {} a gauss ({}): OFS and the matrix are for the autopilot's driver reading that chip \
         at that setting",
        units.raw_label(),
        s.per_gauss,
        s.source
    ))
}

/// The parameters an autopilot's format holds for `model` (ArduPilot's `COMPASS_OFS_*`, `DIA_*`, `ODI_*` in mGauss
/// and unitless; PX4's `CAL_MAG0_*OFF`, `*SCALE`, `*ODIAG` in gauss and unitless), in the order the export writes
/// them, for readings in `units` ([`Units::per_gauss`], µT's scale without one); the same values the export writes
/// and `--write-to mavlink:…` sets. Empty for the other formats.
pub fn autopilot_params(model: &Model, format: ExportFormat, units: &Units) -> Vec<(String, f64)> {
    let (raw_pg, cal_pg) = units.per_gauss().unwrap_or((100.0, 100.0));
    let s = Polar::of(&model.a).symmetric * (raw_pg / cal_pg);
    let offset = Vector3::from(offset_ut(model));
    let axes = ["X", "Y", "Z"];
    let off_diagonal = [("X", (0, 1)), ("Y", (0, 2)), ("Z", (1, 2))];
    let mut out = Vec::new();
    match format {
        ExportFormat::Ardupilot => {
            let ofs = -offset * (1000.0 / raw_pg);
            for (k, axis) in axes.iter().enumerate() {
                out.push((format!("COMPASS_OFS_{axis}"), ofs[k]));
            }
            for (k, axis) in axes.iter().enumerate() {
                out.push((format!("COMPASS_DIA_{axis}"), s[(k, k)]));
            }
            for (name, (r, c)) in off_diagonal {
                out.push((format!("COMPASS_ODI_{name}"), s[(r, c)]));
            }
        }
        ExportFormat::Px4 => {
            let centre = offset / raw_pg;
            for (k, axis) in axes.iter().enumerate() {
                out.push((format!("CAL_MAG0_{axis}OFF"), centre[k]));
            }
            for (k, axis) in axes.iter().enumerate() {
                out.push((format!("CAL_MAG0_{axis}SCALE"), s[(k, k)]));
            }
            for (name, (r, c)) in off_diagonal {
                out.push((format!("CAL_MAG0_{name}ODIAG"), s[(r, c)]));
            }
        }
        ExportFormat::CHeader | ExportFormat::Json => {}
    }
    out
}

/// An autopilot's motor compensation of the current term `k_ut_per_a` of a bench motor test (`current_bias`'s
/// coefficients in µT/A, in the field calibrated by `a`, the calibration's `A`; the identity for readings as
/// recorded), as the parameters the autopilot adds per amp of its battery current:
/// - ArduPilot adds `COMPASS_MOT·I` (mGauss/A) after its matrix, to the calibrated field: `MOT = −10·k`, with
///   `COMPASS_MOTCT` 2 (the battery current);
/// - PX4 adds `I/1000·CAL_MAG0_*COMP` (gauss/kA) to the raw readings, before its offset and matrix:
///   `COMP = −10·A⁻¹·k`, with `CAL_MAG_COMP_TYP` 2 (the first battery's current).
///
/// An error for the formats that hold `A` and `b` only, and for an `A` without an inverse.
pub fn current_params(
    format: ExportFormat,
    k_ut_per_a: [f64; 3],
    a: &[[f64; 3]; 3],
) -> Result<Vec<(String, f64)>, String> {
    let k = Vector3::from(k_ut_per_a);
    let axes = ["X", "Y", "Z"];
    match format {
        ExportFormat::Ardupilot => {
            let mot = -10.0 * k;
            let mut out: Vec<(String, f64)> = axes
                .iter()
                .enumerate()
                .map(|(j, axis)| (format!("COMPASS_MOT_{axis}"), mot[j]))
                .collect();
            out.push(("COMPASS_MOTCT".to_owned(), 2.0));
            Ok(out)
        }
        ExportFormat::Px4 => {
            let a_inv = Matrix3::from_fn(|j, c| a[j][c])
                .try_inverse()
                .ok_or("the calibration's A has no inverse")?;
            let comp = -10.0 * a_inv * k;
            let mut out: Vec<(String, f64)> = axes
                .iter()
                .enumerate()
                .map(|(j, axis)| (format!("CAL_MAG0_{axis}COMP"), comp[j]))
                .collect();
            out.push(("CAL_MAG_COMP_TYP".to_owned(), 2.0));
            Ok(out)
        }
        ExportFormat::CHeader | ExportFormat::Json => Err(format!(
            "the {} export holds A and b only; the report (--report) holds the current term",
            match format {
                ExportFormat::CHeader => "c-header",
                _ => "json",
            }
        )),
    }
}

/// The motor compensation of [`current_params`] as the format's file: ArduPilot's `.param` lines, PX4's
/// QGroundControl lines (the type an integer).
pub fn current_export(
    format: ExportFormat,
    k_ut_per_a: [f64; 3],
    a: &[[f64; 3]; 3],
) -> Result<String, String> {
    let params = current_params(format, k_ut_per_a, a)?;
    let mut out = String::from(
        "# magcal bench motor test: the motor compensation per amp of the battery current (the calibration's other \
         parameters are left as they are)\n",
    );
    if format == ExportFormat::Px4 {
        out += "# Vehicle-Id\tComponent-Id\tName\tValue\tType\n";
    }
    for (name, v) in params {
        let integer = name == "COMPASS_MOTCT" || name == "CAL_MAG_COMP_TYP";
        out += &match (format, integer) {
            (ExportFormat::Px4, true) => format!("1\t1\t{name}\t{v:.0}\t6\n"),
            (ExportFormat::Px4, false) => format!("1\t1\t{name}\t{v:.9}\t9\n"),
            (_, true) => format!("{name},{v:.0}\n"),
            (_, false) => format!("{name},{v:.6}\n"),
        };
    }
    Ok(out)
}

/// ArduPilot's COMPASS_OFS, DIA and ODI lines ([`autopilot_params`]): offsets to 3 decimals of a mGauss, the matrix
/// to 6.
fn ardupilot_values(model: &Model, units: &Units) -> String {
    autopilot_params(model, ExportFormat::Ardupilot, units)
        .into_iter()
        .map(|(name, v)| {
            if name.starts_with("COMPASS_OFS") {
                format!("{name},{v:.3}\n")
            } else {
                format!("{name},{v:.6}\n")
            }
        })
        .collect()
}

/// PX4's CAL_MAG0 lines (QGroundControl's format, [`autopilot_params`]).
fn px4_values(model: &Model, units: &Units) -> String {
    let mut out = String::from("# Vehicle-Id\tComponent-Id\tName\tValue\tType\n");
    for (name, v) in autopilot_params(model, ExportFormat::Px4, units) {
        out += &format!("1\t1\t{name}\t{v:.9}\t9\n");
    }
    out
}

/// The name of `b` in the C header: `MAGCAL_B_UT`, or `MAGCAL_B` when the calibrated field is in the readings' own
/// units (no field magnitude was known).
pub fn c_b_name(units: &Units) -> &'static str {
    if units.calibrated_ut() {
        "MAGCAL_B_UT"
    } else {
        "MAGCAL_B"
    }
}

/// The C header: `A` and `b`, with what `raw` and `B` are in.
fn c_header(model: &Model, units: &Units, corrections: Option<&str>, named: &[String]) -> String {
    let what = match units.raw() {
        None => "microtesla".to_owned(),
        Some(_) if units.calibrated_ut() => format!(
            "B in microtesla; raw: the readings as recorded, in {}",
            units.raw_label()
        ),
        Some(_) => format!(
            "B and raw in the readings' own units, {}: no field magnitude was given, so the scale is theirs (a \
             heading needs only the direction)",
            units.raw_label()
        ),
    };
    let mut out = format!(
        "/* magcal calibration: B = A * raw + b ({what}, sensor axes). */\n#ifndef MAGCAL_CALIBRATION_H\n#define \
         MAGCAL_CALIBRATION_H\n\n"
    );
    if let Some(n) = corrections {
        out += &format!("/* {n} */\n");
    }
    for n in named {
        out += &format!("/* {} */\n", n.replace("*/", "* /"));
    }
    out += "static const float MAGCAL_A[3][3] = {\n";
    for row in &model.a {
        out += &format!(
            "    {{ {:.9}f, {:.9}f, {:.9}f }},\n",
            row[0], row[1], row[2]
        );
    }
    let b = model.b_ut;
    out += &format!(
        "}};\nstatic const float {}[3] = {{ {:.6}f, {:.6}f, {:.6}f }};\n\n",
        c_b_name(units),
        b[0],
        b[1],
        b[2]
    );
    out += "#endif /* MAGCAL_CALIBRATION_H */\n";
    out
}

/// The JSON export: `A`, `b_ut` and `offset_ut` in µT readings; for readings in other units, `b_ut` when the
/// calibrated field is µT (else `b_raw`), `offset_raw` in the readings' units and `raw_units` saying what they are.
fn json(
    model: &Model,
    format: ExportFormat,
    found: &[FoundEffect],
    units: &Units,
    corrections: Option<String>,
) -> String {
    let centre = offset_ut(model);
    let mut value = serde_json::json!({
        "model": "B = A*raw + b (uT, sensor axes)",
        "A": model.a,
        "notes": corrections.into_iter().collect::<Vec<_>>(),
        "target_holds": Holder::Format(format).holds(),
        "left_out": found.iter().map(|e| serde_json::json!({
            "id": e.effect.id().as_str(),
            "correction": e.effect.id().is_correction(),
            "size_ut": e.size_ut,
            "params": crate::report::params_json(e),
            "what": e.what,
            "why": why_not(e, Holder::Format(format)),
        })).collect::<Vec<_>>(),
    });
    let map = value.as_object_mut().expect("an object");
    let b = serde_json::json!(model.b_ut);
    match units.raw() {
        None => {
            map.insert("b_ut".into(), b);
            map.insert("offset_ut".into(), serde_json::json!(centre));
        }
        Some(r) => {
            let calibrated = units.calibrated_label();
            map.insert(
                "model".into(),
                format!(
                    "B = A*raw + b (B in {calibrated}, raw in {}, sensor axes)",
                    units.raw_label()
                )
                .into(),
            );
            map.insert(
                if units.calibrated_ut() {
                    "b_ut"
                } else {
                    "b_raw"
                }
                .into(),
                b,
            );
            map.insert("offset_raw".into(), serde_json::json!(centre));
            map.insert(
                "raw_units".into(),
                serde_json::json!({
                    "unit": units.raw_label(),
                    "radius": r.radius,
                    "per_gauss": r.scale.as_ref().map(|s| s.per_gauss),
                    "source": r.scale.as_ref().map(|s| s.source.clone()),
                    "calibrated": calibrated,
                }),
            );
        }
    }
    serde_json::to_string_pretty(&value).expect("plain data") + "\n"
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    fn value(text: &str, name: &str) -> f64 {
        text.lines()
            .find_map(|l| {
                let f: Vec<&str> = l.split([',', '\t']).collect();
                f.iter()
                    .position(|x| *x == name)
                    .map(|i| f[i + 1].parse().unwrap())
            })
            .unwrap_or_else(|| panic!("{name} not in\n{text}"))
    }

    fn skewed_model() -> (Model, Matrix3<f64>) {
        let s = Matrix3::new(1.1, 0.02, -0.01, 0.02, 0.95, 0.03, -0.01, 0.03, 1.05);
        let r = nalgebra::Rotation3::from_euler_angles(0.02, -0.01, 0.03).into_inner();
        let a = r * s;
        (
            Model::linear(
                std::array::from_fn(|j| std::array::from_fn(|k| a[(j, k)])),
                [12.0, -7.0, 30.0],
            ),
            s,
        )
    }

    /// Each format's own correction of a raw reading must give our calibrated field (up to the dropped rotation).
    #[test]
    fn ardupilot_and_px4_reproduce_our_correction_in_their_convention() {
        let (model, s) = skewed_model();
        let raw = Vector3::new(25.0, -40.0, 10.0);
        let ours = {
            let b = model.apply([raw.x, raw.y, raw.z], &magcal_calib::Inputs::NONE);
            Polar::of(&model.a).rotation.transpose() * Vector3::from(b)
        };
        let ap = export(&model, ExportFormat::Ardupilot, &[], &Units::Microtesla);
        let ofs = Vector3::new(
            value(&ap, "COMPASS_OFS_X"),
            value(&ap, "COMPASS_OFS_Y"),
            value(&ap, "COMPASS_OFS_Z"),
        );
        let m = Matrix3::new(
            value(&ap, "COMPASS_DIA_X"),
            value(&ap, "COMPASS_ODI_X"),
            value(&ap, "COMPASS_ODI_Y"),
            value(&ap, "COMPASS_ODI_X"),
            value(&ap, "COMPASS_DIA_Y"),
            value(&ap, "COMPASS_ODI_Z"),
            value(&ap, "COMPASS_ODI_Y"),
            value(&ap, "COMPASS_ODI_Z"),
            value(&ap, "COMPASS_DIA_Z"),
        );
        let ap_mg = m * (raw * 10.0 + ofs);
        assert!((ap_mg / 10.0 - ours).norm() < 1e-3, "{ap_mg} vs {ours}");
        assert!((m - s).norm() < 1e-5);

        let px = export(&model, ExportFormat::Px4, &[], &Units::Microtesla);
        let off = Vector3::new(
            value(&px, "CAL_MAG0_XOFF"),
            value(&px, "CAL_MAG0_YOFF"),
            value(&px, "CAL_MAG0_ZOFF"),
        );
        let sp = Matrix3::new(
            value(&px, "CAL_MAG0_XSCALE"),
            value(&px, "CAL_MAG0_XODIAG"),
            value(&px, "CAL_MAG0_YODIAG"),
            value(&px, "CAL_MAG0_XODIAG"),
            value(&px, "CAL_MAG0_YSCALE"),
            value(&px, "CAL_MAG0_ZODIAG"),
            value(&px, "CAL_MAG0_YODIAG"),
            value(&px, "CAL_MAG0_ZODIAG"),
            value(&px, "CAL_MAG0_ZSCALE"),
        );
        let px_g = sp * (raw / 100.0 - off);
        assert!((px_g * 100.0 - ours).norm() < 1e-4, "{px_g} vs {ours}");
        assert!(px.contains("misalignment rotation of"));
    }

    /// A current term through each autopilot's formula gives back the field it compensates.
    #[test]
    fn the_motor_compensation_cancels_the_current_term() {
        let k = [0.3, -0.05, 1.0];
        let a = [[1.1, 0.02, 0.0], [0.02, 0.95, 0.01], [0.0, 0.01, 1.03]];
        let value = |p: &[(String, f64)], n: &str| p.iter().find(|(m, _)| m == n).unwrap().1;
        let ap = current_params(ExportFormat::Ardupilot, k, &a).unwrap();
        assert_eq!(value(&ap, "COMPASS_MOTCT"), 2.0);
        // ArduPilot adds MOT·I (mGauss) to the calibrated field, in which the current adds 10·k·I mGauss.
        for (j, axis) in ["X", "Y", "Z"].iter().enumerate() {
            assert!((value(&ap, &format!("COMPASS_MOT_{axis}")) + 10.0 * k[j]).abs() < 1e-12);
        }
        // PX4 adds I/1000·COMP (gauss) to the raw readings, in which the current adds A⁻¹·k·I/100 gauss.
        let px4 = current_params(ExportFormat::Px4, k, &a).unwrap();
        assert_eq!(value(&px4, "CAL_MAG_COMP_TYP"), 2.0);
        let comp = Vector3::new(
            value(&px4, "CAL_MAG0_XCOMP"),
            value(&px4, "CAL_MAG0_YCOMP"),
            value(&px4, "CAL_MAG0_ZCOMP"),
        );
        let raw_g_per_a = Matrix3::from_fn(|j, c| a[j][c]) * (comp / -1000.0) * 100.0;
        assert!(
            (raw_g_per_a - Vector3::from(k)).norm() < 1e-12,
            "{raw_g_per_a}"
        );
        let text = current_export(ExportFormat::Px4, k, &a).unwrap();
        assert!(text.contains("1\t1\tCAL_MAG_COMP_TYP\t2\t6\n"), "{text}");
        assert!(
            current_export(ExportFormat::Ardupilot, k, &a)
                .unwrap()
                .contains("COMPASS_MOT_Z,-10.000000\nCOMPASS_MOTCT,2\n")
        );
        assert!(current_params(ExportFormat::CHeader, k, &a).is_err());
    }

    #[test]
    fn polar_decomposition_recovers_the_parts() {
        let (model, s) = skewed_model();
        let p = Polar::of(&model.a);
        assert!((p.symmetric - s).norm() < 1e-12);
        assert!((p.rotation.determinant() - 1.0).abs() < 1e-12);
        assert!(
            p.angle_deg() > 1.0 && p.angle_deg() < 3.0,
            "{}",
            p.angle_deg()
        );
    }

    /// A found effect with only what the export reads.
    fn found(effect: magcal_calib::Effect, channel: Option<&str>, size_ut: f64) -> FoundEffect {
        FoundEffect {
            effect,
            channel: channel.map(str::to_owned),
            params: Vec::new(),
            rms_before_ut: 0.0,
            rms_after_ut: 0.0,
            holdout_rms_before_ut: 0.0,
            holdout_rms_after_ut: 0.0,
            evidence: 0.0,
            size_ut,
            what: format!("what {}", effect.id()),
            explanation: String::new(),
        }
    }

    /// A temperature bias and a current bias (corrections) and a time lag (not one).
    pub(crate) fn three_found() -> Vec<FoundEffect> {
        use magcal_calib::Effect;
        vec![
            found(
                Effect::TemperatureBias {
                    coef_ut_per_c: [0.01, 0.0, 0.0],
                    t_ref_c: 20.0,
                },
                None,
                0.163,
            ),
            found(
                Effect::CurrentBias {
                    channel: 0,
                    coef_ut_per_a: [0.2, 0.0, 0.0],
                },
                Some("i_motor"),
                0.171,
            ),
            found(Effect::TimeLag { lag_s: 0.012 }, None, 0.118),
        ]
    }

    #[test]
    fn the_c_header_and_json_carry_a_and_b() {
        let (model, _) = skewed_model();
        let h = export(
            &model,
            ExportFormat::CHeader,
            &three_found(),
            &Units::Microtesla,
        );
        assert!(h.contains("MAGCAL_A[3][3]") && h.contains("12.000000f"));
        assert!(
            h.contains("fitted without the 2 body-fixed correction(s)"),
            "{h}"
        );
        assert!(
            h.contains(
                "/* left out: temperature_bias, 0.163 µT RMS per axis on this recording: what temperature_bias; no place"
            ),
            "{h}"
        );
        let j: serde_json::Value =
            serde_json::from_str(&export(&model, ExportFormat::Json, &[], &Units::Microtesla))
                .unwrap();
        assert_eq!(j["b_ut"][2].as_f64(), Some(30.0));
        assert_eq!(j["left_out"].as_array().map(Vec::len), Some(0));
    }

    /// Each format names every effect found with its size, says what it holds, and claims to hold none of them.
    #[test]
    fn every_format_names_what_it_leaves_out() {
        let (model, _) = skewed_model();
        let found = three_found();
        for format in [
            ExportFormat::Ardupilot,
            ExportFormat::Px4,
            ExportFormat::CHeader,
            ExportFormat::Json,
        ] {
            let text = export(&model, format, &found, &Units::Microtesla);
            for line in [
                "left out: temperature_bias, 0.163 µT RMS per axis on this recording: what temperature_bias",
                "left out: current_bias, 0.171 µT RMS per axis on this recording: what current_bias",
                "not a correction: time_lag, 0.118 µT RMS per axis on this recording: what time_lag; timing",
            ] {
                assert_eq!(
                    text.contains(line),
                    format != ExportFormat::Json,
                    "{format:?}: {line}\n{text}"
                );
            }
            assert!(!text.contains("COMPASS_MOT_X,") && !text.contains("\tCAL_MAG0_XCOMP\t"));
        }
        let ap = export(&model, ExportFormat::Ardupilot, &found, &Units::Microtesla);
        assert!(
            ap.contains("# what the target holds: ArduPilot's COMPASS_*"),
            "{ap}"
        );
        assert!(ap.contains("not written: COMPASS_MOT_X/Y/Z"), "{ap}");
        let j: serde_json::Value = serde_json::from_str(&export(
            &model,
            ExportFormat::Json,
            &found,
            &Units::Microtesla,
        ))
        .unwrap();
        let left = j["left_out"].as_array().unwrap();
        assert_eq!(left.len(), 3);
        assert_eq!(left[1]["id"], "current_bias");
        assert_eq!(left[1]["size_ut"].as_f64(), Some(0.171));
        assert_eq!(left[1]["correction"], true);
        assert_eq!(left[2]["correction"], false);
        assert!(
            j["target_holds"]
                .as_str()
                .unwrap()
                .contains("linear model only")
        );
    }
}
