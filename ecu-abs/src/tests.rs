use crate::test_cases;

macro_rules! shared_cases {
    ($($name:ident),* $(,)?) => { $( #[test] fn $name() { test_cases::$name(); } )* };
}

shared_cases!(
    publishes_its_messages_every_10_ms,
    light_braking_passes_the_command_through,
    slipping_wheel_is_released,
    full_braking_stops_short_without_locking,
    full_braking_on_low_friction,
    faulty_build_locks_the_wheels,
    rear_axle_is_select_low,
    front_axle_yaw_moment_builds_up_slowly,
    saturated_brake_resets_the_controller,
    released_wheel_teaches_the_friction_peak,
    abs_inactive_below_the_minimum_speed,
    abs_times_out_after_it_stops_acting,
    traction_control_cuts_on_a_spinning_wheel,
    friction_change_during_a_stop,
    stale_vehicle_speed_passes_the_brake_through,
    stale_pedal_brake_holds_then_stops_the_car,
    invalid_frames_record_invalid_data,
    implausible_wheel_speed_disables_abs,
    outputs_stay_within_limits,
);

mod properties {
    use crate::*;
    use autoplug_can::CanMessage;
    use proptest::prelude::*;

    fn wheel_speed() -> impl Strategy<Value = f32> {
        prop_oneof![
            8 => 0.0f32..260.0,
            1 => Just(f32::NAN),
            1 => -50.0f32..0.0,
            1 => 400.0f32..1000.0,
        ]
    }

    proptest! {
        /// Whatever the readings and commands, every applied brake is within
        /// [0, driver command], releases and the cut within 0..=100, all finite.
        #[test]
        fn outputs_always_within_limits(
            steps in proptest::collection::vec(
                (0u8..=255, 0u8..=100, proptest::array::uniform4(wheel_speed()), any::<bool>()),
                1..200,
            ),
        ) {
            let mut ecu = AbsEcu::new(Variant::Correct, Instant::ZERO);
            for (n, (v, brake, wheels, send)) in steps.into_iter().enumerate() {
                let now = Instant::from_micros(n as u64 * STEP_PERIOD_US);
                if send {
                    ecu.on_frame(now, &VehicleSpeedMsg { vehicle_speed: f32::from(v) }.frame());
                    ecu.on_frame(now, &PedalBrake { brake_cmd: f32::from(brake) }.frame());
                }
                let out = ecu.step(now, &Sensors { wheel_speed_kmh: wheels });
                let status = ecu.status();
                prop_assert!((0.0..=100.0).contains(&status.driver_brake));
                for (applied, release) in out.brake.iter().zip(status.release) {
                    prop_assert!((0.0..=status.driver_brake).contains(applied));
                    prop_assert!((0.0..=100.0).contains(&release));
                }
                prop_assert!((0.0..=100.0).contains(&status.traction_cut));
                if send && status.brake_source == BrakeSource::Driver {
                    prop_assert_eq!(status.driver_brake, f32::from(brake));
                }
                while ecu.poll_transmit(now).is_some() {}
            }
        }

        /// Without slip (all wheels at the vehicle speed), the brake passes through exactly.
        #[test]
        fn no_slip_no_release(v in 0u8..=255, brake in 0u8..=100) {
            let mut ecu = AbsEcu::new(Variant::Correct, Instant::ZERO);
            ecu.on_frame(Instant::ZERO, &VehicleSpeedMsg { vehicle_speed: f32::from(v) }.frame());
            ecu.on_frame(Instant::ZERO, &PedalBrake { brake_cmd: f32::from(brake) }.frame());
            let out = ecu.step(Instant::ZERO, &Sensors { wheel_speed_kmh: [f32::from(v); 4] });
            prop_assert_eq!(out.brake, [f32::from(brake); 4]);
        }
    }
}

/// Turning wheels veto reprogramming, whatever the bus says of the vehicle speed; standing
/// wheels, or readings the ECU does not trust, do not.
#[test]
fn turning_wheels_veto_programming() {
    use crate::*;
    use autoplug_ecu::{EcuLogic, Instant};
    let mut ecu = AbsEcu::new(Variant::Correct, Instant::ZERO);
    assert!(!ecu.own_sensors_show_motion(), "before the first step");
    let mut now = Instant::ZERO;
    for (wheels, vetoes) in [
        ([0.0; 4], false),
        ([0.0, 0.0, 0.0, 0.9], false),
        ([0.0, 0.0, 3.0, 0.0], true),
        ([90.0; 4], true),
        ([0.0; 4], false),
    ] {
        now = now.plus_micros(STEP_PERIOD_US);
        ecu.step(
            now,
            &Sensors {
                wheel_speed_kmh: wheels,
            },
        );
        assert_eq!(ecu.own_sensors_show_motion(), vetoes, "{wheels:?}");
    }
}
