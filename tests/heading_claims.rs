//! Issue 34, row 6 and acceptance 3: are the heading-error claims honest on partial coverage? The summary's "left
//! after it (one standard deviation)" is a 1σ claim at each heading (`Curve::left_deg`, from the fit's covariance
//! and the residual the noise does not explain, `crates/app/src/heading.rs`); a calibrated claim is exceeded by the
//! actual error about 32 % of the time, and twice over about 5 % (a normal error).
//!
//! Simulated recordings of a sensor turned by hand (a smooth random walk of the field's direction in sensor axes, 50
//! Hz, 1500 samples, 0.25 µT of noise per axis, hard and soft iron drawn per seed) through a cap of directions 70°
//! about a random axis, a band within 25° of a random great circle (a flat turn with some tilting), or the whole
//! sphere; for each region and method, 100 accepted fits (refusals counted, not judged), fitted as `magcal-fit` fits
//! them (robust base fit, diagnosis). At every 10° of heading and both faces, the actual heading error of the fitted
//! calibration — the true field at that heading through the true sensor, then the fitted model — is compared with
//! the claim there. The vector method's sensor sits 2° off its axes (which it fits); the scalar method's is
//! symmetric (the rotation it cannot see is not in its claim, and the summary says so).
//!
//! Asserted (≤ 32 % beyond the claim, ≤ 5 % beyond twice it), per face: the claim at each heading, the claim's RMS
//! over 360 headings against the actual RMS, and the worst heading's claim (`Curve::left_worst_deg`, drawn from the
//! covariance) against the actual worst over 360 headings. Reported, not asserted: the actual worst against the
//! largest per-heading claim, what the summary's "worst" was before it was drawn (the largest of 360 correlated
//! errors exceeds it far more often than one standard deviation should).
//!
//! The table is the one in docs/reading-the-results.md (between the `heading-claims` markers): the test fails when
//! they differ. `MAGCAL_BLESS=1` rewrites it. Heavy: `cargo test --release --test heading_claims -- --ignored
//! --nocapture` (CI runs it; about a minute on two cores).

use std::path::Path;

use magcal_app::calibrate::calibrate;
use magcal_app::field::ReferenceField;
use magcal_app::fit::Method;
use magcal_app::verdict::assess;
use magcal_calib::frames;
use magcal_recording::Recording;
use nalgebra::{Matrix3, Rotation3, Vector3};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal, UnitSphere};
use rayon::prelude::*;

const FIELD_NED_UT: [f64; 3] = [20.0, 1.0, 45.0];
const NOISE_UT: f64 = 0.25;
const SAMPLES: usize = 1500;
const RATE_HZ: f64 = 50.0;
/// Accepted fits per region and method.
const FITS: usize = 100;
/// Seeds tried at most per region and method.
const SEEDS: u64 = 400;
/// The turn's angular speed, rad/s.
const SPEED_RAD_S: f64 = 1.2;

/// Where the field's direction goes in sensor axes.
#[derive(Clone, Copy, Debug)]
enum Region {
    /// Within this many degrees of an axis.
    Cap(f64),
    /// Within this many degrees of a great circle.
    Band(f64),
    /// Everywhere.
    Sphere,
}

impl Region {
    fn name(self) -> String {
        match self {
            Region::Cap(d) => format!("cap {d:.0}°"),
            Region::Band(d) => format!("band ±{d:.0}°"),
            Region::Sphere => "full sphere".to_owned(),
        }
    }

    /// Whether `d` is inside, for the axis `axis`.
    fn holds(self, d: Vector3<f64>, axis: Vector3<f64>) -> bool {
        match self {
            Region::Cap(deg) => d.dot(&axis) >= deg.to_radians().cos(),
            Region::Band(deg) => d.dot(&axis).abs() <= deg.to_radians().sin(),
            Region::Sphere => true,
        }
    }
}

/// A unit vector orthogonal to `d`.
fn tangent(d: Vector3<f64>, rng: &mut ChaCha8Rng) -> Vector3<f64> {
    let r: [f64; 3] = UnitSphere.sample(rng);
    let v = Vector3::from(r);
    (v - d * d.dot(&v)).normalize()
}

