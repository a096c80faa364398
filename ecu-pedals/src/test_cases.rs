//! Test cases shared by the host test suite and the on-target (defmt-test) suite. Each case
//! panics on failure.

use crate::*;
use autoplug_can::Message;
use autoplug_ecu::{invalid_data, lost_communication};

fn ms(t: u64) -> Instant {
    Instant::from_millis(t)
}

fn mode_frame(on: bool) -> Frame {
    CruiseModeMsg {
        cruise_mode: if on { CruiseMode::On } else { CruiseMode::Off },
    }
    .frame()
}

fn command_frame(command: f32) -> Frame {
    CruiseAccelMsg {
        cruise_accel: command,
    }
    .frame()
}

fn cut_frame(cut: f32) -> Frame {
    TracMsg { traction_cut: cut }.frame()
}

fn raw_frame(id: u16, data: &[u8]) -> Frame {
    match Frame::new(u32::from(id), data) {
        Ok(frame) => frame,
        Err(e) => panic!("bad test frame: {:?}", e),
    }
}

fn pedals(accelerator_pedal: f32, brake_pedal: f32) -> Sensors {
    Sensors {
        accelerator_pedal,
        brake_pedal,
    }
}

/// What the other ECUs put on the bus, each message at its period (`None`: silent).
#[derive(Clone, Copy)]
struct Bus {
    cruise_on: Option<bool>,
    command: Option<f32>,
    cut: Option<f32>,
}

impl Bus {
    const QUIET: Bus = Bus {
        cruise_on: Some(false),
        command: Some(0.0),
        cut: Some(0.0),
    };

    fn cruise(command: f32) -> Bus {
        Bus {
            cruise_on: Some(true),
            command: Some(command),
            cut: Some(0.0),
        }
    }

    /// Delivers the frames due at `t` (ms).
    fn feed(&self, ecu: &mut PedalsEcu, t: u64) {
        if t % u64::from(CruiseModeMsg::CYCLE_TIME_MS) == 0 {
            if let Some(on) = self.cruise_on {
                ecu.on_frame(ms(t), &mode_frame(on));
            }
        }
        if t % u64::from(CruiseAccelMsg::CYCLE_TIME_MS) == 0 {
            if let Some(command) = self.command {
                ecu.on_frame(ms(t), &command_frame(command));
            }
        }
        if t % u64::from(TracMsg::CYCLE_TIME_MS) == 0 {
            if let Some(cut) = self.cut {
                ecu.on_frame(ms(t), &cut_frame(cut));
            }
        }
    }
}

/// The frames one transmit poll gave.
#[derive(Clone, Copy, Default)]
struct Sent {
    brake: Option<f32>,
    accel: Option<f32>,
    cancel: bool,
}

/// Polls until nothing is due; checks the identifier order and that the only
/// CruiseModeMsg the pedals send is Off.
fn poll_all(ecu: &mut PedalsEcu, t: u64) -> Sent {
    let mut sent = Sent::default();
    let mut last_id = 0;
    while let Some(frame) = ecu.poll_transmit(ms(t)) {
        assert!(frame.id() > last_id, "priority order, lowest ID first");
        last_id = frame.id();
        match Message::from_frame(&frame) {
            Ok(Message::PedalBrake(m)) => sent.brake = Some(m.brake_cmd),
            Ok(Message::PedalAccel(m)) => sent.accel = Some(m.accel_cmd),
            Ok(Message::CruiseModeMsg(m)) => {
                assert_eq!(m.cruise_mode, CruiseMode::Off, "the pedals only send Off");
                sent.cancel = true;
            }
            other => panic!("unexpected {:?}", other),
        }
    }
    sent
}

