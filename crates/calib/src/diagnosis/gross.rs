//! Gross disturbances: the spans where the residual departs grossly from the rest, and what each one is.
//!
//! Input: the per-sample residual of a model, which samples it kept (the robust fit's verdict: outside the spans of
//! samples beyond [`crate::robust::GROSS_SIGMA`] of the scale, see [`crate::robust::gross_spans`]), and the scale.
//! Output: spans (sample ranges), each classified by what explains it:
//! - **fixed to the sensor** — a constant in sensor axes (something magnetic attached to the board): modelled as a
//!   `bias_window`, the samples inside kept;
//! - **fixed to the room** — a constant in NED seen through the attitude (a magnet placed on the bench and taken
//!   away): modelled as a `disturbance`;
//! - **a shift of the magnitude** (scalar method) — a constant in |B| while the sensor turned: a field fixed in the
//!   room adds `|F + D| − |F|` whatever the attitude, which the magnitude shows only as a constant; excluded;
//! - **moving** — neither, while the sensor moved: a field that changes with where the sensor is (a magnet or
//!   steel nearby): excluded, reported with its span and peak;
//! - **unexplained** — neither, and the sensor did not move (something moved near it), or a glitch of a few
//!   samples: excluded, with the reason.
//!
//! A span no constant explains is split at its quiet stretches when a constant explains each part between them
//! (two fields on the board one after the other, merged by the robust fit across the lull between), or else, in
//! the vector method, around a steady stretch a constant explains (a field on the board or in the room next to a
//! pass by a magnet, with no lull between); the parts are classified on their own.
//!
//! A constant explains a span when what it leaves is at the scale of the rest of the recording (or is a small
//! part of the span's energy). The frame is told by the attitude: when the sensor hardly turned during the span the
//! two constants are the same, and the span is modelled as fixed to the sensor with that said.

use crate::effects::Effect;
use crate::frames;
use crate::scan;

use super::candidates::{self, ScanTimes};
use super::chance;
use super::samples::Attitudes;
use super::setup::Setup;

/// A constant explains a span when it leaves at most this many times the scale's variance per axis…
const EXPLAINED_SCALES2: f64 = 4.0;
/// …or at most this fraction of the span's residual energy.
const EXPLAINED_SHARE: f64 = 0.1;
/// A modelled span's sample stays in the fit when the span's constant leaves at most this many scales per axis.
const KEPT_SCALES: f64 = 3.0;
/// The other frame is told apart when it leaves at least this many times what the chosen one leaves.
const FRAME_MARGIN: f64 = 2.0;
/// The sensor turned during a span when the field direction in sensor axes moved by more than this, degrees.
const TURNED_DEG: f64 = 10.0;

/// What a span is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SpanKind {
    /// A constant in sensor axes: `offset_ut` (sensor axes, µT).
    SensorFixed {
        /// The offset, µT.
        offset_ut: [f64; 3],
        /// Whether the sensor turned enough to tell it from a field fixed to the room.
        told_apart: bool,
    },
    /// A constant field in the room, NED, µT.
    RoomFixed {
        /// The field, NED, µT.
        field_ned_ut: [f64; 3],
    },
    /// A constant shift of the magnitude while the sensor turned (scalar method): a field fixed in the room, µT.
    MagnitudeShift {
        /// The shift of |B|, µT.
        shift_ut: f64,
    },
    /// A field that changed as the sensor moved: a magnet or steel nearby.
    Moving,
    /// Neither, with the sensor still, or a glitch.
    Unexplained,
}

/// A gross span of samples `[start, end)` (indices into the diagnosis' samples).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Span {
    pub start: usize,
    pub end: usize,
    /// The largest residual size in it, µT.
    pub peak_ut: f64,
    /// RMS of the residual per axis in it, µT.
    pub rms_ut: f64,
    pub kind: SpanKind,
    /// Whether the sensor turned during it.
    pub turned: bool,
    /// Why modelling it was declined, if it was.
    pub declined: Option<Declined>,
}

/// Why a span that could be modelled is left out instead.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Declined {
    /// With its samples kept, the clean held-out samples fitted worse, or not noticeably better (the no-harm guard).
    NoGain,
    /// Its effect, with the others, left the fit without a solution (a field in the room while the sensor hardly
    /// turned is nearly the offset).
    Undetermined,
}

impl Span {
    /// Whether its samples are modelled (kept, with an effect) rather than excluded: a constant explains it, the
    /// sensor turned, a field fixed to the sensor is told apart from one fixed in the room, and the guard did not
    /// decline it. A still sensor's span adds one direction to the fit, and its constant may be the still part of
    /// something that moved (a magnet's field while the sensor rests near it); a constant that could be either
    /// frame's biases the fit if modelled in the wrong one; the magnitude alone never tells them apart (and sees a
    /// large offset only through a linearisation that no longer holds): such spans are left out.
    pub fn modelled(&self) -> bool {
        self.turned
            && self.declined.is_none()
            && matches!(
                self.kind,
                SpanKind::SensorFixed {
                    told_apart: true,
                    ..
                } | SpanKind::RoomFixed { .. }
            )
    }
}

