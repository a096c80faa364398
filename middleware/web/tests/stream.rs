//! The server against a real WebSocket client: what the stream sends, what it refuses, and
//! that a bad client gets an error while the server goes on.

use std::sync::Arc;
use std::time::Duration;

use autoplug_can::{CanMessage, SteeringMsg, VehicleSpeedMsg};
use autoplug_gateway::CarState;
use autoplug_logs::{FdFlags, LogFrame};
use autoplug_web::{LiveTable, WebConfig, WebServer};
use futures_util::{SinkExt, StreamExt};
use serde_json::Value;
use tokio_tungstenite::tungstenite::client::IntoClientRequest;
use tokio_tungstenite::tungstenite::Message;

type Client =
    tokio_tungstenite::WebSocketStream<tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>>;

fn speed(t_ms: u64, kmh: f32) -> LogFrame {
    LogFrame::from_can(
        t_ms * 1000,
        0,
        &VehicleSpeedMsg { vehicle_speed: kmh }.frame(),
    )
}

fn server(max_clients: usize) -> (Arc<LiveTable>, WebServer) {
    let table = Arc::new(LiveTable::new());
    let mut config = WebConfig::loopback(0);
    config.max_clients = max_clients;
    let server = WebServer::start(config, table.clone(), None).expect("server");
    (table, server)
}

fn runtime() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .expect("runtime")
}

async fn connect(server: &WebServer) -> Client {
    let url = format!("ws://{}/api/stream", server.addr());
    tokio_tungstenite::connect_async(url)
        .await
        .expect("connect")
        .0
}

async fn next_json(client: &mut Client) -> Value {
    loop {
        let message = tokio::time::timeout(Duration::from_secs(5), client.next())
            .await
            .expect("a message within 5 s")
            .expect("open")
            .expect("no error");
        if let Message::Text(text) = message {
            return serde_json::from_str(&text).expect("JSON");
        }
    }
}

#[test]
fn the_stream_sends_the_catalog_everything_then_only_changes() {
    let (table, server) = server(8);
    let mut state = CarState::new();
    state.update(&speed(0, 42.0));
    table.publish(&state);
    runtime().block_on(async {
        let mut client = connect(&server).await;
        let catalog = next_json(&mut client).await;
        assert_eq!(catalog["type"], "catalog");
        let signals = catalog["signals"].as_array().expect("signals");
        let speed_info = signals
            .iter()
            .find(|s| s["path"] == "Vehicle.Speed")
            .expect("Vehicle.Speed");
        assert_eq!(speed_info["unit"], "km/h");
        assert_eq!(speed_info["name"], "VehicleSpeedMsg.VehicleSpeed");

        let first = next_json(&mut client).await;
        assert_eq!(first["type"], "update");
        assert_eq!(first["signals"]["Vehicle.Speed"], 42.0);
        assert!(first["signals"]["Vehicle.Chassis.SteeringWheel.Angle"].is_null());
        assert_eq!(first["bus"]["frames"], 1);
        let vehicle_speed = &first["messages"]["VehicleSpeedMsg"];
        assert_eq!(vehicle_speed["id"], 3);
        assert_eq!(vehicle_speed["count"], 1);
        assert_eq!(vehicle_speed["data"], "2A", "42 km/h");
        assert!(
            vehicle_speed["period_ms"].is_null(),
            "one frame: no period yet"
        );
        assert_eq!(first["messages"]["EngineMsg"]["count"], 0);
        assert_eq!(
            first["signals"].as_object().expect("map").len(),
            signals.len(),
            "the first update has every signal"
        );

        // The next frame changes the speed only.
        state.update(&speed(10, 43.0));
        table.publish(&state);
        let update = next_json(&mut client).await;
        let changed = update["signals"].as_object().expect("map");
        assert_eq!(changed.len(), 1, "{update}");
        assert_eq!(update["signals"]["Vehicle.Speed"], 43.0);
        assert_eq!(update["bus"]["frames"], 2);
        let messages = update["messages"].as_object().expect("messages");
        assert_eq!(messages.len(), 1, "only the message that came: {update}");
        assert_eq!(messages["VehicleSpeedMsg"]["count"], 2);
        assert_eq!(messages["VehicleSpeedMsg"]["period_ms"], 10.0);
        assert_eq!(messages["VehicleSpeedMsg"]["data"], "2B");
        assert!((update["t"].as_f64().expect("t") - 0.010).abs() < 1e-9);
        assert_eq!(update["bus"]["fd_frames"], 0);

        // A CAN FD frame on the speed's identifier (a log of another bus): counted as CAN FD,
        // and not taken for a speed.
        let fd = LogFrame::new_fd(20_000, 0, 3, false, &[99; 12], FdFlags::default())
            .expect("a CAN FD frame");
        state.update(&fd);
        state.update(&speed(30, 44.0));
        table.publish(&state);
        let update = next_json(&mut client).await;
        assert_eq!(update["bus"]["fd_frames"], 1, "{update}");
        assert_eq!(update["signals"]["Vehicle.Speed"], 44.0);
        assert_eq!(update["messages"]["VehicleSpeedMsg"]["count"], 3);

        // A message goes stale 3 periods after its last frame: null.
        state.update(&LogFrame::from_can(
            200_000,
            0,
            &SteeringMsg {
                steering_angle: 10.0,
            }
            .frame(),
        ));
        table.publish(&state);
        let update = next_json(&mut client).await;
        assert!(update["signals"]["Vehicle.Speed"].is_null(), "{update}");
    });
}

