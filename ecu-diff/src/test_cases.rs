//! Test cases shared by the host test suite and the on-target (defmt-test) suite. Each case
//! panics on failure. A small bench plays the other ECUs' frames at their periods; the
//! closed loop runs against a first-order yaw-error plant here, and against the vehicle
//! model in `host-tests/`.

use crate::*;
use autoplug_can::{CanMessage, Message};
use autoplug_ecu::{invalid_data, lost_communication};

fn ms(t: u64) -> Instant {
    Instant::from_millis(t)
}

/// A yaw-rate error outside the dead band whose P response (kp × error) stays inside the
/// split's range, rad/s: the size of the error of a step steer at the limit.
const ERROR: f32 = 0.12;
const _: () = assert!(ERROR > YAW_DEAD_BAND_RAD_S && TUNING.kp * ERROR < SPLIT_LIMIT_NM);

/// The other ECUs around the differential ECU.
struct Bench {
    ecu: DiffEcu,
    t: u64,
    speed_kmh: f32,
    steering_deg: f32,
    /// Applied brakes FL, FR, RL, RR, %.
    brakes: [f32; 4],
    send_speed: bool,
    send_steering: bool,
    send_abs: bool,
}

impl Bench {
    /// At 60 km/h, steering 45° left, no brakes, every input sending; nothing run yet.
    fn new() -> Self {
        Self {
            ecu: DiffEcu::new(ms(0)),
            t: 0,
            speed_kmh: 60.0,
            steering_deg: 45.0,
            brakes: [0.0; 4],
            send_speed: true,
            send_steering: true,
            send_abs: true,
        }
    }

    /// One 10 ms step with this yaw-rate error; returns the split.
    fn step(&mut self, error: f32) -> f32 {
        let now = ms(self.t);
        if self.send_speed {
            let frame = VehicleSpeedMsg {
                vehicle_speed: self.speed_kmh,
            }
            .frame();
            self.ecu.on_frame(now, &frame);
        }
        if self.send_steering {
            let frame = SteeringMsg {
                steering_angle: self.steering_deg,
            }
            .frame();
            self.ecu.on_frame(now, &frame);
        }
        if self.send_abs {
            let [fl, fr, rl, rr] = self.brakes;
            let frame = AbsMsg {
                brake_fl: fl,
                brake_fr: fr,
                brake_rl: rl,
                brake_rr: rr,
                abs_release_fl: 0.0,
                abs_release_fr: 0.0,
                abs_release_rl: 0.0,
                abs_release_rr: 0.0,
            }
            .frame();
            self.ecu.on_frame(now, &frame);
        }
        let split = self
            .ecu
            .step(
                now,
                &Sensors {
                    yaw_rate_error_rad_s: error,
                },
            )
            .torque_split_nm;
        assert!((-SPLIT_LIMIT_NM..=SPLIT_LIMIT_NM).contains(&split));
        self.t += 10;
        split
    }

    /// `n` steps at a constant error; returns the last split.
    fn hold(&mut self, error: f32, n: usize) -> f32 {
        let mut split = 0.0;
        for _ in 0..n {
            split = self.step(error);
        }
        split
    }

    fn mode(&self) -> Mode {
        self.ecu.status().mode
    }
}

/// DiffMsg and YawErrorMsg go out every 10 ms, DiffMsg first; the yaw-rate error is
/// published clamped to ±2.5 rad/s.
pub fn publishes_split_and_yaw_error_every_10_ms() {
    let mut bench = Bench::new();
    let mut counts = [0; 2];
    for _ in 0..10 {
        bench.step(-1.0);
        let now = ms(bench.t - 10);
        let mut last_id = 0;
        while let Some(frame) = bench.ecu.poll_transmit(now) {
            assert!(frame.id() > last_id, "lowest ID first");
            last_id = frame.id();
            match Message::from_frame(&frame) {
                Ok(Message::DiffMsg(m)) => {
                    assert!(m.torque_split < 0.0);
                    counts[0] += 1;
                }
                Ok(Message::YawErrorMsg(m)) => {
                    assert!((m.yaw_rate_error + 1.0).abs() < 0.01);
                    assert_eq!(frame.data(), &[(-51i8) as u8]);
                    counts[1] += 1;
                }
                other => panic!("unexpected {:?}", other),
            }
        }
    }
    assert_eq!(counts, [10, 10]);
    bench.step(-3.0);
    let mut error_frame = None;
    while let Some(frame) = bench.ecu.poll_transmit(ms(bench.t - 10 + 5)) {
        if frame.id() == YawErrorMsg::ID {
            error_frame = Some(frame);
        }
    }
    assert_eq!(error_frame.map(|f| f.data()[0]), Some((-127i8) as u8));
}

