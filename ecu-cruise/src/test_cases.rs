//! Test cases shared by the host test suite and the on-target (defmt-test) suite. Each case
//! panics on failure. The closed loop here runs against a simple longitudinal plant; the
//! closed loop against the vehicle model lives in `host-tests/`.

use crate::*;
use autoplug_can::{CanMessage, CruiseAccelMsg, Message};
use autoplug_ecu::lost_communication;

fn ms(t: u64) -> Instant {
    Instant::from_millis(t)
}

fn mode_frame(on: bool) -> Frame {
    CruiseModeMsg {
        cruise_mode: if on { CruiseMode::On } else { CruiseMode::Off },
    }
    .frame()
}

/// Acceleration in km/h per second for a command, with drag and an optional grade.
fn plant_accel(speed_kmh: f32, command: f32, grade: f32) -> f32 {
    let v = speed_kmh / 3.6;
    let drive = if command >= 0.0 {
        command / 100.0 * 4.0
    } else {
        command / 100.0 * 9.0
    };
    let resist = 0.15 + 0.0004 * v * v + 9.81 * grade;
    (drive - resist) * 3.6
}

/// Runs the ECU in closed loop for `seconds`, feeding it a cruise-mode frame every 20 ms.
/// Returns the speed trace sampled every 100 ms (at most 400 samples).
fn closed_loop(
    ecu: &mut CruiseEcu,
    start_ms: u64,
    seconds: u64,
    speed: &mut f32,
    grade: f32,
    samples: &mut [f32; 400],
) -> usize {
    let mut n = 0;
    for t in (start_ms..start_ms + seconds * 1000).step_by(10) {
        if t % 20 == 0 {
            ecu.on_frame(ms(t), &mode_frame(true));
        }
        let status = ecu.step(
            ms(t),
            &Sensors {
                vehicle_speed_kmh: *speed,
            },
        );
        *speed += plant_accel(*speed, status.command, grade) * 0.01;
        if (t - start_ms) % 100 == 0 && n < samples.len() {
            samples[n] = *speed;
            n += 1;
        }
    }
    n
}

/// The ECU publishes the speed every 10 ms and its command every 20 ms, from the start.
pub fn publishes_speed_and_command_at_their_periods() {
    let mut ecu = CruiseEcu::new(Variant::Correct, ms(0));
    let (mut speed_frames, mut command_frames) = (0, 0);
    for t in (0..100).step_by(10) {
        ecu.step(
            ms(t),
            &Sensors {
                vehicle_speed_kmh: 42.0,
            },
        );
        while let Some(frame) = ecu.poll_transmit(ms(t)) {
            match Message::from_frame(&frame) {
                Ok(Message::VehicleSpeedMsg(m)) => {
                    assert_eq!(m.vehicle_speed, 42.0);
                    speed_frames += 1;
                }
                Ok(Message::CruiseAccelMsg(m)) => {
                    assert_eq!(m.cruise_accel, 0.0, "no command while disengaged");
                    command_frames += 1;
                }
                other => panic!("unexpected {:?}", other),
            }
        }
    }
    assert_eq!((speed_frames, command_frames), (10, 5));
}