#[test]
fn many_changes_between_two_reads_arrive_as_one_update_with_the_latest_values() {
    let (table, server) = server(8);
    let mut state = CarState::new();
    runtime().block_on(async {
        let mut client = connect(&server).await;
        next_json(&mut client).await; // catalog
        next_json(&mut client).await; // everything
                                      // A thousand frames while the client is busy elsewhere.
        for i in 0..1000u64 {
            state.update(&speed(i, (i % 200) as f32));
            table.publish(&state);
        }
        tokio::time::sleep(Duration::from_millis(200)).await;
        let mut last = Value::Null;
        // What is waiting: at most a few updates (one per 50 ms), the last with 999 % 200.
        while let Ok(Some(Ok(Message::Text(text)))) =
            tokio::time::timeout(Duration::from_millis(300), client.next()).await
        {
            last = serde_json::from_str(&text).expect("JSON");
        }
        assert_eq!(last["signals"]["Vehicle.Speed"], 199.0, "{last}");
        assert_eq!(last["bus"]["frames"], 1000);
    });
}

#[test]
fn a_bad_message_gets_an_error_and_the_stream_goes_on() {
    let (_table, server) = server(8);
    runtime().block_on(async {
        let mut client = connect(&server).await;
        next_json(&mut client).await;
        next_json(&mut client).await;
        for bad in [
            Message::Text("not json".into()),
            Message::Text("{\"type\":\"launch\"}".into()),
            Message::Binary(vec![0xFF; 16].into()),
        ] {
            client.send(bad).await.expect("send");
            let answer = next_json(&mut client).await;
            assert_eq!(answer["type"], "error", "{answer}");
            assert!(!answer["error"].as_str().expect("text").is_empty());
        }
        client
            .send(Message::Text("{\"type\":\"ping\"}".into()))
            .await
            .expect("send");
        assert_eq!(next_json(&mut client).await["type"], "pong");
        // Over the size limit: the connection is closed, the server goes on.
        let _ = client.send(Message::Text("x".repeat(100_000).into())).await;
        let mut other = connect(&server).await;
        assert_eq!(next_json(&mut other).await["type"], "catalog");
    });
}

