//! Test cases shared by the host test suite and the on-target (defmt-test) suite. Each case
//! panics on failure.

use crate::*;
use autoplug_can::{CanMessage, Message, ShiftMode};
use autoplug_ecu::{invalid_data, lost_communication};

fn ms(t: u64) -> Instant {
    Instant::from_millis(t)
}

fn acc_frame(mode: EngineMode) -> Frame {
    AccMsg {
        headlights: true,
        brake_lights: false,
        engine_mode: mode,
        shift_mode_request: ShiftMode::Automatic,
    }
    .frame()
}

fn raw_frame(id: u16, data: &[u8]) -> Frame {
    match Frame::new(u32::from(id), data) {
        Ok(frame) => frame,
        Err(e) => panic!("bad test frame: {:?}", e),
    }
}

fn engine(engine_rpm: f32, fuel_level_l: f32) -> Sensors {
    Sensors {
        engine_rpm,
        fuel_level_l,
        fuel_flow_l_per_h: 0.0,
    }
}

/// The EngineMsg one transmit poll gave, raw bytes and message.
fn poll_engine(ecu: &mut EngineEcu, t: u64) -> Option<([u8; 5], EngineMsg)> {
    let frame = ecu.poll_transmit(ms(t))?;
    assert!(ecu.poll_transmit(ms(t)).is_none(), "one message only");
    let mut raw = [0u8; 5];
    assert_eq!(frame.len(), 5);
    raw.copy_from_slice(frame.data());
    match Message::from_frame(&frame) {
        Ok(Message::EngineMsg(m)) => Some((raw, m)),
        other => panic!("unexpected {:?}", other),
    }
}

/// Runs from `from` to `to` (ms, excluded): AccMsg every 100 ms when `mode` is given, a
/// step every 20 ms, a transmit poll every ms. Returns the last status, the number of
/// EngineMsg frames and the last one; checks each frame reports the status.
fn run(
    ecu: &mut EngineEcu,
    from: u64,
    to: u64,
    mode: Option<EngineMode>,
    sensors: Sensors,
) -> (Status, u32, Option<([u8; 5], EngineMsg)>) {
    let mut status = Status::default();
    let mut frames = 0;
    let mut last = None;
    for t in from..to {
        if t % u64::from(AccMsg::CYCLE_TIME_MS) == 0 {
            if let Some(mode) = mode {
                ecu.on_frame(ms(t), &acc_frame(mode));
            }
        }
        if t % 20 == 0 {
            status = ecu.step(ms(t), &sensors);
        }
        if let Some(sent) = poll_engine(ecu, t) {
            assert_eq!(sent.1.engine_mode, status.engine_mode);
            frames += 1;
            last = Some(sent);
        }
    }
    (status, frames, last)
}

/// Spec section 7, "read and report fuel and RPM": EngineMsg every 20 ms with the RPM
/// (35.3 rpm per bit), the fuel level (0.25 L per bit) and the engine mode; readings
/// clamped to the encodable range, NaN reported as 0.
pub fn reports_rpm_and_fuel() {
    let mut ecu = EngineEcu::new(ms(0));
    let (status, frames, last) = run(
        &mut ecu,
        0,
        200,
        Some(EngineMode::Sport),
        engine(3000.0, 48.0),
    );
    assert_eq!(frames, 10, "every 20 ms");
    assert_eq!(status.engine_rpm, 3000.0);
    assert_eq!(status.fuel_level_l, 48.0);
    assert_eq!(status.engine_mode, EngineMode::Sport);
    assert_eq!(last.map(|(raw, _)| raw), Some([85, 192, 0, 0, 0]));

    let cases = [
        (
            engine(12_000.0, 80.0),
            ENGINE_RPM_MAX,
            FUEL_LEVEL_MAX_L,
            [255, 255],
        ),
        (engine(-100.0, -1.0), 0.0, 0.0, [0, 0]),
        (engine(f32::NAN, f32::NAN), 0.0, 0.0, [0, 0]),
        (engine(850.0, 12.3), 850.0, 12.3, [24, 49]),
    ];
    for (i, (sensors, rpm, fuel, raw)) in cases.iter().enumerate() {
        let t = 200 + 20 * i as u64;
        let (status, frames, last) = run(&mut ecu, t, t + 20, Some(EngineMode::Sport), *sensors);
        assert_eq!(frames, 1);
        assert_eq!((status.engine_rpm, status.fuel_level_l), (*rpm, *fuel));
        let Some((sent, msg)) = last else {
            panic!("EngineMsg every step")
        };
        assert_eq!([sent[0], sent[1]], *raw);
        assert!((msg.engine_rpm - rpm).abs() <= 35.3 / 2.0);
        assert!((msg.fuel_level - fuel).abs() <= 0.125);
    }
}

