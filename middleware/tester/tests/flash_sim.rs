//! The tester against the nine ECUs' real diagnostic stacks (`autoplug_uds::DiagNode`) on
//! a simulated bus with simulated time: the flash job, its failures, identification.

use std::cell::RefCell;
use std::rc::Rc;

use autoplug_can::Node;
use autoplug_image::{BootState, ImageSlot};
use autoplug_tester::names::ECUS;
use autoplug_tester::testing::{image_for, image_for_slot, SimBus, SIGNING_SEED};
use autoplug_tester::DEV_SECURITY_SECRET;
use autoplug_tester::{
    FlashConfig, FlashFailure, FlashJob, IdentJob, Phase, Progress, Response, Tester, TesterConfig,
    UdsError,
};
use autoplug_uds::Session;

const MINUTE_US: u64 = 60_000_000;

fn flash_job(ecu: Node, image: Vec<u8>) -> FlashJob {
    FlashJob::new(FlashConfig::new(ecu, image, DEV_SECURITY_SECRET)).expect("an ECU")
}

/// Every ECU is back to normal: default session, communication and DTC setting on.
fn assert_car_restored(bus: &SimBus) {
    for ecu in &bus.ecus {
        let diag = ecu.diag.as_ref().expect("the ECU runs");
        assert_eq!(
            diag.server().session(),
            Session::Default,
            "{:?}",
            ecu.node()
        );
        assert!(diag.server().normal_tx_enabled(), "{:?}", ecu.node());
        assert!(diag.server().dtc_setting_on(), "{:?}", ecu.node());
    }
}

#[test]
fn a_complete_flash_lands_byte_for_byte_and_is_marked() {
    let mut bus = SimBus::new();
    let image = image_for(Node::Cruise, 64 * 1024 - 576, SIGNING_SEED);
    assert_eq!(image.len(), 64 * 1024);
    let mut job = flash_job(Node::Cruise, image.clone());
    let progress: Rc<RefCell<Vec<Progress>>> = Rc::default();
    let seen = Rc::clone(&progress);
    job.on_progress(move |p| seen.borrow_mut().push(p));

    let report = bus.run(&mut job, MINUTE_US).expect("the flash succeeds");
    println!("{report}");
    println!(
        "simulated: {} frames on the bus, {:.3} s",
        bus.frames,
        bus.now.as_micros() as f64 / 1e6
    );

    // The image is in the DFU slot (slot B: the ECU runs A) byte for byte, verified and
    // marked, after one sector erase.
    let cruise = bus.ecu(Node::Cruise);
    assert_eq!(&cruise.backend.dfu[..image.len()], &image[..]);
    assert_eq!(cruise.backend.erases, 1);
    assert!(cruise.backend.dfu[image.len()..].iter().all(|&b| b == 0xFF));
    assert!(cruise.backend.marked);
    assert_eq!(report.slot, Some(ImageSlot::B));
    assert_eq!(cruise.resets, 1);
    // No other ECU was touched, but all of them kept quiet and recorded no DTC meanwhile.
    for ecu in &bus.ecus {
        assert!(ecu.saw_comm_off, "{:?} kept sending", ecu.node());
        assert!(ecu.saw_dtc_off, "{:?} kept recording DTCs", ecu.node());
        if ecu.node() != Node::Cruise {
            assert_eq!(ecu.resets, 0);
            assert!(!ecu.backend.marked);
            assert_eq!(ecu.backend.erases, 0);
        }
    }
    assert_car_restored(&bus);

    // The report: every phase, in order, with its time, and the transfer's throughput.
    let phases: Vec<Phase> = report.phases.iter().map(|p| p.phase).collect();
    assert_eq!(phases, Phase::ALL);
    assert!(report.phases.iter().all(|p| p.duration_us > 0));
    assert_eq!(report.image_len, 65_536);
    assert_eq!(report.block_len, 4093);
    assert_eq!(report.blocks, 17);
    assert!(report.notes.is_empty(), "{:?}", report.notes);
    // The one 128 KiB sector the image needs, about a second, announced with a 0x78.
    let erase = report.phases[2];
    assert!(
        (1_000_000..1_300_000).contains(&erase.duration_us),
        "{erase:?}"
    );
    assert_eq!(erase.response_pending, 1);
    // Communication comes back on first (the functional request's 100 ms window for the
    // answers); the ECU is back 20 ms after its reset (no copy: the bootloader records the
    // trial and starts slot B); the first TesterPresent probe goes 100 ms after the
    // reset's response.
    let reset = report.duration_us(Phase::ResetAndWait).unwrap();
    assert!((200_000..300_000).contains(&reset), "{reset}");
    // 7 bytes per 240 µs frame is 29 KB/s on the wire; block overhead takes a little.
    let throughput = report.transfer_throughput().expect("a throughput");
    assert!((24_000.0..29_200.0).contains(&throughput), "{throughput}");
    assert!(report.to_string().contains("bytes/s"));

    // Progress: phases in order, bytes never going back, ending at the total.
    let progress = progress.borrow();
    assert!(progress
        .windows(2)
        .all(|w| w[0].transferred <= w[1].transferred));
    assert!(progress.len() > 17, "block-level progress at least");
    assert_eq!(progress.last().unwrap().transferred, 65_536);
    assert_eq!(progress.last().unwrap().total, 65_536);
    let mut phase_order: Vec<Phase> = progress.iter().map(|p| p.phase).collect();
    phase_order.dedup();
    assert_eq!(phase_order, Phase::ALL);
}

