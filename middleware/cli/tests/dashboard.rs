//! `autoplug dashboard` as a user starts it: the data folder with its firmware library, the
//! page, the write token, and what the API answers to good and bad requests. (The page
//! itself is driven in a real browser by scripts/dashboard-test.)

mod common;

use std::io::{Read, Write};
use std::process::{Command, Stdio};
use std::time::Duration;

const TOKEN: &str = "dashboard-test-token-0001";

type Dashboard = common::Running;

fn start(data: &std::path::Path) -> Dashboard {
    start_with(data, &[])
}

fn start_with(data: &std::path::Path, extra: &[&str]) -> Dashboard {
    launch(dashboard_command(data, extra))
}

fn dashboard_command(data: &std::path::Path, extra: &[&str]) -> Command {
    let mut command = Command::new(env!("CARGO_BIN_EXE_autoplug"));
    command
        .args(["dashboard", "--listen", "127.0.0.1:0", "--duration", "120"])
        .args(extra)
        .arg("--data")
        .arg(data)
        .arg("--token")
        .arg(TOKEN)
        .stdout(Stdio::piped())
        .stderr(Stdio::null());
    command
}

fn launch(command: Command) -> Dashboard {
    common::launch_dashboard(command, TOKEN)
}

/// One HTTP request: the status and the body.
fn request(
    addr: &str,
    method: &str,
    path: &str,
    token: Option<&str>,
    body: &[u8],
) -> (u16, String) {
    let mut stream = std::net::TcpStream::connect(addr).expect("connect");
    stream
        .set_read_timeout(Some(Duration::from_secs(10)))
        .unwrap();
    let auth = token.map_or(String::new(), |t| format!("Authorization: Bearer {t}\r\n"));
    write!(
        stream,
        "{method} {path} HTTP/1.1\r\nHost: {addr}\r\n{auth}Content-Type: application/json\r\nContent-Length: {}\r\nConnection: close\r\n\r\n",
        body.len()
    )
    .unwrap();
    stream.write_all(body).unwrap();
    let mut response = String::new();
    stream
        .read_to_string(&mut response)
        .unwrap_or_else(|e| panic!("{method} {path}: {e}"));
    let status = response[9..12].parse().expect("status");
    let body = response
        .split_once("\r\n\r\n")
        .map_or(String::new(), |(_, b)| b.to_string());
    (status, body)
}

fn json(body: &str) -> serde_json::Value {
    // A chunked body (a download) is not asked for here: the answers are small JSON.
    serde_json::from_str(body).unwrap_or_else(|e| panic!("JSON ({e}): {body}"))
}