#[test]
fn foreign_origins_and_extra_clients_are_refused_with_a_reason() {
    let (_table, server) = server(2);
    runtime().block_on(async {
        let url = format!("ws://{}/api/stream", server.addr());
        let mut request = url.as_str().into_client_request().expect("request");
        request
            .headers_mut()
            .insert("Origin", "http://evil.example".parse().expect("header"));
        match tokio_tungstenite::connect_async(request).await {
            Err(tokio_tungstenite::tungstenite::Error::Http(response)) => {
                assert_eq!(response.status(), 403);
                let body =
                    String::from_utf8_lossy(response.body().as_deref().unwrap_or(&[])).to_string();
                assert!(body.contains("origin"), "{body}");
            }
            other => panic!("a foreign origin must be refused: {other:?}"),
        }
        // The server's own origin is fine.
        let mut request = url.as_str().into_client_request().expect("request");
        let own = format!("http://{}", server.addr());
        request
            .headers_mut()
            .insert("Origin", own.parse().expect("header"));
        let (mut first, _) = tokio_tungstenite::connect_async(request)
            .await
            .expect("own origin");
        next_json(&mut first).await;
        let mut second = connect(&server).await;
        next_json(&mut second).await;
        match tokio_tungstenite::connect_async(url.as_str()).await {
            Err(tokio_tungstenite::tungstenite::Error::Http(response)) => {
                assert_eq!(response.status(), 503);
            }
            other => panic!("a third stream must be refused: {other:?}"),
        }
        // A client that leaves frees its place.
        drop(first);
        tokio::time::sleep(Duration::from_millis(200)).await;
        let mut third = connect(&server).await;
        assert_eq!(next_json(&mut third).await["type"], "catalog");
    });
}

/// A plain HTTP/1.1 GET, the whole response (status line, headers, body).
fn http_get(server: &WebServer, path: &str) -> String {
    http_get_with(server, path, &format!("Host: {}\r\n", server.addr()))
}

/// The same with the given header lines (each ending in CRLF) instead of the `Host`.
fn http_get_with(server: &WebServer, path: &str, headers: &str) -> String {
    http(
        server,
        &format!("GET {path} HTTP/1.1\r\n{headers}Connection: close\r\n\r\n"),
    )
}

/// The whole response to a request written as it goes on the wire.
fn http(server: &WebServer, request: &str) -> String {
    use std::io::{Read, Write};
    let mut stream = std::net::TcpStream::connect(server.addr()).expect("connect");
    stream.write_all(request.as_bytes()).expect("request");
    let mut response = String::new();
    stream.read_to_string(&mut response).expect("response");
    response
}

#[test]
fn http_errors_say_what_was_wrong() {
    let (table, server) = server(8);
    let mut state = CarState::new();
    state.update(&speed(0, 12.0));
    table.publish(&state);
    let get = |path: &str| http_get(&server, path);
    let missing = get("/api/nothing/here");
    assert!(missing.starts_with("HTTP/1.1 404"), "{missing}");
    assert!(
        missing.contains("no such path: /api/nothing/here"),
        "{missing}"
    );
    let missing_asset = get("/assets/none.js");
    assert!(missing_asset.starts_with("HTTP/1.1 404"), "{missing_asset}");
    // Any other path is one of the page's views: the page itself.
    let view = get("/ecus");
    assert!(view.starts_with("HTTP/1.1 200"), "{view}");
    assert!(view.contains("text/html"), "{view}");
    let post = http(
        &server,
        &format!(
            "POST /ecus HTTP/1.1\r\nHost: {}\r\nContent-Length: 0\r\nConnection: close\r\n\r\n",
            server.addr()
        ),
    );
    assert!(post.starts_with("HTTP/1.1 405"), "{post}");
    let not_ws = get("/api/stream");
    assert!(not_ws.starts_with("HTTP/1.1 400"), "{not_ws}");
    assert!(not_ws.contains("WebSocket"), "{not_ws}");
    let state = get("/api/state");
    assert!(state.starts_with("HTTP/1.1 200"), "{state}");
    assert!(state.contains("\"Vehicle.Speed\":12"), "{state}");
    // Garbage instead of HTTP: the connection is answered or closed, the server goes on.
    {
        use std::io::Write;
        let mut stream = std::net::TcpStream::connect(server.addr()).expect("connect");
        let _ = stream.write_all(&[0u8; 300]);
    }
    assert!(get("/api/catalog").starts_with("HTTP/1.1 200"));
}

