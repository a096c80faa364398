//! Each routine flags the fault it is for, on frames made for it (the shipped scenarios,
//! in tests/scenarios.rs, show the absence of false alarms).

use autoplug_can::{
    AccMsg, CanMessage, CruiseAccelMsg, CruiseMode, CruiseModeMsg, EngineMode, EngineMsg, Frame,
    PedalAccel, PedalBrake, VehicleSpeedMsg,
};
use autoplug_gateway::{Pipeline, Strictness, VecSource};
use autoplug_logs::LogFrame;

use crate::{Diagnostics, Finding, Verdict};

/// Frames every `period_ms` from 0 to `until_ms` made by `make(t_ms)`.
fn every(period_ms: u64, until_ms: u64, make: impl Fn(u64) -> Frame) -> Vec<LogFrame> {
    (0..=until_ms / period_ms)
        .map(|i| LogFrame::from_can(i * period_ms * 1000, 0, &make(i * period_ms)))
        .collect()
}

/// The pipeline and the diagnostics after `frames` (in time order).
fn diagnosed(frames: Vec<LogFrame>) -> (Pipeline, Diagnostics) {
    let mut pipeline = Pipeline::new(Strictness::Strict);
    let mut diagnostics = Diagnostics::new();
    pipeline
        .run(
            &mut VecSource::new("test", frames),
            &mut [&mut diagnostics],
            &mut || false,
        )
        .unwrap();
    (pipeline, diagnostics)
}

/// The diagnosis of every ECU after `frames` (sorted into time order first).
fn report(mut frames: Vec<LogFrame>) -> Vec<crate::EcuDiagnosis> {
    frames.sort_by_key(|f| f.t_us);
    let (pipeline, diagnostics) = diagnosed(frames);
    diagnostics.report(pipeline.state())
}

fn run(frames: Vec<LogFrame>, routine: &str) -> Finding {
    report(frames)
        .into_iter()
        .flat_map(|d| d.findings)
        .find(|f| f.routine == routine)
        .unwrap()
}

fn brake(pct: f32) -> Frame {
    PedalBrake { brake_cmd: pct }.frame()
}

fn accel(pct: f32) -> Frame {
    PedalAccel { accel_cmd: pct }.frame()
}

#[test]
fn accelerating_while_braking_is_faulty_for_the_pedals() {
    let mut frames = every(10, 2000, |_| brake(50.0));
    frames.extend(every(10, 2000, |t| {
        accel(if t >= 1000 { 30.0 } else { 0.0 })
    }));
    let f = run(frames, "brake override of the accelerator");
    assert_eq!(f.verdict, Verdict::Faulty, "{f:?}");
    assert!((f.value.unwrap() - 1.0).abs() < 0.02, "{f:?}");
    let w = f.window.unwrap();
    assert_eq!(w.from_us, 1_000_000);
}

#[test]
fn commands_ignoring_the_cruise_command_are_faulty_for_the_pedals() {
    let on = CruiseModeMsg {
        cruise_mode: CruiseMode::On,
    };
    let mut frames = every(20, 2000, |_| on.frame());
    frames.extend(every(20, 2000, |_| {
        CruiseAccelMsg { cruise_accel: 40.0 }.frame()
    }));
    frames.extend(every(10, 2000, |_| brake(0.0)));
    // The first second right, then the command is ignored.
    frames.extend(every(10, 2000, |t| {
        accel(if t < 1000 { 40.0 } else { 0.0 })
    }));
    let f = run(frames, "commands follow the cruise command");
    assert_eq!(f.verdict, Verdict::Faulty, "{f:?}");
    let right = {
        let mut frames = every(20, 2000, |_| on.frame());
        frames.extend(every(20, 2000, |_| {
            CruiseAccelMsg {
                cruise_accel: -30.0,
            }
            .frame()
        }));
        frames.extend(every(10, 2000, |_| brake(30.0)));
        frames.extend(every(10, 2000, |_| accel(0.0)));
        run(frames, "commands follow the cruise command")
    };
    assert_eq!(
        (right.verdict, right.value),
        (Verdict::Ok, Some(0.0)),
        "{right:?}"
    );
}

#[test]
fn brake_lights_off_under_braking_are_faulty_for_the_console() {
    let mut frames = every(10, 2000, |t| brake(if t >= 500 { 60.0 } else { 0.0 }));
    frames.extend(every(100, 2000, |_| {
        AccMsg {
            brake_lights: false,
            ..AccMsg::default()
        }
        .frame()
    }));
    let f = run(frames, "brake lights against the brake");
    assert_eq!(f.verdict, Verdict::Faulty, "{f:?}");
    assert!(f.value.unwrap() >= 1.4, "{f:?}");
}

