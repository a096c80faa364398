use crate::*;

const CATALOGUE: &str = include_str!("../../can/autoplug.dbc");

const SMALL: &str = r#"VERSION "t"
NS_ :
	CM_
BS_:
BU_: A B
VAL_TABLE_ Onoff 1 "On" 0 "Off" ;
BO_ 16 Msg: 2 A
 SG_ Speed : 0|8@1+ (0.5,-10) [-10|117.5] "km/h" B
 SG_ Mode : 8|2@1+ (1,0) [0|1] "" B,A
BA_DEF_ BO_ "GenMsgCycleTime" INT 0 65535;
BA_DEF_DEF_ "GenMsgCycleTime" 0;
BA_DEF_  "Baudrate" INT 0 1000000;
BA_ "Baudrate" 500000;
BA_ "GenMsgCycleTime" BO_ 16 20;
CM_ SG_ 16 Speed "a \"quoted\" word";
VAL_ 16 Mode 1 "On" 0 "Off" ;
"#;

fn parse_err(text: &str) -> ParseError {
    parse(text).expect_err("should not parse")
}

fn invalid(text: &str) -> Vec<String> {
    match load(text) {
        Err(Error::Invalid(errors)) => errors.iter().map(|e| e.to_string()).collect(),
        other => panic!("expected validation errors, got {other:?}"),
    }
}

#[test]
fn reads_a_small_database() {
    let db = load(SMALL).expect("valid");
    assert_eq!(db.version, "t");
    assert_eq!(db.nodes.len(), 2);
    let m = db.message("Msg").unwrap();
    assert_eq!(
        (m.id, m.dlc, m.transmitters.clone()),
        (16, 2, vec!["A".to_string()])
    );
    let s = m.signal("Speed").unwrap();
    assert_eq!((s.start_bit, s.length, s.signed), (0, 8, false));
    assert_eq!(
        (s.factor, s.offset, s.min, s.max),
        (0.5, -10.0, -10.0, 117.5)
    );
    assert_eq!(s.raw_range(), (0, 255));
    assert_eq!(s.comment.as_deref(), Some("a \"quoted\" word"));
    let mode = m.signal("Mode").unwrap();
    assert_eq!(mode.receivers, vec!["B".to_string(), "A".to_string()]);
    assert_eq!(
        mode.value_descriptions,
        vec![(1, "On".into()), (0, "Off".into())]
    );
    assert_eq!(
        db.message_attribute(m, "GenMsgCycleTime")
            .and_then(AttributeValue::as_int),
        Some(20)
    );
    assert_eq!(
        db.network_attribute("Baudrate")
            .and_then(AttributeValue::as_int),
        Some(500_000)
    );
}

#[test]
fn the_catalogue_loads_and_generates() {
    let db = load(CATALOGUE).expect("catalogue is valid");
    // 18 application messages, 9 UDS request and 9 response identifiers, the functional
    // request and 2 OBD-II responses.
    assert_eq!(db.messages.len(), 18 + 9 + 9 + 1 + 2);
    let cruise_mode = db.message("CruiseModeMsg").unwrap();
    assert_eq!(cruise_mode.transmitters, vec!["Steering", "Pedals"]);
    let rpm = db
        .message("EngineMsg")
        .unwrap()
        .signal("EngineRPM")
        .unwrap();
    assert_eq!(
        rpm.raw_range(),
        (0, 255),
        "9000/255 must keep its end point"
    );
    let yaw = db
        .message("YawErrorMsg")
        .unwrap()
        .signal("YawRateError")
        .unwrap();
    assert_eq!(yaw.raw_range(), (-127, 127));
    let steering = db
        .message("SteeringMsg")
        .unwrap()
        .signal("SteeringAngle")
        .unwrap();
    assert_eq!(steering.raw_range(), (10, 90));
    let code = generate(&db).expect("generates");
    assert!(code.contains("pub struct EngineMsg"));
    assert!(code.contains("pub enum Gear"));
}

