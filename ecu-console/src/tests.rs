use crate::*;
use autoplug_can::Message;
use proptest::prelude::*;

proptest! {
    /// Any switches and any PedalBrake bytes (or none): AccMsg always reports the lamps as
    /// driven and the switches as read, and a brake command above the on threshold always
    /// lights the brake lights.
    #[test]
    fn acc_msg_matches_the_outputs(
        steps in proptest::collection::vec(
            (any::<bool>(), any::<bool>(), any::<bool>(), proptest::option::of(any::<u8>())),
            1..200,
        )
    ) {
        let mut ecu = ConsoleEcu::new(Instant::ZERO);
        for (i, (headlight, economy, manual, brake)) in steps.into_iter().enumerate() {
            let now = Instant::from_millis(i as u64 * 10);
            if let Some(raw) = brake {
                ecu.on_frame(now, &Frame::new(u32::from(PedalBrake::ID), &[raw]).unwrap());
            }
            let sensors = Sensors {
                headlight_switch: headlight,
                economy_mode_switch: economy,
                manual_mode_switch: manual,
            };
            let out = ecu.step(now, &sensors);
            prop_assert_eq!(out.headlights, headlight);
            if brake.is_some_and(|raw| f32::from(raw) > BRAKE_LIGHTS_ON_PCT && raw <= 100) {
                prop_assert!(out.brake_lights);
            }
            while let Some(frame) = ecu.poll_transmit(now) {
                let Ok(Message::AccMsg(acc)) = Message::from_frame(&frame) else {
                    panic!("only AccMsg");
                };
                prop_assert_eq!(acc.headlights, out.headlights);
                prop_assert_eq!(acc.brake_lights, out.brake_lights);
                prop_assert_eq!(acc.engine_mode == EngineMode::Economy, economy);
                prop_assert_eq!(acc.shift_mode_request == ShiftMode::Manual, manual);
                prop_assert_eq!(frame.id(), AccMsg::ID);
            }
        }
    }
}
