//! Test cases shared by the host test suite and the on-target (defmt-test) suite. Each case
//! panics on failure. They sweep every raw value of every signal exhaustively (the signals
//! are at most a byte wide), so the Cortex-M4 run checks the same ground as the host run.

use crate::codec::{self, DecodeError};
use crate::*;

/// Spec section 3, restated as the oracle the DBC is checked against:
/// (name, identifier, data length, period in ms, senders).
const SPEC_TABLE: [(&str, u16, u8, u32, &[Node]); 18] = [
    ("VehicleSpeedMsg", 0x003, 1, 10, &[Node::Cruise]),
    ("PedalBrake", 0x004, 1, 10, &[Node::Pedals]),
    ("SteeringMsg", 0x005, 1, 10, &[Node::Steering]),
    // The spec's three bytes, then the fuel-used counter (bytes 3-4) this project added so
    // a trip's fuel is known to 1 mL, not to the level's 0.25 L steps
    // (docs/src/can-catalogue.md, "Fuel used").
    ("EngineMsg", 0x006, 5, 20, &[Node::Engine]),
    ("PedalAccel", 0x007, 1, 10, &[Node::Pedals]),
    (
        "CruiseModeMsg",
        0x008,
        1,
        20,
        &[Node::Steering, Node::Pedals],
    ),
    ("CruiseAccelMsg", 0x009, 1, 20, &[Node::Cruise]),
    ("ShiftMsg", 0x00A, 1, 20, &[Node::Steering]),
    ("TransMsg", 0x00B, 2, 20, &[Node::Transmission]),
    ("WheelSpeedMsg", 0x00C, 4, 10, &[Node::ABS]),
    ("AbsMsg", 0x00E, 8, 10, &[Node::ABS]),
    ("TracMsg", 0x00F, 1, 10, &[Node::ABS]),
    ("AccMsg", 0x018, 1, 100, &[Node::Console]),
    ("DiffMsg", 0x020, 1, 10, &[Node::Differential]),
    ("YawErrorMsg", 0x021, 1, 10, &[Node::Differential]),
    ("TempMsg", 0x022, 1, 100, &[Node::Cabin]),
    ("TempRefMsg", 0x023, 1, 100, &[Node::Cabin]),
    ("FanMsg", 0x024, 1, 100, &[Node::Cabin]),
];

/// The catalogue holds exactly the spec's 18 messages with their identifiers, lengths,
/// periods and senders, and the 5 ms minimum gap.
pub fn catalogue_matches_the_spec() {
    assert_eq!(MESSAGES.len(), SPEC_TABLE.len());
    for (spec, (name, id, dlc, period, senders)) in MESSAGES.iter().zip(SPEC_TABLE) {
        assert_eq!(spec.name, name);
        assert_eq!(spec.id, id, "{}", name);
        assert_eq!(spec.dlc, dlc, "{}", name);
        assert_eq!(spec.cycle_time_ms, period, "{}", name);
        assert_eq!(spec.senders, senders, "{}", name);
        assert_eq!(spec.min_gap_ms, 5, "{}", name);
        assert_eq!(MessageSpec::by_id(id).map(|m| m.name), Some(name));
    }
    assert_eq!(BAUDRATE, 500_000);
}

/// Node numbers are the spec's (section 2), and every sender and receiver is wired.
pub fn nodes_match_the_spec() {
    let numbers = [
        (Node::Engine, Some(0x03)),
        (Node::Pedals, Some(0x04)),
        (Node::Steering, Some(0x05)),
        (Node::Transmission, Some(0x06)),
        (Node::Cabin, Some(0x0A)),
        (Node::Console, Some(0x0B)),
        (Node::Differential, Some(0x0C)),
        (Node::Cruise, Some(0x0D)),
        (Node::ABS, Some(0x0E)),
        (Node::Gateway, None),
    ];
    for (node, number) in numbers {
        assert_eq!(node.diag_node_number(), number, "{}", node.name());
    }
    // CAN in / CAN out of spec section 2, for the nodes with inputs.
    assert_eq!(Node::Cruise.transmitted_ids(), &[0x003, 0x009]);
    assert_eq!(Node::Cruise.received_ids(), &[0x008]);
    assert_eq!(Node::Pedals.received_ids(), &[0x008, 0x009, 0x00F]);
    assert_eq!(
        Node::Transmission.received_ids(),
        &[0x003, 0x006, 0x00A, 0x018]
    );
    assert_eq!(Node::Differential.received_ids(), &[0x003, 0x005, 0x00E]);
    assert_eq!(Node::ABS.received_ids(), &[0x003, 0x004]);
    assert_eq!(Node::Console.received_ids(), &[0x004]);
    assert_eq!(Node::Engine.received_ids(), &[0x018]);
    // Steering hears CruiseModeMsg to adopt the pedals' cancel (a decision of this project).
    assert_eq!(Node::Steering.received_ids(), &[0x008]);
    assert_eq!(Node::Cabin.received_ids(), &[] as &[u16]);
    assert_eq!(Node::Gateway.received_ids().len(), MESSAGES.len());
}

