//! Test cases shared by the host test suite and the on-target (defmt-test) suite. Each case
//! panics on failure.

use crate::*;
use autoplug_can::{CanMessage, Message};
use autoplug_ecu::lost_communication;

fn ms(t: u64) -> Instant {
    Instant::from_millis(t)
}

fn wheel(angle: f32) -> Sensors {
    Sensors {
        wheel_angle_deg: angle,
        ..Sensors::default()
    }
}

const NOTHING: Sensors = Sensors {
    wheel_angle_deg: 0.0,
    shift_up_button: false,
    shift_down_button: false,
    cruise_on_button: false,
    cruise_off_button: false,
};

const UP: Sensors = Sensors {
    shift_up_button: true,
    ..NOTHING
};

const DOWN: Sensors = Sensors {
    shift_down_button: true,
    ..NOTHING
};

const CRUISE_ON: Sensors = Sensors {
    cruise_on_button: true,
    ..NOTHING
};

const CRUISE_OFF: Sensors = Sensors {
    cruise_off_button: true,
    ..NOTHING
};

fn cancel_frame(on: bool) -> Frame {
    CruiseModeMsg {
        cruise_mode: if on { CruiseMode::On } else { CruiseMode::Off },
    }
    .frame()
}

fn raw_frame(id: u16, data: &[u8]) -> Frame {
    match Frame::new(u32::from(id), data) {
        Ok(frame) => frame,
        Err(e) => panic!("bad test frame: {:?}", e),
    }
}

/// The frames one transmit poll gave.
#[derive(Clone, Copy, Default)]
struct Sent {
    steering: Option<f32>,
    cruise: Option<CruiseMode>,
    shift: Option<ShiftRequest>,
}

fn poll_all(ecu: &mut SteeringEcu, t: u64) -> Sent {
    let mut sent = Sent::default();
    let mut last_id = 0;
    while let Some(frame) = ecu.poll_transmit(ms(t)) {
        assert!(frame.id() > last_id, "priority order, lowest ID first");
        last_id = frame.id();
        match Message::from_frame(&frame) {
            Ok(Message::SteeringMsg(m)) => sent.steering = Some(m.steering_angle),
            Ok(Message::CruiseModeMsg(m)) => sent.cruise = Some(m.cruise_mode),
            Ok(Message::ShiftMsg(m)) => sent.shift = Some(m.shift_request),
            other => panic!("unexpected {:?}", other),
        }
    }
    sent
}

/// Frames of one kind sent over a run: when (ms) and what, up to 128.
struct Trace<T: Copy> {
    at: [u64; 128],
    value: [Option<T>; 128],
    len: usize,
}

impl<T: Copy + PartialEq + core::fmt::Debug> Trace<T> {
    fn new() -> Self {
        Self {
            at: [0; 128],
            value: [None; 128],
            len: 0,
        }
    }

    fn push(&mut self, t: u64, value: Option<T>) {
        if let Some(v) = value {
            assert!(self.len < 128, "trace full");
            self.at[self.len] = t;
            self.value[self.len] = Some(v);
            self.len += 1;
        }
    }

    /// Asserts the trace is exactly `expected`.
    fn assert_is(&self, expected: &[(u64, T)]) {
        assert_eq!(self.len, expected.len(), "frame count");
        for (i, (t, v)) in expected.iter().enumerate() {
            assert_eq!((self.at[i], self.value[i]), (*t, Some(*v)), "frame {}", i);
        }
    }
}

/// Runs from `from` to `to` (ms, excluded), a step every 10 ms with `sensors(t)`, a
/// transmit poll every ms; records the ShiftMsg and CruiseModeMsg frames.
fn run(
    ecu: &mut SteeringEcu,
    from: u64,
    to: u64,
    sensors: impl Fn(u64) -> Sensors,
    shifts: &mut Trace<ShiftRequest>,
    cruise: &mut Trace<CruiseMode>,
) -> Actuators {
    let mut out = Actuators::default();
    for t in from..to {
        if t % 10 == 0 {
            out = ecu.step(ms(t), &sensors(t));
        }
        let sent = poll_all(ecu, t);
        shifts.push(t, sent.shift);
        cruise.push(t, sent.cruise);
    }
    out
}

