//! The pin maps of the nine boards (`ecu-*/src/bin/*-fw/board.rs`): each board's table
//! names exactly the pins its code takes, every header position agrees with the
//! Nucleo-F446RE's connectors, no pin serves two signals, the pins the Nucleo reserves are
//! left alone, the bench tables of docs/src/ecus-and-bench.md are the boards' tables, and
//! each table is its ECU crate's `pins` declaration (which the firmware's scales and the
//! virtual car's wiring come from), with the F446's ADC and TIM3 channels for those pins.

use std::collections::{BTreeMap, BTreeSet};
use std::fs;
use std::path::{Path, PathBuf};

use autoplug_ecu::pins::{Pull, Signal};

/// Nucleo-F446RE header positions (ST UM1724): MCU pin, Arduino name ("—" for none),
/// Morpho position.
const HEADERS: &[(&str, &str, &str)] = &[
    ("PA0", "A0", "CN7-28"),
    ("PA1", "A1", "CN7-30"),
    ("PA4", "A2", "CN7-32"),
    ("PB0", "A3", "CN7-34"),
    ("PC1", "A4", "CN7-36"),
    ("PC0", "A5", "CN7-38"),
    ("PA10", "D2", "CN10-33"),
    ("PB3", "D3", "CN10-31"),
    ("PB5", "D4", "CN10-29"),
    ("PB4", "D5", "CN10-27"),
    ("PB10", "D6", "CN10-25"),
    ("PA8", "D7", "CN10-23"),
    ("PA9", "D8", "CN10-21"),
    ("PC7", "D9", "CN10-19"),
    ("PB6", "D10", "CN10-17"),
    ("PA7", "D11", "CN10-15"),
    ("PA6", "D12", "CN10-13"),
    ("PA5", "D13 (LD2)", "CN10-11"),
    ("PB9", "D14", "CN10-5"),
    ("PB8", "D15", "CN10-3"),
    ("PC8", "—", "CN10-2"),
    ("PC9", "—", "CN10-1"),
];

/// Pins the Nucleo uses itself: a board that took one would break the probe, the log or
/// the clock.
const RESERVED: &[(&str, &str)] = &[
    ("PA2", "ST-LINK virtual COM port TX"),
    ("PA3", "ST-LINK virtual COM port RX"),
    ("PA13", "SWDIO"),
    ("PA14", "SWCLK"),
    ("PH0", "HSE input (the ST-LINK's 8 MHz clock)"),
    ("PC14", "LSE crystal"),
    ("PC15", "LSE crystal"),
];

/// Every ECU's short name (`ecu-{name}/src/bin/{name}-fw/board.rs`), from the registry.
fn ecus() -> impl Iterator<Item = &'static str> {
    autoplug_ecus::ECUS.iter().map(|e| e.name)
}

