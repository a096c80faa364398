//! `autoplug gateway` on the virtual car: the recording, the trips in the database, and
//! what `autoplug trips` and `autoplug log export` make of them; a `kill -9` in the middle
//! leaves a readable recording and a consistent database.

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use autoplug_store::{SqliteStore, TripStatus, TripStore};
use autoplug_virtual_car::car::VirtualCar;
use autoplug_virtual_car::scenario::Scenario;
use autoplug_virtual_car::socketcand::SocketcandServer;

mod common;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn autoplug(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_autoplug"))
        .args(args)
        .current_dir(root())
        .output()
        .expect("the autoplug binary runs")
}

/// `autoplug gateway --bus BUS --fast --quiet` recording into `DIR/rec` and storing its
/// trips in `DIR/trips.db`, with `extra` arguments: the output, the recording folder and
/// the database.
fn record_fast(bus: &str, dir: &Path, extra: &[&str]) -> (Output, PathBuf, PathBuf) {
    let (rec, db) = (dir.join("rec"), dir.join("trips.db"));
    let mut args = vec![
        "gateway",
        "--bus",
        bus,
        "--fast",
        "--quiet",
        "--record",
        rec.to_str().unwrap(),
        "--db",
        db.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    (autoplug(&args), rec, db)
}

/// `autoplug replay` of the recording's (first) file into `db`, which must succeed.
fn replay_recording(rec: &Path, db: &Path) {
    let file = std::fs::read_dir(rec)
        .unwrap()
        .next()
        .unwrap()
        .unwrap()
        .path();
    let replay = autoplug(&[
        "replay",
        file.to_str().unwrap(),
        "--db",
        db.to_str().unwrap(),
    ]);
    assert!(replay.status.success(), "{replay:?}");
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

#[test]
fn the_live_gateway_records_the_bus_and_stores_the_trip() {
    let dir = tempfile::tempdir().unwrap();
    let (output, rec, db) = record_fast(
        "virtual:scenarios/stop-100-dry.toml",
        dir.path(),
        &["--vehicle", "JA3AP00TEST000001"],
    );
    let stdout = text(&output.stdout);
    assert!(output.status.success(), "{output:?}");
    assert!(stdout.contains("stored trip(s) 1"), "{stdout}");

    // The recording: one file, every frame of the run, readable strictly.
    let files: Vec<_> = std::fs::read_dir(&rec).unwrap().collect();
    assert_eq!(files.len(), 1, "{stdout}");
    let file = files[0].as_ref().unwrap().path();
    let frames = autoplug_logs::open(&file)
        .unwrap()
        .collect::<Result<Vec<_>, _>>()
        .unwrap();
    assert!(stdout.contains(&format!("recording: {} frames", frames.len())));
    assert!(frames.len() > 5000, "8 s of bus: {}", frames.len());

    // The trip, as the database keeps it and as `trips` shows it.
    let store = SqliteStore::open(&db).unwrap();
    let trips = store.trips(Some("JA3AP00TEST000001")).unwrap();
    assert_eq!(trips.len(), 1);
    let trip = &trips[0];
    assert_eq!(trip.status, TripStatus::Closed);
    assert!(trip.stats.hard_brakings == 1 && trip.stats.abs_interventions >= 1);
    let detail = store.trip(trip.id).unwrap().unwrap();
    assert_eq!(
        detail.verdicts.len(),
        autoplug_can::Node::ECUS.len(),
        "{detail:?}"
    );
    // A stop from 100 km/h never engages cruise: its routine had nothing to judge, and
    // the trip says so rather than a green OK it did not earn.
    for v in &detail.verdicts {
        let expected = if v.ecu == "cruise" {
            "not exercised"
        } else {
            "ok"
        };
        assert_eq!(v.verdict, expected, "{v:?}");
    }
    let speed = store.series(trip.id, "Vehicle.Speed").unwrap();
    assert_eq!(speed.len(), 8, "8 s in 1 s buckets: {speed:?}");
    assert!(speed[0].max >= 99.0 && speed[7].min == 0.0, "{speed:?}");

    let list = autoplug(&["trips", "list", "--db", db.to_str().unwrap()]);
    assert!(list.status.success(), "{list:?}");
    assert!(text(&list.stdout).contains("JA3AP00TEST000001"));
    let show = autoplug(&["trips", "show", "1", "--db", db.to_str().unwrap()]);
    let shown = text(&show.stdout);
    assert!(show.status.success(), "{show:?}");
    assert!(shown.contains("hard brakings    1"), "{shown}");
    assert!(shown.contains("abs"), "{shown}");
    let json = autoplug(&["trips", "show", "1", "--json", "--db", db.to_str().unwrap()]);
    let value: serde_json::Value = serde_json::from_slice(&json.stdout).unwrap();
    assert_eq!(value["row"]["stats"]["hard_brakings"], 1);

    // A trip that is not there, and a database that is not one: short, clear errors.
    let missing = autoplug(&["trips", "show", "7", "--db", db.to_str().unwrap()]);
    assert_eq!(missing.status.code(), Some(1));
    assert!(
        text(&missing.stderr).contains("there is no trip 7"),
        "{missing:?}"
    );
    let garbage = dir.path().join("garbage.db");
    std::fs::write(&garbage, vec![0x5Au8; 4096]).unwrap();
    let refused = autoplug(&["trips", "list", "--db", garbage.to_str().unwrap()]);
    assert_eq!(refused.status.code(), Some(1));
    let message = text(&refused.stderr);
    assert!(
        message.contains("garbage.db") && message.lines().count() == 1,
        "{message}"
    );

    // The recording exported to ASC: every frame, and no file left behind on refusal.
    let asc = dir.path().join("rec.asc");
    let export = autoplug(&[
        "log",
        "export",
        file.to_str().unwrap(),
        "--out",
        asc.to_str().unwrap(),
    ]);
    assert!(export.status.success(), "{export:?}");
    let exported = autoplug_logs::open(&asc)
        .unwrap()
        .collect::<Result<Vec<_>, _>>()
        .unwrap();
    assert_eq!(exported.len(), frames.len());
    for (a, b) in exported.iter().zip(&frames) {
        assert_eq!((a.id, a.data()), (b.id, b.data()));
    }
    let again = autoplug(&[
        "log",
        "export",
        file.to_str().unwrap(),
        "--out",
        asc.to_str().unwrap(),
    ]);
    assert!(text(&again.stderr).contains("already exists"), "{again:?}");
}

#[test]
fn replay_stores_the_same_trip_as_the_live_gateway() {
    let dir = tempfile::tempdir().unwrap();
    let (live, rec, db) = record_fast("virtual:scenarios/drive-cycle.toml", dir.path(), &[]);
    assert!(live.status.success(), "{live:?}");
    replay_recording(&rec, &db);
    let store = SqliteStore::open(&db).unwrap();
    let trips = store.trips(None).unwrap();
    assert_eq!(trips.len(), 2);
    assert_eq!(trips[0].stats, trips[1].stats, "live and replayed trips");
    let verdicts = |id| store.trip(id).unwrap().unwrap().verdicts;
    assert_eq!(verdicts(trips[0].id), verdicts(trips[1].id));
    assert!(trips[0].stats.shifts > 10 && trips[0].stats.fuel_used_l > 0.5);
}

/// The same with MF4 recordings: the trip replayed from the MF4 is the live one.
#[test]
fn an_mf4_recording_replays_to_the_same_trip() {
    let dir = tempfile::tempdir().unwrap();
    let (live, rec, db) = record_fast(
        "virtual:scenarios/drive-cycle.toml",
        dir.path(),
        &["--record-format", "mf4"],
    );
    assert!(live.status.success(), "{live:?}");
    let files: Vec<PathBuf> = std::fs::read_dir(&rec)
        .unwrap()
        .map(|f| f.unwrap().path())
        .collect();
    assert_eq!(files.len(), 1);
    assert!(
        files[0].extension().is_some_and(|e| e == "mf4"),
        "{files:?}"
    );
    assert!(std::fs::read(&files[0]).unwrap().starts_with(b"MDF     "));
    replay_recording(&rec, &db);
    let store = SqliteStore::open(&db).unwrap();
    let trips = store.trips(None).unwrap();
    assert_eq!(trips.len(), 2);
    assert_eq!(trips[0].stats, trips[1].stats, "live and replayed trips");
}

#[test]
fn kill_9_during_a_recording_leaves_a_readable_log_and_a_consistent_database() {
    kill_9_during_a_recording(&[]);
}

/// An MF4 recording killed: `UnFinMF`, read to its last flush.
#[test]
fn kill_9_during_an_mf4_recording_leaves_a_readable_file() {
    let bytes = kill_9_during_a_recording(&["--record-format", "mf4"]);
    assert!(bytes.starts_with(b"UnFinMF "));
}

/// The gateway recording the drive cycle at 20 x real time, killed after 3 s: a readable
/// recording (its bytes returned) and a consistent database.
fn kill_9_during_a_recording(extra: &[&str]) -> Vec<u8> {
    let dir = tempfile::tempdir().unwrap();
    let db = dir.path().join("trips.db");
    let rec = dir.path().join("rec");
    // The drive cycle at 20 x real time: 7.5 s of wall time, killed after 3 s.
    let mut child = Command::new(env!("CARGO_BIN_EXE_autoplug"))
        .args([
            "gateway",
            "--bus",
            "virtual:scenarios/drive-cycle.toml",
            "--speed",
            "20",
            "--quiet",
            "--record",
            rec.to_str().unwrap(),
            "--db",
            db.to_str().unwrap(),
        ])
        .args(extra)
        .current_dir(root())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let started = Instant::now();
    std::thread::sleep(Duration::from_secs(3));
    assert!(child.try_wait().unwrap().is_none(), "still running at 3 s");
    child.kill().unwrap(); // SIGKILL
    child.wait().unwrap();
    assert!(started.elapsed() < Duration::from_secs(7));

    // The recording: complete lines only, in time order, from the start of the run.
    let files: Vec<_> = std::fs::read_dir(&rec).unwrap().collect();
    assert_eq!(files.len(), 1);
    let frames = autoplug_logs::open(files[0].as_ref().unwrap().path())
        .unwrap()
        .collect::<Result<Vec<_>, _>>()
        .expect("every line of the killed recording reads");
    assert!(frames.len() > 1000, "{} frames", frames.len());
    assert!(frames.windows(2).all(|w| w[0].t_us <= w[1].t_us));

    // The database: intact, the trip marked interrupted with a checkpoint's statistics.
    let conn = rusqlite::Connection::open(&db).unwrap();
    let check: String = conn
        .query_row("PRAGMA integrity_check", [], |r| r.get(0))
        .unwrap();
    assert_eq!(check, "ok");
    drop(conn);
    let store = SqliteStore::open(&db).unwrap();
    let trips = store.trips(None).unwrap();
    assert_eq!(trips.len(), 1, "{trips:?}");
    assert_eq!(trips[0].status, TripStatus::Interrupted);
    assert!(trips[0].stats.distance_m > 0.0, "{:?}", trips[0].stats);
    // The checkpoint is of frames the gateway had seen; the recording is at most 100 ms
    // behind them.
    let last_frame_s = frames.last().unwrap().t_us as f64 * 1e-6;
    assert!(trips[0].stats.end_us as f64 * 1e-6 <= last_frame_s + 0.2);
    std::fs::read(files[0].as_ref().unwrap().path()).unwrap()
}

#[test]
fn a_transmitting_gateway_keeps_the_inventory_and_the_trouble_codes_a_replay_finds_again() {
    let dir = tempfile::tempdir().unwrap();
    let scenario = dir.path().join("console-silent.toml");
    std::fs::write(
        &scenario,
        "name = \"console-silent\"\nduration_s = 20.0\nvin = \"JA3AP47H3YF000777\"\n\
         [factory]\ncruise = \"1.1.0\"\n[[at]]\nt_s = 3.0\nfault = { silence = \"Console\" }\n",
    )
    .unwrap();
    let bus = format!("virtual:{}", scenario.display());
    let (live, rec, db) = record_fast(&bus, dir.path(), &["--transmit", "--dtc-interval", "5"]);
    let stdout = text(&live.stdout);
    assert!(live.status.success(), "{live:?}");
    assert!(stdout.contains("AP-CRUISE-0001"), "{stdout}");
    assert!(
        stdout.contains("DTCs engine") && stdout.contains("U0140-87"),
        "{stdout}"
    );

    let store = SqliteStore::open(&db).unwrap();
    // The vehicle is known by the VIN its ECUs answer (F190); the cruise left the factory
    // with other software than the rest.
    assert!(
        stdout.contains("vehicle: VIN JA3AP47H3YF000777"),
        "{stdout}"
    );
    let inventory = store.inventory("JA3AP47H3YF000777").unwrap();
    assert_eq!(
        inventory.len(),
        autoplug_can::Node::ECUS.len(),
        "{inventory:?}"
    );
    assert!(inventory.iter().all(|(e, _, _)| e.part_number.is_some()
        && e.software_version.as_deref()
            == Some(if e.ecu == "cruise" { "1.1.0" } else { "1.0.0" })));
    let trip = store.trips(None).unwrap().remove(0);
    assert_eq!(trip.vehicle, "JA3AP47H3YF000777");
    let detail = store.trip(trip.id).unwrap().unwrap();
    let lost: Vec<&str> = detail
        .dtcs
        .iter()
        .filter(|d| d.code == "U0140-87")
        .map(|d| d.ecu.as_str())
        .collect();
    assert_eq!(lost, ["engine", "transmission"], "{:?}", detail.dtcs);
    assert!(detail.dtcs[0]
        .description
        .contains("lost communication with the Console"));
    // The console went silent for good: asking it did not hide that.
    let console = detail.verdicts.iter().find(|v| v.ecu == "console").unwrap();
    assert_eq!(console.verdict, "no data", "{console:?}");

    // The recording holds the requests and answers: its replay stores the same codes.
    replay_recording(&rec, &db);
    let trips = store.trips(None).unwrap();
    let replayed = store.trip(trips[0].id).unwrap().unwrap();
    assert_eq!(replayed.dtcs, detail.dtcs);
    assert_eq!(replayed.verdicts, detail.verdicts);
}

/// The virtual car served over socketcand in real time on a thread, as `virtual-car run
/// --socketcand --realtime` serves it, until `stop` or the scenario's end.
fn serve_car(
    server: SocketcandServer,
    scenario: Scenario,
    stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
) {
    use std::sync::atomic::Ordering;
    assert!(
        server.wait_for_raw_client(Duration::from_secs(5)),
        "no client in raw mode"
    );
    let mut car = VirtualCar::new(&scenario);
    let wall = Instant::now();
    let mut from_client = std::collections::VecDeque::new();
    while !car.finished() && !stop.load(Ordering::Relaxed) {
        car.tick();
        while let Some(client) = server.try_recv() {
            from_client.push_back(client.frame);
        }
        while let Some(frame) = from_client.front() {
            if !car.inject(*frame) {
                break;
            }
            from_client.pop_front();
        }
        for entry in car.take_log().iter().filter(|e| e.sender.is_some()) {
            server.broadcast(entry.t_us, &entry.frame, None);
        }
        if car.time_us() % 10_000 == 0 {
            if let Some(wait) = Duration::from_micros(car.time_us()).checked_sub(wall.elapsed()) {
                std::thread::sleep(wait);
            }
        }
    }
}

#[test]
fn the_gateway_on_socketcand_watches_the_car_and_talks_to_its_ecus() {
    let root = root();
    let scenario = Scenario::load(&root.join("scenarios/workshop.toml")).unwrap();
    let server = SocketcandServer::start("127.0.0.1:0").unwrap();
    let url = format!("socketcand://127.0.0.1:{}/can0", server.address().port());
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let car = {
        let stop = std::sync::Arc::clone(&stop);
        std::thread::spawn(move || serve_car(server, scenario, stop))
    };
    let output = autoplug(&[
        "gateway",
        "--bus",
        &url,
        "--duration",
        "3",
        "--no-db",
        "--quiet",
        "--transmit",
    ]);
    stop.store(true, std::sync::atomic::Ordering::Relaxed);
    car.join().unwrap();
    let stdout = text(&output.stdout);
    assert!(output.status.success(), "{output:?}");
    // About 1190 frames a second for 3 s of wall time, less the connection's start.
    let frames: u64 = stdout
        .lines()
        .find_map(|l| l.split_once(" frames, ").map(|(n, _)| n.parse().unwrap()))
        .unwrap();
    assert!(frames > 1500, "{stdout}");
    // Its tester read the nine ECUs' identification and trouble codes over the link.
    assert!(
        stdout.contains("AP-CRUISE-0001") && stdout.contains("AP-ABS-0001"),
        "{stdout}"
    );
    assert!(stdout.contains("DTCs abs at"), "{stdout}");
    // A live bus refuses pacing options.
    let paced = autoplug(&["gateway", "--bus", &url, "--speed", "2", "--no-db"]);
    assert_eq!(paced.status.code(), Some(1));
    assert!(
        text(&paced.stderr).contains("pace the virtual car only"),
        "{paced:?}"
    );
}

/// `autoplug gateway --web`: the live stream serves what the virtual car puts on the bus.
#[test]
fn the_gateway_serves_the_car_live_over_http_and_websocket() {
    use std::io::{Read, Write};
    let mut command = Command::new(env!("CARGO_BIN_EXE_autoplug"));
    command
        .args([
            "gateway",
            "--bus",
            "virtual:../../scenarios/drive-cycle.toml",
            "--web",
            "127.0.0.1:0",
            "--no-db",
            "--quiet",
            "--duration",
            "20",
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::null());
    let running = common::launch(command, "live stream on ws://", "/api/stream");
    let addr = running.addr.clone();
    let get = |path: &str| {
        let mut stream = std::net::TcpStream::connect(&addr).expect("connect");
        write!(
            stream,
            "GET {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n"
        )
        .expect("request");
        let mut response = String::new();
        stream.read_to_string(&mut response).expect("response");
        response
    };
    // The car runs in real time: within a few seconds the speed is on the stream.
    let mut state = String::new();
    for _ in 0..50 {
        std::thread::sleep(std::time::Duration::from_millis(200));
        state = get("/api/state");
        if state.contains("\"Vehicle.Speed\":") && !state.contains("\"Vehicle.Speed\":null") {
            break;
        }
    }
    drop(running);
    assert!(state.starts_with("HTTP/1.1 200"), "{state}");
    assert!(
        !state.contains("\"Vehicle.Speed\":null"),
        "the speed is live: {state}"
    );
    assert!(state.contains("\"frames\":"), "{state}");
}

/// `autoplug gateway ... | head`, standard error closed too: the reader going away ends
/// neither the run nor the trip; the gateway still stores it closed and exits 0.
#[test]
fn a_reader_gone_away_still_gets_the_trip_stored() {
    let dir = tempfile::tempdir().unwrap();
    let db = dir.path().join("trips.db");
    let mut child = Command::new(env!("CARGO_BIN_EXE_autoplug"))
        .args([
            "gateway",
            "--bus",
            "virtual:scenarios/stop-100-dry.toml",
            "--fast",
            "--db",
        ])
        .arg(&db)
        .args(["--vehicle", "JA3AP00TEST000001"])
        .current_dir(root())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the autoplug binary runs");
    drop(child.stdout.take());
    drop(child.stderr.take());
    let status = child.wait().expect("it ends");
    assert!(status.success(), "{status:?}");
    let store = SqliteStore::open(&db).unwrap();
    let trips = store.trips(Some("JA3AP00TEST000001")).unwrap();
    assert_eq!(trips.len(), 1);
    assert_eq!(trips[0].status, TripStatus::Closed);
}
