use crate::driver::Timeline;
use crate::scenario::{Button, GearName, Scenario, Software};
use autoplug_can::{Frame, Node};

const EXAMPLE: &str = r#"
name = "cruise-hold"
duration_s = 40.0
[road]
grade_percent = 0.0
[initial]
speed_kmh = 90.0
gear = "4"
[ecus]
cruise = "faulty"
[driver]
accelerator = 20.0
[[at]]
t_s = 2.0
press = ["cruise_on"]
accelerator = 0.0
[[at]]
t_s = 5.0
ramp_s = 2.0
steering_deg = 30.0
headlights = true
[[at]]
t_s = 20.0
grade_percent = 6.0
fault = { silence = "Steering" }
"#;

#[test]
fn scenarios_parse_with_defaults() {
    let s = Scenario::parse(EXAMPLE, "example").unwrap();
    assert_eq!(s.name, "cruise-hold");
    assert_eq!(s.initial.gear, GearName::Forward(4));
    assert_eq!(s.ecus.cruise, Software::Faulty);
    assert_eq!(s.ecus.abs, Software::Correct);
    assert_eq!(s.road.mu_left, 1.0);
    assert_eq!(s.at.len(), 3);
    assert_eq!(s.at[0].press, vec![Button::CruiseOn]);
    // No VIN given: one from the seed, valid; every ECU left the factory with 1.0.0.
    assert_eq!(
        s.vin().to_string(),
        crate::scenario::vin_from_seed(1).to_string()
    );
    assert_eq!(
        s.factory_version(autoplug_can::Node::Cruise).to_string(),
        "1.0.0"
    );
    let s = Scenario::parse(
        &format!("{EXAMPLE}[factory]\ncruise = \"1.1.0\"\n").replace(
            "duration_s = 40.0",
            "duration_s = 40.0\nvin = \"JA3AP47H3YF000777\"",
        ),
        "example",
    )
    .unwrap();
    assert_eq!(s.vin().as_str(), "JA3AP47H3YF000777");
    assert_eq!(
        s.factory_version(autoplug_can::Node::Cruise).to_string(),
        "1.1.0"
    );
    assert_eq!(
        s.factory_version(autoplug_can::Node::ABS).to_string(),
        "1.0.0"
    );
    assert_eq!(
        s.at[2].fault.as_ref().unwrap().silence.as_deref(),
        Some("Steering")
    );
}

#[test]
fn scenario_errors_name_the_field() {
    let cases = [
        (
            EXAMPLE.replace("accelerator = 20.0", "accelerator = 120.0"),
            "driver.accelerator = 120 is outside 0..=100",
        ),
        (
            EXAMPLE.replace("gear = \"4\"", "gear = \"7\""),
            "gear \"7\"",
        ),
        (
            EXAMPLE.replace("cruise = \"faulty\"", "cruise = \"broken\""),
            "unknown variant `broken`",
        ),
        (
            EXAMPLE.replace("headlights = true", "headlight = true"),
            "unknown field `headlight`",
        ),
        (
            EXAMPLE.replace("t_s = 20.0", "t_s = 1.0"),
            "events must be in time order",
        ),
        (
            EXAMPLE.replace("silence = \"Steering\"", "silence = \"Wheel\""),
            "fault names node \"Wheel\"",
        ),
        (
            EXAMPLE.replace("t_s = 20.0", "t_s = 50.0"),
            "at[2].t_s = 50 is outside 0..=40",
        ),
        (
            EXAMPLE.replace("name = \"cruise-hold\"", "name = \"a/b\""),
            "name \"a/b\"",
        ),
        (
            EXAMPLE.replace("duration_s = 40.0", "duration_s = 3601.0"),
            "duration_s = 3601 is outside",
        ),
        (
            EXAMPLE.replace(
                "duration_s = 40.0",
                "duration_s = 40.0\nvin = \"JA3AP47H9YF000042\"",
            ),
            "vin \"JA3AP47H9YF000042\": the check digit (character 9) is '9'",
        ),
        (
            format!("{EXAMPLE}[factory]\nradio = \"1.0.0\"\n"),
            "factory.radio: no such ECU",
        ),
        (
            format!("{EXAMPLE}[factory]\ncruise = \"1.x\"\n"),
            "factory.cruise = \"1.x\"",
        ),
    ];
    for (text, expected) in cases {
        let e = Scenario::parse(&text, "x.toml").unwrap_err();
        let shown = e.to_string();
        assert!(shown.starts_with("x.toml: "), "{shown}");
        assert!(
            shown.contains(expected),
            "expected {expected:?} in {shown:?}"
        );
    }
}