#[test]
fn syntax_errors_name_line_and_column() {
    let e = parse_err("VERSION \"x\"\nBO_ 1 M: 1 A\n SG_ S : 0|8@2+ (1,0) [0|1] \"\" A\n");
    assert_eq!((e.line, e.column), (3, 14));
    assert!(e.message.contains("byte order"), "{e}");

    let e = parse_err("BO_ 1 M 1 A\n");
    assert_eq!(e.line, 1);
    assert!(e.message.contains("expected ':'"), "{e}");

    let e = parse_err("VERSION \"open");
    assert!(e.message.contains("not closed"), "{e}");

    let e = parse_err("BO_ 1 M: 1 A\n SG_ S : 0|8@1* (1,0) [0|1] \"\" A\n");
    assert!(e.message.contains("unexpected character '*'"), "{e}");

    let e = parse_err("SIG_VALTYPE_ 1 S : 1;\n");
    assert!(
        e.message
            .contains("unsupported DBC statement 'SIG_VALTYPE_'"),
        "{e}"
    );

    let e = parse_err("BU_: A\nBO_ 1 M: 1 A\n SG_ S : 0|8@1+ (x,0) [0|1] \"\" A\n");
    assert!(e.message.contains("expected factor"), "{e}");

    let e = parse_err("BU_: A\nBO_ 1 M: 1 A\nCM_ SG_ 1 T \"no such signal\";\n");
    assert!(e.message.contains("has no signal 'T'"), "{e}");

    let e = parse_err("BA_ \"Nope\" BO_ 1 3;\n");
    assert!(e.message.contains("not defined"), "{e}");

    let e = parse_err("BA_DEF_ BO_ \"C\" INT 0 10;\nBU_: A\nBO_ 1 M: 1 A\nBA_ \"C\" BO_ 1 11;\n");
    assert!(e.message.contains("outside 0..=10"), "{e}");

    let e = parse_err("BO_ 1 M: 1 A\n SG_ S : 0|8@1+ (1,0) [0|1] \"\" A\n SG_");
    assert!(e.message.contains("file ends"), "{e}");
}

#[test]
fn inconsistencies_are_all_reported() {
    let text = r#"BU_: A B
BO_ 1 M: 1 A
 SG_ X : 0|8@1+ (1,0) [0|255] "" B
 SG_ Y : 4|8@1+ (1,0) [0|255] "" C
BO_ 1 N: 9 Z
 SG_ W : 0|8@1+ (1,0) [0|300] "" B
BO_ 2 P: 1 A
 SG_ V : 0|8@1- (1,0) [0|2] "" B
VAL_ 2 V 5 "Five" ;
BO_ 3 Q: 1 A
 SG_ U : 4|8@1+ (1,0) [0|255] "" B
"#;
    let errors = invalid(text);
    let joined = errors.join("\n");
    for expected in [
        "line 4: signal M.Y: bit 4 is also used by signal X",
        "line 4: signal M.Y: receiver C is not a node",
        "line 5: message N: identifier 0x1 is used twice",
        "line 5: message N: length 9 bytes exceeds classic CAN's 8",
        "line 5: message N: transmitter Z is not a node",
        "line 6: signal N.W: range [0|300] needs raw 0..300, but 8 bits hold only 0..=255",
        "line 8: signal P.V: value description 5 \"Five\" lies outside the valid raw range 0..=2",
        "line 11: signal Q.U: bit 8 lies beyond the message's 1 bytes",
    ] {
        assert!(
            joined.lines().any(|l| l.starts_with(expected)),
            "missing {expected:?} in\n{joined}"
        );
    }
}