/// The engine mode follows AccMsg's bit 2, reported at the next step.
pub fn echoes_the_engine_mode() {
    let mut ecu = EngineEcu::new(ms(0));
    let (status, _, last) = run(
        &mut ecu,
        0,
        150,
        Some(EngineMode::Sport),
        engine(2000.0, 30.0),
    );
    assert_eq!(status.engine_mode, EngineMode::Sport);
    assert_eq!(last.map(|(raw, _)| raw[2]), Some(0));
    // The switch flips at 150 ms: the console sends at once, the echo follows at 160 ms.
    ecu.on_frame(ms(150), &acc_frame(EngineMode::Economy));
    let (status, _, last) = run(&mut ecu, 151, 170, None, engine(2000.0, 30.0));
    assert_eq!(status.engine_mode, EngineMode::Economy);
    assert_eq!(last.map(|(raw, _)| raw[2]), Some(1));
    let (status, _, _) = run(
        &mut ecu,
        170,
        400,
        Some(EngineMode::Sport),
        engine(2000.0, 30.0),
    );
    assert_eq!(status.engine_mode, EngineMode::Sport);
    assert_eq!(ecu.dtcs().records().count(), 0);
}

/// Economy until the first AccMsg and while AccMsg is stale, with "lost communication
/// with the console ECU"; the echo resumes when the frames return.
pub fn stale_console_reports_economy() {
    let mut ecu = EngineEcu::new(ms(0));
    assert_eq!(
        ecu.step(ms(0), &engine(900.0, 40.0)).engine_mode,
        SAFE_ENGINE_MODE,
        "unknown before the first AccMsg"
    );
    assert_eq!(SAFE_ENGINE_MODE, EngineMode::Economy);
    let (status, _, _) = run(
        &mut ecu,
        20,
        200,
        Some(EngineMode::Sport),
        engine(900.0, 40.0),
    );
    assert_eq!(status.engine_mode, EngineMode::Sport);
    // The last AccMsg at 100 ms: stale at 400 ms.
    let (status, _, _) = run(&mut ecu, 200, 400, None, engine(900.0, 40.0));
    assert_eq!(status.engine_mode, EngineMode::Sport, "fresh until 400 ms");
    let (status, _, last) = run(&mut ecu, 400, 420, None, engine(900.0, 40.0));
    assert_eq!(status.engine_mode, EngineMode::Economy);
    assert_eq!(last.map(|(raw, _)| raw[2]), Some(1));
    let dtc = lost_communication(Node::Console);
    assert!(ecu.dtcs().is_active(dtc));
    let (status, _, _) = run(
        &mut ecu,
        500,
        520,
        Some(EngineMode::Sport),
        engine(900.0, 40.0),
    );
    assert_eq!(status.engine_mode, EngineMode::Sport);
    assert!(!ecu.dtcs().is_active(dtc));
    assert!(ecu.dtcs().get(dtc).is_some(), "the DTC stays stored");
}