/// The residual of one sample as classification sees it.
pub(crate) enum Residual<'a> {
    /// Three components in sensor axes, and the attitude when known.
    Vector {
        e: &'a [[f64; 3]],
        rot: Option<Attitudes<'a>>,
    },
    /// The magnitude's residual and the field direction (sensor axes), against the field's magnitude `field_ut`.
    Magnitude {
        rho: &'a [f64],
        unit: &'a [[f64; 3]],
        field_ut: f64,
    },
}

impl Residual<'_> {
    fn size(&self, i: usize) -> f64 {
        match self {
            Residual::Vector { e, .. } => frames::norm(e[i]),
            Residual::Magnitude { rho, .. } => rho[i].abs(),
        }
    }

    /// Whether sample `i` is quiet: within [`crate::robust::RAMP_SIGMA`] scales.
    fn quiet(&self, i: usize, scale_ut: f64) -> bool {
        self.size(i) <= crate::robust::RAMP_SIGMA * scale_ut
    }

    fn dims(&self) -> f64 {
        match self {
            Residual::Vector { .. } => 3.0,
            Residual::Magnitude { .. } => 1.0,
        }
    }
}

/// Whether sample `i` of a modelled span is explained by the span's constant: what it leaves is within
/// [`KEPT_SCALES`] scales per axis. The rest (a ramp as a magnet is put on, a part that moved) stays out of the fit.
pub(crate) fn explained_at(
    residual: &Residual<'_>,
    kind: &SpanKind,
    i: usize,
    scale_ut: f64,
) -> bool {
    let left = match (residual, kind) {
        (Residual::Vector { e, .. }, SpanKind::SensorFixed { offset_ut, .. }) => {
            frames::norm(frames::sub(e[i], *offset_ut))
        }
        (Residual::Vector { e, rot: Some(r) }, SpanKind::RoomFixed { field_ned_ut }) => {
            frames::norm(frames::sub(frames::mat_vec(&r.at(i), e[i]), *field_ned_ut))
        }
        (
            Residual::Magnitude {
                rho,
                unit,
                field_ut,
            },
            SpanKind::SensorFixed { offset_ut, .. },
        ) => {
            let m = frames::scale(unit[i], field_ut + rho[i]);
            (frames::norm(frames::sub(m, *offset_ut)) - field_ut).abs()
        }
        _ => return false,
    };
    left <= KEPT_SCALES * scale_ut * residual.dims().sqrt()
}

/// Stages 2 and 3's hand-off: the classified spans, the glitches, which samples the fits include and which are
/// clean, and the modelled spans' effects.
pub(crate) struct GrossStage {
    /// The gross spans that are findings, in time order.
    pub spans: Vec<Span>,
    /// The gross spans that are not ([`chance::judge`]): left out of the fits, counted, never a finding.
    pub glitches: Vec<Span>,
    /// Per sample: in the fits (clean, or in a modelled span's window and explained by its constant).
    pub included: Vec<bool>,
    /// Per sample: outside every gross span.
    pub clean: Vec<bool>,
    /// The modelled spans' effects (`bias_window` or `disturbance`) with their times set, and the times' intervals.
    pub span_effects: Vec<(Effect, ScanTimes)>,
}

/// Stages 2 and 3: the spans of `residual`'s gross samples (those not `kept`; `scale` the residual's), classified;
/// the spans overlapping `left_out` are not modelled, for the reason given there.
pub(crate) fn stage(
    setup: &Setup<'_>,
    residual: &[[f64; 3]],
    kept: &[bool],
    scale: f64,
    left_out: &[(usize, usize, Declined)],
) -> GrossStage {
    let s = setup.samples;
    let n = s.len();
    let rho: Vec<f64> = if setup.vector {
        Vec::new()
    } else {
        residual.iter().map(|e| e[0]).collect()
    };
    let view = if setup.vector {
        Residual::Vector {
            e: residual,
            rot: s.rot(),
        }
    } else {
        Residual::Magnitude {
            rho: &rho,
            unit: &setup.unit,
            field_ut: setup.field_ut,
        }
    };
    let sizes: Vec<f64> = residual.iter().map(|e| setup.size(e)).collect();
    let dims = if setup.vector { 3.0 } else { 1.0 };
    let candidates = spans(&view, kept, scale, &setup.unit);
    let extents: Vec<(usize, usize, Option<f64>)> = candidates
        .iter()
        .map(|sp| (sp.start, sp.end, duration_s(s, sp)))
        .collect();
    let verdicts = chance::judge(&sizes, &extents, scale, dims);
    let (mut spans, mut glitches) = (Vec::new(), Vec::new());
    for (span, finding) in candidates.into_iter().zip(verdicts) {
        if finding {
            spans.push(span)
        } else {
            glitches.push(span)
        }
    }
    drop(sizes);
    let mut included = vec![true; n];
    let mut clean = vec![true; n];
    for g in &glitches {
        clean[g.start..g.end].fill(false);
        included[g.start..g.end].fill(false);
    }
    let mut span_effects = Vec::new();
    for span in &mut spans {
        clean[span.start..span.end].fill(false);
        included[span.start..span.end].fill(false);
        if let Some(&(_, _, why)) = left_out
            .iter()
            .find(|&&(a, b, _)| a < span.end && span.start < b)
        {
            span.declined = Some(why);
        }
        if !span.modelled() || !s.has_time {
            continue;
        }
        let (a, b) = if setup.vector {
            refine_edges(span, residual, s.rot(), scale)
        } else {
            (span.start, span.end)
        };
        for (i, inc) in included.iter_mut().enumerate().take(b).skip(a) {
            *inc = explained_at(&view, &span.kind, i, scale);
        }
        span_effects.push(span_effect(setup, span, a, b));
    }
    GrossStage {
        spans,
        glitches,
        included,
        clean,
        span_effects,
    }
}