#[test]
fn fuel_rising_while_driving_is_faulty_for_the_engine() {
    let mut frames = every(10, 5000, |_| {
        VehicleSpeedMsg {
            vehicle_speed: 60.0,
        }
        .frame()
    });
    frames.extend(every(20, 5000, |t| {
        EngineMsg {
            engine_rpm: 2000.0,
            fuel_level: 30.0 + t as f32 / 1000.0,
            engine_mode: EngineMode::Economy,
            fuel_used: 0.0,
        }
        .frame()
    }));
    let f = run(frames, "fuel level never rising while driving");
    assert_eq!(f.verdict, Verdict::Faulty, "{f:?}");
    assert!((f.value.unwrap() - 5.0).abs() < 0.3, "{f:?}");
}

#[test]
fn an_ecu_that_stops_mid_log_is_no_data_and_a_gap_is_faulty() {
    // EngineMsg for 1 s, then nothing while the cruise ECU goes on for 2 s more.
    let mut frames = every(20, 1000, |_| {
        EngineMsg {
            engine_rpm: 900.0,
            fuel_level: 30.0,
            engine_mode: EngineMode::Economy,
            fuel_used: 0.0,
        }
        .frame()
    });
    frames.extend(every(10, 3000, |_| {
        VehicleSpeedMsg { vehicle_speed: 0.0 }.frame()
    }));
    let stopped = run(frames.clone(), crate::presence::ROUTINE);
    assert_eq!(stopped.verdict, Verdict::NoData, "{stopped:?}");
    // The engine comes back at 2.5 s: a gap of 75 periods, no diagnostic session.
    frames.extend(
        every(20, 500, |_| {
            EngineMsg {
                engine_rpm: 900.0,
                fuel_level: 30.0,
                engine_mode: EngineMode::Economy,
                fuel_used: 0.0,
            }
            .frame()
        })
        .into_iter()
        .map(|mut f| {
            f.t_us += 2_500_000;
            f
        }),
    );
    let gap = run(frames, crate::presence::ROUTINE);
    assert_eq!(gap.verdict, Verdict::Faulty, "{gap:?}");
    assert!(gap.value.unwrap() > 70.0, "{gap:?}");
}

#[test]
fn the_whole_bus_asleep_is_the_ignition_off_not_a_gap() {
    // Engine and cruise for 1 s, the whole bus silent for 6 s (the ignition off), both
    // again for 1 s: nobody is blamed.
    let engine = |_| {
        EngineMsg {
            engine_rpm: 900.0,
            fuel_level: 30.0,
            engine_mode: EngineMode::Economy,
            fuel_used: 0.0,
        }
        .frame()
    };
    let speed = |_| VehicleSpeedMsg { vehicle_speed: 0.0 }.frame();
    let shifted = |frames: Vec<LogFrame>, by_us: u64| {
        frames.into_iter().map(move |mut f| {
            f.t_us += by_us;
            f
        })
    };
    let mut frames = every(20, 1000, engine);
    frames.extend(every(10, 1000, speed));
    frames.extend(shifted(every(20, 1000, engine), 7_000_000));
    frames.extend(shifted(every(10, 1000, speed), 7_000_000));
    frames.sort_by_key(|f| f.t_us);
    let f = run(frames.clone(), crate::presence::ROUTINE);
    assert_eq!(f.verdict, Verdict::Ok, "{f:?}");

    // The engine alone missing while the rest of the bus is awake is still a gap.
    let mut frames: Vec<LogFrame> = frames
        .into_iter()
        .filter(|f| f.t_us < 7_000_000 || f.id != u32::from(EngineMsg::ID))
        .collect();
    frames.extend(shifted(every(10, 6000, speed), 1_000_000));
    frames.extend(shifted(every(20, 1000, engine), 7_500_000));
    frames.sort_by_key(|f| f.t_us);
    let f = run(frames, crate::presence::ROUTINE);
    assert_eq!(f.verdict, Verdict::Faulty, "{f:?}");
}

fn differential_frames(split: f32, speed: f32, steering: f32, error: f32) -> Vec<LogFrame> {
    use autoplug_can::{AbsMsg, DiffMsg, SteeringMsg, YawErrorMsg};
    let mut frames = every(10, 2000, |_| {
        DiffMsg {
            torque_split: split,
        }
        .frame()
    });
    frames.extend(every(10, 2000, |_| {
        YawErrorMsg {
            yaw_rate_error: error,
        }
        .frame()
    }));
    frames.extend(every(10, 2000, |_| {
        VehicleSpeedMsg {
            vehicle_speed: speed,
        }
        .frame()
    }));
    frames.extend(every(10, 2000, |_| {
        SteeringMsg {
            steering_angle: steering,
        }
        .frame()
    }));
    frames.extend(every(10, 2000, |_| AbsMsg::default().frame()));
    frames
}

