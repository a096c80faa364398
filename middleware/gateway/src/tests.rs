use autoplug_can::{
    CanMessage, CruiseMode, CruiseModeMsg, EngineMode, EngineMsg, Frame, SteeringMsg,
    VehicleSpeedMsg, MESSAGES,
};
use autoplug_logs::LogFrame;

use crate::pipeline::{Observer, Pipeline, Strictness};
use crate::source::VecSource;
use crate::state::{CarState, Update, MAX_LISTED_UNKNOWN_IDS, RECENT_INTERVALS};

fn at(t_ms: u64, frame: Frame) -> LogFrame {
    LogFrame::from_can(t_ms * 1000, 0, &frame)
}

fn raw(t_ms: u64, id: u32, data: &[u8]) -> LogFrame {
    at(t_ms, Frame::new(id, data).unwrap())
}

fn speed(t_ms: u64, kmh: f32) -> LogFrame {
    at(t_ms, VehicleSpeedMsg { vehicle_speed: kmh }.frame())
}

#[test]
fn signals_start_at_their_start_values_and_are_not_fresh() {
    let state = CarState::new();
    let steering = state.signal("SteeringMsg.SteeringAngle").unwrap();
    assert_eq!(steering.value, 0.0, "raw 50 is straight ahead");
    assert_eq!(steering.updated_us, None);
    assert!(!steering.is_fresh(0));
    let gear = state.signal("TransMsg.Gear").unwrap();
    assert_eq!(gear.label(), Some("Neutral"));
    let count: usize = MESSAGES.iter().map(|m| m.signals.len()).sum();
    assert_eq!(state.signals().len(), count);
}

#[test]
fn a_frame_updates_value_time_and_freshness() {
    let mut state = CarState::new();
    let update = state.update(&speed(100, 87.0));
    assert!(matches!(update, Update::Message { valid: true, .. }));
    let s = state.signal("Vehicle.Speed").unwrap();
    assert_eq!((s.value, s.spec.unit), (87.0, "km/h"));
    assert_eq!(s.updated_us, Some(100_000));
    // Stale after 3 periods of 10 ms.
    assert_eq!(s.stale_after_us(), 30_000);
    assert!(s.is_fresh(130_000));
    assert!(!s.is_fresh(130_001));
    assert_eq!(state.get::<VehicleSpeedMsg>().vehicle_speed, 87.0);
}

#[test]
fn every_signal_has_a_unique_vss_path_and_the_standard_ones_are_found() {
    let state = CarState::new();
    let mut paths: Vec<&str> = state.signals().iter().map(|s| s.vss()).collect();
    assert!(paths.iter().all(|p| p.starts_with("Vehicle.")));
    paths.sort_unstable();
    let n = paths.len();
    paths.dedup();
    assert_eq!(paths.len(), n, "VSS paths must be unique");
    for (path, signal) in [
        ("Vehicle.Speed", "VehicleSpeedMsg.VehicleSpeed"),
        (
            "Vehicle.Powertrain.CombustionEngine.Speed",
            "EngineMsg.EngineRPM",
        ),
        (
            "Vehicle.Powertrain.FuelSystem.AbsoluteLevel",
            "EngineMsg.FuelLevel",
        ),
        (
            "Vehicle.Chassis.Axle.Row2.Wheel.Right.Speed",
            "WheelSpeedMsg.WheelSpeedRR",
        ),
        ("Vehicle.Body.Lights.Brake.IsActive", "AccMsg.BrakeLights"),
        (
            "Vehicle.Private.AutoPlug.ActiveDifferential.TorqueSplit",
            "DiffMsg.TorqueSplit",
        ),
    ] {
        let by_path = state.signal(path).unwrap();
        assert_eq!(
            format!("{}.{}", by_path.message.name, by_path.spec.name),
            signal
        );
    }
}

