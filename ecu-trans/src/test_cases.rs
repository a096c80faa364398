//! Test cases shared by the host test suite and the on-target (defmt-test) suite. Each case
//! panics on failure. A small bench plays the other ECUs' frames at their periods and a
//! gearbox that engages the commanded gear by the next step; the closed loop against the
//! vehicle model lives in `host-tests/`.

use crate::*;
use autoplug_can::{CanMessage, Message};
use autoplug_ecu::{invalid_data, lost_communication};

fn ms(t: u64) -> Instant {
    Instant::from_millis(t)
}

const SHIFT_TIMEOUT_MS: u64 = SHIFT_TIMEOUT_US / 1000;

/// The other ECUs and the gearbox around the transmission ECU.
struct Bench {
    ecu: TransEcu,
    t: u64,
    speed_kmh: f32,
    /// Engine speed to report; `None`: computed from the speed and the engaged gear.
    rpm: Option<f32>,
    engine_mode: EngineMode,
    shift_mode: ShiftMode,
    request: ShiftRequest,
    engaged: Gear,
    /// The gearbox ignores the command (a broken actuator).
    stuck: bool,
    send_speed: bool,
    send_shift: bool,
    send_engine: bool,
    send_acc: bool,
    last: Actuators,
}

impl Bench {
    /// Power-up at t = 0 in `gear`, every input sending: the first step has run.
    fn new(gear: Gear, shift_mode: ShiftMode, engine_mode: EngineMode, speed_kmh: f32) -> Self {
        let mut bench = Self::idle(gear, shift_mode, engine_mode, speed_kmh);
        bench.run_once();
        bench
    }

    /// The same, before the first step (`run_once` runs it).
    fn idle(gear: Gear, shift_mode: ShiftMode, engine_mode: EngineMode, speed_kmh: f32) -> Self {
        Self {
            ecu: TransEcu::new(ms(0)),
            t: 0,
            speed_kmh,
            rpm: None,
            engine_mode,
            shift_mode,
            request: ShiftRequest::None,
            engaged: gear,
            stuck: false,
            send_speed: true,
            send_shift: true,
            send_engine: true,
            send_acc: true,
            last: Actuators { gear_cmd: gear },
        }
    }

    fn engine_rpm(&self) -> f32 {
        self.rpm.unwrap_or_else(|| match gear_ratio(self.engaged) {
            Some(ratio) if self.engaged != Gear::Neutral => {
                engine_rpm_at(self.speed_kmh, ratio).max(800.0)
            }
            _ => 800.0,
        })
    }

    fn run_once(&mut self) -> Gear {
        let now = ms(self.t);
        if self.send_speed {
            let frame = VehicleSpeedMsg {
                vehicle_speed: self.speed_kmh,
            }
            .frame();
            self.ecu.on_frame(now, &frame);
        }
        if self.send_engine && self.t % 20 == 0 {
            let frame = EngineMsg {
                engine_rpm: self.engine_rpm(),
                fuel_level: 40.0,
                engine_mode: self.engine_mode,
                fuel_used: 0.0,
            }
            .frame();
            self.ecu.on_frame(now, &frame);
        }
        if self.send_shift && self.t % 20 == 0 {
            let frame = ShiftMsg {
                shift_request: self.request,
            }
            .frame();
            self.ecu.on_frame(now, &frame);
        }
        if self.send_acc && self.t % 100 == 0 {
            let frame = AccMsg {
                headlights: false,
                brake_lights: false,
                engine_mode: self.engine_mode,
                shift_mode_request: self.shift_mode,
            }
            .frame();
            self.ecu.on_frame(now, &frame);
        }
        self.last = self.ecu.step(
            now,
            &Sensors {
                current_gear: self.engaged,
            },
        );
        if !self.stuck {
            self.engaged = self.last.gear_cmd;
        }
        self.last.gear_cmd
    }

    /// Advances one step (10 ms) and returns the gear commanded.
    fn tick(&mut self) -> Gear {
        self.t += 10;
        self.run_once()
    }

    /// Runs for `duration` ms.
    fn run(&mut self, duration: u64) -> Gear {
        for _ in 0..duration / 10 {
            self.tick();
        }
        self.last.gear_cmd
    }

