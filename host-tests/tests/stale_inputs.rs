//! A silenced sender puts each receiver into its safe state within 3 periods, with a DTC
//! (spec section 2).

use autoplug_can::{Node, MESSAGES};
use autoplug_ecu::lost_communication;
use autoplug_host_tests::*;
use autoplug_virtual_car::car::VirtualCar;

const SILENCE_AT_US: u64 = 3_000_000;

fn cruising() -> autoplug_virtual_car::scenario::Scenario {
    inline(
        r#"
name = "stale"
duration_s = 4.0
[initial]
speed_kmh = 90.0
gear = "5"
[driver]
accelerator = 22.0
economy_mode = true
[[at]]
t_s = 1.0
press = ["cruise_on"]
accelerator = 0.0
"#,
    )
}

/// Control step period of each ECU, µs (the ECUs' own constants, from their registry).
fn step_period_us(node: Node) -> u64 {
    autoplug_ecus::ecu(node).map_or(0, |e| e.step_period_us)
}

/// Nodes that supervise a message: its receivers in the DBC, less the gateway and the
/// steering ECU's CruiseModeMsg (normally silent: it carries only the pedals' cancels).
fn supervisors(message: &autoplug_can::MessageSpec) -> Vec<Node> {
    message
        .signals
        .iter()
        .flat_map(|s| s.receivers.iter().copied())
        .filter(|n| *n != Node::Gateway)
        .filter(|n| !(*n == Node::Steering && message.name == "CruiseModeMsg"))
        .fold(Vec::new(), |mut v, n| {
            if !v.contains(&n) {
                v.push(n);
            }
            v
        })
}

#[test]
fn every_receiver_records_lost_communication_within_three_periods() {
    let mut checked = 0;
    for sender in Node::ALL.into_iter().filter(|n| *n != Node::Gateway) {
        // Deadline per receiver: 3 periods of the slowest message it hears from the sender,
        // plus one of its own steps to notice, plus the frame time.
        let mut expected: Vec<(Node, u64)> = Vec::new();
        for m in MESSAGES
            .iter()
            .filter(|m| m.senders.first() == Some(&sender))
        {
            for receiver in supervisors(m) {
                let deadline =
                    3 * u64::from(m.cycle_time_ms) * 1000 + step_period_us(receiver) + 1_000;
                match expected.iter_mut().find(|(n, _)| *n == receiver) {
                    Some((_, d)) => *d = (*d).min(deadline),
                    None => expected.push((receiver, deadline)),
                }
            }
        }
        if expected.is_empty() {
            continue;
        }
        let mut car = VirtualCar::new(&cruising());
        let dtc = lost_communication(sender);
        while car.time_us() < SILENCE_AT_US {
            car.tick();
        }
        for (node, dtcs) in car.dtcs() {
            assert!(
                !dtcs.is_active(dtc),
                "{node:?} had {dtc} before {sender:?} was silenced"
            );
        }
        car.set_silenced(sender, true);
        let mut noticed: Vec<(Node, u64)> = Vec::new();
        while car.time_us() < SILENCE_AT_US + 400_000 {
            car.tick();
            for (node, dtcs) in car.dtcs() {
                if dtcs.is_active(dtc) && !noticed.iter().any(|(n, _)| *n == node) {
                    noticed.push((node, car.time_us() - SILENCE_AT_US));
                }
            }
        }
        for (receiver, deadline) in expected {
            let after = noticed
                .iter()
                .find(|(n, _)| *n == receiver)
                .map(|(_, t)| *t)
                .unwrap_or_else(|| {
                    panic!("{receiver:?} never recorded {dtc} when {sender:?} went silent")
                });
            assert!(
                after <= deadline,
                "{receiver:?} recorded {dtc} {after} us after {sender:?} went silent (deadline {deadline} us)"
            );
            checked += 1;
        }
    }
    assert!(
        checked >= 15,
        "only {checked} sender/receiver pairs checked"
    );
}

/// The safe states that matter most, seen on the car: cruise disengages when the steering
/// ECU falls silent; without the speed reference ABS passes the brake through, the
/// gearbox holds its gear and the differential opens; without the pedals ECU the brake
/// lights come on.
#[test]
fn safe_states_on_the_car() {
    // Steering silent: cruise disengages.
    let mut car = VirtualCar::new(&cruising());
    while car.time_us() < SILENCE_AT_US {
        car.tick();
    }
    assert!(car.cruise_status().expect("host logic").engaged);
    car.set_silenced(Node::Steering, true);
    while car.time_us() < SILENCE_AT_US + 70_000 {
        car.tick();
    }
    assert!(
        !car.cruise_status().expect("host logic").engaged,
        "cruise still engaged after CruiseModeMsg stopped"
    );

    // Cruise ECU silent (VehicleSpeedMsg lost).
    let mut car = VirtualCar::new(&cruising());
    while car.time_us() < SILENCE_AT_US {
        car.tick();
    }
    let gear = car.trans_status().expect("host logic").engaged;
    car.set_silenced(Node::Cruise, true);
    while car.time_us() < SILENCE_AT_US + 200_000 {
        car.tick();
    }
    assert_eq!(
        car.abs_status().expect("host logic").availability,
        autoplug_ecus::abs::Availability::NoSpeedReference
    );
    assert_eq!(
        car.trans_status().expect("host logic").engaged,
        gear,
        "gear held"
    );
    assert_eq!(car.diff_status().expect("host logic").torque_split_nm, 0.0);

    // Pedals ECU silent: brake lights on (fail-safe).
    let mut car = VirtualCar::new(&cruising());
    while car.time_us() < SILENCE_AT_US {
        car.tick();
    }
    assert!(!car.vehicle().brake_lights);
    car.set_silenced(Node::Pedals, true);
    while car.time_us() < SILENCE_AT_US + 60_000 {
        car.tick();
    }
    assert!(
        car.vehicle().brake_lights,
        "brake lights stay off with the brake state unknown"
    );
}
