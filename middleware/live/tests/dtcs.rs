//! Trouble codes read over UDS (0x19 02 FF) from the virtual car's ECUs, and the same codes
//! heard by the gateway's passive monitor on the bus: a console that falls silent leaves
//! "lost communication with the console" in the engine and the transmission.

use autoplug_can::Node;
use autoplug_diagnostics::{describe_dtc, DtcMonitor};
use autoplug_ecu::lost_communication;
use autoplug_gateway::{Pipeline, Strictness, VecSource};
use autoplug_live::on_car::OnCar;
use autoplug_logs::LogFrame;
use autoplug_tester::names::ECUS;
use autoplug_tester::{dtc_table, ClearDtcsJob, DtcJob, TesterConfig};
use autoplug_virtual_car::car::VirtualCar;
use autoplug_virtual_car::scenario::Scenario;

#[test]
fn a_silent_console_is_reported_by_its_receivers_over_uds_and_heard_by_the_gateway() {
    let scenario = Scenario::parse(
        "name = \"console-silent\"\nduration_s = 10.0\n[[at]]\nt_s = 1.0\nfault = { silence = \"Console\" }\n",
        "test",
    )
    .unwrap();
    let mut car = VirtualCar::new(&scenario);
    while car.time_us() < 2_000_000 {
        car.tick();
    }
    let mut job = OnCar::new(DtcJob::new(&ECUS, TesterConfig::DEFAULT), &mut car);
    let reports = job
        .run(&mut car, 5_000_000)
        .expect("the job ends within 5 s")
        .unwrap();
    println!("{}", dtc_table(&reports));
    assert_eq!(reports.len(), Node::ECUS.len());
    let lost = lost_communication(Node::Console);
    let reporting: Vec<Node> = reports
        .iter()
        .filter(|r| {
            r.entries
                .as_ref()
                .is_ok_and(|e| e.iter().any(|e| e.dtc == lost))
        })
        .map(|r| r.ecu)
        .collect();
    assert_eq!(reporting, [Node::Engine, Node::Transmission]);
    // The silenced console itself cannot answer.
    let console = reports.iter().find(|r| r.ecu == Node::Console).unwrap();
    assert!(console.entries.is_err(), "{console:?}");
    assert!(dtc_table(&reports).contains("lost communication with the Console ECU"));

    // The gateway, listening to the same bus, heard the same reports.
    let frames: Vec<LogFrame> = car
        .log()
        .iter()
        .map(|f| LogFrame::from_can(f.t_us, 0, &f.frame))
        .collect();
    let mut pipeline = Pipeline::new(Strictness::Strict);
    let mut monitor = DtcMonitor::new();
    pipeline
        .run(
            &mut VecSource::new("car", frames),
            &mut [&mut monitor],
            &mut || false,
        )
        .unwrap();
    let heard: Vec<_> = monitor
        .latest()
        .iter()
        .map(|r| (r.ecu, r.entries.clone()))
        .collect();
    let asked: Vec<_> = reports
        .iter()
        .filter_map(|r| Some((r.ecu, r.entries.clone().ok()?)))
        .collect();
    assert_eq!(heard, asked);
    assert!(describe_dtc(lost).contains("Console"));
}

#[test]
fn clearing_removes_the_codes_of_a_fault_that_has_gone_and_each_ecu_answers() {
    let scenario = Scenario::parse(
        "name = \"console-back\"\nduration_s = 20.0\n[[at]]\nt_s = 1.0\nfault = { silence = \"Console\" }\n[[at]]\nt_s = 2.0\nfault = { restore = \"Console\" }\n",
        "test",
    )
    .unwrap();
    let mut car = VirtualCar::new(&scenario);
    while car.time_us() < 3_000_000 {
        car.tick();
    }
    let lost = lost_communication(Node::Console);
    let read = |car: &mut VirtualCar| {
        let mut job = OnCar::new(DtcJob::new(&ECUS, TesterConfig::DEFAULT), car);
        job.run(car, 5_000_000).expect("read within 5 s").unwrap()
    };
    let with_lost = |reports: &[autoplug_tester::EcuDtcReport]| -> Vec<Node> {
        reports
            .iter()
            .filter(|r| {
                r.entries
                    .as_ref()
                    .is_ok_and(|e| e.iter().any(|e| e.dtc == lost))
            })
            .map(|r| r.ecu)
            .collect()
    };
    // The console is back, but the codes stay stored until a tester clears them.
    assert_eq!(
        with_lost(&read(&mut car)),
        [Node::Engine, Node::Transmission]
    );

    let mut clear = OnCar::new(ClearDtcsJob::new(&ECUS, TesterConfig::DEFAULT), &mut car);
    let cleared = clear
        .run(&mut car, 5_000_000)
        .expect("the clear ends within 5 s")
        .unwrap();
    assert_eq!(cleared.len(), Node::ECUS.len());
    assert!(
        cleared.iter().all(|r| r.outcome.is_ok()),
        "every ECU confirms the clear: {cleared:?}"
    );
    let after = read(&mut car);
    assert!(with_lost(&after).is_empty(), "{}", dtc_table(&after));
    assert!(after.iter().all(|r| r.entries.is_ok()));
}
