//! Firmware of the transmission ECU for a Nucleo-F446RE: wires [`ecu_trans::TransEcu`] to
//! CAN1, the gear lines from the gearbox and the gear command lines, and nothing else:
//! every decision is the logic crate's, and the control loop, CAN and the watchdog are
//! `autoplug-firmware`'s. Build and flash: `cargo fw -p ecu-trans`; pin map: `board.rs`.
//!
//! On the host it only says what it is and how to build it for
//! `--target thumbv7em-none-eabihf`.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
mod board;

autoplug_firmware::ecu_main!(ecu_trans::TransEcu::new);
