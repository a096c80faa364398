//! The `autoplug` command: argument errors, keys, images, and `ids` / `flash` over
//! socketcand against ECUs served in real time.

use std::fs;
use std::path::Path;
use std::process::{Command, Output};

use autoplug_can::Node;
use autoplug_image::{ImageSlot, SigningKey};

const F446RE_LOAD_ADDRESS: u32 = ImageSlot::A.vector_table();
use autoplug_cli::cli::{run, Cli};
use autoplug_tester::names::ECUS;
use autoplug_tester::testing::{image_for, EcuServer, SIGNING_SEED};
use clap::Parser;

fn autoplug(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_autoplug"))
        .args(args)
        .output()
        .expect("the autoplug binary runs")
}

fn stderr(output: &Output) -> String {
    String::from_utf8_lossy(&output.stderr).into_owned()
}

fn stdout(output: &Output) -> String {
    String::from_utf8_lossy(&output.stdout).into_owned()
}

/// Runs a command line in-process; its output, or the error's message.
fn run_args(args: &[&str]) -> Result<String, String> {
    let cli = Cli::try_parse_from(std::iter::once("autoplug").chain(args.iter().copied()))
        .map_err(|e| e.to_string())?;
    let mut out = Vec::new();
    let result = run(cli, &mut out);
    let text = String::from_utf8(out).unwrap();
    result
        .map(|()| text.clone())
        .map_err(|e| format!("{text}{e}"))
}

fn path(dir: &Path, name: &str) -> String {
    dir.join(name).to_str().unwrap().to_string()
}

#[test]
fn help_lists_the_commands() {
    let output = autoplug(&["--help"]);
    assert!(output.status.success());
    let text = stdout(&output);
    for command in [
        "keygen",
        "image",
        "ids",
        "flash",
        "socketcand://HOST:PORT/BUS",
    ] {
        assert!(text.contains(command), "{text}");
    }
}

#[test]
fn argument_errors_are_clear() {
    let output = autoplug(&[
        "ids",
        "--via",
        "socketcand://127.0.0.1:29536/can0",
        "--ecu",
        "brakes",
    ]);
    assert_eq!(output.status.code(), Some(2));
    let text = stderr(&output);
    assert!(text.contains("unknown ECU 'brakes'"), "{text}");
    assert!(text.contains("transmission, cabin"), "{text}");

    let output = autoplug(&["ids", "--via", "tcp://127.0.0.1:29536"]);
    assert_eq!(output.status.code(), Some(2));
    let text = stderr(&output);
    assert!(
        text.contains("invalid transport URL 'tcp://127.0.0.1:29536'"),
        "{text}"
    );
    assert!(text.contains("unknown transport 'tcp'"), "{text}");

    let error = run_args(&[
        "image",
        "build",
        "--ecu",
        "cruise",
        "--version",
        "1.3",
        "--payload",
        "x",
        "--key",
        "k",
        "--out",
        "o",
    ])
    .unwrap_err();
    assert!(error.contains("version '1.3'"), "{error}");

    let error = run_args(&[
        "image",
        "build",
        "--ecu",
        "cruise",
        "--version",
        "1.3.0",
        "--build-id",
        "abc",
        "--payload",
        "x",
        "--key",
        "k",
        "--out",
        "o",
    ])
    .unwrap_err();
    assert!(
        error.contains("build id 'abc' has 3 hex digits, expected 32"),
        "{error}"
    );

    let error = run_args(&[
        "image",
        "build",
        "--ecu",
        "cruise",
        "--version",
        "1.3.0",
        "--variant",
        "broken",
        "--payload",
        "x",
        "--key",
        "k",
        "--out",
        "o",
    ])
    .unwrap_err();
    assert!(
        error.contains("'broken'") && error.contains("standard"),
        "{error}"
    );

    let error = run_args(&["flash", "--via", "socketcan://can0", "--ecu", "diff"]).unwrap_err();
    assert!(error.contains("--image"), "{error}");
    let error = run_args(&["keygen"]).unwrap_err();
    assert!(error.contains("--out"), "{error}");
}

