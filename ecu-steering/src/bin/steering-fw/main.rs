//! Firmware of the steering ECU for a Nucleo-F446RE: wires [`ecu_steering::SteeringEcu`] to
//! CAN1, the steering-wheel potentiometer, the paddle and cruise buttons and the steering
//! command PWM output, and nothing else: every decision is the logic crate's, and the
//! control loop, CAN and the watchdog are `autoplug-firmware`'s. Build and flash: `cargo
//! fw-steering`; pin map: `board.rs`.
//!
//! On the host this is an empty program: the firmware only builds for
//! `--target thumbv7em-none-eabihf`.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(not(target_os = "none"))]
fn main() {
    println!(
        "steering-fw is the steering ECU's firmware for the Nucleo-F446RE: \
         build it with `cargo fw-steering` (--target thumbv7em-none-eabihf)"
    );
}

#[cfg(target_os = "none")]
mod board;

#[cfg(target_os = "none")]
autoplug_firmware::ecu_main!(ecu_steering::SteeringEcu::new);