/// Spec section 4: UDS at 0x700 + node number, responses at 0x780 + node number, OBD-II
/// functional requests at 0x7DF, answered by the owners of speed (cruise), RPM and fuel
/// (engine) on ISO 15765-4 response identifiers; none of them is an application message.
pub fn diagnostic_identifiers_follow_spec_section_4() {
    for node in Node::ALL {
        match node.diag_node_number() {
            Some(number) => {
                assert_eq!(node.diag_request_id(), Some(0x700 + u16::from(number)));
                assert_eq!(node.diag_response_id(), Some(0x780 + u16::from(number)));
            }
            None => {
                assert_eq!(node.diag_request_id(), None, "{}", node.name());
                assert_eq!(node.diag_response_id(), None, "{}", node.name());
            }
        }
        for id in [node.diag_request_id(), node.diag_response_id()]
            .into_iter()
            .flatten()
        {
            assert!(!MESSAGES.iter().any(|m| m.id == id), "0x{id:03X}");
            assert!(!node.received_ids().contains(&id), "0x{id:03X}");
        }
    }
    assert_eq!(crate::DIAG_FUNCTIONAL_REQUEST_ID, 0x7DF);
    assert_eq!(Node::Engine.obd_response_id(), Some(0x7E8));
    assert_eq!(Node::Cruise.obd_response_id(), Some(0x7E9));
    assert_eq!(Node::ABS.obd_response_id(), None);
}

/// The frame of a message at its start values, with one signal's raw value replaced.
fn frame_with(index: usize, signal: &SignalSpec, raw: i64) -> ([u8; 8], usize) {
    let mut buf = [0u8; 8];
    let len = Message::all_defaults()[index].encode_into(&mut buf);
    let start = u32::from(signal.start_bit);
    let length = u32::from(signal.length);
    let field = codec::insert(-1, start, length);
    let bits = (u64::from_le_bytes(buf) & !field) | codec::insert(raw, start, length);
    (bits.to_le_bytes(), len)
}

/// Every valid raw value of every signal decodes to its physical value and encodes back to
/// the same bytes.
pub fn every_valid_raw_value_round_trips() {
    for (index, spec) in MESSAGES.iter().enumerate() {
        for (signal_index, signal) in spec.signals.iter().enumerate() {
            let (lo, hi) = match signal.kind {
                SignalKind::Scaled => (
                    i64::from(signal.scale.raw_min()),
                    i64::from(signal.scale.raw_max()),
                ),
                SignalKind::Bool => (0, 1),
                SignalKind::Enum => (signal.values[0].0, signal.values[signal.values.len() - 1].0),
            };
            for raw in lo..=hi {
                if !signal.accepts_raw(raw) {
                    continue;
                }
                let (frame, len) = frame_with(index, signal, raw);
                let message = Message::decode(spec.id, &frame[..len]).unwrap_or_else(|e| {
                    panic!("{}.{} raw {}: {:?}", spec.name, signal.name, raw, e)
                });
                let expected = match signal.kind {
                    SignalKind::Scaled => signal.scale.to_physical_unchecked(raw as i32),
                    _ => raw as f32,
                };
                assert_eq!(message.signal(signal_index), Some(expected));
                assert_eq!(
                    spec.decode_signal(signal_index, &frame[..len]),
                    Ok(expected)
                );
                let mut again = [0u8; 8];
                let again_len = message.encode_into(&mut again);
                assert_eq!(again_len, len);
                assert_eq!(
                    &again[..len],
                    &frame[..len],
                    "{}.{} raw {}",
                    spec.name,
                    signal.name,
                    raw
                );
            }
        }
    }
}