#[test]
fn the_kept_front_end_build_is_served_with_its_third_party_licences() {
    // middleware/web/ui/dist is kept in the repository, so every build embeds the page and the
    // main command needs no Node.js.
    assert!(
        autoplug_web::assets::built(),
        "ui/dist is missing from the checkout"
    );
    let (_table, server) = server(8);
    let get = |path: &str| http_get(&server, path);
    let page = get("/");
    assert!(page.starts_with("HTTP/1.1 200"), "{page}");
    let script = page
        .split('"')
        .find(|part| part.starts_with("/assets/") && part.ends_with(".js"))
        .unwrap_or_else(|| panic!("no bundled script in the page: {page}"));
    assert!(get(script).starts_with("HTTP/1.1 200"));
    // The bundle holds uPlot (MIT): its licence is served beside it.
    let licences = get("/third-party-licenses.txt");
    assert!(licences.starts_with("HTTP/1.1 200"), "{licences}");
    assert!(licences.contains("text/plain"), "{licences}");
    assert!(licences.contains("uplot 1.6.32 (MIT)"), "{licences}");
    assert!(
        licences.contains("Permission is hereby granted"),
        "{licences}"
    );
}

#[test]
fn stopping_the_server_closes_open_streams_at_once() {
    let (_table, server) = server(8);
    runtime().block_on(async {
        let mut client = connect(&server).await;
        next_json(&mut client).await;
        let started = std::time::Instant::now();
        drop(server);
        assert!(
            started.elapsed() < Duration::from_secs(1),
            "{:?}",
            started.elapsed()
        );
        // The client sees its stream end.
        let end = tokio::time::timeout(Duration::from_secs(5), async {
            loop {
                match client.next().await {
                    None | Some(Err(_)) | Some(Ok(Message::Close(_))) => return,
                    Some(Ok(_)) => {}
                }
            }
        })
        .await;
        assert!(end.is_ok(), "the stream ended");
    });
}

