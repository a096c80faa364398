//! A replayed recording shows its world: the poses of the world file beside the log are
//! handed over as the log's clock passes them, and a seek starts the world over.

use std::cell::RefCell;
use std::rc::Rc;
use std::time::Duration;

use autoplug_gateway::{FrameSource, Poll};
use autoplug_live::replay::{ControlledReplay, ReplayDesk, WorldEvent};
use autoplug_virtual_car::world::{world_file_for, WorldFileWriter, WorldPose};

#[test]
fn a_replay_hands_over_its_world_as_its_clock_passes_the_poses() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("drive.log");
    // Two seconds of a frame every 10 ms, and a pose every 50 ms.
    let mut text = String::new();
    for i in 0..=200u64 {
        text.push_str(&format!(
            "({}.{:06}) can0 1A0#0000000000000000\n",
            i / 100,
            (i % 100) * 10_000
        ));
    }
    std::fs::write(&log, text).unwrap();
    let mut writer = WorldFileWriter::create(&world_file_for(&log)).unwrap();
    writer.describe(r#"{"road":null,"car":{}}"#).unwrap();
    for i in 0..=40 {
        let pose = WorldPose {
            t_s: i as f64 * 0.05,
            x_m: i as f64,
            ..WorldPose::default()
        };
        writer.pose(&pose.to_json()).unwrap();
    }
    writer.flush().unwrap();
    drop(writer);

    let desk = Rc::new(RefCell::new(ReplayDesk::new(2.0)));
    desk.borrow_mut().speed = 100.0;
    let mut replay = ControlledReplay::open(&log, 0, desk.clone()).unwrap();
    let events = Rc::new(RefCell::new(Vec::new()));
    let sink = events.clone();
    let damage = replay
        .with_world(Box::new(move |event| sink.borrow_mut().push(event)))
        .unwrap();
    assert_eq!(damage, None);
    assert!(matches!(events.borrow()[0], WorldEvent::Describe(_)));
    let mut frames = 0;
    for _ in 0..10_000 {
        match replay.poll(Duration::from_millis(5)).unwrap() {
            Poll::Frame(frame) => {
                frames += 1;
                // No pose from the future: every pose handed over is at or before the clock.
                let clock = replay.clock_us().unwrap() as f64 * 1e-6;
                for event in events.borrow().iter() {
                    if let WorldEvent::Pose(json) = event {
                        let pose: serde_json::Value = serde_json::from_str(json).unwrap();
                        assert!(
                            pose[0].as_f64().unwrap() <= clock + 1e-9,
                            "{json} at {clock}"
                        );
                    }
                }
                let _ = frame;
            }
            _ if desk.borrow().at_end => break,
            _ => {}
        }
    }
    assert_eq!(frames, 201);
    let poses = |events: &[WorldEvent]| {
        events
            .iter()
            .filter(|e| matches!(e, WorldEvent::Pose(_)))
            .count()
    };
    assert_eq!(poses(&events.borrow()), 41, "every pose once");
    // A seek: the world again, then the poses from there on.
    events.borrow_mut().clear();
    desk.borrow_mut().seek(1.5);
    desk.borrow_mut().playing = true;
    for _ in 0..10_000 {
        if let Poll::End = replay.poll(Duration::from_millis(5)).unwrap() {
            break;
        }
        if desk.borrow().at_end {
            break;
        }
    }
    let events = events.borrow();
    assert!(matches!(events[0], WorldEvent::Describe(_)), "{events:?}");
    // Played from 0.5 s (the second before the target is primed): 0.50 .. 2.00 s.
    assert_eq!(poses(&events), 31, "{events:?}");
}

#[test]
fn a_replay_without_a_world_file_says_so() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("bus.log");
    std::fs::write(&log, "(0.000000) can0 1A0#00\n").unwrap();
    let desk = Rc::new(RefCell::new(ReplayDesk::new(0.0)));
    let mut replay = ControlledReplay::open(&log, 0, desk).unwrap();
    let why = replay.with_world(Box::new(|_| {})).unwrap_err();
    assert!(why.contains("no world file"), "{why}");
}