/// Engages on an off -> on edge at the current speed; off disengages and zeroes the command.
pub fn engages_on_the_edge_and_latches_the_speed() {
    let mut ecu = CruiseEcu::new(Variant::Correct, ms(0));
    ecu.on_frame(ms(0), &mode_frame(false));
    assert!(
        !ecu.step(
            ms(0),
            &Sensors {
                vehicle_speed_kmh: 88.0
            }
        )
        .engaged
    );
    ecu.on_frame(ms(10), &mode_frame(true));
    let status = ecu.step(
        ms(10),
        &Sensors {
            vehicle_speed_kmh: 89.0,
        },
    );
    assert!(!status.engaged, "one step of 'on' is not enough");
    let status = ecu.step(
        ms(20),
        &Sensors {
            vehicle_speed_kmh: 90.0,
        },
    );
    assert!(status.engaged, "'on' for two steps engages");
    assert_eq!(status.set_speed_kmh, 90.0);
    let status = ecu.step(
        ms(30),
        &Sensors {
            vehicle_speed_kmh: 85.0,
        },
    );
    assert!(status.command > 0.0, "below the set speed: accelerate");
    let status = ecu.step(
        ms(40),
        &Sensors {
            vehicle_speed_kmh: 95.0,
        },
    );
    assert!(status.command < 0.0, "above the set speed: brake");
    ecu.on_frame(ms(50), &mode_frame(false));
    let status = ecu.step(
        ms(50),
        &Sensors {
            vehicle_speed_kmh: 95.0,
        },
    );
    assert_eq!(status, Status::default(), "off: disengaged, command 0");
    // Switching on again latches the new speed, with the integrator reset.
    ecu.on_frame(ms(60), &mode_frame(true));
    ecu.step(
        ms(60),
        &Sensors {
            vehicle_speed_kmh: 70.0,
        },
    );
    let status = ecu.step(
        ms(70),
        &Sensors {
            vehicle_speed_kmh: 70.0,
        },
    );
    assert_eq!((status.engaged, status.set_speed_kmh), (true, 70.0));
    let status = ecu.step(
        ms(80),
        &Sensors {
            vehicle_speed_kmh: 70.0,
        },
    );
    assert!(
        status.command.abs() < 1e-6,
        "no error, fresh integrator: no command"
    );
}

/// A single stray "on" frame right after a cancel (a queued steering frame that lost the
/// race with the pedals' "off") does not engage cruise.
pub fn a_stray_on_after_a_cancel_does_not_engage() {
    let mut ecu = CruiseEcu::new(Variant::Correct, ms(0));
    ecu.on_frame(ms(0), &mode_frame(true));
    ecu.step(
        ms(0),
        &Sensors {
            vehicle_speed_kmh: 100.0,
        },
    );
    assert!(
        ecu.step(
            ms(10),
            &Sensors {
                vehicle_speed_kmh: 100.0
            }
        )
        .engaged
    );
    ecu.on_frame(ms(11), &mode_frame(false)); // the pedals' cancel
    let status = ecu.step(
        ms(20),
        &Sensors {
            vehicle_speed_kmh: 99.0,
        },
    );
    assert!(!status.engaged);
    ecu.on_frame(ms(22), &mode_frame(true)); // the stale steering frame
    assert!(
        !ecu.step(
            ms(30),
            &Sensors {
                vehicle_speed_kmh: 98.0
            }
        )
        .engaged
    );
    ecu.on_frame(ms(31), &mode_frame(false)); // steering adopted the cancel
    for t in (40..200).step_by(10) {
        if t % 20 == 0 {
            ecu.on_frame(ms(t), &mode_frame(false));
        }
        assert!(
            !ecu.step(
                ms(t),
                &Sensors {
                    vehicle_speed_kmh: 97.0
                }
            )
            .engaged,
            "at {} ms",
            t
        );
    }
}

/// On a level road the PI holds the set speed within 1 km/h after 8 s; a 6 % grade costs
/// less than 3 km/h and is recovered.
pub fn holds_speed_and_rejects_a_grade() {
    let mut ecu = CruiseEcu::new(Variant::Correct, ms(0));
    let mut speed = 90.0;
    let mut trace = [0.0f32; 400];
    let n = closed_loop(&mut ecu, 0, 20, &mut speed, 0.0, &mut trace);
    for (i, v) in trace[..n].iter().enumerate() {
        if i >= 80 {
            assert!(
                (v - 90.0).abs() <= 1.0,
                "{} km/h at {} s",
                v,
                i as f32 / 10.0
            );
        }
    }
    let n = closed_loop(&mut ecu, 20_000, 30, &mut speed, 0.06, &mut trace);
    let lowest = trace[..n].iter().fold(f32::MAX, |a, b| a.min(*b));
    assert!(lowest >= 87.0, "grade dip to {} km/h", lowest);
    assert!(
        (trace[n - 1] - 90.0).abs() <= 1.0,
        "recovered to {}",
        trace[n - 1]
    );
    for t in 0..100 {
        let status = ecu.step(
            ms(50_000 + t * 10),
            &Sensors {
                vehicle_speed_kmh: 300.0,
            },
        );
        assert!((-100.0..=100.0).contains(&status.command));
    }
}