#[test]
fn a_split_while_it_must_hold_or_against_the_error_is_faulty_for_the_differential() {
    // 30 N.m of split at 10 km/h: below the differential's minimum speed.
    let slow = run(
        differential_frames(30.0, 10.0, 45.0, 0.5),
        "torque split 0 when it must hold",
    );
    assert_eq!(slow.verdict, Verdict::Faulty, "{slow:?}");
    // Pushing the wrong way: a positive error wants a positive split.
    let wrong = run(
        differential_frames(-30.0, 100.0, 45.0, 0.5),
        "torque split against the yaw-rate error",
    );
    assert_eq!(wrong.verdict, Verdict::Faulty, "{wrong:?}");
    let right = run(
        differential_frames(30.0, 100.0, 45.0, 0.5),
        "torque split against the yaw-rate error",
    );
    assert_eq!(
        (right.verdict, right.value),
        (Verdict::Ok, Some(0.0)),
        "{right:?}"
    );
}

#[test]
fn a_value_out_of_range_is_charged_to_its_sender() {
    // SteeringMsg raw 5 is below the encoding's 10..90.
    let mut frames = every(10, 500, |_| Frame::new(0x005, &[50]).unwrap());
    frames.push(LogFrame::from_can(
        505_000,
        0,
        &Frame::new(0x005, &[5]).unwrap(),
    ));
    frames.push(LogFrame::from_can(
        506_000,
        0,
        &Frame::new(0x005, &[50, 0]).unwrap(),
    ));
    let mut pipeline = Pipeline::new(Strictness::Strict);
    let mut diagnostics = Diagnostics::new();
    frames.sort_by_key(|f| f.t_us);
    pipeline
        .run(
            &mut VecSource::new("t", frames),
            &mut [&mut diagnostics],
            &mut || false,
        )
        .unwrap();
    let report = diagnostics.report(pipeline.state());
    let steering = report
        .iter()
        .find(|d| d.ecu == autoplug_can::Node::Steering)
        .unwrap();
    let f = steering
        .findings
        .iter()
        .find(|f| f.routine.starts_with("values in range"))
        .unwrap();
    assert_eq!((f.verdict, f.value), (Verdict::Faulty, Some(2.0)), "{f:?}");
    assert!(f.evidence.contains("1 of the wrong length"), "{f:?}");
}

#[test]
fn a_fan_off_in_a_hot_cabin_is_faulty_for_the_cabin() {
    use autoplug_can::{FanMsg, TempMsg, TempRefMsg};
    let until = 200_000;
    let mut frames = every(100, until, |_| TempMsg { cabin_temp: 85.0 }.frame());
    frames.extend(every(100, until, |_| {
        TempRefMsg {
            cabin_set_temp: 70.0,
        }
        .frame()
    }));
    frames.extend(every(100, until, |_| FanMsg { fan_power: 0.0 }.frame()));
    let f = run(frames, "fan against the temperature error");
    assert_eq!(f.verdict, Verdict::Faulty, "{f:?}");
    assert!(f.value.unwrap() > 190.0, "{f:?}");
}

fn trans_frames(gears: impl Fn(u64) -> autoplug_can::Gear, speed: f32) -> Vec<LogFrame> {
    use autoplug_can::{AccMsg, ShiftMode, TransMsg};
    let mut frames = every(20, 10_000, |t| {
        TransMsg {
            gear: gears(t),
            shift_mode: ShiftMode::Automatic,
        }
        .frame()
    });
    frames.extend(every(10, 10_000, |_| {
        VehicleSpeedMsg {
            vehicle_speed: speed,
        }
        .frame()
    }));
    frames.extend(every(10, 10_000, |_| brake(0.0)));
    frames.extend(every(100, 10_000, |_| AccMsg::default().frame()));
    frames.extend(every(20, 10_000, |_| {
        EngineMsg {
            engine_rpm: 3000.0,
            fuel_level: 30.0,
            engine_mode: EngineMode::Economy,
            fuel_used: 0.0,
        }
        .frame()
    }));
    frames
}

