//! `--plots DIR`: SVG pictures of the diagnosis — the residual against time before and after modelling, the residual
//! against the channel it is blamed on, and the residual over the sphere of field directions.

use std::path::{Path, PathBuf};

use anyhow::Context;
use magcal_calib::diagnosis::{Diagnosis, Residuals};
use magcal_calib::effects::EffectId;
use plotters::prelude::*;

/// Time bins of the residual-against-time plot.
const TIME_BINS: usize = 400;
/// Most points drawn in a scatter plot.
const SCATTER_POINTS: usize = 2000;
/// Bins of the binned means drawn over a scatter plot.
const CHANNEL_BINS: usize = 24;
/// Fewest samples for a cell of the orientation map to be drawn.
const MIN_CELL_SAMPLES: usize = 5;

type PlotResult<T> = Result<T, Box<dyn std::error::Error>>;

/// Writes the plots into `dir` (created if needed) and returns their paths.
pub fn write_plots(dir: &Path, d: &Diagnosis) -> anyhow::Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let mut written = Vec::new();
    let mut plot = |name: &str, draw: &dyn Fn(&Path) -> PlotResult<()>| -> anyhow::Result<()> {
        let path = dir.join(name);
        draw(&path).map_err(|e| anyhow::anyhow!("drawing {}: {e}", path.display()))?;
        written.push(path);
        Ok(())
    };
    let r = &d.residuals;
    if r.t_s.iter().any(|t| *t != 0.0) {
        plot("residual_time.svg", &|p| {
            residual_time(p, r, d.noise_floor_ut)
        })?;
    }
    if let Some((name, values)) = blamed_channel(d) {
        plot("residual_channel.svg", &|p| {
            residual_channel(p, r, name, values)
        })?;
    }
    plot("residual_orientation.svg", &|p| {
        residual_orientation(p, r, d.noise_floor_ut)
    })?;
    Ok(written)
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
    match e.effect.id() {
        EffectId::TemperatureBias | EffectId::TemperatureScale => by_name("temp"),
        EffectId::CurrentBias => e.channel.as_deref().and_then(by_name),
        EffectId::TimeLag | EffectId::RateCoupling => by_name("rotation_rate"),
        _ => by_name("t"),
    }
}

/// Per-sample residual magnitude (RMS over the components).
fn magnitude(res: &[Vec<f64>]) -> Vec<f64> {
    res.iter()
        .map(|r| (r.iter().map(|v| v * v).sum::<f64>() / r.len().max(1) as f64).sqrt())
        .collect()
}

fn residual_time(path: &Path, r: &Residuals, floor_ut: f64) -> PlotResult<()> {
    let (t0, t1) = (r.t_s[0], r.t_s[r.t_s.len() - 1]);
    let bin = |res: &[Vec<f64>]| -> Vec<(f64, f64)> {
        let mut sum = vec![0.0; TIME_BINS];
        let mut count = vec![0usize; TIME_BINS];
        for (t, m) in r.t_s.iter().zip(magnitude(res)) {
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
    let before = bin(&r.base);
    let after = bin(&r.extended);
    let top = before
        .iter()
        .chain(&after)
        .map(|p| p.1)
        .fold(floor_ut, f64::max)
        * 1.1;
    let root = SVGBackend::new(path, (1000, 420)).into_drawing_area();
    root.fill(&WHITE)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "residual RMS against time, before and after modelling",
            ("sans-serif", 18),
        )
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(t0..t1, 0.0..top)?;
    chart
        .configure_mesh()
        .x_desc("t (s)")
        .y_desc("residual RMS (µT)")
        .draw()?;
    chart
        .draw_series(LineSeries::new(before, RED.stroke_width(1)))?
        .label("base fit")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RED));
    chart
        .draw_series(LineSeries::new(after, BLUE.stroke_width(1)))?
        .label("with the effects found")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLUE));
    chart
        .draw_series(LineSeries::new(
            vec![(t0, floor_ut), (t1, floor_ut)],
            BLACK.stroke_width(1),
        ))?
        .label("noise floor")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK));
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()?;
    root.present()?;
    Ok(())
}

