//! The tester driven over a socketcand link with the wall clock (the nine ECUs served from
//! a thread). The client itself is tested in autoplug-transport.

use std::time::Duration;

use autoplug_tester::driver;
use autoplug_tester::names::ECUS;
use autoplug_tester::testing::EcuServer;
use autoplug_tester::{IdentJob, TesterConfig};
use autoplug_transport::socketcand::SocketcandClient;

const TIMEOUT: Duration = Duration::from_secs(5);

#[test]
fn identification_over_socketcand_with_the_wall_clock() {
    let ecus = EcuServer::start(&ECUS);
    let mut client =
        SocketcandClient::connect("127.0.0.1", ecus.address.port(), "can0", TIMEOUT).unwrap();
    // Generous P2: a loaded machine's scheduler, not the ECUs, sets the latency here.
    let config = TesterConfig {
        p2_us: 1_000_000,
        ..TesterConfig::default()
    };
    let mut job = IdentJob::new(&ECUS, config);
    let rows = driver::run(&mut client, &mut job).unwrap();
    assert_eq!(rows.len(), autoplug_can::Node::ECUS.len());
    for row in &rows {
        assert!(row.answered(), "{:?}", row.ecu);
        let part = format!("AP-{}-0001", row.ecu.name().to_ascii_uppercase());
        assert_eq!(row.part_number.as_deref(), Ok(part.as_bytes()));
        assert_eq!(row.hardware_version.as_deref(), Ok(&b"NUCLEO-F446RE"[..]));
    }
    drop(client);
    ecus.stop();
}