#[test]
fn an_image_the_bootloader_would_not_start_is_refused_before_anything_goes_to_the_car() {
    let mut bus = SimBus::new();
    // Signed and for the right ECU, but its vector table is erased flash.
    let mut builder = autoplug_image::ImageBuilder::new(
        Node::Cruise.diag_node_number().unwrap(),
        autoplug_image::Version::new(1, 3, 0),
        vec![0xFF; 4000],
    );
    builder.load_address = ImageSlot::B.vector_table();
    let image = builder
        .sign(&autoplug_image::SigningKey::from_seed(SIGNING_SEED))
        .unwrap();
    let mut job = flash_job(Node::Cruise, image);
    let error = bus.run(&mut job, MINUTE_US).unwrap_err();
    let text = error.to_string();
    println!("{text}");
    assert!(matches!(error.failure, FlashFailure::Invalid(_)), "{text}");
    assert!(
        text.contains("vector table cannot start the core"),
        "{text}"
    );
    assert!(text.contains("initial SP 0xFFFFFFFF"), "{text}");
    assert_eq!(bus.frames, 0, "nothing went on the bus");
    assert!(error.report.phases.is_empty());
}

#[test]
fn a_moving_car_refuses_the_programming_session() {
    let mut bus = SimBus::new();
    bus.set_speed(Some(30.0));
    let mut job = flash_job(Node::Cruise, image_for(Node::Cruise, 4000, SIGNING_SEED));
    let error = bus.run(&mut job, MINUTE_US).unwrap_err();
    // The tester asked again for three seconds (the car might have been about to stand),
    // then said why in words.
    assert!(
        matches!(error.failure, FlashFailure::NotStanding { waited_us } if (3_000_000..3_200_000).contains(&waited_us)),
        "{:?}",
        error.failure
    );
    assert_eq!(error.phase, Phase::SessionSetup);
    let text = error.to_string();
    assert!(text.contains("cruise (0x0D)"), "{text}");
    assert!(text.contains("NRC 0x22 conditionsNotCorrect"), "{text}");
    assert!(text.contains("stop the car and flash again"), "{text}");
    // Nothing was erased; the restore phase ran anyway. The ECU's standstill check came
    // before anything was switched off: no ECU fell silent or stopped recording its codes,
    // while the car (moving) runs on their messages.
    assert_eq!(bus.ecu(Node::Cruise).backend.erases, 0);
    for ecu in &bus.ecus {
        assert!(!ecu.saw_comm_off, "{:?} was silenced", ecu.node());
        assert!(!ecu.saw_dtc_off, "{:?} stopped recording DTCs", ecu.node());
    }
    let phases: Vec<Phase> = error.report.phases.iter().map(|p| p.phase).collect();
    assert_eq!(phases, [Phase::SessionSetup, Phase::Restore]);
    assert_car_restored(&bus);
}

