//! Where the base model's residual departs from the noise: which axes, which time spans, which orientations, and
//! which recorded channel it follows.

/// A time span where the residual is above the noise.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Segment {
    /// Start, s.
    pub t0_s: f64,
    /// End, s.
    pub t1_s: f64,
    /// Residual RMS inside, µT.
    pub rms_ut: f64,
}

/// The field direction (in sensor axes) where the residual is largest.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Orientation {
    /// The sensor axis the field points along, e.g. `"+X"`.
    pub direction: &'static str,
    /// Residual RMS there, µT.
    pub rms_ut: f64,
    /// Residual RMS in the other directions, µT.
    pub elsewhere_rms_ut: f64,
}

/// Where the mismatch is.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Located {
    /// Axes whose residual exceeds the noise floor (`x`, `y`, `z`; `|B|` for the scalar method).
    pub axes: Vec<&'static str>,
    /// Residual RMS per axis (one entry for the scalar method), µT.
    pub axis_rms_ut: Vec<f64>,
    /// Time spans where the residual is above the noise.
    pub segments: Vec<Segment>,
    /// The orientation with the largest residual, if it stands out.
    pub orientation: Option<Orientation>,
    /// The recorded channel the residual follows (`temp`, `i_<name>`, `t`, `rotation_rate`), if any.
    pub channel: Option<String>,
    /// The fraction of the residual's variance that channel explains.
    pub channel_share: f64,
}

/// Per-sample components (one per calibrated axis, or one: |B|), `dims` values a sample, in one vector.
#[derive(Clone, Debug, PartialEq)]
pub struct Components {
    /// Components per sample.
    pub dims: usize,
    /// The values, sample after sample.
    pub values: Vec<f64>,
}

impl Components {
    /// The first `dims` components of each residual.
    pub(crate) fn of<'r>(residuals: impl Iterator<Item = &'r [f64; 3]>, dims: usize) -> Components {
        let mut values = Vec::with_capacity(residuals.size_hint().0 * dims);
        for e in residuals {
            values.extend_from_slice(&e[..dims]);
        }
        Components { dims, values }
    }

    /// The first `dims` components of each residual, taking the residuals' memory when they are all kept (`dims` 3):
    /// a per-sample vector the size of the residuals is not held twice.
    pub(crate) fn from_residuals(residuals: Vec<[f64; 3]>, dims: usize) -> Components {
        if dims == 3 {
            return Components {
                dims,
                values: residuals.into_flattened(),
            };
        }
        Components::of(residuals.iter(), dims)
    }

    /// Samples held.
    pub fn len(&self) -> usize {
        self.values.len() / self.dims.max(1)
    }

    /// Whether no sample is held.
    pub fn is_empty(&self) -> bool {
        self.values.is_empty()
    }

    /// Each sample's components, in order.
    pub fn iter(&self) -> std::slice::ChunksExact<'_, f64> {
        self.values.chunks_exact(self.dims.max(1))
    }
}

/// A residual above the noise by this factor (in RMS) is a mismatch worth locating.
const EXCESS: f64 = 1.2;

/// Locates the mismatch in per-sample residuals (`res[i]`: one or three components) against the per-axis noise floor.
pub(crate) fn locate(
    res: &Components,
    floor_ut: &[f64],
    t: Option<&[f64]>,
    directions: &[[f64; 3]],
    channels: &[(&str, &[f64])],
) -> Located {
    let n = res.len();
    let dims = floor_ut.len();
    if n == 0 {
        return Located::default();
    }
    let nf = n as f64;
    let axis_rms_ut: Vec<f64> = (0..dims)
        .map(|j| (res.iter().map(|r| r[j] * r[j]).sum::<f64>() / nf).sqrt())
        .collect();
    // Significant excess: the mean square's ratio to the floor beyond 3 standard errors of a χ² mean, and large.
    let names: &[&'static str] = if dims == 3 {
        &["x", "y", "z"]
    } else {
        &["|B|"]
    };
    let axes = (0..dims)
        .filter(|&j| {
            let ratio2 = (axis_rms_ut[j] / floor_ut[j]).powi(2);
            ratio2 - 1.0 > 3.0 * (2.0 / nf).sqrt() && axis_rms_ut[j] > EXCESS * floor_ut[j]
        })
        .map(|j| names[j])
        .collect();
    let energy: Vec<f64> = res
        .iter()
        .map(|r| r.iter().map(|v| v * v).sum::<f64>() / dims as f64)
        .collect();
    let floor_rms = (floor_ut.iter().map(|f| f * f).sum::<f64>() / dims as f64).sqrt();
    let segments = match t {
        Some(t) => segments(&energy, t, floor_rms),
        None => Vec::new(),
    };
    let orientation = orientation(&energy, directions, floor_rms);
    let (channel, channel_share) = follows(res, channels);
    Located {
        axes,
        axis_rms_ut,
        segments,
        orientation,
        channel,
        channel_share,
    }
}