#[test]
fn the_dashboard_serves_its_page_takes_writes_only_with_the_token_and_says_what_was_wrong() {
    let dir = tempfile::tempdir().unwrap();
    let dash = start(dir.path());
    let addr = dash.addr.as_str();

    // The data folder: the database, the recordings, the library with the demo images.
    for name in [
        "cruise-1.1.0-faulty.img",
        "cruise-1.2.0.img",
        "abs-1.1.0-faulty.img",
        "abs-1.2.0.img",
    ] {
        assert!(dir.path().join("images").join(name).is_file(), "{name}");
    }
    let (status, page) = request(addr, "GET", "/car", None, b"");
    assert_eq!(status, 200);
    assert!(
        page.contains("<html") || page.contains("<!doctype html>"),
        "{page}"
    );
    let (_, info) = request(addr, "GET", "/api/info", None, b"");
    assert_eq!(json(&info)["write"], true);
    let (_, images) = request(addr, "GET", "/api/images", None, b"");
    let images = json(&images);
    assert_eq!(images.as_array().unwrap().len(), 4);
    assert!(images
        .as_array()
        .unwrap()
        .iter()
        .any(|i| i["name"] == "cruise-1.1.0-faulty.img"
            && i["variant"] == "faulty"
            && i["node"] == 13));

    // Writes: refused without the token or with a wrong one.
    let (status, body) = request(addr, "POST", "/api/recording", None, br#"{"on":true}"#);
    assert_eq!(status, 401, "{body}");
    assert!(json(&body)["error"].as_str().unwrap().contains("token"));
    let (status, _) = request(
        addr,
        "POST",
        "/api/recording",
        Some("not-the-token-at-all"),
        br#"{"on":true}"#,
    );
    assert_eq!(status, 401);

    // Bad requests get the reason, and the server goes on.
    let bad: [(&str, &[u8], u16, &str); 6] = [
        ("/api/recording", b"{\"on\":", 400, "body"),
        ("/api/ecus/radio/clear-dtcs", b"", 409, "radio"),
        (
            "/api/ecus/cruise/flash",
            b"this is not an image",
            409,
            "not a firmware image",
        ),
        (
            "/api/ecus/cruise/flash?image=..%2Fsecret.img",
            b"",
            400,
            "file name",
        ),
        (
            "/api/ecus/cruise/flash?image=nothing.img",
            b"",
            404,
            "no file",
        ),
        (
            "/api/ecus/abs/flash?image=cruise-1.2.0.img",
            b"",
            409,
            "not for abs",
        ),
    ];
    for (path, body, expected, says) in bad {
        let (status, answer) = request(addr, "POST", path, Some(TOKEN), body);
        assert_eq!(status, expected, "{path}: {answer}");
        let error = json(&answer)["error"].as_str().unwrap().to_string();
        assert!(error.contains(says), "{path}: {error}");
    }
    // A release cut short, or with bytes after it, is refused before it goes on the bus
    // (whichever of its images the ECU would have been sent).
    let release = std::fs::read(dir.path().join("images").join("cruise-1.2.0.img")).unwrap();
    let mut trailing = release.clone();
    trailing.extend_from_slice(b"junk after the release");
    for (body, says) in [
        (
            &release[..release.len() - 1],
            "not a firmware image or release",
        ),
        (&trailing[..], "not a firmware image or release"),
    ] {
        let (status, answer) = request(addr, "POST", "/api/ecus/cruise/flash", Some(TOKEN), body);
        assert_eq!(status, 409, "{answer}");
        assert!(answer.contains(says), "{answer}");
    }
    let (status, answer) = request(
        addr,
        "POST",
        "/api/road",
        Some(TOKEN),
        br#"{"mu_left":0.0,"mu_right":1.0}"#,
    );
    assert_eq!(status, 409, "{answer}");
    assert!(answer.contains("outside"), "{answer}");

    // With the token: record, clear the codes, change the road.
    let (status, answer) = request(
        addr,
        "POST",
        "/api/recording",
        Some(TOKEN),
        br#"{"on":true}"#,
    );
    assert_eq!(status, 200, "{answer}");
    let (status, answer) = request(addr, "POST", "/api/ecus/all/clear-dtcs", Some(TOKEN), b"");
    assert_eq!(status, 200, "{answer}");
    assert_eq!(
        json(&answer)["ecus"].as_array().unwrap().len(),
        autoplug_can::Node::ECUS.len()
    );
    let (status, _) = request(
        addr,
        "POST",
        "/api/road",
        Some(TOKEN),
        br#"{"mu_left":1.0,"mu_right":0.2}"#,
    );
    assert_eq!(status, 200);
    // The simulator steers the dashboard's car along its track (the handling circuit);
    // a body that is not a switch is refused with the reason, and so is a missing token.
    let (status, answer) = request(
        addr,
        "POST",
        "/api/road/steering",
        Some(TOKEN),
        br#"{"along_road":"yes"}"#,
    );
    assert_eq!(status, 422, "{answer}");
    assert!(answer.contains("along_road"), "{answer}");
    let (status, _) = request(
        addr,
        "POST",
        "/api/road/steering",
        None,
        br#"{"along_road":true}"#,
    );
    assert_eq!(status, 401);
    let mut steering = (0, String::new());
    for _ in 0..50 {
        // The session learns the car has a track from the car's first report.
        steering = request(
            addr,
            "POST",
            "/api/road/steering",
            Some(TOKEN),
            br#"{"along_road":true}"#,
        );
        if steering.0 == 200 {
            break;
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    assert_eq!(steering.0, 200, "{}", steering.1);
    // A verdict is reset per ECU (the token needed, the ECU named rightly).
    let (status, _) = request(addr, "POST", "/api/ecus/abs/reset-verdict", None, b"");
    assert_eq!(status, 401);
    let (status, answer) = request(
        addr,
        "POST",
        "/api/ecus/abs/reset-verdict",
        Some(TOKEN),
        b"",
    );
    assert_eq!(
        (status, json(&answer)["ecus"][0].as_str()),
        (200, Some("abs")),
        "{answer}"
    );
    let (status, answer) = request(
        addr,
        "POST",
        "/api/ecus/brakes/reset-verdict",
        Some(TOKEN),
        b"",
    );
    assert_eq!(status, 409, "{answer}");
    assert!(answer.contains("brakes"), "{answer}");
    // The session shows them: the recording grows, the clear is reported, the road changed.
    let mut session = serde_json::Value::Null;
    for _ in 0..100 {
        std::thread::sleep(Duration::from_millis(100));
        let (_, state) = request(addr, "GET", "/api/state", None, b"");
        session = json(&state)["session"].clone();
        let cleared = session["events"].as_array().is_some_and(|e| {
            e.iter()
                .any(|e| e["text"].as_str().unwrap().contains("cleared"))
        });
        if cleared && session["recording"]["frames"].as_u64().unwrap_or(0) > 1000 {
            break;
        }
    }
    assert!(
        session["recording"]["frames"].as_u64().unwrap() > 1000,
        "{session}"
    );
    assert_eq!(session["driver"]["mu_right"], 0.2, "{session}");
    assert_eq!(session["driver"]["on_track"], true, "{session}");
    assert_eq!(session["driver"]["steers_along_road"], true, "{session}");
    assert_eq!(session["source"]["drive"], true);
    assert_eq!(
        session["inventory"].as_array().unwrap().len(),
        autoplug_can::Node::ECUS.len(),
        "{session}"
    );
    // F1A0 of every ECU: the virtual car's ECUs start from a confirmed slot A.
    for row in session["inventory"].as_array().unwrap() {
        assert_eq!(row["slot"], "A", "{row}");
        assert_eq!(row["boot_state"], "confirmed", "{row}");
    }
    let (status, answer) = request(
        addr,
        "POST",
        "/api/recording",
        Some(TOKEN),
        br#"{"on":false}"#,
    );
    assert_eq!(status, 200, "{answer}");
    let stopped = json(&answer);
    let file = stopped["files"][0].as_str().unwrap().to_string();
    assert!(stopped["frames"].as_u64().unwrap() > 1000);
    let (status, list) = request(addr, "GET", "/api/recordings", None, b"");
    assert_eq!(status, 200);
    assert!(list.contains(&file), "{list}");
    let (status, _) = request(addr, "GET", &format!("/api/recordings/{file}"), None, b"");
    assert_eq!(status, 200);
    let recorded = autoplug_logs::open(dir.path().join("recordings").join(&file))
        .unwrap()
        .count();
    assert!(recorded as u64 >= stopped["frames"].as_u64().unwrap());

    // The server went on through all of it.
    let (status, _) = request(addr, "GET", "/api/info", None, b"");
    assert_eq!(status, 200);
}

#[test]
fn a_recorded_log_plays_pauses_changes_speed_and_seeks_from_the_page() {
    let dir = tempfile::tempdir().unwrap();
    let rec = dir.path().join("rec");
    let recorded = Command::new(env!("CARGO_BIN_EXE_autoplug"))
        .args([
            "gateway",
            "--bus",
            "virtual:../../scenarios/stop-100-dry.toml",
            "--fast",
            "--quiet",
            "--no-db",
            "--record",
        ])
        .arg(&rec)
        .output()
        .unwrap();
    assert!(recorded.status.success(), "{recorded:?}");
    let log = std::fs::read_dir(&rec)
        .unwrap()
        .next()
        .unwrap()
        .unwrap()
        .path();
    let dash = start_with(&dir.path().join("data"), &["--log", log.to_str().unwrap()]);
    let addr = dash.addr.as_str();
    let replay = |body: &str| request(addr, "POST", "/api/replay", Some(TOKEN), body.as_bytes());
    let session = || json(&request(addr, "GET", "/api/state", None, b"").1)["session"].clone();

    let (status, answer) = replay(r#"{"action":"speed","speed":4}"#);
    assert_eq!(status, 200, "{answer}");
    let duration = json(&answer)["duration_s"].as_f64().unwrap();
    assert!(duration > 5.0, "{answer}");
    std::thread::sleep(Duration::from_millis(500));
    let moving = session()["replay"]["position_s"].as_f64().unwrap();
    assert!(
        moving > 1.0,
        "at 4x, 0.5 s of wall time is about 2 s of the log: {moving}"
    );

    let (status, _) = replay(r#"{"action":"pause"}"#);
    assert_eq!(status, 200);
    // The session's state is written twice a second: read it after a write that came
    // after the pause.
    std::thread::sleep(Duration::from_millis(1100));
    let paused = session()["replay"]["position_s"].as_f64().unwrap();
    std::thread::sleep(Duration::from_millis(500));
    assert_eq!(
        session()["replay"]["position_s"].as_f64().unwrap(),
        paused,
        "paused: the log's clock stands"
    );

    let (status, answer) = replay(r#"{"action":"seek","t":2.5}"#);
    assert_eq!(status, 200, "{answer}");
    let (status, _) = replay(r#"{"action":"play"}"#);
    assert_eq!(status, 200);
    let mut after = serde_json::Value::Null;
    for _ in 0..50 {
        std::thread::sleep(Duration::from_millis(50));
        after = session();
        if after["replay"]["position_s"].as_f64().unwrap() > 2.5 {
            break;
        }
    }
    let position = after["replay"]["position_s"].as_f64().unwrap();
    assert!(
        position > 2.5 && position < paused.max(3.0) + 2.0,
        "{after}"
    );
    assert!(
        after["events"].to_string().contains("jumped to 2.5 s"),
        "{after}"
    );

    // Bad controls get the reason; a replay cannot be flashed or driven.
    for (body, says) in [
        (r#"{"action":"seek","t":-1}"#, "outside the log"),
        (r#"{"action":"speed","speed":1000}"#, "outside"),
        (r#"{"action":"rewind"}"#, "body"),
    ] {
        let (status, answer) = replay(body);
        assert!(
            status == 409 || status == 400 || status == 422,
            "{body}: {status} {answer}"
        );
        assert!(
            json(&answer)["error"].as_str().unwrap().contains(says),
            "{body}: {answer}"
        );
    }
    let (status, answer) = request(
        addr,
        "POST",
        "/api/ecus/cruise/clear-dtcs",
        Some(TOKEN),
        b"",
    );
    assert_eq!(status, 409);
    assert!(answer.contains("only listens"), "{answer}");
    assert_eq!(session()["source"]["kind"], "replay");
}

/// The descriptors `pid` has open.
#[cfg(target_os = "linux")]
fn descriptors(pid: u32) -> usize {
    std::fs::read_dir(format!("/proc/{pid}/fd")).map_or(0, |dir| dir.count())
}

/// A GET on a new connection, answered within a second: the status.
fn get_within_a_second(addr: &str, path: &str) -> u16 {
    let mut stream = std::net::TcpStream::connect(addr).expect("connect");
    stream
        .set_read_timeout(Some(Duration::from_secs(1)))
        .unwrap();
    write!(
        stream,
        "GET {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n"
    )
    .unwrap();
    let mut response = Vec::new();
    stream
        .read_to_end(&mut response)
        .unwrap_or_else(|e| panic!("GET {path} not answered within a second: {e}"));
    String::from_utf8_lossy(&response)[9..12]
        .parse()
        .expect("a status")
}

#[cfg(target_os = "linux")]
#[test]
fn idle_connections_lock_no_one_out_and_their_descriptors_come_back() {
    use std::os::unix::process::CommandExt;
    // This process holds the idle connections: it needs the descriptors for them.
    rlimit::increase_nofile_limit(u64::MAX).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let mut command = dashboard_command(dir.path(), &[]);
    // The dashboard with the usual limit of 1024 descriptors, which it cannot raise.
    unsafe {
        command.pre_exec(|| rlimit::setrlimit(rlimit::Resource::NOFILE, 1024, 1024));
    }
    let dash = launch(command);
    let addr = dash.addr.as_str();
    let pid = dash.child.id();
    assert_eq!(get_within_a_second(addr, "/api/state"), 200);
    let before = descriptors(pid);

    // 2,000 connections that say nothing, then a slow one that sends half a request.
    let idle: Vec<std::net::TcpStream> = (0..2000)
        .map(|_| std::net::TcpStream::connect(addr).expect("the server accepts"))
        .collect();
    let mut slow = std::net::TcpStream::connect(addr).unwrap();
    slow.write_all(b"GET /api/state HTTP/1.1\r\nHost: ")
        .unwrap();
    // Whoever comes now gets the page and the state, within a second.
    for path in ["/", "/api/state", "/api/catalog"] {
        assert_eq!(get_within_a_second(addr, path), 200, "{path}");
    }
    let held = descriptors(pid);
    assert!(
        held < 1024,
        "{held} descriptors with 2,000 idle connections"
    );

    // The server lets go of connections that send no request in time (5 s), the half
    // request too, without the clients closing them.
    let give_up = std::time::Instant::now() + Duration::from_secs(10);
    while descriptors(pid) > before + 8 && std::time::Instant::now() < give_up {
        std::thread::sleep(Duration::from_millis(100));
    }
    let after = descriptors(pid);
    assert!(
        after <= before + 8,
        "{before} descriptors before, {after} after the deadline"
    );
    slow.set_read_timeout(Some(Duration::from_secs(1))).unwrap();
    let mut rest = Vec::new();
    let closed = slow.read_to_end(&mut rest).is_ok();
    assert!(closed, "the half request's connection was closed");
    drop(idle);
    assert_eq!(get_within_a_second(addr, "/api/state"), 200);
}
