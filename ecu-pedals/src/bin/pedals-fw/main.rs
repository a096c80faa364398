//! Firmware of the pedals ECU (node 0x04) for a Nucleo-F446RE: wires [`ecu_pedals::PedalsEcu`]
//! to CAN1, the pedal ADC inputs and the command PWM outputs, and nothing else (every
//! decision is the logic crate's). Build and flash: `cargo fw-pedals` (see
//! `.cargo/config.toml`); pin map: `board.rs`.
//!
//! Tasks (one thread-mode executor):
//! - the control loop (in `main`, after start-up): owns the logic. Runs `step` on a ticker
//!   every `STEP_PERIOD_US` (reading the pedals, driving the outputs, feeding the watchdog)
//!   and `on_frame` as soon as a frame arrives; after either, queues every frame
//!   `poll_transmit` hands out.
//! - `can_rx`: CAN1 → RX queue; `can_tx`: TX queue → CAN1 mailboxes.
//! - `can_monitor`: logs CAN error counters and bus-off once a second when they change.
//!
//! On the host this is an empty program: the firmware only builds for
//! `--target thumbv7em-none-eabihf`.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(not(target_os = "none"))]
fn main() {
    println!(
        "pedals-fw is the pedals ECU's firmware for the Nucleo-F446RE: \
         build it with `cargo fw-pedals` (--target thumbv7em-none-eabihf)"
    );
}

#[cfg(target_os = "none")]
mod board;
#[cfg(target_os = "none")]
mod can_io;
#[cfg(target_os = "none")]
mod fault;
#[cfg(target_os = "none")]
mod firmware;

/// Independent watchdog timeout: ten control periods. Fed by the control loop only.
#[cfg(target_os = "none")]
const WATCHDOG_TIMEOUT_US: u32 = 10 * ecu_pedals::STEP_PERIOD_US as u32;