/// How long a span lasts, from its first sample to its last and one sample interval more, s; `None` without time.
fn duration_s(s: &super::samples::Samples<'_>, sp: &Span) -> Option<f64> {
    s.has_time.then(|| {
        let step = candidates::sample_interval_s(s);
        s.t[sp.end - 1] - s.t[sp.start] + step
    })
}

/// A modelled span's effect over samples `[a, b)` — a `disturbance` for a field fixed in the room, a `bias_window`
/// for one fixed to the sensor — with its times, known to the sample.
fn span_effect(setup: &Setup<'_>, span: &Span, a: usize, b: usize) -> (Effect, ScanTimes) {
    let s = setup.samples;
    let (t0_s, t1_s) = (candidates::between(s, a), candidates::between(s, b));
    let effect = match span.kind {
        SpanKind::RoomFixed { .. } => Effect::Disturbance {
            t0_s,
            t1_s,
            field_ned_ut: [0.0; 3],
        },
        _ => Effect::BiasWindow {
            t0_s,
            t1_s,
            offset_ut: [0.0; 3],
        },
    };
    let times = ScanTimes {
        start_s: (t0_s, t0_s),
        end_s: Some((t1_s, t1_s)),
        sample_interval_s: candidates::sample_interval_s(s),
    };
    (effect, times)
}

/// The gross spans (the runs of samples not `kept`: the robust fit's spans, merged and widened there), classified.
/// `scale_ut` is the residual's scale per axis, `directions` the field direction in sensor axes per sample.
pub(crate) fn spans(
    residual: &Residual<'_>,
    kept: &[bool],
    scale_ut: f64,
    directions: &[[f64; 3]],
) -> Vec<Span> {
    let spans = crate::robust::excluded_runs(kept)
        .into_iter()
        .flat_map(|(a, b)| {
            let span = classify(residual, a, b, scale_ut, directions);
            match span.kind {
                SpanKind::Moving | SpanKind::Unexplained => {
                    split_at_lulls(residual, a, b, scale_ut, directions)
                        .or_else(|| split_at_steady(residual, a, b, scale_ut, directions))
                        .unwrap_or(vec![span])
                }
                _ => vec![span],
            }
        });
    join_agreeing(residual, spans, scale_ut, directions)
}

/// Spans that one constant explains, in the same frame, joined with the samples and spans between them when that
/// constant explains the whole: a field on the board shows as gross only where the reference's own error adds to it,
/// and the robust fit kept the stretches between (on the physical BROAD 02 recording with 5.6 µT added on the board
/// for 53 s: seven windows, and the fit dragged by the stretches kept to A 0.08 off). A joined span's edges are then
/// located again ([`refine_edges`]): a stretch at either end the fit kept is as much a part of it, and left in, the
/// only samples of the field on the board in those directions, it would pull the fit all the more. Two fields one
/// after the other, or a clean stretch between, leave the joined span unexplained and stay apart.
fn join_agreeing(
    residual: &Residual<'_>,
    spans: impl Iterator<Item = Span>,
    scale_ut: f64,
    directions: &[[f64; 3]],
) -> Vec<Span> {
    let frame = |s: &Span| match s.kind {
        SpanKind::SensorFixed {
            told_apart: true, ..
        } if s.turned => Some(true),
        SpanKind::RoomFixed { .. } if s.turned => Some(false),
        _ => None,
    };
    let mut out: Vec<Span> = Vec::new();
    let mut joined: Vec<bool> = Vec::new();
    for span in spans {
        let f = frame(&span);
        let partner = f.and_then(|f| out.iter().rposition(|s| frame(s) == Some(f)));
        if let (Some(f), Some(j)) = (f, partner) {
            let whole = classify(residual, out[j].start, span.end, scale_ut, directions);
            if frame(&whole) == Some(f) {
                out.truncate(j);
                joined.truncate(j);
                out.push(whole);
                joined.push(true);
                continue;
            }
        }
        out.push(span);
        joined.push(false);
    }
    let Residual::Vector { e, rot } = residual else {
        return out;
    };
    for k in 0..out.len() {
        if !joined[k] {
            continue;
        }
        let (a, b) = refine_edges(&out[k], e, *rot, scale_ut);
        let floor = if k == 0 { 0 } else { out[k - 1].end };
        let ceiling = out.get(k + 1).map_or(e.len(), |s| s.start);
        let (a, b) = (a.clamp(floor, out[k].start), b.clamp(out[k].end, ceiling));
        let wider = classify(residual, a, b, scale_ut, directions);
        if frame(&wider) == frame(&out[k]) {
            out[k] = wider;
        }
    }
    out
}

/// A quiet stretch inside a span holds at least this share of the span's samples…
const LULL_SHARE: f64 = 0.05;
/// …and at least this many samples.
const LULL_SAMPLES: usize = 20;

