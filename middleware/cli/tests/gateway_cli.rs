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
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
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
    assert_eq!(ecus.len(), autoplug_can::Node::ECUS.len());
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

/// The faulty drive exported to MF4 (plain and compressed) is judged as its log is: the
/// same numbers, to the last digit, and `replay` reads the MF4 back frame for frame.
#[test]
fn an_mf4_export_is_diagnosed_as_the_log_it_came_from() {
    let dir = tempfile::tempdir().unwrap();
    let log = bus_log(dir.path(), "cruise-faulty");
    let original = autoplug(&["diagnose", "--json", log.to_str().unwrap()]);
    let original: serde_json::Value = serde_json::from_slice(&original.stdout).unwrap();
    for compress in [false, true] {
        let mf4 = dir.path().join(format!("drive-{compress}.mf4"));
        let mut args = vec![
            "log",
            "export",
            log.to_str().unwrap(),
            "--format",
            "mf4",
            "--out",
            mf4.to_str().unwrap(),
        ];
        if compress {
            args.push("--compress");
        }
        let export = autoplug(&args);
        assert!(export.status.success(), "{export:?}");
        let said = String::from_utf8_lossy(&export.stdout);
        assert!(
            said.contains("decoded into their messages' signals"),
            "{said}"
        );
        let output = autoplug(&["diagnose", "--json", mf4.to_str().unwrap()]);
        assert_eq!(output.status.code(), Some(3), "{output:?}");
        let mut json: serde_json::Value = serde_json::from_slice(&output.stdout).unwrap();
        json["log"] = original["log"].clone();
        assert_eq!(json, original);
        let frames: Vec<_> = autoplug_logs::open(&mf4)
            .unwrap()
            .map(|f| f.unwrap())
            .collect();
        let logged: Vec<_> = autoplug_logs::open(&log)
            .unwrap()
            .map(|f| f.unwrap())
            .collect();
        assert_eq!(frames, logged);
    }
    let refused = autoplug(&[
        "log",
        "export",
        log.to_str().unwrap(),
        "--format",
        "asc",
        "--compress",
        "--out",
        dir.path().join("x.asc").to_str().unwrap(),
    ]);
    assert!(!refused.status.success());
    assert!(String::from_utf8_lossy(&refused.stderr).contains("--compress is for --format mf4"));
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

/// A BLF file of these frames as CANoe and python-can write them: CAN_MESSAGE objects in
/// zlib containers of 128 KiB of objects each.
fn blf_of(frames: &[autoplug_logs::LogFrame]) -> Vec<u8> {
    use std::io::Write;
    let mut file = b"LOGG".to_vec();
    file.extend_from_slice(&144u32.to_le_bytes());
    file.resize(40, 0);
    // Measurement start 2023-11-14 22:13:20.000 (a Tuesday), and its end.
    for _ in 0..2 {
        for v in [2023u16, 11, 2, 14, 22, 13, 20, 0] {
            file.extend_from_slice(&v.to_le_bytes());
        }
    }
    file.resize(144, 0);
    let mut objects = Vec::new();
    for f in frames {
        objects.extend_from_slice(b"LOBJ");
        objects.extend_from_slice(&32u16.to_le_bytes());
        objects.extend_from_slice(&1u16.to_le_bytes());
        objects.extend_from_slice(&48u32.to_le_bytes());
        objects.extend_from_slice(&1u32.to_le_bytes());
        objects.extend_from_slice(&2u32.to_le_bytes()); // nanoseconds
        objects.extend_from_slice(&[0; 4]);
        objects.extend_from_slice(&(f.t_us * 1000).to_le_bytes());
        objects.extend_from_slice(&(u16::from(f.channel) + 1).to_le_bytes());
        objects.push(0);
        objects.push(f.len() as u8);
        objects.extend_from_slice(&f.id.to_le_bytes());
        let mut data = [0u8; 8];
        data[..f.data().len()].copy_from_slice(f.data());
        objects.extend_from_slice(&data);
    }
    for chunk in objects.chunks(128 * 1024) {
        let mut zlib = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
        zlib.write_all(chunk).unwrap();
        let packed = zlib.finish().unwrap();
        let size = 32 + packed.len();
        file.extend_from_slice(b"LOBJ");
        file.extend_from_slice(&16u16.to_le_bytes());
        file.extend_from_slice(&1u16.to_le_bytes());
        file.extend_from_slice(&(size as u32).to_le_bytes());
        file.extend_from_slice(&10u32.to_le_bytes());
        file.extend_from_slice(&2u16.to_le_bytes());
        file.extend_from_slice(&[0; 6]);
        file.extend_from_slice(&(chunk.len() as u32).to_le_bytes());
        file.extend_from_slice(&[0; 4]);
        file.extend_from_slice(&packed);
        file.resize(file.len() + size % 4, 0);
    }
    file
}

fn scenario_frames(name: &str) -> Vec<autoplug_logs::LogFrame> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let scenario = Scenario::load(&root.join(format!("scenarios/{name}.toml"))).unwrap();
    report::run(&scenario)
        .log
        .iter()
        .map(|f| autoplug_logs::LogFrame::from_can(f.t_us, 0, &f.frame))
        .collect()
}