/// The residual component most correlated with the channel, against the channel.
fn residual_channel(path: &Path, r: &Residuals, name: &str, values: &[f64]) -> PlotResult<()> {
    let dims = r.base.first().map_or(1, Vec::len);
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
    let pick = |res: &[Vec<f64>]| -> Vec<(f64, f64)> {
        values
            .iter()
            .zip(res)
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
    let means = |res: &[Vec<f64>]| -> Vec<(f64, f64)> {
        let mut sum = [0.0; CHANNEL_BINS];
        let mut count = [0usize; CHANNEL_BINS];
        for (c, v) in values.iter().zip(res) {
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
    let root = SVGBackend::new(path, (800, 500)).into_drawing_area();
    root.fill(&WHITE)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            format!("residual ({axis}) against {name}: samples and binned means"),
            ("sans-serif", 18),
        )
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(lo..hi, -span..span)?;
    chart
        .configure_mesh()
        .x_desc(name)
        .y_desc(format!("residual {axis} (µT)"))
        .draw()?;
    chart.draw_series(
        before
            .iter()
            .map(|p| Circle::new(*p, 2, RED.mix(0.25).filled())),
    )?;
    chart.draw_series(
        after
            .iter()
            .map(|p| Circle::new(*p, 2, BLUE.mix(0.25).filled())),
    )?;
    chart
        .draw_series(LineSeries::new(means(&r.base), RED.stroke_width(3)))?
        .label("base fit")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RED.stroke_width(3)));
    chart
        .draw_series(LineSeries::new(means(&r.extended), BLUE.stroke_width(3)))?
        .label("with the effects found")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLUE.stroke_width(3)));
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()?;
    root.present()?;
    Ok(())
}

/// The residual RMS in cells of azimuth × elevation of the field direction (sensor axes), base fit beside extended
/// fit, coloured from blue (at or below the noise floor) to red (twice the floor or more).
fn residual_orientation(path: &Path, r: &Residuals, floor_ut: f64) -> PlotResult<()> {
    const AZ: usize = 36;
    const EL: usize = 18;
    let grid = |res: &[Vec<f64>]| -> Vec<Option<f64>> {
        let mut sum = vec![0.0; AZ * EL];
        let mut count = vec![0usize; AZ * EL];
        for (d, m) in r.direction.iter().zip(magnitude(res)) {
            let az = d[1].atan2(d[0]).to_degrees() + 180.0;
            let el = d[2].clamp(-1.0, 1.0).asin().to_degrees() + 90.0;
            let cell = ((el / 10.0) as usize).min(EL - 1) * AZ + ((az / 10.0) as usize).min(AZ - 1);
            sum[cell] += m * m;
            count[cell] += 1;
        }
        (0..AZ * EL)
            .map(|c| (count[c] >= MIN_CELL_SAMPLES).then(|| (sum[c] / count[c] as f64).sqrt()))
            .collect()
    };
    let (before, after) = (grid(&r.base), grid(&r.extended));
    let root = SVGBackend::new(path, (1100, 380)).into_drawing_area();
    root.fill(&WHITE)?;
    let (left, right) = root.split_horizontally(550);
    for (area, cells, title) in [
        (left, &before, "base fit"),
        (right, &after, "with the effects found"),
    ] {
        let mut chart = ChartBuilder::on(&area)
            .caption(
                format!("{title}: blue = noise floor {floor_ut:.3} µT, red ≥ twice it"),
                ("sans-serif", 14),
            )
            .margin(10)
            .x_label_area_size(35)
            .y_label_area_size(45)
            .build_cartesian_2d(-180.0..180.0, -90.0..90.0)?;
        chart
            .configure_mesh()
            .x_desc("azimuth in sensor x–y (°)")
            .y_desc("elevation towards +z (°)")
            .draw()?;
        chart.draw_series(cells.iter().enumerate().filter_map(|(c, v)| {
            let v = (*v)?;
            let (az, el) = (
                (c % AZ) as f64 * 10.0 - 180.0,
                (c / AZ) as f64 * 10.0 - 90.0,
            );
            let shade = (v / floor_ut - 1.0).clamp(0.0, 1.0);
            let color = RGBColor(
                (255.0 * shade) as u8,
                (80.0 * (1.0 - shade)) as u8,
                (255.0 * (1.0 - shade)) as u8,
            );
            Some(Rectangle::new(
                [(az, el), (az + 10.0, el + 10.0)],
                color.filled(),
            ))
        }))?;
    }
    root.present()?;
    Ok(())
}
