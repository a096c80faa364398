//! The fleet store on both engines: migrations, inventory and trip reports, and the recall
//! queries, which must return exactly the vehicles concerned.

mod common;

use std::collections::BTreeSet;

use autoplug_fleet::migrations::SCHEMA_VERSION;
use autoplug_fleet::{
    EvidenceQuery, Finding, FleetStore, InventoryQuery, InventoryReport, StoreError, Stored,
    TripReport,
};
use autoplug_store::{DtcRecord, EcuIdentity, VerdictRecord};
use autoplug_trips::{TripEnd, TripStats};
use autoplug_vin::Vin;
use common::engines;

fn vin(n: u32) -> String {
    Vin::with_check_digit(&format!("JA3AP47H0YF{n:06}"))
        .unwrap()
        .to_string()
}

fn identity(ecu: &str, node: u8, version: &str, hardware: &str, serial: &str) -> EcuIdentity {
    EcuIdentity {
        ecu: ecu.to_string(),
        node,
        part_number: Some(format!("AP-{}-0001", ecu.to_ascii_uppercase())),
        software_version: Some(version.to_string()),
        hardware_version: Some(hardware.to_string()),
        serial_number: Some(serial.to_string()),
    }
}

/// Vehicle `n` of a small synthetic fleet: cruise software by `n % 4`, hardware revision
/// by `n % 3`, serials in order.
fn inventory(n: u32) -> InventoryReport {
    let cruise = ["1.0.0", "1.1.0", "1.1.3", "1.2.0"][n as usize % 4];
    let hardware = ["NUCLEO-F446RE", "NUCLEO-F446RE", "NUCLEO-F446RE-C"][n as usize % 3];
    InventoryReport {
        vin: vin(n),
        read_at_ms: 1_000,
        ecus: vec![
            identity(
                "engine",
                0x03,
                "1.0.0",
                "NUCLEO-F446RE",
                &format!("AP03{n:08}"),
            ),
            identity("cruise", 0x0D, cruise, hardware, &format!("AP0D{n:08}")),
            identity(
                "abs",
                0x0E,
                "1.0.0",
                "NUCLEO-F446RE",
                &format!("AP0E{n:08}"),
            ),
        ],
    }
}

fn verdict(ecu: &str, verdict: &str, number: f64) -> VerdictRecord {
    VerdictRecord {
        ecu: ecu.to_string(),
        verdict: verdict.to_string(),
        routine: format!("{ecu} routine"),
        number: Some(number),
        unit: "km/h".into(),
        suspect_above: 3.0,
        faulty_above: 6.0,
        window_s: Some((10.0, 20.0)),
        evidence: format!("{ecu}: {number} km/h off the set speed"),
    }
}

fn trip(n: u32, trip: i64, ended_at_ms: i64, cruise: &str, dtcs: &[&str]) -> TripReport {
    TripReport {
        vin: vin(n),
        trip,
        started_at_ms: ended_at_ms - 600_000,
        ended_at_ms,
        stats: TripStats {
            distance_m: 5_000.0,
            duration_s: 600.0,
            max_speed_kmh: 120.0,
            ..TripStats::default()
        },
        end: TripEnd::Parked,
        verdicts: vec![verdict("cruise", cruise, 7.5), verdict("abs", "ok", 0.1)],
        dtcs: dtcs
            .iter()
            .map(|code| DtcRecord {
                ecu: "engine".into(),
                code: code.to_string(),
                status: 0x09,
                description: "lost communication".into(),
            })
            .collect(),
    }
}

fn vins<'a>(list: impl IntoIterator<Item = &'a String>) -> BTreeSet<String> {
    list.into_iter().cloned().collect()
}