/// A logger that lost power: the BLF's last 200 bytes never reached the disk. Everything
/// before the damage is read, reported and exported; the error says where, and the exit
/// status (4) says the log was incomplete.
#[test]
fn a_blf_cut_short_keeps_what_precedes_the_damage() {
    let dir = tempfile::tempdir().unwrap();
    let frames = scenario_frames("stop-100-dry");
    let mut blf = blf_of(&frames);
    blf.truncate(blf.len() - 200);
    let log = dir.path().join("cut.blf");
    std::fs::write(&log, &blf).unwrap();
    let path = log.to_str().unwrap();
    // What the reader gives before its error: most of the file.
    let readable = autoplug_logs::open(&log)
        .unwrap()
        .take_while(Result::is_ok)
        .count();
    assert!(
        readable > frames.len() - 200 && readable < frames.len(),
        "{readable} of {}",
        frames.len()
    );

    for lenient in [false, true] {
        let mut args = vec!["diagnose", "--json", path];
        if lenient {
            args.insert(1, "--lenient");
        }
        let output = autoplug(&args);
        let err = String::from_utf8_lossy(&output.stderr);
        assert_eq!(output.status.code(), Some(4), "{args:?}: {err}");
        let json: serde_json::Value = serde_json::from_slice(&output.stdout).unwrap();
        assert_eq!(json["frames"], readable as u64, "{args:?}");
        let why = json["incomplete"].as_str().unwrap();
        assert!(
            why.contains("truncated file?") && why.contains("at byte"),
            "{why}"
        );
        assert!(err.contains("incomplete") && err.contains(why), "{err}");
        assert_eq!(
            json["ecus"].as_array().unwrap().len(),
            autoplug_can::Node::ECUS.len()
        );
    }

    let replay = autoplug(&["replay", path]);
    assert_eq!(replay.status.code(), Some(4), "{replay:?}");
    let text = String::from_utf8_lossy(&replay.stdout);
    assert!(text.contains(&format!("{readable} frames over")), "{text}");
    assert!(text.contains("Vehicle.Speed"), "{text}");

    let asc = dir.path().join("cut.asc");
    let export = autoplug(&["log", "export", path, "--out", asc.to_str().unwrap()]);
    assert_eq!(export.status.code(), Some(4), "{export:?}");
    let exported = autoplug_logs::open(&asc)
        .unwrap()
        .collect::<Result<Vec<_>, _>>()
        .unwrap();
    assert_eq!(exported.len(), readable);
    assert!(String::from_utf8_lossy(&export.stdout).contains(&format!("{readable} frames")));
}

/// candump's DROPCOUNT lines are frames the logger lost: counted and reported, never a
/// reason to stop.
#[test]
fn dropped_frames_the_logger_reported_are_counted() {
    let dir = tempfile::tempdir().unwrap();
    let log = bus_log(dir.path(), "stop-100-dry");
    let text = std::fs::read_to_string(&log).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    let half = lines.len() / 2;
    let with_drops = format!(
        "{}\nDROPCOUNT: dropped 5 CAN frames on 'can0' socket (total drops 5)\n{}\n",
        lines[..half].join("\n"),
        lines[half..].join("\n")
    );
    let log = dir.path().join("drops.log");
    std::fs::write(&log, with_drops).unwrap();
    let path = log.to_str().unwrap();
    let output = autoplug(&["diagnose", "--json", path]);
    assert_eq!(output.status.code(), Some(0), "{output:?}");
    let json: serde_json::Value = serde_json::from_slice(&output.stdout).unwrap();
    assert_eq!(json["frames"], lines.len() as u64);
    assert_eq!(json["frames_dropped_by_logger"], 5);
    assert_eq!(json["malformed_lines_skipped"], 0);
    let replay = autoplug(&["replay", path]);
    assert_eq!(replay.status.code(), Some(0), "{replay:?}");
    let text = String::from_utf8_lossy(&replay.stdout);
    assert!(text.contains("5 frame(s) dropped by the logger"), "{text}");
}