/// Runs from `from` to `to` (ms, excluded): the bus every ms, a step every 10 ms and a
/// transmit poll every `poll_every` ms. Returns the last outputs and the number of cancel
/// frames sent; asserts the cancel frames are at least the minimum gap apart and no
/// further apart than one step.
fn run(
    ecu: &mut PedalsEcu,
    from: u64,
    to: u64,
    bus: Bus,
    sensors: Sensors,
    poll_every: u64,
) -> (Actuators, u32) {
    let step_ms = STEP_PERIOD_US / 1000;
    let mut out = Actuators::default();
    let mut cancels = 0;
    let mut last_cancel: Option<u64> = None;
    for t in from..to {
        bus.feed(ecu, t);
        if t % step_ms == 0 {
            out = ecu.step(ms(t), &sensors);
        }
        if t % poll_every == 0 && poll_all(ecu, t).cancel {
            if let Some(last) = last_cancel {
                let gap = t - last;
                assert!(
                    gap >= u64::from(CruiseModeMsg::MIN_GAP_MS),
                    "cancel frames {} ms apart",
                    gap
                );
                assert!(gap <= step_ms, "cancel frames {} ms apart", gap);
            }
            last_cancel = Some(t);
            cancels += 1;
        }
    }
    (out, cancels)
}

fn close(a: f32, b: f32) -> bool {
    (a - b).abs() < 1e-4
}

/// Spec section 7, "read and report pedal signals": with cruise off the commands are the
/// pedals, clamped to 0..100, published every 10 ms in identifier order; the pedals never
/// send CruiseModeMsg on their own, cruise on or off.
pub fn reports_the_driver_pedals() {
    let mut ecu = PedalsEcu::new(ms(0));
    let (mut brake_frames, mut accel_frames) = (0, 0);
    for t in 0..100 {
        Bus::QUIET.feed(&mut ecu, t);
        if t % 10 == 0 {
            let out = ecu.step(ms(t), &pedals(42.0, 0.0));
            assert_eq!(
                out,
                Actuators {
                    accelerator_cmd: 42.0,
                    brake_cmd: 0.0
                }
            );
        }
        let sent = poll_all(&mut ecu, t);
        assert!(!sent.cancel);
        if let Some(accel) = sent.accel {
            assert_eq!(accel, 42.0);
            accel_frames += 1;
        }
        if let Some(brake) = sent.brake {
            assert_eq!(brake, 0.0);
            brake_frames += 1;
        }
    }
    assert_eq!((brake_frames, accel_frames), (10, 10));

    let cases = [
        (pedals(3.0, 17.0), 0.0, 17.0), // brake pressed: accelerator 0 (override)
        (pedals(130.0, 0.0), 100.0, 0.0),
        (pedals(-5.0, 250.0), 0.0, 100.0),
        (pedals(f32::NAN, f32::NAN), 0.0, 0.0),
        (pedals(f32::INFINITY, f32::NEG_INFINITY), 100.0, 0.0),
    ];
    for (i, (sensors, accel, brake)) in cases.iter().enumerate() {
        let t = 100 + 10 * i as u64;
        Bus::QUIET.feed(&mut ecu, t);
        let out = ecu.step(ms(t), sensors);
        assert_eq!((out.accelerator_cmd, out.brake_cmd), (*accel, *brake));
    }
    // Cruise on, feet off the pedals: a second of cruise without a single CruiseModeMsg.
    let (_, cancels) = run(&mut ecu, 200, 1200, Bus::cruise(20.0), pedals(0.0, 0.0), 1);
    assert_eq!(cancels, 0);
}

/// Cruise on: a positive cruise command drives the accelerator, a negative one the brake;
/// pedals below the threshold are ignored. Cruise off: the pedals again.
pub fn cruise_command_drives_the_commands() {
    let mut ecu = PedalsEcu::new(ms(0));
    let light = pedals(PEDAL_PRESSED_THRESHOLD - 1.0, 0.0);
    let (out, _) = run(&mut ecu, 0, 100, Bus::cruise(40.0), light, 10);
    assert!(ecu.cruise_driving());
    assert_eq!(
        out,
        Actuators {
            accelerator_cmd: 40.0,
            brake_cmd: 0.0
        }
    );
    let (out, _) = run(&mut ecu, 100, 150, Bus::cruise(0.0), light, 10);
    assert_eq!(out, Actuators::default(), "cruise command 0: coasting");
    assert!(
        out.brake_cmd.is_sign_positive() && out.accelerator_cmd.is_sign_positive(),
        "no -0.0 to the output stage"
    );
    let (out, _) = run(&mut ecu, 150, 200, Bus::cruise(-30.0), light, 10);
    assert_eq!(
        out,
        Actuators {
            accelerator_cmd: 0.0,
            brake_cmd: 30.0
        }
    );
    let (out, _) = run(&mut ecu, 200, 300, Bus::cruise(-30.0), pedals(0.0, 4.0), 10);
    assert_eq!(out.brake_cmd, 30.0, "a resting foot adds nothing");
    assert!(!ecu.cancelling());
    let (out, cancels) = run(&mut ecu, 300, 400, Bus::QUIET, light, 10);
    assert!(!ecu.cruise_driving());
    assert_eq!(cancels, 0);
    assert_eq!(
        out,
        Actuators {
            accelerator_cmd: PEDAL_PRESSED_THRESHOLD - 1.0,
            brake_cmd: 0.0
        }
    );
}

