//! `--plots DIR`: SVG pictures to look at.
//!
//! - `readings.svg` — the raw readings in three projections with the fitted ellipsoid's outline, and the calibrated
//!   ones on the sphere of |B|: what the calibration did. Written even when the fit is refused (raw only), so a
//!   recording that does not turn enough can be seen.
//! - `heading.svg` — the heading error against heading, with the raw readings and what the calibration leaves
//!   ([`crate::heading`]).
//! - `residual_time.svg` — the residual against time, with the noise floor, the spans where the diagnosis located
//!   the misfit and the events it found (steps, disturbances).
//! - `residual_orientation.svg` — the residual over the directions of the field in sensor axes, with a colour bar.
//! - `residual_channel.svg` (diagnosis) — the residual against the channel it is blamed on.
//!
//! Every axis carries its unit; legends sit in a strip above the data, never on it. Each file is drawn in memory and
//! written atomically, so a link in the folder is replaced, never written through.

use std::path::{Path, PathBuf};

use anyhow::Context;
use magcal_calib::diagnosis::{Components, Diagnosis, Verdict as Finding};
use magcal_calib::effects::{Effect, Frame, Need};
use magcal_calib::frames;
use magcal_recording::Recording;
use nalgebra::{Matrix2, Matrix3};
use plotters::coord::Shift;
use plotters::element::DashedPathElement;
use plotters::prelude::*;

use crate::files::write_atomic;
use crate::fit::{Calibration, Fit};
use crate::heading::{Face, HeadingErrors};
use crate::readings::calibrate_rows;
use crate::readings::expected_field;
use crate::verdict::Assessment;

/// Time bins of the residual-against-time plot.
const TIME_BINS: usize = 400;
/// Most points drawn in a scatter plot (each is an SVG element: this keeps a file well under a megabyte).
const SCATTER_POINTS: usize = 1000;
/// Most points drawn in one projection of the readings.
const PROJECTION_POINTS: usize = 700;
/// Bins of the binned means drawn over a scatter plot.
const CHANNEL_BINS: usize = 24;
/// Fewest samples for a cell of the orientation map to be drawn.
const MIN_CELL_SAMPLES: usize = 5;
/// Height of the legend strip above a chart, pixels.
const LEGEND_PX: u32 = 34;
/// Side of a projection panel's square plotting area, pixels.
const PANEL_PX: u32 = 250;

type PlotResult<T> = Result<T, Box<dyn std::error::Error>>;
type Area<'a> = DrawingArea<SVGBackend<'a>, Shift>;

/// Colours used throughout.
const BEFORE: RGBColor = RGBColor(214, 39, 40);
const AFTER: RGBColor = RGBColor(31, 119, 180);
const POINTS: RGBColor = RGBColor(31, 119, 180);
const OUTLINE: RGBColor = RGBColor(214, 39, 40);
const SPAN: RGBColor = RGBColor(255, 187, 120);
const EVENT: RGBColor = RGBColor(148, 103, 189);
const GREY: RGBColor = RGBColor(90, 90, 90);
/// A map's cell the field never pointed through.
const UNVISITED: RGBColor = RGBColor(228, 228, 228);

/// The files `--plots` may write, in the folder it names (each through [`crate::outputs`] first).
pub const PLOT_FILES: [&str; 5] = [
    "readings.svg",
    "heading.svg",
    "residual_time.svg",
    "residual_orientation.svg",
    "residual_channel.svg",
];

/// Writes the plots of a calibration of `rec` into `dir` (created if needed) and returns their paths.
pub fn write_plots(
    dir: &Path,
    cal: &Calibration,
    rec: &Recording,
    assessment: &Assessment,
) -> anyhow::Result<Vec<PathBuf>> {
    let mut plots = Plots::new(dir)?;
    plots.plot("readings.svg", &|p| readings(p, rec, Some(cal)))?;
    if let Some(h) = &assessment.heading {
        plots.plot("heading.svg", &|p| heading(p, h))?;
    }
    let series = Series::of(cal, rec);
    if series.t_s.iter().any(|t| *t != series.t_s[0]) {
        plots.plot("residual_time.svg", &|p| residual_time(p, &series))?;
    }
    plots.plot("residual_orientation.svg", &|p| {
        residual_orientation(p, &series)
    })?;
    if let Some(d) = &cal.diagnosis
        && let Some((name, values)) = blamed_channel(d)
    {
        plots.plot("residual_channel.svg", &|p| {
            residual_channel(p, d, name, values)
        })?;
    }
    Ok(plots.written)
}

/// The plots [`write_plots`] leaves out for this calibration, each with why (`heading.svg` without the local field's
/// direction, the time plot without time, the channel plot without a channel the residual is blamed on).
pub fn not_written(cal: &Calibration, rec: &Recording, assessment: &Assessment) -> Vec<String> {
    let mut out = Vec::new();
    if assessment.heading.is_none() {
        out.push(
            "heading.svg not written: the heading error needs the local field's direction (give --location \
             LAT,LON,ALT --date YYYY-MM-DD, or --field-ned N,E,D)"
                .to_owned(),
        );
    }
    if rec
        .t_s
        .as_ref()
        .is_none_or(|t| t.iter().all(|v| *v == t[0]))
    {
        out.push("residual_time.svg not written: the recording has no time column".to_owned());
    }
    if let Some(d) = &cal.diagnosis
        && blamed_channel(d).is_none()
    {
        out.push(
            "residual_channel.svg not written: the residual follows no channel (temperature, a current, time, \
             the field's rate of change) and no effect found depends on one"
                .to_owned(),
        );
    }
    out
}

