//! Benchmark: recall queries over a synthetic fleet of a million vehicles in PostgreSQL.
//!
//! Fills a throwaway schema (the fleet's own migrations, so the shipped indexes) by COPY:
//! `VEHICLES` vehicles with nine ECUs each (the cruise software split 35/30/35 % over
//! 1.0.0, 1.0.2 and the faulty 1.1.0; 3 % on a second hardware revision), one trip a
//! vehicle over a year with the cruise ECU's verdict (faulty for 2 % of the 1.1.0
//! carriers) and a trouble code for 1 % of the vehicles. Then times each recall the
//! command line offers through `FleetStore` (median of 5, the rows turned into the
//! answer included) and prints its query plan (`EXPLAIN (ANALYZE, BUFFERS)`).
//!
//! ```text
//! cargo run --release -p autoplug-fleet --example recall_benchmark [VEHICLES]
//! ```
//! The server: `AUTOPLUG_TEST_POSTGRES` (default the local one).

use std::io::Write;
use std::time::Instant;

use autoplug_fleet::db::Value;
use autoplug_fleet::testing::{ecus, PgSchema};
use autoplug_fleet::{EvidenceQuery, Finding, FleetStore, InventoryQuery};
use autoplug_image::Version;
use autoplug_vin::Vin;

const DAY_MS: i64 = 86_400_000;
/// The year the trips fall in ends here (ms since the epoch).
const YEAR_END_MS: i64 = 1_790_000_000_000;

/// A cheap deterministic spread (the same fleet every run).
fn mix(i: u64, salt: u64) -> u64 {
    let mut x = i.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ salt.wrapping_mul(0xD1B5_4A32_D192_ED03);
    x ^= x >> 31;
    x = x.wrapping_mul(0xBF58_476D_1CE4_E5B9);
    x ^ (x >> 29)
}

fn cruise_version(i: u64) -> (u32, u32, u32) {
    match mix(i, 1) % 100 {
        0..=34 => (1, 0, 0),
        35..=64 => (1, 0, 2),
        _ => (1, 1, 0),
    }
}

fn fill(url: &str, vehicles: u64) -> Result<(), postgres::Error> {
    let mut client = postgres::Client::connect(url, postgres::NoTls)?;
    let vin = |i: u64| {
        Vin::with_check_digit(&format!(
            "JA3AP47H0Y{}{:06}",
            (b'A' + (i / 1_000_000) as u8) as char,
            i % 1_000_000
        ))
        .expect("a VIN")
        .to_string()
    };
    let mut w = client
        .copy_in("COPY vehicles (vin, first_seen_ms, last_seen_ms, inventory_at_ms) FROM STDIN")?;
    for i in 0..vehicles {
        writeln!(
            w,
            "{}\t{}\t{}\t{}",
            vin(i),
            YEAR_END_MS - 400 * DAY_MS,
            YEAR_END_MS,
            YEAR_END_MS - 30 * DAY_MS
        )
        .expect("COPY");
    }
    w.finish()?;
    let mut w = client.copy_in(
        "COPY ecus (vin, ecu, node, part_number, software_version, sw_major, sw_minor, sw_patch, hardware_version, serial, reported_at_ms) FROM STDIN",
    )?;
    for i in 0..vehicles {
        let v = vin(i);
        let hardware = if mix(i, 2) % 100 < 3 {
            "NUCLEO-F446RE-B"
        } else {
            "NUCLEO-F446RE"
        };
        for (ecu, node) in ecus() {
            let (ma, mi, pa) = if ecu == "cruise" {
                cruise_version(i)
            } else {
                (1, 0, (mix(i, u64::from(node)) % 4) as u32)
            };
            writeln!(
                w,
                "{v}\t{ecu}\t{node}\tAP-{}-0001\t{ma}.{mi}.{pa}\t{ma}\t{mi}\t{pa}\t{hardware}\tSN{node:02}{i:08}\t{}",
                ecu.to_uppercase(),
                YEAR_END_MS - 30 * DAY_MS
            )
            .expect("COPY");
        }
    }
    w.finish()?;
    let mut w = client.copy_in(
        "COPY trips (vin, trip, started_at_ms, ended_at_ms, end_reason, distance_m, duration_s, fuel_used_l, max_speed_kmh, abs_interventions, shifts, cruise_time_s, stats, received_at_ms) FROM STDIN",
    )?;
    let ended = |i: u64| YEAR_END_MS - (mix(i, 3) % 365) as i64 * DAY_MS;
    for i in 0..vehicles {
        let end = ended(i);
        writeln!(
            w,
            "{}\t1\t{}\t{end}\tbus_silent\t14000\t600\t0.9\t110\t0\t12\t300\t{{}}\t{end}",
            vin(i),
            end - 600_000
        )
        .expect("COPY");
    }
    w.finish()?;
    let mut w = client.copy_in(
        "COPY verdicts (vin, trip, ecu, routine, verdict, number, unit, evidence, judged_at_ms) FROM STDIN",
    )?;
    for i in 0..vehicles {
        let faulty = cruise_version(i) == (1, 1, 0) && mix(i, 4) % 100 < 2;
        let (verdict, number) = if faulty { ("faulty", 4.8) } else { ("ok", 0.4) };
        writeln!(
            w,
            "{}\t1\tcruise\tspeed hold\t{verdict}\t{number}\tkm/h rms\tcruise engaged 300 s\t{}",
            vin(i),
            ended(i)
        )
        .expect("COPY");
    }
    w.finish()?;
    let mut w = client.copy_in(
        "COPY dtcs (vin, trip, ecu, code, status, description, reported_at_ms) FROM STDIN",
    )?;
    for i in (0..vehicles).filter(|i| mix(*i, 5).is_multiple_of(100)) {
        writeln!(
            w,
            "{}\t1\tcruise\tU0140-87\t9\tlost communication with the body control module\t{}",
            vin(i),
            ended(i)
        )
        .expect("COPY");
    }
    w.finish()?;
    client.batch_execute("ANALYZE")?;
    Ok(())
}