const TABLE_HEADER: &str = "| Arduino | Morpho | MCU pin | signal | direction | electrical range |";

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn board_source(ecu: &str) -> String {
    let path = root().join(format!("ecu-{ecu}/src/bin/{ecu}-fw/board.rs"));
    fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The table rows of a board module's documentation, as lines without the `//! `.
fn table_rows(source: &str) -> Vec<String> {
    let lines: Vec<&str> = source
        .lines()
        .filter_map(|l| l.strip_prefix("//! "))
        .collect();
    let start = lines
        .iter()
        .position(|l| *l == TABLE_HEADER)
        .expect("the board documents its pins in the standard table");
    lines[start + 2..]
        .iter()
        .take_while(|l| l.starts_with('|'))
        .map(|l| l.to_string())
        .collect()
}

fn cells(row: &str) -> Vec<&str> {
    row.trim_matches('|').split('|').map(str::trim).collect()
}

/// The shared bring-up every board calls (`board_init!`, in autoplug-firmware), whose
/// pins (CAN1's) are the board's too.
fn shared_bring_up() -> String {
    let path = root().join("shared/firmware/src/lib.rs");
    let source = fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let start = source
        .find("macro_rules! board_init")
        .expect("autoplug-firmware defines board_init!");
    let end = source[start..]
        .find("\n}\n")
        .map_or(source.len(), |e| start + e);
    source[start..end].replace("$p.", "p.")
}

/// The GPIO pins a board's code takes from the HAL's peripherals (`p.PA0`, ...), the
/// shared bring-up's included when the board calls it.
fn board_pins(source: &str) -> BTreeSet<String> {
    let mut pins = pins_in_code(source);
    if source.contains("autoplug_firmware::board_init!(p, platform)") {
        pins.extend(pins_in_code(&shared_bring_up()));
    }
    pins
}

/// The GPIO pins the code takes from the HAL's peripherals (`p.PA0`, ...).
fn pins_in_code(source: &str) -> BTreeSet<String> {
    let code: String = source
        .lines()
        .filter(|l| !l.trim_start().starts_with("//"))
        .collect::<Vec<_>>()
        .join("\n");
    let mut pins = BTreeSet::new();
    let mut rest = code.as_str();
    while let Some(at) = rest.find("p.P") {
        let name: String = rest[at + 2..]
            .chars()
            .take_while(|c| c.is_ascii_alphanumeric())
            .collect();
        let is_pin = name.len() >= 3
            && matches!(name.as_bytes()[1], b'A'..=b'H')
            && name[2..].chars().all(|c| c.is_ascii_digit());
        if is_pin {
            pins.insert(name);
        }
        rest = &rest[at + 3..];
    }
    pins
}

#[test]
fn every_board_table_names_exactly_the_pins_its_code_takes() {
    for ecu in ecus() {
        let source = board_source(ecu);
        let rows = table_rows(&source);
        let mut documented = BTreeSet::new();
        for row in &rows {
            let cells = cells(row);
            assert_eq!(cells.len(), 6, "{ecu}: malformed row {row}");
            assert!(
                documented.insert(cells[2].to_string()),
                "{ecu}: {} serves two signals",
                cells[2]
            );
        }
        assert_eq!(
            documented,
            board_pins(&source),
            "{ecu}: the table and the code name different pins"
        );
    }
}

#[test]
fn header_positions_agree_with_the_nucleo_connectors() {
    let headers: BTreeMap<&str, (&str, &str)> =
        HEADERS.iter().map(|&(pin, a, m)| (pin, (a, m))).collect();
    for ecu in ecus() {
        for row in table_rows(&board_source(ecu)) {
            let cells = cells(&row);
            let (arduino, morpho, pin) = (cells[0], cells[1], cells[2]);
            let expected = headers
                .get(pin)
                .unwrap_or_else(|| panic!("{ecu}: {pin} is not a known header pin"));
            assert_eq!(
                (arduino, morpho),
                *expected,
                "{ecu}: {pin} is at {expected:?} on the Nucleo-F446RE"
            );
            assert!(
                matches!(cells[4], "in" | "out"),
                "{ecu}: {pin} direction must be in or out, not {}",
                cells[4]
            );
        }
    }
}

#[test]
fn no_board_takes_a_pin_the_nucleo_reserves() {
    for ecu in ecus() {
        let pins = board_pins(&board_source(ecu));
        for (pin, use_) in RESERVED {
            assert!(!pins.contains(*pin), "{ecu} takes {pin}, the {use_}");
        }
    }
}

#[test]
fn every_board_is_on_can1_at_pb8_pb9() {
    assert!(
        shared_bring_up().contains("Can::new(p.CAN1, p.PB8, p.PB9, $crate::can_io::Irqs)"),
        "the shared bring-up puts CAN1 on PB8 (RX) / PB9 (TX), the bench's common wiring"
    );
    for ecu in ecus() {
        let source = board_source(ecu);
        assert!(
            source.contains("autoplug_firmware::board_init!(p, platform)")
                && !source.contains("p.CAN1"),
            "{ecu}: the board brings CAN1 up through board_init! (the bench's common wiring)"
        );
    }
}

#[test]
fn the_readme_bench_tables_are_the_boards_tables() {
    let readme = fs::read_to_string(root().join("docs/src/ecus-and-bench.md")).expect("book page");
    for ecu in ecus() {
        let rows = table_rows(&board_source(ecu));
        let block = format!(
            "{TABLE_HEADER}\n|---|---|---|---|---|---|\n{}\n",
            rows.join("\n")
        );
        let heading = format!("#### {ecu}-fw");
        let section = readme
            .split("\n#### ")
            .find(|s| format!("#### {s}").starts_with(&heading))
            .unwrap_or_else(|| panic!("docs/src/ecus-and-bench.md: no section '{heading}'"));
        assert!(
            section.contains(&block),
            "docs/src/ecus-and-bench.md, {heading}: the wiring table differs from \
             ecu-{ecu}/src/bin/{ecu}-fw/board.rs; copy the board's table:\n{block}"
        );
    }
}

/// Each ECU's declared signals (its crate's `pins::SIGNALS`, from the registry).
fn declared(ecu: &str) -> &'static [Signal] {
    autoplug_ecus::by_name(ecu)
        .unwrap_or_else(|| panic!("no ECU {ecu}"))
        .signals
}

