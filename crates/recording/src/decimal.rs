//! The common case of a number in a data row, read without a general float parser: a plain decimal — a sign, digits,
//! a point, digits, no exponent — whose value is a ratio of two numbers an `f64` holds exactly (at most 19 digits
//! with a mantissa below 2⁵³, at most 22 after the point). Its quotient is then correctly rounded, as Clinger's fast
//! path has it, so the value is bit for bit what a correct parser gives; anything else is left to one.

/// The powers of ten an `f64` holds exactly.
const POW10: [f64; 23] = [
    1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16,
    1e17, 1e18, 1e19, 1e20, 1e21, 1e22,
];

/// The plain decimal at the start of `bytes` and the bytes it takes, or `None` when it is not one this reads exactly
/// (then a general parser must).
pub(crate) fn parse_plain(bytes: &[u8]) -> Option<(f64, usize)> {
    let (negative, mut pos) = match bytes.first() {
        Some(b'-') => (true, 1),
        Some(b'+') => (false, 1),
        _ => (false, 0),
    };
    let mut mantissa: u64 = 0;
    let mut digits = 0usize;
    let mut after_point = 0usize;
    let mut point = false;
    while let Some(&b) = bytes.get(pos) {
        let d = b.wrapping_sub(b'0');
        if d < 10 {
            mantissa = mantissa.wrapping_mul(10).wrapping_add(u64::from(d));
            digits += 1;
            after_point += usize::from(point);
        } else if b == b'.' && !point {
            point = true;
        } else {
            break;
        }
        pos += 1;
    }
    let exact = digits > 0
        && digits <= 19
        && mantissa < 1 << 53
        && after_point < POW10.len()
        && !matches!(bytes.get(pos), Some(b'e' | b'E'));
    if !exact {
        return None;
    }
    let value = mantissa as f64 / POW10[after_point];
    Some((if negative { -value } else { value }, pos))
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};

    #[test]
    fn plain_decimals_are_read_bit_for_bit_as_the_standard_library_reads_them() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        for _ in 0..200_000 {
            let int_digits = rng.random_range(0..10usize);
            let frac_digits = rng.random_range(0..12usize);
            let mut text = String::new();
            match rng.random_range(0..3) {
                0 => text.push('-'),
                1 => text.push('+'),
                _ => {}
            }
            for _ in 0..int_digits {
                text.push(char::from(b'0' + rng.random_range(0..10u8)));
            }
            if frac_digits > 0 || rng.random_bool(0.5) {
                text.push('.');
            }
            for _ in 0..frac_digits {
                text.push(char::from(b'0' + rng.random_range(0..10u8)));
            }
            let std = text.parse::<f64>();
            match parse_plain(text.as_bytes()) {
                Some((value, used)) => {
                    assert_eq!(used, text.len(), "{text}");
                    assert_eq!(value.to_bits(), std.unwrap().to_bits(), "{text}");
                }
                // Not read here: no digits, or too many to be exact.
                None => assert!(
                    std.is_err() || int_digits + frac_digits > 15,
                    "{text} left to a general parser"
                ),
            }
        }
    }

    #[test]
    fn anything_else_is_left_to_a_general_parser_or_ends_the_number() {
        for text in [
            "",
            "-",
            ".",
            "+.",
            "1e5",
            "1.5E-3",
            "12345678901234567890",
            "0.00000000000000000000001",
        ] {
            assert_eq!(parse_plain(text.as_bytes()), None, "{text}");
        }
        // The number ends where a byte that is not part of it starts.
        assert_eq!(parse_plain(b"-41.95,12"), Some((-41.95, 6)));
        assert_eq!(parse_plain(b"1.2.3"), Some((1.2, 3)));
        assert_eq!(parse_plain(b"-0"), Some((-0.0, 2)));
        assert!(parse_plain(b"-0").unwrap().0.is_sign_negative());
    }
}
