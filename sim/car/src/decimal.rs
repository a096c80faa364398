//! Fixed-point decimal text for the trace: `push_fixed(out, v, 3)` appends what
//! `format!("{v:.3}")` gives, byte for byte, several times faster.
//!
//! Why not `write!`: core formats a float with a given precision exactly (Grisu with a
//! Dragon4 fallback over big integers), and the trace of a 150 s run has over half a million
//! numbers: that was a seventh of the drive-cycle run's whole time. Here the value is scaled
//! by 10^decimals and rounded as an integer, which is exact except within an ulp of a
//! tie; those few values (and non-finite or huge ones) still go to core.

use std::io::Write;

/// Powers of ten up to the most decimals the fast path takes.
const POW10: [f64; 10] = [1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9];

/// Appends `v` with `decimals` digits after the point, exactly as `{:.decimals$}` writes it.
pub fn push_fixed(out: &mut Vec<u8>, v: f64, decimals: usize) {
    if let Some(scaled) = POW10.get(decimals).map(|p| v.abs() * p) {
        // Below 2^52 the scaled value's ulp is at most 1/2, its rounding error at most
        // scaled · 2^-53 (one multiplication by an exact power of ten).
        if scaled < 4_503_599_627_370_496.0 {
            let fraction = scaled - scaled.floor();
            let error = scaled * 2.3e-16;
            if (fraction - 0.5).abs() > error {
                push_scaled(out, v.is_sign_negative(), scaled.round() as u64, decimals);
                return;
            }
        }
    }
    // Writing to a Vec cannot fail.
    let _ = write!(out, "{v:.decimals$}");
}

/// Appends `n / 10^decimals` with `decimals` digits after the point.
fn push_scaled(out: &mut Vec<u8>, negative: bool, n: u64, decimals: usize) {
    let mut digits = [0u8; 20];
    let mut len = 0;
    let mut rest = n;
    // At least one digit before the point: all the decimals and then one more.
    while rest > 0 || len <= decimals {
        digits[len] = b'0' + (rest % 10) as u8;
        rest /= 10;
        len += 1;
    }
    if negative {
        out.push(b'-');
    }
    for (k, digit) in digits[..len].iter().rev().enumerate() {
        if k == len - decimals && decimals > 0 {
            out.push(b'.');
        }
        out.push(*digit);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn fixed(v: f64, decimals: usize) -> String {
        let mut out = Vec::new();
        push_fixed(&mut out, v, decimals);
        String::from_utf8(out).unwrap()
    }

    #[test]
    fn matches_core_on_the_edges() {
        let values = [
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.5,
            2.5,
            0.125,
            0.375,
            1.005,
            2.675,
            0.045,
            1e-9,
            -1e-9,
            9.995,
            99.995,
            0.999_999,
            123_456.789_5,
            4.5e15,
            1e300,
            -1e300,
            f64::MAX,
            f64::MIN_POSITIVE,
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ];
        for v in values {
            for decimals in 0..=6 {
                assert_eq!(
                    fixed(v, decimals),
                    format!("{v:.decimals$}"),
                    "{v:e} .{decimals}"
                );
            }
        }
        // And the precisions the fast path does not take.
        assert_eq!(fixed(1.0 / 3.0, 12), format!("{:.12}", 1.0 / 3.0));
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(20_000))]

        #[test]
        fn matches_core(v in -1e7f64..1e7, decimals in 0usize..=6) {
            prop_assert_eq!(fixed(v, decimals), format!("{v:.decimals$}"));
        }

        /// Values on a grid of halves of the last digit, where rounding is decided.
        #[test]
        fn matches_core_near_ties(n in -10_000_000i64..10_000_000, decimals in 0usize..=5) {
            let v = (n as f64 + 0.5) / POW10[decimals];
            prop_assert_eq!(fixed(v, decimals), format!("{v:.decimals$}"));
        }

        #[test]
        fn matches_core_at_any_magnitude(bits in any::<u64>(), decimals in 0usize..=9) {
            let v = f64::from_bits(bits);
            prop_assert_eq!(fixed(v, decimals), format!("{v:.decimals$}"));
        }
    }
}