#[test]
fn an_invalid_value_is_counted_and_the_last_good_one_kept() {
    let mut state = CarState::new();
    state.update(&at(
        0,
        SteeringMsg {
            steering_angle: 45.0,
        }
        .frame(),
    ));
    // Raw 5 is below the encoding's 10..90.
    let update = state.update(&raw(10, 0x005, &[5]));
    assert!(matches!(update, Update::Message { valid: false, .. }));
    let s = state.signal("SteeringMsg.SteeringAngle").unwrap();
    assert_eq!(s.value, 43.875, "45 deg quantised to 3.375 deg steps, kept");
    assert_eq!((s.invalid, s.updated_us), (1, Some(0)));
    let stats = state.stats_of(SteeringMsg::ID).unwrap();
    assert_eq!((stats.count, stats.invalid), (2, 1));
}

#[test]
fn one_invalid_signal_does_not_hold_back_the_valid_ones() {
    let mut state = CarState::new();
    let good = EngineMsg {
        engine_rpm: 3000.0,
        fuel_level: 40.0,
        engine_mode: EngineMode::Economy,
        fuel_used: 0.0,
    }
    .frame();
    state.update(&at(0, good));
    let mut data = [0u8; 5];
    data.copy_from_slice(good.data());
    data[0] = 100; // a new RPM
    data[2] = 7; // engine mode 7 is not in the value table
    state.update(&raw(20, u32::from(EngineMsg::ID), &data));
    let rpm = state.signal("EngineMsg.EngineRPM").unwrap();
    assert_eq!(rpm.updated_us, Some(20_000));
    assert!((rpm.value - 3529.41).abs() < 0.01, "{}", rpm.value);
    let mode = state.signal("EngineMsg.EngineMode").unwrap();
    assert_eq!((mode.updated_us, mode.invalid), (Some(0), 1));
    assert_eq!(mode.label(), Some("Economy"));
}

#[test]
fn wrong_lengths_unknown_ids_and_diagnostic_frames_are_counted_not_fatal() {
    let mut state = CarState::new();
    assert_eq!(
        state.update(&raw(0, 0x003, &[1, 2])),
        Update::WrongLength,
        "VehicleSpeedMsg has 1 byte"
    );
    assert_eq!(state.update(&raw(1, 0x123, &[1])), Update::Other);
    assert_eq!(state.update(&raw(2, 0x123, &[])), Update::Other);
    assert_eq!(
        state.update(&raw(3, 0x70D, &[2, 0x3E, 0])),
        Update::Diagnostic
    );
    assert_eq!(state.update(&raw(4, 0x7E8, &[0; 8])), Update::Diagnostic);
    let c = state.counters();
    assert_eq!((c.frames, c.unknown_frames, c.diagnostic_frames), (5, 2, 2));
    assert_eq!(c.unknown_ids.get(&0x123), Some(&2));
    assert_eq!(state.stats_of(VehicleSpeedMsg::ID).unwrap().wrong_length, 1);
    assert_eq!(state.signal("Vehicle.Speed").unwrap().updated_us, None);
}

/// A CAN FD frame carrying a catalogue identifier is still not the catalogue's message: a
/// classic bus cannot carry it. Counted apart, no signal touched.
#[test]
fn can_fd_frames_are_counted_and_left_aside() {
    let mut state = CarState::new();
    let fd = LogFrame::new_fd(
        0,
        0,
        u32::from(VehicleSpeedMsg::ID),
        false,
        &[100],
        Default::default(),
    )
    .unwrap();
    assert_eq!(state.update(&fd), Update::Other);
    assert!(matches!(
        state.update(&speed(1, 50.0)),
        Update::Message { valid: true, .. }
    ));
    let c = state.counters();
    assert_eq!((c.frames, c.fd_frames, c.unknown_frames), (2, 1, 0));
    assert_eq!(state.stats_of(VehicleSpeedMsg::ID).unwrap().count, 1);
}

#[test]
fn unknown_identifiers_are_listed_up_to_a_bound() {
    let mut state = CarState::new();
    for id in 0x100..0x300 {
        state.update(&raw(0, id, &[]));
    }
    let c = state.counters();
    assert_eq!(c.unknown_frames, 0x200);
    assert_eq!(c.unknown_ids.len(), MAX_LISTED_UNKNOWN_IDS);
}

