use crate::test_cases;
use crate::*;
use proptest::prelude::*;

proptest! {
    /// Whatever the readings (NaN, infinities, anything): the fan stays within 0..=100 %
    /// and the published values are valid frames.
    #[test]
    fn fan_always_within_limits(
        readings in proptest::collection::vec((any::<f32>(), any::<f32>(), 1u64..2000), 1..200),
    ) {
        let mut ecu = CabinEcu::new();
        let mut t = 0;
        for (cabin, set, dt_ms) in readings {
            t += dt_ms;
            let out = ecu.step(Instant::from_millis(t), &Sensors { cabin_temp_f: cabin, set_temp_f: set });
            prop_assert!((0.0..=100.0).contains(&out.fan));
            let status = ecu.status();
            prop_assert!(status.cabin_temp_f.is_finite());
            prop_assert!((SET_TEMP_MIN_F..=SET_TEMP_MAX_F).contains(&status.set_temp_f));
            while let Some(frame) = ecu.poll_transmit(Instant::from_millis(t)) {
                prop_assert!(autoplug_can::Message::from_frame(&frame).is_ok());
            }
        }
    }
}

/// Prints the step response, for tuning: `cargo test -p ecu-cabin trace -- --ignored --nocapture`.
#[test]
#[ignore]
fn trace() {
    extern crate std;
    let mut cabin = test_cases::Cabin::new(75.0, 75.0, 1);
    cabin.run(1200);
    cabin.set_f = 65.0;
    for minute in 0..20 {
        let trace = cabin.run(60);
        std::println!(
            "{:2} min: {:.2} °F fan {:.1} {:?}",
            minute + 1,
            cabin.temp_f,
            cabin.fan,
            trace
        );
    }
}