#[test]
fn migrations_run_once_and_a_newer_schema_is_refused() {
    for engine in engines() {
        let mut store = engine.open();
        let rows = store
            .db()
            .query(
                "SELECT version, name FROM fleet_schema_migrations ORDER BY version",
                &[],
            )
            .unwrap();
        assert_eq!(rows.len() as i64, SCHEMA_VERSION, "{}", engine.label());
        drop(store);
        // A second start migrates nothing.
        let mut store = engine.open();
        let rows = store
            .db()
            .query("SELECT count(*) FROM fleet_schema_migrations", &[])
            .unwrap();
        assert_eq!(rows[0][0].int(), Some(SCHEMA_VERSION), "{}", engine.label());
        // A database migrated by a newer program.
        store
            .db()
            .execute(
                "INSERT INTO fleet_schema_migrations (version, name, applied_at_ms) VALUES ($1, 'future', 0)",
                &[(SCHEMA_VERSION + 1).into()],
            )
            .unwrap();
        drop(store);
        let Err(error) = FleetStore::open(&engine.address()) else {
            panic!("{}: a newer schema was accepted", engine.label());
        };
        assert!(
            error.to_string().contains("newer than this program"),
            "{}: {error}",
            engine.label()
        );
    }
}

#[test]
fn services_starting_together_migrate_once() {
    let schema = common::PgSchema::new();
    let threads: Vec<_> = (0..4)
        .map(|_| {
            let url = schema.url.clone();
            std::thread::spawn(move || FleetStore::open(&url).map(|_| ()))
        })
        .collect();
    for t in threads {
        t.join().unwrap().unwrap();
    }
    let mut store = FleetStore::open(&schema.url).unwrap();
    let rows = store
        .db()
        .query("SELECT count(*) FROM fleet_schema_migrations", &[])
        .unwrap();
    assert_eq!(rows[0][0].int(), Some(SCHEMA_VERSION));
}

#[test]
fn an_inventory_recall_returns_exactly_the_vehicles_carrying_it() {
    const FLEET: u32 = 60;
    for engine in engines() {
        let label = engine.label();
        let mut store = engine.open();
        for n in 0..FLEET {
            store.record_inventory(&inventory(n)).unwrap();
        }
        let truth = |keep: &dyn Fn(&EcuIdentity) -> bool| -> BTreeSet<String> {
            (0..FLEET)
                .map(inventory)
                .filter(|r| r.ecus.iter().any(keep))
                .map(|r| r.vin)
                .collect()
        };
        let version = |v: &str| Some(v.parse().unwrap());

        // Part number and a software range: 1.1.0 up to 1.1.x.
        let query = InventoryQuery {
            part_number: Some("AP-CRUISE-0001".into()),
            software_from: version("1.1.0"),
            software_to: version("1.1.65535"),
            ..InventoryQuery::default()
        };
        let hits = store.recall_by_inventory(&query).unwrap();
        let expected = truth(&|e| {
            e.ecu == "cruise"
                && e.software_version
                    .as_deref()
                    .is_some_and(|v| v.starts_with("1.1."))
        });
        assert_eq!(expected.len(), 30, "{label}");
        assert_eq!(vins(hits.iter().map(|h| &h.vin)), expected, "{label}");
        assert_eq!(hits.len(), expected.len(), "{label}: one hit per vehicle");
        assert!(
            hits.iter()
                .all(|h| h.ecu == "cruise" && h.part_number.as_deref() == Some("AP-CRUISE-0001")),
            "{label}"
        );

        // Exactly one version, and the hardware revision.
        let query = InventoryQuery {
            ecu: Some("cruise".into()),
            software_from: version("1.1.0"),
            software_to: version("1.1.0"),
            hardware_version: Some("NUCLEO-F446RE-C".into()),
            ..InventoryQuery::default()
        };
        let hits = store.recall_by_inventory(&query).unwrap();
        let expected = truth(&|e| {
            e.ecu == "cruise"
                && e.software_version.as_deref() == Some("1.1.0")
                && e.hardware_version.as_deref() == Some("NUCLEO-F446RE-C")
        });
        assert!(!expected.is_empty());
        assert_eq!(vins(hits.iter().map(|h| &h.vin)), expected, "{label}");

        // A serial range.
        let query = InventoryQuery {
            part_number: Some("AP-CRUISE-0001".into()),
            serial_from: Some("AP0D00000010".into()),
            serial_to: Some("AP0D00000019".into()),
            ..InventoryQuery::default()
        };
        let hits = store.recall_by_inventory(&query).unwrap();
        assert_eq!(
            vins(hits.iter().map(|h| &h.vin)),
            (10..20).map(vin).collect(),
            "{label}"
        );

        // Version order is numeric, not textual: 1.10.0 is above 1.2.0.
        let mut odd = inventory(FLEET);
        odd.ecus[1].software_version = Some("1.10.0".into());
        store.record_inventory(&odd).unwrap();
        let query = InventoryQuery {
            ecu: Some("cruise".into()),
            software_from: version("1.3.0"),
            ..InventoryQuery::default()
        };
        let hits = store.recall_by_inventory(&query).unwrap();
        assert_eq!(
            vins(hits.iter().map(|h| &h.vin)),
            [vin(FLEET)].into(),
            "{label}"
        );

        // A recall of nothing in particular would be the whole fleet: refused.
        let error = store
            .recall_by_inventory(&InventoryQuery::default())
            .unwrap_err();
        assert!(
            error.to_string().contains("at least one of"),
            "{label}: {error}"
        );
    }
}