/// Writes `readings.svg` with the raw readings only (for a recording the fit refused).
pub fn write_readings_plot(dir: &Path, rec: &Recording) -> anyhow::Result<PathBuf> {
    let mut plots = Plots::new(dir)?;
    plots.plot("readings.svg", &|p| readings(p, rec, None))?;
    Ok(plots.written.remove(0))
}

/// The output directory and what was written to it.
struct Plots<'a> {
    dir: &'a Path,
    written: Vec<PathBuf>,
}

impl<'a> Plots<'a> {
    fn new(dir: &'a Path) -> anyhow::Result<Plots<'a>> {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        Ok(Plots {
            dir,
            written: Vec::new(),
        })
    }

    /// Draws a plot and writes it to `name` in the folder atomically (never through a link there).
    fn plot(
        &mut self,
        name: &str,
        draw: &dyn Fn(&mut String) -> PlotResult<()>,
    ) -> anyhow::Result<()> {
        debug_assert!(PLOT_FILES.contains(&name), "{name} is not in PLOT_FILES");
        let path = self.dir.join(name);
        let mut svg = String::new();
        draw(&mut svg).map_err(|e| anyhow::anyhow!("drawing {}: {e}", path.display()))?;
        write_atomic(&path, svg.as_bytes())
            .with_context(|| format!("writing {}", path.display()))?;
        self.written.push(path);
        Ok(())
    }
}

/// How a legend entry is drawn.
#[derive(Clone, Copy)]
enum Mark {
    Line(RGBColor, u32),
    Dashed(RGBColor),
    Dot(RGBColor),
    Patch(RGBColor),
    /// A map's cell: a solid patch with a thin border.
    Cell(RGBColor),
    /// No mark: a note beside the entries.
    Note,
}

/// Width of a legend entry, pixels (14 px sans-serif averages under 7 px a character).
fn entry_px(label: &str) -> i32 {
    30 + 7 * label.chars().count() as i32 + 24
}

/// Height of the strip a legend of `entries` needs in `width` pixels.
fn legend_px(entries: &[(Mark, String)], width: u32) -> u32 {
    let mut rows = 1;
    let mut x = 60;
    for (_, label) in entries {
        if x + entry_px(label) > width as i32 && x > 60 {
            rows += 1;
            x = 60;
        }
        x += entry_px(label);
    }
    LEGEND_PX + (rows - 1) * 20
}

/// A legend in its own strip above the chart: marks and labels side by side, wrapped to the strip's width.
fn legend(area: &Area<'_>, entries: &[(Mark, String)]) -> PlotResult<()> {
    let width = area.dim_in_pixel().0 as i32;
    let mut y = (LEGEND_PX / 2) as i32;
    let mut x = 60i32;
    let style = ("sans-serif", 14).into_font().color(&BLACK);
    for (mark, label) in entries {
        if x + entry_px(label) > width && x > 60 {
            x = 60;
            y += 20;
        }
        match *mark {
            Mark::Line(c, w) => {
                area.draw(&PathElement::new(
                    vec![(x, y), (x + 24, y)],
                    c.stroke_width(w),
                ))?;
            }
            Mark::Dashed(c) => {
                area.draw(&DashedPathElement::new(
                    vec![(x, y), (x + 24, y)],
                    5,
                    3,
                    c.stroke_width(2),
                ))?;
            }
            Mark::Dot(c) => area.draw(&Circle::new((x + 12, y), 3, c.filled()))?,
            Mark::Patch(c) => {
                area.draw(&Rectangle::new(
                    [(x, y - 6), (x + 24, y + 6)],
                    c.mix(0.5).filled(),
                ))?;
            }
            Mark::Cell(c) => {
                area.draw(&Rectangle::new([(x, y - 6), (x + 24, y + 6)], c.filled()))?;
                area.draw(&Rectangle::new(
                    [(x, y - 6), (x + 24, y + 6)],
                    GREY.stroke_width(1),
                ))?;
            }
            Mark::Note => {}
        }
        area.draw_text(label, &style, (x + 30, y - 7))?;
        x += entry_px(label);
    }
    Ok(())
}

/// The root area split into a legend strip (drawn) and the rest.
fn with_legend<'a>(root: &Area<'a>, entries: &[(Mark, String)]) -> PlotResult<Area<'a>> {
    root.fill(&WHITE)?;
    let (strip, body) = root.split_vertically(legend_px(entries, root.dim_in_pixel().0));
    legend(&strip, entries)?;
    Ok(body)
}

/// Ranges for a plotting area of `px` pixels so that one µT is as long on both axes.
fn equal_ranges(
    centre: (f64, f64),
    half: f64,
    px: (u32, u32),
) -> (std::ops::Range<f64>, std::ops::Range<f64>) {
    let per_px = 2.0 * half / f64::from(px.0.min(px.1).max(1));
    let (hx, hy) = (
        per_px * f64::from(px.0) / 2.0,
        per_px * f64::from(px.1) / 2.0,
    );
    (centre.0 - hx..centre.0 + hx, centre.1 - hy..centre.1 + hy)
}