#[test]
fn a_flipped_byte_fails_the_check_routine_and_nothing_is_marked() {
    let mut bus = SimBus::new();
    let mut image = image_for(Node::Cruise, 20_000, SIGNING_SEED);
    image[512 + 10_000] ^= 0x01; // in the payload: the header still parses and checks
    let mut job = flash_job(Node::Cruise, image);
    let error = bus.run(&mut job, MINUTE_US).unwrap_err();
    assert_eq!(error.phase, Phase::Check);
    assert_eq!(
        error.uds(),
        Some(&UdsError::Negative {
            service: 0x31,
            nrc: 0x72,
            name: "generalProgrammingFailure"
        })
    );
    let cruise = bus.ecu(Node::Cruise);
    assert!(!cruise.backend.marked);
    assert_eq!(cruise.resets, 0, "no reset after a failed check");
    assert!(error.to_string().contains("generalProgrammingFailure"));
    assert_car_restored(&bus);
}

#[test]
fn another_ecus_image_is_refused_at_transfer_data() {
    let mut bus = SimBus::new();
    let mut job = flash_job(Node::Cruise, image_for(Node::Engine, 20_000, SIGNING_SEED));
    let error = bus.run(&mut job, MINUTE_US).unwrap_err();
    assert_eq!(error.phase, Phase::Transfer);
    assert_eq!(
        error.uds(),
        Some(&UdsError::Negative {
            service: 0x36,
            nrc: 0x31,
            name: "requestOutOfRange"
        })
    );
    // Refused with the first block, before the rest crossed the bus.
    assert_eq!(error.report.blocks, 0);
    assert!(!bus.ecu(Node::Cruise).backend.marked);
    assert_car_restored(&bus);
}

#[test]
fn an_image_signed_with_another_key_fails_the_check() {
    let mut bus = SimBus::new();
    let mut job = flash_job(Node::Cruise, image_for(Node::Cruise, 5_000, [9; 32]));
    let error = bus.run(&mut job, MINUTE_US).unwrap_err();
    assert_eq!(
        (error.phase, error.uds().and_then(UdsError::nrc)),
        (Phase::Check, Some(0x72))
    );
    assert!(!bus.ecu(Node::Cruise).backend.marked);
}

#[test]
fn a_lost_response_times_out_cleanly() {
    let mut bus = SimBus::new();
    // Every positive response to RequestDownload is lost on the bus.
    bus.drop_frames(|frame| frame.id() == 0x78D && frame.data().get(1) == Some(&0x74));
    let mut job = flash_job(Node::Cruise, image_for(Node::Cruise, 5_000, SIGNING_SEED));
    let error = bus.run(&mut job, MINUTE_US).unwrap_err();
    assert_eq!(error.phase, Phase::Transfer);
    assert_eq!(
        error.uds(),
        Some(&UdsError::Timeout {
            service: 0x34,
            waited_us: 50_000,
            pending: 0
        })
    );
    assert!(error
        .to_string()
        .contains("no response to 0x34 RequestDownload within 50 ms"));
    assert_eq!(bus.dropped, 1);
    // The job ended after P2 and the restore, not after some long wait.
    let took_us = bus.now.as_micros() - autoplug_uds::STANDSTILL_WINDOW_US;
    assert!(took_us < 4_000_000, "{took_us} us");
    assert_car_restored(&bus);
}

#[test]
fn a_lost_transfer_data_response_is_repeated_and_the_flash_succeeds() {
    let mut bus = SimBus::new();
    let mut lost = false;
    // The acknowledgement of block 2 is lost once.
    bus.drop_frames(move |frame| {
        let hit = !lost && frame.id() == 0x78D && frame.data()[..3] == [0x02, 0x76, 0x02];
        lost |= hit;
        hit
    });
    let image = image_for(Node::Cruise, 12_000, SIGNING_SEED);
    let mut job = flash_job(Node::Cruise, image.clone());
    let report = bus.run(&mut job, MINUTE_US).expect("the repeat succeeds");
    assert_eq!(bus.dropped, 1);
    assert_eq!(report.blocks, 4); // 12 576 bytes in blocks of 4093
    assert_eq!(report.notes.len(), 1, "{:?}", report.notes);
    assert!(report.notes[0].contains("block 2"), "{:?}", report.notes);
    assert_eq!(
        &bus.ecu(Node::Cruise).backend.dfu[..image.len()],
        &image[..]
    );
    assert!(bus.ecu(Node::Cruise).backend.marked);
}