#[test]
fn time_going_backwards_is_counted_and_the_clock_does_not_go_back() {
    let mut state = CarState::new();
    state.update(&speed(100, 50.0));
    state.update(&speed(90, 51.0));
    state.update(&speed(110, 52.0));
    assert_eq!(state.counters().time_backwards, 1);
    assert_eq!(state.now_us(), 110_000);
    assert_eq!(state.signal("Vehicle.Speed").unwrap().value, 52.0);
}

#[test]
fn period_and_jitter_are_measured_per_message() {
    let mut state = CarState::new();
    for (i, t) in [0u64, 10, 20, 30, 40].iter().enumerate() {
        state.update(&speed(*t, i as f32));
    }
    let s = state.stats_of(VehicleSpeedMsg::ID).unwrap();
    assert_eq!(s.period_ms(), Some(10.0));
    assert_eq!(s.jitter_ms(), Some(0.0));
    for t in [50u64, 62, 70, 84, 90] {
        state.update(&speed(t, 1.0));
    }
    let s = state.stats_of(VehicleSpeedMsg::ID).unwrap();
    assert_eq!(s.period_ms(), Some(10.0));
    assert!(s.jitter_ms().unwrap() > 1.0);
    assert_eq!(
        (s.min_interval_us, s.max_interval_us),
        (Some(6_000), Some(14_000))
    );
}

#[test]
fn the_recent_jitter_forgets_a_gap_the_whole_runs_keeps() {
    let mut state = CarState::new();
    let mut t = 0;
    for _ in 0..100 {
        t += 10;
        state.update(&speed(t, 1.0));
    }
    // Two seconds of silence (the ECU being flashed), then regular again.
    t += 2000;
    state.update(&speed(t, 1.0));
    let s = state.stats_of(VehicleSpeedMsg::ID).unwrap();
    assert!(s.recent_jitter_ms().unwrap() > 100.0);
    for _ in 0..(RECENT_INTERVALS + 1) {
        t += 10;
        state.update(&speed(t, 1.0));
    }
    let s = state.stats_of(VehicleSpeedMsg::ID).unwrap();
    assert_eq!(s.recent_period_ms(), Some(10.0));
    assert_eq!(s.recent_jitter_ms(), Some(0.0));
    assert!(s.jitter_ms().unwrap() > 100.0, "the run's own keeps it");
}

#[derive(Default)]
struct Seen {
    updates: Vec<Update>,
    last_cruise: Option<CruiseMode>,
}

impl Observer for Seen {
    fn on_frame(&mut self, _: &LogFrame, update: Update, state: &CarState) {
        self.updates.push(update);
        self.last_cruise = Some(state.get::<CruiseModeMsg>().cruise_mode);
    }
}

#[test]
fn observers_see_each_frame_after_the_state_took_it() {
    let frames = vec![
        speed(0, 10.0),
        at(
            5,
            CruiseModeMsg {
                cruise_mode: CruiseMode::On,
            }
            .frame(),
        ),
        raw(6, 0x555, &[]),
    ];
    let mut pipeline = Pipeline::new(Strictness::Strict);
    let mut seen = Seen::default();
    pipeline
        .run(
            &mut VecSource::new("test", frames),
            &mut [&mut seen],
            &mut || false,
        )
        .unwrap();
    assert_eq!(seen.updates.len(), 3);
    assert_eq!(seen.last_cruise, Some(CruiseMode::On));
    assert_eq!(seen.updates[2], Update::Other);
}

fn log_file(text: &str) -> tempfile::TempPath {
    let mut file = tempfile::Builder::new().suffix(".log").tempfile().unwrap();
    std::io::Write::write_all(&mut file, text.as_bytes()).unwrap();
    file.into_temp_path()
}

const WITH_A_BAD_LINE: &str =
    "(0.000000) can0 003#50\n(0.010000) can0 003#5G\n(0.020000) can0 003#52 R\n";