/// An AccMsg of the wrong length records "invalid data received from the console ECU"
/// and keeps the last good mode; only invalid frames drive the input stale.
pub fn invalid_console_frame_records_a_dtc() {
    let mut ecu = EngineEcu::new(ms(0));
    run(
        &mut ecu,
        0,
        100,
        Some(EngineMode::Sport),
        engine(900.0, 40.0),
    );
    // An economy bit, but two bytes: refused.
    ecu.on_frame(ms(100), &raw_frame(AccMsg::ID, &[0b0100, 0]));
    ecu.on_frame(ms(100), &raw_frame(AccMsg::ID, &[]));
    assert!(ecu.dtcs().is_active(invalid_data(Node::Console)));
    assert_eq!(
        ecu.step(ms(100), &engine(900.0, 40.0)).engine_mode,
        EngineMode::Sport
    );
    ecu.on_frame(ms(110), &acc_frame(EngineMode::Sport));
    assert!(!ecu.dtcs().is_active(invalid_data(Node::Console)));
    // Only invalid frames from 200 ms on: the last good one at 110 ms, stale at 410 ms.
    let mut status = Status::default();
    for t in (120..=420).step_by(20) {
        if t % 100 == 0 {
            ecu.on_frame(ms(t), &raw_frame(AccMsg::ID, &[0, 0]));
        }
        status = ecu.step(ms(t), &engine(900.0, 40.0));
        if t < 410 {
            assert_eq!(status.engine_mode, EngineMode::Sport, "at {} ms", t);
        }
    }
    assert_eq!(status.engine_mode, EngineMode::Economy);
    assert!(ecu.dtcs().is_active(lost_communication(Node::Console)));
}

/// The fuel flow is integrated over the measured step time into the rolling 1 mL counter:
/// exact over many steps (the sub-millilitre remainder is carried), wrapping after
/// 65535 mL, a NaN or negative flow adds nothing and a long gap counts as one second.
pub fn counts_fuel_used() {
    let mut ecu = EngineEcu::new(ms(0));
    let flow = |fuel_flow_l_per_h| Sensors {
        engine_rpm: 3000.0,
        fuel_level_l: 40.0,
        fuel_flow_l_per_h,
    };
    // 36 L/h is 10 mL/s: 100 s of 20 ms steps is 1000 mL.
    let mut status = Status::default();
    for step in 0..=5000u64 {
        status = ecu.step(ms(step * 20), &flow(36.0));
    }
    assert_eq!(status.fuel_used_ml, 1000);
    let mut last = None;
    while let Some(frame) = ecu.poll_transmit(ms(100_000)) {
        last = Some(frame);
    }
    let Some(frame) = last else {
        panic!("EngineMsg sent")
    };
    let msg = match EngineMsg::decode(frame.data()) {
        Ok(msg) => msg,
        Err(e) => panic!("{:?}", e),
    };
    assert_eq!(msg.fuel_used, 1000.0);
    assert_eq!(&frame.data()[3..5], &1000u16.to_le_bytes());

    // 0.9 L/h is 5 µL a 20 ms step: still counted (1 mL after 200 steps).
    let mut slow = EngineEcu::new(ms(0));
    let mut status = Status::default();
    for step in 0..=200u64 {
        status = slow.step(ms(step * 20), &flow(0.9));
    }
    assert_eq!(status.fuel_used_ml, 1);

    // Nothing for an unreadable or negative flow; a 10 s gap counts as 1 s.
    let t = 100_000;
    assert_eq!(ecu.step(ms(t + 20), &flow(f32::NAN)).fuel_used_ml, 1000);
    assert_eq!(ecu.step(ms(t + 40), &flow(-50.0)).fuel_used_ml, 1000);
    assert_eq!(ecu.step(ms(t + 10_040), &flow(36.0)).fuel_used_ml, 1010);

    // The counter wraps at 16 bits: 150 L/h (the input's maximum, 41.67 mL/s) for 1600 s
    // is 66667 mL, sent as 66667 - 65536.
    let mut full = EngineEcu::new(ms(0));
    let mut status = Status::default();
    for step in 0..=80_000u64 {
        status = full.step(ms(step * 20), &flow(1000.0));
    }
    assert!(
        (1129..=1133).contains(&status.fuel_used_ml),
        "{}",
        status.fuel_used_ml
    );
}

autoplug_ecu::test_cases!(
    reports_rpm_and_fuel,
    echoes_the_engine_mode,
    stale_console_reports_economy,
    invalid_console_frame_records_a_dtc,
    counts_fuel_used,
);