/// Samples of at most `max` elements.
fn thin<T: Copy>(v: &[T], max: usize) -> Vec<T> {
    v.iter().step_by((v.len() / max).max(1)).copied().collect()
}

/// The projection planes: axis pairs and their names.
const PLANES: [(usize, usize, &str, &str); 3] =
    [(0, 1, "x", "y"), (0, 2, "x", "z"), (1, 2, "y", "z")];

/// One projection panel: points, an outline, equal scales; the axes named and in `unit`.
fn projection(
    area: &Area<'_>,
    title: &str,
    points: &[(f64, f64)],
    outline: &[(f64, f64)],
    axes: (&str, &str),
    unit: &str,
) -> PlotResult<()> {
    let area = area.titled(title, ("sans-serif", 15))?;
    let all = points.iter().chain(outline);
    let (mut lo, mut hi) = (
        (f64::INFINITY, f64::INFINITY),
        (f64::NEG_INFINITY, f64::NEG_INFINITY),
    );
    for p in all {
        lo = (lo.0.min(p.0), lo.1.min(p.1));
        hi = (hi.0.max(p.0), hi.1.max(p.1));
    }
    let centre = ((lo.0 + hi.0) / 2.0, (lo.1 + hi.1) / 2.0);
    let half = ((hi.0 - lo.0).max(hi.1 - lo.1) / 2.0 * 1.08).max(1e-6);
    let build = |x: std::ops::Range<f64>, y: std::ops::Range<f64>| {
        ChartBuilder::on(&area)
            .margin(8)
            .x_label_area_size(36)
            .y_label_area_size(56)
            .build_cartesian_2d(x, y)
    };
    let px = build(0.0..1.0, 0.0..1.0)?.plotting_area().dim_in_pixel();
    let (x, y) = equal_ranges(centre, half, px);
    let mut chart = build(x, y)?;
    chart
        .configure_mesh()
        .light_line_style(TRANSPARENT)
        .x_desc(format!("{} ({unit})", axes.0))
        .y_desc(format!("{} ({unit})", axes.1))
        .x_labels(5)
        .y_labels(5)
        .draw()?;
    chart.draw_series(
        points
            .iter()
            .map(|p| Circle::new(*p, 1, POINTS.mix(0.35).filled())),
    )?;
    if !outline.is_empty() {
        let mut closed = outline.to_vec();
        closed.push(outline[0]);
        chart.draw_series(LineSeries::new(closed, OUTLINE.stroke_width(2)))?;
    }
    Ok(())
}

/// The outline of the ellipsoid `{m : |A·m + b| = F}` projected on the plane of axes `(i, j)`: its shadow's edge.
fn ellipsoid_shadow(
    a: &[[f64; 3]; 3],
    b: [f64; 3],
    field_ut: f64,
    (i, j): (usize, usize),
) -> Vec<(f64, f64)> {
    let Some(inv) = Matrix3::from_fn(|r, c| a[r][c]).try_inverse() else {
        return Vec::new();
    };
    let centre = magcal_calib::scalar::centre(a, b);
    // The points centre + F·A⁻¹·u, |u| = 1, project onto the ellipse whose matrix is P·A⁻¹·A⁻ᵀ·Pᵀ.
    let m = Matrix2::new(
        inv.row(i).dot(&inv.row(i)),
        inv.row(i).dot(&inv.row(j)),
        inv.row(j).dot(&inv.row(i)),
        inv.row(j).dot(&inv.row(j)),
    );
    let Some(l) = m.cholesky().map(|c| c.l()) else {
        return Vec::new();
    };
    (0..120)
        .map(|k| {
            let t = k as f64 / 120.0 * std::f64::consts::TAU;
            let (s, c) = t.sin_cos();
            (
                centre[i] + field_ut * (l[(0, 0)] * c + l[(0, 1)] * s),
                centre[j] + field_ut * (l[(1, 0)] * c + l[(1, 1)] * s),
            )
        })
        .collect()
}

