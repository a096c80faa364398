//! The diagnostics on every shipped scenario, run on the virtual car and judged from its
//! bus alone: the faulty software is flagged with its number, correct software never is,
//! a silenced ECU is "no data" for exactly that ECU, and every one of these buses is
//! recognised as an AutoPlug car.

use std::path::{Path, PathBuf};

use autoplug_can::Node;
use autoplug_diagnostics::{Diagnostics, EcuDiagnosis, Recognition, Verdict};
use autoplug_gateway::{Pipeline, Strictness, VecSource};
use autoplug_logs::LogFrame;
use autoplug_virtual_car::report;
use autoplug_virtual_car::scenario::Scenario;

fn scenarios_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenarios")
}

fn diagnose_and_recognise(scenario: &Scenario) -> (Vec<EcuDiagnosis>, Recognition) {
    let record = report::run(scenario);
    let frames = record
        .log
        .iter()
        .map(|f| LogFrame::from_can(f.t_us, 0, &f.frame))
        .collect();
    let mut pipeline = Pipeline::new(Strictness::Strict);
    let mut diagnostics = Diagnostics::new();
    pipeline
        .run(
            &mut VecSource::new(&scenario.name, frames),
            &mut [&mut diagnostics],
            &mut || false,
        )
        .unwrap();
    (
        diagnostics.report(pipeline.state()),
        diagnostics.recognition(),
    )
}

fn verdict(report: &[EcuDiagnosis], node: Node) -> &EcuDiagnosis {
    report.iter().find(|d| d.ecu == node).unwrap()
}

#[test]
fn every_shipped_scenario_gets_the_right_verdicts() {
    let mut paths: Vec<PathBuf> = std::fs::read_dir(scenarios_dir())
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    paths.sort();
    assert!(paths.len() >= 17, "{paths:?}");
    let mut judged = 0;
    for path in paths {
        let scenario = Scenario::load(&path).unwrap();
        let (report, recognition) = diagnose_and_recognise(&scenario);
        assert!(
            recognition.autoplug && recognition.foreign_frames == 0,
            "{}: {recognition:?}",
            scenario.name
        );
        // Every message of the catalogue on the bus, and a verdict for every ECU.
        assert_eq!(
            recognition.messages_seen, recognition.catalogue_messages,
            "{}",
            scenario.name
        );
        assert_eq!(
            report.len(),
            autoplug_diagnostics::ecus().count(),
            "{}",
            scenario.name
        );
        let faulty: &[Node] = match scenario.name.as_str() {
            "cruise-faulty" => &[Node::Cruise],
            "abs-faulty-split-mu" => &[Node::ABS],
            _ => &[],
        };
        for d in &report {
            // A scenario that never brakes hard judges no ABS: "not exercised", never a
            // green OK it did not earn, and never worse.
            let expected = if faulty.contains(&d.ecu) {
                Verdict::Faulty
            } else if d.verdict == Verdict::NotExercised {
                let headline = d.headline().unwrap();
                assert!(headline.value.is_none(), "{}: {headline:?}", scenario.name);
                assert!(
                    headline.evidence.starts_with("not exercised"),
                    "{}: {headline:?}",
                    scenario.name
                );
                Verdict::NotExercised
            } else {
                Verdict::Ok
            };
            assert_eq!(
                d.verdict,
                expected,
                "{}: {} judged {} ({:?})",
                scenario.name,
                d.ecu.name(),
                d.verdict,
                d.headline()
            );
        }
        for &node in faulty {
            let headline = verdict(&report, node).headline().unwrap();
            let value = headline.value.expect("a number");
            assert!(value > headline.faulty_above, "{headline:?}");
            assert!(headline.window.is_some(), "{headline:?}");
        }
        judged += 1;
    }
    assert!(judged >= 17);
}

#[test]
fn a_silenced_ecu_is_no_data_for_exactly_that_ecu() {
    let base = Scenario::load(&scenarios_dir().join("socketcand-smoke.toml")).unwrap();
    for node in autoplug_diagnostics::ecus() {
        let mut scenario = base.clone();
        let text = format!(
            "name = \"silenced\"\nduration_s = 1.0\n[[at]]\nt_s = 0.0\nfault = {{ silence = \"{}\" }}\n",
            node.name()
        );
        let with_fault = Scenario::parse(&text, "silenced").unwrap();
        scenario.at.insert(0, with_fault.at[0].clone());
        let (report, recognition) = diagnose_and_recognise(&scenario);
        assert!(
            recognition.autoplug,
            "{} silenced: {recognition:?}",
            node.name()
        );
        for d in &report {
            if d.ecu == node {
                assert_eq!(d.verdict, Verdict::NoData, "{}: {:?}", node.name(), d);
            } else {
                assert_ne!(
                    d.verdict,
                    Verdict::NoData,
                    "{} silenced, {} judged no data",
                    node.name(),
                    d.ecu.name()
                );
                assert!(
                    !matches!(d.verdict, Verdict::Faulty),
                    "{} silenced, {} judged faulty: {:?}",
                    node.name(),
                    d.ecu.name(),
                    d.headline()
                );
            }
        }
    }
}