    /// A paddle press: "up" or "down" for 100 ms, then "none" for 60 ms.
    fn press(&mut self, request: ShiftRequest) -> Gear {
        self.request = request;
        self.run(100);
        self.request = ShiftRequest::None;
        self.run(60)
    }

    /// Waits out the shift timeout.
    fn settle(&mut self) -> Gear {
        self.run(SHIFT_TIMEOUT_MS + 100)
    }
}

/// Accelerates along `speed(t_ms)` for `duration_ms`, checking that every shift goes one
/// gear up; returns the gears engaged in order (at most 8) and the final gear.
fn upshift_sequence(
    bench: &mut Bench,
    duration_ms: u64,
    accel_kmh_per_s: f32,
) -> ([Gear; 8], usize) {
    let mut seen = [Gear::Neutral; 8];
    seen[0] = bench.last.gear_cmd;
    let mut n = 1;
    let start = bench.t;
    let v0 = bench.speed_kmh;
    for _ in 0..duration_ms / 10 {
        bench.speed_kmh = v0 + accel_kmh_per_s * (bench.t + 10 - start) as f32 * 1e-3;
        let before = bench.last.gear_cmd;
        let gear = bench.tick();
        if gear != before {
            assert_eq!(
                Some(gear),
                gear_up(before),
                "{:?} -> {:?} at {} km/h: not one gear up",
                before,
                gear,
                bench.speed_kmh
            );
            assert!(n < seen.len(), "too many shifts: hunting");
            seen[n] = gear;
            n += 1;
        }
    }
    (seen, n)
}

/// The ECU publishes the engaged gear and the shift mode every 20 ms, and a change at once.
pub fn publishes_gear_and_mode_every_20_ms() {
    let mut ecu = TransEcu::new(ms(0));
    let mut frames = 0;
    for t in (0..100).step_by(10) {
        ecu.step(
            ms(t),
            &Sensors {
                current_gear: Gear::Third,
            },
        );
        while let Some(frame) = ecu.poll_transmit(ms(t)) {
            match Message::from_frame(&frame) {
                Ok(Message::TransMsg(m)) => {
                    assert_eq!(m.gear, Gear::Third);
                    assert_eq!(m.shift_mode, ShiftMode::Automatic);
                    assert_eq!(frame.data(), &[4, 0]);
                    frames += 1;
                }
                other => panic!("unexpected {:?}", other),
            }
        }
    }
    assert_eq!(frames, 5);
    // The console switches to manual: the new mode goes out at the next step, not at the
    // next period.
    let acc = AccMsg {
        headlights: false,
        brake_lights: false,
        engine_mode: EngineMode::Sport,
        shift_mode_request: ShiftMode::Manual,
    };
    ecu.on_frame(ms(110), &acc.frame());
    ecu.step(
        ms(110),
        &Sensors {
            current_gear: Gear::Third,
        },
    );
    let frame = ecu
        .poll_transmit(ms(110))
        .expect("a change goes out at once");
    assert_eq!(frame.data(), &[4, 1]);
}

