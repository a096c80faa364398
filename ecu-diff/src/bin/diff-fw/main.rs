//! Firmware of the differential ECU for a Nucleo-F446RE: wires [`ecu_diff::DiffEcu`] to
//! CAN1, the yaw-rate error ADC input and the torque-split PWM output, and nothing else:
//! every decision is the logic crate's, and the control loop, CAN and the watchdog are
//! `autoplug-firmware`'s. Build and flash: `cargo fw -p ecu-diff`; pin map: `board.rs`.
//!
//! On the host it only says what it is and how to build it for
//! `--target thumbv7em-none-eabihf`.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
mod board;

autoplug_firmware::ecu_main!(ecu_diff::DiffEcu::new);
