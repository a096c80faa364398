use crate::*;
use proptest::prelude::*;

/// One step's inputs: pedals, and the raw bytes of the three inputs (any byte, valid or not).
fn any_step() -> impl Strategy<Value = (f32, f32, u8, u8, u8)> {
    (
        prop_oneof![any::<f32>(), -10.0f32..110.0],
        prop_oneof![any::<f32>(), -10.0f32..110.0],
        0u8..3,
        any::<u8>(),
        any::<u8>(),
    )
}

proptest! {
    /// Any pedals, any frames: the commands stay in 0..100, a pressed brake zeroes the
    /// accelerator, and the pedals only ever send CruiseModeMsg Off, at least 5 ms apart.
    #[test]
    fn outputs_always_within_limits(steps in proptest::collection::vec(any_step(), 1..200)) {
        let mut ecu = PedalsEcu::new(Instant::ZERO);
        let mut last_cancel: Option<u64> = None;
        for (i, (accel, brake, mode, command, cut)) in steps.into_iter().enumerate() {
            let t = i as u64 * 5;
            let now = Instant::from_millis(t);
            for (id, raw) in [(CruiseModeMsg::ID, mode), (CruiseAccelMsg::ID, command), (TracMsg::ID, cut)] {
                ecu.on_frame(now, &Frame::new(u32::from(id), &[raw]).unwrap());
            }
            let out = ecu.step(now, &Sensors { accelerator_pedal: accel, brake_pedal: brake });
            prop_assert!((0.0..=PEDAL_FULL).contains(&out.accelerator_cmd));
            prop_assert!((0.0..=PEDAL_FULL).contains(&out.brake_cmd));
            if brake > PEDAL_PRESSED_THRESHOLD {
                prop_assert_eq!(out.accelerator_cmd, 0.0);
            }
            while let Some(frame) = ecu.poll_transmit(now) {
                if frame.id() == CruiseModeMsg::ID {
                    prop_assert_eq!(frame.data(), &[0u8][..]);
                    if let Some(last) = last_cancel {
                        prop_assert!(t - last >= u64::from(CruiseModeMsg::MIN_GAP_MS));
                    }
                    last_cancel = Some(t);
                }
            }
        }
    }
}