/// `readings.svg`: raw readings (top) and calibrated ones (bottom), three projections each.
fn readings(svg: &mut String, rec: &Recording, cal: Option<&Calibration>) -> PlotResult<()> {
    let panel_w = PANEL_PX + 56 + 16;
    let panel_h = PANEL_PX + 36 + 16 + 24;
    let rows = if cal.is_some() { 2 } else { 1 };
    let root =
        SVGBackend::with_string(svg, (3 * panel_w, LEGEND_PX + rows * panel_h)).into_drawing_area();
    let raw = thin(&rec.mag_ut, PROJECTION_POINTS);
    let field_ut = cal.map(|c| {
        c.fit
            .face()
            .magnitude_ut()
            .or(c.field.magnitude())
            .unwrap_or(f64::NAN)
    });
    // The readings' unit and the calibrated field's: µT, or raw units (crate::units).
    let (raw_unit, cal_unit) = cal.map_or(("µT".to_owned(), "µT".to_owned()), |c| {
        (c.units.raw_label(), c.units.calibrated_label())
    });
    let mut entries = vec![(
        Mark::Dot(POINTS),
        format!("readings ({raw_unit}, sensor axes)"),
    )];
    if let Some(f) = field_ut {
        entries.push((
            Mark::Line(OUTLINE, 2),
            format!(
                "top: the fitted ellipsoid's outline (A and b); bottom: the sphere |B| = {f:.1} {cal_unit}"
            ),
        ));
    } else {
        entries.push((
            Mark::Note,
            "raw readings only: the fit was refused".to_owned(),
        ));
    }
    let body = with_legend(&root, &entries)?;
    let panels = body.split_evenly((rows as usize, 3));
    for (k, &(i, j, xi, xj)) in PLANES.iter().enumerate() {
        let outline = match (cal, field_ut) {
            (Some(c), Some(f)) if f.is_finite() => {
                let m = c.base_model();
                ellipsoid_shadow(&m.a, m.b_ut, f, (i, j))
            }
            _ => Vec::new(),
        };
        let points: Vec<(f64, f64)> = raw.iter().map(|m| (m[i], m[j])).collect();
        projection(
            &panels[k],
            &format!("raw {xi}–{xj}"),
            &points,
            &outline,
            (xi, xj),
            &raw_unit,
        )?;
    }
    if let (Some(c), Some(f)) = (cal, field_ut) {
        let calibrated = thin(&calibrate_rows(&c.model(), rec), PROJECTION_POINTS);
        for (k, &(i, j, xi, xj)) in PLANES.iter().enumerate() {
            let points: Vec<(f64, f64)> = calibrated
                .iter()
                .filter(|m| m.iter().all(|v| v.is_finite()))
                .map(|m| (m[i], m[j]))
                .collect();
            let circle: Vec<(f64, f64)> = if f.is_finite() {
                (0..120)
                    .map(|n| {
                        let t = n as f64 / 120.0 * std::f64::consts::TAU;
                        (f * t.cos(), f * t.sin())
                    })
                    .collect()
            } else {
                Vec::new()
            };
            projection(
                &panels[3 + k],
                &format!("calibrated {xi}–{xj}"),
                &points,
                &circle,
                (xi, xj),
                &cal_unit,
            )?;
        }
    }
    root.present()?;
    Ok(())
}

/// Splits a heading-error curve where it wraps around ±180°, so no line crosses the plot.
fn unwrapped_pieces(errors_deg: &[f64]) -> Vec<Vec<(f64, f64)>> {
    let mut pieces: Vec<Vec<(f64, f64)>> = vec![Vec::new()];
    for (k, e) in errors_deg.iter().enumerate() {
        let last = pieces.last_mut().expect("one piece at least");
        if let Some(&(_, prev)) = last.last()
            && (e - prev).abs() > 180.0
        {
            pieces.push(Vec::new());
        }
        pieces
            .last_mut()
            .expect("one piece at least")
            .push((k as f64, *e));
    }
    pieces
}

/// `heading.svg`: the raw readings' heading error (top) and what the calibration leaves (bottom), per heading.
fn heading(svg: &mut String, h: &HeadingErrors) -> PlotResult<()> {
    let root = SVGBackend::with_string(svg, (1000, 740)).into_drawing_area();
    let body = with_legend(
        &root,
        &[
            (Mark::Line(BEFORE, 2), "raw readings (top)".to_owned()),
            (
                Mark::Line(AFTER, 2),
                "left after calibration (bottom)".to_owned(),
            ),
            (Mark::Line(GREY, 1), "a single reading's noise".to_owned()),
            (
                Mark::Line(BLACK, 2),
                "solid: sensor level, z down (x forward, y right)".to_owned(),
            ),
            (
                Mark::Dashed(BLACK),
                "dashed: z up (x forward, y left)".to_owned(),
            ),
        ],
    )?;
    let (upper, lower) = body.split_vertically(body.dim_in_pixel().1 / 2);
    let headings = || 0.0..360.0;
    let whole = |x: &f64| format!("{x:.0}");
    // Top: raw readings used as if calibrated.
    let span = (h.before.worst_deg * 1.1).clamp(0.5, 180.0);
    let mut chart = ChartBuilder::on(&upper)
        .caption(
            format!(
                "raw readings used as if calibrated: worst {}, RMS {}",
                crate::verdict::fmt_deg(h.before.worst_deg),
                crate::verdict::fmt_deg(h.before.rms_deg)
            ),
            ("sans-serif", 16),
        )
        .margin(10)
        .x_label_area_size(36)
        .y_label_area_size(64)
        .build_cartesian_2d(headings(), -span..span)?;
    chart
        .configure_mesh()
        .light_line_style(TRANSPARENT)
        .x_desc("true heading (°)")
        .y_desc("heading error (°)")
        .x_label_formatter(&whole)
        .y_label_formatter(&whole)
        .draw()?;
    for c in &h.curves {
        for piece in unwrapped_pieces(&c.before_deg) {
            draw_curve(&mut chart, c.face, piece, BEFORE)?;
        }
    }
    // Bottom: what is left.
    let top_left = h
        .curves
        .iter()
        .flat_map(|c| c.left_deg.iter())
        .fold(h.noise_deg, |m, e| m.max(*e))
        * 1.15;
    let mut chart = ChartBuilder::on(&lower)
        .caption(
            format!(
                "left after calibration (one standard deviation): worst {}, RMS {}",
                crate::verdict::fmt_deg(h.left.worst_deg),
                crate::verdict::fmt_deg(h.left.rms_deg)
            ),
            ("sans-serif", 16),
        )
        .margin(10)
        .x_label_area_size(36)
        .y_label_area_size(64)
        .build_cartesian_2d(headings(), 0.0..top_left.max(1e-3))?;
    chart
        .configure_mesh()
        .light_line_style(TRANSPARENT)
        .x_desc("true heading (°)")
        .y_desc("heading error left (°)")
        .x_label_formatter(&whole)
        .draw()?;
    for c in &h.curves {
        let pts: Vec<(f64, f64)> = c
            .left_deg
            .iter()
            .enumerate()
            .map(|(k, e)| (k as f64, *e))
            .collect();
        draw_curve(&mut chart, c.face, pts, AFTER)?;
    }
    chart.draw_series(LineSeries::new(
        vec![(0.0, h.noise_deg), (360.0, h.noise_deg)],
        GREY.stroke_width(1),
    ))?;
    root.present()?;
    Ok(())
}

