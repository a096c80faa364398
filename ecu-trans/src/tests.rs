use crate::*;
use autoplug_can::{AccMsg, CanMessage, EngineMsg, ShiftMsg, VehicleSpeedMsg};
use proptest::prelude::*;

fn any_gear() -> impl Strategy<Value = Gear> {
    proptest::sample::select(Gear::ALL.to_vec())
}

proptest! {
    /// Whatever the inputs: the command moves at most one gear per step and at most one
    /// shift per shift timeout; no forward downshift ever predicts more than the over-rev
    /// limit from the RPM the ECU was told; Reverse is only engaged at standstill.
    #[test]
    fn shifts_are_single_rate_limited_and_safe(
        start in any_gear(),
        inputs in proptest::collection::vec(
            (0u8..=255, 0u8..=255, 0u8..=2, any::<bool>(), any::<bool>(), any::<bool>()),
            1..400,
        ),
    ) {
        let mut ecu = TransEcu::new(Instant::ZERO);
        let mut engaged = start;
        let mut last_shift: Option<u64> = None;
        let mut rpm_raw = 0u8;
        let mut speed_raw = 0u8;
        for (i, (speed, rpm, request, manual, sport, drop)) in inputs.into_iter().enumerate() {
            let t = i as u64 * 10;
            let now = Instant::from_millis(t);
            if !drop {
                ecu.on_frame(now, &Frame::new(u32::from(VehicleSpeedMsg::ID), &[speed]).unwrap());
                ecu.on_frame(now, &Frame::new(u32::from(EngineMsg::ID), &[rpm, 100, u8::from(!sport)]).unwrap());
                ecu.on_frame(now, &Frame::new(u32::from(ShiftMsg::ID), &[request]).unwrap());
                ecu.on_frame(now, &AccMsg {
                    headlights: false,
                    brake_lights: false,
                    engine_mode: EngineMode::Sport,
                    shift_mode_request: if manual { ShiftMode::Manual } else { ShiftMode::Automatic },
                }.frame());
                rpm_raw = rpm;
                speed_raw = speed;
            }
            let out = ecu.step(now, &Sensors { current_gear: engaged });
            if out.gear_cmd != engaged {
                prop_assert!(
                    gear_up(engaged) == Some(out.gear_cmd) || gear_down(engaged) == Some(out.gear_cmd),
                    "{:?} -> {:?}", engaged, out.gear_cmd
                );
                if let Some(at) = last_shift {
                    prop_assert!((t - at) * 1000 >= SHIFT_TIMEOUT_US);
                }
                last_shift = Some(t);
                if out.gear_cmd == Gear::Reverse {
                    prop_assert!(f32::from(speed_raw) <= STANDSTILL_KMH);
                }
                if let (Some(from), Some(to)) = (gear_ratio(engaged), gear_ratio(out.gear_cmd)) {
                    if engaged != Gear::Reverse && out.gear_cmd != Gear::Reverse && to > from && ecu.status().shift_mode == ShiftMode::Manual {
                        let rpm = f32::from(rpm_raw) * 9000.0 / 255.0;
                        prop_assert!(rpm * to / from <= OVER_REV_LIMIT_RPM + 1.0);
                    }
                }
            }
            engaged = out.gear_cmd;
        }
    }
}
