//! The gateway live on the virtual car's bus, recording as it goes, and the same pipeline
//! on the recording afterwards: the recording holds exactly the frames of the bus, and the
//! verdicts are identical.

use std::path::Path;

use autoplug_diagnostics::{Diagnostics, Verdict};
use autoplug_gateway::{LogSource, Pipeline, RecordingSink, Strictness};
use autoplug_live::sources::VirtualCarSource;
use autoplug_logs::{Recorder, RotatePolicy};
use autoplug_virtual_car::car::VirtualCar;
use autoplug_virtual_car::report;
use autoplug_virtual_car::scenario::Scenario;

fn scenario(name: &str) -> Scenario {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    Scenario::load(&root.join(format!("scenarios/{name}.toml"))).unwrap()
}

fn live_then_replay(name: &str) -> Verdict {
    let scenario = scenario(name);
    let dir = tempfile::tempdir().unwrap();
    // Live: the car's bus through the pipeline, diagnostics and the recorder.
    let mut source = VirtualCarSource::new(VirtualCar::new(&scenario));
    let mut live = Pipeline::new(Strictness::Strict);
    let mut diagnostics = Diagnostics::new();
    let recorder = Recorder::start(dir.path(), "live", RotatePolicy::default()).unwrap();
    let mut recording = RecordingSink::new(recorder);
    live.run(
        &mut source,
        &mut [&mut diagnostics, &mut recording],
        &mut || false,
    )
    .unwrap();
    let live_verdicts = diagnostics.report(live.state());
    let summary = recording.stop().unwrap();
    assert_eq!(summary.files.len(), 1);

    // The recording holds exactly the bus: the car's own bus log of the same run.
    let reference = report::run(&scenario).log;
    let recorded: Vec<_> = autoplug_logs::open(&summary.files[0])
        .unwrap()
        .map(|f| f.unwrap())
        .collect();
    assert_eq!(recorded.len(), reference.len(), "{name}");
    for (r, f) in recorded.iter().zip(&reference) {
        assert_eq!(
            (r.t_us, r.as_can_frame()),
            (f.t_us, Some(f.frame)),
            "{name}"
        );
    }

    // Replay: the same pipeline on the file.
    let mut replay = Pipeline::new(Strictness::Strict);
    let mut replay_diagnostics = Diagnostics::new();
    replay
        .run(
            &mut LogSource::open(&summary.files[0]).unwrap(),
            &mut [&mut replay_diagnostics],
            &mut || false,
        )
        .unwrap();
    let replay_verdicts = replay_diagnostics.report(replay.state());
    assert_eq!(live_verdicts, replay_verdicts, "{name}");
    live_verdicts.iter().map(|d| d.verdict).max().unwrap()
}

#[test]
fn live_and_replayed_verdicts_are_identical_on_the_drive_cycle() {
    assert_eq!(live_then_replay("drive-cycle"), Verdict::Ok);
}

#[test]
fn live_and_replayed_verdicts_are_identical_with_the_faulty_cruise() {
    assert_eq!(live_then_replay("cruise-faulty"), Verdict::Faulty);
}