/// Spec section 7, "read wheel, report angle": the wheel angle drives the steering output
/// and SteeringMsg, clamped to ±135°; SteeringMsg every 10 ms, ShiftMsg (None) and
/// CruiseModeMsg (Off) every 20 ms from the start.
pub fn reports_the_wheel_angle() {
    assert_eq!(
        SteeringMsg::STEERING_ANGLE.to_physical_unchecked(90),
        STEERING_LIMIT_DEG,
        "the limit is the catalogue's range"
    );
    assert_eq!(
        SteeringMsg::STEERING_ANGLE.to_physical_unchecked(10),
        -STEERING_LIMIT_DEG
    );
    let mut ecu = SteeringEcu::new(ms(0));
    let (mut steering, mut shift, mut cruise) = (0, 0, 0);
    for t in 0..100 {
        if t % 10 == 0 {
            let out = ecu.step(ms(t), &wheel(45.0));
            assert_eq!(out.steering_cmd_deg, 45.0);
        }
        let sent = poll_all(&mut ecu, t);
        if let Some(angle) = sent.steering {
            assert!((angle - 45.0).abs() <= 3.375 / 2.0, "sent {}", angle);
            steering += 1;
        }
        if let Some(request) = sent.shift {
            assert_eq!(request, ShiftRequest::None);
            shift += 1;
        }
        if let Some(mode) = sent.cruise {
            assert_eq!(mode, CruiseMode::Off);
            cruise += 1;
        }
    }
    assert_eq!((steering, shift, cruise), (10, 5, 5));

    let cases = [
        (-90.0, -90.0),
        (0.0, 0.0),
        (200.0, 135.0),
        (-500.0, -135.0),
        (f32::INFINITY, 135.0),
        (f32::NAN, 0.0),
    ];
    for (i, (angle, expected)) in cases.iter().enumerate() {
        let t = 100 + 10 * i as u64;
        let out = ecu.step(ms(t), &wheel(*angle));
        assert_eq!(out.steering_cmd_deg, *expected);
        let sent = poll_all(&mut ecu, t);
        let Some(angle) = sent.steering else {
            panic!("SteeringMsg every step")
        };
        assert!((angle - expected).abs() <= 3.375 / 2.0, "sent {}", angle);
    }
}

/// A button counts after 2 consecutive steps; a one-step blip does nothing, and a
/// one-step bounce while held is not a new press.
pub fn buttons_are_debounced() {
    let mut ecu = SteeringEcu::new(ms(0));
    let (mut shifts, mut cruise) = (Trace::new(), Trace::new());
    // One-step blips of every button.
    for (i, button) in [UP, DOWN, CRUISE_ON].into_iter().enumerate() {
        let blip = 30 * i as u64 + 10;
        run(
            &mut ecu,
            blip - 10,
            blip + 20,
            |t| if t == blip { button } else { NOTHING },
            &mut shifts,
            &mut cruise,
        );
        assert_eq!(ecu.shift_request(), ShiftRequest::None);
        assert_eq!(ecu.cruise_mode(), CruiseMode::Off);
    }
    // Two steps: the press counts at the second.
    ecu.step(ms(100), &CRUISE_ON);
    assert_eq!(ecu.cruise_mode(), CruiseMode::Off);
    ecu.step(ms(110), &CRUISE_ON);
    assert_eq!(ecu.cruise_mode(), CruiseMode::On);
    // Held with a one-step bounce, then off and on again via the off button in between:
    // the bounce is not a release, so holding on does not re-engage after the off press.
    ecu.step(ms(120), &NOTHING);
    ecu.step(ms(130), &CRUISE_ON);
    let both = Sensors {
        cruise_off_button: true,
        ..CRUISE_ON
    };
    ecu.step(ms(140), &both);
    ecu.step(ms(150), &both);
    assert_eq!(ecu.cruise_mode(), CruiseMode::Off);
    for t in (160..300).step_by(10) {
        ecu.step(ms(t), &if t == 200 { NOTHING } else { CRUISE_ON });
    }
    assert_eq!(ecu.cruise_mode(), CruiseMode::Off, "no new press edge");
    // A real release (2 steps) and press (2 steps).
    ecu.step(ms(300), &NOTHING);
    ecu.step(ms(310), &NOTHING);
    ecu.step(ms(320), &CRUISE_ON);
    assert_eq!(ecu.cruise_mode(), CruiseMode::Off);
    ecu.step(ms(330), &CRUISE_ON);
    assert_eq!(ecu.cruise_mode(), CruiseMode::On);
    assert_eq!(DEBOUNCE_STEPS, 2, "the timings above assume 2 steps");
}