/// A smooth random walk of directions inside `region`: the heading of the motion turns at random, and turns back
/// inside when the walk would leave.
fn walk(region: Region, axis: Vector3<f64>, rng: &mut ChaCha8Rng) -> Vec<Vector3<f64>> {
    let step = SPEED_RAD_S / RATE_HZ;
    let mut d = match region {
        Region::Cap(_) => axis,
        Region::Band(_) => tangent(axis, rng),
        Region::Sphere => Vector3::from(UnitSphere.sample(rng) as [f64; 3]),
    };
    let mut v = tangent(d, rng);
    let turn = Normal::new(0.0, 0.35).unwrap();
    let mut out = Vec::with_capacity(SAMPLES);
    while out.len() < SAMPLES {
        let w: f64 = turn.sample(rng);
        v = Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(d), w) * v;
        let next = (d * step.cos() + v * step.sin()).normalize();
        if region.holds(next, axis) {
            v = (v * step.cos() - d * step.sin()).normalize();
            d = next;
            out.push(d);
        } else {
            // Turn back towards the region's middle: the axis (cap) or the great circle (band).
            let inward = match region {
                Region::Cap(_) => axis - d * d.dot(&axis),
                _ => -(axis - d * d.dot(&axis)) * d.dot(&axis).signum(),
            };
            if inward.norm() > 1e-9 {
                v = (inward.normalize() + tangent(d, rng) * 0.3).normalize();
                v = (v - d * d.dot(&v)).normalize();
            }
        }
    }
    out
}

/// The true sensor of a seed: `A` (with a 2° mounting rotation for the vector method, symmetric for the scalar one)
/// and `b`, µT.
fn sensor(method: Method, rng: &mut ChaCha8Rng) -> (Matrix3<f64>, Vector3<f64>) {
    let mut s = Matrix3::identity();
    for j in 0..3 {
        s[(j, j)] += rng.random_range(-0.08..0.08);
        for k in j + 1..3 {
            let x = rng.random_range(-0.03..0.03);
            s[(j, k)] = x;
            s[(k, j)] = x;
        }
    }
    let a = if method == Method::Vector {
        let axis: [f64; 3] = UnitSphere.sample(rng);
        Rotation3::from_axis_angle(
            &nalgebra::Unit::new_normalize(Vector3::from(axis)),
            2f64.to_radians(),
        )
        .into_inner()
            * s
    } else {
        s
    };
    let b = Vector3::from(std::array::from_fn::<f64, 3, _>(|_| {
        rng.random_range(-30.0..30.0)
    }));
    (a, b)
}

/// What one fit's claims met: the actual error over the claim at every 10° of heading on both faces (the curve), and
/// per face the actual worst and RMS over 360 headings over the summary's worst and RMS claims, and the actual worst
/// over the largest per-heading claim.
struct Ratios {
    each: Vec<f64>,
    worst: Vec<f64>,
    rms: Vec<f64>,
    largest: Vec<f64>,
}

/// The ratios of one seed's fit; `None` when the fit refuses.
fn ratios(method: Method, region: Region, seed: u64) -> Option<Ratios> {
    let mut rng = ChaCha8Rng::seed_from_u64(
        seed + 10_000 * matches!(method, Method::Scalar) as u64
            + match region {
                Region::Cap(_) => 100_000,
                Region::Band(_) => 200_000,
                Region::Sphere => 300_000,
            },
    );
    let axis = Vector3::from(UnitSphere.sample(&mut rng) as [f64; 3]);
    let (a, b) = sensor(method, &mut rng);
    let f = frames::norm(FIELD_NED_UT);
    let fields: Vec<(Vector3<f64>, Vector3<f64>)> = walk(region, axis, &mut rng)
        .into_iter()
        .map(|d| (d * f, d * f))
        .collect();
    fit_and_compare(method, (a, b), &fields, &mut rng).map(|(r, _)| r)
}