#[test]
fn a_flash_changes_the_inventory_and_leaves_a_history() {
    for engine in engines() {
        let label = engine.label();
        let mut store = engine.open();
        let mut report = inventory(1); // cruise 1.1.0
        assert_eq!(store.record_inventory(&report).unwrap().len(), 3, "{label}");
        // The same again changes nothing.
        assert!(
            store.record_inventory(&report).unwrap().is_empty(),
            "{label}"
        );
        report.ecus[1].software_version = Some("1.2.0".into());
        report.read_at_ms = 2_000;
        assert_eq!(
            store.record_inventory(&report).unwrap(),
            ["cruise"],
            "{label}"
        );
        let now = store.vehicle_inventory(&vin(1)).unwrap();
        let cruise = now.iter().find(|e| e.ecu == "cruise").unwrap();
        assert_eq!(cruise.software_version.as_deref(), Some("1.2.0"), "{label}");
        let history = store
            .db()
            .query(
                "SELECT software_version FROM ecu_history WHERE vin = $1 AND ecu = 'cruise' ORDER BY id",
                &[vin(1).into()],
            )
            .unwrap();
        let versions: Vec<_> = history
            .iter()
            .map(|r| r[0].text().unwrap().to_string())
            .collect();
        assert_eq!(versions, ["1.1.0", "1.2.0"], "{label}");
        // The recall of 1.1.0 no longer finds it.
        let query = InventoryQuery {
            ecu: Some("cruise".into()),
            software_from: Some("1.1.0".parse().unwrap()),
            software_to: Some("1.1.0".parse().unwrap()),
            ..InventoryQuery::default()
        };
        assert!(
            store.recall_by_inventory(&query).unwrap().is_empty(),
            "{label}"
        );
    }
}