/// The EVO VI calibration and what the schedules make of it: every upshift lands above the
/// next gear's downshift point (hysteresis), economy upshifts near 3200 rpm, sport near
/// 6800 rpm, and every sport shift point lies above economy's.
pub fn calibration_and_schedules_are_consistent() {
    assert_eq!(GEAR_RATIOS, [2.909, 1.944, 1.434, 1.100, 0.868, 0.693]);
    assert_eq!(
        (REVERSE_RATIO, FINAL_DRIVE_RATIO, TYRE_RADIUS_M),
        (3.3, 4.529, 0.31)
    );
    assert_eq!(gear_ratio(Gear::Neutral), None);
    assert_eq!(gear_ratio(Gear::Sixth), Some(0.693));
    // 1000 rpm in 1st is 8.87 km/h; 6th at 150 km/h is 4028 rpm.
    assert!((road_speed_kmh(1000.0, 2.909) - 8.87).abs() < 0.05);
    assert!((engine_rpm_at(150.0, 0.693) - 4028.0).abs() < 10.0);
    let expected_economy_up = [28.4, 42.5, 57.6, 75.1, 95.1];
    let expected_sport_up = [60.3, 90.3, 122.4, 159.5, 202.2];
    for i in 0..5 {
        assert!((ECONOMY.upshift_kmh[i] - expected_economy_up[i]).abs() < 0.1);
        assert!((SPORT.upshift_kmh[i] - expected_sport_up[i]).abs() < 0.1);
        assert!(SPORT.upshift_kmh[i] > ECONOMY.upshift_kmh[i] + 20.0);
        assert!(SPORT.downshift_kmh[i] > ECONOMY.downshift_kmh[i]);
        for (schedule, down_rpm) in [
            (&ECONOMY, ECONOMY_DOWNSHIFT_RPM),
            (&SPORT, SPORT_DOWNSHIFT_RPM),
        ] {
            // Right after an upshift the engine is well above the downshift point of the
            // new gear, and right after a downshift below the upshift point.
            let after_up = engine_rpm_at(schedule.upshift_kmh[i], GEAR_RATIOS[i + 1]);
            assert!(
                after_up > down_rpm + 500.0,
                "{} rpm after upshift {}",
                after_up,
                i + 1
            );
            let after_down = engine_rpm_at(schedule.downshift_kmh[i], GEAR_RATIOS[i]);
            assert!(after_down < schedule_upshift_rpm(schedule) - 500.0);
        }
    }
    assert_eq!(ECONOMY.upshift_speed(Gear::Sixth), None);
    assert_eq!(ECONOMY.downshift_speed(Gear::First), None);
    assert_eq!(ECONOMY.next_gear(Gear::Second, 50.0), Gear::Third);
    assert_eq!(ECONOMY.next_gear(Gear::Second, 30.0), Gear::Second);
    assert_eq!(ECONOMY.next_gear(Gear::Second, 15.0), Gear::First);
    assert_eq!(ECONOMY.next_gear(Gear::Neutral, 50.0), Gear::Neutral);
    assert!(
        !ShiftSchedule::from_rpm(3000.0, 2500.0).is_valid(),
        "no hysteresis"
    );
}

fn schedule_upshift_rpm(schedule: &ShiftSchedule) -> f32 {
    if schedule == &SPORT {
        SPORT_UPSHIFT_RPM
    } else {
        ECONOMY_UPSHIFT_RPM
    }
}

/// Automatic, economy, full throttle 0 to 150 km/h in 12 s: 1st to 6th in order, one gear
/// at a time, never back down; speed dithering around a shift point shifts once; braking
/// to a stop comes down in order to 1st.
pub fn automatic_steps_through_the_gears_without_hunting() {
    let mut bench = Bench::new(Gear::First, ShiftMode::Automatic, EngineMode::Economy, 0.0);
    let (seen, n) = upshift_sequence(&mut bench, 12_000, 12.5);
    assert_eq!(
        &seen[..n],
        &[
            Gear::First,
            Gear::Second,
            Gear::Third,
            Gear::Fourth,
            Gear::Fifth,
            Gear::Sixth
        ]
    );
    assert_eq!(bench.engaged, Gear::Sixth);

    // Dithering +-3 km/h around the 2-3 upshift point (43.2 km/h): one shift, no return.
    let mut bench = Bench::new(
        Gear::Second,
        ShiftMode::Automatic,
        EngineMode::Economy,
        40.0,
    );
    let mut shifts = 0;
    for i in 0..500 {
        bench.speed_kmh = if (i / 10) % 2 == 0 { 40.0 } else { 46.0 };
        let before = bench.last.gear_cmd;
        if bench.tick() != before {
            shifts += 1;
        }
    }
    assert_eq!((shifts, bench.engaged), (1, Gear::Third));

    // Braking from 150 km/h to a stop at 8 km/h/s: downshifts only, one gear at a time.
    let mut bench = Bench::new(
        Gear::Sixth,
        ShiftMode::Automatic,
        EngineMode::Economy,
        150.0,
    );
    for _ in 0..2000 {
        bench.speed_kmh = (bench.speed_kmh - 0.08).max(0.0);
        let before = bench.last.gear_cmd;
        let gear = bench.tick();
        if gear != before {
            assert_eq!(Some(gear), gear_down(before), "{:?} -> {:?}", before, gear);
        }
    }
    assert_eq!(
        bench.engaged,
        Gear::First,
        "stopped in 1st, ready to move off"
    );
}