#[test]
fn a_track_and_its_driver_are_checked_against_each_other() {
    let on_circuit = "name = \"x\"\nduration_s = 10\n[road]\ntrack = \"handling-circuit\"\n";
    let s = Scenario::parse(on_circuit, "x.toml").unwrap();
    let track = s.track.as_ref().expect("the shipped road is read");
    assert_eq!(track.name, "handling circuit");
    let cases = [
        (
            "name = \"x\"\nduration_s = 10\n[road]\ntrack = \"nurburgring\"\n".to_string(),
            "road.track \"nurburgring\": no such road (the shipped ones: handling-circuit, braking-straight",
        ),
        (
            "name = \"x\"\nduration_s = 10\n[road]\ntrack = \"missing.toml\"\n".to_string(),
            "road.track: missing.toml: cannot read",
        ),
        (
            format!("{on_circuit}grade_percent = 4\n"),
            "road.grade_percent: on a track (handling circuit) the track sets the grade",
        ),
        (
            format!("{on_circuit}start_m = 5000\n"),
            "road.start_m = 5000 is outside the track (0..=3221.69 m)",
        ),
        (
            format!("{on_circuit}lane_m = -4.5\n"),
            "road.lane_m = -4.5: the car must start on the road",
        ),
        (
            "name = \"x\"\nduration_s = 10\n[driver]\nfollow_road = true\n".to_string(),
            "driver.follow_road: there is no road to follow (road.track)",
        ),
        (
            format!("{on_circuit}[driver]\nfollow_road = true\n[[at]]\nt_s = 2\nsteering_deg = 10\n"),
            "at[0] (t_s = 2): steering_deg: the driver follows the road here",
        ),
        (
            format!("{on_circuit}[[at]]\nt_s = 2\ngrade_percent = 3\n"),
            "at[0] (t_s = 2): grade_percent: on a track the track sets the grade",
        ),
        (
            format!("{on_circuit}[driver]\nspeed_kmh = 300\n"),
            "driver.speed_kmh = 300 is outside 0..=250",
        ),
    ];
    for (text, expected) in cases {
        let shown = Scenario::parse(&text, "x.toml").unwrap_err().to_string();
        assert!(
            shown.contains(expected),
            "expected {expected:?} in {shown:?}"
        );
    }
    // A road file by path, from the scenario file's folder; steering again once the
    // driver stops following.
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("short.toml"),
        "name = \"short\"\nwidth_m = 8\n[[segment]]\nstraight_m = 200\n",
    )
    .unwrap();
    let path = dir.path().join("s.toml");
    std::fs::write(
        &path,
        "name = \"x\"\nduration_s = 10\n[road]\ntrack = \"short.toml\"\n[driver]\nfollow_road = true\n[[at]]\nt_s = 1\nfollow_road = false\nsteering_deg = 5\n",
    )
    .unwrap();
    let s = Scenario::load(&path).unwrap();
    assert_eq!(s.track.as_ref().unwrap().road.length_m(), 200.0);
}