/// A heading curve: solid for z down, dashed for z up.
fn draw_curve<X, Y>(
    chart: &mut ChartContext<'_, SVGBackend<'_>, Cartesian2d<X, Y>>,
    face: Face,
    pts: Vec<(f64, f64)>,
    color: RGBColor,
) -> PlotResult<()>
where
    X: Ranged<ValueType = f64>,
    Y: Ranged<ValueType = f64>,
{
    match face {
        Face::ZDown => {
            chart.draw_series(LineSeries::new(pts, color.stroke_width(2)))?;
        }
        Face::ZUp => {
            chart.draw_series(std::iter::once(DashedPathElement::new(
                pts,
                6,
                4,
                color.stroke_width(2),
            )))?;
        }
    }
    Ok(())
}

/// A marked time: a step at `t0_s`, or a window `t0_s`–`t1_s`.
struct Event {
    t0_s: f64,
    t1_s: Option<f64>,
    what: &'static str,
}

/// Per-sample residuals for the residual plots, from the diagnosis or from the base fit.
struct Series {
    t_s: Vec<f64>,
    direction: Vec<[f64; 3]>,
    /// Per-sample residual size (RMS over the components), µT.
    base: Vec<f64>,
    /// The same with the effects found, when diagnosed.
    extended: Option<Vec<f64>>,
    floor_ut: f64,
    spans: Vec<(f64, f64)>,
    events: Vec<Event>,
    /// What the residuals are in: µT, or the readings' own units when no field magnitude was known.
    unit: String,
}

/// Per-sample residual magnitude (RMS over the components).
fn magnitude(res: &Components) -> Vec<f64> {
    res.iter()
        .map(|r| (r.iter().map(|v| v * v).sum::<f64>() / r.len().max(1) as f64).sqrt())
        .collect()
}

impl Series {
    fn of(cal: &Calibration, rec: &Recording) -> Series {
        let mut series = match &cal.diagnosis {
            Some(d) => Series::diagnosed(d),
            None => Series::fitted(cal, rec),
        };
        series.unit = cal.units.calibrated_label();
        series
    }

    fn diagnosed(d: &Diagnosis) -> Series {
        let r = &d.residuals;
        let events = d
            .effects
            .iter()
            .filter_map(|e| match e.effect {
                Effect::BiasStep { t_s, .. } => Some(Event {
                    t0_s: t_s,
                    t1_s: None,
                    what: "offset step found",
                }),
                Effect::Disturbance { t0_s, t1_s, .. } => Some(Event {
                    t0_s,
                    t1_s: Some(t1_s),
                    what: "disturbance found",
                }),
                _ => None,
            })
            .collect();
        Series {
            t_s: r.t_s.clone(),
            direction: r.direction.clone(),
            base: magnitude(&r.base),
            extended: (!d.effects.is_empty()).then(|| magnitude(&r.extended)),
            floor_ut: d.noise_floor_ut,
            spans: if d.verdict == Finding::Mismatch {
                d.located
                    .segments
                    .iter()
                    .map(|s| (s.t0_s, s.t1_s))
                    .collect()
            } else {
                Vec::new()
            },
            events,
            unit: "µT".to_owned(),
        }
    }

    /// The base fit's residual, computed here (`--no-diagnose`).
    fn fitted(cal: &Calibration, rec: &Recording) -> Series {
        let model = cal.base_model();
        let cal_ut = |i: usize| frames::add(frames::mat_vec(&model.a, rec.mag_ut[i]), model.b_ut);
        let t = |i: usize| rec.t_s.as_ref().map_or(0.0, |t| t[i]);
        let (mut t_s, mut direction, mut base) = (Vec::new(), Vec::new(), Vec::new());
        match (&cal.fit, expected_field(rec, &cal.fitted_field())) {
            (Fit::Vector(_), Ok(expected)) => {
                for (i, e) in expected.iter().enumerate() {
                    if !e.iter().all(|v| v.is_finite()) {
                        continue;
                    }
                    let d = frames::sub(cal_ut(i), *e);
                    t_s.push(t(i));
                    direction.push(frames::scale(*e, 1.0 / frames::norm(*e)));
                    base.push((frames::dot(d, d) / 3.0).sqrt());
                }
            }
            (fit, _) => {
                let field_ut = fit
                    .face()
                    .magnitude_ut()
                    .or(cal.field.magnitude())
                    .unwrap_or(0.0);
                for i in 0..rec.len() {
                    let c = cal_ut(i);
                    let n = frames::norm(c);
                    t_s.push(t(i));
                    direction.push(frames::scale(c, 1.0 / n));
                    base.push((n - field_ut).abs());
                }
            }
        }
        Series {
            t_s,
            direction,
            base,
            extended: None,
            floor_ut: cal.noise_floor_ut,
            spans: Vec::new(),
            events: Vec::new(),
            unit: "µT".to_owned(),
        }
    }
}