/// The same full-throttle run in sport holds every gear longer: at 150 km/h the car is in
/// 4th, never in a higher gear than economy would use at that speed; switching to economy
/// at speed upshifts, one gear per shift timeout.
pub fn sport_shifts_later_than_economy() {
    let mut sport = Bench::new(Gear::First, ShiftMode::Automatic, EngineMode::Sport, 0.0);
    let mut economy = Bench::new(Gear::First, ShiftMode::Automatic, EngineMode::Economy, 0.0);
    let mut sport_later = false;
    for i in 1..=1200u64 {
        let v = 12.5 * i as f32 * 0.01;
        sport.speed_kmh = v;
        economy.speed_kmh = v;
        let (s, e) = (sport.tick(), economy.tick());
        assert!(s <= e, "sport {:?} above economy {:?} at {} km/h", s, e, v);
        sport_later |= s < e;
    }
    assert!(sport_later);
    assert_eq!(
        (sport.engaged, economy.engaged),
        (Gear::Fourth, Gear::Sixth)
    );
    assert_eq!(sport.ecu.status().schedule, EngineMode::Sport);

    sport.engine_mode = EngineMode::Economy;
    let t0 = sport.t;
    let mut shift_times = [0u64; 2];
    let mut n = 0;
    for _ in 0..300 {
        let before = sport.last.gear_cmd;
        if sport.tick() != before {
            assert!(n < 2, "4th to 6th is two shifts");
            shift_times[n] = sport.t - t0;
            n += 1;
        }
    }
    assert_eq!((n, sport.engaged), (2, Gear::Sixth));
    assert_eq!(shift_times[1] - shift_times[0], SHIFT_TIMEOUT_MS);
}

/// At most one shift per shift timeout, whatever asks for it: the schedule catching up
/// from 1st at 150 km/h, or two paddle presses in quick succession (the second waits for
/// the end of the timeout, it is not lost).
pub fn shift_timeout_limits_the_shift_rate() {
    assert!((600_000..=1_000_000).contains(&SHIFT_TIMEOUT_US));
    let mut bench = Bench::new(
        Gear::First,
        ShiftMode::Automatic,
        EngineMode::Economy,
        150.0,
    );
    // The first shift goes at once (power-up step), then one per timeout.
    assert_eq!(bench.engaged, Gear::Second);
    let mut last_shift = 0;
    for _ in 0..500 {
        let before = bench.last.gear_cmd;
        if bench.tick() != before {
            assert_eq!(
                bench.t - last_shift,
                SHIFT_TIMEOUT_MS,
                "shift at {} ms",
                bench.t
            );
            last_shift = bench.t;
        }
    }
    assert_eq!(bench.engaged, Gear::Sixth);

    let mut bench = Bench::new(Gear::Second, ShiftMode::Manual, EngineMode::Economy, 50.0);
    bench.run(100);
    bench.request = ShiftRequest::Up;
    while bench.engaged == Gear::Second {
        bench.tick();
        assert!(bench.t < 200);
    }
    let first_shift = bench.t;
    bench.run(100);
    bench.request = ShiftRequest::None;
    bench.run(60);
    bench.press(ShiftRequest::Up); // within the timeout
    assert_eq!(bench.engaged, Gear::Third, "second press waits");
    while bench.engaged == Gear::Third && bench.t < first_shift + 2000 {
        bench.tick();
    }
    assert_eq!(bench.engaged, Gear::Fourth, "and is not lost");
    assert_eq!(bench.t - first_shift, SHIFT_TIMEOUT_MS);
}

