use crate::*;
use proptest::prelude::*;

fn any_sensors() -> impl Strategy<Value = Sensors> {
    (
        prop_oneof![any::<f32>(), -200.0f32..200.0],
        any::<bool>(),
        any::<bool>(),
        any::<bool>(),
        any::<bool>(),
    )
        .prop_map(|(angle, up, down, on, off)| Sensors {
            wheel_angle_deg: angle,
            shift_up_button: up,
            shift_down_button: down,
            cruise_on_button: on,
            cruise_off_button: off,
        })
}

proptest! {
    /// Any wheel angle and button sequence: the steering command stays within ±135°, a
    /// shift request never lasts longer than the pulse, and Up never turns into Down
    /// without a None in between.
    #[test]
    fn outputs_always_within_limits(steps in proptest::collection::vec(any_sensors(), 1..300)) {
        let mut ecu = SteeringEcu::new(Instant::ZERO);
        let mut previous = ShiftRequest::None;
        let mut held_steps = 0u64;
        for (i, sensors) in steps.iter().enumerate() {
            let now = Instant::from_millis(i as u64 * 10);
            let out = ecu.step(now, sensors);
            prop_assert!(out.steering_cmd_deg.abs() <= STEERING_LIMIT_DEG);
            let request = ecu.shift_request();
            if request == ShiftRequest::None {
                held_steps = 0;
            } else {
                held_steps += 1;
                prop_assert!(held_steps * 10 <= SHIFT_PULSE_MS);
                prop_assert!(previous == ShiftRequest::None || previous == request);
            }
            previous = request;
            while ecu.poll_transmit(now).is_some() {}
        }
    }
}