#[test]
fn keygen_writes_a_key_pair_and_refuses_to_overwrite() {
    let dir = tempfile::tempdir().unwrap();
    let out = path(dir.path(), "keys/dev");
    let output = autoplug(&["keygen", "--out", &out]);
    assert!(output.status.success(), "{}", stderr(&output));
    let secret = fs::read_to_string(dir.path().join("keys/dev.key")).unwrap();
    let public = fs::read_to_string(dir.path().join("keys/dev.pub")).unwrap();
    let key = SigningKey::parse(&secret).unwrap();
    assert_eq!(public, key.public_key_file_string());
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let mode = fs::metadata(dir.path().join("keys/dev.key"))
            .unwrap()
            .permissions()
            .mode();
        assert_eq!(mode & 0o777, 0o600);
    }
    // A second run refuses, and leaves the keys as they were.
    let output = autoplug(&["keygen", "--out", &out]);
    assert_eq!(output.status.code(), Some(1));
    let text = stderr(&output);
    assert!(text.contains("refusing to overwrite"), "{text}");
    assert!(text.contains("dev.key"), "{text}");
    assert_eq!(
        fs::read_to_string(dir.path().join("keys/dev.key")).unwrap(),
        secret
    );
    // Even when only the public half is there.
    fs::remove_file(dir.path().join("keys/dev.key")).unwrap();
    let error = run_args(&["keygen", "--out", &out]).unwrap_err();
    assert!(
        error.contains("refusing to overwrite") && error.contains("dev.pub"),
        "{error}"
    );
    assert!(!dir.path().join("keys/dev.key").exists());
}

/// Writes the ECUs' trusted key pair as keys/test.key and keys/test.pub.
fn test_keys(dir: &Path) -> (String, String) {
    let key = SigningKey::from_seed(SIGNING_SEED);
    autoplug_image_tool::write_key_pair(&dir.join("keys/test"), &key).unwrap();
    (path(dir, "keys/test.key"), path(dir, "keys/test.pub"))
}

#[test]
fn image_build_and_inspect_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let (secret, public) = test_keys(dir.path());
    let payload = path(dir.path(), "app.bin");
    fs::write(
        &payload,
        (0..10_000u32).map(|i| i as u8).collect::<Vec<u8>>(),
    )
    .unwrap();
    let image = path(dir.path(), "cruise.img");
    let output = autoplug(&[
        "image",
        "build",
        "--ecu",
        "cruise",
        "--version",
        "1.3.0",
        "--variant",
        "faulty",
        "--part-number",
        "AP-CRUISE-0001",
        "--payload",
        &payload,
        "--key",
        &secret,
        "--out",
        &image,
    ]);
    assert!(output.status.success(), "{}", stderr(&output));
    assert!(
        stdout(&output).contains("10576 bytes"),
        "{}",
        stdout(&output)
    );
    assert_eq!(fs::metadata(&image).unwrap().len(), 10_576);

    let output = autoplug(&["image", "inspect", &image, "--key", &public]);
    assert!(output.status.success(), "{}", stderr(&output));
    let text = stdout(&output);
    for expected in [
        "ECU node:       0x0D (Cruise)",
        "Variant:        faulty (demonstration)",
        "Version:        1.3.0",
        "Payload length: 10000 bytes",
        "Load address:   0x08020200",
        "Part number:    AP-CRUISE-0001",
        "header 512 + payload 10000 + signature 64 = 10576 bytes; 10576 bytes in the file (matches)",
        "linked for slot A; fits an F446RE slot",
        "Signature:      valid",
    ] {
        assert!(text.contains(expected), "{expected:?} in\n{text}");
    }
    // The default build id is the payload's SHA-256, cut to 16 bytes.
    let id = autoplug_image_tool::default_build_id(&fs::read(&payload).unwrap());
    let hex: String = id.iter().map(|b| format!("{b:02x}")).collect();
    assert!(text.contains(&format!("Build id:       {hex}")), "{text}");

    // Without a key: the header, and a note that the signature was not checked.
    let text = run_args(&["image", "inspect", &image]).unwrap();
    assert!(text.contains("Signature:      not checked"), "{text}");
    // A secret key file works as well as the public one.
    let text = run_args(&["image", "inspect", &image, "--key", &secret]).unwrap();
    assert!(text.contains("Signature:      valid"), "{text}");
}