#[test]
fn hunting_and_a_gear_out_of_its_band_are_flagged_for_the_transmission() {
    use autoplug_can::Gear;
    // 3rd, 4th at 2 s, back to 3rd at 3 s, 4th again at 4 s: hunting, twice.
    let hunting = run(
        trans_frames(
            |t| match t {
                2000..=2999 | 4000.. => Gear::Fourth,
                _ => Gear::Third,
            },
            50.0,
        ),
        "shift rate and hunting",
    );
    assert_eq!(hunting.verdict, Verdict::Suspect, "{hunting:?}");
    assert_eq!(hunting.value, Some(2.0), "{hunting:?}");
    // 2nd gear at 120 km/h in economy for 10 s: far above its upshift speed.
    let stuck = run(
        trans_frames(|_| Gear::Second, 120.0),
        "gear against the shift schedule",
    );
    assert_eq!(stuck.verdict, Verdict::Faulty, "{stuck:?}");
    let fine = run(
        trans_frames(|_| Gear::Sixth, 120.0),
        "gear against the shift schedule",
    );
    assert_eq!(
        (fine.verdict, fine.value),
        (Verdict::Ok, Some(0.0)),
        "{fine:?}"
    );
}

#[test]
fn a_stuck_paddle_request_is_faulty_for_the_steering() {
    use autoplug_can::{ShiftMsg, ShiftRequest};
    let pulse = |t: u64| {
        let request = match t {
            1000..=1100 => ShiftRequest::Up,
            3000..=4000 => ShiftRequest::Down,
            _ => ShiftRequest::None,
        };
        ShiftMsg {
            shift_request: request,
        }
        .frame()
    };
    let f = run(every(20, 5000, pulse), "paddle requests as pulses");
    assert_eq!(f.verdict, Verdict::Faulty, "{f:?}");
    assert!((f.value.unwrap() - 1.0).abs() < 0.03, "{f:?}");
    let ok = |t: u64| {
        ShiftMsg {
            shift_request: if (1000..1100).contains(&t) {
                ShiftRequest::Up
            } else {
                ShiftRequest::None
            },
        }
        .frame()
    };
    let f = run(every(20, 5000, ok), "paddle requests as pulses");
    assert_eq!(f.verdict, Verdict::Ok, "{f:?}");
}

#[test]
fn only_a_positive_reset_response_on_the_ecus_own_identifier_restarts_its_routines() {
    use crate::is_reset_response;
    use autoplug_can::Node;
    let frame = |id: u32, data: &[u8]| {
        LogFrame::new(0, 0, id, false, autoplug_logs::FrameKind::Data, data).unwrap()
    };
    assert!(is_reset_response(
        Node::Cruise,
        &frame(0x78D, &[0x02, 0x51, 0x01, 0xAA, 0xAA, 0xAA, 0xAA, 0xAA])
    ));
    // Another ECU's response, a negative response, a request, a first frame.
    assert!(!is_reset_response(
        Node::Cruise,
        &frame(0x78E, &[0x02, 0x51, 0x01])
    ));
    assert!(!is_reset_response(
        Node::Cruise,
        &frame(0x78D, &[0x03, 0x7F, 0x11, 0x22])
    ));
    assert!(!is_reset_response(
        Node::Cruise,
        &frame(0x70D, &[0x02, 0x11, 0x01])
    ));
    assert!(!is_reset_response(
        Node::Cruise,
        &frame(0x78D, &[0x10, 0x14, 0x51, 0x01])
    ));
    assert!(!is_reset_response(Node::Cruise, &frame(0x78D, &[0x02])));

    // A fuel level that rose, then the engine reset: judged again from the reset on.
    let mut frames = every(20, 5000, |t| {
        EngineMsg {
            engine_rpm: 2000.0,
            fuel_level: 30.0 + t as f32 / 1000.0,
            engine_mode: EngineMode::Economy,
            fuel_used: 0.0,
        }
        .frame()
    });
    let mut pipeline = Pipeline::new(Strictness::Strict);
    let mut diagnostics = Diagnostics::new();
    frames.push(
        LogFrame::new(
            5_001_000,
            0,
            0x783,
            false,
            autoplug_logs::FrameKind::Data,
            &[0x02, 0x51, 0x01],
        )
        .unwrap(),
    );
    frames.extend(
        every(20, 2000, |_| {
            EngineMsg {
                engine_rpm: 2000.0,
                fuel_level: 35.0,
                engine_mode: EngineMode::Economy,
                fuel_used: 0.0,
            }
            .frame()
        })
        .into_iter()
        .map(|mut f| {
            f.t_us += 5_010_000;
            f
        }),
    );
    pipeline
        .run(
            &mut VecSource::new("test", frames),
            &mut [&mut diagnostics],
            &mut || false,
        )
        .unwrap();
    assert_eq!(diagnostics.restarts().len(), 1);
    assert_eq!(diagnostics.restarts()[0].at_us, 5_001_000);
    let engine = diagnostics
        .report(pipeline.state())
        .into_iter()
        .find(|d| d.ecu == Node::Engine)
        .unwrap();
    assert_eq!(engine.verdict, Verdict::Ok, "{engine:?}");
}