#[test]
fn an_evidence_recall_returns_exactly_the_vehicles_the_drives_convicted() {
    const DAY: i64 = 86_400_000;
    for engine in engines() {
        let label = engine.label();
        let mut store = engine.open();
        // Vehicles 0..20: cruise faulty on the drives of n % 5 == 0, in the period for
        // n < 15; codes U0140-87 on n % 7 == 0 and U0140-00 on n == 3.
        for n in 0..20u32 {
            store.record_inventory(&inventory(n)).unwrap();
            let day = if n < 15 { 10 } else { 40 };
            let cruise = if n % 5 == 0 { "faulty" } else { "ok" };
            let mut codes = Vec::new();
            if n % 7 == 0 {
                codes.push("U0140-87");
            }
            if n == 3 {
                codes.push("U0140-00");
            }
            let report = trip(n, 1, day * DAY, cruise, &codes);
            assert_eq!(store.record_trip(&report).unwrap(), Stored::New, "{label}");
            // Redelivered (MQTT at-least-once): stored once.
            assert_eq!(
                store.record_trip(&report).unwrap(),
                Stored::Duplicate,
                "{label}"
            );
            // A second, clean drive changes nothing of the evidence.
            let seen = |store: &mut FleetStore| {
                store
                    .db()
                    .query(
                        "SELECT last_seen_ms FROM vehicles WHERE vin = $1",
                        &[autoplug_fleet::db::Value::from(vin(n).as_str())],
                    )
                    .unwrap()[0][0]
                    .int()
                    .unwrap()
            };
            let before = seen(&mut store);
            std::thread::sleep(std::time::Duration::from_millis(2));
            store
                .record_trip(&trip(n, 2, (day + 1) * DAY, "ok", &[]))
                .unwrap();
            // The vehicle was seen again (written after the trip's commit).
            assert!(seen(&mut store) > before, "{label}");
        }
        let period = |finding, ecu: Option<&str>| EvidenceQuery {
            finding,
            ecu: ecu.map(str::to_string),
            since_ms: 5 * DAY,
            until_ms: 30 * DAY,
        };
        let hits = store
            .recall_by_evidence(&period(Finding::Faulty, Some("cruise")))
            .unwrap();
        assert_eq!(
            vins(hits.iter().map(|h| &h.vin)),
            [0, 5, 10].map(vin).into(),
            "{label}"
        );
        for hit in &hits {
            assert_eq!(hit.evidence.len(), 1, "{label}: {hit:?}");
            let e = &hit.evidence[0];
            assert_eq!((e.trip, e.ecu.as_str()), (1, "cruise"), "{label}");
            assert!(
                e.what.starts_with("faulty: cruise routine (7.5 km/h)"),
                "{label}: {e:?}"
            );
            assert!(e.detail.contains("off the set speed"), "{label}");
        }
        // No ABS was ever judged faulty.
        assert!(store
            .recall_by_evidence(&period(Finding::Faulty, Some("abs")))
            .unwrap()
            .is_empty());
        // A code with its failure type, and the base code with any.
        let hits = store
            .recall_by_evidence(&period(Finding::Dtc("U0140-87".into()), None))
            .unwrap();
        assert_eq!(
            vins(hits.iter().map(|h| &h.vin)),
            [0, 7, 14].map(vin).into(),
            "{label}"
        );
        let hits = store
            .recall_by_evidence(&period(Finding::Dtc("U0140".into()), Some("engine")))
            .unwrap();
        assert_eq!(
            vins(hits.iter().map(|h| &h.vin)),
            [0, 3, 7, 14].map(vin).into(),
            "{label}"
        );
        // Bad questions get a clear answer.
        let mut empty = period(Finding::Faulty, None);
        empty.until_ms = empty.since_ms;
        assert!(store
            .recall_by_evidence(&empty)
            .unwrap_err()
            .to_string()
            .contains("empty"));
        let error = store
            .recall_by_evidence(&period(Finding::Dtc("U01'; DROP".into()), None))
            .unwrap_err();
        assert!(error.to_string().contains("not a trouble code"), "{error}");
        let summary = store.summary().unwrap();
        assert_eq!((summary.vehicles, summary.trips), (20, 40), "{label}");
        assert_eq!(summary.faulty_verdicts, 4, "{label}");
        assert!((summary.distance_km - 200.0).abs() < 1e-9, "{label}");
    }
}

#[test]
fn bad_reports_are_refused_with_their_reason_and_store_nothing() {
    for engine in engines() {
        let label = engine.label();
        let mut store = engine.open();
        let mut report = inventory(1);
        report.vin = "JA3AP47H9YF000001".into();
        let error = store.record_inventory(&report).unwrap_err();
        assert!(matches!(error, StoreError::Invalid(_)), "{label}");
        assert!(
            error.to_string().contains("check digit"),
            "{label}: {error}"
        );
        let mut report = inventory(1);
        report.ecus[0].part_number = Some("AP\u{0}X".into());
        let error = store.record_inventory(&report).unwrap_err();
        assert!(
            error.to_string().contains("control characters"),
            "{label}: {error}"
        );
        let mut report = inventory(1);
        report.ecus.push(report.ecus[0].clone());
        let error = store.record_inventory(&report).unwrap_err();
        assert!(
            error.to_string().contains("listed twice"),
            "{label}: {error}"
        );
        let mut bad = trip(1, 1, 1_000, "ok", &[]);
        bad.stats.distance_m = f64::NAN;
        let error = store.record_trip(&bad).unwrap_err();
        assert!(
            error.to_string().contains("distance is NaN"),
            "{label}: {error}"
        );
        assert_eq!(store.summary().unwrap().vehicles, 0, "{label}");
    }
}