/// Fits a recording of the sensor `(A, b)` that met `fields` — per sample the true field and the reference's (the
/// uniform field the recording's metadata gives), both in sensor axes, µT — with noise, as `magcal-fit` fits it,
/// and compares its heading claims with the fitted calibration's actual heading errors. Also returns whether the
/// fit's warnings or verdict hint at another convention or clock for the reference. `None` when the fit refuses.
fn fit_and_compare(
    method: Method,
    (a, b): (Matrix3<f64>, Vector3<f64>),
    fields: &[(Vector3<f64>, Vector3<f64>)],
    rng: &mut ChaCha8Rng,
) -> Option<(Ratios, bool)> {
    let a_inv = a.try_inverse().unwrap();
    let noise = Normal::new(0.0, NOISE_UT).unwrap();
    let mut text = format!(
        "# magcal-recording v1\n# field_ned_ut: {}, {}, {}\n",
        FIELD_NED_UT[0], FIELD_NED_UT[1], FIELD_NED_UT[2]
    );
    text += if method == Method::Vector {
        "t,mx,my,mz,rx,ry,rz\n"
    } else {
        "t,mx,my,mz\n"
    };
    for (i, (field, reference)) in fields.iter().enumerate() {
        let raw = a_inv * (field - b);
        let m: [f64; 3] = std::array::from_fn(|k| raw[k] + noise.sample(rng));
        text += &format!(
            "{:.4},{:.5},{:.5},{:.5}",
            i as f64 / RATE_HZ,
            m[0],
            m[1],
            m[2]
        );
        if method == Method::Vector {
            text += &format!(",{:.5},{:.5},{:.5}", reference.x, reference.y, reference.z);
        }
        text.push('\n');
    }
    let rec = Recording::from_reader("claims.csv", text.as_bytes()).unwrap();
    let reference = ReferenceField::Vector {
        field_ned_ut: FIELD_NED_UT,
        source: "study".into(),
    };
    let cal = calibrate(&rec, method, reference, true).ok()?;
    let assessment = assess(&cal, &rec, false);
    let blames_reference = cal
        .warnings
        .iter()
        .chain([&assessment.verdict.reason, &assessment.verdict.todo])
        .any(|w| {
            [
                "another convention",
                "conjugate",
                "out of step",
                "one clock",
            ]
            .iter()
            .any(|h| w.contains(h))
        });
    let heading = assessment.heading?;
    let model = cal.model();
    let field_level = [heading.field.horizontal_ut, 0.0, heading.field.vertical_ut];
    let mut out = Ratios {
        each: Vec::new(),
        worst: Vec::new(),
        rms: Vec::new(),
        largest: Vec::new(),
    };
    for curve in &heading.curves {
        let (mut worst, mut ss) = (0.0f64, 0.0);
        for k in 0..360 {
            let r = curve.face.sensor_to_level(f64::from(k as u32).to_radians());
            let truth = Vector3::from(frames::mat_t_vec(&r, field_level));
            let raw = a_inv * (truth - b);
            let calibrated = model.apply([raw.x, raw.y, raw.z], &magcal_calib::Inputs::NONE);
            let w = frames::mat_vec(&r, calibrated);
            let actual_deg = -w[1].atan2(w[0]).to_degrees();
            worst = worst.max(actual_deg.abs());
            ss += actual_deg * actual_deg;
            if k % 10 == 0 {
                out.each.push(actual_deg.abs() / curve.left_deg[k]);
            }
        }
        // This face's worst and RMS claims over 360 headings (the summary's are the worse face's).
        let largest = curve.left_deg.iter().fold(0.0f64, |m, e| m.max(*e));
        let claim_rms = (curve.left_deg.iter().map(|e| e * e).sum::<f64>() / 360.0).sqrt();
        out.worst.push(worst / curve.left_worst_deg);
        out.rms.push((ss / 360.0).sqrt() / claim_rms);
        out.largest.push(worst / largest);
    }
    Some((out, blames_reference))
}

/// The shares of `ratios` above 1 and above 2.
fn beyond(ratios: &[f64]) -> (f64, f64) {
    let share =
        |k: f64| ratios.iter().filter(|z| **z > k).count() as f64 / ratios.len().max(1) as f64;
    (share(1.0), share(2.0))
}

/// One row of the study.
struct Row {
    region: Region,
    method: Method,
    fitted: usize,
    refused: usize,
    each: (f64, f64),
    worst: (f64, f64),
    rms: (f64, f64),
    largest: (f64, f64),
}