/// A positive error (the car yaws less counter-clockwise than the reference) gives a
/// positive split (more torque to the right rear: counter-clockwise moment), a negative
/// error a negative split; the first active step is the P response kp × error.
pub fn split_sign_follows_the_yaw_error() {
    for error in [ERROR, -ERROR, 0.1, -0.1] {
        let mut bench = Bench::new();
        let split = bench.step(error);
        assert_eq!(bench.mode(), Mode::Active);
        assert!(
            (split - TUNING.kp * error).abs() < 1e-4,
            "{} for {}",
            split,
            error
        );
        let later = bench.hold(error, 50);
        assert!(
            later.signum() == error.signum() && later.abs() > split.abs(),
            "the integral adds in the same direction"
        );
    }
    // Turning right (negative steering) works the same way: the sign of the split comes
    // from the error alone.
    let mut bench = Bench::new();
    bench.steering_deg = -45.0;
    assert!(bench.step(ERROR) > 0.0);
    // A large error uses the whole range at once.
    let mut bench = Bench::new();
    assert_eq!(bench.step(0.5), SPLIT_LIMIT_NM);
}

/// Dead band with hysteresis: an error just inside [`YAW_DEAD_BAND_RAD_S`] does not start
/// control, one just outside does; once active, an error between the exit threshold and
/// the dead band keeps it active, one below [`YAW_DEAD_BAND_EXIT_RAD_S`] stops it (split 0,
/// PID reset: the next start is pure P).
pub fn dead_band_with_hysteresis() {
    let inside = YAW_DEAD_BAND_RAD_S - 0.01;
    let outside = YAW_DEAD_BAND_RAD_S + 0.01;
    let between = 0.5 * (YAW_DEAD_BAND_RAD_S + YAW_DEAD_BAND_EXIT_RAD_S);
    let below = YAW_DEAD_BAND_EXIT_RAD_S - 0.01;
    let mut bench = Bench::new();
    assert_eq!(bench.hold(inside, 20), 0.0);
    assert_eq!(bench.mode(), Mode::SmallError);
    assert_eq!(bench.hold(-inside, 20), 0.0);
    let first = bench.step(outside);
    assert_eq!(bench.mode(), Mode::Active);
    assert!((first - TUNING.kp * outside).abs() < 1e-4);
    bench.hold(outside, 100);
    let held = bench.step(between);
    assert_eq!(bench.mode(), Mode::Active, "hysteresis");
    assert!(
        held > TUNING.kp * between,
        "with the integral built up: {}",
        held
    );
    assert_eq!(bench.step(below), 0.0);
    assert_eq!(bench.mode(), Mode::SmallError);
    let restart = bench.step(ERROR);
    assert!(
        (restart - TUNING.kp * ERROR).abs() < 1e-4,
        "integral was reset: {}",
        restart
    );
}

/// No control (split 0, PID reset) below 20 km/h, with the steering wheel within ±10°, or
/// with any applied brake above 20 %; a light brake does not stop it.
pub fn control_only_when_fast_turning_and_not_braking() {
    let mut bench = Bench::new();
    assert!(bench.hold(1.0, 20) > 0.0);
    bench.speed_kmh = 15.0;
    assert_eq!(bench.step(1.0), 0.0);
    assert_eq!(bench.mode(), Mode::TooSlow);
    bench.speed_kmh = 25.0;
    bench.steering_deg = 5.0;
    assert_eq!(bench.step(1.0), 0.0);
    assert_eq!(bench.mode(), Mode::Straight);
    bench.steering_deg = -5.0;
    assert_eq!(bench.step(-1.0), 0.0);
    bench.steering_deg = -20.0;
    let split = bench.step(-ERROR);
    assert!(
        (split + TUNING.kp * ERROR).abs() < 1e-4,
        "fresh start: {}",
        split
    );
    bench.brakes = [0.0, 0.0, 30.0, 0.0];
    assert_eq!(bench.step(-1.0), 0.0);
    assert_eq!(bench.mode(), Mode::Braking);
    bench.brakes = [15.0, 15.0, 15.0, 15.0];
    assert!(bench.step(-1.0) < 0.0, "light braking: control continues");
    assert_eq!(bench.mode(), Mode::Active);
}

