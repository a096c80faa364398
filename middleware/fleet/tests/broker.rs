//! The shipped broker configuration, on a real Mosquitto: logins, the rights that keep
//! each vehicle to its own topics, persistent sessions that let an offline vehicle catch up.

mod common;

use std::time::Duration;

use autoplug_fleet::broker::FLEET_USER;
use autoplug_fleet::mqtt::{LinkOptions, MqttLink};
use autoplug_fleet::topics::{self, ReportKind};
use autoplug_vin::Vin;
use common::{runtime, PrivateBroker};

const A: &str = "JA3AP47H0YF000042";
const B: &str = "JA3AP47H2YF000043";

fn vin(text: &str) -> Vin {
    Vin::parse(text).unwrap()
}

/// Waits for the next message on `link` whose topic is `topic`, skipping none: returns
/// the first message at all, so a test sees exactly what came first.
fn next(link: &mut MqttLink, wait: Duration) -> Option<(String, Vec<u8>)> {
    link.recv_timeout(wait).map(|m| (m.topic, m.payload))
}

/// A car logged in as `user` with the client id of `client_of` (its own, or another's).
fn vehicle(
    rt: &tokio::runtime::Runtime,
    broker: &PrivateBroker,
    user: &str,
    client_of: &str,
    subscriptions: Vec<String>,
) -> MqttLink {
    let client_id =
        autoplug_fleet::mqtt::vehicle_client_id(client_of, Some(&format!("pw-{client_of}")));
    let mut options = LinkOptions::new(client_id);
    options.persistent_session = true;
    options.subscriptions = subscriptions;
    MqttLink::connect(
        rt.handle(),
        &broker.url(user, &format!("pw-{user}")),
        options,
    )
}

fn fleet_link(rt: &tokio::runtime::Runtime, broker: &PrivateBroker) -> MqttLink {
    let mut options = LinkOptions::new("fleet-test");
    options.subscriptions = vec![topics::REPORTS_SHARED.to_string()];
    let link = MqttLink::connect(rt.handle(), &broker.url(FLEET_USER, "pw-fleet"), options);
    link.wait_connected(Duration::from_secs(5)).unwrap();
    wait_subscribed(&link, 1);
    link
}

fn wait_subscribed(link: &MqttLink, n: usize) {
    for _ in 0..500 {
        let s = link.status();
        if s.granted.len() + s.denied.len() >= n {
            return;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    panic!("no SUBACK: {:?}", link.status());
}

fn broker_with_logins() -> PrivateBroker {
    let broker = PrivateBroker::start();
    broker.add_login(FLEET_USER, "pw-fleet");
    for v in [A, B] {
        broker.add_login(v, &format!("pw-{v}"));
    }
    broker
}

#[test]
fn a_vehicle_publishes_only_as_itself_and_reads_only_its_own_commands() {
    let broker = broker_with_logins();
    let rt = runtime();
    let mut fleet = fleet_link(&rt, &broker);

    // A wrong password is refused at login, with the reason.
    let mut options = LinkOptions::new(A);
    options.max_backoff = Duration::from_millis(200);
    let intruder = MqttLink::connect(rt.handle(), &broker.url(A, "guess"), options);
    let refused = intruder.wait_connected(Duration::from_secs(5)).unwrap_err();
    assert!(refused.0.contains("refused the login"), "{refused}");
    drop(intruder);

    let mut a = vehicle(
        &rt,
        &broker,
        A,
        A,
        vec![topics::command(&vin(A)), topics::command(&vin(B))],
    );
    a.wait_connected(Duration::from_secs(5)).unwrap();
    wait_subscribed(&a, 2);
    // Subscribing to another vehicle's commands is refused at SUBACK.
    assert!(a.status().granted.contains(&topics::command(&vin(A))));
    assert_eq!(a.status().denied, [topics::command(&vin(B))]);

    // A publishes a report as B, then one as itself: only its own reaches the fleet.
    a.publish(
        &topics::report(&vin(B), ReportKind::Trip),
        b"forged".to_vec(),
        false,
    )
    .unwrap();
    a.publish(
        &topics::report(&vin(A), ReportKind::Trip),
        b"own".to_vec(),
        false,
    )
    .unwrap();
    let first = next(&mut fleet, Duration::from_secs(5));
    assert_eq!(
        first,
        Some((topics::report(&vin(A), ReportKind::Trip), b"own".to_vec())),
        "the report published as another VIN was dropped by the broker"
    );
    // Nor may a vehicle write commands, to itself or another.
    a.publish(&topics::command(&vin(A)), b"self-command".to_vec(), false)
        .unwrap();
    // Commands from the fleet reach the vehicle they are for, and only it.
    fleet
        .publish(&topics::command(&vin(B)), b"for B".to_vec(), false)
        .unwrap();
    fleet
        .publish(&topics::command(&vin(A)), b"for A".to_vec(), false)
        .unwrap();
    assert_eq!(
        next(&mut a, Duration::from_secs(5)),
        Some((topics::command(&vin(A)), b"for A".to_vec()))
    );
    assert_eq!(next(&mut a, Duration::from_millis(300)), None);
    assert_eq!(next(&mut fleet, Duration::from_millis(300)), None);
}

#[test]
fn an_offline_vehicle_finds_its_command_when_it_reconnects_even_after_a_broker_restart() {
    let mut broker = broker_with_logins();
    let rt = runtime();
    let fleet = fleet_link(&rt, &broker);

    // B has been online once: the broker keeps its session and subscription.
    let b = vehicle(&rt, &broker, B, B, vec![topics::command(&vin(B))]);
    b.wait_connected(Duration::from_secs(5)).unwrap();
    wait_subscribed(&b, 1);
    b.close(Duration::from_secs(2));

    fleet
        .publish(&topics::command(&vin(B)), b"campaign 1".to_vec(), false)
        .unwrap();
    std::thread::sleep(Duration::from_millis(300));
    drop(fleet);

    // Another vehicle cannot log in with B's client id (and so never reaches B's queue).
    let a_as_b = vehicle(&rt, &broker, A, B, vec![topics::command(&vin(A))]);
    let refused = a_as_b.wait_connected(Duration::from_secs(5)).unwrap_err();
    assert!(refused.0.contains("refused the login"), "{refused}");
    drop(a_as_b);

    // The broker restarts (its persistence is on disk); B comes back.
    broker.restart();
    let mut b = vehicle(&rt, &broker, B, B, vec![topics::command(&vin(B))]);
    b.wait_connected(Duration::from_secs(10)).unwrap();
    assert_eq!(
        next(&mut b, Duration::from_secs(5)),
        Some((topics::command(&vin(B)), b"campaign 1".to_vec()))
    );
}
