extern crate std;

use crate::test_cases;
use crate::*;
use proptest::prelude::*;

macro_rules! shared_cases {
    ($($name:ident),* $(,)?) => { $( #[test] fn $name() { test_cases::$name(); } )* };
}

shared_cases!(
    catalogue_matches_the_spec,
    nodes_match_the_spec,
    diagnostic_identifiers_follow_spec_section_4,
    every_valid_raw_value_round_trips,
    invalid_raw_values_are_rejected,
    wrong_length_is_rejected,
    unknown_identifiers_are_rejected,
    sending_clamps,
    typed_messages_follow_the_spec,
    update_keeps_the_last_good_value,
);

/// Any value for every signal of a message: physical values anywhere (in range, beyond it,
/// non-finite), flags and enumeration values from their tables.
fn any_message() -> impl Strategy<Value = Message> {
    (
        0..MESSAGES.len(),
        prop::collection::vec((any::<f32>(), -1e4f32..1e4, 0usize..64, any::<bool>()), 8),
    )
        .prop_map(|(index, picks)| {
            let mut message = Message::all_defaults()[index];
            for (signal_index, signal) in MESSAGES[index].signals.iter().enumerate() {
                let (wild, tame, pick, use_wild) = picks[signal_index];
                let value = match signal.kind {
                    SignalKind::Scaled if use_wild => wild,
                    SignalKind::Scaled => tame,
                    SignalKind::Bool => (pick % 2) as f32,
                    SignalKind::Enum => signal.values[pick % signal.values.len()].0 as f32,
                };
                message
                    .set_signal(signal_index, value)
                    .expect("valid value");
            }
            message
        })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(4096))]

    /// Whatever a sender holds, the frame decodes, and each value arrives within half a
    /// step of what was sent after clamping to the signal's range.
    #[test]
    fn what_is_sent_is_what_arrives(message in any_message()) {
        let spec = message.spec();
        let mut buf = [0u8; 8];
        let len = message.encode_into(&mut buf);
        prop_assert_eq!(len, usize::from(spec.dlc));
        let received = Message::decode(spec.id, &buf[..len]).expect("an encoded frame is valid");
        for (i, signal) in spec.signals.iter().enumerate() {
            let sent = message.signal(i).unwrap();
            let got = received.signal(i).unwrap();
            match signal.kind {
                SignalKind::Scaled => {
                    let scale = signal.scale;
                    let clamped = if sent.is_nan() { scale.quantize(0.0) } else { sent.clamp(scale.physical_min(), scale.physical_max()) };
                    let tolerance = scale.factor().abs() * 0.5 * (1.0 + 1e-4);
                    prop_assert!((got - clamped).abs() <= tolerance, "{}.{}: sent {} got {}", spec.name, signal.name, sent, got);
                }
                _ => prop_assert_eq!(got, sent),
            }
        }
    }

    /// Decoding arbitrary frames never panics; whatever it accepts re-encodes to the same
    /// bytes but for the reserved bits (which receivers ignore and senders clear), and
    /// whatever it refuses is named.
    #[test]
    fn arbitrary_frames_are_decoded_or_refused(id in prop_oneof![0u16..0x800, prop::sample::select(MESSAGES.iter().map(|m| m.id).collect::<std::vec::Vec<_>>())], data in prop::collection::vec(any::<u8>(), 0..=8)) {
        match Message::decode(id, &data) {
            Ok(message) => {
                let mut buf = [0u8; 8];
                let len = message.encode_into(&mut buf);
                let mut expected = [0u8; 8];
                expected[..len].copy_from_slice(&data);
                let expected = (u64::from_le_bytes(expected) & message.spec().signal_bits()).to_le_bytes();
                prop_assert_eq!(&buf[..len], &expected[..len]);
            }
            Err(e) => {
                let text = std::format!("{e}");
                prop_assert!(!text.is_empty());
                if let Some(spec) = MessageSpec::by_id(id) {
                    prop_assert!(text.starts_with(spec.name), "{}", text);
                }
            }
        }
    }

    /// `update_from` on arbitrary data leaves every signal valid: it only takes values
    /// that decode.
    #[test]
    fn updates_never_take_invalid_values(index in 0..MESSAGES.len(), data in prop::collection::vec(any::<u8>(), 0..=8)) {
        let mut message = Message::all_defaults()[index];
        let _ = message.update_from(&data);
        let mut buf = [0u8; 8];
        let len = message.encode_into(&mut buf);
        prop_assert!(Message::decode(message.id(), &buf[..len]).is_ok());
    }
}

#[test]
fn errors_read_well() {
    let e = Message::decode(SteeringMsg::ID, &[5]).unwrap_err();
    assert_eq!(
        std::format!("{e}"),
        "SteeringMsg.SteeringAngle: raw value 5 is outside the valid range 10..=90"
    );
    let e = Message::decode(EngineMsg::ID, &[1, 2]).unwrap_err();
    assert_eq!(
        std::format!("{e}"),
        "EngineMsg: frame has 2 data bytes, the catalogue says 5"
    );
    let e = Message::decode(0x123, &[]).unwrap_err();
    assert_eq!(
        std::format!("{e}"),
        "identifier 0x123 is not in the CAN catalogue"
    );
    let e = Message::decode(TransMsg::ID, &[9, 0]).unwrap_err();
    assert_eq!(
        std::format!("{e}"),
        "TransMsg.Gear: raw value 9 is not defined in its value table"
    );
}

#[test]
fn frames_check_identifier_and_length() {
    let f = Frame::new(0x7FF, &[1, 2, 3]).unwrap();
    assert_eq!((f.id(), f.len(), f.data()), (0x7FF, 3, &[1u8, 2, 3][..]));
    assert_eq!(std::format!("{f:?}"), "7FF#010203");
    assert_eq!(
        Frame::new(0x800, &[]),
        Err(FrameError::IdTooLarge { id: 0x800 })
    );
    assert_eq!(Frame::new(1, &[0; 9]), Err(FrameError::TooLong { len: 9 }));
    assert!(std::format!("{}", FrameError::IdTooLarge { id: 0x1234 }).contains("0x1234"));
    let msg = Message::EngineMsg(EngineMsg {
        engine_rpm: 9000.0,
        fuel_level: 1.0,
        engine_mode: EngineMode::Sport,
        fuel_used: 0.0,
    });
    let frame = msg.to_frame();
    assert_eq!(std::format!("{frame:?}"), "006#FF04000000");
    assert_eq!(Message::from_frame(&frame), Ok(msg));
}
