//! `virtual-car` against hostile command lines and files: errors stay short whatever the
//! input, name the argument that is wrong, and no numeric argument panics.

use std::process::{Command, Output, Stdio};

fn virtual_car(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_virtual-car"))
        .args(args)
        .current_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."))
        .output()
        .expect("the virtual-car binary runs")
}

fn stderr(output: &Output) -> String {
    String::from_utf8_lossy(&output.stderr).into_owned()
}

#[test]
fn errors_on_huge_or_hostile_scenario_files_stay_short() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let cases = [
        // One long line under the size limit: the parser's own excerpt would echo it.
        ("long-line.toml", format!("name = \"{}\n", "x".repeat(900_000))),
        // Deep nesting: the parser's recursion limit, with its excerpt.
        ("nested.toml", format!("a = {}\n", "[".repeat(100_000))),
        // A value the checks quote back.
        (
            "node.toml",
            format!(
                "name = \"n\"\nduration_s = 1.0\n[[at]]\nt_s = 0.5\nfault = {{ silence = \"{}\" }}\n",
                "Q".repeat(100_000)
            ),
        ),
        // Over the size limit: refused before it is read.
        ("huge.toml", "#".repeat(2 << 20)),
    ];
    for (name, text) in cases {
        let path = dir.path().join(name);
        std::fs::write(&path, text).unwrap();
        let output = virtual_car(&[
            "run",
            path.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ]);
        assert_eq!(output.status.code(), Some(1), "{name}: {output:?}");
        let text = stderr(&output);
        assert!(text.len() < 600, "{name}: {} bytes of error", text.len());
        assert!(text.contains(name), "{name}: {text}");
    }
    let text = stderr(&virtual_car(&[
        "run",
        dir.path().join("long-line.toml").to_str().unwrap(),
    ]));
    assert!(text.contains("line 1, column"), "{text}");
}

/// A device with no end and no size (`/dev/zero`) is read only as far as the limit.
#[cfg(unix)]
#[test]
fn an_endless_scenario_file_is_refused_at_the_size_limit() {
    let output = virtual_car(&["run", "/dev/zero"]);
    assert_eq!(output.status.code(), Some(1), "{output:?}");
    let text = stderr(&output);
    assert!(
        text.contains("/dev/zero") && text.contains("at most"),
        "{text}"
    );
}

#[test]
fn a_wrong_output_folder_is_named_as_such() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("a-file");
    std::fs::write(&file, "").unwrap();
    let output = virtual_car(&[
        "run",
        "scenarios/stop-100-dry.toml",
        "--out",
        file.to_str().unwrap(),
    ]);
    assert_eq!(output.status.code(), Some(2), "{output:?}");
    let text = stderr(&output);
    assert!(text.contains("--out") && text.contains("a-file"), "{text}");
    assert!(
        !text.contains("stop-100-dry"),
        "not the scenario's fault: {text}"
    );
}

#[test]
fn numeric_arguments_are_checked_never_a_panic() {
    for value in ["1e20", "inf", "-inf", "nan", "-1", "x", ""] {
        let arg = format!("--wait-for-client={value}");
        let output = virtual_car(&[
            "run",
            "scenarios/stop-100-dry.toml",
            "--socketcand",
            "127.0.0.1:0",
            &arg,
        ]);
        assert_eq!(output.status.code(), Some(2), "{value}: {output:?}");
        let text = stderr(&output);
        assert!(text.contains("--wait-for-client"), "{value}: {text}");
        assert!(!text.contains("panicked"), "{value}: {text}");
    }
}

/// `virtual-car run a.toml b.toml | head`: the reader goes away before anything is
/// written; the program does not panic and still runs every scenario and writes its files.
#[test]
fn a_reader_gone_away_costs_no_output_file() {
    let dir = tempfile::tempdir().unwrap();
    let mut child = Command::new(env!("CARGO_BIN_EXE_virtual-car"))
        .args(["run", "--out"])
        .arg(dir.path())
        .args(["scenarios/stop-100-dry.toml", "scenarios/stop-100-wet.toml"])
        .current_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the virtual-car binary runs");
    drop(child.stdout.take());
    let output = child.wait_with_output().expect("it ends");
    let err = stderr(&output);
    assert!(output.status.success(), "{:?}: {err}", output.status);
    assert!(!err.contains("panicked"), "{err}");
    for scenario in ["stop-100-dry", "stop-100-wet"] {
        let summary = dir.path().join(scenario).join("summary.json");
        assert!(summary.exists(), "{} missing", summary.display());
    }
}