/// The cancel protocol on a brake press, polled every millisecond: CruiseModeMsg Off goes
/// out in the step that sees the press, then every 5 ms (the minimum gap) while the bus
/// still says On, even after the pedal is released; it stops once the bus shows Off. From
/// the press on, the outputs are the driver's pedals.
pub fn brake_press_cancels_cruise_until_off_is_seen() {
    let mut ecu = PedalsEcu::new(ms(0));
    let (out, cancels) = run(&mut ecu, 0, 100, Bus::cruise(50.0), pedals(0.0, 0.0), 1);
    assert_eq!((out.accelerator_cmd, cancels), (50.0, 0));

    // The press, at a step.
    Bus::cruise(50.0).feed(&mut ecu, 100);
    let out = ecu.step(ms(100), &pedals(0.0, 30.0));
    assert!(ecu.cancelling());
    assert_eq!(
        out,
        Actuators {
            accelerator_cmd: 0.0,
            brake_cmd: 30.0
        }
    );
    let sent = poll_all(&mut ecu, 100);
    assert!(sent.cancel, "Off in the same step as the press");
    assert_eq!(sent.brake, Some(30.0));
    for t in 101..105 {
        assert!(!poll_all(&mut ecu, t).cancel, "no sooner than 5 ms");
    }
    // The steering ECU is slow to adopt: On keeps coming. Off every 5 ms.
    let (out, cancels) = run(&mut ecu, 105, 130, Bus::cruise(50.0), pedals(0.0, 30.0), 1);
    assert_eq!(cancels, 5, "105, 110, 115, 120, 125");
    assert_eq!(out.brake_cmd, 30.0);
    // Released: the cancel still stands, the outputs stay the driver's (now nothing).
    let (out, cancels) = run(&mut ecu, 130, 162, Bus::cruise(50.0), pedals(0.0, 0.0), 1);
    assert_eq!(cancels, 7, "130 to 160");
    assert_eq!(
        out,
        Actuators::default(),
        "no cruise command during a cancel"
    );
    assert!(ecu.cancelling());
    // The steering ECU's Off arrives between steps: the cancel stops at once (nothing at
    // 165 ms), and a pressed pedal with cruise off sends nothing.
    let off = Bus {
        cruise_on: Some(false),
        ..Bus::cruise(50.0)
    };
    ecu.on_frame(ms(162), &mode_frame(false));
    assert!(!ecu.cancelling());
    let (_, cancels) = run(&mut ecu, 162, 1000, off, pedals(0.0, 30.0), 1);
    assert_eq!(cancels, 0, "nothing after Off is seen");
    assert!(!ecu.cancelling());
}