#[test]
fn an_unreachable_server_is_named_in_the_error() {
    // Port 9 (discard) on loopback: nothing listens there.
    let Err(error) = FleetStore::open("postgresql://fleet:s3cret@127.0.0.1:9/fleet") else {
        panic!("connected to nothing");
    };
    let text = error.to_string();
    assert!(
        text.starts_with("postgresql://127.0.0.1:9/fleet: cannot connect"),
        "{text}"
    );
    assert!(!text.contains("s3cret"), "{text}");
}

/// What makes a good report bad.
type Spoil = Box<dyn Fn(&mut TripReport)>;

#[test]
fn figures_no_car_can_produce_and_ecus_the_catalogue_does_not_know_are_refused() {
    for engine in engines() {
        let label = engine.label();
        let mut store = engine.open();
        store.record_inventory(&inventory(1)).unwrap();
        store
            .record_trip(&trip(1, 1, 1_000_000, "ok", &[]))
            .unwrap();
        // Two trips of 1.7e308 m made the overview's distance sum overflow in PostgreSQL.
        let refusals: Vec<(Spoil, &str)> = vec![
            (
                Box::new(|t| t.stats.distance_m = 1.7e308),
                "the distance (m) is 1.7e308, more than",
            ),
            (
                Box::new(|t| t.stats.distance_m = 43_000.0),
                "the top speed for the whole trip",
            ),
            (
                Box::new(|t| t.stats.max_speed_kmh = 256.0),
                "VehicleSpeedMsg's range",
            ),
            (Box::new(|t| t.stats.duration_s = 1e12), "30 days"),
            (Box::new(|t| t.stats.fuel_used_l = 120.0), "600 L/h"),
            (
                Box::new(|t| t.stats.cruise_time_s = 700.0),
                "the trip's duration",
            ),
            (Box::new(|t| t.stats.shifts = 70_000), "one per 10 ms"),
            (
                Box::new(|t| t.ended_at_ms = t.started_at_ms - 1),
                "before it starts",
            ),
            (
                Box::new(|t| t.verdicts[0].ecu = "brakes".into()),
                "names ECU \"brakes\"",
            ),
            (
                Box::new(|t| {
                    t.dtcs.push(DtcRecord {
                        ecu: "Engine".into(),
                        code: "U0100".into(),
                        status: 9,
                        description: String::new(),
                    })
                }),
                "names ECU \"Engine\"",
            ),
        ];
        for (i, (spoil, says)) in refusals.iter().enumerate() {
            let mut bad = trip(1, 10 + i as i64, 2_000_000, "ok", &[]);
            spoil(&mut bad);
            let error = store.record_trip(&bad).unwrap_err();
            assert!(matches!(error, StoreError::Invalid(_)), "{label}");
            assert!(error.to_string().contains(says), "{label}: {error}");
        }
        // An inventory naming an ECU the car has not, or an ECU at another's node.
        let mut report = inventory(2);
        report.ecus[0].ecu = "turbo".into();
        let error = store.record_inventory(&report).unwrap_err();
        assert!(
            error.to_string().contains("none of the car's"),
            "{label}: {error}"
        );
        let mut report = inventory(2);
        report.ecus[0].node = 0x0E;
        let error = store.record_inventory(&report).unwrap_err();
        assert!(
            error.to_string().contains("its node is 0x03"),
            "{label}: {error}"
        );
        // Nothing of them was stored, and the overview still adds up.
        let summary = store.summary().unwrap();
        assert_eq!((summary.vehicles, summary.trips), (1, 1), "{label}");
        assert!((summary.distance_km - 5.0).abs() < 1e-9, "{label}");
    }
}