#[test]
fn a_wrong_secret_is_refused_with_invalid_key() {
    let mut bus = SimBus::new();
    let config = FlashConfig::new(
        Node::ABS,
        image_for(Node::ABS, 5_000, SIGNING_SEED),
        b"not the secret",
    );
    let mut job = FlashJob::new(config).unwrap();
    let error = bus.run(&mut job, MINUTE_US).unwrap_err();
    assert_eq!(error.phase, Phase::Security);
    assert_eq!(
        error.uds(),
        Some(&UdsError::Negative {
            service: 0x27,
            nrc: 0x35,
            name: "invalidKey"
        })
    );
    assert_eq!(bus.ecu(Node::ABS).backend.erases, 0);
}

#[test]
fn an_ecu_that_does_not_come_back_fails_the_job() {
    let mut bus = SimBus::new();
    bus.boot_us = 20_000_000;
    let mut config = FlashConfig::new(
        Node::Pedals,
        image_for(Node::Pedals, 3_000, SIGNING_SEED),
        DEV_SECURITY_SECRET,
    );
    config.reset_timeout_us = 5_000_000;
    let mut job = FlashJob::new(config).unwrap();
    let error = bus.run(&mut job, MINUTE_US).unwrap_err();
    assert_eq!(error.phase, Phase::ResetAndWait);
    match error.failure {
        FlashFailure::NoReturnAfterReset { waited_us } => {
            assert!((5_000_000..5_300_000).contains(&waited_us), "{waited_us}")
        }
        other => panic!("{other:?}"),
    }
    // The image itself went in and was marked.
    assert!(bus.ecu(Node::Pedals).backend.marked);
    assert!(error.to_string().contains("did not answer TesterPresent"));
}

#[test]
fn identification_of_all_ecus() {
    let mut bus = SimBus::new();
    bus.ecu_mut(Node::Cabin).absent = true;
    let mut job = IdentJob::new(&ECUS, TesterConfig::default());
    let rows = bus.run(&mut job, MINUTE_US).unwrap();
    assert_eq!(rows.len(), Node::ECUS.len());
    for row in &rows {
        if row.ecu == Node::Cabin {
            assert!(!row.answered());
            assert!(matches!(row.part_number, Err(UdsError::Timeout { .. })));
            assert!(matches!(
                row.hardware_version,
                Err(UdsError::Timeout { .. })
            ));
            continue;
        }
        let number = row.ecu.diag_node_number().unwrap();
        let part = format!("AP-{}-0001", row.ecu.name().to_ascii_uppercase());
        assert_eq!(row.part_number.as_deref(), Ok(part.as_bytes()));
        assert_eq!(row.software_version.as_deref(), Ok(&b"1.2.0"[..]));
        let serial = format!("{number:02X}0000000042");
        assert_eq!(row.serial_number.as_deref(), Ok(serial.as_bytes()));
        assert_eq!(row.hardware_version.as_deref(), Ok(&b"NUCLEO-F446RE"[..]));
        assert_eq!(row.vin.as_deref(), Ok(&b"JA3AP47H0YF000042"[..]));
        assert_eq!(
            row.running_slot(),
            Some((ImageSlot::A, BootState::Confirmed))
        );
    }
    assert_eq!(
        autoplug_tester::vehicle_vin(&rows).map(|v| v.map(|v| v.to_string())),
        Ok(Some("JA3AP47H0YF000042".to_string()))
    );
    let table = autoplug_tester::identification_table(&rows);
    assert!(table.contains("AP-CRUISE-0001"), "{table}");
    assert!(table.contains("slot A, confirmed"), "{table}");
    assert!(
        table.contains("cabin") && table.contains("no response"),
        "{table}"
    );
    // Eight ECUs x 6 requests plus one silent ECU asked once (50 ms), from the bus's start.
    let took_us = bus.now.as_micros() - autoplug_uds::STANDSTILL_WINDOW_US;
    assert!(took_us < 200_000, "{took_us} us");
}