/// Manual: each paddle press shifts exactly one gear, on the press's leading edge;
/// holding the paddle does not repeat; a paddle held since power-up does nothing; up from
/// 6th does nothing. Automatic ignores requests in a forward gear, except down from 1st.
pub fn manual_requests_shift_one_gear_per_press() {
    let mut bench = Bench::new(Gear::First, ShiftMode::Manual, EngineMode::Economy, 20.0);
    bench.run(100);
    let edge_at = bench.t + 20;
    bench.request = ShiftRequest::Up;
    while bench.engaged == Gear::First {
        bench.tick();
        assert!(bench.t <= edge_at + 10, "shift on the first up frame");
    }
    bench.run(1000); // held for a second: no repeat
    assert_eq!(bench.engaged, Gear::Second);
    bench.request = ShiftRequest::None;
    bench.run(100);
    bench.speed_kmh = 100.0;
    for expected in [
        Gear::Third,
        Gear::Fourth,
        Gear::Fifth,
        Gear::Sixth,
        Gear::Sixth,
    ] {
        bench.press(ShiftRequest::Up);
        assert_eq!(bench.engaged, expected);
        bench.settle();
    }
    assert_eq!(bench.ecu.status().shift_mode, ShiftMode::Manual);
    // Manual never shifts on its own: 6th at 10 km/h stays 6th.
    bench.speed_kmh = 10.0;
    bench.rpm = Some(900.0);
    assert_eq!(bench.settle(), Gear::Sixth);
    for expected in [Gear::Fifth, Gear::Fourth, Gear::Third] {
        bench.press(ShiftRequest::Down);
        assert_eq!(bench.engaged, expected);
        bench.settle();
    }

    // A paddle held from power-up: nothing until it is released and pressed again.
    let mut bench = Bench::idle(Gear::Third, ShiftMode::Manual, EngineMode::Economy, 50.0);
    bench.request = ShiftRequest::Up;
    bench.run_once();
    bench.run(2000);
    assert_eq!(bench.engaged, Gear::Third);
    bench.request = ShiftRequest::None;
    bench.run(40);
    bench.press(ShiftRequest::Up);
    assert_eq!(bench.engaged, Gear::Fourth);
    // The same when the steering ECU starts later, with the paddle pulled: the catalogue's
    // start value "none" is not an observed release.
    let mut bench = Bench::idle(Gear::Third, ShiftMode::Manual, EngineMode::Economy, 50.0);
    bench.send_shift = false;
    bench.run_once();
    bench.run(20);
    bench.send_shift = true;
    bench.request = ShiftRequest::Up;
    bench.run(500);
    assert_eq!(bench.engaged, Gear::Third);

    // Automatic: requests in 3rd are ignored, and not kept for later.
    let mut bench = Bench::new(Gear::Third, ShiftMode::Automatic, EngineMode::Economy, 50.0);
    bench.run(100);
    bench.press(ShiftRequest::Down);
    bench.press(ShiftRequest::Up);
    assert_eq!(bench.settle(), Gear::Third);
    assert!(!bench.ecu.status().last_request_refused);
}

/// Automatic engages 1st from Neutral at standstill by itself (like "D"), not while
/// rolling. A driver who selects Neutral (down from 1st) stays there until asking for a
/// gear; Reverse only at standstill, left only by a request.
pub fn neutral_and_reverse_in_automatic() {
    let mut bench = Bench::new(
        Gear::Neutral,
        ShiftMode::Automatic,
        EngineMode::Economy,
        0.0,
    );
    assert_eq!(bench.engaged, Gear::First, "engaged at the first step");

    let mut rolling = Bench::new(
        Gear::Neutral,
        ShiftMode::Automatic,
        EngineMode::Economy,
        20.0,
    );
    assert_eq!(rolling.settle(), Gear::Neutral);
    rolling.speed_kmh = 2.0;
    assert_eq!(rolling.run(20), Gear::First);

    bench.settle();
    bench.press(ShiftRequest::Down);
    assert_eq!(bench.engaged, Gear::Neutral, "down from 1st: Neutral");
    assert_eq!(
        bench.settle(),
        Gear::Neutral,
        "the driver's Neutral is kept"
    );
    bench.press(ShiftRequest::Down);
    assert_eq!(bench.engaged, Gear::Reverse);
    assert_eq!(
        bench.settle(),
        Gear::Reverse,
        "automatic leaves Reverse alone"
    );
    bench.press(ShiftRequest::Up);
    assert_eq!(bench.engaged, Gear::Neutral);
    bench.settle();
    bench.press(ShiftRequest::Up);
    assert_eq!(bench.engaged, Gear::First);

    // Reverse is refused while moving, and so is 1st at a speed that would over-rev it.
    let mut bench = Bench::new(Gear::Neutral, ShiftMode::Manual, EngineMode::Economy, 10.0);
    bench.run(100);
    bench.press(ShiftRequest::Down);
    assert_eq!(bench.engaged, Gear::Neutral);
    assert!(bench.ecu.status().last_request_refused);
    bench.speed_kmh = 90.0; // 8500 rpm in 1st
    bench.settle();
    bench.press(ShiftRequest::Up);
    assert_eq!(bench.engaged, Gear::Neutral);
    bench.speed_kmh = 60.0; // 6350 rpm in 1st
    bench.settle();
    bench.press(ShiftRequest::Up);
    assert_eq!(bench.engaged, Gear::First);
    assert!(!bench.ecu.status().last_request_refused);
}