/// A shift-up press edge makes ShiftMsg Up for 100 ms (5 frames at 20 ms, the first at
/// once), then None; holding the paddle does not repeat it. Down alike.
pub fn shift_paddle_sends_a_pulse() {
    let mut ecu = SteeringEcu::new(ms(0));
    let (mut shifts, mut cruise) = (Trace::new(), Trace::new());
    run(&mut ecu, 0, 100, |_| NOTHING, &mut shifts, &mut cruise);
    let (mut shifts, mut cruise) = (Trace::new(), Trace::new());
    // Held from 100 ms: debounced at 110 ms; the pulse ends at 210 ms.
    run(&mut ecu, 100, 400, |_| UP, &mut shifts, &mut cruise);
    use ShiftRequest::{Down, None, Up};
    shifts.assert_is(&[
        (100, None),
        (110, Up),
        (130, Up),
        (150, Up),
        (170, Up),
        (190, Up),
        (210, None),
        (230, None),
        (250, None),
        (270, None),
        (290, None),
        (310, None),
        (330, None),
        (350, None),
        (370, None),
        (390, None),
    ]);
    assert_eq!(SHIFT_PULSE_MS, 100, "the trace above assumes 100 ms");
    let (mut shifts, mut cruise) = (Trace::new(), Trace::new());
    run(&mut ecu, 400, 460, |_| NOTHING, &mut shifts, &mut cruise);
    let (mut shifts, mut cruise) = (Trace::new(), Trace::new());
    run(
        &mut ecu,
        460,
        600,
        |t| if t < 500 { DOWN } else { NOTHING },
        &mut shifts,
        &mut cruise,
    );
    shifts.assert_is(&[
        (470, Down),
        (490, Down),
        (510, Down),
        (530, Down),
        (550, Down),
        (570, None),
        (590, None),
    ]);
}

/// A press edge during a pulse, its last step included, is ignored: two requests are
/// always separated by None, so the transmission sees every None -> Up/Down edge.
pub fn a_press_during_a_pulse_is_ignored() {
    let mut ecu = SteeringEcu::new(ms(0));
    let (mut shifts, mut cruise) = (Trace::new(), Trace::new());
    run(&mut ecu, 0, 100, |_| NOTHING, &mut shifts, &mut cruise);
    let (mut shifts, mut cruise) = (Trace::new(), Trace::new());
    // Press edges at 110 ms (starts the pulse, which ends at 210 ms), 150 ms (during the
    // pulse) and 210 ms (the pulse's last step).
    let taps = |t: u64| {
        if (100..120).contains(&t) || (140..160).contains(&t) || (200..220).contains(&t) {
            UP
        } else {
            NOTHING
        }
    };
    run(&mut ecu, 100, 300, taps, &mut shifts, &mut cruise);
    use ShiftRequest::{None, Up};
    shifts.assert_is(&[
        (100, None),
        (110, Up),
        (130, Up),
        (150, Up),
        (170, Up),
        (190, Up),
        (210, None),
        (230, None),
        (250, None),
        (270, None),
        (290, None),
    ]);
    // After the pulse, a press is a new request again.
    let (mut shifts, mut cruise) = (Trace::new(), Trace::new());
    run(&mut ecu, 300, 330, |_| UP, &mut shifts, &mut cruise);
    shifts.assert_is(&[(310, Up)]);
}