#[test]
fn functional_requests_collect_every_ecu_and_tester_present_keeps_sessions() {
    /// A job that sends one functional request, then only TesterPresent until `until`.
    struct Functional {
        tester: Tester,
        sent: bool,
        responses: Option<Vec<autoplug_tester::FunctionalResponse>>,
        until: autoplug_ecu::Instant,
        done: bool,
    }
    impl autoplug_tester::Job for Functional {
        type Output = Vec<autoplug_tester::FunctionalResponse>;
        type Error = UdsError;
        fn tester(&self) -> &Tester {
            &self.tester
        }
        fn tester_mut(&mut self) -> &mut Tester {
            &mut self.tester
        }
        fn advance(&mut self, now: autoplug_ecu::Instant) {
            if !self.sent {
                self.sent = true;
                self.tester.set_tester_present(true);
                self.tester.request_functional(now, &[0x10, 0x03]).unwrap();
            }
            if let Some(Ok(Response::Functional(list))) = self.tester.take_response() {
                self.responses = Some(list);
            }
            self.done = now >= self.until;
        }
        fn own_deadline(&self) -> Option<autoplug_ecu::Instant> {
            Some(self.until)
        }
        fn take_result(&mut self) -> Option<Result<Self::Output, UdsError>> {
            if self.done {
                self.done = false;
                return Some(Ok(self.responses.take().unwrap_or_default()));
            }
            None
        }
    }

    let mut bus = SimBus::new();
    let mut job = Functional {
        tester: Tester::new(TesterConfig::default()),
        sent: false,
        responses: None,
        until: autoplug_ecu::Instant::from_micros(12_000_000),
        done: false,
    };
    let responses = bus.run(&mut job, MINUTE_US).unwrap();
    let mut answered: Vec<Node> = responses.iter().map(|r| r.ecu).collect();
    answered.sort_by_key(|n| n.diag_node_number());
    assert_eq!(answered, ECUS);
    for response in &responses {
        assert_eq!(
            response.result.as_deref(),
            Ok(&[0x50, 0x03, 0x00, 0x32, 0x01, 0xF4][..])
        );
    }
    // 12 s later, well past S3 (5 s), TesterPresent kept every ECU in its session.
    for ecu in &bus.ecus {
        assert_eq!(
            ecu.diag.as_ref().unwrap().server().session(),
            Session::Extended
        );
    }
    // Without it, S3 ends the sessions.
    bus.idle(6_000_000);
    for ecu in &bus.ecus {
        assert_eq!(
            ecu.diag.as_ref().unwrap().server().session(),
            Session::Default
        );
    }
}

/// A release file with both slots' images: the job asks the ECU which slot it runs and
/// sends the other slot's image only.
#[test]
fn from_a_release_the_image_for_the_slot_the_ecu_writes_goes() {
    let mut bus = SimBus::new();
    let a = image_for_slot(Node::Cruise, ImageSlot::A, 20_000, SIGNING_SEED);
    let b = image_for_slot(Node::Cruise, ImageSlot::B, 20_000, SIGNING_SEED);
    let release = [a.clone(), b.clone()].concat();
    let mut job = flash_job(Node::Cruise, release);
    let report = bus.run(&mut job, MINUTE_US).expect("the flash succeeds");
    assert_eq!(report.slot, Some(ImageSlot::B));
    assert_eq!(report.image_len, b.len() as u64);
    let cruise = bus.ecu(Node::Cruise);
    assert_eq!(&cruise.backend.dfu[..b.len()], &b[..]);
    assert!(cruise.backend.marked);
    assert_car_restored(&bus);
}

/// An image linked for the slot the ECU runs cannot go to the other one: the job says so
/// before anything is erased, and leaves the car as it was.
#[test]
fn an_image_for_the_running_slot_is_refused_before_the_erase() {
    let mut bus = SimBus::new();
    let a = image_for_slot(Node::Cruise, ImageSlot::A, 20_000, SIGNING_SEED);
    let mut job = flash_job(Node::Cruise, a);
    let error = bus.run(&mut job, MINUTE_US).expect_err("the wrong slot");
    let text = error.to_string();
    assert!(
        text.contains("the ECU runs slot A and writes the update to slot B")
            && text.contains("linked for slot A"),
        "{text}"
    );
    assert_eq!(error.phase, Phase::Erase);
    assert_eq!(bus.ecu(Node::Cruise).backend.erases, 0);
    assert!(!bus.ecu(Node::Cruise).backend.marked);
    assert_car_restored(&bus);
}