#[test]
fn dtc_reports_are_heard_single_and_multi_frame_and_described() {
    use crate::dtcs::describe;
    use crate::DtcMonitor;
    use autoplug_can::Node;
    use autoplug_ecu::{invalid_data, lost_communication};
    let diag = |t: u64, id: u32, data: &[u8]| {
        LogFrame::new(t, 0, id, false, autoplug_logs::FrameKind::Data, data).unwrap()
    };
    let lost = lost_communication(Node::Console).to_bytes();
    let invalid = invalid_data(Node::Pedals).to_bytes();
    let gear = autoplug_ecu_params::trans::GEAR_NOT_ENGAGED.to_bytes();
    let frames = vec![
        // The cruise ECU: one code, in a single frame (7 bytes: 59 02 mask + 1 record).
        diag(
            1,
            0x78D,
            &[0x07, 0x59, 0x02, 0xFF, lost[0], lost[1], lost[2], 0x2F],
        ),
        // The transmission: three codes (15 bytes) in a first and two consecutive frames.
        diag(
            2,
            0x786,
            &[0x10, 0x0F, 0x59, 0x02, 0xFF, lost[0], lost[1], lost[2]],
        ),
        diag(
            3,
            0x786,
            &[
                0x21, 0x2F, invalid[0], invalid[1], invalid[2], 0x28, gear[0],
            ],
        ),
        diag(
            4,
            0x786,
            &[0x22, gear[1], gear[2], 0x09, 0xAA, 0xAA, 0xAA, 0xAA],
        ),
        // The ABS: a consecutive frame out of sequence spoils its response.
        diag(
            5,
            0x78E,
            &[0x10, 0x0B, 0x59, 0x02, 0xFF, lost[0], lost[1], lost[2]],
        ),
        diag(6, 0x78E, &[0x22, 0x2F, 0, 0, 0, 0, 0]),
        // A negative response and a request are not reports.
        diag(7, 0x78C, &[0x03, 0x7F, 0x19, 0x31]),
        diag(8, 0x70C, &[0x03, 0x19, 0x02, 0xFF]),
    ];
    let mut pipeline = Pipeline::new(Strictness::Strict);
    let mut monitor = DtcMonitor::new();
    pipeline
        .run(
            &mut VecSource::new("test", frames),
            &mut [&mut monitor],
            &mut || false,
        )
        .unwrap();
    let latest = monitor.latest();
    assert_eq!(latest.len(), 2, "{latest:?}");
    assert_eq!(latest[0].ecu, Node::Transmission);
    let codes: Vec<String> = latest[0]
        .entries
        .iter()
        .map(|e| e.dtc.to_string())
        .collect();
    assert_eq!(codes, ["U0140-87", "U0429-86", "P0730-00"]);
    assert_eq!(latest[0].entries[2].status, 0x09);
    assert_eq!(latest[1].ecu, Node::Cruise);
    assert_eq!(latest[1].read_at_us, 1);
    assert_eq!(
        describe(latest[1].entries[0].dtc),
        "lost communication with the Console ECU (missing message)"
    );
    assert!(
        describe(autoplug_ecu_params::trans::GEAR_NOT_ENGAGED).starts_with("incorrect gear ratio")
    );
    assert!(
        describe(autoplug_ecu_params::abs::WHEEL_SENSOR_DTCS[1]).starts_with("front right wheel")
    );
    assert!(describe(autoplug_ecu::Dtc::from_u24(0x12_3456)).starts_with("not an AutoPlug code"));
}