/// A span neither constant explains, split at its quiet stretches (residual within
/// [`crate::robust::RAMP_SIGMA`] scales) into the disturbed stretches between them, when a constant explains each
/// of those: two fields on the board one after the other, merged across a lull, are not a magnet nearby. The quiet
/// stretches belong to no span.
fn split_at_lulls(
    residual: &Residual<'_>,
    a: usize,
    b: usize,
    scale_ut: f64,
    directions: &[[f64; 3]],
) -> Option<Vec<Span>> {
    let quiet = |i: usize| residual.quiet(i, scale_ut);
    let min_lull = LULL_SAMPLES.max((LULL_SHARE * (b - a) as f64) as usize);
    // The disturbed stretches: maximal runs not interrupted by a quiet run of at least `min_lull` samples.
    let mut parts: Vec<(usize, usize)> = Vec::new();
    let mut i = a;
    while i < b {
        if quiet(i) {
            let start = i;
            while i < b && quiet(i) {
                i += 1;
            }
            if i - start >= min_lull || parts.is_empty() || i == b {
                continue;
            }
            // A short quiet run belongs to the stretch around it.
            parts.last_mut().expect("a part").1 = i;
        } else {
            let start = i;
            while i < b && !quiet(i) {
                i += 1;
            }
            match parts.last_mut() {
                Some(last) if last.1 == start => last.1 = i,
                _ => parts.push((start, i)),
            }
        }
    }
    if parts.len() < 2 {
        return None;
    }
    let spans: Vec<Span> = parts
        .into_iter()
        .map(|(p, q)| classify(residual, p, q, scale_ut, directions))
        .collect();
    spans
        .iter()
        .all(|s| !matches!(s.kind, SpanKind::Moving | SpanKind::Unexplained))
        .then_some(spans)
}

/// Samples apart over which a residual that holds still is compared with itself ([`split_at_steady`])…
const STEADY_LAG: usize = 5;
/// …the share of the span a steady stretch holds at least…
const STEADY_SHARE: f64 = 0.25;
/// …the share of its samples its constant must explain…
const STEADY_EXPLAINED: f64 = 0.9;
/// …and the share of the span's peak the constant must reach (the still moments of a magnet's pass are a small part
/// of its field).
const STEADY_OF_PEAK: f64 = 0.25;

/// A span neither constant explains, split around its steady stretches — runs of at least [`LULL_SAMPLES`] and
/// [`STEADY_SHARE`] of the span in which the residual holds still in sensor axes or in the room (it moves by at most
/// [`crate::robust::RAMP_SIGMA`] times the noise of a difference over [`STEADY_LAG`] samples) — when a constant
/// explains one of them sample by sample ([`STEADY_EXPLAINED`] of its samples within [`KEPT_SCALES`]) while the
/// sensor turned, and stands out of the noise and the span ([`STEADY_OF_PEAK`]): a field on the board, or one
/// placed in the room, next to a pass by a magnet with no lull between, is not all a magnet nearby. The other parts
/// are classified on their own, whole (a part all quiet belongs to no span). (A shorter steady stretch is as likely
/// a moment in which a magnet's field, seen from a sensor carried past it, held still: on the Nexus 5 walked past
/// perturbations, 1.4 s of a 10 s pass.)
fn split_at_steady(
    residual: &Residual<'_>,
    a: usize,
    b: usize,
    scale_ut: f64,
    directions: &[[f64; 3]],
) -> Option<Vec<Span>> {
    let Residual::Vector { e, rot } = residual else {
        return None;
    };
    // A difference of two samples' noise: √2 scales per axis, over three axes.
    let still = crate::robust::RAMP_SIGMA * scale_ut * 6f64.sqrt();
    let steady = |i: usize| {
        if i < a + STEADY_LAG {
            return false;
        }
        let j = i - STEADY_LAG;
        let body = frames::norm(frames::sub(e[i], e[j])) <= still;
        let world = rot.is_some_and(|r| {
            let (wi, wj) = (
                frames::mat_vec(&r.at(i), e[i]),
                frames::mat_vec(&r.at(j), e[j]),
            );
            frames::norm(frames::sub(wi, wj)) <= still
        });
        body || world
    };
    let quiet = |i: usize| residual.quiet(i, scale_ut);
    let peak_ut = (a..b).map(|i| residual.size(i)).fold(0.0, f64::max);
    let constant_part = |s: &Span| {
        let offset = match s.kind {
            SpanKind::SensorFixed {
                offset_ut,
                told_apart: true,
            } => offset_ut,
            SpanKind::RoomFixed { field_ned_ut } => field_ned_ut,
            _ => return false,
        };
        let floor = (crate::robust::GROSS_SIGMA * scale_ut).max(STEADY_OF_PEAK * peak_ut);
        if !s.turned || frames::norm(offset) <= floor {
            return false;
        }
        let inside = (s.start..s.end)
            .filter(|&i| explained_at(residual, &s.kind, i, scale_ut))
            .count();
        inside as f64 >= STEADY_EXPLAINED * (s.end - s.start) as f64
    };
    let min_run = LULL_SAMPLES.max((STEADY_SHARE * (b - a) as f64) as usize);
    // The steady runs that a constant explains (a run's first sample is the one STEADY_LAG before its first steady
    // one), and the parts between them.
    let mut constants: Vec<Span> = Vec::new();
    let mut i = a;
    while i < b {
        if !steady(i) {
            i += 1;
            continue;
        }
        let start = (i - STEADY_LAG).max(constants.last().map_or(a, |s| s.end));
        while i < b && steady(i) {
            i += 1;
        }
        if i - start >= min_run {
            let span = classify(residual, start, i, scale_ut, directions);
            if constant_part(&span) {
                constants.push(span);
            }
        }
    }
    if constants.is_empty() {
        return None;
    }
    // The parts between, whole: a quiet edge next to a magnet's pass is its fading field, and stays out of the fit
    // (a part all quiet belongs to no span).
    let between = |p: usize, q: usize| {
        (!(p..q).all(quiet)).then(|| classify(residual, p, q, scale_ut, directions))
    };
    let mut parts = Vec::new();
    let mut at = a;
    for c in constants {
        parts.extend(between(at, c.start));
        at = c.end;
        parts.push(c);
    }
    parts.extend(between(at, b));
    Some(parts)
}