/// When CruiseModeMsg stops, cruise disengages within 3 periods and records a DTC; it
/// does not re-engage by itself when the frames return.
pub fn stale_cruise_mode_disengages() {
    let mut ecu = CruiseEcu::new(Variant::Correct, ms(0));
    ecu.on_frame(ms(0), &mode_frame(true));
    ecu.step(
        ms(0),
        &Sensors {
            vehicle_speed_kmh: 90.0,
        },
    );
    assert!(
        ecu.step(
            ms(10),
            &Sensors {
                vehicle_speed_kmh: 90.0
            }
        )
        .engaged
    );
    let period = u64::from(CruiseModeMsg::CYCLE_TIME_MS);
    let mut disengaged_at = None;
    for t in (20..=200).step_by(10) {
        let status = ecu.step(
            ms(t),
            &Sensors {
                vehicle_speed_kmh: 80.0,
            },
        );
        if !status.engaged && disengaged_at.is_none() {
            disengaged_at = Some(t);
            assert_eq!(status.command, 0.0);
        }
    }
    assert_eq!(disengaged_at, Some(3 * period));
    let dtc = lost_communication(Node::Steering);
    assert!(ecu.dtcs().is_active(dtc));
    ecu.on_frame(ms(210), &mode_frame(true));
    assert!(
        !ecu.step(
            ms(210),
            &Sensors {
                vehicle_speed_kmh: 80.0
            }
        )
        .engaged
    );
    assert!(!ecu.dtcs().is_active(dtc), "communication is back");
    assert!(ecu.dtcs().get(dtc).is_some(), "the DTC stays stored");
    ecu.on_frame(ms(220), &mode_frame(false));
    assert!(
        !ecu.step(
            ms(220),
            &Sensors {
                vehicle_speed_kmh: 80.0
            }
        )
        .engaged
    );
    ecu.on_frame(ms(230), &mode_frame(true));
    ecu.step(
        ms(230),
        &Sensors {
            vehicle_speed_kmh: 80.0,
        },
    );
    let status = ecu.step(
        ms(240),
        &Sensors {
            vehicle_speed_kmh: 80.0,
        },
    );
    assert!(status.engaged, "off then on: the driver engaged it again");
    assert_eq!(status.set_speed_kmh, 80.0);
}

/// The faulty build slams between full throttle and full braking and never settles.
pub fn faulty_build_oscillates() {
    let mut ecu = CruiseEcu::new(Variant::Faulty, ms(0));
    assert_eq!(ecu.variant(), Variant::Faulty);
    let mut speed = 90.0;
    let mut commands_seen = (false, false);
    for t in (0..20_000).step_by(10) {
        if t % 20 == 0 {
            ecu.on_frame(ms(t), &mode_frame(true));
        }
        let status = ecu.step(
            ms(t),
            &Sensors {
                vehicle_speed_kmh: speed,
            },
        );
        assert!(
            status.command == 0.0 || status.command.abs() == 100.0,
            "bang-bang only, got {}",
            status.command
        );
        commands_seen.0 |= status.command == 100.0;
        commands_seen.1 |= status.command == -100.0;
        speed += plant_accel(speed, status.command, 0.0) * 0.01;
    }
    assert!(
        commands_seen.0 && commands_seen.1,
        "both full throttle and full braking"
    );
    // The correct build, on the same plant, ends with a small command.
    let mut correct = CruiseEcu::new(Variant::Correct, ms(0));
    let mut speed = 90.0;
    let mut trace = [0.0f32; 400];
    closed_loop(&mut correct, 0, 20, &mut speed, 0.0, &mut trace);
    assert!(correct.status().command.abs() < 30.0);
    let frame = CruiseAccelMsg {
        cruise_accel: correct.status().command,
    }
    .frame();
    assert!(frame.data()[0] <= 200);
}

autoplug_ecu::test_cases!(
    publishes_speed_and_command_at_their_periods,
    engages_on_the_edge_and_latches_the_speed,
    a_stray_on_after_a_cancel_does_not_engage,
    holds_speed_and_rejects_a_grade,
    stale_cruise_mode_disengages,
    faulty_build_oscillates,
);