/// An accelerator press cancels too; with transmit polls only at the steps, Off goes out
/// in the press step and at every step until Off is seen.
pub fn accelerator_press_cancels_cruise() {
    let mut ecu = PedalsEcu::new(ms(0));
    run(&mut ecu, 0, 100, Bus::cruise(-20.0), pedals(0.0, 0.0), 10);
    Bus::cruise(-20.0).feed(&mut ecu, 100);
    let out = ecu.step(ms(100), &pedals(60.0, 0.0));
    assert!(poll_all(&mut ecu, 100).cancel);
    assert_eq!(
        out,
        Actuators {
            accelerator_cmd: 60.0,
            brake_cmd: 0.0
        }
    );
    let (_, cancels) = run(
        &mut ecu,
        101,
        150,
        Bus::cruise(-20.0),
        pedals(60.0, 0.0),
        10,
    );
    assert_eq!(cancels, 4, "110, 120, 130, 140: one per step");
    ecu.on_frame(ms(150), &mode_frame(false));
    let off = Bus {
        cruise_on: Some(false),
        ..Bus::cruise(-20.0)
    };
    let (out, cancels) = run(&mut ecu, 150, 400, off, pedals(60.0, 0.0), 10);
    assert_eq!(cancels, 0);
    assert_eq!(out.accelerator_cmd, 60.0);
    // Cruise switched on again while the foot is still down: cancelled again at once.
    Bus::cruise(-20.0).feed(&mut ecu, 400);
    ecu.step(ms(400), &pedals(60.0, 0.0));
    assert!(poll_all(&mut ecu, 400).cancel);
}

/// No cancel for a press below the threshold, nor for a press with cruise off.
pub fn no_cancel_below_the_threshold_or_with_cruise_off() {
    let mut ecu = PedalsEcu::new(ms(0));
    let light = pedals(PEDAL_PRESSED_THRESHOLD, PEDAL_PRESSED_THRESHOLD);
    let (out, cancels) = run(&mut ecu, 0, 500, Bus::cruise(10.0), light, 1);
    assert_eq!(cancels, 0);
    assert_eq!(out.accelerator_cmd, 10.0);
    let (out, cancels) = run(&mut ecu, 500, 1000, Bus::QUIET, pedals(80.0, 0.0), 1);
    assert_eq!(cancels, 0);
    assert_eq!(out.accelerator_cmd, 80.0);
}

/// A brake pressed past the threshold forces the accelerator command to 0.
pub fn brake_overrides_the_accelerator() {
    let mut ecu = PedalsEcu::new(ms(0));
    let (out, _) = run(&mut ecu, 0, 50, Bus::QUIET, pedals(80.0, 20.0), 10);
    assert_eq!(
        out,
        Actuators {
            accelerator_cmd: 0.0,
            brake_cmd: 20.0
        }
    );
    let below = PEDAL_PRESSED_THRESHOLD - 1.0;
    let (out, _) = run(&mut ecu, 50, 100, Bus::QUIET, pedals(80.0, below), 10);
    assert_eq!(
        out,
        Actuators {
            accelerator_cmd: 80.0,
            brake_cmd: below
        }
    );
}

/// TracMsg's cut scales the accelerator command, driver or cruise; the brake is never
/// cut. TracMsg stale: no cut, and "lost communication with the ABS ECU".
pub fn traction_cut_reduces_the_accelerator() {
    let mut ecu = PedalsEcu::new(ms(0));
    let cut = |c: f32| Bus {
        cut: Some(c),
        ..Bus::QUIET
    };
    let (out, _) = run(&mut ecu, 0, 50, cut(25.0), pedals(60.0, 0.0), 10);
    assert!(close(out.accelerator_cmd, 45.0), "{}", out.accelerator_cmd);
    let (out, _) = run(&mut ecu, 50, 100, cut(100.0), pedals(60.0, 0.0), 10);
    assert_eq!(out.accelerator_cmd, 0.0);
    let (out, _) = run(&mut ecu, 100, 150, cut(100.0), pedals(0.0, 50.0), 10);
    assert_eq!(out.brake_cmd, 50.0, "the brake is not cut");
    let cruise_cut = Bus {
        cut: Some(50.0),
        ..Bus::cruise(80.0)
    };
    let (out, _) = run(&mut ecu, 150, 250, cruise_cut, pedals(0.0, 0.0), 10);
    assert!(ecu.cruise_driving());
    assert!(close(out.accelerator_cmd, 40.0), "{}", out.accelerator_cmd);

    // TracMsg stops after its frame at 240 ms: stale at 270 ms, no cut from then on.
    let dtc = lost_communication(Node::ABS);
    let silent = Bus {
        cut: None,
        ..Bus::QUIET
    };
    let mut stale_at = None;
    for t in (250..400).step_by(10) {
        silent.feed(&mut ecu, t);
        let out = ecu.step(ms(t), &pedals(60.0, 0.0));
        if stale_at.is_none() && out.accelerator_cmd == 60.0 {
            stale_at = Some(t);
        }
    }
    assert_eq!(stale_at, Some(240 + 3 * u64::from(TracMsg::CYCLE_TIME_MS)));
    assert!(ecu.dtcs().is_active(dtc));
    let (out, _) = run(&mut ecu, 400, 450, cut(50.0), pedals(60.0, 0.0), 10);
    assert_eq!(out.accelerator_cmd, 30.0);
    assert!(!ecu.dtcs().is_active(dtc), "communication is back");
    assert!(ecu.dtcs().get(dtc).is_some(), "the DTC stays stored");
}