#[test]
fn inspect_says_when_an_image_is_corrupted() {
    let dir = tempfile::tempdir().unwrap();
    let (secret, public) = test_keys(dir.path());
    let payload = path(dir.path(), "app.bin");
    fs::write(&payload, vec![0x5A; 3000]).unwrap();
    let image = path(dir.path(), "abs.img");
    run_args(&[
        "image",
        "build",
        "--ecu",
        "abs",
        "--version",
        "2.0.1",
        "--build-id",
        "00112233445566778899aabbccddeeff",
        "--payload",
        &payload,
        "--key",
        &secret,
        "--out",
        &image,
    ])
    .unwrap();
    let good = fs::read(&image).unwrap();

    // A flipped payload byte: the header reads, the signature does not verify.
    let mut bad = good.clone();
    bad[600] ^= 0x01;
    let flipped = path(dir.path(), "flipped.img");
    fs::write(&flipped, &bad).unwrap();
    let output = autoplug(&["image", "inspect", &flipped, "--key", &public]);
    assert_eq!(output.status.code(), Some(1));
    assert!(
        stdout(&output).contains("Signature:      INVALID"),
        "{}",
        stdout(&output)
    );
    let text = stderr(&output);
    assert!(text.contains("is corrupted"), "{text}");
    assert!(text.contains("signature does not match"), "{text}");

    // Cut short.
    let truncated = path(dir.path(), "truncated.img");
    fs::write(&truncated, &good[..good.len() - 10]).unwrap();
    let error = run_args(&["image", "inspect", &truncated]).unwrap_err();
    assert!(error.contains("(MISMATCH)"), "{error}");
    assert!(
        error.contains("is corrupted: truncated: 3566 bytes, the header gives 3576"),
        "{error}"
    );

    // Not an image at all.
    let error = run_args(&["image", "inspect", &payload]).unwrap_err();
    assert!(
        error.contains("is not a valid AutoPlug image: not an AutoPlug image"),
        "{error}"
    );

    // Signed with another key.
    let other = SigningKey::from_seed([1; 32]);
    autoplug_image_tool::write_key_pair(&dir.path().join("other"), &other).unwrap();
    let error = run_args(&[
        "image",
        "inspect",
        &image,
        "--key",
        &path(dir.path(), "other.pub"),
    ])
    .unwrap_err();
    assert!(error.contains("signature does not match"), "{error}");
}

#[test]
fn image_build_errors_name_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let (secret, public) = test_keys(dir.path());
    let payload = path(dir.path(), "app.bin");
    fs::write(&payload, [1, 2, 3]).unwrap();
    let out = path(dir.path(), "x.img");
    let build = |payload: &str, key: &str| {
        run_args(&[
            "image",
            "build",
            "--ecu",
            "engine",
            "--version",
            "1.0.0",
            "--payload",
            payload,
            "--key",
            key,
            "--out",
            &out,
        ])
    };
    let error = build(&payload, &public).unwrap_err();
    assert!(error.contains("bad key file"), "{error}");
    assert!(error.contains("this is a public key file"), "{error}");
    let error = build(&path(dir.path(), "missing.bin"), &secret).unwrap_err();
    assert!(error.contains("cannot read the payload"), "{error}");
    assert!(error.contains("missing.bin"), "{error}");
    let large = path(dir.path(), "large.bin");
    fs::write(&large, vec![0; 200_000]).unwrap();
    let error = build(&large, &secret).unwrap_err();
    assert!(
        error.contains("large.bin") && error.contains("do not fit the slot"),
        "{error}"
    );
    let error = run_args(&[
        "image",
        "build",
        "--ecu",
        "engine",
        "--version",
        "1.0.0",
        "--part-number",
        "AP-ENGINE-0001-TOO-LONG",
        "--payload",
        &payload,
        "--key",
        &secret,
        "--out",
        &out,
    ])
    .unwrap_err();
    assert!(error.contains("part number is 23 bytes long"), "{error}");
}