#[test]
fn path_svg_draws_the_road_and_the_path_at_one_scale() {
    use crate::path_plot::path_svg;
    // A 60 m stop along the braking straight, the car sliding at its end.
    let s = Scenario::parse(
        "name = \"x\"\nduration_s = 1\n[road]\ntrack = \"braking-straight\"\n",
        "x",
    )
    .unwrap();
    let rows: Vec<crate::car::TraceRow> = (0..=60)
        .map(|i| {
            let sliding = i > 40;
            crate::car::TraceRow {
                t_s: i as f64 * 0.05,
                x_m: i as f64,
                y_m: 0.0,
                heading_rad: if sliding { 0.02 * (i - 40) as f64 } else { 0.0 },
                speed_kmh: 50.0,
                distance_m: i as f64,
                marks: [sliding; 4],
                ..Default::default()
            }
        })
        .collect();
    let svg = path_svg(
        &rows,
        s.track.as_deref(),
        &crate::car::VirtualCar::vehicle_params(),
    );
    assert!(svg.starts_with("<svg") && svg.trim_end().ends_with("</svg>"));
    assert!(
        svg.contains("Path on the braking straight (equal scale)"),
        "title"
    );
    assert!(!svg.contains("NaN") && !svg.contains("inf"));
    // One scale: 60 m of path with 8 m of ground and the road's half width either side
    // spans the 900 px limit, so a metre is 900 / 90 px; the 14 m road then shows 140 px
    // wide (its two edges are 140 px apart at the start).
    let scale = 900.0 / (60.0 + 2.0 * (8.0 + 7.0));
    let edges: Vec<&str> = svg
        .lines()
        .filter(|l| l.contains(r##"stroke="#ffffff" stroke-width="1.5""##))
        .collect();
    assert_eq!(edges.len(), 2, "two road edges");
    let first_y = |line: &str| -> f64 {
        let points = line.split("points=\"").nth(1).unwrap();
        points
            .split_whitespace()
            .next()
            .unwrap()
            .split(',')
            .nth(1)
            .unwrap()
            .parse()
            .unwrap()
    };
    let apart = (first_y(edges[0]) - first_y(edges[1])).abs();
    assert!((apart - 14.0 * scale).abs() < 0.2, "{apart} px for 14 m");
    // Tyre marks for each wheel while it was locked, and the car's outline at intervals.
    assert_eq!(
        svg.matches(r##"stroke="#1a1a1a""##).count(),
        4,
        "tyre marks"
    );
    assert!(svg.matches("<title>t = ").count() >= 12, "outlines");
}

#[test]
fn a_value_of_the_wrong_type_names_its_key_and_shows_its_line() {
    let shown = Scenario::parse("name = \"x\"\nduration_s = \"long\"\n", "x.toml")
        .unwrap_err()
        .to_string();
    assert_eq!(
        shown,
        "x.toml: line 2, column 14, key duration_s: invalid type: string \"long\", expected f64 (the line: duration_s = \"long\")"
    );
    // In a table, and in an inline table of the timeline.
    let text = EXAMPLE.replace("speed_kmh = 90.0", "speed_kmh = true");
    let shown = Scenario::parse(&text, "x.toml").unwrap_err().to_string();
    assert!(
        shown.contains("key initial.speed_kmh: invalid type: boolean"),
        "{shown}"
    );
    assert!(shown.contains("(the line: speed_kmh = true)"), "{shown}");
    let text = EXAMPLE.replace(r#"{ silence = "Steering" }"#, "{ silence = 3 }");
    let shown = Scenario::parse(&text, "x.toml").unwrap_err().to_string();
    assert!(
        shown.contains("key at.fault.silence: invalid type: integer"),
        "{shown}"
    );
    // A long line: a snippet around the place, never the whole line.
    let long = format!("name = \"x\"\nduration_s = \"{}\"\n", "l".repeat(500));
    let shown = Scenario::parse(&long, "x.toml").unwrap_err().to_string();
    assert!(shown.contains("key duration_s"), "{shown}");
    assert!(shown.len() < 400, "{shown}");
}

#[test]
fn the_timeline_ramps_latches_and_presses() {
    let s = Scenario::parse(EXAMPLE, "example").unwrap();
    let mut timeline = Timeline::new(&s);
    let mut road_events = Vec::new();
    let c = timeline.advance(0.0, |_| {});
    assert_eq!((c.held.accelerator, c.buttons.cruise_on), (20.0, false));
    let c = timeline.advance(2.0, |_| {});
    assert_eq!((c.held.accelerator, c.buttons.cruise_on), (0.0, true));
    let c = timeline.advance(2.09, |_| {});
    assert!(c.buttons.cruise_on, "held for 100 ms");
    let c = timeline.advance(2.1, |_| {});
    assert!(!c.buttons.cruise_on, "released after 100 ms");
    let c = timeline.advance(6.0, |_| {});
    assert!(
        (c.held.steering_deg - 15.0).abs() < 1e-9,
        "half-way through the 2 s ramp: {}",
        c.held.steering_deg
    );
    assert!(c.held.headlights);
    let c = timeline.advance(7.5, |_| {});
    assert_eq!(c.held.steering_deg, 30.0);
    timeline.advance(20.0, |e| road_events.push(e.grade_percent));
    assert_eq!(road_events, vec![Some(6.0)]);
    timeline.advance(30.0, |e| road_events.push(e.grade_percent));
    assert_eq!(road_events.len(), 1, "each event fires once");
}

#[test]
fn bus_log_lines_are_candump_and_read_back() {
    use crate::car::LoggedFrame;
    use crate::report::write_bus_log;
    let frame = Frame::new(0x00C, &[0x0A, 0x14, 0x1E, 0x28]).unwrap();
    let log = [
        LoggedFrame {
            t_us: 12_345_678,
            frame,
            sender: Some(Node::Pedals),
        },
        LoggedFrame {
            t_us: 5,
            frame: Frame::new(0x7FF, &[]).unwrap(),
            sender: None,
        },
    ];
    let mut out = Vec::new();
    write_bus_log(&mut out, &log).unwrap();
    let text = String::from_utf8(out).unwrap();
    assert_eq!(
        text,
        "(12.345678) can0 00C#0A141E28\n(0.000005) can0 7FF#\n"
    );
    let back: Vec<_> = autoplug_logs::read::CandumpReader::new(text.as_bytes())
        .map(|f| f.unwrap())
        .collect();
    assert_eq!(back[0].t_us, 12_345_678);
    assert_eq!(back[0].as_can_frame(), Some(frame));
    assert_eq!(
        back[1].t_us, 5,
        "time going backwards is the reader's caller's business"
    );
    assert!(back[1].data().is_empty());
}

#[test]
fn a_run_bus_log_reads_back_exactly() {
    use crate::report::{run, write_bus_log};
    let s = Scenario::parse(
        "name = \"readback\"\nduration_s = 0.5\n[driver]\naccelerator = 30.0\n",
        "readback",
    )
    .unwrap();
    let log = run(&s).log;
    assert!(log.len() > 100);
    let mut text = Vec::new();
    write_bus_log(&mut text, &log).unwrap();
    let back: Vec<_> = autoplug_logs::read::CandumpReader::new(&text[..])
        .map(|f| f.unwrap())
        .collect();
    assert_eq!(back.len(), log.len());
    for (read, written) in back.iter().zip(&log) {
        assert_eq!(read.t_us, written.t_us);
        assert_eq!(read.channel, 0);
        assert_eq!(read.as_can_frame(), Some(written.frame));
    }
}

mod socketcand {
    use crate::socketcand::{parse_command, Command, SocketcandServer};
    use autoplug_can::Frame;
    use std::io::{Read, Write};
    use std::net::TcpStream;
    use std::time::{Duration, Instant};

    /// Reads until `expected` has arrived in full (the server writes each message whole,
    /// but TCP may still split or join reads).
    fn read_until(stream: &mut TcpStream, received: &mut String, expected: &str) {
        let deadline = Instant::now() + Duration::from_secs(5);
        let mut chunk = [0u8; 256];
        while !received.contains(expected) {
            assert!(
                Instant::now() < deadline,
                "timed out waiting for {expected:?}; got {received:?}"
            );
            if let Ok(n) = stream.read(&mut chunk) {
                received.push_str(std::str::from_utf8(&chunk[..n]).unwrap());
            }
        }
    }

    fn wait_for(mut condition: impl FnMut() -> bool) {
        let deadline = Instant::now() + Duration::from_secs(5);
        while !condition() {
            assert!(Instant::now() < deadline, "timed out");
            std::thread::sleep(Duration::from_millis(2));
        }
    }

    #[test]
    fn a_client_handshakes_receives_and_sends() {
        let server = SocketcandServer::start("127.0.0.1:0").unwrap();
        let mut client = TcpStream::connect(server.address()).unwrap();
        client
            .set_read_timeout(Some(Duration::from_millis(50)))
            .unwrap();
        let mut got = String::new();
        read_until(&mut client, &mut got, "< hi >");
        // Frames before raw mode are not sent to the client.
        server.broadcast(1, &Frame::new(0x001, &[1]).unwrap(), None);
        client.write_all(b"< open can0 >").unwrap();
        read_until(&mut client, &mut got, "< hi >< ok >");
        // A command split across two writes.
        client.write_all(b"< raw").unwrap();
        client.flush().unwrap();
        std::thread::sleep(Duration::from_millis(20));
        client.write_all(b"mode >").unwrap();
        read_until(&mut client, &mut got, "< hi >< ok >< ok >");
        wait_for(|| server.raw_clients() == 1);
        server.broadcast(12_345_678, &Frame::new(0x00C, &[0x0A, 0x14]).unwrap(), None);
        server.broadcast(20_000_000, &Frame::new(0x7FF, &[]).unwrap(), None);
        read_until(&mut client, &mut got, "< frame 7FF 20.000000  >");
        assert_eq!(
            got,
            "< hi >< ok >< ok >< frame 00C 12.345678 0A14 >< frame 7FF 20.000000  >"
        );
        // Two commands in one write, one of them empty.
        client
            .write_all(b"< send 123 2 de ad >< send 7FF 0  >< echo >")
            .unwrap();
        read_until(&mut client, &mut got, "< echo >");
        let mut frames = Vec::new();
        wait_for(|| {
            while let Some(f) = server.try_recv() {
                frames.push(f);
            }
            frames.len() == 2
        });
        assert_eq!(frames[0].frame, Frame::new(0x123, &[0xDE, 0xAD]).unwrap());
        assert_eq!(frames[1].frame, Frame::new(0x7FF, &[]).unwrap());
        // Its own frame is not echoed back to it.
        server.broadcast(30_000_000, &frames[0].frame, Some(frames[0].client));
        server.broadcast(30_000_001, &Frame::new(0x002, &[]).unwrap(), None);
        read_until(&mut client, &mut got, "< frame 002 30.000001  >");
        assert!(!got.contains("< frame 123"), "{got}");
        assert_eq!(server.refused_commands(), 0);
    }

    #[test]
    fn bad_commands_are_refused_with_a_reason() {
        let cases = [
            ("send 12345678 1 00", "extended"),
            ("send 12G 1 00", "not hexadecimal"),
            ("send 123 2 00", "length 2 but 1 data bytes"),
            ("send 800 0", "does not fit 11 bits"),
            ("send 123 9 0 1 2 3 4 5 6 7 8", "at most 8"),
            ("bogus", "unknown command 'bogus'"),
        ];
        for (message, expected) in cases {
            let e = parse_command(message).unwrap_err();
            assert!(e.contains(expected), "{message}: {e}");
        }
        assert_eq!(parse_command("open can0"), Ok(Command::Open("can0".into())));
        let server = SocketcandServer::start("127.0.0.1:0").unwrap();
        let mut client = TcpStream::connect(server.address()).unwrap();
        client
            .set_read_timeout(Some(Duration::from_millis(50)))
            .unwrap();
        let mut got = String::new();
        client
            .write_all(b"< rawmode >< open vcan9 >< send 123 0 >")
            .unwrap();
        read_until(&mut client, &mut got, "send needs rawmode");
        assert!(got.contains("< error open a bus before rawmode >"), "{got}");
        assert!(got.contains("could not open bus 'vcan9'"), "{got}");
        assert_eq!(server.refused_commands(), 3);
        assert!(server.try_recv().is_none());
    }

    /// python-can reads the rawmode `< ok >` with one `recv()` and compares it whole: a
    /// client that joins a running bus and reaches that `recv()` late must still find the
    /// reply alone, not glued to frames. It may send at once.
    #[test]
    fn the_rawmode_reply_is_not_glued_to_frames() {
        use crate::socketcand::RAW_MODE_GRACE;
        assert!(
            RAW_MODE_GRACE >= Duration::from_millis(30),
            "room for a late recv()"
        );
        let server = SocketcandServer::start("127.0.0.1:0").unwrap();
        let address = server.address();
        let client = std::thread::spawn(move || {
            let mut client = TcpStream::connect(address).unwrap();
            client
                .set_read_timeout(Some(Duration::from_millis(50)))
                .unwrap();
            let mut got = String::new();
            read_until(&mut client, &mut got, "< hi >");
            client.write_all(b"< open can0 >").unwrap();
            read_until(&mut client, &mut got, "< hi >< ok >");
            client.write_all(b"< rawmode >< send 123 1 01 >").unwrap();
            // A slow client: the reply (and, without the grace, frames) arrive before it
            // reads.
            std::thread::sleep(Duration::from_millis(10));
            read_until(&mut client, &mut got, "< hi >< ok >< ok >");
            let handshake = got.clone();
            // Frames follow after the grace.
            read_until(&mut client, &mut got, "< frame 003 ");
            handshake
        });
        // The bus is busy: a frame every millisecond.
        let mut t_us = 0;
        while !client.is_finished() {
            server.broadcast(t_us, &Frame::new(0x003, &[42]).unwrap(), None);
            t_us += 1000;
            std::thread::sleep(Duration::from_millis(1));
        }
        let handshake = client.join().unwrap();
        assert_eq!(
            handshake, "< hi >< ok >< ok >",
            "the rawmode reply must come alone"
        );
        // The send right after rawmode was accepted.
        assert_eq!(
            server.try_recv().map(|f| f.frame),
            Some(Frame::new(0x123, &[1]).unwrap())
        );
        assert_eq!(server.refused_commands(), 0);
    }
}

#[test]
fn plots_are_svg_with_every_series() {
    use crate::plot::{Axis, Plot, Series};
    let plot = Plot {
        title: "Cruise <hold>".into(),
        x_label: "Time (s)".into(),
        left_label: "Speed (km/h)".into(),
        right_label: "Command".into(),
        series: vec![
            Series {
                name: "Speed".into(),
                points: (0..100)
                    .map(|i| (i as f64 * 0.1, 80.0 + i as f64 * 0.1))
                    .collect(),
                axis: Axis::Left,
                steps: false,
            },
            Series {
                name: "Gear".into(),
                points: vec![(0.0, 1.0), (5.0, 2.0), (9.9, 2.0)],
                axis: Axis::Right,
                steps: true,
            },
            Series {
                name: "Empty".into(),
                points: vec![],
                axis: Axis::Left,
                steps: false,
            },
        ],
    };
    let svg = plot.to_svg();
    assert!(svg.starts_with("<svg"));
    assert!(svg.trim_end().ends_with("</svg>"));
    assert!(svg.contains("Cruise &lt;hold&gt;"));
    assert_eq!(svg.matches("<path").count(), 3);
    assert!(svg.contains("Gear (right)"));
    assert!(!svg.contains("NaN"));
    // Ticks land on round numbers covering the data: 0..10 s, 80..90 km/h.
    assert!(
        svg.contains(">10</text>") && svg.contains(">0</text>"),
        "x ticks"
    );
    assert!(
        svg.contains(">90</text>") && svg.contains(">80</text>"),
        "y ticks"
    );
}

#[test]
fn the_streamed_bus_log_and_trace_are_the_recorded_ones() {
    use crate::report::{run, run_streaming, write_bus_log, write_trace};
    let s = Scenario::parse(
        "name = \"stream\"\nduration_s = 1.5\n[driver]\naccelerator = 30.0\n",
        "stream",
    )
    .unwrap();
    let whole = run(&s);
    let mut recorded = Vec::new();
    write_bus_log(&mut recorded, &whole.log).unwrap();
    let mut recorded_trace = Vec::new();
    write_trace(&mut recorded_trace, &whole.trace).unwrap();
    let (mut streamed, mut streamed_trace) = (Vec::new(), Vec::new());
    let mut frames_seen = 0;
    let mut handed_over = None;
    let record = run_streaming(
        &s,
        &mut streamed,
        &mut streamed_trace,
        |_, frames| frames_seen += frames.len(),
        |record| {
            handed_over = Some(record.trace.len());
            Ok(())
        },
    )
    .unwrap();
    assert_eq!(handed_over, Some(record.trace.len()));
    assert!(record.log.is_empty(), "streamed runs keep no log in memory");
    assert!(recorded.len() > 1000);
    assert_eq!(streamed, recorded);
    // 151 rows and the header, written in batches beside the run.
    assert_eq!(
        String::from_utf8(streamed_trace.clone())
            .unwrap()
            .lines()
            .count(),
        152
    );
    assert_eq!(streamed_trace, recorded_trace);
    assert_eq!(record.trace, whole.trace);
    assert_eq!(
        frames_seen,
        String::from_utf8(recorded).unwrap().lines().count()
    );
}

/// A car standing still (for programming), with its ECUs as from the factory.
fn standing_car(cruise: &str) -> crate::car::VirtualCar {
    let text = format!(
        "name = \"standstill\"\nduration_s = 60.0\n[initial]\nspeed_kmh = 0.0\ngear = \"N\"\n[ecus]\ncruise = \"{cruise}\"\n"
    );
    let scenario = Scenario::parse(&text, "standstill").unwrap();
    let mut car = crate::car::VirtualCar::new(&scenario);
    car.capture_external_rx(true);
    car
}

/// Runs the car for `ms` ticks, returning the frames the external node received.
fn run_ms(car: &mut crate::car::VirtualCar, ms: u64) -> Vec<Frame> {
    let mut frames = Vec::new();
    for _ in 0..ms {
        car.tick();
        frames.extend(car.take_external_rx());
    }
    frames
}

#[test]
fn an_injected_frame_enters_at_the_time_the_bus_has_reached() {
    // Emulated MCUs run with the bus, window by window: a frame from outside must not run
    // the bus ahead of them (they would meet a tick of frames at once).
    let mut car = standing_car("correct");
    run_ms(&mut car, 20);
    let bus_ns = car.bus().now_ns();
    assert!(car.inject(Frame::new(0x70D, &[0x02, 0x10, 0x03, 0, 0, 0, 0, 0]).unwrap()));
    assert_eq!(car.bus().now_ns(), bus_ns, "the bus did not run ahead");
    // It is answered as before.
    let frames = run_ms(&mut car, 20);
    assert!(frames
        .iter()
        .any(|f| f.id() == 0x78D && f.data()[1] == 0x50));
}

#[test]
fn virtual_ecus_answer_uds_and_obd_on_their_identifiers() {
    use autoplug_can::Node;
    let mut car = standing_car("correct");
    run_ms(&mut car, 50);
    // Diagnostic session control to the cruise ECU (physical): a single-frame answer.
    assert!(
        car.inject(Frame::new(0x70D, &[0x02, 0x10, 0x03, 0xCC, 0xCC, 0xCC, 0xCC, 0xCC]).unwrap())
    );
    let frames = run_ms(&mut car, 20);
    let response = frames
        .iter()
        .find(|f| f.id() == 0x78D)
        .expect("a response on 0x78D");
    assert_eq!(
        response.data()[..7],
        [0x06, 0x50, 0x03, 0x00, 0x32, 0x01, 0xF4]
    );
    // OBD-II vehicle speed, functionally: the cruise ECU (which measures it) answers on
    // 0x7E9, nobody else.
    assert!(car.inject(Frame::new(0x7DF, &[0x02, 0x01, 0x0D, 0, 0, 0, 0, 0]).unwrap()));
    let frames = run_ms(&mut car, 20);
    let obd: Vec<_> = frames
        .iter()
        .filter(|f| (0x7E8..=0x7EF).contains(&f.id()))
        .collect();
    assert_eq!(obd.len(), 1, "{obd:?}");
    assert_eq!(
        (obd[0].id(), obd[0].data()[..3].to_vec()),
        (0x7E9, vec![0x03, 0x41, 0x0D])
    );
    // What each ECU runs is its factory image.
    for node in Node::ALL.into_iter().filter(|n| *n != Node::Gateway) {
        let diag = car.ecu_diag(node).unwrap();
        assert_eq!(diag.installed().version, crate::diag::FACTORY_VERSION);
        assert_eq!(
            usize::from(diag.installed().node),
            usize::from(node.diag_node_number().unwrap())
        );
    }
}

#[test]
fn communication_control_silences_the_application_frames() {
    let mut car = standing_car("correct");
    run_ms(&mut car, 100);
    // Extended session, then normal messages off, to every ECU at once (functional).
    car.inject(Frame::new(0x7DF, &[0x02, 0x10, 0x03, 0, 0, 0, 0, 0]).unwrap());
    run_ms(&mut car, 10);
    car.inject(Frame::new(0x7DF, &[0x03, 0x28, 0x03, 0x01, 0, 0, 0, 0]).unwrap());
    let answers = run_ms(&mut car, 20);
    let responses: Vec<u16> = Node::ECUS
        .iter()
        .filter_map(|n| n.diag_response_id())
        .collect();
    assert_eq!(
        answers
            .iter()
            .filter(|f| responses.contains(&f.id()) && f.data()[1] == 0x68)
            .count(),
        Node::ECUS.len(),
        "every ECU confirms"
    );
    let before = car.log().len();
    run_ms(&mut car, 200);
    let application = car.log()[before..]
        .iter()
        .filter(|f| f.frame.id() < 0x700)
        .count();
    assert_eq!(application, 0, "the bus is free for a download");
    // Without tester present, S3 ends the session after 5 s: the ECUs talk again.
    run_ms(&mut car, 5_100);
    let before = car.log().len();
    run_ms(&mut car, 100);
    assert!(car.log()[before..].iter().any(|f| f.frame.id() == 0x003));
}

#[test]
fn the_faulty_software_a_scenario_installs_is_what_the_ecu_reports() {
    let car = standing_car("faulty");
    let diag = car.ecu_diag(autoplug_can::Node::Cruise).unwrap();
    assert_eq!(
        diag.installed().variant,
        autoplug_image::SoftwareVariant::Faulty
    );
    assert!(
        !car.cruise_status().expect("host logic").engaged,
        "a standing car's cruise is off"
    );
}

#[test]
fn a_pass_through_neutral_is_not_a_shift() {
    use crate::report::shifts;
    assert_eq!(shifts(&[0, 1, 0, 2, 0, 3]), 2);
    assert_eq!(shifts(&[0, 1, 2, 1]), 2);
    assert_eq!(shifts(&[2, 0, 2]), 0, "back into the same gear");
    assert_eq!(shifts(&[0, -1, 0, 1]), 1);
    assert_eq!(shifts(&[0]), 0);
    assert_eq!(shifts(&[]), 0);
}

#[test]
fn a_person_at_the_wheel_drives_the_car_through_its_sensors() {
    use crate::car::VirtualCar;
    use crate::driver::HeldControls;
    let scenario = Scenario::parse(
        "name = \"free\"\nduration_s = 600.0\n[driver]\nbrake = 30.0\n[[at]]\nt_s = 1.0\nbrake = 0.0\naccelerator = 50.0\n",
        "test",
    )
    .unwrap();
    let mut car = VirtualCar::new(&scenario);
    let run = |car: &mut VirtualCar, s: f64| {
        let until = car.time_us() + (s * 1e6) as u64;
        while car.time_us() < until {
            car.tick();
        }
    };
    run(&mut car, 0.5);
    // The person takes over from the timeline's brake, and the timeline's later
    // accelerator event no longer moves the pedal.
    let person = car.take_wheel();
    assert_eq!(person.held().brake, 30.0);
    let release = HeldControls {
        brake: 0.0,
        ..*person.held()
    };
    person.hold(release).unwrap();
    run(&mut car, 3.0);
    assert_eq!(
        car.controls().held.accelerator,
        0.0,
        "the timeline no longer drives"
    );
    assert!(car.vehicle().speed_kmh() < 1.0);
    assert!(!car.trace_row().brake_lights);

    car.take_wheel()
        .hold(HeldControls {
            accelerator: 100.0,
            ..release
        })
        .unwrap();
    run(&mut car, 5.0);
    let fast = car.vehicle().speed_kmh();
    assert!(fast > 30.0, "full throttle for 5 s: {fast} km/h");

    car.take_wheel()
        .hold(HeldControls {
            brake: 80.0,
            ..release
        })
        .unwrap();
    run(&mut car, 0.3);
    assert!(
        car.trace_row().brake_lights,
        "the console lights the brake lights"
    );
    run(&mut car, 5.0);
    assert!(car.vehicle().speed_kmh() < fast - 20.0);

    // Out-of-range values are clamped, a NaN is refused and changes nothing.
    let person = car.take_wheel();
    person
        .hold(HeldControls {
            accelerator: 250.0,
            steering_deg: -1e6,
            ..release
        })
        .unwrap();
    assert_eq!(person.held().accelerator, 100.0);
    assert_eq!(person.held().steering_deg, -crate::driver::MAX_STEERING_DEG);
    assert!(person
        .hold(HeldControls {
            brake: f64::NAN,
            ..release
        })
        .is_err());
    assert_eq!(person.held().accelerator, 100.0);

    // A pressed button is held for the scenario's press time, from the next tick.
    car.take_wheel().press(Button::ShiftUp);
    car.tick();
    assert!(car.controls().buttons.shift_up);
    run(&mut car, 0.2);
    assert!(!car.controls().buttons.shift_up);

    assert!(car.set_friction(0.2, 1.0).is_ok());
    assert_eq!(car.friction(), (0.2, 1.0));
    assert!(car.set_friction(0.0, 1.0).is_err());
    assert!(car.set_friction(f64::NAN, 1.0).is_err());
}

#[test]
fn a_world_file_reads_back_and_a_damaged_one_keeps_what_precedes_the_damage() {
    use crate::world::{read_world_file, world_file_for, WorldFileWriter, WorldPose};
    let dir = tempfile::tempdir().unwrap();
    let candump = dir.path().join("drive.log");
    let path = world_file_for(&candump);
    assert_eq!(path.file_name().unwrap(), "drive.world.jsonl");
    let s = Scenario::parse(
        "name = \"x\"\nduration_s = 1\n[road]\ntrack = \"handling-circuit\"\n",
        "x",
    )
    .unwrap();
    let about = crate::world::description(
        s.track.as_deref(),
        &crate::car::VirtualCar::vehicle_params(),
    );
    assert_eq!(about["road"]["name"], "handling circuit");
    assert_eq!(about["road"]["patches"][0]["name"], "split-μ pad");
    assert_eq!(about["car"]["wheels"].as_array().unwrap().len(), 4);
    let mut car = crate::car::VirtualCar::new(&s);
    let mut writer = WorldFileWriter::create(&path).unwrap();
    writer.describe(&about.to_string()).unwrap();
    let mut written = Vec::new();
    for _ in 0..5 {
        for _ in 0..50 {
            car.tick();
        }
        let pose = WorldPose::of(&car);
        writer.pose(&pose.to_json()).unwrap();
        written.push(pose);
    }
    writer.flush().unwrap();
    drop(writer);
    let log = read_world_file(&path).unwrap();
    assert_eq!(log.description, about);
    assert_eq!(log.poses.len(), 5);
    assert_eq!(log.damaged, None);
    for (read, wrote) in log.poses.iter().zip(&written) {
        assert!((read.t_s - wrote.t_s).abs() < 1e-9 && (read.x_m - wrote.x_m).abs() < 1e-3);
    }
    // Cut in the middle of its last line: the poses before it stay.
    let text = std::fs::read_to_string(&path).unwrap();
    std::fs::write(&path, &text[..text.len() - 10]).unwrap();
    let log = read_world_file(&path).unwrap();
    assert_eq!(log.poses.len(), 4);
    assert!(
        log.damaged.as_deref().unwrap().contains("line 6"),
        "{:?}",
        log.damaged
    );
    // Not a world file at all.
    std::fs::write(&path, "[0,0,0,0,0,0,0]\n").unwrap();
    let refused = read_world_file(&path).unwrap_err();
    assert!(refused.contains("starts with its description"), "{refused}");
    std::fs::write(&path, "{\"description\":{}}\n[1,2,3]\n").unwrap();
    let short = read_world_file(&path).unwrap();
    assert!(short.damaged.unwrap().contains("not a pose"));
}

#[test]
fn the_timeline_puts_the_car_back_at_its_start_line() {
    use crate::car::VirtualCar;
    let scenario = Scenario::parse(
        "name = \"twice\"\nduration_s = 30.0\n[road]\ntrack = \"braking-straight\"\nstart_m = 20.0\n\
         [initial]\nspeed_kmh = 60.0\ngear = \"3\"\n[[at]]\nt_s = 1.0\nsteering_deg = 40.0\n\
         [[at]]\nt_s = 4.0\nto_start = true\nsteering_deg = 0.0\n",
        "twice.toml",
    )
    .unwrap();
    assert!(scenario.at[1].to_start && !scenario.at[0].to_start);
    let mut car = VirtualCar::new(&scenario);
    while car.time_us() < 3_990_000 {
        car.tick();
    }
    let before = car.vehicle().clone();
    assert!(
        before.x_m > 60.0 && before.heading_rad.abs() > 0.3,
        "{before:?}"
    );
    while car.time_us() < 4_020_000 {
        car.tick();
    }
    // Put back on the start line, standing, heading along the road; the odometer keeps
    // what the car drove.
    let after = car.vehicle().clone();
    assert!(
        (after.x_m - 20.0).abs() < 0.5 && after.y_m.abs() < 0.1,
        "{after:?}"
    );
    assert!(
        after.heading_rad.abs() < 1e-3 && after.speed_mps.abs() < 0.5,
        "{after:?}"
    );
    assert!(after.distance_m >= before.distance_m);
    assert!(car.track().unwrap().wheels().iter().all(|w| w.on_road));
}

#[test]
fn the_simulators_hand_turns_the_wheel_no_faster_than_a_hand() {
    // The dashboard's car on its circuit; a person holds the wheel at full left lock, then
    // lets the simulator steer along the road: it straightens the wheel, as fast as a
    // quick hand (the gateway's steering routine judges faster turns a faulty ECU).
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../scenarios/dashboard.toml"
    ))
    .unwrap();
    let scenario = Scenario::parse(&text, "dashboard").unwrap();
    let mut car = crate::car::VirtualCar::new(&scenario);
    let lock = crate::driver::MAX_STEERING_DEG;
    let mut held = *car.take_wheel().held();
    held.steering_deg = lock;
    car.take_wheel().hold(held).unwrap();
    run_ms(&mut car, 50);
    assert_eq!(car.controls().held.steering_deg, lock);
    car.set_steering_along_road(true).unwrap();
    let mut last = lock;
    let mut fastest: f64 = 0.0;
    for _ in 0..1000 {
        car.tick();
        let angle = car.controls().held.steering_deg;
        fastest = fastest.max((angle - last).abs() * 1000.0);
        last = angle;
    }
    assert!(
        fastest <= crate::car::HAND_RATE_DEG_S + 1e-6,
        "{fastest} °/s"
    );
    assert!(last.abs() < 10.0, "the wheel came back straight: {last}°");
}

#[test]
fn missing_firmware_is_named_all_at_once_with_the_commands_that_build_it() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("cruise-fw"), b"").unwrap();
    let choice = crate::firmware::FirmwareChoice::parse("all", dir.path()).unwrap();
    let missing = choice.missing();
    assert_eq!(
        missing.len(),
        autoplug_ecus::ECUS.len(),
        "every ECU but cruise, and the bootloader: {missing:?}"
    );
    let error = choice.check_files().unwrap_err();
    for file in ["engine-fw", "abs-fw", "boot"] {
        assert!(error.contains(file), "{error}");
    }
    assert!(!error.contains("cruise-fw"), "{error}");
    // The firmware in one build, the bootloader in one of its own.
    assert!(
        error.contains(
            "cargo build --profile firmware --target thumbv7em-none-eabihf -p ecu-engine"
        ),
        "{error}"
    );
    assert!(
        error.contains(
            "&& cargo build --profile firmware --target thumbv7em-none-eabihf -p autoplug-boot"
        ),
        "{error}"
    );
    let commands = crate::firmware::FirmwareChoice::build_commands(&missing);
    assert_eq!(commands.len(), 2);
    assert_eq!(
        commands[0].iter().filter(|a| *a == "-p").count(),
        autoplug_ecus::ECUS.len() - 1
    );
}