/// What explains the residual of samples `[a, b)`.
fn classify(
    residual: &Residual<'_>,
    a: usize,
    b: usize,
    scale_ut: f64,
    directions: &[[f64; 3]],
) -> Span {
    let n = (b - a) as f64;
    let peak_ut = (a..b).map(|i| residual.size(i)).fold(0.0, f64::max);
    let energy: f64 = (a..b).map(|i| residual.size(i).powi(2)).sum();
    let rms_ut = (energy / (n * residual.dims())).sqrt();
    let explained = |rss: f64| {
        rss <= EXPLAINED_SCALES2 * scale_ut * scale_ut * n * residual.dims()
            || rss <= EXPLAINED_SHARE * energy
    };
    let turned = turned_deg(&directions[a..b]) > TURNED_DEG;
    let unexplained = if !turned {
        SpanKind::Unexplained
    } else {
        SpanKind::Moving
    };
    let kind = match residual {
        Residual::Vector { e, rot } => {
            let (body, rss_body) = constant(&e[a..b], None);
            let world = rot.map(|r| constant(&e[a..b], Some(r.range(a, b))));
            match world {
                // Told apart as the sensor frame is (below): the sensor frame leaves at least FRAME_MARGIN times
                // more; otherwise either frame could hold it, and it is left out.
                Some((field, rss_world)) if rss_world < rss_body && explained(rss_world) => {
                    if rss_body >= FRAME_MARGIN * rss_world {
                        SpanKind::RoomFixed {
                            field_ned_ut: field,
                        }
                    } else {
                        SpanKind::SensorFixed {
                            offset_ut: body,
                            told_apart: false,
                        }
                    }
                }
                _ if explained(rss_body) => SpanKind::SensorFixed {
                    offset_ut: body,
                    told_apart: world.is_none_or(|(_, w)| w >= FRAME_MARGIN * rss_body) && turned,
                },
                _ => unexplained,
            }
        }
        Residual::Magnitude {
            rho,
            unit,
            field_ut,
        } => {
            let shift_ut = rho[a..b].iter().sum::<f64>() / n;
            let rss_shift: f64 = rho[a..b].iter().map(|r| (r - shift_ut).powi(2)).sum();
            let body = along(&rho[a..b], &unit[a..b]);
            // The first-order `d·u` holds for an offset small against the field; a larger one is fitted exactly, as
            // the centre of the sphere of the field's radius the readings lie on (150 µT on the board of a turning
            // sensor moved |B| between 111 and 154 µT, and was called a field fixed in the room).
            let exact = off_centre(&rho[a..b], &unit[a..b], *field_ut, body.map(|(d, _)| d));
            let rss_body = body.map_or(f64::INFINITY, |(_, rss)| rss);
            let body = match (body, exact) {
                (Some(first), Some(exact)) if exact.1 < first.1 => Some(exact),
                (first, _) => first,
            };
            let rss_body = rss_body.min(body.map_or(f64::INFINITY, |(_, rss)| rss));
            match body {
                _ if turned && explained(rss_shift) && rss_shift < FRAME_MARGIN * rss_body => {
                    SpanKind::MagnitudeShift { shift_ut }
                }
                Some((offset, rss)) if explained(rss) => SpanKind::SensorFixed {
                    offset_ut: offset,
                    told_apart: false,
                },
                _ => unexplained,
            }
        }
    };
    Span {
        start: a,
        end: b,
        peak_ut,
        rms_ut,
        kind,
        turned,
        declined: None,
    }
}

/// The constant that best explains residuals `e` — in sensor axes, or in NED through `rot` — and what it leaves.
fn constant(e: &[[f64; 3]], rot: Option<Attitudes<'_>>) -> ([f64; 3], f64) {
    let frame = |i: usize| match rot {
        Some(r) => frames::mat_vec(&r.at(i), e[i]),
        None => e[i],
    };
    let n = e.len() as f64;
    let mean = (0..e.len()).fold([0.0; 3], |s, i| frames::add(s, frame(i)));
    let mean = frames::scale(mean, 1.0 / n);
    let rss = (0..e.len())
        .map(|i| {
            let d = frames::sub(frame(i), mean);
            frames::dot(d, d)
        })
        .sum();
    (mean, rss)
}