/// A little-endian ELF32 for Arm whose loadable segments are `segments`.
fn elf(segments: &[(u32, &[u8])]) -> Vec<u8> {
    let phoff = 52u32;
    let mut offset = phoff + 32 * segments.len() as u32;
    let mut out = vec![0x7F, b'E', b'L', b'F', 1, 1, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0];
    for half in [2u16, 40] {
        out.extend_from_slice(&half.to_le_bytes()); // ET_EXEC, EM_ARM
    }
    for word in [1u32, F446RE_LOAD_ADDRESS + 1, phoff, 0, 0x0500_0200] {
        out.extend_from_slice(&word.to_le_bytes());
    }
    for half in [52u16, 32, segments.len() as u16, 40, 0, 0] {
        out.extend_from_slice(&half.to_le_bytes());
    }
    for (address, data) in segments {
        for word in [
            1,
            offset,
            *address,
            *address,
            data.len() as u32,
            data.len() as u32,
            5,
            4,
        ] {
            out.extend_from_slice(&u32::to_le_bytes(word));
        }
        offset += data.len() as u32;
    }
    for (_, data) in segments {
        out.extend_from_slice(data);
    }
    out
}

#[test]
fn image_build_takes_an_elf_file() {
    let dir = tempfile::tempdir().unwrap();
    let (secret, public) = test_keys(dir.path());
    let firmware = path(dir.path(), "cruise.elf");
    fs::write(
        &firmware,
        elf(&[
            (F446RE_LOAD_ADDRESS, &[0xAA; 16]),
            (F446RE_LOAD_ADDRESS + 32, &[0xBB; 8]),
        ]),
    )
    .unwrap();
    let image = path(dir.path(), "cruise.img");
    let text = run_args(&[
        "image",
        "build",
        "--ecu",
        "cruise",
        "--version",
        "1.4.0",
        "--payload",
        &firmware,
        "--key",
        &secret,
        "--out",
        &image,
    ])
    .unwrap();
    assert!(text.contains("ELF, 2 loadable segment(s)"), "{text}");
    let bytes = fs::read(&image).unwrap();
    let payload = &bytes[512..512 + 40];
    assert_eq!(&payload[..16], &[0xAA; 16]);
    assert_eq!(&payload[16..32], &[0xFF; 16], "the gap is erased flash");
    assert_eq!(&payload[32..], &[0xBB; 8]);
    run_args(&["image", "inspect", &image, "--key", &public]).unwrap();

    // A segment in the bootloader's flash is refused.
    fs::write(&firmware, elf(&[(0x0800_0000, &[0xAA; 16])])).unwrap();
    let error = run_args(&[
        "image",
        "build",
        "--ecu",
        "cruise",
        "--version",
        "1.4.0",
        "--payload",
        &firmware,
        "--key",
        &secret,
        "--out",
        &image,
    ])
    .unwrap_err();
    assert!(error.contains("cruise.elf"), "{error}");
    assert!(error.contains("not for slot A"), "{error}");

    // A release for both slots: the slot-A and slot-B builds, one file.
    let slot_b = path(dir.path(), "cruise-b.elf");
    let b = ImageSlot::B.vector_table();
    fs::write(&firmware, elf(&[(F446RE_LOAD_ADDRESS, &[0xAA; 16])])).unwrap();
    fs::write(&slot_b, elf(&[(b, &[0xBB; 16])])).unwrap();
    let release = path(dir.path(), "cruise-release.img");
    let build = |payloads: &[&str], out: &str| {
        let mut args = vec!["image", "build", "--ecu", "cruise", "--version", "1.5.0"];
        for payload in payloads {
            args.extend(["--payload", payload]);
        }
        args.extend(["--key", &secret, "--out", out]);
        run_args(&args)
    };
    let text = build(&[&slot_b, &firmware], &release).unwrap();
    assert!(text.contains("2 image(s)"), "{text}");
    assert!(text.contains("slot B: payload 16 bytes"), "{text}");
    assert!(text.contains("slot A: payload 16 bytes"), "{text}");
    let text = run_args(&["image", "inspect", &release, "--key", &public]).unwrap();
    assert!(text.contains("--- image 1 of 2"), "{text}");
    assert!(text.contains("Load address:   0x08040200"), "{text}");
    assert!(text.contains("Load address:   0x08020200"), "{text}");
    assert_eq!(text.matches("Signature:      valid").count(), 2, "{text}");
    // Two builds for one slot make no release.
    let error = build(&[&firmware, &firmware], &release).unwrap_err();
    assert!(
        error.contains("both payloads are linked for slot A"),
        "{error}"
    );
}