fn study(region: Region, method: Method) -> Row {
    let (mut each, mut worst, mut rms, mut largest) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let (mut fitted, mut refused) = (0, 0);
    // Seeds in batches on all threads, in order, until FITS are accepted.
    let mut next = 0;
    while fitted < FITS && next < SEEDS {
        let batch = (FITS - fitted).max(8) as u64;
        let runs: Vec<Option<Ratios>> = (next..(next + batch).min(SEEDS))
            .into_par_iter()
            .map(|seed| ratios(method, region, seed))
            .collect();
        next += batch;
        for run in runs {
            if fitted == FITS {
                break;
            }
            match run {
                Some(r) => {
                    fitted += 1;
                    each.extend(r.each);
                    worst.extend(r.worst);
                    rms.extend(r.rms);
                    largest.extend(r.largest);
                }
                None => refused += 1,
            }
        }
    }
    Row {
        region,
        method,
        fitted,
        refused,
        each: beyond(&each),
        worst: beyond(&worst),
        rms: beyond(&rms),
        largest: beyond(&largest),
    }
}

/// Compares `table` with the one between the markers `begin` and `end` of docs/reading-the-results.md, or writes it
/// there with `MAGCAL_BLESS=1`; a failure when they differ.
fn docs_table(begin: &str, end: &str, table: &str) -> Option<String> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/reading-the-results.md");
    let text = std::fs::read_to_string(&path).unwrap();
    let (head, rest) = text
        .split_once(begin)
        .unwrap_or_else(|| panic!("{}: no {begin}", path.display()));
    let (old, tail) = rest
        .split_once(end)
        .unwrap_or_else(|| panic!("{}: no {end}", path.display()));
    if std::env::var("MAGCAL_BLESS").is_ok() {
        std::fs::write(&path, format!("{head}{begin}{table}{end}{tail}")).unwrap();
        None
    } else {
        (old != table).then(|| {
            format!(
                "{}'s table after {} differs from the study's (MAGCAL_BLESS=1 rewrites it):\n{old}",
                path.display(),
                begin.trim_end()
            )
        })
    }
}

const BEGIN: &str = "<!-- heading-claims: begin (tests/heading_claims.rs) -->\n";
const END: &str = "<!-- heading-claims: end -->";

#[test]
#[ignore = "statistics over 600 simulated fits: run in release (CI does)"]
fn heading_claims_are_calibrated_on_caps_bands_and_the_sphere() {
    let mut table = String::from(
        "| coverage | method | fits (refused) | at each heading: beyond 1σ, twice it | the RMS over headings: \
         beyond its claim, twice it | the worst heading: beyond its claim, twice it | the worst heading against the \
         largest per-heading claim (not asserted) |\n\
         |---|---|---|---|---|---|---|\n",
    );
    let mut failures = Vec::new();
    let started = std::time::Instant::now();
    let pct = |(one, two): (f64, f64)| format!("{:.0} %, {:.1} %", 100.0 * one, 100.0 * two);
    for region in [Region::Cap(70.0), Region::Band(25.0), Region::Sphere] {
        for method in [Method::Vector, Method::Scalar] {
            let r = study(region, method);
            table += &format!(
                "| {} | {} | {} ({}) | {} | {} | {} | {} |\n",
                r.region.name(),
                r.method.as_str(),
                r.fitted,
                r.refused,
                pct(r.each),
                pct(r.rms),
                pct(r.worst),
                pct(r.largest)
            );
            eprintln!(
                "{:.0} s: {}",
                started.elapsed().as_secs_f64(),
                table.lines().last().unwrap_or_default()
            );
            if r.fitted < FITS {
                failures.push(format!(
                    "{}, {:?}: {} fits",
                    r.region.name(),
                    r.method,
                    r.fitted
                ));
            }
            // A calibrated claim: exceeded at most as often as a normal error's one standard deviation (31.7 %),
            // twice over at most as often as its two (4.6 %).
            for (what, (one, two)) in [
                ("each heading", r.each),
                ("RMS", r.rms),
                ("worst heading", r.worst),
            ] {
                if one > 0.32 || two > 0.05 {
                    failures.push(format!(
                        "{}, {:?}, {what}: beyond the claim {:.1} %, twice it {:.1} %",
                        r.region.name(),
                        r.method,
                        100.0 * one,
                        100.0 * two
                    ));
                }
            }
        }
    }
    println!("{table}");
    failures.extend(docs_table(BEGIN, END, &table));
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// How the sensor goes through a field that is not the same everywhere along its path (issue 37, acceptance 5).
#[derive(Clone, Copy, Debug)]
enum Route {
    /// Turned by hand while it wanders about the room.
    Hand,
    /// Turned by a robot about a point the sensor sits off by a lever arm.
    Robot,
}

impl Route {
    fn name(self) -> &'static str {
        match self {
            Route::Hand => "by hand",
            Route::Robot => "robot",
        }
    }
}