/// Every invalid raw value is rejected with an error naming the message, the signal and
/// the value; `update_from` keeps that signal's last good value.
pub fn invalid_raw_values_are_rejected() {
    let mut rejected = 0u32;
    for (index, spec) in MESSAGES.iter().enumerate() {
        for (signal_index, signal) in spec.signals.iter().enumerate() {
            let (bit_lo, bit_hi) = if signal.signed {
                (
                    -(1i64 << (signal.length - 1)),
                    (1i64 << (signal.length - 1)) - 1,
                )
            } else {
                (0, (1i64 << signal.length) - 1)
            };
            for raw in bit_lo..=bit_hi {
                if signal.accepts_raw(raw) {
                    continue;
                }
                rejected += 1;
                let (frame, len) = frame_with(index, signal, raw);
                let expected = match signal.kind {
                    SignalKind::Scaled => DecodeError::OutOfRange {
                        message: spec.name,
                        signal: signal.name,
                        raw,
                        min: i64::from(signal.scale.raw_min()),
                        max: i64::from(signal.scale.raw_max()),
                    },
                    _ => DecodeError::UndefinedValue {
                        message: spec.name,
                        signal: signal.name,
                        raw,
                    },
                };
                assert_eq!(Message::decode(spec.id, &frame[..len]), Err(expected));
                assert_eq!(
                    spec.decode_signal(signal_index, &frame[..len]),
                    Err(expected)
                );

                let before = Message::all_defaults()[index];
                let mut after = before;
                assert_eq!(after.update_from(&frame[..len]), Err(expected));
                assert_eq!(after, before, "{}.{} raw {}", spec.name, signal.name, raw);
            }
        }
    }
    // Steering 0..9 and 91..255, torque split and yaw extremes, enums beyond their tables…
    assert!(rejected > 1000, "only {} invalid values swept", rejected);
}

/// A frame of any length but the catalogue's is rejected whole, and changes nothing.
pub fn wrong_length_is_rejected() {
    for (index, spec) in MESSAGES.iter().enumerate() {
        let data = [0x55u8; 8];
        for len in 0..=8usize {
            if len == usize::from(spec.dlc) {
                continue;
            }
            let expected = DecodeError::WrongLength {
                message: spec.name,
                expected: usize::from(spec.dlc),
                actual: len,
            };
            assert_eq!(Message::decode(spec.id, &data[..len]), Err(expected));
            let before = Message::all_defaults()[index];
            let mut after = before;
            assert_eq!(after.update_from(&data[..len]), Err(expected));
            assert_eq!(after, before);
        }
    }
}

/// Identifiers outside the catalogue are named in the error.
pub fn unknown_identifiers_are_rejected() {
    for id in 0..=0x7FFu16 {
        if MessageSpec::by_id(id).is_none() {
            assert_eq!(
                Message::decode(id, &[0]),
                Err(DecodeError::UnknownId { id })
            );
        }
    }
}

/// Values beyond a signal's range are sent clamped; NaN is sent as the neutral value.
pub fn sending_clamps() {
    for (index, spec) in MESSAGES.iter().enumerate() {
        for (signal_index, signal) in spec.signals.iter().enumerate() {
            if signal.kind != SignalKind::Scaled {
                continue;
            }
            let scale = signal.scale;
            let cases = [
                (1e9, scale.raw_max()),
                (f32::INFINITY, scale.raw_max()),
                (-1e9, scale.raw_min()),
                (f32::NEG_INFINITY, scale.raw_min()),
                (scale.physical_max(), scale.raw_max()),
                (scale.physical_min(), scale.raw_min()),
                (f32::NAN, scale.to_raw_saturating(0.0)),
            ];
            for (value, raw) in cases {
                let mut message = Message::all_defaults()[index];
                message
                    .set_signal(signal_index, value)
                    .expect("scaled signal");
                let mut buf = [0u8; 8];
                let len = message.encode_into(&mut buf);
                let bits = codec::load(&buf[..len], len, spec.name).expect("own length");
                assert_eq!(
                    signal.raw_in(bits),
                    i64::from(raw),
                    "{}.{} <- {}",
                    spec.name,
                    signal.name,
                    value
                );
            }
        }
    }
}

