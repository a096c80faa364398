use crate::test_cases;
use crate::LinearScale;
use proptest::prelude::*;

macro_rules! shared_cases {
    ($($name:ident),* $(,)?) => { $( #[test] fn $name() { test_cases::$name(); } )* };
}

shared_cases!(
    every_raw_value_round_trips,
    out_of_range_raw_is_rejected,
    sending_saturates,
    anchor_points,
    quantisation_error_is_half_a_step,
    rounding,
    unit_conversions,
);

fn any_scale() -> impl Strategy<Value = LinearScale> {
    (
        prop_oneof![0.001f32..100.0, -100.0f32..-0.001],
        -1000.0f32..1000.0,
        -40_000i32..40_000,
        0i32..40_000,
    )
        .prop_map(|(factor, offset, min, span)| LinearScale::new(factor, offset, min, min + span))
}

proptest! {
    #[test]
    fn sent_raw_is_always_in_range(scale in any_scale(), x in any::<f32>()) {
        let raw = scale.to_raw_saturating(x);
        prop_assert!(scale.contains_raw(raw));
    }

    #[test]
    fn sending_is_monotonic(scale in any_scale(), a in -1e6f32..1e6, b in -1e6f32..1e6) {
        let (lo, hi) = if a <= b { (a, b) } else { (b, a) };
        let (rlo, rhi) = (scale.to_raw_saturating(lo), scale.to_raw_saturating(hi));
        if scale.factor() > 0.0 {
            prop_assert!(rlo <= rhi);
        } else {
            prop_assert!(rlo >= rhi);
        }
    }

    #[test]
    fn in_range_values_quantise_within_half_a_step(scale in any_scale(), t in 0.0f32..=1.0) {
        let x = scale.physical_min() + (scale.physical_max() - scale.physical_min()) * t;
        let err = (scale.quantize(x) - x).abs();
        // f32 carries ~7 significant digits: allow that on top of half a step.
        let slack = 1e-6 * (x.abs() + scale.offset().abs() + scale.factor().abs() * 40_000.0);
        prop_assert!(err <= scale.factor().abs() * 0.5 + slack, "err {err} at {x}");
    }

    #[test]
    fn received_raw_is_accepted_exactly_in_range(scale in any_scale(), raw in any::<i32>()) {
        prop_assert_eq!(scale.to_physical(raw).is_ok(), scale.contains_raw(raw));
    }
}