/// The attitudes (sensor → NED) of a path: by hand, an angular velocity that wanders (each component a smoothed
/// random walk, about [`SPEED_RAD_S`] in all); a robot, whole turns at [`SPEED_RAD_S`] about a few axes of the
/// sensor in turn.
fn attitudes(route: Route, rng: &mut ChaCha8Rng) -> Vec<Rotation3<f64>> {
    let dt = 1.0 / RATE_HZ;
    let mut r = Rotation3::from_axis_angle(
        &nalgebra::Unit::new_normalize(Vector3::from(UnitSphere.sample(rng) as [f64; 3])),
        rng.random_range(0.0..std::f64::consts::TAU),
    );
    let mut out = Vec::with_capacity(SAMPLES);
    match route {
        Route::Hand => {
            let kick = Normal::new(0.0, 0.25).unwrap();
            let mut w = Vector3::from(UnitSphere.sample(rng) as [f64; 3]) * SPEED_RAD_S;
            while out.len() < SAMPLES {
                w += Vector3::from(std::array::from_fn::<f64, 3, _>(|_| kick.sample(rng)));
                w = w.normalize() * SPEED_RAD_S;
                r *= Rotation3::new(w * dt);
                out.push(r);
            }
        }
        Route::Robot => {
            while out.len() < SAMPLES {
                let axis = Vector3::from(UnitSphere.sample(rng) as [f64; 3]);
                let steps = (std::f64::consts::TAU / SPEED_RAD_S * RATE_HZ) as usize;
                for _ in 0..steps.min(SAMPLES - out.len()) {
                    r *= Rotation3::new(axis * SPEED_RAD_S * dt);
                    out.push(r);
                }
            }
        }
    }
    out
}

/// The field's change along a path (NED, µT) about its mean, scaled so that the fields of two samples differ by at
/// most `span_ut`: by hand, the field where the sensor has wandered to (sines of 5–30 s periods in each direction);
/// a robot, a field gradient (of a field without sources there) times the position of a sensor 0.2 m off the point
/// it is turned about.
fn field_change(
    route: Route,
    attitudes: &[Rotation3<f64>],
    span_ut: f64,
    rng: &mut ChaCha8Rng,
) -> Vec<Vector3<f64>> {
    let raw: Vec<Vector3<f64>> = match route {
        Route::Hand => {
            let waves: Vec<(Vector3<f64>, f64, f64)> = (0..4)
                .map(|_| {
                    (
                        Vector3::from(UnitSphere.sample(rng) as [f64; 3]),
                        rng.random_range(5.0..30.0),
                        rng.random_range(0.0..std::f64::consts::TAU),
                    )
                })
                .collect();
            (0..attitudes.len())
                .map(|i| {
                    let t = i as f64 / RATE_HZ;
                    waves
                        .iter()
                        .map(|(v, period_s, phase)| {
                            v * (std::f64::consts::TAU * t / period_s + phase).sin()
                        })
                        .sum()
                })
                .collect()
        }
        Route::Robot => {
            // A field without sources where the sensor goes: its gradient is symmetric (no curl) and traceless (no
            // divergence).
            let m = Matrix3::from_fn(|_, _| rng.random_range(-1.0..1.0));
            let symmetric = (m + m.transpose()) * 0.5;
            let gradient = symmetric - Matrix3::identity() * (symmetric.trace() / 3.0);
            let lever = Vector3::from(UnitSphere.sample(rng) as [f64; 3]) * 0.2;
            attitudes.iter().map(|r| gradient * (r * lever)).collect()
        }
    };
    let mean = raw.iter().sum::<Vector3<f64>>() / raw.len() as f64;
    let centred: Vec<Vector3<f64>> = raw.iter().map(|v| v - mean).collect();
    let widest = centred
        .iter()
        .flat_map(|u| centred.iter().step_by(25).map(move |v| (u - v).norm()))
        .fold(0.0f64, f64::max);
    centred.iter().map(|v| v * (span_ut / widest)).collect()
}