/// The report's figure: at −3 rad/s the P term alone asks far more than −50 N·m, the split
/// is clamped to −50; a long saturation does not wind the integral beyond the limit, so
/// when the error shrinks to a limit manoeuvre's size the split comes back off the limit
/// at once.
pub fn split_is_clamped_without_windup() {
    let mut bench = Bench::new();
    assert_eq!(bench.step(-3.0), -SPLIT_LIMIT_NM);
    assert_eq!(bench.hold(-3.0, 500), -SPLIT_LIMIT_NM);
    assert_eq!(
        bench.hold(3.0, 1),
        SPLIT_LIMIT_NM,
        "anti-windup: off the limit at once"
    );
    let mut bench = Bench::new();
    bench.hold(-3.0, 500);
    let split = bench.step(-ERROR);
    assert!(split > -SPLIT_LIMIT_NM, "{}", split);
    assert!(bench.hold(-ERROR, 300) > -SPLIT_LIMIT_NM);
}

/// Closed loop on a yaw-error plant (`de/dt = −e/τ − g × split`, the car recovering by
/// itself with τ = 1.5 s): from −3 rad/s the split starts at −50 N·m and the error gets
/// within 0.3 rad/s sooner than without control, with no overshoot past the dead band, the
/// split never changing sign and ending at 0.
pub fn closed_loop_drives_the_yaw_error_back() {
    const TAU_S: f32 = 1.5;
    const GAIN: f32 = 0.04; // rad/s² per N·m
    let time_to_recover = |control: bool| -> (u64, f32, f32) {
        let mut bench = Bench::new();
        let mut error = -3.0f32;
        let (mut recovered_at, mut most_positive_error, mut most_positive_split) =
            (None, f32::MIN, f32::MIN);
        for i in 0..500u64 {
            let split = bench.step(error);
            let split = if control { split } else { 0.0 };
            if i == 0 && control {
                assert_eq!(split, -SPLIT_LIMIT_NM);
            }
            most_positive_split = most_positive_split.max(split);
            error += (-error / TAU_S - GAIN * split) * 0.01;
            most_positive_error = most_positive_error.max(error);
            if error.abs() < 0.3 {
                recovered_at.get_or_insert(i * 10);
            }
        }
        if control {
            assert_eq!(bench.mode(), Mode::SmallError);
            assert_eq!(bench.ecu.status().torque_split_nm, 0.0);
        }
        (
            recovered_at.expect("recovered"),
            most_positive_error,
            most_positive_split,
        )
    };
    let (without, _, _) = time_to_recover(false);
    let (with, overshoot, split_max) = time_to_recover(true);
    assert!(
        with * 2 < without,
        "{} ms with control, {} ms without",
        with,
        without
    );
    assert!(
        overshoot <= YAW_DEAD_BAND_RAD_S,
        "overshoot to {}",
        overshoot
    );
    assert!(split_max <= 0.0, "split went positive: {}", split_max);
}

/// A car at the limit after a step steer swings about its yaw-rate reference: a lightly
/// damped yaw mode (1.5 s period, ζ = 0.1) with the split's yaw moment acting on the yaw
/// acceleration (`ė = −2ζω·e + s − g·split`, `ṡ = −ω²·e`, g = 0.025 rad/s² per N·m as
/// the EVO's AYC gives). From the overshoot (−0.17 rad/s) the split damps the swings: the
/// next peak of the error is at most a third of the uncontrolled one, and the split
/// settles without oscillating (at most two changes of sign, 0 at the end).
pub fn yaw_oscillation_is_damped() {
    const OMEGA: f32 = 2.0 * core::f32::consts::PI / 1.5;
    const ZETA: f32 = 0.1;
    const GAIN: f32 = 0.025;
    let run = |control: bool| -> (f32, u32, f32) {
        let mut bench = Bench::new();
        bench.speed_kmh = 130.0;
        bench.steering_deg = 90.0;
        // Starting at the overshoot's peak: ė = 0.
        let mut error = -0.17f32;
        let mut state = 2.0 * ZETA * OMEGA * error;
        let (mut next_peak, mut sign_changes, mut last_sign) = (0.0f32, 0u32, 0.0f32);
        let mut split = 0.0;
        for _ in 0..600 {
            split = bench.step(error);
            let applied = if control { split } else { 0.0 };
            let rate = -2.0 * ZETA * OMEGA * error + state - GAIN * applied;
            state += -OMEGA * OMEGA * error * 0.01;
            error += rate * 0.01;
            next_peak = next_peak.max(error);
            if split != 0.0 {
                if last_sign != 0.0 && split.signum() != last_sign {
                    sign_changes += 1;
                }
                last_sign = split.signum();
            }
        }
        (next_peak, sign_changes, split)
    };
    let (open_peak, _, _) = run(false);
    let (peak, sign_changes, last_split) = run(true);
    assert!(
        peak <= open_peak / 3.0,
        "next peak {} with control, {} without",
        peak,
        open_peak
    );
    assert!(
        sign_changes <= 2,
        "split changed sign {} times",
        sign_changes
    );
    assert_eq!(last_split, 0.0);
}