/// Manual downshift over-rev protection: predicted RPM = engine RPM × ratio(target) /
/// ratio(current). 3rd to 2nd at 5500 rpm would give 7456 rpm: refused, gear kept; at
/// 4500 rpm (6100 rpm after) it goes. Down from 1st to Neutral is never refused.
pub fn manual_downshift_that_would_over_rev_is_refused() {
    let mut bench = Bench::new(Gear::Third, ShiftMode::Manual, EngineMode::Sport, 110.0);
    bench.rpm = Some(5500.0);
    bench.run(100);
    bench.press(ShiftRequest::Down);
    assert_eq!(bench.engaged, Gear::Third);
    assert!(bench.ecu.status().last_request_refused);
    assert_eq!(
        bench.settle(),
        Gear::Third,
        "a refused request is not retried"
    );
    bench.rpm = Some(4500.0);
    bench.press(ShiftRequest::Down);
    assert_eq!(bench.engaged, Gear::Second);
    assert!(!bench.ecu.status().last_request_refused);
    bench.settle();
    // 2nd to 1st at 5050 rpm: 7557 rpm, over the limit; at 4600: 6883, allowed.
    bench.rpm = Some(5050.0);
    bench.press(ShiftRequest::Down);
    assert_eq!(bench.engaged, Gear::Second);
    bench.rpm = Some(4600.0);
    bench.settle();
    bench.press(ShiftRequest::Down);
    assert_eq!(bench.engaged, Gear::First);
    bench.settle();
    bench.rpm = Some(7400.0);
    bench.press(ShiftRequest::Down);
    assert_eq!(bench.engaged, Gear::Neutral);
    // Upshifts are never refused, whatever the RPM.
    let mut bench = Bench::new(Gear::Fourth, ShiftMode::Manual, EngineMode::Sport, 180.0);
    bench.rpm = Some(7400.0);
    bench.run(100);
    bench.press(ShiftRequest::Up);
    assert_eq!(bench.engaged, Gear::Fifth);
}

/// VehicleSpeedMsg lost: the gear is held (no automatic shift, whatever the speed was),
/// "lost communication with the cruise ECU" is recorded; shifting resumes when it returns.
pub fn stale_vehicle_speed_holds_the_gear() {
    let mut bench = Bench::new(Gear::Third, ShiftMode::Automatic, EngineMode::Economy, 50.0);
    bench.run(100);
    let dtc = lost_communication(Node::Cruise);
    bench.send_speed = false;
    bench.speed_kmh = 100.0; // the last frame said 50: nothing to act on
    let stopped_at = bench.t;
    let period = u64::from(VehicleSpeedMsg::CYCLE_TIME_MS);
    while !bench.ecu.dtcs().is_active(dtc) {
        bench.tick();
        assert!(bench.t <= stopped_at + 3 * period + 10);
    }
    assert_eq!(bench.run(3000), Gear::Third, "held");
    // Manual requests that do not need the speed still work; Neutral to 1st does not.
    bench.shift_mode = ShiftMode::Manual;
    bench.run(200);
    bench.press(ShiftRequest::Up);
    assert_eq!(bench.engaged, Gear::Fourth);
    bench.send_speed = true;
    bench.shift_mode = ShiftMode::Automatic;
    bench.run(2000);
    assert!(!bench.ecu.dtcs().is_active(dtc));
    assert!(bench.ecu.dtcs().get(dtc).is_some(), "stays stored");
    assert_eq!(
        bench.engaged,
        Gear::Sixth,
        "schedule resumes: 100 km/h is 6th in economy"
    );

    let mut bench = Bench::new(Gear::Neutral, ShiftMode::Manual, EngineMode::Economy, 0.0);
    bench.send_speed = false;
    bench.run(200);
    bench.press(ShiftRequest::Up);
    assert_eq!(bench.engaged, Gear::Neutral, "1st needs a known speed");
    bench.press(ShiftRequest::Down);
    assert_eq!(bench.engaged, Gear::Neutral, "so does Reverse");
}