/// CruiseModeMsg stale: cruise treated as off (the pedals pass through, no cancel is sent
/// on a press), and "lost communication with the steering ECU".
pub fn stale_cruise_mode_passes_the_pedals_through() {
    let mut ecu = PedalsEcu::new(ms(0));
    let light = pedals(3.0, 0.0);
    let (out, _) = run(&mut ecu, 0, 100, Bus::cruise(60.0), light, 10);
    assert_eq!(out.accelerator_cmd, 60.0);
    // The last CruiseModeMsg was at 80 ms: stale at 140 ms.
    let silent = Bus {
        cruise_on: None,
        ..Bus::cruise(60.0)
    };
    let (out, _) = run(&mut ecu, 100, 140, silent, light, 10);
    assert_eq!(out.accelerator_cmd, 60.0, "still fresh at 130 ms");
    let (out, _) = run(&mut ecu, 140, 150, silent, light, 10);
    assert_eq!(
        out.accelerator_cmd, 3.0,
        "stale at 140 ms: the driver's pedal"
    );
    assert!(ecu.dtcs().is_active(lost_communication(Node::Steering)));
    let (out, cancels) = run(&mut ecu, 150, 400, silent, pedals(0.0, 40.0), 1);
    assert_eq!(cancels, 0, "nothing to cancel");
    assert_eq!(out.brake_cmd, 40.0);
}

/// CruiseAccelMsg stale with cruise on: the outputs are the driver's pedals (no coasting
/// on an unknown command), "lost communication with the cruise ECU"; a press still
/// cancels cruise.
pub fn stale_cruise_command_means_no_cruise_outputs() {
    let mut ecu = PedalsEcu::new(ms(0));
    let light = pedals(2.0, 0.0);
    let (out, _) = run(&mut ecu, 0, 100, Bus::cruise(70.0), light, 10);
    assert_eq!(out.accelerator_cmd, 70.0);
    let silent = Bus {
        command: None,
        ..Bus::cruise(70.0)
    };
    // The last CruiseAccelMsg was at 80 ms: stale at 140 ms.
    let (out, _) = run(&mut ecu, 100, 140, silent, light, 10);
    assert_eq!(out.accelerator_cmd, 70.0);
    let (out, cancels) = run(&mut ecu, 140, 200, silent, light, 10);
    assert_eq!(out.accelerator_cmd, 2.0);
    assert_eq!(cancels, 0);
    assert!(!ecu.cruise_driving());
    assert!(ecu.dtcs().is_active(lost_communication(Node::Cruise)));
    silent.feed(&mut ecu, 200);
    ecu.step(ms(200), &pedals(0.0, 50.0));
    assert!(poll_all(&mut ecu, 200).cancel, "the bus says On: cancel");
    // The steering ECU confirms the cancel; later cruise is switched on again and the
    // command returns: cruise drives again.
    ecu.on_frame(ms(210), &mode_frame(false));
    let (out, _) = run(&mut ecu, 210, 300, Bus::cruise(70.0), light, 10);
    assert!(!ecu.dtcs().is_active(lost_communication(Node::Cruise)));
    assert_eq!(out.accelerator_cmd, 70.0);
}

