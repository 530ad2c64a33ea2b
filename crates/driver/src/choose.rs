//! Picking a supported range or rate for a requested one, and scaling counts.

/// The smallest option whose value is at least `request`, or the largest
/// option when none is; `None` when `request` is not a finite positive number.
pub(crate) fn range_at_least<T: Copy>(
    options: &[T],
    value: impl Fn(T) -> f32,
    request: f32,
) -> Option<T> {
    if !(request.is_finite() && request > 0.0) {
        return None;
    }
    let mut fitting: Option<T> = None;
    let mut largest: Option<T> = None;
    for &option in options {
        let v = value(option);
        if v >= request && fitting.is_none_or(|f| v < value(f)) {
            fitting = Some(option);
        }
        if largest.is_none_or(|l| v > value(l)) {
            largest = Some(option);
        }
    }
    fitting.or(largest)
}

/// The option whose value is nearest to `request` (the lower one on a tie);
/// `None` when `request` is not a finite positive number.
pub(crate) fn nearest<T: Copy>(options: &[T], value: impl Fn(T) -> f32, request: f32) -> Option<T> {
    if !(request.is_finite() && request > 0.0) {
        return None;
    }
    let distance = |option: T| {
        let d = value(option) - request;
        if d < 0.0 { -d } else { d }
    };
    let mut best: Option<T> = None;
    for &option in options {
        let better = best.is_none_or(|b| {
            distance(option) < distance(b)
                || (distance(option) == distance(b) && value(option) < value(b))
        });
        if better {
            best = Some(option);
        }
    }
    best
}

/// Whether any count is within 1 % of the output's extremes `min..=max` (1 % of half the span): the field is at or
/// past the end of the chip's range, so the value is clipped, not measured. For chips without a saturation flag.
pub(crate) fn near_full_scale(counts: [i32; 3], min: i32, max: i32) -> bool {
    let margin = (max - min) / 200;
    counts
        .iter()
        .any(|&c| c >= max - margin || c <= min + margin)
}

/// Multiplies three axis counts by the resolution.
pub(crate) fn scale(counts: [i32; 3], lsb_ut: f32) -> [f32; 3] {
    counts.map(|c| c as f32 * lsb_ut)
}

/// Rounds half away from zero to an integer count, `None` if `x` is not finite
/// or does not fit in `i16` (core has no `f32::round` without `std`).
pub(crate) fn round_to_i16(x: f32) -> Option<i16> {
    if !x.is_finite() {
        return None;
    }
    let rounded = if x >= 0.0 { x + 0.5 } else { x - 0.5 };
    if rounded <= f32::from(i16::MIN) - 1.0 || rounded >= f32::from(i16::MAX) + 1.0 {
        return None;
    }
    Some(rounded as i16)
}

#[cfg(test)]
mod tests {
    use super::*;

    const RANGES: [f32; 4] = [400.0, 800.0, 1200.0, 1600.0];

    #[test]
    fn range_picks_smallest_that_fits_or_largest() {
        let pick = |r| range_at_least(&RANGES, |v| v, r);
        assert_eq!(pick(50.0), Some(400.0));
        assert_eq!(pick(400.0), Some(400.0));
        assert_eq!(pick(400.1), Some(800.0));
        assert_eq!(pick(5000.0), Some(1600.0));
        assert_eq!(pick(0.0), None);
        assert_eq!(pick(-3.0), None);
        assert_eq!(pick(f32::NAN), None);
        assert_eq!(pick(f32::INFINITY), None);
    }

    #[test]
    fn nearest_rate_prefers_lower_on_tie() {
        let rates = [10.0, 20.0, 50.0, 100.0];
        let pick = |r| nearest(&rates, |v| v, r);
        assert_eq!(pick(1.0), Some(10.0));
        assert_eq!(pick(15.0), Some(10.0));
        assert_eq!(pick(16.0), Some(20.0));
        assert_eq!(pick(74.0), Some(50.0));
        assert_eq!(pick(1000.0), Some(100.0));
        assert_eq!(pick(0.0), None);
        assert_eq!(pick(f32::NAN), None);
    }

    #[test]
    fn rounding_to_counts() {
        assert_eq!(round_to_i16(2.5), Some(3));
        assert_eq!(round_to_i16(-2.5), Some(-3));
        assert_eq!(round_to_i16(-2.4), Some(-2));
        assert_eq!(round_to_i16(32767.4), Some(32767));
        assert_eq!(round_to_i16(-32768.4), Some(-32768));
        assert_eq!(round_to_i16(32767.5), None);
        assert_eq!(round_to_i16(-32768.5), None);
        assert_eq!(round_to_i16(f32::NAN), None);
    }
}