fn main() {
    let vehicles: u64 = std::env::args()
        .nth(1)
        .map(|a| a.parse().expect("a number of vehicles"))
        .unwrap_or(1_000_000);
    let schema = PgSchema::new();
    let mut store = FleetStore::open(&schema.url).expect("the fleet schema");
    let started = Instant::now();
    fill(&schema.url, vehicles).expect("the synthetic fleet");
    let fill_s = started.elapsed().as_secs_f64();
    let size = store
        .db()
        .query("SELECT pg_size_pretty(sum(pg_total_relation_size(quote_ident(table_name)))::bigint) FROM information_schema.tables WHERE table_schema = current_schema()", &[])
        .ok()
        .and_then(|r| r.first().and_then(|r| r.first().and_then(|v| v.text().map(str::to_string))))
        .unwrap_or_default();
    println!(
        "recall: {vehicles} vehicles, {} ECU rows, {vehicles} trips and verdicts, filled by COPY in {fill_s:.1} s ({size} with indexes), {}",
        vehicles * 9,
        store.name()
    );

    let version = |s: &str| Some(s.parse::<Version>().expect("a version"));
    let inventory = [
        (
            "part AP-CRUISE-0001, software 1.1.0 to 1.1.0",
            InventoryQuery {
                part_number: Some("AP-CRUISE-0001".into()),
                software_from: version("1.1.0"),
                software_to: version("1.1.0"),
                ..InventoryQuery::default()
            },
        ),
        (
            "ECU cruise, hardware NUCLEO-F446RE-B",
            InventoryQuery {
                ecu: Some("cruise".into()),
                hardware_version: Some("NUCLEO-F446RE-B".into()),
                ..InventoryQuery::default()
            },
        ),
        (
            "part AP-CRUISE-0001, serials SN1300010000 to SN1300010999",
            InventoryQuery {
                part_number: Some("AP-CRUISE-0001".into()),
                serial_from: Some("SN1300010000".into()),
                serial_to: Some("SN1300010999".into()),
                ..InventoryQuery::default()
            },
        ),
    ];
    let evidence = [
        (
            "cruise judged faulty in the last 30 days",
            EvidenceQuery {
                finding: Finding::Faulty,
                ecu: Some("cruise".into()),
                since_ms: YEAR_END_MS - 30 * DAY_MS,
                until_ms: YEAR_END_MS + 1,
            },
        ),
        (
            "trouble code U0140 in the year",
            EvidenceQuery {
                finding: Finding::Dtc("U0140".into()),
                ecu: None,
                since_ms: YEAR_END_MS - 366 * DAY_MS,
                until_ms: YEAR_END_MS + 1,
            },
        ),
    ];
    let median = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    for (name, query) in &inventory {
        let mut times = Vec::new();
        let mut hits = 0;
        for _ in 0..5 {
            let t = Instant::now();
            hits = store.recall_by_inventory(query).expect("a recall").len();
            times.push(t.elapsed().as_secs_f64() * 1e3);
        }
        let (sql, params) = FleetStore::inventory_sql(query);
        report(&mut store, name, hits, median(times), &sql, &params);
    }
    for (name, query) in &evidence {
        let mut times = Vec::new();
        let mut hits = 0;
        for _ in 0..5 {
            let t = Instant::now();
            hits = store.recall_by_evidence(query).expect("a recall").len();
            times.push(t.elapsed().as_secs_f64() * 1e3);
        }
        let (sql, params) = FleetStore::evidence_sql(query);
        report(&mut store, name, hits, median(times), &sql, &params);
    }
    if std::env::var_os("AUTOPLUG_BENCH_KEEP").is_some() {
        println!("(schema kept: {})", schema.url);
        std::mem::forget(schema);
    }
}

fn report(store: &mut FleetStore, name: &str, hits: usize, ms: f64, sql: &str, params: &[Value]) {
    println!("\n{name}: {hits} vehicles in {ms:.1} ms (median of 5)");
    match store
        .db()
        .query(&format!("EXPLAIN (ANALYZE, BUFFERS) {sql}"), params)
    {
        Ok(rows) => {
            for row in rows {
                if let Some(line) = row.first().and_then(|v| v.text()) {
                    println!("    {line}");
                }
            }
        }
        Err(e) => println!("    (no plan: {e})"),
    }
}