/// `residual_time.svg`: binned residual RMS against time, the noise floor, located spans and events.
fn residual_time(svg: &mut String, s: &Series) -> PlotResult<()> {
    let (t0, t1) = (s.t_s[0], s.t_s[s.t_s.len() - 1]);
    let bin = |res: &[f64]| -> Vec<(f64, f64)> {
        let mut sum = vec![0.0; TIME_BINS];
        let mut count = vec![0usize; TIME_BINS];
        for (t, m) in s.t_s.iter().zip(res) {
            let k = (((t - t0) / (t1 - t0).max(1e-9)) * TIME_BINS as f64) as usize;
            sum[k.min(TIME_BINS - 1)] += m * m;
            count[k.min(TIME_BINS - 1)] += 1;
        }
        (0..TIME_BINS)
            .filter(|&k| count[k] > 0)
            .map(|k| {
                (
                    t0 + (k as f64 + 0.5) * (t1 - t0) / TIME_BINS as f64,
                    (sum[k] / count[k] as f64).sqrt(),
                )
            })
            .collect()
    };
    let before = bin(&s.base);
    let after = s.extended.as_deref().map(bin);
    let top = before
        .iter()
        .chain(after.iter().flatten())
        .map(|p| p.1)
        .fold(s.floor_ut, f64::max)
        * 1.1;
    let root = SVGBackend::with_string(svg, (1000, 460)).into_drawing_area();
    let mut entries = vec![(
        Mark::Line(BEFORE, 1),
        if after.is_some() {
            "the base fit"
        } else {
            "the fit"
        }
        .to_owned(),
    )];
    if after.is_some() {
        entries.push((Mark::Line(AFTER, 1), "with the effects found".to_owned()));
    }
    entries.push((Mark::Line(BLACK, 1), "the sensor's noise".to_owned()));
    if !s.spans.is_empty() {
        entries.push((Mark::Patch(SPAN), "where the misfit was located".to_owned()));
    }
    for what in ["offset step found", "disturbance found"] {
        if s.events.iter().any(|e| e.what == what) {
            entries.push((Mark::Dashed(EVENT), what.to_owned()));
        }
    }
    let body = with_legend(&root, &entries)?;
    let mut chart = ChartBuilder::on(&body)
        .caption(
            "residual against time (RMS over 1/400 of the recording)",
            ("sans-serif", 16),
        )
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(64)
        .build_cartesian_2d(t0..t1.max(t0 + 1e-9), 0.0..top)?;
    chart
        .configure_mesh()
        .light_line_style(TRANSPARENT)
        .x_desc("t (s)")
        .y_desc(format!("residual RMS ({})", s.unit))
        .draw()?;
    chart.draw_series(
        s.spans
            .iter()
            .map(|&(a, b)| Rectangle::new([(a, 0.0), (b, top)], SPAN.mix(0.35).filled())),
    )?;
    chart.draw_series(s.events.iter().filter_map(|e| {
        e.t1_s
            .map(|b| Rectangle::new([(e.t0_s, 0.0), (b, top)], EVENT.mix(0.15).filled()))
    }))?;
    for e in &s.events {
        for t in std::iter::once(e.t0_s).chain(e.t1_s) {
            chart.draw_series(std::iter::once(DashedPathElement::new(
                vec![(t, 0.0), (t, top)],
                6,
                4,
                EVENT.stroke_width(2),
            )))?;
        }
    }
    chart.draw_series(LineSeries::new(before, BEFORE.stroke_width(1)))?;
    if let Some(after) = after {
        chart.draw_series(LineSeries::new(after, AFTER.stroke_width(1)))?;
    }
    chart.draw_series(LineSeries::new(
        vec![(t0, s.floor_ut), (t1, s.floor_ut)],
        BLACK.stroke_width(1),
    ))?;
    root.present()?;
    Ok(())
}

/// Blue at or below the noise floor `lo`, red at `hi` or more.
fn shade(v: f64, lo: f64, hi: f64) -> RGBColor {
    let t = ((v - lo) / (hi - lo)).clamp(0.0, 1.0);
    RGBColor(
        (255.0 * t) as u8,
        (80.0 * (1.0 - t)) as u8,
        (255.0 * (1.0 - t)) as u8,
    )
}

