//! Generates the codec from `autoplug.dbc`, the single source of the CAN catalogue. A DBC
//! that does not parse, contradicts itself or uses what the generator cannot express stops
//! the build with the DBC line at fault.

use std::{env, fs, path::PathBuf, process};

fn main() {
    let dbc_path = PathBuf::from(env::var("CARGO_MANIFEST_DIR").unwrap()).join("autoplug.dbc");
    println!("cargo:rerun-if-changed={}", dbc_path.display());
    let text = match fs::read_to_string(&dbc_path) {
        Ok(text) => text,
        Err(e) => fail(&format!("cannot read {}: {e}", dbc_path.display())),
    };
    let code = match autoplug_dbc::compile(&text) {
        Ok(code) => code,
        Err(e) => fail(&format!("{}: {e}", dbc_path.display())),
    };
    let out = PathBuf::from(env::var("OUT_DIR").unwrap()).join("catalogue.rs");
    if let Err(e) = fs::write(&out, code) {
        fail(&format!("cannot write {}: {e}", out.display()));
    }
}

fn fail(message: &str) -> ! {
    for line in message.lines() {
        println!("cargo:warning={line}");
    }
    eprintln!("{message}");
    process::exit(1);
}