#[test]
fn a_gap_is_explained_by_the_ecus_answers_to_a_tester_not_by_requests_alone() {
    use autoplug_can::Node;
    let engine = |_| {
        EngineMsg {
            engine_rpm: 900.0,
            fuel_level: 30.0,
            engine_mode: EngineMode::Economy,
            fuel_used: 0.0,
        }
        .frame()
    };
    let diag = |t_ms: u64, id: u32, data: &[u8]| {
        LogFrame::new(
            t_ms * 1000,
            0,
            id,
            false,
            autoplug_logs::FrameKind::Data,
            data,
        )
        .unwrap()
    };
    let verdict = |frames: Vec<LogFrame>| {
        report(frames)
            .into_iter()
            .find(|d| d.ecu == Node::Engine)
            .unwrap()
    };
    // The engine sends for 1 s, then stops; a tester asks it for its DTCs every second.
    let mut asked = every(20, 1000, engine);
    asked.extend(every(10, 4000, |_| {
        VehicleSpeedMsg { vehicle_speed: 0.0 }.frame()
    }));
    for t in [1500, 2500, 3500] {
        asked.push(diag(t, 0x703, &[0x03, 0x19, 0x02, 0xFF]));
    }
    assert_eq!(verdict(asked.clone()).verdict, Verdict::NoData);

    // The same, but it answers: it is in a diagnostic session, alive.
    let mut answered = asked;
    for t in [1501, 2501, 3501] {
        answered.push(diag(t, 0x783, &[0x03, 0x59, 0x02, 0xFF]));
    }
    // And it resumes at 4 s, so the gap ends.
    answered.extend(every(20, 500, engine).into_iter().map(|mut f| {
        f.t_us += 4_000_000;
        f
    }));
    let d = verdict(answered);
    assert_eq!(d.verdict, Verdict::Ok, "{d:?}");
}

#[test]
fn an_engine_rpm_that_disagrees_with_speed_and_gear_is_flagged() {
    use autoplug_can::{Gear, ShiftMode, TransMsg};
    // 100 km/h in 4th for 10 s; the engine reports `rpm(t)`.
    let run_with = |rpm: &dyn Fn(u64) -> f32| {
        let mut frames = every(10, 10_000, |_| {
            VehicleSpeedMsg {
                vehicle_speed: 100.0,
            }
            .frame()
        });
        frames.extend(every(10, 10_000, |_| brake(0.0)));
        frames.extend(every(20, 10_000, |_| {
            TransMsg {
                gear: Gear::Fourth,
                shift_mode: ShiftMode::Automatic,
            }
            .frame()
        }));
        frames.extend(every(20, 10_000, |t| {
            EngineMsg {
                engine_rpm: rpm(t),
                fuel_level: 30.0,
                engine_mode: EngineMode::Economy,
                fuel_used: 0.0,
            }
            .frame()
        }));
        run(frames, "RPM against speed and gear")
    };
    let expected = autoplug_ecu_params::trans::engine_rpm_at(
        100.0,
        autoplug_ecu_params::trans::GEAR_RATIOS[3],
    );
    let ok = run_with(&|_| expected);
    assert_eq!(ok.verdict, Verdict::Ok, "{ok:?}");
    assert!(ok.evidence.starts_with("held in all"), "{ok:?}");
    // A sensor stuck at idle from 2 s on: faulty, for the 8 s it lasted.
    let stuck = run_with(&|t| if t < 2000 { expected } else { 850.0 });
    assert_eq!(stuck.verdict, Verdict::Faulty, "{stuck:?}");
    assert!((stuck.value.unwrap() - 8.0).abs() < 0.1, "{stuck:?}");
    // 10 % off is within the tolerance (quantisation, tyre slip).
    let slipping = run_with(&|_| expected * 1.1);
    assert_eq!(slipping.verdict, Verdict::Ok, "{slipping:?}");
}

#[test]
fn a_steering_angle_that_jumps_faster_than_a_hand_is_flagged() {
    use autoplug_can::SteeringMsg;
    let angle = |deg: f32| {
        SteeringMsg {
            steering_angle: deg,
        }
        .frame()
    };
    // A 180 deg/s ramp (the step steer is 200): ok, measured close to it.
    let ramp = run(
        every(10, 2000, |t| angle((t as f32 * 0.18).min(135.0) - 67.5)),
        "steering angle rate",
    );
    assert_eq!(ramp.verdict, Verdict::Ok, "{ramp:?}");
    assert!((ramp.value.unwrap() - 180.0).abs() < 40.0, "{ramp:?}");
    // A jump from -90 to +90 degrees between two frames: 3600 deg/s over 50 ms.
    let jump = run(
        every(10, 2000, |t| angle(if t < 1000 { -90.0 } else { 90.0 })),
        "steering angle rate",
    );
    assert_eq!(jump.verdict, Verdict::Faulty, "{jump:?}");
}

/// Cruise engaged at 1 s for 20 s; VehicleSpeedMsg every 10 ms from `speed(t_ms)`.
fn cruise_run(speed: impl Fn(u64) -> f32) -> Finding {
    let mut frames = every(10, 22_000, |t| {
        CruiseModeMsg {
            cruise_mode: if (1000..21_000).contains(&t) {
                CruiseMode::On
            } else {
                CruiseMode::Off
            },
        }
        .frame()
    });
    frames.extend(every(10, 22_000, |t| {
        VehicleSpeedMsg {
            vehicle_speed: speed(t),
        }
        .frame()
    }));
    run(frames, "tracking error")
}

