use crate::candump::{parse_line, read_log, write_record};
use crate::driver::Timeline;
use crate::scenario::{Button, GearName, Scenario, Software};
use autoplug_can::Frame;

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
fn the_timeline_ramps_latches_and_presses() {
    let s = Scenario::parse(EXAMPLE, "example").unwrap();
    let mut timeline = Timeline::new(&s);
    let mut road_events = Vec::new();
    let c = timeline.advance(0.0, |_| {});
    assert_eq!((c.accelerator, c.buttons.cruise_on), (20.0, false));
    let c = timeline.advance(2.0, |_| {});
    assert_eq!((c.accelerator, c.buttons.cruise_on), (0.0, true));
    let c = timeline.advance(2.09, |_| {});
    assert!(c.buttons.cruise_on, "held for 100 ms");
    let c = timeline.advance(2.1, |_| {});
    assert!(!c.buttons.cruise_on, "released after 100 ms");
    let c = timeline.advance(6.0, |_| {});
    assert!(
        (c.steering_deg - 15.0).abs() < 1e-9,
        "half-way through the 2 s ramp: {}",
        c.steering_deg
    );
    assert!(c.headlights);
    let c = timeline.advance(7.5, |_| {});
    assert_eq!(c.steering_deg, 30.0);
    timeline.advance(20.0, |e| road_events.push(e.grade_percent));
    assert_eq!(road_events, vec![Some(6.0)]);
    timeline.advance(30.0, |e| road_events.push(e.grade_percent));
    assert_eq!(road_events.len(), 1, "each event fires once");
}

#[test]
fn candump_lines_round_trip() {
    let frame = Frame::new(0x00C, &[0x0A, 0x14, 0x1E, 0x28]).unwrap();
    let mut out = Vec::new();
    write_record(&mut out, 12_345_678, "can0", &frame).unwrap();
    write_record(&mut out, 5, "can0", &Frame::new(0x7FF, &[]).unwrap()).unwrap();
    let text = String::from_utf8(out).unwrap();
    assert_eq!(
        text,
        "(12.345678) can0 00C#0A141E28\n(0.000005) can0 7FF#\n"
    );
    let records = read_log(text.as_bytes()).unwrap();
    assert_eq!(records[0].t_us, 12_345_678);
    assert_eq!(records[0].frame, frame);
    assert_eq!(records[1].frame.len(), 0);
    // python-can's direction suffix and other timestamp precisions.
    let r = parse_line("(1436509052.249713) can0 044#2A366C2BBA R", 1).unwrap();
    assert_eq!(r.t_us, 1_436_509_052_249_713);
    assert_eq!(parse_line("(1.5) vcan0 123#00", 1).unwrap().t_us, 1_500_000);
}

#[test]
fn broken_log_lines_are_named() {
    let cases = [
        ("(1.0) can0 12345678#00", "11-bit identifiers"),
        ("(1.0) can0 123#0", "odd number of hex digits"),
        ("(1.0) can0 123#000102030405060708", "at most 8"),
        ("(1.0) can0 123##100", "CAN FD"),
        ("(1.0) can0 123#R", "remote frames"),
        ("1.0 can0 123#00", "not in parentheses"),
        ("(1.x) can0 123#00", "not seconds.fraction"),
        ("(1.0) can0 12G#00", "not hexadecimal"),
        ("(1.0) can0", "expected"),
        ("(1.0) can0 123#00 X", "unexpected \"X\""),
        ("(1.0) can0 800#00", "does not fit 11 bits"),
    ];
    for (line, expected) in cases {
        let e = parse_line(line, 7).unwrap_err();
        assert_eq!(e.line, 7);
        assert!(e.message.contains(expected), "{line}: {e}");
    }
    let text = "(1.0) can0 001#00\n\n(2.0) can0 002#01\n(3.0) can0 zz\n(4.0) can0 004#00\n";
    let (kept, e) = read_log(text.as_bytes()).unwrap_err();
    assert_eq!(kept.len(), 2, "records before the bad line are kept");
    assert_eq!(e.line, 4);
}