/// The offset `δ` (sensor axes) that best explains magnitude residuals `ρ ≈ u·δ`, and what it leaves; None when
/// the directions do not determine it.
fn along(rho: &[f64], unit: &[[f64; 3]]) -> Option<([f64; 3], f64)> {
    let mut m = nalgebra::Matrix3::<f64>::zeros();
    let mut v = nalgebra::Vector3::<f64>::zeros();
    for (r, u) in rho.iter().zip(unit) {
        let u = nalgebra::Vector3::from(*u);
        m += u * u.transpose();
        v += u * *r;
    }
    // A span with a single direction determines only the component along it: regularise the others to zero.
    let trace = m.trace().max(f64::MIN_POSITIVE);
    let d = (m + nalgebra::Matrix3::identity() * (1e-6 * trace)).try_inverse()? * v;
    let rss = rho
        .iter()
        .zip(unit)
        .map(|(r, u)| (r - frames::dot(*u, [d.x, d.y, d.z])).powi(2))
        .sum();
    Some(([d.x, d.y, d.z], rss))
}

/// Gauss–Newton steps of [`off_centre`].
const OFF_CENTRE_STEPS: usize = 20;

/// The offset `d` (sensor axes, calibrated µT) for which the readings `(field_ut + rho)·unit` lie on the sphere of
/// radius `field_ut` around it, and the sum of squares of `|m − d| − field_ut` it leaves; from `start` (the
/// first-order offset) and from the readings' mean (the centre, when the sensor turned through many directions),
/// the better; `None` if the readings do not determine it.
fn off_centre(
    rho: &[f64],
    unit: &[[f64; 3]],
    field_ut: f64,
    start: Option<[f64; 3]>,
) -> Option<([f64; 3], f64)> {
    let readings: Vec<nalgebra::Vector3<f64>> = rho
        .iter()
        .zip(unit)
        .map(|(r, u)| nalgebra::Vector3::from(*u) * (field_ut + r))
        .collect();
    let mean = readings.iter().sum::<nalgebra::Vector3<f64>>() / readings.len().max(1) as f64;
    start
        .map(nalgebra::Vector3::from)
        .into_iter()
        .chain([mean])
        .filter_map(|d| centre_from(&readings, field_ut, d))
        .min_by(|x, y| x.1.total_cmp(&y.1))
}

/// [`off_centre`] by Gauss–Newton from `d`.
fn centre_from(
    readings: &[nalgebra::Vector3<f64>],
    field_ut: f64,
    mut d: nalgebra::Vector3<f64>,
) -> Option<([f64; 3], f64)> {
    for _ in 0..OFF_CENTRE_STEPS {
        let (mut jtj, mut jtr) = (
            nalgebra::Matrix3::<f64>::zeros(),
            nalgebra::Vector3::<f64>::zeros(),
        );
        for m in readings {
            let to = m - d;
            let dist = to.norm();
            if dist == 0.0 {
                continue;
            }
            let j = -to / dist;
            jtj += j * j.transpose();
            jtr += j * (dist - field_ut);
        }
        let step = jtj.try_inverse()? * -jtr;
        d += step;
        if step.norm() < 1e-9 * field_ut.max(1.0) {
            break;
        }
    }
    let rss: f64 = readings
        .iter()
        .map(|m| ((m - d).norm() - field_ut).powi(2))
        .sum();
    rss.is_finite().then_some(([d.x, d.y, d.z], rss))
}

/// The largest angle between the field directions of a span and their mean, degrees.
fn turned_deg(directions: &[[f64; 3]]) -> f64 {
    let mean = directions.iter().fold([0.0; 3], |s, d| frames::add(s, *d));
    let m = frames::norm(mean);
    if m == 0.0 {
        return 180.0;
    }
    let mean = frames::scale(mean, 1.0 / m);
    directions
        .iter()
        .map(|d| {
            let c = frames::dot(*d, mean) / frames::norm(*d).max(f64::MIN_POSITIVE);
            c.clamp(-1.0, 1.0).acos().to_degrees()
        })
        .fold(0.0, f64::max)
}