#[test]
fn generator_refuses_what_it_cannot_express() {
    let motorola = "BU_: A\nBA_DEF_ \"Baudrate\" INT 0 1000000;\nBA_ \"Baudrate\" 500000;\nBO_ 1 M: 2 A\n SG_ S : 7|8@0+ (1,0) [0|255] \"\" A\n";
    match compile(motorola) {
        Err(Error::Generate(e)) => assert!(e.to_string().contains("Motorola"), "{e}"),
        other => panic!("{other:?}"),
    }
    let start = "BU_: A\nBA_DEF_ \"Baudrate\" INT 0 1000000;\nBA_ \"Baudrate\" 500000;\nBO_ 1 M: 1 A\n SG_ S : 0|8@1+ (1,0) [10|20] \"\" A\n";
    match compile(start) {
        Err(Error::Generate(e)) => {
            assert!(e.to_string().contains("line 5"), "{e}");
            assert!(e.to_string().contains("GenSigStartValue"), "{e}");
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn every_signal_has_its_own_vss_path_where_the_dbc_defines_them() {
    let head = "BU_: A\nBA_DEF_ \"Baudrate\" INT 0 1000000;\nBA_ \"Baudrate\" 500000;\nBA_DEF_ SG_ \"VssPath\" STRING ;\nBA_DEF_DEF_ \"VssPath\" \"\";\nBO_ 1 M: 2 A\n SG_ S : 0|8@1+ (1,0) [0|255] \"\" A\n SG_ T : 8|8@1+ (1,0) [0|255] \"\" A\n";
    let ok = format!("{head}BA_ \"VssPath\" SG_ 1 S \"Vehicle.Speed\";\nBA_ \"VssPath\" SG_ 1 T \"Vehicle.Private.X.T\";\n");
    let code = compile(&ok).expect("valid");
    assert!(code.contains("vss: \"Vehicle.Speed\""), "{code}");
    for (text, expected) in [
        (format!("{head}BA_ \"VssPath\" SG_ 1 S \"Vehicle.Speed\";\n"), "M.T has no VssPath"),
        (format!("{head}BA_ \"VssPath\" SG_ 1 S \"Vehicle.Speed\";\nBA_ \"VssPath\" SG_ 1 T \"Vehicle.Speed\";\n"), "already signal M.S's"),
        (format!("{head}BA_ \"VssPath\" SG_ 1 S \"Speed\";\nBA_ \"VssPath\" SG_ 1 T \"Vehicle.T\";\n"), "is not a VSS path"),
    ] {
        match compile(&text) {
            Err(Error::Generate(e)) => assert!(e.to_string().contains(expected), "{e}"),
            other => panic!("expected {expected:?}, got {other:?}"),
        }
    }
}

#[test]
fn motorola_bits_walk_across_bytes() {
    let s = Signal {
        start_bit: 7,
        length: 12,
        byte_order: ByteOrder::BigEndian,
        ..Signal::default()
    };
    assert_eq!(s.bits(), vec![7, 6, 5, 4, 3, 2, 1, 0, 15, 14, 13, 12]);
}

#[test]
fn names_become_rust_identifiers() {
    use crate::codegen::{snake_case, variant_ident};
    assert_eq!(snake_case("EngineRPM"), "engine_rpm");
    assert_eq!(snake_case("WheelSpeedFL"), "wheel_speed_fl");
    assert_eq!(snake_case("RPMValue"), "rpm_value");
    assert_eq!(snake_case("yaw_rate"), "yaw_rate");
    assert_eq!(variant_ident("no request"), "NoRequest");
    assert_eq!(variant_ident("1st"), "V1st");
    assert_eq!(variant_ident("Sixth"), "Sixth");
}

/// A network with diagnostics, as the catalogue declares them; `extra` is appended.
fn diag_network(request_id: u32, extra: &str) -> String {
    format!(
        "BU_: A T\nBA_DEF_ \"Baudrate\" INT 0 1000000;\nBA_DEF_ BU_ \"DiagNodeNumber\" INT 0 255;\n\
         BA_DEF_ BO_ \"DiagKind\" ENUM \"None\",\"PhysicalRequest\",\"PhysicalResponse\",\"FunctionalRequest\",\"ObdResponse\";\n\
         BA_DEF_DEF_ \"DiagKind\" \"None\";\nBA_ \"Baudrate\" 500000;\nBA_ \"DiagNodeNumber\" BU_ A 3;\n\
         BO_ {request_id} ReqA: 8 T\n SG_ Data : 0|64@1+ (1,0) [0|0] \"\" A\n\
         BO_ 1923 RespA: 8 A\n SG_ Data : 0|64@1+ (1,0) [0|0] \"\" T\n\
         BO_ 2015 Functional: 8 T\n SG_ Data : 0|64@1+ (1,0) [0|0] \"\" A\n\
         BA_ \"DiagKind\" BO_ {request_id} 1;\nBA_ \"DiagKind\" BO_ 1923 2;\nBA_ \"DiagKind\" BO_ 2015 3;\n{extra}"
    )
}

#[test]
fn diagnostic_identifiers_follow_the_node_numbers() {
    let source = compile(&diag_network(0x703, "")).expect("a sound diagnostic network");
    assert!(source.contains("pub const DIAG_FUNCTIONAL_REQUEST_ID: u16 = 0x7DF;"));
    assert!(source.contains("Node::A => Some(0x703),"), "{source}");
    assert!(source.contains("Node::A => Some(0x783),"), "{source}");
    // Transport messages are not codec messages: no struct, not in the receive filters.
    assert!(!source.contains("pub struct ReqA"), "{source}");
    assert!(source.contains("Node::A => &[],"), "{source}");

    match compile(&diag_network(0x704, "")) {
        Err(Error::Generate(e)) => {
            assert!(e.to_string().contains("0x704"), "{e}");
            assert!(e.to_string().contains("gives 0x703"), "{e}");
        }
        other => panic!("{other:?}"),
    }
    let obd = "BO_ 2032 ObdA: 8 A\n SG_ Data : 0|64@1+ (1,0) [0|0] \"\" T\nBA_ \"DiagKind\" BO_ 2032 4;\n";
    match compile(&diag_network(0x703, obd)) {
        Err(Error::Generate(e)) => assert!(e.to_string().contains("0x7E8..=0x7EF"), "{e}"),
        other => panic!("{other:?}"),
    }
    let short = diag_network(0x703, "").replace(
        "BO_ 1923 RespA: 8 A\n SG_ Data : 0|64@1+",
        "BO_ 1923 RespA: 8 A\n SG_ Data : 0|32@1+",
    );
    match compile(&short) {
        Err(Error::Generate(e)) => assert!(e.to_string().contains("64-bit"), "{e}"),
        other => panic!("{other:?}"),
    }
}

#[test]
fn network_trouble_codes_come_from_the_node_attributes() {
    let defs =
        "BA_DEF_ BU_ \"LostCommunicationDtc\" STRING ;\nBA_DEF_ BU_ \"InvalidDataDtc\" STRING ;\n\
                BA_DEF_DEF_ \"LostCommunicationDtc\" \"\";\nBA_DEF_DEF_ \"InvalidDataDtc\" \"\";\n";
    let codes = |a: &str, t: &str| {
        format!(
            "BA_ \"LostCommunicationDtc\" BU_ A \"{a}\";\nBA_ \"InvalidDataDtc\" BU_ A \"U0401\";\n\
             BA_ \"LostCommunicationDtc\" BU_ T \"{t}\";\nBA_ \"InvalidDataDtc\" BU_ T \"U0446\";\n"
        )
    };
    let source = compile(&diag_network(
        0x703,
        &format!("{defs}{}", codes("U0100", "U0146")),
    ))
    .expect("a catalogue with its trouble codes");
    assert!(source.contains("Node::A => (0xC100, 0xC401),"), "{source}");
    assert!(source.contains("Node::T => (0xC146, 0xC446),"), "{source}");
    // Without the attributes there is no method; with them, every node needs a sound code.
    assert!(!compile(&diag_network(0x703, ""))
        .expect("sound")
        .contains("network_dtc_codes"));
    for (a, t, expected) in [
        ("U0100", "", "node T: LostCommunicationDtc"),
        ("U4100", "U0146", "node A: LostCommunicationDtc"),
        ("X0100", "U0146", "\"X0100\""),
        ("U01000", "U0146", "\"U01000\""),
    ] {
        match compile(&diag_network(0x703, &format!("{defs}{}", codes(a, t)))) {
            Err(Error::Generate(e)) => assert!(e.to_string().contains(expected), "{expected}: {e}"),
            other => panic!("expected {expected:?}, got {other:?}"),
        }
    }
}