#[test]
fn a_malformed_line_stops_a_strict_run_with_its_line_number() {
    let path = log_file(WITH_A_BAD_LINE);
    let mut source = crate::LogSource::open(&path).unwrap();
    let mut pipeline = Pipeline::new(Strictness::Strict);
    let error = pipeline
        .run(&mut source, &mut [], &mut || false)
        .unwrap_err()
        .to_string();
    assert!(error.contains("line 2"), "{error}");
    assert!(error.contains("--lenient"), "{error}");
    assert_eq!(pipeline.state().counters().frames, 1);
}

#[test]
fn a_lenient_run_skips_and_counts_malformed_lines() {
    let path = log_file(WITH_A_BAD_LINE);
    let mut source = crate::LogSource::open(&path).unwrap();
    let mut pipeline = Pipeline::new(Strictness::Lenient);
    pipeline.run(&mut source, &mut [], &mut || false).unwrap();
    assert_eq!(pipeline.malformed(), 1);
    assert_eq!(pipeline.first_malformed().unwrap().line, 2);
    assert_eq!(pipeline.state().counters().frames, 2);
    assert_eq!(
        pipeline.state().signal("Vehicle.Speed").unwrap().value,
        82.0
    );
}

/// A BLF file of speed frames 10 ms apart, in one stored container, its last `cut`
/// bytes missing (a logger that lost power).
fn cut_blf(frames: u64, cut: usize) -> tempfile::TempPath {
    let mut file = b"LOGG".to_vec();
    file.extend_from_slice(&144u32.to_le_bytes());
    file.resize(144, 0);
    let mut objects = Vec::new();
    for i in 0..frames {
        objects.extend_from_slice(b"LOBJ");
        objects.extend_from_slice(&32u16.to_le_bytes());
        objects.extend_from_slice(&1u16.to_le_bytes());
        objects.extend_from_slice(&48u32.to_le_bytes());
        objects.extend_from_slice(&1u32.to_le_bytes());
        objects.extend_from_slice(&2u32.to_le_bytes());
        objects.extend_from_slice(&[0; 4]);
        objects.extend_from_slice(&(i * 10_000_000).to_le_bytes());
        objects.extend_from_slice(&[1, 0, 0, 1, 3, 0, 0, 0, 80, 0, 0, 0, 0, 0, 0, 0]);
    }
    let size = 32 + objects.len() as u32;
    file.extend_from_slice(b"LOBJ");
    file.extend_from_slice(&[16, 0, 1, 0]);
    file.extend_from_slice(&size.to_le_bytes());
    file.extend_from_slice(&10u32.to_le_bytes());
    file.extend_from_slice(&[0; 8]);
    file.extend_from_slice(&(objects.len() as u32).to_le_bytes());
    file.extend_from_slice(&[0; 4]);
    file.extend_from_slice(&objects);
    file.truncate(file.len() - cut);
    let mut out = tempfile::Builder::new().suffix(".blf").tempfile().unwrap();
    std::io::Write::write_all(&mut out, &file).unwrap();
    out.into_temp_path()
}

/// The pipeline after running the log at `path` through it, with no observers.
fn run_log(path: &std::path::Path, strictness: Strictness) -> Pipeline {
    let mut pipeline = Pipeline::new(strictness);
    pipeline
        .run(
            &mut crate::LogSource::open(path).unwrap(),
            &mut [],
            &mut || false,
        )
        .unwrap();
    pipeline
}

#[test]
fn a_log_cut_short_ends_the_run_with_what_precedes_the_damage() {
    for strictness in [Strictness::Strict, Strictness::Lenient] {
        // 100 objects of 48 bytes, 100 bytes missing: 97 whole ones.
        let pipeline = run_log(&cut_blf(100, 100), strictness);
        assert_eq!(pipeline.state().counters().frames, 97);
        assert_eq!(pipeline.state().now_us(), 960_000);
        let e = pipeline.incomplete().unwrap();
        assert_eq!(e.line, 98);
        assert!(e.message.contains("truncated file?"), "{e}");
        assert_eq!(pipeline.malformed(), 0);
    }
    let whole = run_log(&cut_blf(100, 0), Strictness::Strict);
    assert!(whole.incomplete().is_none());
    assert_eq!(whole.state().counters().frames, 100);
}