#[test]
fn a_held_speed_one_step_off_the_latched_value_is_ok_for_the_cruise() {
    // Latched at 100 (the bus value 20 ms after engagement), then held where the bus shows
    // 99: the ECU latched its own reading, e.g. 99.4, and holds it perfectly.
    let f = cruise_run(|t| if t <= 1030 { 100.0 } else { 99.0 });
    assert_eq!(f.verdict, Verdict::Ok, "{f:?}");
    assert!(f.value.unwrap() < 0.01, "{f:?}");
    // Flickering between the two steps around it: still ok.
    let f = cruise_run(|t| {
        if t <= 1030 || (t / 10) % 3 == 0 {
            100.0
        } else {
            99.0
        }
    });
    assert_eq!(f.verdict, Verdict::Ok, "{f:?}");
}

#[test]
fn an_offset_beyond_one_step_or_an_oscillation_still_counts_for_the_cruise() {
    // 3 km/h below the set speed for good: 2 km/h beyond the latch's uncertainty.
    let f = cruise_run(|t| if t <= 1030 { 100.0 } else { 97.0 });
    assert_eq!(f.verdict, Verdict::Faulty, "{f:?}");
    assert!((f.value.unwrap() - 2.0).abs() < 0.01, "{f:?}");
    // The report's bang-bang: ±2 km/h around the set speed, a 4 s period.
    let f = cruise_run(|t| {
        if t <= 1030 {
            100.0
        } else {
            100.0 + (2.0 * (t as f32 * 1e-3 * core::f32::consts::PI / 2.0).sin()).round()
        }
    });
    assert_eq!(f.verdict, Verdict::Faulty, "{f:?}");
    assert!(f.value.unwrap() > 1.1, "{f:?}");
}

/// The recognition after `frames` (in time order).
fn recognise(frames: Vec<LogFrame>) -> crate::Recognition {
    diagnosed(frames).1.recognition()
}

fn data(t_ms: u64, id: u32, extended: bool, bytes: &[u8]) -> LogFrame {
    LogFrame::new(
        t_ms * 1000,
        0,
        id,
        extended,
        autoplug_logs::FrameKind::Data,
        bytes,
    )
    .unwrap()
}

/// Every catalogue message at its length every 10 ms for `ms`.
fn autoplug_bus(ms: u64) -> Vec<LogFrame> {
    let mut frames = Vec::new();
    for t in (0..ms).step_by(10) {
        for m in autoplug_can::MESSAGES.iter() {
            frames.push(data(
                t,
                u32::from(m.id),
                false,
                &[0; 8][..usize::from(m.dlc)],
            ));
        }
    }
    frames
}

#[test]
fn the_catalogue_on_the_bus_is_an_autoplug_car() {
    let r = recognise(autoplug_bus(2000));
    assert!(r.autoplug, "{r:?}");
    assert_eq!((r.messages_seen, r.catalogue_messages), (18, 18));
    assert_eq!((r.catalogue_frames, r.foreign_frames), (3600, 0));
    assert_eq!(
        r.summary(),
        "an AutoPlug car (18 of the catalogue's 18 messages, 0.0 % of 3600 data frames foreign)"
    );
}

#[test]
fn a_tester_and_a_few_strangers_beside_the_car_change_nothing() {
    let mut frames = autoplug_bus(2000);
    for t in (0..2000).step_by(2) {
        // A scan tool on the OBD-II and UDS identifiers, busier than the car itself...
        frames.push(data(t, 0x7DF, false, &[2, 1, 0x0D, 0, 0, 0, 0, 0]));
        frames.push(data(
            t,
            0x7E0 + (t as u32 / 2) % 8,
            false,
            &[2, 0x3E, 0, 0, 0, 0, 0, 0],
        ));
        frames.push(data(
            t,
            0x7E8 + (t as u32 / 2) % 8,
            false,
            &[2, 0x7E, 0, 0, 0, 0, 0, 0],
        ));
    }
    // ... and a device of its own: 10 % of the data frames.
    for t in (0..2000).step_by(5) {
        frames.push(data(t, 0x555, false, &[1]));
    }
    frames.sort_by_key(|f| f.t_us);
    let r = recognise(frames);
    assert!(r.autoplug, "{r:?}");
    assert_eq!(r.foreign_frames, 400);
    assert!((r.foreign_share - 0.1).abs() < 1e-9, "{r:?}");
}

