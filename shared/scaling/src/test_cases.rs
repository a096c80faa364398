//! Test cases shared by the host test suite and the on-target (defmt-test) suite, so the
//! Cortex-M4 run checks exactly what the host run checks. Each case panics on failure.

use crate::units::*;
use crate::{round_half_away_from_zero, LinearScale, RawOutOfRange};

/// Shapes of the catalogue's conversions (engine RPM, steering, yaw rate, offset-encoded
/// cruise command), restated here so that this crate's cases do not depend on the DBC.
const SCALES: [LinearScale; 4] = [
    LinearScale::new(9000.0 / 255.0, 0.0, 0, 255),
    LinearScale::new(3.375, -168.75, 10, 90),
    LinearScale::new(2.5 / 127.0, 0.0, -127, 127),
    LinearScale::new(1.0, -100.0, 0, 200),
];

/// Every valid raw value survives raw -> physical -> raw unchanged.
pub fn every_raw_value_round_trips() {
    for scale in SCALES {
        for raw in scale.raw_min()..=scale.raw_max() {
            let physical = scale.to_physical(raw).expect("raw in range");
            assert_eq!(scale.to_raw_saturating(physical), raw);
        }
    }
}

/// Raw values one step outside the range are rejected and named in the error.
pub fn out_of_range_raw_is_rejected() {
    for scale in SCALES {
        for raw in [scale.raw_min() - 1, scale.raw_max() + 1, i32::MIN, i32::MAX] {
            assert_eq!(
                scale.to_physical(raw),
                Err(RawOutOfRange {
                    raw,
                    min: scale.raw_min(),
                    max: scale.raw_max()
                })
            );
        }
    }
}

/// Physical values beyond the range, infinities included, clamp to the range ends; NaN
/// goes to the neutral value (physical zero, clamped).
pub fn sending_saturates() {
    for scale in SCALES {
        let lo = scale.physical_min();
        let hi = scale.physical_max();
        assert_eq!(scale.to_raw_saturating(lo - 1000.0), scale.raw_min());
        assert_eq!(scale.to_raw_saturating(hi + 1000.0), scale.raw_max());
        assert_eq!(scale.to_raw_saturating(f32::NEG_INFINITY), scale.raw_min());
        assert_eq!(scale.to_raw_saturating(f32::INFINITY), scale.raw_max());
        assert_eq!(
            scale.to_raw_saturating(f32::NAN),
            scale.to_raw_saturating(0.0)
        );
        assert_eq!(scale.to_raw_saturating(f32::MAX), scale.raw_max());
        assert_eq!(scale.to_raw_saturating(f32::MIN), scale.raw_min());
    }
}

/// The catalogue's anchor points land on the raw values the spec gives.
pub fn anchor_points() {
    let [rpm, steering, yaw, cruise] = SCALES;
    assert_eq!(rpm.to_raw_saturating(9000.0), 255);
    assert_eq!(rpm.to_raw_saturating(0.0), 0);
    assert_eq!(steering.to_raw_saturating(0.0), 50);
    assert_eq!(steering.to_raw_saturating(-135.0), 10);
    assert_eq!(steering.to_raw_saturating(135.0), 90);
    assert_eq!(yaw.to_raw_saturating(2.5), 127);
    assert_eq!(yaw.to_raw_saturating(-2.5), -127);
    assert_eq!(cruise.to_raw_saturating(-100.0), 0);
    assert_eq!(cruise.to_raw_saturating(0.0), 100);
    assert_eq!(cruise.to_raw_saturating(100.0), 200);
}

/// Quantisation error is at most half a step inside the range.
pub fn quantisation_error_is_half_a_step() {
    for scale in SCALES {
        let lo = scale.physical_min();
        let hi = scale.physical_max();
        let steps = 1000;
        for i in 0..=steps {
            let x = lo + (hi - lo) * (i as f32 / steps as f32);
            let err = (scale.quantize(x) - x).abs();
            assert!(err <= scale.factor() * 0.5 + 1e-3, "error {} at {}", err, x);
        }
    }
}

/// Rounding is half away from zero and saturates instead of overflowing.
pub fn rounding() {
    assert_eq!(round_half_away_from_zero(0.5), 1);
    assert_eq!(round_half_away_from_zero(-0.5), -1);
    assert_eq!(round_half_away_from_zero(1.49), 1);
    assert_eq!(round_half_away_from_zero(-1.49), -1);
    assert_eq!(round_half_away_from_zero(2.5), 3);
    assert_eq!(round_half_away_from_zero(1e30), i32::MAX);
    assert_eq!(round_half_away_from_zero(-1e30), i32::MIN);
    assert_eq!(round_half_away_from_zero(f32::NAN), 0);
}

/// Unit conversions invert each other and hit known points.
pub fn unit_conversions() {
    fn close(a: f32, b: f32) -> bool {
        (a - b).abs() <= 1e-4 * (1.0 + b.abs())
    }
    assert!(close(kmh_to_mps(36.0), 10.0));
    assert!(close(mps_to_kmh(kmh_to_mps(123.4)), 123.4));
    assert!(close(rpm_to_rad_s(60.0), core::f32::consts::TAU));
    assert!(close(rad_s_to_rpm(rpm_to_rad_s(6500.0)), 6500.0));
    assert!(close(fahrenheit_to_celsius(212.0), 100.0));
    assert!(close(celsius_to_fahrenheit(-40.0), -40.0));
    assert!(close(rad_to_deg(deg_to_rad(135.0)), 135.0));
    assert_eq!(fraction_to_pedal_units(0.5), 50.0);
    assert_eq!(fraction_to_pedal_units(1.7), 100.0);
    assert_eq!(fraction_to_pedal_units(f32::NAN), 0.0);
    assert_eq!(pedal_units_to_fraction(-3.0), 0.0);
    assert_eq!(pedal_units_to_fraction(25.0), 0.25);
}