/// Both paddles at once mean no request; pressing the other paddle during a pulse ends it.
pub fn both_paddles_mean_no_request() {
    let mut ecu = SteeringEcu::new(ms(0));
    let (mut shifts, mut cruise) = (Trace::new(), Trace::new());
    let both = Sensors {
        shift_down_button: true,
        ..UP
    };
    run(&mut ecu, 0, 200, |_| both, &mut shifts, &mut cruise);
    for i in 0..shifts.len {
        assert_eq!(shifts.value[i], Some(ShiftRequest::None));
    }
    assert_eq!(ecu.shift_request(), ShiftRequest::None);
    let (mut shifts, mut cruise) = (Trace::new(), Trace::new());
    run(&mut ecu, 200, 260, |_| NOTHING, &mut shifts, &mut cruise);
    let (mut shifts, mut cruise) = (Trace::new(), Trace::new());
    run(
        &mut ecu,
        260,
        320,
        |t| if t < 280 { UP } else { both },
        &mut shifts,
        &mut cruise,
    );
    shifts.assert_is(&[
        (260, ShiftRequest::None),
        (270, ShiftRequest::Up),
        (290, ShiftRequest::None),
        (310, ShiftRequest::None),
    ]);
}

/// The cruise buttons set the cruise state, sent at once on a change and every 20 ms;
/// both at once: Off.
pub fn cruise_buttons_set_the_state() {
    let mut ecu = SteeringEcu::new(ms(0));
    let (mut shifts, mut cruise) = (Trace::new(), Trace::new());
    run(&mut ecu, 0, 45, |_| NOTHING, &mut shifts, &mut cruise);
    let (mut shifts, mut cruise) = (Trace::new(), Trace::new());
    run(
        &mut ecu,
        45,
        120,
        |t| if t < 70 { CRUISE_ON } else { NOTHING },
        &mut shifts,
        &mut cruise,
    );
    use CruiseMode::{Off, On};
    cruise.assert_is(&[(60, On), (80, On), (100, On)]);
    let (mut shifts, mut cruise) = (Trace::new(), Trace::new());
    run(
        &mut ecu,
        120,
        200,
        |t| if t < 160 { CRUISE_OFF } else { NOTHING },
        &mut shifts,
        &mut cruise,
    );
    cruise.assert_is(&[(120, On), (130, Off), (150, Off), (170, Off), (190, Off)]);
    run(
        &mut ecu,
        200,
        260,
        |t| if t < 230 { CRUISE_ON } else { NOTHING },
        &mut shifts,
        &mut cruise,
    );
    assert_eq!(ecu.cruise_mode(), On);
    let both = Sensors {
        cruise_off_button: true,
        ..CRUISE_ON
    };
    let (mut shifts, mut cruise) = (Trace::new(), Trace::new());
    run(&mut ecu, 260, 300, |_| both, &mut shifts, &mut cruise);
    assert_eq!(ecu.cruise_mode(), Off);
    cruise.assert_is(&[(270, Off), (290, Off)]);
}