#[test]
fn flash_checks_the_image_before_connecting() {
    let dir = tempfile::tempdir().unwrap();
    let image = path(dir.path(), "engine.img");
    fs::write(&image, image_for(Node::Engine, 1000, SIGNING_SEED)).unwrap();
    // No server at this address: the image is refused before any connection is tried.
    let via = "socketcand://127.0.0.1:9/can0";
    let error =
        run_args(&["flash", "--via", via, "--ecu", "cruise", "--image", &image]).unwrap_err();
    assert!(
        error.contains("is an image for engine (0x03), not for cruise (0x0D)"),
        "{error}"
    );
    // A right image, but nobody there.
    let error =
        run_args(&["flash", "--via", via, "--ecu", "engine", "--image", &image]).unwrap_err();
    assert!(
        error.contains("cannot connect to the socketcand server at 127.0.0.1:9"),
        "{error}"
    );
    // An empty secret file.
    let secret = path(dir.path(), "secret");
    fs::write(&secret, "\n").unwrap();
    let error = run_args(&[
        "flash",
        "--via",
        via,
        "--ecu",
        "engine",
        "--image",
        &image,
        "--secret-file",
        &secret,
    ])
    .unwrap_err();
    assert!(
        error.contains("security secret file") && error.contains("empty"),
        "{error}"
    );
}

#[test]
fn ids_and_flash_over_socketcand() {
    let ecus = EcuServer::start(&ECUS);
    let url = ecus.url();
    // Generous P2: on a loaded machine the scheduler, not the ECUs, sets the latency.
    let timing = ["--p2-ms", "300"];

    let mut args = vec!["ids", "--via", &url];
    args.extend(timing);
    let output = autoplug(&args);
    assert!(output.status.success(), "{}", stderr(&output));
    let table = stdout(&output);
    // A header, every ECU and the vehicle they all name.
    assert_eq!(
        table.lines().count(),
        autoplug_can::Node::ECUS.len() + 2,
        "{table}"
    );
    assert!(
        table
            .lines()
            .last()
            .unwrap()
            .contains("vehicle: VIN JA3AP47H0YF000042"),
        "{table}"
    );
    assert!(table.contains("AP-CRUISE-0001"), "{table}");
    assert!(table.contains("NUCLEO-F446RE"), "{table}");

    let dir = tempfile::tempdir().unwrap();
    let image = path(dir.path(), "cruise.img");
    let bytes = image_for(Node::Cruise, 9_000, SIGNING_SEED);
    fs::write(&image, &bytes).unwrap();
    let (_, public) = test_keys(dir.path());
    let mut args = vec![
        "flash", "--via", &url, "--ecu", "cruise", "--image", &image, "--key", &public,
    ];
    args.extend(timing);
    let text = run_args(&args).unwrap();
    println!("{text}");
    assert!(text.contains("flashing cruise (0x0D)"), "{text}");
    for phase in [
        "session setup",
        "security",
        "erase",
        "transfer",
        "check",
        "reset and wait",
        "restore",
    ] {
        assert!(text.contains(phase), "{phase} in\n{text}");
    }
    assert!(text.contains("bytes/s"), "{text}");
    assert!(
        text.contains("done: cruise (0x0D) runs the new image"),
        "{text}"
    );

    // A wrong secret: the ECU's refusal, named.
    let secret = path(dir.path(), "secret");
    fs::write(&secret, "not the secret\n").unwrap();
    let mut args = vec![
        "flash",
        "--via",
        &url,
        "--ecu",
        "cruise",
        "--image",
        &image,
        "--secret-file",
        &secret,
    ];
    args.extend(timing);
    let error = run_args(&args).unwrap_err();
    assert!(error.contains("NRC 0x35 invalidKey"), "{error}");
    assert!(error.contains("phase 'security'"), "{error}");

    let backends = ecus.stop();
    let cruise = backends.iter().find(|b| b.node == Node::Cruise).unwrap();
    assert_eq!(&cruise.dfu[..bytes.len()], &bytes[..]);
    assert!(cruise.marked);
}

