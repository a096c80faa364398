//! Firmware of the cruise control ECU for a Nucleo-F446RE: wires [`ecu_cruise::CruiseEcu`]
//! to CAN1, the vehicle-speed ADC input and the cruise lamp (the `faulty` feature builds
//! the report's faulty software), and nothing else: every decision is the logic crate's,
//! and the control loop, CAN and the watchdog are `autoplug-firmware`'s. Build and flash:
//! `cargo fw -p ecu-cruise`; pin map: `board.rs`.
//!
//! On the host it only says what it is and how to build it for
//! `--target thumbv7em-none-eabihf`.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
mod board;

autoplug_firmware::ecu_main!(|now| ecu_cruise::CruiseEcu::new(ecu_cruise::BUILD_VARIANT, now));
