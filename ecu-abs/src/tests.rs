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

/// The ABS's own vehicle-speed estimate while braking (`AbsEcu::speed_reference`), fed as
/// `abs` feeds it, against a car whose true speed is known.
mod speed_reference {
    extern crate std;
    use crate::*;
    use std::vec::Vec;

    /// A stop at `decel_mps2` from 60 km/h: VehicleSpeedMsg rounded to 1 km/h, measured one
    /// message cycle before the ABS uses it and sent every 10 ms; wheels slipping `slip`
    /// (the fastest `fastest_slip`). Returns (estimate, message, true speed) per ABS step.
    fn run(decel_mps2: f32, slip: f32, fastest_slip: f32) -> Vec<(f32, f32, f32)> {
        let mut ecu = AbsEcu::new(Variant::Correct, Instant::ZERO);
        let dt_s = STEP_PERIOD_US as f32 * 1e-6;
        let cycle_steps = (VehicleSpeedMsg::CYCLE_TIME_MS as u64 * 1000 / STEP_PERIOD_US) as usize;
        let speed_at = |k: usize| 60.0 - decel_mps2 * 3.6 * dt_s * k as f32;
        let mut v_msg = speed_at(0).round();
        let mut out = Vec::new();
        for k in 0..400 {
            let v = speed_at(k);
            if v < 10.0 {
                break;
            }
            if k % cycle_steps == 0 {
                v_msg = speed_at(k.saturating_sub(cycle_steps)).round();
            }
            let wheels = [
                v * (1.0 - slip),
                v * (1.0 - slip),
                v * (1.0 - fastest_slip),
                v * (1.0 - slip),
            ];
            ecu.update_friction_estimate(v_msg, dt_s);
            out.push((ecu.speed_reference(v_msg, &wheels, dt_s), v_msg, v));
        }
        out
    }

    fn rms(errors: impl Iterator<Item = f32>) -> f32 {
        let (sum, n) = errors.fold((0.0, 0), |(s, n), e| (s + e * e, n + 1));
        (sum / n as f32).sqrt()
    }

    #[test]
    fn follows_a_stop_closer_than_the_message_does() {
        for decel in [2.0, 5.0, 9.0] {
            let run = run(decel, 0.05, 0.05);
            assert!(run.len() > 100);
            // Once the deceleration filter has settled (its time constant, a few times).
            let settled = &run[(4.0 * DECEL_FILTER_TAU_S / 0.005) as usize..];
            // Against what the ABS had before: the last message, rounded and late.
            let estimate = rms(settled.iter().map(|(e, _, v)| e - v));
            let message = rms(settled.iter().map(|(_, m, v)| m - v));
            // Closer than the message at every deceleration, and by far on ice, where one
            // 1 km/h step is more slip than the tyre's peak and the estimate matters most.
            let bound = if decel < 3.0 { 0.5 } else { 0.9 };
            assert!(
                estimate < bound * message,
                "decel {decel}: estimate rms {estimate} km/h, the message alone {message}"
            );
            for (e, _, v) in settled {
                assert!((e - v).abs() < 1.0, "decel {decel}: estimate {e}, true {v}");
            }
        }
    }

    #[test]
    fn never_above_what_the_message_allows_and_never_below_the_fastest_wheel() {
        let run = run(5.0, 0.08, 0.0);
        for (e, m, v) in &run {
            // The unbraked wheel turns at the true speed: the estimate is at least that,
            // unless the message's rounding rules it out; and never above that rounding.
            let high = m + SPEED_MSG_ROUNDING_KMH;
            assert!(
                *e >= v.min(high) - 1e-3,
                "estimate {e} below the free wheel {v}"
            );
            assert!(
                *e <= high + 1e-3,
                "estimate {e} above the message {m} allows"
            );
        }
    }
}