#[test]
fn a_demonstration_on_firmware_checks_its_releases_before_it_starts() {
    use autoplug_image::{SoftwareVariant, Version};
    use autoplug_virtual_car::diag::build_image;
    let dir = tempfile::tempdir().unwrap();
    let images = dir.path().to_str().unwrap();
    let without = run_args(&["demo", "cruise", "--firmware", "cruise"]).unwrap_err();
    assert!(
        without.contains("--firmware needs --images DIR"),
        "{without}"
    );
    let no_firmware = run_args(&["demo", "cruise", "--images", images]).unwrap_err();
    assert!(no_firmware.contains("--firmware"), "{no_firmware}");
    let missing =
        run_args(&["demo", "cruise", "--firmware", "cruise", "--images", images]).unwrap_err();
    assert!(
        missing.contains("cannot read the release") && missing.contains("cruise-1.1.0-faulty.img"),
        "{missing}"
    );

    let dev = SigningKey::from_seed(autoplug_image::dev::SIGNING_SEED);
    let write = |name: &str, variant, version, key: &SigningKey| {
        let image = build_image(Node::Cruise, version, variant, 1024, key);
        fs::write(dir.path().join(name), image).unwrap();
    };
    let (faulty, fixed) = (Version::new(1, 1, 0), Version::new(1, 2, 0));
    // The correct software under the faulty one's name.
    write(
        "cruise-1.1.0-faulty.img",
        SoftwareVariant::Standard,
        faulty,
        &dev,
    );
    write("cruise-1.2.0.img", SoftwareVariant::Standard, fixed, &dev);
    let swapped =
        run_args(&["demo", "cruise", "--firmware", "cruise", "--images", images]).unwrap_err();
    assert!(
        swapped.contains("cruise-1.1.0-faulty.img' is standard software 1.1.0")
            && swapped.contains("flashes the Cruise ECU's faulty"),
        "{swapped}"
    );
    // Signed with a key the bootloader does not trust.
    write(
        "cruise-1.1.0-faulty.img",
        SoftwareVariant::Faulty,
        faulty,
        &dev,
    );
    let other = SigningKey::from_seed(SIGNING_SEED);
    write("cruise-1.2.0.img", SoftwareVariant::Standard, fixed, &other);
    let unsigned =
        run_args(&["demo", "cruise", "--firmware", "cruise", "--images", images]).unwrap_err();
    assert!(
        unsigned.contains("cruise-1.2.0.img'") && unsigned.contains("development key"),
        "{unsigned}"
    );
    // The flashed ECU must be one that runs its firmware.
    let elsewhere =
        run_args(&["demo", "cruise", "--firmware", "abs", "--images", images]).unwrap_err();
    assert!(
        elsewhere.contains("the Cruise ECU: it must run as its firmware (--firmware cruise)"),
        "{elsewhere}"
    );
}
