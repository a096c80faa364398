use std::path::Path;

use autoplug_can::{CanMessage, EngineMode, EngineMsg, Frame, VehicleSpeedMsg};
use autoplug_gateway::{Pipeline, Strictness, VecSource};
use autoplug_logs::LogFrame;
use autoplug_virtual_car::report;
use autoplug_virtual_car::scenario::Scenario;

use crate::*;

fn trips_of(frames: Vec<LogFrame>) -> (Vec<CompletedTrip>, TripTracker) {
    let mut pipeline = Pipeline::new(Strictness::Strict);
    let mut tracker = TripTracker::new();
    pipeline
        .run(
            &mut VecSource::new("test", frames),
            &mut [&mut tracker],
            &mut || false,
        )
        .unwrap();
    tracker.finish();
    (tracker.take_completed(), tracker)
}

fn at(t_ms: u64, frame: Frame) -> LogFrame {
    LogFrame::from_can(t_ms * 1000, 0, &frame)
}

fn engine(rpm: f32, fuel_used_ml: u16) -> Frame {
    EngineMsg {
        engine_rpm: rpm,
        fuel_level: 40.0,
        engine_mode: EngineMode::Economy,
        fuel_used: f32::from(fuel_used_ml),
    }
    .frame()
}

fn speed(kmh: f32) -> Frame {
    VehicleSpeedMsg { vehicle_speed: kmh }.frame()
}

/// The virtual car's own figures of a scenario, and the trips the gateway finds in the
/// car's bus log of the same run.
fn scenario_trips(name: &str) -> (report::Summary, Vec<CompletedTrip>) {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let scenario = Scenario::load(&root.join(format!("scenarios/{name}.toml"))).unwrap();
    let run = report::run(&scenario);
    let frames = run
        .log
        .iter()
        .map(|f| LogFrame::from_can(f.t_us, 0, &f.frame))
        .collect();
    (run.summary, trips_of(frames).0)
}

/// The acceptance of the trips: the statistics the gateway takes from the bus agree with
/// the virtual car's own summary of the same run.
fn agrees_with_the_car(name: &str) -> TripStats {
    agrees_with_the_car_but(name, false)
}

/// As [`agrees_with_the_car`]; `spins` for a run where the car spins, so its path is longer
/// than the bus can show: the speed sensor measures the speed along the car's axis, which
/// goes negative while it slides backwards and is sent as 0 (VehicleSpeedMsg is unsigned).
fn agrees_with_the_car_but(name: &str, spins: bool) -> TripStats {
    let (summary, trips) = scenario_trips(name);
    assert_eq!(trips.len(), 1, "{name}: one trip, {trips:?}");
    let trip = &trips[0];
    assert_eq!(trip.end, TripEnd::EndOfInput, "{name}");
    let s = &trip.stats;
    let distance_error = (s.distance_m - summary.distance_m).abs();
    assert!(
        distance_error <= 0.01 * summary.distance_m || (spins && s.distance_m < summary.distance_m),
        "{name}: distance {} m, the car says {} m",
        s.distance_m,
        summary.distance_m
    );
    assert!(
        (s.fuel_used_l - summary.fuel_used_l).abs() <= 0.05,
        "{name}: fuel {} L, the car says {} L",
        s.fuel_used_l,
        summary.fuel_used_l
    );
    assert!(
        (s.max_speed_kmh - summary.max_speed_kmh).abs() <= 1.0,
        "{name}: max speed {} km/h, the car says {} km/h",
        s.max_speed_kmh,
        summary.max_speed_kmh
    );
    assert_eq!(s.shifts as usize, summary.shifts, "{name}: shifts");
    assert_eq!(
        s.abs_interventions as usize, summary.abs_interventions,
        "{name}: ABS interventions"
    );
    s.clone()
}