/// The edges of a modelled span located again by a scan of the constant's window over the span and a margin of
/// half its length on either side: the first sample inside and one past the last.
pub(crate) fn refine_edges(
    span: &Span,
    e: &[[f64; 3]],
    rot: Option<Attitudes<'_>>,
    scale_ut: f64,
) -> (usize, usize) {
    let n = e.len();
    let len = span.end - span.start;
    let lo = span.start.saturating_sub(len / 2);
    let hi = (span.end + len / 2).min(n);
    let world: Vec<[f64; 3]> = match (span.kind, rot) {
        (SpanKind::RoomFixed { .. }, Some(r)) => {
            (lo..hi).map(|i| frames::mat_vec(&r.at(i), e[i])).collect()
        }
        _ => e[lo..hi].to_vec(),
    };
    match scan::window(&world, scale_ut * scale_ut) {
        Some(w) => (lo + w.start, lo + w.end),
        None => (span.start, span.end),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Field directions that turn through a full circle every 200 samples.
    fn turning(n: usize) -> Vec<[f64; 3]> {
        (0..n)
            .map(|i| {
                let (s, c) = (i as f64 * std::f64::consts::TAU / 200.0).sin_cos();
                [0.8 * c, 0.8 * s, 0.6]
            })
            .collect()
    }

    #[test]
    fn two_fields_on_the_board_merged_across_a_lull_are_two_spans() {
        // Samples 100–400 carry one field on the board, 500–900 another; between them a clean lull, all of it one
        // excluded run (as the robust fit's merge across short lulls makes it).
        let n = 1000;
        let mut e = vec![[0.0; 3]; n];
        for (i, v) in e.iter_mut().enumerate() {
            // A little noise-like wobble so that no residual is exactly zero.
            let w = 0.01 * ((i * 7919) % 13) as f64;
            *v = [w, -w, w];
        }
        e[100..400].fill([20.0, 0.0, 0.0]);
        e[500..900].fill([0.0, -15.0, 5.0]);
        let mut kept = vec![true; n];
        kept[100..900].fill(false);
        let dirs = turning(n);
        let residual = Residual::Vector { e: &e, rot: None };
        let found = spans(&residual, &kept, 0.1, &dirs);
        let ranges: Vec<(usize, usize)> = found.iter().map(|s| (s.start, s.end)).collect();
        assert_eq!(ranges, vec![(100, 400), (500, 900)], "{found:?}");
        assert!(
            found
                .iter()
                .all(|s| matches!(s.kind, SpanKind::SensorFixed { .. })),
            "{found:?}"
        );
        // When the second is a field that changes as the sensor moves (no constant explains it), the field on the
        // board is still its own span, and the magnet's pass is not cut into pieces.
        for (k, v) in e[500..900].iter_mut().enumerate() {
            let x = k as f64 / 400.0;
            *v = [40.0 * x * x, -30.0 * x, 10.0 * (1.0 - x)];
        }
        let residual = Residual::Vector { e: &e, rot: None };
        let found = spans(&residual, &kept, 0.1, &dirs);
        let ranges: Vec<(usize, usize)> = found.iter().map(|s| (s.start, s.end)).collect();
        assert_eq!(ranges, vec![(100, 400), (400, 900)], "{found:?}");
        assert!(matches!(found[1].kind, SpanKind::Moving), "{found:?}");
        // And a pass alone stays whole.
        kept[100..500].fill(true);
        let whole = spans(&residual, &kept, 0.1, &dirs);
        assert_eq!(whole.len(), 1, "{whole:?}");
        assert!(matches!(whole[0].kind, SpanKind::Moving), "{whole:?}");
    }

    /// What the scalar method sees of calibrated readings: their directions, and their magnitudes less the field's.
    fn magnitude_of(readings: &[[f64; 3]], field_ut: f64) -> (Vec<[f64; 3]>, Vec<f64>) {
        readings
            .iter()
            .map(|m| {
                (
                    frames::scale(*m, 1.0 / frames::norm(*m)),
                    frames::norm(*m) - field_ut,
                )
            })
            .unzip()
    }

    /// Directions through the whole sphere (a golden-angle spiral, scrambled).
    fn tumbling(n: usize) -> Vec<[f64; 3]> {
        (0..n)
            .map(|i| {
                let j = (i * 7919) % n;
                let z = 1.0 - 2.0 * (j as f64 + 0.5) / n as f64;
                let r = (1.0 - z * z).sqrt();
                let phi = j as f64 * 2.399_963;
                [r * phi.cos(), r * phi.sin(), z]
            })
            .collect()
    }

    #[test]
    fn in_the_magnitude_a_large_field_on_the_board_is_not_one_in_the_room() {
        // 150 µT on the board of a tumbling sensor moves |B| between 100 and 200 µT; first order (u·d) it was a
        // constant shift, "a field fixed in the room". 150 µT fixed in the room adds a constant to |B|.
        let (n, field_ut) = (1000, 50.0);
        let t = tumbling(n);
        for on_board in [true, false] {
            let readings: Vec<[f64; 3]> = (0..n)
                .map(|i| match i {
                    300..700 if on_board => {
                        frames::add(frames::scale(t[i], field_ut), [150.0, 0.0, 0.0])
                    }
                    300..700 => frames::scale(t[i], 180.0),
                    _ => frames::scale(t[i], field_ut),
                })
                .collect();
            let (unit, rho) = magnitude_of(&readings, field_ut);
            let mut kept = vec![true; n];
            kept[300..700].fill(false);
            let residual = Residual::Magnitude {
                rho: &rho,
                unit: &unit,
                field_ut,
            };
            let found = spans(&residual, &kept, 0.1, &unit);
            assert_eq!(found.len(), 1, "{found:?}");
            let shift = matches!(found[0].kind, SpanKind::MagnitudeShift { .. });
            assert_eq!(shift, !on_board, "on the board: {on_board}: {found:?}");
            if let SpanKind::SensorFixed { offset_ut, .. } = found[0].kind {
                assert!(
                    frames::norm(frames::sub(offset_ut, [150.0, 0.0, 0.0])) < 1.0,
                    "{found:?}"
                );
            }
        }
    }

    #[test]
    fn in_the_magnitude_two_fields_on_the_board_merged_across_a_lull_are_two_spans() {
        // The scalar method sees a field d on the board in |F·t + d| (t: the field's true direction): 100–400 one
        // field, 500–900 another, the lull between clean, all of it one excluded run.
        let n = 1000;
        let field_ut = 50.0;
        let readings: Vec<[f64; 3]> = turning(n)
            .iter()
            .enumerate()
            .map(|(i, t)| {
                let d = match i {
                    100..400 => [20.0, 0.0, 0.0],
                    500..900 => [0.0, -15.0, 5.0],
                    _ => [0.0; 3],
                };
                frames::add(frames::scale(*t, field_ut), d)
            })
            .collect();
        let (unit, mut rho) = magnitude_of(&readings, field_ut);
        for (i, r) in rho.iter_mut().enumerate() {
            *r += 0.01 * ((i * 7919) % 13) as f64;
        }
        let mut kept = vec![true; n];
        kept[100..900].fill(false);
        let residual = Residual::Magnitude {
            rho: &rho,
            unit: &unit,
            field_ut,
        };
        let found = spans(&residual, &kept, 0.1, &unit);
        let ranges: Vec<(usize, usize)> = found.iter().map(|s| (s.start, s.end)).collect();
        assert_eq!(ranges, vec![(100, 400), (500, 900)], "{found:?}");
    }

    #[test]
    fn a_field_on_the_board_next_to_a_pass_by_a_magnet_is_its_own_span() {
        // A magnet's pass (a field changing as the sensor moves) from 100 to 400, and straight after it a field on
        // the board from 400 to 700, no lull between: one excluded run, two spans.
        let n = 800;
        let mut e: Vec<[f64; 3]> = (0..n)
            .map(|i| {
                let w = 0.05 * (((i * 7919) % 13) as f64 / 6.0 - 1.0);
                [w, -w, w]
            })
            .collect();
        for (k, v) in e[100..400].iter_mut().enumerate() {
            let x = k as f64 / 300.0;
            let bump = 60.0 * (std::f64::consts::PI * x).sin();
            *v = [bump * x, -bump, 0.5 * bump];
        }
        for v in &mut e[400..700] {
            *v = frames::add(*v, [12.0, -30.0, 8.0]);
        }
        let mut kept = vec![true; n];
        kept[100..700].fill(false);
        let dirs = turning(n);
        let residual = Residual::Vector { e: &e, rot: None };
        let found = spans(&residual, &kept, 0.1, &dirs);
        assert_eq!(found.len(), 2, "{found:?}");
        assert!(matches!(found[0].kind, SpanKind::Moving), "{found:?}");
        assert!(
            matches!(
                found[1].kind,
                SpanKind::SensorFixed {
                    told_apart: true,
                    ..
                }
            ),
            "{found:?}"
        );
        assert!(
            found[1].start.abs_diff(400) <= 10 && found[1].end == 700,
            "{found:?}"
        );
    }

    #[test]
    fn the_stage_models_a_field_on_the_board_and_keeps_the_samples_it_explains() {
        use super::super::testbench::{Bench, on_board, with_setup};
        let bench = Bench::new(1500, &[on_board(10.0, 20.0, [15.0, 0.0, -5.0])], 23);
        with_setup(&bench, |setup, residual| {
            let (_, kept, scale) = bench.base();
            let stage = stage(setup, residual, &kept, scale, &[]);
            assert_eq!(stage.spans.len(), 1, "{:?}", stage.spans);
            assert!(stage.spans[0].modelled());
            let [(effect, times)] = stage.span_effects[..] else {
                panic!("{:?}", stage.span_effects)
            };
            let Effect::BiasWindow { t0_s, t1_s, .. } = effect else {
                panic!("{effect:?}")
            };
            assert!(
                (t0_s - 10.0).abs() < 0.05 && (t1_s - 20.0).abs() < 0.05,
                "{t0_s}–{t1_s}"
            );
            assert_eq!(times.start_s, (t0_s, t0_s));
            let t = &setup.samples.t;
            let inside: Vec<usize> = (0..t.len())
                .filter(|&i| (10.05..19.95).contains(&t[i]))
                .collect();
            assert!(inside.iter().all(|&i| !stage.clean[i]));
            let back = inside.iter().filter(|&&i| stage.included[i]).count();
            assert!(back > 450, "{back} of {} back in the fit", inside.len());
            // Declined, it is left out whole.
            let declined = super::stage(
                setup,
                residual,
                &kept,
                scale,
                &[(0, t.len(), Declined::NoGain)],
            );
            assert!(!declined.spans[0].modelled() && declined.span_effects.is_empty());
            assert!(inside.iter().all(|&i| !declined.included[i]));
        });
    }

    #[test]
    fn one_sample_spikes_are_glitches_and_readings_off_for_a_tenth_of_a_second_a_span() {
        use super::super::testbench::{Bench, with_setup};
        let mut bench = Bench::new(1500, &[], 24);
        // One reading 40 µT off, another 30 µT off ten seconds later: each one reading's fault. Then five readings
        // in a row (0.1 s at 50 Hz) 30 µT off: as long as a magnet passing a few centimetres away takes, and more
        // than the noise, with two such spikes in it, makes by chance in a row.
        bench.raw_ut[300][0] += 40.0;
        bench.raw_ut[800][2] -= 30.0;
        for i in 1200..1205 {
            bench.raw_ut[i][1] -= 30.0;
        }
        with_setup(&bench, |setup, residual| {
            let (_, kept, scale) = bench.base();
            let stage = stage(setup, residual, &kept, scale, &[]);
            assert_eq!(stage.glitches.len(), 2, "{:?}", stage.glitches);
            assert_eq!(stage.spans.len(), 1, "{:?}", stage.spans);
            assert!((stage.spans[0].start..stage.spans[0].end).contains(&1200));
            // Glitches are left out of the fits all the same.
            assert!(!stage.clean[300] && !stage.included[300] && !stage.included[800]);
        });
    }
}