/// Each input lost (VehicleSpeedMsg, SteeringMsg, AbsMsg): split 0 within 3 periods, "lost
/// communication" with its sender recorded; control resumes when it returns.
pub fn stale_inputs_open_the_differential() {
    for (lost, sender) in [(0, Node::Cruise), (1, Node::Steering), (2, Node::ABS)] {
        let mut bench = Bench::new();
        assert!(bench.hold(1.0, 10) > 0.0);
        match lost {
            0 => bench.send_speed = false,
            1 => bench.send_steering = false,
            _ => bench.send_abs = false,
        }
        let dtc = lost_communication(sender);
        assert!(bench.hold(1.0, 2) > 0.0, "still fresh");
        assert_eq!(bench.step(1.0), 0.0, "30 ms after the last frame");
        assert_eq!(bench.mode(), Mode::InputsLost);
        assert!(bench.ecu.dtcs().is_active(dtc));
        assert_eq!(bench.hold(1.0, 100), 0.0);
        bench.send_speed = true;
        bench.send_steering = true;
        bench.send_abs = true;
        let split = bench.step(ERROR);
        assert!(
            (split - TUNING.kp * ERROR).abs() < 1e-4,
            "resumes from a reset PID: {}",
            split
        );
        assert!(!bench.ecu.dtcs().is_active(dtc));
        assert!(bench.ecu.dtcs().get(dtc).is_some(), "stays stored");
    }
    // Nothing received yet: open differential.
    let mut ecu = DiffEcu::new(ms(0));
    let out = ecu.step(
        ms(0),
        &Sensors {
            yaw_rate_error_rad_s: 2.0,
        },
    );
    assert_eq!(out.torque_split_nm, 0.0);
    assert_eq!(ecu.status().mode, Mode::InputsLost);
}

/// Invalid frames record "invalid data" against their sender and keep the last good
/// values; a yaw-rate error that is not a number means no control.
pub fn invalid_inputs_are_refused() {
    let mut bench = Bench::new();
    bench.hold(1.0, 5);
    let now = ms(bench.t);
    bench
        .ecu
        .on_frame(now, &Frame::new(u32::from(SteeringMsg::ID), &[5]).unwrap());
    assert!(bench.ecu.dtcs().is_active(invalid_data(Node::Steering)));
    bench.ecu.on_frame(
        now,
        &Frame::new(u32::from(AbsMsg::ID), &[101, 0, 0, 0, 0, 0, 0, 0]).unwrap(),
    );
    assert!(bench.ecu.dtcs().is_active(invalid_data(Node::ABS)));
    bench.ecu.on_frame(
        now,
        &Frame::new(u32::from(VehicleSpeedMsg::ID), &[1, 2]).unwrap(),
    );
    assert!(bench.ecu.dtcs().is_active(invalid_data(Node::Cruise)));
    // The last good values (45° left, no brakes, 60 km/h) stay in use.
    bench.send_speed = false;
    bench.send_steering = false;
    bench.send_abs = false;
    assert!(bench.step(1.0) > 0.0);
    assert_eq!(bench.mode(), Mode::Active);
    for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
        let mut bench = Bench::new();
        bench.hold(1.0, 5);
        assert_eq!(bench.step(bad), 0.0);
        assert_eq!(bench.ecu.status().yaw_rate_error_rad_s, 0.0);
    }
}

autoplug_ecu::test_cases!(
    publishes_split_and_yaw_error_every_10_ms,
    split_sign_follows_the_yaw_error,
    dead_band_with_hysteresis,
    control_only_when_fast_turning_and_not_braking,
    split_is_clamped_without_windup,
    closed_loop_drives_the_yaw_error_back,
    yaw_oscillation_is_damped,
    stale_inputs_open_the_differential,
    invalid_inputs_are_refused,
);
