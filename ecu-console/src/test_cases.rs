//! Test cases shared by the host test suite and the on-target (defmt-test) suite. Each case
//! panics on failure.

use crate::*;
use autoplug_can::{CanMessage, Message};
use autoplug_ecu::{invalid_data, lost_communication};

fn ms(t: u64) -> Instant {
    Instant::from_millis(t)
}

fn brake_frame(brake_cmd: f32) -> Frame {
    PedalBrake { brake_cmd }.frame()
}

fn raw_frame(id: u16, data: &[u8]) -> Frame {
    match Frame::new(u32::from(id), data) {
        Ok(frame) => frame,
        Err(e) => panic!("bad test frame: {:?}", e),
    }
}

fn switches(
    headlight_switch: bool,
    economy_mode_switch: bool,
    manual_mode_switch: bool,
) -> Sensors {
    Sensors {
        headlight_switch,
        economy_mode_switch,
        manual_mode_switch,
    }
}

/// The AccMsg frames one transmit poll gave (at most one), as raw byte and message.
fn poll_acc(ecu: &mut ConsoleEcu, t: u64) -> Option<(u8, AccMsg)> {
    let frame = ecu.poll_transmit(ms(t))?;
    assert!(ecu.poll_transmit(ms(t)).is_none(), "one message only");
    match Message::from_frame(&frame) {
        Ok(Message::AccMsg(m)) => Some((frame.data()[0], m)),
        other => panic!("unexpected {:?}", other),
    }
}

/// Runs from `from` to `to` (ms, excluded): PedalBrake every 10 ms when `brake` is given,
/// a step every 10 ms, a transmit poll every ms. Returns the last outputs, the number of
/// AccMsg frames and the last one.
fn run(
    ecu: &mut ConsoleEcu,
    from: u64,
    to: u64,
    brake: Option<f32>,
    sensors: Sensors,
) -> (Actuators, u32, Option<(u8, AccMsg)>) {
    let mut out = Actuators::default();
    let mut frames = 0;
    let mut last = None;
    for t in from..to {
        if t % 10 == 0 {
            if let Some(b) = brake {
                ecu.on_frame(ms(t), &brake_frame(b));
            }
            out = ecu.step(ms(t), &sensors);
        }
        if let Some(acc) = poll_acc(ecu, t) {
            assert_eq!(
                acc.1.brake_lights, out.brake_lights,
                "AccMsg reports the lights"
            );
            assert_eq!(acc.1.headlights, out.headlights);
            frames += 1;
            last = Some(acc);
        }
    }
    (out, frames, last)
}

/// Spec section 7, "read switches, report signals": each switch drives its AccMsg bit
/// (and the headlights), sent at once on a change and every 100 ms.
pub fn reports_the_switches() {
    let mut ecu = ConsoleEcu::new(ms(0));
    let (out, frames, last) = run(&mut ecu, 0, 1000, Some(0.0), switches(false, false, false));
    assert_eq!(out, Actuators::default());
    assert_eq!(frames, 10, "every 100 ms");
    assert_eq!(last.map(|(raw, _)| raw), Some(0));
    assert_eq!(AccMsg::CYCLE_TIME_MS, 100);

    let cases = [
        (switches(true, false, false), 0b0001),
        (switches(false, true, false), 0b0100),
        (switches(false, false, true), 0b1000),
        (switches(true, true, true), 0b1101),
    ];
    // Each case: the periodic frame at t, the switch change at t + 50 (sent at once, half
    // a period early), the next periodic frame at t + 150.
    let mut t = 1000;
    let mut previous = switches(false, false, false);
    for (sensors, raw) in cases {
        let (_, frames, _) = run(&mut ecu, t, t + 50, Some(0.0), previous);
        assert_eq!(frames, 1, "the periodic frame at {} ms", t);
        ecu.on_frame(ms(t + 50), &brake_frame(0.0));
        let out = ecu.step(ms(t + 50), &sensors);
        assert_eq!(out.headlights, sensors.headlight_switch);
        let Some((sent, msg)) = poll_acc(&mut ecu, t + 50) else {
            panic!("a change goes out at once")
        };
        assert_eq!(sent, raw);
        assert_eq!(
            msg.engine_mode == EngineMode::Economy,
            sensors.economy_mode_switch
        );
        assert_eq!(
            msg.shift_mode_request == ShiftMode::Manual,
            sensors.manual_mode_switch
        );
        let (_, frames, last) = run(&mut ecu, t + 51, t + 250, Some(0.0), sensors);
        assert_eq!(frames, 1, "then every 100 ms: at {} ms", t + 150);
        assert_eq!(last.map(|(raw, _)| raw), Some(raw));
        previous = sensors;
        t += 250;
    }
}