/// ADC1's input channel of an F446 pin (RM0390 / DS10693 pin table), for the Nucleo's
/// analog header pins.
fn adc1_channel(pin: &str) -> Option<u8> {
    Some(match pin {
        "PA0" => 0,
        "PA1" => 1,
        "PA4" => 4,
        "PB0" => 8,
        "PC1" => 11,
        "PC0" => 10,
        _ => return None,
    })
}

/// TIM3's channel on an F446 pin (alternate function 2, DS10693 table 11).
fn tim3_channel(pin: &str) -> Option<u8> {
    Some(match pin {
        "PA6" | "PB4" | "PC6" => 1,
        "PA7" | "PB5" | "PC7" => 2,
        "PB0" | "PC8" => 3,
        "PB1" | "PC9" => 4,
        _ => return None,
    })
}

#[test]
fn every_board_table_is_its_crates_pin_declaration() {
    for ecu in ecus() {
        let source = board_source(ecu);
        let mut documented = BTreeMap::new();
        for row in table_rows(&source) {
            let cells = cells(&row);
            if matches!(cells[2], "PB8" | "PB9") {
                continue; // CAN1, the same on every board (checked above)
            }
            documented.insert(
                cells[2].to_string(),
                (cells[3].to_string(), cells[4] == "in"),
            );
        }
        let signals = declared(ecu);
        let pins: BTreeSet<String> = signals.iter().map(|s| s.pin().to_string()).collect();
        assert_eq!(
            pins,
            documented.keys().cloned().collect(),
            "{ecu}: the table and ecu-{ecu}/src/pins.rs name different pins"
        );
        assert_eq!(pins.len(), signals.len(), "{ecu}: a pin declared twice");
        for signal in signals {
            let pin = signal.pin().to_string();
            let (text, input) = &documented[&pin];
            assert_eq!(*input, signal.is_input(), "{ecu}: {pin}'s direction");
            match signal {
                Signal::Analog(a) => {
                    assert_eq!(
                        adc1_channel(&pin),
                        Some(a.adc_channel),
                        "{ecu}: {pin}'s ADC channel"
                    );
                    assert!(
                        text.contains(&format!("(ADC1_IN{})", a.adc_channel)),
                        "{ecu}: {pin}'s row names another channel: {text}"
                    );
                }
                Signal::Pwm(p) => {
                    assert_eq!(
                        tim3_channel(&pin),
                        Some(p.tim3_channel),
                        "{ecu}: {pin}'s TIM3 channel"
                    );
                    assert!(
                        text.contains(&format!("(TIM3_CH{} PWM)", p.tim3_channel)),
                        "{ecu}: {pin}'s row names another channel: {text}"
                    );
                }
                Signal::Input(d) => {
                    let pull = match d.pull {
                        Pull::Up => "Pull::Up",
                        Pull::Down => "Pull::Down",
                    };
                    assert!(
                        source.contains(&format!("Input::new(p.{pin}, {pull})")),
                        "{ecu}: the code does not take {pin} as an input with {pull}"
                    );
                }
                Signal::Output(_) => assert!(
                    source.contains(&format!("Output::new(p.{pin}, Level::Low")),
                    "{ecu}: the code does not take {pin} as an output, low at power-up"
                ),
            }
        }
        // The scales come from the declaration: a board states none of its own.
        for literal in ["LinearInput::new(", "LinearOutput::new("] {
            assert!(
                !source.contains(literal),
                "{ecu}: board.rs builds a scale ({literal}...); take it from ecu-{ecu}/src/pins.rs"
            );
        }
    }
}