/// The anchor points of spec section 3, through the typed structs firmware uses.
pub fn typed_messages_follow_the_spec() {
    assert_eq!(
        EngineMsg {
            engine_rpm: 9000.0,
            fuel_level: 48.0,
            engine_mode: EngineMode::Economy,
            fuel_used: 0.0,
        }
        .encode(),
        [255, 192, 1, 0, 0]
    );
    assert_eq!(
        EngineMsg {
            engine_rpm: 0.0,
            fuel_level: 0.0,
            engine_mode: EngineMode::Sport,
            fuel_used: 0.0,
        }
        .encode(),
        [0, 0, 0, 0, 0]
    );
    assert_eq!(
        SteeringMsg {
            steering_angle: 0.0
        }
        .encode(),
        [50]
    );
    assert_eq!(
        SteeringMsg {
            steering_angle: -135.0
        }
        .encode(),
        [10]
    );
    assert_eq!(
        SteeringMsg {
            steering_angle: 135.0
        }
        .encode(),
        [90]
    );
    assert_eq!(
        SteeringMsg {
            steering_angle: 200.0
        }
        .encode(),
        [90]
    );
    assert_eq!(
        YawErrorMsg {
            yaw_rate_error: 2.5
        }
        .encode(),
        [127]
    );
    assert_eq!(
        YawErrorMsg {
            yaw_rate_error: -2.5
        }
        .encode(),
        [(-127i8) as u8]
    );
    assert!(YawErrorMsg::decode(&[0x80]).is_err());
    assert_eq!(
        CruiseAccelMsg {
            cruise_accel: -100.0
        }
        .encode(),
        [0]
    );
    assert_eq!(CruiseAccelMsg { cruise_accel: 0.0 }.encode(), [100]);
    assert_eq!(
        CruiseAccelMsg {
            cruise_accel: 100.0
        }
        .encode(),
        [200]
    );
    assert_eq!(
        DiffMsg {
            torque_split: -50.0
        }
        .encode(),
        [(-50i8) as u8]
    );
    assert_eq!(
        DiffMsg {
            torque_split: -60.0
        }
        .encode(),
        [(-50i8) as u8]
    );
    assert_eq!(TempMsg { cabin_temp: 72.5 }.encode(), [145]);
    assert_eq!(
        TransMsg {
            gear: Gear::Sixth,
            shift_mode: ShiftMode::Manual
        }
        .encode(),
        [7, 1]
    );
    assert_eq!(
        TransMsg {
            gear: Gear::Reverse,
            shift_mode: ShiftMode::Automatic
        }
        .encode(),
        [0, 0]
    );
    assert_eq!(
        ShiftMsg {
            shift_request: ShiftRequest::Up
        }
        .encode(),
        [2]
    );
    assert_eq!(
        AccMsg {
            headlights: true,
            brake_lights: false,
            engine_mode: EngineMode::Economy,
            shift_mode_request: ShiftMode::Manual
        }
        .encode(),
        [0b1101]
    );
    assert_eq!(
        WheelSpeedMsg {
            wheel_speed_fl: 1.0,
            wheel_speed_fr: 2.0,
            wheel_speed_rl: 3.0,
            wheel_speed_rr: 4.0
        }
        .encode(),
        [1, 2, 3, 4]
    );
    let abs = AbsMsg::decode(&[10, 20, 30, 40, 50, 60, 70, 80]).expect("valid");
    assert_eq!(
        (
            abs.brake_fl,
            abs.brake_rr,
            abs.abs_release_fl,
            abs.abs_release_rr
        ),
        (10.0, 40.0, 50.0, 80.0)
    );
    assert!(AbsMsg::decode(&[101, 0, 0, 0, 0, 0, 0, 0]).is_err());
    // Start values: what a receiver assumes before the first frame.
    assert_eq!(SteeringMsg::default().steering_angle, 0.0);
    assert_eq!(CruiseAccelMsg::default().cruise_accel, 0.0);
    assert_eq!(ShiftMsg::default().shift_request, ShiftRequest::None);
    assert_eq!(TransMsg::default().gear, Gear::Neutral);
    assert_eq!(CruiseModeMsg::default().cruise_mode, CruiseMode::Off);
}

/// A frame with one bad signal updates the good ones and keeps the bad one's last value.
pub fn update_keeps_the_last_good_value() {
    let mut engine = EngineMsg {
        engine_rpm: 3000.0,
        fuel_level: 40.0,
        engine_mode: EngineMode::Economy,
        fuel_used: 0.0,
    };
    let result = engine.update_from(&[100, 120, 7, 0, 0]);
    assert_eq!(
        result,
        Err(DecodeError::UndefinedValue {
            message: "EngineMsg",
            signal: "EngineMode",
            raw: 7
        })
    );
    assert_eq!(
        engine.engine_rpm,
        EngineMsg::ENGINE_RPM.to_physical_unchecked(100)
    );
    assert_eq!(engine.fuel_level, 30.0);
    assert_eq!(engine.engine_mode, EngineMode::Economy);

    let mut steering = SteeringMsg {
        steering_angle: 33.75,
    };
    assert!(steering.update_from(&[5]).is_err());
    assert_eq!(steering.steering_angle, 33.75);
    assert_eq!(steering.update_from(&[60]), Ok(()));
    assert_eq!(steering.steering_angle, 33.75);
    assert_eq!(steering.update_from(&[70]), Ok(()));
    assert_eq!(steering.steering_angle, 67.5);
}