/// `residual_orientation.svg`: residual RMS in cells of azimuth × elevation of the field direction (sensor axes),
/// the fit (and, when diagnosed, the fit with the effects found), with a colour bar.
fn residual_orientation(svg: &mut String, s: &Series) -> PlotResult<()> {
    const AZ: usize = 36;
    const EL: usize = 18;
    let grid = |res: &[f64]| -> Vec<Option<f64>> {
        let mut sum = vec![0.0; AZ * EL];
        let mut count = vec![0usize; AZ * EL];
        for (d, m) in s.direction.iter().zip(res) {
            let az = d[1].atan2(d[0]).to_degrees() + 180.0;
            let el = d[2].clamp(-1.0, 1.0).asin().to_degrees() + 90.0;
            if !(az.is_finite() && el.is_finite()) {
                continue;
            }
            let cell = ((el / 10.0) as usize).min(EL - 1) * AZ + ((az / 10.0) as usize).min(AZ - 1);
            sum[cell] += m * m;
            count[cell] += 1;
        }
        (0..AZ * EL)
            .map(|c| (count[c] >= MIN_CELL_SAMPLES).then(|| (sum[c] / count[c] as f64).sqrt()))
            .collect()
    };
    let mut maps = vec![(
        grid(&s.base),
        if s.extended.is_some() {
            "the base fit"
        } else {
            "the fit"
        },
    )];
    if let Some(e) = &s.extended {
        maps.push((grid(e), "with the effects found"));
    }
    // The scale runs from the noise to the larger of twice the noise and the 95th percentile of the cells.
    let mut cells: Vec<f64> = maps
        .iter()
        .flat_map(|(g, _)| g.iter().flatten().copied())
        .collect();
    cells.sort_by(f64::total_cmp);
    let p95 = cells
        .get((cells.len() as f64 * 0.95) as usize)
        .copied()
        .unwrap_or(0.0);
    let (lo, hi) = (s.floor_ut, p95.max(2.0 * s.floor_ut));
    let width = 60 + 520 * maps.len() as u32 + 120;
    let entries = [
        (
            Mark::Cell(UNVISITED),
            "the field never pointed this way: no readings".to_owned(),
        ),
        (
            Mark::Note,
            "colour: the residual where it did, from the sensor's noise (blue) up (red)".to_owned(),
        ),
    ];
    let root = SVGBackend::with_string(svg, (width, 400 + LEGEND_PX)).into_drawing_area();
    let body = with_legend(&root, &entries)?;
    let (maps_area, bar_area) = body.split_horizontally(width - 120);
    let panels = maps_area.split_evenly((1, maps.len()));
    for (area, (cells, title)) in panels.iter().zip(&maps) {
        let mut chart = ChartBuilder::on(area)
            .caption(
                format!("residual RMS by the field's direction: {title}"),
                ("sans-serif", 15),
            )
            .margin(10)
            .x_label_area_size(38)
            .y_label_area_size(56)
            .build_cartesian_2d(-180.0..180.0, -90.0..90.0)?;
        chart
            .configure_mesh()
            .light_line_style(TRANSPARENT)
            .x_desc("around the sensor's z axis, from +x towards +y (°)")
            .y_desc("up from the x–y plane towards +z (°)")
            .x_labels(9)
            .y_labels(7)
            .draw()?;
        chart.draw_series(cells.iter().enumerate().map(|(c, v)| {
            let (az, el) = (
                (c % AZ) as f64 * 10.0 - 180.0,
                (c / AZ) as f64 * 10.0 - 90.0,
            );
            let colour = v.map_or(UNVISITED, |v| shade(v, lo, hi));
            Rectangle::new([(az, el), (az + 10.0, el + 10.0)], colour.filled())
        }))?;
    }
    colour_bar(&bar_area, lo, hi, &s.unit)?;
    root.present()?;
    Ok(())
}

/// A vertical colour bar from the noise floor `lo` (blue) to `hi` (red), labelled in `unit`.
fn colour_bar(area: &Area<'_>, lo: f64, hi: f64, unit: &str) -> PlotResult<()> {
    let (x0, x1, y_top, y_bottom) = (12i32, 34i32, 70i32, 330i32);
    let steps = 40;
    for k in 0..steps {
        let t = k as f64 / steps as f64;
        let y = y_bottom - ((y_bottom - y_top) as f64 * (k + 1) as f64 / steps as f64) as i32;
        let h = ((y_bottom - y_top) as f64 / steps as f64).ceil() as i32 + 1;
        area.draw(&Rectangle::new(
            [(x0, y), (x1, y + h)],
            shade(lo + t * (hi - lo), lo, hi).filled(),
        ))?;
    }
    area.draw(&Rectangle::new(
        [(x0, y_top), (x1, y_bottom)],
        BLACK.stroke_width(1),
    ))?;
    let style = ("sans-serif", 13).into_font().color(&BLACK);
    area.draw_text("residual", &style, (4, y_top - 42))?;
    area.draw_text(&format!("RMS ({unit})"), &style, (4, y_top - 26))?;
    for (frac, label) in [
        (0.0, format!("≤ {lo:.3}")),
        (0.5, format!("{:.3}", (lo + hi) / 2.0)),
        (1.0, format!("≥ {hi:.3}")),
    ] {
        let y = y_bottom - ((y_bottom - y_top) as f64 * frac) as i32;
        area.draw(&PathElement::new(vec![(x1, y), (x1 + 4, y)], BLACK))?;
        area.draw_text(&label, &style, (x1 + 6, y - 6))?;
    }
    area.draw_text("(the noise)", &style, (x1 + 6, y_bottom + 8))?;
    Ok(())
}