/// ShiftMsg lost: requests are ignored (a paddle held through the loss does nothing when
/// frames return), "lost communication with the steering ECU" is recorded.
pub fn stale_shift_requests_are_ignored() {
    let mut bench = Bench::new(Gear::Third, ShiftMode::Manual, EngineMode::Economy, 60.0);
    bench.run(100);
    let dtc = lost_communication(Node::Steering);
    bench.send_shift = false;
    bench.run(3 * u64::from(ShiftMsg::CYCLE_TIME_MS));
    assert!(bench.ecu.dtcs().is_active(dtc));
    // The steering ECU comes back with the paddle already pulled: no shift.
    bench.request = ShiftRequest::Up;
    bench.send_shift = true;
    bench.run(500);
    assert_eq!(bench.engaged, Gear::Third);
    assert!(!bench.ecu.dtcs().is_active(dtc));
    bench.request = ShiftRequest::None;
    bench.run(40);
    bench.press(ShiftRequest::Up);
    assert_eq!(bench.engaged, Gear::Fourth, "a fresh press works");
}

/// EngineMsg lost: the economy schedule is used even in sport, every manual downshift
/// between forward gears is refused (engine speed unknown), "lost communication with the
/// engine ECU" is recorded.
pub fn stale_engine_selects_economy_and_refuses_downshifts() {
    let mut bench = Bench::new(Gear::Second, ShiftMode::Automatic, EngineMode::Sport, 50.0);
    bench.run(200);
    assert_eq!(bench.engaged, Gear::Second, "sport holds 2nd at 50 km/h");
    assert_eq!(bench.ecu.status().schedule, EngineMode::Sport);
    bench.send_engine = false;
    bench.run(3 * u64::from(EngineMsg::CYCLE_TIME_MS));
    assert!(bench.ecu.dtcs().is_active(lost_communication(Node::Engine)));
    assert_eq!(bench.ecu.status().schedule, EngineMode::Economy);
    assert_eq!(bench.settle(), Gear::Third, "economy upshifts at 43 km/h");

    bench.shift_mode = ShiftMode::Manual;
    bench.run(200);
    bench.speed_kmh = 20.0; // 2nd would be fine, but the RPM is unknown
    bench.press(ShiftRequest::Down);
    assert_eq!(bench.engaged, Gear::Third);
    assert!(bench.ecu.status().last_request_refused);
    bench.press(ShiftRequest::Up);
    assert_eq!(bench.settle(), Gear::Fourth, "upshifts still work");

    // Never received at all: the same, from the first step.
    let mut bench = Bench::idle(Gear::Third, ShiftMode::Manual, EngineMode::Sport, 30.0);
    bench.send_engine = false;
    bench.run_once();
    assert_eq!(bench.ecu.status().schedule, EngineMode::Economy);
    bench.run(100);
    bench.press(ShiftRequest::Down);
    assert_eq!(bench.engaged, Gear::Third);
    assert!(bench.ecu.dtcs().is_active(lost_communication(Node::Engine)));
}

/// AccMsg lost: the last shift mode is kept (manual stays manual), "lost communication
/// with the console" is recorded.
pub fn stale_console_keeps_the_shift_mode() {
    let mut bench = Bench::new(Gear::Third, ShiftMode::Manual, EngineMode::Economy, 100.0);
    bench.run(200);
    assert_eq!(bench.ecu.status().shift_mode, ShiftMode::Manual);
    bench.send_acc = false;
    bench.run(3 * u64::from(AccMsg::CYCLE_TIME_MS) + 100);
    assert!(bench
        .ecu
        .dtcs()
        .is_active(lost_communication(Node::Console)));
    assert_eq!(bench.ecu.status().shift_mode, ShiftMode::Manual);
    assert_eq!(
        bench.settle(),
        Gear::Third,
        "still manual: no automatic upshift"
    );
    let frame = loop {
        bench.tick();
        if let Some(frame) = bench.ecu.poll_transmit(ms(bench.t)) {
            break frame;
        }
    };
    assert_eq!(frame.data()[1], 1, "published as manual");
}

