//! What reaches the bus matches the vehicle (spec section 7: each ECU reads and reports
//! its signals; the middleware's data matches what was sent): engine RPM, fuel level and
//! steering angle on CAN agree with the model within their quantisation; brake lights
//! follow the brake pedal.

use autoplug_can::{EngineMsg, Message, SteeringMsg};
use autoplug_host_tests::*;
use autoplug_virtual_car::car::VirtualCar;

/// Runs `scenario` and checks every EngineMsg and SteeringMsg against the model state at
/// the moment the sending ECU read its sensors (its frame goes out within that step).
#[test]
fn engine_and_steering_signals_match_the_model() {
    let s = inline(
        r#"
name = "signals"
duration_s = 12.0
[driver]
accelerator = 40.0
[[at]]
t_s = 4.0
ramp_s = 4.0
steering_deg = -100.0
"#,
    );
    let mut car = VirtualCar::new(&s);
    let rpm_step = EngineMsg::ENGINE_RPM.factor();
    let fuel_step = EngineMsg::FUEL_LEVEL.factor();
    let angle_step = SteeringMsg::STEERING_ANGLE.factor();
    let (mut engine_frames, mut steering_frames) = (0, 0);
    let mut checked = 0;
    while !car.finished() {
        // The model's values now, before the tick in which the ECUs read them.
        let model_rpm = car.vehicle().engine_rpm;
        let model_fuel = car.vehicle().fuel_l;
        let model_angle = car.controls().held.steering_deg;
        let seen = car.log().len();
        car.tick();
        for entry in &car.log()[seen..] {
            match Message::from_frame(&entry.frame).expect("catalogue frame") {
                Message::EngineMsg(m) => {
                    engine_frames += 1;
                    // The ECU sampled within the last 20 ms: allow the change over it.
                    let drift = 40.0;
                    assert!(
                        (f64::from(m.engine_rpm) - model_rpm).abs()
                            <= rpm_step as f64 / 2.0 + drift,
                        "EngineRPM {} vs model {model_rpm:.0}",
                        m.engine_rpm
                    );
                    assert!(
                        (f64::from(m.fuel_level) - model_fuel).abs()
                            <= fuel_step as f64 / 2.0 + 0.01
                    );
                    checked += 1;
                }
                Message::SteeringMsg(m) => {
                    steering_frames += 1;
                    // The ramp moves 25 deg/s: 10 ms of it on top of half a step.
                    assert!(
                        (f64::from(m.steering_angle) - model_angle).abs()
                            <= angle_step as f64 / 2.0 + 0.5,
                        "SteeringAngle {} vs wheel {model_angle:.2}",
                        m.steering_angle
                    );
                    checked += 1;
                }
                _ => {}
            }
        }
    }
    assert!(
        engine_frames >= 12 * 50 - 5,
        "{engine_frames} EngineMsg in 12 s (20 ms period)"
    );
    assert!(
        steering_frames >= 12 * 100 - 5,
        "{steering_frames} SteeringMsg in 12 s (10 ms period)"
    );
    assert!(checked > 1500);
}

/// Brake lights come on with the brake pedal and go off after it.
#[test]
fn brake_lights_follow_the_brake_pedal() {
    let s = inline(
        r#"
name = "lights"
duration_s = 6.0
[initial]
speed_kmh = 60.0
gear = "3"
[[at]]
t_s = 2.0
brake = 30.0
[[at]]
t_s = 3.0
brake = 0.0
"#,
    );
    let r = run(&s);
    assert!(!at(&r.trace, 1.9).brake_lights);
    let on = r
        .trace
        .iter()
        .find(|row| row.brake_lights)
        .expect("brake lights came on");
    assert!(on.t_s >= 2.0 && on.t_s <= 2.05, "on at {:.3} s", on.t_s);
    assert!(at(&r.trace, 2.9).brake_lights);
    let off = r
        .trace
        .iter()
        .find(|row| row.t_s > 3.0 && !row.brake_lights)
        .expect("off again");
    assert!(off.t_s <= 3.05, "off at {:.3} s", off.t_s);
}

/// The headlight switch on the console lights the headlights (through the console ECU),
/// and the engine-mode switch reaches the engine ECU's EngineMsg through AccMsg.
#[test]
fn console_switches_reach_the_car_and_the_bus() {
    let s = inline(
        r#"
name = "console"
duration_s = 3.0
[driver]
economy_mode = false
[[at]]
t_s = 1.0
headlights = true
economy_mode = true
"#,
    );
    let r = run(&s);
    assert!(!at(&r.trace, 0.9).headlights);
    let on = r
        .trace
        .iter()
        .find(|row| row.headlights)
        .expect("headlights came on");
    assert!(on.t_s <= 1.02, "on at {:.3} s", on.t_s);
    // EngineMsg echoes the mode: sport before the switch, economy within a few frames after.
    let modes: Vec<(u64, autoplug_can::EngineMode)> = r
        .log
        .iter()
        .filter_map(|e| match Message::from_frame(&e.frame) {
            Ok(Message::EngineMsg(m)) => Some((e.t_us, m.engine_mode)),
            _ => None,
        })
        .collect();
    let before: Vec<_> = modes
        .iter()
        .filter(|(t, _)| *t > 300_000 && *t < 1_000_000)
        .collect();
    assert!(
        !before.is_empty()
            && before
                .iter()
                .all(|(_, m)| *m == autoplug_can::EngineMode::Sport)
    );
    let switched = modes
        .iter()
        .find(|(t, m)| *t >= 1_000_000 && *m == autoplug_can::EngineMode::Economy)
        .expect("EngineMsg reports economy");
    assert!(
        switched.0 <= 1_060_000,
        "economy on the bus at {} us",
        switched.0
    );
}

/// The pedals ECU reads both pedals and reports them: PedalAccel and PedalBrake on the bus
/// carry the driver's pedals (no cruise, no traction cut here) within their 1 % step.
#[test]
fn pedal_commands_on_the_bus_follow_the_pedals() {
    let s = inline(
        r#"
name = "pedals"
duration_s = 6.0
[[at]]
t_s = 0.5
ramp_s = 1.0
accelerator = 40.0
[[at]]
t_s = 3.0
accelerator = 0.0
ramp_s = 0.5
brake = 35.0
"#,
    );
    let mut car = VirtualCar::new(&s);
    let (mut accel_frames, mut brake_frames) = (0, 0);
    while !car.finished() {
        let pedals = *car.controls();
        let seen = car.log().len();
        car.tick();
        for entry in &car.log()[seen..] {
            // A ramp of 40 %/s moves 0.4 % in the 10 ms since the ECU sampled.
            match Message::from_frame(&entry.frame).expect("catalogue frame") {
                Message::PedalAccel(m) => {
                    accel_frames += 1;
                    let driver = if pedals.held.brake > 5.0 {
                        0.0
                    } else {
                        pedals.held.accelerator
                    };
                    assert!(
                        (f64::from(m.accel_cmd) - driver).abs() <= 0.5 + 0.8,
                        "AccelCmd {} vs pedal {driver:.2}",
                        m.accel_cmd
                    );
                }
                Message::PedalBrake(m) => {
                    brake_frames += 1;
                    assert!(
                        (f64::from(m.brake_cmd) - pedals.held.brake).abs() <= 0.5 + 0.8,
                        "BrakeCmd {} vs pedal {:.2}",
                        m.brake_cmd,
                        pedals.held.brake
                    );
                }
                _ => {}
            }
        }
    }
    assert!(
        accel_frames >= 595 && brake_frames >= 595,
        "{accel_frames} / {brake_frames} frames in 6 s"
    );
}