/// Invalid frames record "invalid data" against the sender and keep the last good value;
/// a sender that only sends invalid frames drives the input stale.
pub fn invalid_frames_record_dtcs() {
    let mut ecu = PedalsEcu::new(ms(0));
    let cruise_cut = Bus {
        cut: Some(50.0),
        ..Bus::cruise(40.0)
    };
    let (out, _) = run(&mut ecu, 0, 100, cruise_cut, pedals(0.0, 0.0), 10);
    assert_eq!(out.accelerator_cmd, 20.0);

    ecu.on_frame(ms(100), &raw_frame(CruiseAccelMsg::ID, &[201]));
    ecu.on_frame(ms(100), &raw_frame(TracMsg::ID, &[101]));
    ecu.on_frame(ms(100), &raw_frame(CruiseModeMsg::ID, &[2]));
    let out = ecu.step(ms(100), &pedals(0.0, 0.0));
    assert_eq!(out.accelerator_cmd, 20.0, "last good values kept");
    for node in [Node::Cruise, Node::ABS, Node::Steering] {
        assert!(ecu.dtcs().is_active(invalid_data(node)), "{:?}", node);
    }
    ecu.on_frame(ms(110), &command_frame(40.0));
    ecu.step(ms(110), &pedals(0.0, 0.0));
    assert!(!ecu.dtcs().is_active(invalid_data(Node::Cruise)));

    // Wrong length, then only invalid commands: stale 60 ms after the last good one.
    ecu.on_frame(ms(115), &raw_frame(CruiseAccelMsg::ID, &[100, 0]));
    assert!(ecu.dtcs().is_active(invalid_data(Node::Cruise)));
    let invalid_commands = Bus {
        command: None,
        ..cruise_cut
    };
    let mut out = Actuators::default();
    for t in (120..=170).step_by(10) {
        invalid_commands.feed(&mut ecu, t);
        if t % 20 == 0 {
            ecu.on_frame(ms(t), &raw_frame(CruiseAccelMsg::ID, &[255]));
        }
        out = ecu.step(ms(t), &pedals(0.0, 0.0));
        if t < 170 {
            assert_eq!(out.accelerator_cmd, 20.0, "at {} ms", t);
        }
    }
    assert_eq!(
        out.accelerator_cmd, 0.0,
        "stale at 170 ms (last good at 110 ms)"
    );
    assert!(ecu.dtcs().is_active(lost_communication(Node::Cruise)));
}

/// Whatever the pedals and the bus say, the commands stay within 0..100 and the
/// accelerator is 0 while the brake pedal is pressed.
pub fn commands_stay_within_limits() {
    let values = [
        f32::NAN,
        f32::NEG_INFINITY,
        -1000.0,
        -100.0,
        -1.0,
        0.0,
        PEDAL_PRESSED_THRESHOLD,
        50.0,
        100.0,
        1000.0,
        f32::INFINITY,
    ];
    let mut t = 0;
    for on in [false, true] {
        for command in [-100.0, -30.0, 0.0, 30.0, 100.0] {
            for cut in [0.0, 50.0, 100.0] {
                let mut ecu = PedalsEcu::new(ms(t));
                for accel in values {
                    for brake in values {
                        t += 10;
                        ecu.on_frame(ms(t), &mode_frame(on));
                        ecu.on_frame(ms(t), &command_frame(command));
                        ecu.on_frame(ms(t), &cut_frame(cut));
                        let out = ecu.step(ms(t), &pedals(accel, brake));
                        assert!((0.0..=PEDAL_FULL).contains(&out.accelerator_cmd));
                        assert!((0.0..=PEDAL_FULL).contains(&out.brake_cmd));
                        if brake > PEDAL_PRESSED_THRESHOLD {
                            assert_eq!(out.accelerator_cmd, 0.0);
                        }
                    }
                }
            }
        }
    }
}

autoplug_ecu::test_cases!(
    reports_the_driver_pedals,
    cruise_command_drives_the_commands,
    brake_press_cancels_cruise_until_off_is_seen,
    accelerator_press_cancels_cruise,
    no_cancel_below_the_threshold_or_with_cruise_off,
    brake_overrides_the_accelerator,
    traction_cut_reduces_the_accelerator,
    stale_cruise_mode_passes_the_pedals_through,
    stale_cruise_command_means_no_cruise_outputs,
    invalid_frames_record_dtcs,
    commands_stay_within_limits,
);
