//! Firmware of the ABS ECU for a Nucleo-F446RE: wires [`ecu_abs::AbsEcu`] to CAN1, the four
//! wheel-speed ADC inputs and the four brake PWM outputs (the `faulty` feature builds the
//! report's faulty software), and nothing else: every decision is the logic crate's, and
//! the control loop, CAN and the watchdog are `autoplug-firmware`'s. Build and flash:
//! `cargo fw-abs`; pin map: `board.rs`.
//!
//! On the host this is an empty program: the firmware only builds for
//! `--target thumbv7em-none-eabihf`.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(not(target_os = "none"))]
fn main() {
    println!(
        "abs-fw is the ABS ECU's firmware for the Nucleo-F446RE: \
         build it with `cargo fw-abs` (--target thumbv7em-none-eabihf)"
    );
}

#[cfg(target_os = "none")]
mod board;

#[cfg(target_os = "none")]
autoplug_firmware::ecu_main!(|now| ecu_abs::AbsEcu::new(ecu_abs::BUILD_VARIANT, now));
