//! `autoplug diagnose` and `autoplug replay` on logs the virtual car wrote.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use autoplug_virtual_car::report;
use autoplug_virtual_car::scenario::Scenario;

fn autoplug(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_autoplug"))
        .args(args)
        .output()
        .expect("the autoplug binary runs")
}

/// Runs a shipped scenario and writes its bus log into `dir`.
fn bus_log(dir: &Path, scenario: &str) -> PathBuf {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let scenario = Scenario::load(&root.join(format!("scenarios/{scenario}.toml"))).unwrap();
    let record = report::run(&scenario);
    let path = dir.join(format!("{}.log", scenario.name));
    let mut file = std::io::BufWriter::new(std::fs::File::create(&path).unwrap());
    report::write_bus_log(&mut file, &record.log).unwrap();
    drop(file);
    path
}

#[test]
fn diagnose_flags_the_faulty_cruise_with_its_number_and_exit_status_3() {
    let dir = tempfile::tempdir().unwrap();
    let log = bus_log(dir.path(), "cruise-faulty");
    let output = autoplug(&["diagnose", "--json", log.to_str().unwrap()]);
    assert_eq!(output.status.code(), Some(3), "{output:?}");
    let json: serde_json::Value = serde_json::from_slice(&output.stdout).unwrap();
    assert_eq!(json["any_faulty"], true);
    let ecus = json["ecus"].as_array().unwrap();
    assert_eq!(ecus.len(), 9);
    for ecu in ecus {
        let name = ecu["ecu"].as_str().unwrap();
        let expected = if name == "cruise" { "faulty" } else { "ok" };
        assert_eq!(ecu["verdict"], expected, "{ecu}");
    }
    let cruise = ecus.iter().find(|e| e["ecu"] == "cruise").unwrap();
    assert_eq!(cruise["unit"], "km/h rms");
    assert!(cruise["number"].as_f64().unwrap() > cruise["faulty_above"].as_f64().unwrap());
    let window = cruise["window_s"].as_array().unwrap();
    assert!(window[1].as_f64().unwrap() > window[0].as_f64().unwrap() + 5.0);
    assert!(String::from_utf8_lossy(&output.stderr).contains("judged faulty: cruise"));

    // The table says the same, and replay runs the same pipeline.
    let table = autoplug(&["diagnose", log.to_str().unwrap()]);
    let text = String::from_utf8_lossy(&table.stdout);
    assert!(
        text.lines()
            .any(|l| l.starts_with("cruise") && l.contains("faulty") && l.contains("km/h rms")),
        "{text}"
    );
    let replay = autoplug(&["replay", log.to_str().unwrap()]);
    assert!(replay.status.success(), "{replay:?}");
    let text = String::from_utf8_lossy(&replay.stdout);
    assert!(text.contains("Vehicle.Speed"), "{text}");
    assert!(text.contains("VehicleSpeedMsg  0x003"), "{text}");
}

#[test]
fn diagnose_on_correct_software_exits_0() {
    let dir = tempfile::tempdir().unwrap();
    let log = bus_log(dir.path(), "stop-100-dry");
    let output = autoplug(&["diagnose", log.to_str().unwrap()]);
    assert_eq!(output.status.code(), Some(0), "{output:?}");
}

#[test]
fn a_malformed_line_is_named_and_lenient_mode_counts_it() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("bad.log");
    std::fs::write(
        &log,
        "(0.000000) can0 003#50\n(0.010000) can0 003#5\n(0.020000) can0 003#50\n",
    )
    .unwrap();
    let strict = autoplug(&["diagnose", log.to_str().unwrap()]);
    assert_eq!(strict.status.code(), Some(1));
    let message = String::from_utf8_lossy(&strict.stderr);
    assert!(message.contains("line 2"), "{message}");
    assert!(message.contains("--lenient"), "{message}");
    let lenient = autoplug(&["diagnose", "--lenient", "--json", log.to_str().unwrap()]);
    assert_eq!(lenient.status.code(), Some(0), "{lenient:?}");
    let json: serde_json::Value = serde_json::from_slice(&lenient.stdout).unwrap();
    assert_eq!(json["malformed_lines_skipped"], 1);
    assert_eq!(json["frames"], 2);
    let missing = autoplug(&["diagnose", "/nonexistent/x.log"]);
    assert_eq!(missing.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&missing.stderr).contains("/nonexistent/x.log"));
}

/// `autoplug replay log | head`: the reader leaving early is no error and no panic.
#[test]
fn replay_into_a_reader_gone_away_exits_0() {
    let dir = tempfile::tempdir().unwrap();
    let log = bus_log(dir.path(), "stop-100-dry");
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_autoplug"))
        .arg("replay")
        .arg(&log)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("the autoplug binary runs");
    drop(child.stdout.take());
    let output = child.wait_with_output().expect("it ends");
    let err = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "{:?}: {err}", output.status);
    assert!(err.is_empty(), "{err}");
}