/// A CruiseModeMsg Off from the pedals while cruise is On turns the state Off at once:
/// the next transmit poll (no sooner than 5 ms after the previous frame) sends Off, and
/// Off stays.
/// A received On is ignored.
pub fn adopts_a_cancel_from_the_pedals() {
    let mut ecu = SteeringEcu::new(ms(0));
    let (mut shifts, mut cruise) = (Trace::new(), Trace::new());
    run(
        &mut ecu,
        0,
        100,
        |t| if t < 30 { CRUISE_ON } else { NOTHING },
        &mut shifts,
        &mut cruise,
    );
    assert_eq!(ecu.cruise_mode(), CruiseMode::On);
    // The last CruiseModeMsg went at 90 ms; the cancel arrives between steps.
    ecu.on_frame(ms(103), &cancel_frame(false));
    assert_eq!(ecu.cruise_mode(), CruiseMode::Off);
    let (mut shifts, mut cruise) = (Trace::new(), Trace::new());
    run(&mut ecu, 103, 160, |_| NOTHING, &mut shifts, &mut cruise);
    use CruiseMode::Off;
    cruise.assert_is(&[(103, Off), (123, Off), (143, Off)]);
    // The pedals never send On; if anything did, only the button turns cruise on.
    ecu.on_frame(ms(160), &cancel_frame(true));
    ecu.step(ms(160), &NOTHING);
    assert_eq!(ecu.cruise_mode(), CruiseMode::Off);
    // A cancel while already off changes nothing.
    ecu.on_frame(ms(165), &cancel_frame(false));
    assert_eq!(ecu.cruise_mode(), CruiseMode::Off);
    assert_eq!(ecu.dtcs().records().count(), 0);
}

/// CruiseModeMsg is normally silent (the steering ECU does not hear its own frames, the
/// pedals send only to cancel): seconds without it are no fault, no DTC, no state change.
pub fn cruise_mode_input_is_not_supervised() {
    let mut ecu = SteeringEcu::new(ms(0));
    let (mut shifts, mut cruise) = (Trace::new(), Trace::new());
    run(
        &mut ecu,
        0,
        2000,
        |t| if t < 30 { CRUISE_ON } else { wheel(10.0) },
        &mut shifts,
        &mut cruise,
    );
    assert_eq!(ecu.cruise_mode(), CruiseMode::On);
    assert_eq!(ecu.dtcs().records().count(), 0);
    assert!(!ecu.dtcs().is_active(lost_communication(Node::Pedals)));
    assert!(!ecu.dtcs().is_active(lost_communication(Node::Steering)));
}

/// A cancel frame with an invalid value (or length) records "invalid data received from
/// the pedals ECU" and changes nothing; the next valid cancel clears it.
pub fn invalid_cancel_records_a_dtc() {
    let mut ecu = SteeringEcu::new(ms(0));
    ecu.step(ms(0), &CRUISE_ON);
    ecu.step(ms(10), &CRUISE_ON);
    assert_eq!(ecu.cruise_mode(), CruiseMode::On);
    ecu.on_frame(ms(15), &raw_frame(CruiseModeMsg::ID, &[2]));
    assert_eq!(ecu.cruise_mode(), CruiseMode::On);
    assert!(ecu.dtcs().is_active(INVALID_CANCEL_DTC));
    assert_eq!(INVALID_CANCEL_DTC, autoplug_ecu::invalid_data(Node::Pedals));
    assert!(ecu
        .dtcs()
        .get(autoplug_ecu::invalid_data(Node::Steering))
        .is_none());
    ecu.on_frame(ms(16), &raw_frame(CruiseModeMsg::ID, &[0, 0]));
    assert_eq!(ecu.cruise_mode(), CruiseMode::On, "wrong length: refused");
    // Other identifiers are not this ECU's business.
    ecu.on_frame(ms(17), &raw_frame(ShiftMsg::ID, &[9]));
    ecu.on_frame(ms(18), &cancel_frame(false));
    assert_eq!(ecu.cruise_mode(), CruiseMode::Off);
    assert!(!ecu.dtcs().is_active(INVALID_CANCEL_DTC));
    assert_eq!(ecu.dtcs().records().count(), 1, "only the invalid cancel");
    assert_eq!(CruiseModeMsg::DLC, 1);
}

autoplug_ecu::test_cases!(
    reports_the_wheel_angle,
    buttons_are_debounced,
    shift_paddle_sends_a_pulse,
    a_press_during_a_pulse_is_ignored,
    both_paddles_mean_no_request,
    cruise_buttons_set_the_state,
    adopts_a_cancel_from_the_pedals,
    cruise_mode_input_is_not_supervised,
    invalid_cancel_records_a_dtc,
);