#[test]
fn the_drive_cycle_agrees_with_the_car() {
    let s = agrees_with_the_car("drive-cycle");
    assert!(s.distance_m > 3000.0 && s.shifts > 10, "{s:?}");
    assert!(s.cruise_time_s > 10.0, "the drive cycle cruises: {s:?}");
    assert!(s.abs_interventions >= 1 && s.hard_brakings >= 1, "{s:?}");
}

#[test]
fn the_braking_scenarios_agree_with_the_car() {
    for name in [
        "stop-100-dry",
        "stop-100-wet",
        "stop-100-split-mu",
        "abs-stop-190",
        "abs-faulty-split-mu",
    ] {
        // The faulty ABS locks the wheels on split friction and the car spins.
        let s = agrees_with_the_car_but(name, name == "abs-faulty-split-mu");
        // Every stop is a hard braking. (On split friction the ABS holds the grippy side
        // back to keep the car straight, under 0.4 g; on the braking straight the car
        // drifts 0.8 m left over the stop and its right wheels reach the dry half below
        // 45 km/h, where it then stops harder.)
        assert_eq!(s.hard_brakings, 1, "{name}: {s:?}");
        if name != "abs-faulty-split-mu" {
            assert!(s.abs_interventions >= 1, "{name}: the ABS acts, {s:?}");
        }
    }
}

#[test]
fn the_other_scenarios_agree_with_the_car() {
    for name in [
        "accel-economy",
        "accel-sport",
        "cruise-hold",
        "cruise-faulty",
        "diff-step-steer",
        "diff-step-steer-open",
    ] {
        agrees_with_the_car(name);
    }
    let s = agrees_with_the_car("diff-step-steer");
    assert_eq!(s.diff_interventions, 1, "one step steer: {s:?}");
    assert!(s.diff_time_s > 0.5, "{s:?}");
}

#[test]
fn a_trip_begins_with_the_engine_and_ends_parked_30_s_after_it_stops() {
    let mut frames = Vec::new();
    // Engine off for 1 s: no trip yet.
    for t in (0..1000).step_by(20) {
        frames.push(at(t, engine(0.0, 0)));
    }
    // Running from 1 s to 11 s, burning 1 mL every 20 ms (180 L/h).
    for (i, t) in (1000..11_000).step_by(20).enumerate() {
        frames.push(at(t, engine(850.0, i as u16)));
    }
    // Off again for 40 s.
    for t in (11_000..51_000).step_by(20) {
        frames.push(at(t, engine(0.0, 499)));
    }
    let (trips, _) = trips_of(frames);
    assert_eq!(trips.len(), 1, "{trips:?}");
    let trip = &trips[0];
    assert_eq!(trip.end, TripEnd::Parked);
    assert_eq!(trip.stats.start_us, 1_000_000);
    assert_eq!(trip.stats.end_us, 10_980_000, "the last frame running");
    assert!((trip.stats.fuel_used_l - 0.499).abs() < 1e-9, "{trip:?}");
    assert_eq!(trip.stats.distance_m, 0.0);
}

#[test]
fn a_silent_bus_ends_the_trip_and_the_next_frames_begin_another() {
    let mut frames = Vec::new();
    for t in (0..2000).step_by(10) {
        frames.push(at(t, speed(36.0)));
    }
    // 10 s of silence, then driving again.
    for t in (12_000..14_000).step_by(10) {
        frames.push(at(t, speed(72.0)));
    }
    let (trips, _) = trips_of(frames);
    assert_eq!(trips.len(), 2, "{trips:?}");
    assert_eq!(trips[0].end, TripEnd::BusSilent);
    assert_eq!(trips[1].end, TripEnd::EndOfInput);
    // 36 km/h is 10 m/s: 1.99 s of samples is 19.9 m; the gap is not integrated over.
    assert!((trips[0].stats.distance_m - 19.9).abs() < 1e-6, "{trips:?}");
    assert!((trips[1].stats.distance_m - 39.8).abs() < 1e-6, "{trips:?}");
    assert_eq!(trips[1].stats.max_speed_kmh, 72.0);
}