/// The channel the residual is blamed on: the one it follows, or the one the first effect found depends on.
fn blamed_channel(d: &Diagnosis) -> Option<(&str, &[f64])> {
    let by_name = |name: &str| {
        d.residuals
            .channels
            .iter()
            .find(|(n, _)| n == name)
            .map(|(n, v)| (n.as_str(), v.as_slice()))
    };
    if let Some(found) = d.located.channel.as_deref().and_then(by_name) {
        return Some(found);
    }
    let e = d.effects.first()?;
    let id = e.effect.id();
    let needs = id.descriptor().needs;
    if needs.contains(&Need::Temperature) {
        by_name("temp")
    } else if needs.contains(&Need::Current) {
        e.channel.as_deref().and_then(by_name)
    } else if id.frame() == Frame::Timing {
        by_name("rotation_rate")
    } else {
        by_name("t")
    }
}

/// A channel the diagnosis compares the residual with, as an axis names it: what it is, with its unit.
/// `rotation_rate` is the expected field's rate of change, |dB/dt| in µT/s (the field turning in sensor axes), not a
/// gyro's rad/s.
pub fn channel_label(name: &str) -> String {
    match name {
        "temp" => "temperature (°C)".to_owned(),
        "t" => "time (s)".to_owned(),
        "rotation_rate" => "the field's rate of change in sensor axes, |dB/dt| (µT/s)".to_owned(),
        n if n.starts_with("i_") => format!("{n} (A)"),
        n => format!("{n} (as recorded)"),
    }
}

/// `residual_channel.svg`: the residual component most correlated with the channel, against the channel.
fn residual_channel(svg: &mut String, d: &Diagnosis, name: &str, values: &[f64]) -> PlotResult<()> {
    let r = &d.residuals;
    let dims = r.base.dims;
    let n = values.len() as f64;
    let cm = values.iter().sum::<f64>() / n;
    let corr = |j: usize| {
        let rm = r.base.iter().map(|v| v[j]).sum::<f64>() / n;
        r.base
            .iter()
            .zip(values)
            .map(|(v, c)| (v[j] - rm) * (c - cm))
            .sum::<f64>()
            .abs()
    };
    let j = (0..dims)
        .max_by(|&a, &b| corr(a).total_cmp(&corr(b)))
        .unwrap_or(0);
    let stride = (values.len() / SCATTER_POINTS).max(1);
    let pick = |res: &Components| -> Vec<(f64, f64)> {
        values
            .iter()
            .zip(res.iter())
            .step_by(stride)
            .map(|(c, v)| (*c, v[j]))
            .collect()
    };
    let (before, after) = (pick(&r.base), pick(&r.extended));
    let (lo, hi) = values
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(*v), b.max(*v))
        });
    let hi = hi.max(lo + 1e-9);
    // Binned means show the trend the scatter hides.
    let means = |res: &Components| -> Vec<(f64, f64)> {
        let mut sum = [0.0; CHANNEL_BINS];
        let mut count = [0usize; CHANNEL_BINS];
        for (c, v) in values.iter().zip(res.iter()) {
            let k = (((c - lo) / (hi - lo)) * CHANNEL_BINS as f64) as usize;
            sum[k.min(CHANNEL_BINS - 1)] += v[j];
            count[k.min(CHANNEL_BINS - 1)] += 1;
        }
        (0..CHANNEL_BINS)
            .filter(|&k| count[k] >= MIN_CELL_SAMPLES)
            .map(|k| {
                (
                    lo + (k as f64 + 0.5) * (hi - lo) / CHANNEL_BINS as f64,
                    sum[k] / count[k] as f64,
                )
            })
            .collect()
    };
    let span = before
        .iter()
        .chain(&after)
        .map(|p| p.1.abs())
        .fold(1e-6, f64::max)
        * 1.1;
    let axis = if dims == 3 { ["x", "y", "z"][j] } else { "|B|" };
    let root = SVGBackend::with_string(svg, (800, 540)).into_drawing_area();
    let body = with_legend(
        &root,
        &[
            (
                Mark::Line(BEFORE, 3),
                "the base fit (binned means)".to_owned(),
            ),
            (Mark::Line(AFTER, 3), "with the effects found".to_owned()),
        ],
    )?;
    let mut chart = ChartBuilder::on(&body)
        .caption(
            format!("residual ({axis}) against what it follows: samples and binned means"),
            ("sans-serif", 16),
        )
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(64)
        .build_cartesian_2d(lo..hi, -span..span)?;
    chart
        .configure_mesh()
        .light_line_style(TRANSPARENT)
        .x_desc(channel_label(name))
        .y_desc(format!("residual {axis} (µT)"))
        .draw()?;
    chart.draw_series(
        before
            .iter()
            .map(|p| Circle::new(*p, 2, BEFORE.mix(0.25).filled())),
    )?;
    chart.draw_series(
        after
            .iter()
            .map(|p| Circle::new(*p, 2, AFTER.mix(0.25).filled())),
    )?;
    chart.draw_series(LineSeries::new(means(&r.base), BEFORE.stroke_width(3)))?;
    chart.draw_series(LineSeries::new(means(&r.extended), AFTER.stroke_width(3)))?;
    root.present()?;
    Ok(())
}