#[test]
fn another_cars_bus_is_not_an_autoplug_car() {
    // Its own identifiers, and 0x00E at the catalogue's length: 1 message of 18 matches.
    let mut frames = Vec::new();
    for t in (0..3000).step_by(10) {
        frames.push(data(t, 0x00E, false, &[200; 8]));
        for id in [0x0B4, 0x025, 0x1C4, 0x2C1, 0x3B7] {
            frames.push(data(t, id, false, &[0; 8]));
        }
        frames.push(data(t, 0x18FEF100, true, &[0; 8]));
    }
    let r = recognise(frames);
    assert!(!r.autoplug, "{r:?}");
    assert_eq!((r.catalogue_frames, r.foreign_frames), (300, 1800));
    assert_eq!(r.messages_seen, 1);
    assert_eq!(
        r.reasons,
        [
            "85.7 % of its 2100 data frames have an identifier or a length the catalogue does not know (above 20 %)",
            "only 1 of the catalogue's 18 messages in 3.0 s (fewer than 9)"
        ]
    );
    assert!(
        r.summary().starts_with("not an AutoPlug car: 85.7 %"),
        "{}",
        r.summary()
    );
}

#[test]
fn the_catalogues_identifiers_at_other_lengths_are_foreign() {
    // A car whose traffic sits on the catalogue's identifiers, every one at 8 bytes.
    let mut frames = Vec::new();
    for t in (0..2000).step_by(10) {
        for m in autoplug_can::MESSAGES.iter() {
            frames.push(data(t, u32::from(m.id), false, &[0; 8]));
        }
    }
    let r = recognise(frames);
    assert!(!r.autoplug, "{r:?}");
    // AbsMsg alone is 8 bytes long in the catalogue.
    assert_eq!((r.messages_seen, r.catalogue_frames), (1, 200));
    assert_eq!(r.reasons.len(), 2, "{r:?}");
}

#[test]
fn missing_messages_count_only_once_there_was_time_for_them() {
    // One message, no stranger: a filtered capture. Under 1 s: not judged on it.
    let short: Vec<LogFrame> = (0..99).map(|i| data(i * 10, 0x003, false, &[50])).collect();
    let r = recognise(short);
    assert!(r.autoplug, "{r:?}");
    // Over 1 s, half the catalogue must show.
    let long: Vec<LogFrame> = (0..101)
        .map(|i| data(i * 10, 0x003, false, &[50]))
        .collect();
    let r = recognise(long);
    assert!(!r.autoplug, "{r:?}");
    assert_eq!(
        r.reasons,
        ["only 1 of the catalogue's 18 messages in 1.0 s (fewer than 9)"]
    );
    // Nothing at all is nothing against it.
    assert!(recognise(Vec::new()).autoplug);
}

#[test]
fn a_routine_never_exercised_says_so_and_a_reset_judges_again() {
    use autoplug_can::Node;
    // Cruise frames with cruise never engaged: the tracking error has nothing to judge.
    let mut frames = every(20, 3000, |_| {
        CruiseModeMsg {
            cruise_mode: CruiseMode::Off,
        }
        .frame()
    });
    frames.extend(every(10, 3000, |_| {
        VehicleSpeedMsg {
            vehicle_speed: 50.0,
        }
        .frame()
    }));
    frames.extend(every(20, 3000, |_| {
        CruiseAccelMsg { cruise_accel: 0.0 }.frame()
    }));
    let tracking = run(frames.clone(), "tracking error");
    assert_eq!(tracking.verdict, Verdict::NotExercised, "{tracking:?}");
    assert_eq!(tracking.value, None);
    assert!(
        tracking.evidence.starts_with("not exercised"),
        "{tracking:?}"
    );
    assert_eq!(Verdict::NotExercised.name(), "not exercised");
    // The ECU is not shown as proven: its headline is the routine that had nothing to judge.
    frames.sort_by_key(|f| f.t_us);
    let (pipeline, mut diagnostics) = diagnosed(frames);
    let cruise = |d: &Diagnostics| {
        d.report(pipeline.state())
            .into_iter()
            .find(|d| d.ecu == Node::Cruise)
            .unwrap()
    };
    let before = cruise(&diagnostics);
    assert_eq!(before.verdict, Verdict::NotExercised, "{before:?}");
    assert_eq!(before.headline().unwrap().routine, "tracking error");
    // A reset forgets what was seen: presence has nothing yet (no data) until frames come.
    diagnostics.reset(Node::Cruise);
    assert_eq!(cruise(&diagnostics).verdict, Verdict::NoData);
    // The other ECUs keep their findings.
    let others = diagnostics.report(pipeline.state());
    let abs = others.iter().find(|d| d.ecu == Node::ABS).unwrap();
    assert_eq!(
        abs.verdict,
        Verdict::NoData,
        "no ABS frames were sent: {abs:?}"
    );
}