/// Brake lights on above 2 %, off again at or below 1 %; AccMsg reports them at once.
pub fn brake_lights_follow_the_brake_command() {
    let mut ecu = ConsoleEcu::new(ms(0));
    let lights = switches(true, false, false);
    let (out, _, _) = run(&mut ecu, 0, 100, Some(0.0), lights);
    assert!(!out.brake_lights);
    let (out, _, _) = run(&mut ecu, 100, 150, Some(BRAKE_LIGHTS_ON_PCT), lights);
    assert!(!out.brake_lights, "at the threshold: off");
    ecu.on_frame(ms(150), &brake_frame(BRAKE_LIGHTS_ON_PCT + 1.0));
    assert!(ecu.step(ms(150), &lights).brake_lights);
    let Some((raw, _)) = poll_acc(&mut ecu, 150) else {
        panic!("the change goes out at once")
    };
    assert_eq!(raw, 0b0011);
    let (out, _, _) = run(&mut ecu, 151, 300, Some(BRAKE_LIGHTS_ON_PCT), lights);
    assert!(out.brake_lights, "hysteresis: still on at 2 %");
    let (out, _, last) = run(&mut ecu, 300, 350, Some(BRAKE_LIGHTS_OFF_PCT), lights);
    assert!(!out.brake_lights);
    assert_eq!(last.map(|(raw, _)| raw), Some(0b0001));
    let (out, _, _) = run(&mut ecu, 350, 400, Some(100.0), lights);
    assert!(out.brake_lights);
    assert_eq!(ecu.dtcs().records().count(), 0);
}

/// PedalBrake stale (and before the first frame): brake lights on, and "lost
/// communication with the pedals ECU"; back to normal when the frames return.
pub fn stale_brake_command_turns_the_brake_lights_on() {
    let mut ecu = ConsoleEcu::new(ms(0));
    let none = Sensors::default();
    assert!(
        ecu.step(ms(0), &none).brake_lights,
        "unknown before the first frame"
    );
    let (out, _, _) = run(&mut ecu, 10, 100, Some(0.0), none);
    assert!(!out.brake_lights);
    // The last PedalBrake at 90 ms: stale at 120 ms.
    let (out, _, _) = run(&mut ecu, 100, 120, None, none);
    assert!(!out.brake_lights, "fresh until 120 ms");
    let (out, _, last) = run(&mut ecu, 120, 130, None, none);
    assert!(out.brake_lights);
    assert_eq!(last.map(|(raw, _)| raw), Some(0b0010), "reported at once");
    let dtc = lost_communication(Node::Pedals);
    assert!(ecu.dtcs().is_active(dtc));
    let (out, _, _) = run(&mut ecu, 130, 500, None, none);
    assert!(out.brake_lights);
    let (out, _, _) = run(&mut ecu, 500, 520, Some(0.0), none);
    assert!(!out.brake_lights);
    assert!(!ecu.dtcs().is_active(dtc));
    assert!(ecu.dtcs().get(dtc).is_some(), "the DTC stays stored");
}

/// An invalid PedalBrake records "invalid data received from the pedals ECU" and keeps
/// the last good value; only invalid frames drive the input stale (lights on).
pub fn invalid_brake_frame_records_a_dtc() {
    let mut ecu = ConsoleEcu::new(ms(0));
    let none = Sensors::default();
    run(&mut ecu, 0, 100, Some(50.0), none);
    ecu.on_frame(ms(100), &raw_frame(PedalBrake::ID, &[101]));
    ecu.on_frame(ms(100), &raw_frame(PedalBrake::ID, &[0, 0]));
    assert!(ecu.dtcs().is_active(invalid_data(Node::Pedals)));
    assert!(ecu.step(ms(100), &none).brake_lights, "last good: 50 %");
    run(&mut ecu, 110, 150, Some(0.0), none);
    assert!(!ecu.dtcs().is_active(invalid_data(Node::Pedals)));
    // Only invalid frames from 150 ms on: the last good one was at 140 ms, stale at 170.
    let mut out = Actuators::default();
    for t in (150..=170).step_by(10) {
        ecu.on_frame(ms(t), &raw_frame(PedalBrake::ID, &[200]));
        out = ecu.step(ms(t), &none);
        if t < 170 {
            assert!(!out.brake_lights, "at {} ms: last good 0 %", t);
        }
    }
    assert!(out.brake_lights);
    assert!(ecu.dtcs().is_active(lost_communication(Node::Pedals)));
}

autoplug_ecu::test_cases!(
    reports_the_switches,
    brake_lights_follow_the_brake_command,
    stale_brake_command_turns_the_brake_lights_on,
    invalid_brake_frame_records_a_dtc,
);