/// Binary segmentation of the residual energy for changes in its mean; the spans whose RMS is above the noise.
fn segments(energy: &[f64], t: &[f64], floor_rms: f64) -> Vec<Segment> {
    let n = energy.len();
    let min_len = (n / 100).max(20);
    // Noise of the energy sequence, from first differences (robust to the changes being looked for).
    let mut d: Vec<f64> = energy.windows(2).map(|w| (w[1] - w[0]).abs()).collect();
    if d.is_empty() {
        return Vec::new();
    }
    let mid = d.len() / 2;
    let mad = *d.select_nth_unstable_by(mid, f64::total_cmp).1;
    let var = (mad / 0.6745 / std::f64::consts::SQRT_2).powi(2).max(1e-30);
    let penalty = 3.0 * (n as f64).ln() * var;
    let mut prefix = vec![0.0; n + 1];
    for i in 0..n {
        prefix[i + 1] = prefix[i] + energy[i];
    }
    let mut cuts = vec![0, n];
    let mut stack = vec![(0, n)];
    while let Some((a, b)) = stack.pop() {
        if b - a < 2 * min_len || cuts.len() > 17 {
            continue;
        }
        let total = prefix[b] - prefix[a];
        let best = (a + min_len..=b - min_len)
            .map(|k| {
                let (l, r) = ((k - a) as f64, (b - k) as f64);
                let ml = (prefix[k] - prefix[a]) / l;
                let mr = (total - (prefix[k] - prefix[a])) / r;
                (k, l * r / (l + r) * (ml - mr).powi(2))
            })
            .max_by(|x, y| x.1.total_cmp(&y.1));
        if let Some((k, gain)) = best
            && gain > penalty
        {
            cuts.push(k);
            stack.push((a, k));
            stack.push((k, b));
        }
    }
    cuts.sort_unstable();
    let mut out: Vec<Segment> = Vec::new();
    for w in cuts.windows(2) {
        let (a, b) = (w[0], w[1]);
        let rms = ((prefix[b] - prefix[a]) / (b - a) as f64).sqrt();
        if rms <= EXCESS * floor_rms {
            continue;
        }
        let (t0, t1) = (t[a], t[b - 1]);
        match out.last_mut() {
            // Merge neighbours that are both above the noise.
            Some(last) if (last.t1_s - t[a.saturating_sub(1)]).abs() < 1e-12 => {
                let la = last.t1_s - last.t0_s;
                let lb = t1 - t0;
                last.rms_ut =
                    ((last.rms_ut.powi(2) * la + rms.powi(2) * lb) / (la + lb).max(1e-12)).sqrt();
                last.t1_s = t1;
            }
            _ => out.push(Segment {
                t0_s: t0,
                t1_s: t1,
                rms_ut: rms,
            }),
        }
    }
    out
}

/// The residual by the sensor axis the field points along (six bins), if one direction stands out.
fn orientation(energy: &[f64], directions: &[[f64; 3]], floor_rms: f64) -> Option<Orientation> {
    const NAMES: [&str; 6] = ["+X", "−X", "+Y", "−Y", "+Z", "−Z"];
    let mut sum = [0.0; 6];
    let mut count = [0usize; 6];
    for (e, d) in energy.iter().zip(directions) {
        let k = (0..3)
            .max_by(|&i, &j| d[i].abs().total_cmp(&d[j].abs()))
            .unwrap_or(0);
        let bin = 2 * k + usize::from(d[k] < 0.0);
        sum[bin] += e;
        count[bin] += 1;
    }
    let n: usize = count.iter().sum();
    let total: f64 = sum.iter().sum();
    let (bin, rms) = (0..6)
        .filter(|&b| count[b] * 20 >= n)
        .map(|b| (b, (sum[b] / count[b] as f64).sqrt()))
        .max_by(|x, y| x.1.total_cmp(&y.1))?;
    let rest = n - count[bin];
    if rest == 0 {
        return None;
    }
    let elsewhere = ((total - sum[bin]) / rest as f64).sqrt();
    (rms > EXCESS * elsewhere && rms > EXCESS * floor_rms).then_some(Orientation {
        direction: NAMES[bin],
        rms_ut: rms,
        elsewhere_rms_ut: elsewhere,
    })
}

