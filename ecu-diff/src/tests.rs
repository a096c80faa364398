use crate::*;
use autoplug_can::{AbsMsg, SteeringMsg, VehicleSpeedMsg};
use proptest::prelude::*;

proptest! {
    /// Whatever the inputs: the split stays within ±50 N·m and is 0 whenever a condition
    /// for control is missing or the error is invalid or inside the dead band.
    #[test]
    fn split_within_limits_and_conditions(
        steps in proptest::collection::vec(
            (any::<f32>(), 0u8..=255, 10u8..=90, 0u8..=100, any::<bool>()),
            1..300,
        ),
    ) {
        let mut ecu = DiffEcu::new(Instant::ZERO);
        for (i, (error, speed, steering, brake, drop)) in steps.into_iter().enumerate() {
            let now = Instant::from_millis(i as u64 * 10);
            if !drop {
                ecu.on_frame(now, &Frame::new(u32::from(VehicleSpeedMsg::ID), &[speed]).unwrap());
                ecu.on_frame(now, &Frame::new(u32::from(SteeringMsg::ID), &[steering]).unwrap());
                ecu.on_frame(now, &Frame::new(u32::from(AbsMsg::ID), &[brake, 0, 0, 0, 0, 0, 0, 0]).unwrap());
            }
            let split = ecu.step(now, &Sensors { yaw_rate_error_rad_s: error }).torque_split_nm;
            prop_assert!((-SPLIT_LIMIT_NM..=SPLIT_LIMIT_NM).contains(&split));
            let status = ecu.status();
            if status.mode != Mode::Active {
                prop_assert_eq!(split, 0.0);
            }
            let steering_deg = f32::from(steering) * 3.375 - 168.75;
            let held = f32::from(speed) < MIN_SPEED_KMH
                || steering_deg.abs() < MIN_STEERING_DEG
                || f32::from(brake) > BRAKE_HOLD_PCT;
            if !drop && held {
                prop_assert_eq!(split, 0.0);
            }
            if !error.is_finite() || error.abs() < YAW_DEAD_BAND_EXIT_RAD_S {
                prop_assert_eq!(split, 0.0);
            }
        }
    }
}