/// CAN FD frames in a log of the (classic) AutoPlug bus: counted and left aside by the
/// diagnostics, even on a catalogue identifier, and kept by every export.
#[test]
fn can_fd_frames_are_counted_apart_and_kept_by_exports() {
    let dir = tempfile::tempdir().unwrap();
    let log = bus_log(dir.path(), "stop-100-dry");
    let text = std::fs::read_to_string(&log).unwrap();
    let mut with_fd = String::new();
    let mut fd = 0;
    for (i, line) in text.lines().enumerate() {
        with_fd.push_str(line);
        with_fd.push('\n');
        if i % 500 == 0 {
            // The same time, VehicleSpeedMsg's identifier, 12 bytes with BRS.
            let stamp = line.split(' ').next().unwrap();
            with_fd.push_str(&format!("{stamp} can0 003##1{}\n", "A5".repeat(12)));
            fd += 1;
        }
    }
    let log = dir.path().join("fd.log");
    std::fs::write(&log, &with_fd).unwrap();
    let path = log.to_str().unwrap();
    let output = autoplug(&["diagnose", "--json", path]);
    assert_eq!(output.status.code(), Some(0), "{output:?}");
    let json: serde_json::Value = serde_json::from_slice(&output.stdout).unwrap();
    assert_eq!(json["can_fd_frames"], fd);
    assert_eq!(json["malformed_lines_skipped"], 0);
    let replay = autoplug(&["replay", path]);
    let summary = String::from_utf8_lossy(&replay.stdout);
    assert!(
        summary.contains(&format!("{fd} CAN FD (not for a classic bus)")),
        "{summary}"
    );
    for (format, extension) in [("blf", "blf"), ("asc", "asc"), ("candump", "log")] {
        let out = dir.path().join(format!("out.{extension}"));
        let export = autoplug(&[
            "log",
            "export",
            path,
            "--format",
            format,
            "--out",
            out.to_str().unwrap(),
        ]);
        assert_eq!(export.status.code(), Some(0), "{export:?}");
        let frames: Vec<_> = autoplug_logs::open(&out)
            .unwrap()
            .map(|f| f.unwrap())
            .filter(|f| f.is_fd())
            .collect();
        assert_eq!(frames.len(), fd, "{format}");
        assert!(frames
            .iter()
            .all(|f| f.id == 0x003 && f.data() == [0xA5; 12] && f.fd().unwrap().brs));
    }
}

/// Another vehicle's bus, which also uses identifier 0x00E (with values AutoPlug's ABS
/// never sends): 5 s of it in candump form.
fn someone_elses_car() -> String {
    let mut text = String::new();
    for tick in 0..500u64 {
        let t = tick * 10_000;
        let mut frame = |dt: u64, id: &str, data: &str| {
            text.push_str(&format!(
                "({}.{:06}) can0 {id}#{data}\n",
                (t + dt) / 1_000_000,
                (t + dt) % 1_000_000
            ));
        };
        frame(0, "00E", "C8C8C8C8C8C8C8C8");
        frame(150, "0B4", "000000000A1B2C3D");
        frame(300, "025", "0FFF000000000000");
        if tick % 2 == 0 {
            frame(450, "1C4", "1122334455667788");
            frame(600, "2C1", "0102030405FF");
        }
        if tick % 10 == 0 {
            frame(750, "3B7", "0000000000000000");
            frame(900, "610", "01020304");
            frame(1050, "00C", "0102030405060708");
        }
    }
    text
}

#[test]
fn diagnose_does_not_judge_someone_elses_car() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("other-car.log");
    std::fs::write(&log, someone_elses_car()).unwrap();
    let path = log.to_str().unwrap();

    let table = autoplug(&["diagnose", path]);
    let text = String::from_utf8_lossy(&table.stdout);
    assert_eq!(table.status.code(), Some(5), "{table:?}");
    assert!(text.contains("not an AutoPlug car"), "{text}");
    assert!(!text.lines().any(|l| l.starts_with("abs")), "{text}");
    assert!(String::from_utf8_lossy(&table.stderr).contains("--force"));

    let output = autoplug(&["diagnose", "--json", path]);
    assert_eq!(output.status.code(), Some(5), "{output:?}");
    let json: serde_json::Value = serde_json::from_slice(&output.stdout).unwrap();
    assert_eq!(json["vehicle"]["autoplug"], false, "{json}");
    assert_eq!(json["vehicle"]["messages_seen"], 1, "{json}");
    // Its 0x00E frames are the catalogue's AbsMsg, at its length; the rest is foreign.
    assert_eq!(json["vehicle"]["catalogue_frames"], 500, "{json}");
    assert_eq!(json["vehicle"]["foreign_frames"], 1650, "{json}");
    assert_eq!(json["judged"], false);
    assert!(json["ecus"].as_array().unwrap().is_empty());

    // Judged anyway on request: the ABS takes the blame for the other car's 0x00E.
    let forced = autoplug(&["diagnose", "--force", "--json", path]);
    assert_eq!(forced.status.code(), Some(3), "{forced:?}");
    let json: serde_json::Value = serde_json::from_slice(&forced.stdout).unwrap();
    assert_eq!(json["judged"], true);
    let abs = json["ecus"]
        .as_array()
        .unwrap()
        .iter()
        .find(|e| e["ecu"] == "abs")
        .unwrap();
    assert_eq!(abs["verdict"], "faulty");
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