/// The channel explaining the largest share of the residual's variance (linear in the centred channel, per
/// component), if significant (N·R² > 25, p < 10⁻⁵ for three components).
fn follows(res: &Components, channels: &[(&str, &[f64])]) -> (Option<String>, f64) {
    let n = res.len() as f64;
    let dims = res.dims;
    let means: Vec<f64> = (0..dims)
        .map(|j| res.iter().map(|r| r[j]).sum::<f64>() / n)
        .collect();
    let var_res: f64 = (0..dims)
        .map(|j| res.iter().map(|r| (r[j] - means[j]).powi(2)).sum::<f64>())
        .sum();
    let mut best = (None, 0.0);
    for &(name, c) in channels {
        let cm = c.iter().sum::<f64>() / n;
        let var_c: f64 = c.iter().map(|v| (v - cm).powi(2)).sum();
        if var_c <= 0.0 || var_res <= 0.0 {
            continue;
        }
        let explained: f64 = (0..dims)
            .map(|j| {
                res.iter()
                    .zip(c)
                    .map(|(r, v)| (r[j] - means[j]) * (v - cm))
                    .sum::<f64>()
                    .powi(2)
                    / var_c
            })
            .sum();
        let share = explained / var_res;
        if share > best.1 && n * share > 25.0 {
            best = (Some(name.to_owned()), share);
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, StandardNormal};

    fn noisy(n: usize, seed: u64) -> Vec<[f64; 3]> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut g = move || -> f64 { StandardNormal.sample(&mut rng) };
        (0..n).map(|_| [0.1 * g(), 0.1 * g(), 0.1 * g()]).collect()
    }

    #[test]
    fn finds_the_axis_and_the_span_of_a_burst() {
        let n = 3000;
        let t: Vec<f64> = (0..n).map(|i| i as f64 * 0.01).collect();
        let mut res = noisy(n, 4);
        for r in &mut res[1000..1500] {
            r[0] += 0.5;
        }
        let loc = locate(
            &Components::of(res.iter(), 3),
            &[0.1; 3],
            Some(&t),
            &vec![[1.0, 0.0, 0.0]; n],
            &[("t", &t[..])],
        );
        assert_eq!(loc.axes, vec!["x"]);
        assert_eq!(loc.segments.len(), 1, "{:?}", loc.segments);
        let s = loc.segments[0];
        assert!(
            (s.t0_s - 10.0).abs() < 0.3 && (s.t1_s - 15.0).abs() < 0.3,
            "{s:?}"
        );
    }

    #[test]
    fn finds_the_channel_and_the_orientation() {
        let n = 3000;
        let temp: Vec<f64> = (0..n).map(|i| 20.0 + (i as f64 * 0.003).sin()).collect();
        let mut res = noisy(n, 5);
        // Along +Y the residual follows the temperature; the field points along +Y in the first third.
        let dirs: Vec<[f64; 3]> = (0..n)
            .map(|i| {
                if i < n / 3 {
                    [0.0, 1.0, 0.0]
                } else {
                    [0.0, 0.0, -1.0]
                }
            })
            .collect();
        for i in 0..n / 3 {
            res[i][1] += 0.3 * (temp[i] - 20.0);
        }
        let loc = locate(
            &Components::of(res.iter(), 3),
            &[0.1; 3],
            None,
            &dirs,
            &[("temp", &temp[..])],
        );
        assert_eq!(loc.channel.as_deref(), Some("temp"));
        assert_eq!(loc.orientation.map(|o| o.direction), Some("+Y"));
        let clean = locate(
            &Components::of(noisy(n, 6).iter(), 3),
            &[0.1; 3],
            None,
            &dirs,
            &[("temp", &temp[..])],
        );
        assert!(
            clean.axes.is_empty() && clean.channel.is_none() && clean.orientation.is_none(),
            "{clean:?}"
        );
    }
}