/// Seeds per path and method of the path-field study.
const PATH_SEEDS: u64 = 200;

/// One seed of the path-field study: the actual worst heading error over the summary's claim (the worse face's of
/// each), and whether the fit blamed the reference's convention or clock; `None` when the fit refuses.
fn path_seed(route: Route, method: Method, seed: u64) -> Option<(f64, bool)> {
    let mut rng = ChaCha8Rng::seed_from_u64(
        seed + 500_000
            + 10_000 * matches!(method, Method::Scalar) as u64
            + 1_000 * matches!(route, Route::Robot) as u64,
    );
    let (a, b) = sensor(method, &mut rng);
    let turns = attitudes(route, &mut rng);
    let span_ut = rng.random_range(1.0..5.0);
    let change = field_change(route, &turns, span_ut, &mut rng);
    let field = Vector3::from(FIELD_NED_UT);
    let fields: Vec<(Vector3<f64>, Vector3<f64>)> = turns
        .iter()
        .zip(&change)
        .map(|(r, c)| (r.inverse() * (field + c), r.inverse() * field))
        .collect();
    let (ratios, blames) = fit_and_compare(method, (a, b), &fields, &mut rng)?;
    Some((ratios.worst.iter().fold(0.0, |m: f64, x| m.max(*x)), blames))
}

const PATH_BEGIN: &str = "<!-- path-field: begin (tests/heading_claims.rs) -->\n";
const PATH_END: &str = "<!-- path-field: end -->";

#[test]
#[ignore = "statistics over 800 simulated fits: run in release (CI does)"]
fn heading_claims_hold_through_a_field_that_varies_along_the_path() {
    let mut table = String::from(
        "| path | method | fits (refused) | worst heading beyond its claim | beyond twice it | the reference's \
         convention or clock blamed |\n|---|---|---|---|---|---|\n",
    );
    let mut failures = Vec::new();
    for route in [Route::Hand, Route::Robot] {
        for method in [Method::Vector, Method::Scalar] {
            let runs: Vec<Option<(f64, bool)>> = (0..PATH_SEEDS)
                .into_par_iter()
                .map(|seed| path_seed(route, method, seed))
                .collect();
            let fits: Vec<(f64, bool)> = runs.iter().flatten().copied().collect();
            let n = fits.len().max(1) as f64;
            let share = |k: f64| fits.iter().filter(|(r, _)| *r > k).count() as f64 / n;
            let blamed = fits.iter().filter(|(_, b)| *b).count();
            table += &format!(
                "| {} | {} | {} ({}) | {:.0} % | {:.1} % | {} |\n",
                route.name(),
                method.as_str(),
                fits.len(),
                runs.len() - fits.len(),
                100.0 * share(1.0),
                100.0 * share(2.0),
                blamed
            );
            eprintln!("{}", table.lines().last().unwrap_or_default());
            // Covered: the actual worst within twice the one-standard-deviation claim (where a normal error is 95 %
            // of the time) in at least 90 % of the vector fits; no hint at the reference's convention or clock from
            // either method. The scalar method's claims do not hold here yet (the rows say by how much): a magnitude
            // that changes with the sensor's attitude bends the fitted ellipsoid the same way in any stretch of the
            // path, so neither the residual nor the halves' disagreement shows it.
            let covered = method == Method::Scalar || share(2.0) <= 0.10;
            if !covered || blamed > 0 || fits.len() < PATH_SEEDS as usize / 2 {
                failures.push(table.lines().last().unwrap_or_default().to_owned());
            }
        }
    }
    println!("{table}");
    failures.extend(docs_table(PATH_BEGIN, PATH_END, &table));
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
