//! `autoplug`: keys, signed images, ECU identification and flashing over CAN.
//!
//!     autoplug keygen --out keys/dev
//!     autoplug image build --ecu cruise --version 1.3.0 --payload app.elf --key keys/dev.key --out cruise.img
//!     autoplug image inspect cruise.img --key keys/dev.pub
//!     autoplug ids --via socketcand://127.0.0.1:29536/can0
//!     autoplug flash --via socketcand://127.0.0.1:29536/can0 --ecu cruise --image cruise.img

use std::process::ExitCode;

fn main() -> ExitCode {
    // The usual soft limit of 1024 descriptors is low for a server (the dashboard's
    // connections, the fleet's cars): take what the hard limit allows. Where it cannot be
    // raised the servers size their limits to what there is.
    #[cfg(unix)]
    let _ = rlimit::increase_nofile_limit(u64::MAX);
    autoplug_cli::cli::main()
}