#[test]
fn frames_the_logger_reported_dropped_are_counted() {
    let path = log_file(
        "(0.000000) can0 003#50\nDROPCOUNT: dropped 7 CAN frames on 'can0' socket (total drops 7)\n(0.010000) can0 003#51\nDROPCOUNT: dropped 1 CAN frame on 'can0' socket (total drops 8)\n",
    );
    let pipeline = run_log(&path, Strictness::Strict);
    assert_eq!(pipeline.dropped_by_logger(), 8);
    assert_eq!(pipeline.state().counters().frames, 2);
    assert_eq!(pipeline.malformed(), 0);
}

#[test]
fn a_missing_log_is_a_clear_error() {
    let error = crate::LogSource::open(std::path::Path::new("/nonexistent/drive.log"))
        .err()
        .unwrap()
        .to_string();
    assert!(error.contains("/nonexistent/drive.log"), "{error}");
}

#[test]
fn a_full_disk_stops_the_recording_and_not_the_pipeline() {
    use crate::sinks::RecordingSink;
    use autoplug_logs::{Recorder, RotatePolicy};
    let dir = tempfile::tempdir().unwrap();
    // Writes to /dev/full fail with ENOSPC, as on a full disk.
    let recorder = Recorder::start_with(
        dir.path(),
        "full",
        RotatePolicy::default(),
        Box::new(|_| std::fs::OpenOptions::new().write(true).open("/dev/full")),
    )
    .unwrap();
    let mut sink = RecordingSink::new(recorder);
    // More than the recorder buffers before it writes.
    let frames: Vec<LogFrame> = (0..20_000).map(|i| speed(i, 50.0)).collect();
    let mut pipeline = Pipeline::new(Strictness::Strict);
    pipeline
        .run(
            &mut VecSource::new("test", frames),
            &mut [&mut sink],
            &mut || false,
        )
        .unwrap();
    assert!(!sink.is_recording());
    let failure = sink.failure().expect("the recording stopped");
    assert!(failure.is_disk_full(), "{failure}");
    assert!(failure.to_string().contains("disk full"), "{failure}");
    assert_eq!(pipeline.state().counters().frames, 20_000);
}

#[test]
fn a_long_log_arrives_whole_and_in_order_through_the_reading_thread() {
    use std::io::Write;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("long.log");
    let mut file = std::io::BufWriter::new(std::fs::File::create(&path).unwrap());
    // 30 batches' worth, a malformed line deep inside.
    for i in 0..30_000u64 {
        if i == 20_000 {
            writeln!(file, "(20.000000) can0 003#zz").unwrap();
        }
        writeln!(
            file,
            "({}.{:06}) can0 003#{:02X}",
            i / 1000,
            (i % 1000) * 1000,
            i % 200
        )
        .unwrap();
    }
    drop(file);

    let mut strict = Pipeline::new(Strictness::Strict);
    let error = strict
        .run(
            &mut crate::LogSource::open(&path).unwrap(),
            &mut [],
            &mut || false,
        )
        .unwrap_err();
    assert!(error.to_string().contains("line 20001"), "{error}");
    assert_eq!(strict.state().counters().frames, 20_000);

    let mut lenient = Pipeline::new(Strictness::Lenient);
    lenient
        .run(
            &mut crate::LogSource::open(&path).unwrap(),
            &mut [],
            &mut || false,
        )
        .unwrap();
    assert_eq!(lenient.state().counters().frames, 30_000);
    assert_eq!(lenient.malformed(), 1);
    assert_eq!(lenient.state().counters().time_backwards, 0, "in order");

    // Stopping early and dropping the source ends its thread instead of blocking it.
    let mut taken = 0;
    let mut early = Pipeline::new(Strictness::Lenient);
    early
        .run(
            &mut crate::LogSource::open(&path).unwrap(),
            &mut [],
            &mut || {
                taken += 1;
                taken > 10
            },
        )
        .unwrap();
    assert_eq!(early.state().counters().frames, 10);
}