/// Frames, then a silent bus whose clock runs on (the virtual car with its ECUs asleep).
struct FallsAsleep {
    frames: std::vec::IntoIter<LogFrame>,
    clock_us: u64,
}

impl autoplug_gateway::FrameSource for FallsAsleep {
    fn poll(
        &mut self,
        _max_wait: std::time::Duration,
    ) -> Result<autoplug_gateway::Poll, autoplug_gateway::SourceError> {
        Ok(match self.frames.next() {
            Some(frame) => {
                self.clock_us = frame.t_us;
                autoplug_gateway::Poll::Frame(frame)
            }
            None => {
                self.clock_us += 5_000;
                autoplug_gateway::Poll::Idle
            }
        })
    }

    fn describe(&self) -> String {
        "a bus that falls asleep".into()
    }

    fn clock_us(&self) -> Option<u64> {
        Some(self.clock_us)
    }
}

#[test]
fn a_silence_ends_the_trip_on_the_sources_clock_without_another_frame() {
    let frames: Vec<LogFrame> = (0..2000).step_by(10).map(|t| at(t, speed(36.0))).collect();
    let mut source = FallsAsleep {
        frames: frames.into_iter(),
        clock_us: 0,
    };
    let mut pipeline = Pipeline::new(Strictness::Strict);
    let mut tracker = TripTracker::new();
    // 4.9 s of silence: the trip goes on.
    let mut polls = 0;
    pipeline
        .run(&mut source, &mut [&mut tracker], &mut || {
            polls += 1;
            polls > 200 + 980
        })
        .unwrap();
    assert!(tracker.take_completed().is_empty());
    assert!(tracker.current().is_some());
    // Past 5 s it ends, with no frame to show the gap.
    let mut polls = 0;
    pipeline
        .run(&mut source, &mut [&mut tracker], &mut || {
            polls += 1;
            polls > 30
        })
        .unwrap();
    let trips = tracker.take_completed();
    assert_eq!(trips.len(), 1);
    assert_eq!(trips[0].end, TripEnd::BusSilent);
    assert_eq!(trips[0].stats.end_us, 1_990_000);
    assert!(tracker.current().is_none());
}

#[test]
fn the_fuel_counter_wraps_and_a_restarted_ecu_counts_from_zero() {
    let mut frames = Vec::new();
    let mut counter: u16 = 65_000;
    for t in (0..20_000).step_by(20) {
        frames.push(at(t, engine(3000.0, counter)));
        counter = counter.wrapping_add(1);
    }
    // 1000 frames, 999 steps of 1 mL across the wrap at 65536.
    let (trips, _) = trips_of(frames.clone());
    assert!(
        (trips[0].stats.fuel_used_l - 0.999).abs() < 1e-9,
        "{trips:?}"
    );

    // The ECU restarts at 20 s: its counter begins again at 0, then 5 mL.
    frames.push(at(20_000, engine(3000.0, 0)));
    frames.push(at(20_020, engine(3000.0, 5)));
    let (trips, _) = trips_of(frames);
    assert!(
        (trips[0].stats.fuel_used_l - 1.004).abs() < 1e-9,
        "{trips:?}"
    );
}

#[test]
fn the_series_keeps_mean_min_and_max_per_second() {
    let mut frames = Vec::new();
    for t in (0..3000).step_by(10) {
        let kmh = if t == 1500 { 100.0 } else { 50.0 };
        frames.push(at(t, speed(kmh)));
    }
    let (trips, _) = trips_of(frames);
    let speed: Vec<_> = trips[0]
        .series
        .iter()
        .filter(|p| p.signal == "Vehicle.Speed")
        .collect();
    assert_eq!(speed.len(), 3, "{speed:?}");
    assert_eq!(
        (speed[1].t_s, speed[1].min, speed[1].max),
        (1.0, 50.0, 100.0)
    );
    assert!((speed[1].mean - 50.5).abs() < 1e-9);
    assert_eq!(speed[0].mean, 50.0);
}