/// Invalid frames (undefined value, wrong length) record "invalid data" against their
/// sender and leave the last good values in use.
pub fn invalid_frames_are_refused() {
    let mut bench = Bench::new(Gear::Third, ShiftMode::Manual, EngineMode::Sport, 60.0);
    bench.run(100);
    let now = ms(bench.t);
    let bad_shift = Frame::new(u32::from(ShiftMsg::ID), &[3]).unwrap();
    bench.ecu.on_frame(now, &bad_shift);
    assert!(bench.ecu.dtcs().is_active(invalid_data(Node::Steering)));
    let bad_engine = Frame::new(u32::from(EngineMsg::ID), &[100, 100, 2]).unwrap();
    bench.ecu.on_frame(now, &bad_engine);
    assert!(bench.ecu.dtcs().is_active(invalid_data(Node::Engine)));
    let short_speed = Frame::new(u32::from(VehicleSpeedMsg::ID), &[]).unwrap();
    bench.ecu.on_frame(now, &short_speed);
    assert!(bench.ecu.dtcs().is_active(invalid_data(Node::Cruise)));
    let long_acc = Frame::new(u32::from(AccMsg::ID), &[0, 0]).unwrap();
    bench.ecu.on_frame(now, &long_acc);
    assert!(bench.ecu.dtcs().is_active(invalid_data(Node::Console)));
    // The partly valid EngineMsg kept its mode (sport), and nothing shifted.
    bench.send_engine = false;
    bench.send_shift = false;
    bench.tick();
    assert_eq!(bench.ecu.status().schedule, EngineMode::Sport);
    assert_eq!(bench.engaged, Gear::Third);
    // A frame of another ECU is none of its business.
    let other = Frame::new(0x020, &[5]).unwrap();
    bench.ecu.on_frame(now, &other);
    assert_eq!(bench.ecu.dtcs().records().count(), 4);
}

/// A gearbox that does not engage the commanded gear within 1 s records P0730; engaging it
/// clears the fault (it stays stored).
pub fn gear_not_engaged_is_recorded() {
    let mut bench = Bench::new(
        Gear::Second,
        ShiftMode::Automatic,
        EngineMode::Economy,
        30.0,
    );
    bench.run(100);
    bench.stuck = true;
    bench.speed_kmh = 50.0;
    bench.tick();
    assert_eq!(bench.last.gear_cmd, Gear::Third);
    assert_eq!(bench.engaged, Gear::Second);
    bench.run(GEAR_ENGAGE_TIMEOUT_US / 1000 - 20);
    assert!(!bench.ecu.dtcs().is_active(GEAR_NOT_ENGAGED), "not yet");
    bench.run(20);
    assert!(bench.ecu.dtcs().is_active(GEAR_NOT_ENGAGED));
    assert_eq!(bench.ecu.status().engaged, Gear::Second);
    bench.stuck = false;
    bench.run(20);
    assert!(!bench.ecu.dtcs().is_active(GEAR_NOT_ENGAGED));
    assert!(bench.ecu.dtcs().get(GEAR_NOT_ENGAGED).is_some());
    assert_eq!(GEAR_NOT_ENGAGED.to_bytes(), [0x07, 0x30, 0x00]);
}

autoplug_ecu::test_cases!(
    publishes_gear_and_mode_every_20_ms,
    calibration_and_schedules_are_consistent,
    automatic_steps_through_the_gears_without_hunting,
    sport_shifts_later_than_economy,
    shift_timeout_limits_the_shift_rate,
    manual_requests_shift_one_gear_per_press,
    neutral_and_reverse_in_automatic,
    manual_downshift_that_would_over_rev_is_refused,
    stale_vehicle_speed_holds_the_gear,
    stale_shift_requests_are_ignored,
    stale_engine_selects_economy_and_refuses_downshifts,
    stale_console_keeps_the_shift_mode,
    invalid_frames_are_refused,
    gear_not_engaged_is_recorded,
);