#[test]
fn driving_over_the_stream_needs_the_token_and_reaches_the_session() {
    let table = Arc::new(LiveTable::new());
    let mut config = WebConfig::loopback(0);
    config.token = Some("stream-token-0123456789".into());
    let (control, commands) = autoplug_web::control::channel();
    let server = WebServer::start(config, table, Some(control)).expect("server");
    let drive = r#"{"type":"drive","accelerator":40,"brake":0,"steering_deg":5,"headlights":true,"economy_mode":false,"manual_mode":false,"set_temp_f":70}"#;
    runtime().block_on(async {
        let mut client = connect(&server).await;
        assert_eq!(next_json(&mut client).await["type"], "catalog");
        assert_eq!(next_json(&mut client).await["type"], "update");
        // Not yet authenticated: refused, nothing reaches the session.
        client.send(Message::Text(drive.into())).await.unwrap();
        let refused = next_json(&mut client).await;
        assert_eq!(refused["type"], "error");
        assert!(
            refused["error"].as_str().unwrap().contains("token"),
            "{refused}"
        );
        client
            .send(Message::Text(r#"{"type":"auth","token":"guess"}"#.into()))
            .await
            .unwrap();
        assert_eq!(next_json(&mut client).await["ok"], false);
        client
            .send(Message::Text(
                r#"{"type":"drive","accelerator":"full"}"#.into(),
            ))
            .await
            .unwrap();
        assert_eq!(next_json(&mut client).await["type"], "error");
        client
            .send(Message::Text(
                r#"{"type":"auth","token":"stream-token-0123456789"}"#.into(),
            ))
            .await
            .unwrap();
        assert_eq!(next_json(&mut client).await["ok"], true);
        client.send(Message::Text(drive.into())).await.unwrap();
        client
            .send(Message::Text(
                r#"{"type":"press","button":"cruise_on"}"#.into(),
            ))
            .await
            .unwrap();
        client
            .send(Message::Text(r#"{"type":"press","button":"horn"}"#.into()))
            .await
            .unwrap();
        let unknown = next_json(&mut client).await;
        assert_eq!(unknown["type"], "error", "{unknown}");
        client.send(Message::Close(None)).await.unwrap();
        tokio::time::sleep(Duration::from_millis(300)).await;
    });
    let mut got = Vec::new();
    while let Some(command) = commands.next() {
        got.push(format!("{command:?}"));
    }
    assert_eq!(got.len(), 3, "{got:?}");
    assert!(
        got[0].starts_with("Drive(HeldControls { accelerator: 40.0"),
        "{got:?}"
    );
    assert_eq!(got[1], "Press(CruiseOn)");
    // The page that drove left: the session releases the pedals.
    assert_eq!(got[2], "DriverLeft");
}

#[test]
fn a_page_that_rebinds_its_name_to_the_dashboard_is_refused() {
    let (table, server) = server(8);
    let mut state = CarState::new();
    state.update(&speed(0, 12.0));
    table.publish(&state);
    let port = server.addr().port();
    // The browser of a page at http://rebind.example:PORT whose name now points at 127.0.0.1
    // sends its own name, on plain requests and on the stream's upgrade alike.
    let foreign =
        format!("Host: rebind.example:{port}\r\nOrigin: http://rebind.example:{port}\r\n");
    for path in ["/api/state", "/api/recordings", "/api/trips", "/"] {
        let answer = http_get_with(&server, path, &foreign);
        assert!(answer.starts_with("HTTP/1.1 421"), "{path}: {answer}");
        assert!(
            answer.contains("does not answer for the host 'rebind.example:"),
            "{answer}"
        );
        assert!(!answer.contains("Vehicle.Speed"), "{answer}");
    }
    let upgrade = format!(
        "{foreign}Upgrade: websocket\r\nConnection: Upgrade\r\nSec-WebSocket-Version: 13\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n"
    );
    let answer = http_get_with(&server, "/api/stream", &upgrade);
    assert!(answer.starts_with("HTTP/1.1 421"), "{answer}");
    // The server's own names: its address, localhost, with its port; no Host at all (a tool).
    for host in [
        format!("127.0.0.1:{port}"),
        format!("localhost:{port}"),
        format!("LOCALHOST:{port}"),
    ] {
        let answer = http_get_with(&server, "/api/state", &format!("Host: {host}\r\n"));
        assert!(answer.starts_with("HTTP/1.1 200"), "{host}: {answer}");
    }
    // Another port, a name without one (port 80), garbage.
    for host in [
        format!("127.0.0.1:{}", port.wrapping_add(1)),
        "localhost".to_string(),
        "[::1".to_string(),
        format!("localhost:{port}x"),
    ] {
        let answer = http_get_with(&server, "/api/state", &format!("Host: {host}\r\n"));
        assert!(answer.starts_with("HTTP/1.1 421"), "{host}: {answer}");
    }
}

#[test]
fn names_the_user_allows_are_answered() {
    use autoplug_web::server::host_allowed;
    let mut config = WebConfig::loopback(0);
    config.allowed_hosts = vec!["car.lan".into(), "bench.lan:9000".into()];
    let local: std::net::SocketAddr = "127.0.0.1:8080".parse().unwrap();
    assert!(host_allowed("car.lan:8080", &config, local));
    assert!(host_allowed("CAR.LAN:8080", &config, local));
    assert!(!host_allowed("car.lan:8081", &config, local));
    assert!(host_allowed("bench.lan:9000", &config, local));
    assert!(!host_allowed("bench.lan:8080", &config, local));
    assert!(!host_allowed("evil.lan:8080", &config, local));
    assert!(
        host_allowed("[::1]:8080", &config, local),
        "loopback is loopback"
    );
    // Listening on every address: any address literal, but still no foreign name.
    let all: std::net::SocketAddr = "0.0.0.0:8080".parse().unwrap();
    assert!(host_allowed("192.0.2.7:8080", &config, all));
    assert!(host_allowed("[2001:db8::1]:8080", &config, all));
    assert!(!host_allowed("evil.lan:8080", &config, all));
    // Listening on one address: that one only.
    let one: std::net::SocketAddr = "192.0.2.7:8080".parse().unwrap();
    assert!(host_allowed("192.0.2.7:8080", &config, one));
    assert!(!host_allowed("192.0.2.8:8080", &config, one));
    assert!(!host_allowed("localhost:8080", &config, one));
}

#[test]
fn a_driver_at_60_inputs_a_second_builds_no_backlog_and_inputs_are_coalesced() {
    let table = Arc::new(LiveTable::new());
    let mut config = WebConfig::loopback(0);
    config.token = Some("stream-token-0123456789".into());
    let (control, commands) = autoplug_web::control::channel();
    let server = WebServer::start(config, table.clone(), Some(control)).expect("server");
    // The car keeps changing, as a running one does: an update is due every period.
    let running = Arc::new(std::sync::atomic::AtomicBool::new(true));
    let publisher = {
        let (table, running) = (table.clone(), running.clone());
        std::thread::spawn(move || {
            let mut state = CarState::new();
            let mut t_ms = 0;
            while running.load(std::sync::atomic::Ordering::Acquire) {
                t_ms += 1;
                state.update(&speed(t_ms, (t_ms % 200) as f32));
                table.publish(&state);
                std::thread::sleep(Duration::from_millis(1));
            }
        })
    };
    let drive = |brake: u32| {
        format!(
            r#"{{"type":"drive","accelerator":0,"brake":{brake},"steering_deg":0,"headlights":false,"economy_mode":false,"manual_mode":false,"set_temp_f":70}}"#
        )
    };
    let pong_after = runtime().block_on(async {
        let mut client = connect(&server).await;
        assert_eq!(next_json(&mut client).await["type"], "catalog");
        let auth = r#"{"type":"auth","token":"stream-token-0123456789"}"#;
        client.send(Message::Text(auth.into())).await.unwrap();
        while next_json(&mut client).await["type"] != "auth" {}
        // Two seconds of driving at 60 inputs a second with a press among them, then a
        // burst of 80 more.
        let mut pace = tokio::time::interval(Duration::from_micros(16_667));
        for brake in 0..200 {
            if brake < 120 {
                pace.tick().await;
            }
            let input = drive(brake);
            client.send(Message::Text(input.into())).await.unwrap();
            if brake == 50 {
                let press = r#"{"type":"press","button":"shift_up"}"#;
                client.send(Message::Text(press.into())).await.unwrap();
            }
        }
        let sent = std::time::Instant::now();
        let ping = r#"{"type":"ping"}"#;
        client.send(Message::Text(ping.into())).await.unwrap();
        while next_json(&mut client).await["type"] != "pong" {}
        let pong_after = sent.elapsed();
        tokio::time::sleep(Duration::from_millis(100)).await;
        pong_after
    });
    running.store(false, std::sync::atomic::Ordering::Release);
    publisher.join().unwrap();
    // Every message is read as it comes: the ping waits behind no backlog.
    assert!(pong_after < Duration::from_millis(500), "{pong_after:?}");
    let mut drives = Vec::new();
    let mut presses = 0;
    while let Some(command) = commands.next() {
        match command {
            autoplug_web::Command::Drive(input) => drives.push(input.brake),
            autoplug_web::Command::Press(_) => presses += 1,
            _ => {}
        }
    }
    assert_eq!(presses, 1, "the press is never coalesced away");
    // Coalesced: the burst's inputs did not all reach the session, the latest last.
    assert!(
        !drives.is_empty() && drives.len() < 160,
        "{} inputs",
        drives.len()
    );
    assert_eq!(drives.last(), Some(&199.0), "{drives:?}");
}

#[test]
fn the_world_goes_on_a_channel_of_its_own() {
    let (table, server) = server(8);
    table
        .world()
        .describe(r#"{"road":{"name":"handling circuit"},"car":{}}"#.into())
        .unwrap();
    table.world().publish("[0.05,20,0,0,1.5,0,0]".into());
    runtime().block_on(async {
        let mut client = connect(&server).await;
        let world = loop {
            let message = next_json(&mut client).await;
            assert!(
                message.get("poses").is_none() || message["type"] == "world",
                "the signals' updates carry no pose: {message}"
            );
            if message["type"] == "world" {
                break message;
            }
        };
        assert_eq!(world["description"]["road"]["name"], "handling circuit");
        assert_eq!(world["poses"][0][1], 20);
        table.world().publish("[0.10,21,0,0,1.5,0,1]".into());
        let next = loop {
            let message = next_json(&mut client).await;
            if message["type"] == "world" {
                break message;
            }
        };
        assert!(next.get("description").is_none(), "{next}");
        assert_eq!(next["poses"].as_array().unwrap().len(), 1, "{next}");
        assert_eq!(next["poses"][0][6], 1);
    });
    // The same over plain HTTP: everything kept.
    let response = http_get(&server, "/api/world");
    let body = response.split_once("\r\n\r\n").map_or("", |(_, b)| b);
    let whole: Value = serde_json::from_str(body).expect("JSON");
    assert_eq!(whole["poses"].as_array().unwrap().len(), 2, "{whole}");
}

/// The body of an HTTP response, parsed as JSON (the status must be 200).
fn json_body(response: &str) -> Value {
    assert!(response.starts_with("HTTP/1.1 200"), "{response}");
    let body = response.split("\r\n\r\n").nth(1).expect("a body");
    serde_json::from_str(body).unwrap_or_else(|e| panic!("{e}: {body}"))
}

/// The frames a pipeline hands the publisher: the vehicle speed every 10 ms for `seconds`.
fn drive(publisher: &mut autoplug_web::Publisher, state: &mut CarState, seconds: u64) {
    use autoplug_gateway::Observer;
    for i in 0..seconds * 100 {
        let frame = speed(i * 10, (i % 120) as f32);
        let update = state.update(&frame);
        publisher.on_frame(&frame, update, state);
    }
}

#[test]
fn the_history_holds_the_session_from_its_first_second() {
    let (table, server) = server(8);
    let mut publisher = autoplug_web::Publisher::new(table.clone());
    let mut state = CarState::new();
    drive(&mut publisher, &mut state, 30);
    let history = json_body(&http_get(
        &server,
        "/api/history?paths=Vehicle.Speed,Vehicle.Chassis.SteeringWheel.Angle",
    ));
    assert_eq!(history["t0"], 0.0, "{history}");
    let speed = &history["signals"]["Vehicle.Speed"];
    let t = speed["t"].as_array().unwrap();
    let v = speed["v"].as_array().unwrap();
    assert!(t[0].as_f64().unwrap() < 0.1, "from the start: {}", t[0]);
    assert!(t.last().unwrap().as_f64().unwrap() > 29.0);
    assert_eq!(t.len(), v.len());
    let top = v.iter().filter_map(Value::as_f64).fold(0.0, f64::max);
    assert_eq!(top, 119.0, "the ramps' tops are kept");
    let steering = &history["signals"]["Vehicle.Chassis.SteeringWheel.Angle"];
    assert_eq!(steering["t"], speed["t"], "one time axis for every signal");
    assert!(steering["v"].as_array().unwrap().iter().all(Value::is_null));
    // Bad requests name what was wrong.
    let unknown = http_get(&server, "/api/history?paths=Vehicle.Nothing");
    assert!(unknown.starts_with("HTTP/1.1 404"), "{unknown}");
    assert!(unknown.contains("Vehicle.Nothing"), "{unknown}");
    let none = http_get(&server, "/api/history");
    assert!(none.starts_with("HTTP/1.1 400"), "{none}");
}

#[test]
fn the_trace_gives_every_frame_once_and_the_bus_load_is_measured() {
    let (table, server) = server(8);
    let mut publisher = autoplug_web::Publisher::new(table.clone());
    let mut state = CarState::new();
    drive(&mut publisher, &mut state, 2);
    let first = json_body(&http_get(&server, "/api/trace?limit=50"));
    let frames = first["frames"].as_array().unwrap();
    assert_eq!(frames.len(), 50, "the newest 50");
    assert_eq!(first["last"], 200);
    assert_eq!(frames[49][6], "VehicleSpeedMsg");
    let again = json_body(&http_get(&server, "/api/trace?after=200"));
    assert!(again["frames"].as_array().unwrap().is_empty());
    let bad = http_get(&server, "/api/trace?after=-1");
    assert!(bad.starts_with("HTTP/1.1 400"), "{bad}");
    // One 1-byte frame every 10 ms: 55 bits plus stuff bits, 100 a second, at 500 kbit/s
    // about 1.1 to 1.3 % of the bus.
    let state_json = json_body(&http_get(&server, "/api/state"));
    let load = state_json["bus"]["load_percent"].as_f64().expect("a load");
    assert!((1.0..1.4).contains(&load), "{load}");
    let last_t = state_json["messages"]["VehicleSpeedMsg"]["last_t"]
        .as_f64()
        .unwrap();
    assert!((last_t - 1.99).abs() < 1e-6, "{last_t}");
}

#[test]
fn the_dbc_downloads_as_the_file_it_is() {
    let (_table, server) = server(8);
    let response = http_get(&server, "/api/dbc");
    assert!(response.starts_with("HTTP/1.1 200"), "{response}");
    assert!(response.contains("filename=\"autoplug.dbc\""));
    let body = response.split("\r\n\r\n").nth(1).unwrap();
    assert_eq!(body, autoplug_can::DBC_FILE);
    assert!(body.contains("BO_ 3 VehicleSpeedMsg"), "a DBC");
}

#[test]
fn a_car_halted_by_a_debugger_is_streamed_and_refuses_actions_with_the_reason() {
    let table = Arc::new(LiveTable::new());
    let mut config = WebConfig::loopback(0);
    config.token = Some("debugger-token-0123456789".into());
    let (control, commands) = autoplug_web::control::channel();
    let server = WebServer::start(config, table.clone(), Some(control)).expect("server");
    let debugger = |halted: bool| {
        serde_json::json!({"ecus": [{"ecu": "cruise", "address": "127.0.0.1:3333",
            "attached": halted, "halted": halted,
            "client": halted.then_some("127.0.0.1:50210")}]})
    };
    let version = table.set_debugger(&debugger(true));
    assert_eq!(
        table.set_debugger(&debugger(true)),
        version,
        "the same object again is no change"
    );
    assert_eq!(table.halted_by_debugger(), ["cruise"]);
    let refused = http(
        &server,
        &format!(
            "POST /api/recording HTTP/1.1\r\nHost: {}\r\nAuthorization: Bearer debugger-token-0123456789\r\nContent-Type: application/json\r\nContent-Length: 11\r\nConnection: close\r\n\r\n{{\"on\":true}}",
            server.addr()
        ),
    );
    assert!(refused.starts_with("HTTP/1.1 409"), "{refused}");
    let body: Value = serde_json::from_str(refused.split("\r\n\r\n").nth(1).unwrap()).unwrap();
    assert_eq!(
        body["error"],
        "the car is halted by the debugger (cruise): continue it in GDB first"
    );
    assert!(commands.next().is_none(), "nothing reached the session");
    runtime().block_on(async {
        let mut client = connect(&server).await;
        assert_eq!(next_json(&mut client).await["type"], "catalog");
        let first = next_json(&mut client).await;
        assert_eq!(first["debugger"], debugger(true), "{first}");
        table.set_debugger(&debugger(false));
        let update = next_json(&mut client).await;
        assert_eq!(update["debugger"], debugger(false), "{update}");
        assert!(update["signals"].as_object().unwrap().is_empty());
    });
    assert!(table.halted_by_debugger().is_empty());
}
