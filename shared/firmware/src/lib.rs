//! What the nine AutoPlug ECU firmwares share on the Nucleo-F446RE, so that each ECU's
//! binary is only its board (which pin is which sensor or actuator) and a call to
//! [`runtime::run`]:
//!
//! - [`clocks`]: 168 MHz from the ST-LINK's 8 MHz clock, APB1 at 42 MHz for CAN1;
//! - [`can_io`]: CAN1 at 500 kbit/s with acceptance filters from the catalogue, the RX and
//!   TX tasks, the error-counter monitor and bus-off recovery;
//! - [`runtime`]: the control loop (logic step on a ticker, frames in and out, outputs,
//!   watchdog, DTC log) generic over [`autoplug_ecu::EcuLogic`];
//! - [`io`]: analog inputs and PWM outputs with their scaling, for the board modules;
//! - `entropy`: the sources of the security seeds (the F446 has no RNG);
//! - `fault`: panics and HardFaults logged through defmt, then a reset;
//! - [`analog`] and [`reset`]: the pure parts (ADC and PWM scaling, the reset cause), which
//!   also build on the host, where their unit tests run.
//!
//! Everything else exists for `--target thumbv7em-none-eabihf` only.
#![no_std]
#![deny(missing_docs)]

pub mod analog;
pub mod reset;

#[cfg(target_os = "none")]
pub mod can_io;
#[cfg(target_os = "none")]
pub mod clocks;
#[cfg(target_os = "none")]
pub mod diag;
#[cfg(target_os = "none")]
pub mod entropy;
#[cfg(target_os = "none")]
mod fault;
#[cfg(target_os = "none")]
pub mod io;
#[cfg(target_os = "none")]
pub mod runtime;

/// The entry point of an ECU firmware binary: brings up the board (the binary's `board`
/// module: `init() -> (Platform, impl Io<E>)`) and runs the ECU built by `$new_ecu`
/// (`fn(Instant) -> E`) with [`runtime::run`]. On the host, where the firmware cannot
/// run, the binary only says what it is and how to build it: every firmware's `main.rs`
/// is then this one line and its `board` module.
///
/// ```ignore
/// #![cfg_attr(target_os = "none", no_std, no_main)]
/// #[cfg(target_os = "none")]
/// mod board;
/// autoplug_firmware::ecu_main!(ecu_pedals::PedalsEcu::new);
/// ```
#[cfg(target_os = "none")]
#[macro_export]
macro_rules! ecu_main {
    ($new_ecu:expr) => {
        #[embassy_executor::main]
        async fn main(spawner: embassy_executor::Spawner) {
            let (platform, board) = board::init();
            $crate::runtime::run(spawner, platform, board, $new_ecu).await
        }
    };
}

/// The bring-up every board shares, in its `init()`: the clocks (`$p` becomes the HAL's
/// peripherals, the rest of which are the board's own), and `$platform` the
/// [`runtime::Platform`]: CAN1 on the bench's CAN wiring (PB8 RX, PB9 TX to the
/// transceiver, on every board), the watchdog and the flash controller.
///
/// ```ignore
/// pub fn init() -> (Platform, Board) {
///     autoplug_firmware::board_init!(p, platform);
///     (platform, Board { pedal: p.PA0.degrade_adc(), /* ... */ })
/// }
/// ```
#[cfg(target_os = "none")]
#[macro_export]
macro_rules! board_init {
    ($p:ident, $platform:ident) => {
        let $p = $crate::clocks::init();
        let $platform = $crate::runtime::Platform {
            can: ::embassy_stm32::can::Can::new($p.CAN1, $p.PB8, $p.PB9, $crate::can_io::Irqs),
            watchdog: $p.IWDG,
            flash: $p.FLASH,
        };
    };
}

/// A timer's PWM channels as every board's actuator outputs use them: [`io::PWM_FREQUENCY_HZ`],
/// edge-aligned, push-pull on the pins given (a channel not named stays unused), split into
/// its four channels for [`io::PwmOutput`].
///
/// ```ignore
/// let pwm = autoplug_firmware::pwm_channels!(p.TIM3, ch1 = p.PB4, ch2 = p.PB5);
/// let accelerator = PwmOutput::new(pwm.ch1, COMMAND, 0.0);
/// ```
#[cfg(target_os = "none")]
#[macro_export]
macro_rules! pwm_channels {
    ($timer:expr $(, ch1 = $c1:expr)? $(, ch2 = $c2:expr)? $(, ch3 = $c3:expr)? $(, ch4 = $c4:expr)? $(,)?) => {
        ::embassy_stm32::timer::simple_pwm::SimplePwm::new(
            $timer,
            $crate::pwm_pin!($($c1)?),
            $crate::pwm_pin!($($c2)?),
            $crate::pwm_pin!($($c3)?),
            $crate::pwm_pin!($($c4)?),
            ::embassy_stm32::time::Hertz($crate::io::PWM_FREQUENCY_HZ),
            ::embassy_stm32::timer::low_level::CountingMode::EdgeAlignedUp,
        )
        .split()
    };
}

/// One channel's pin for [`pwm_channels!`]: push-pull, or none.
#[cfg(target_os = "none")]
#[doc(hidden)]
#[macro_export]
macro_rules! pwm_pin {
    () => {
        None
    };
    ($pin:expr) => {
        Some(::embassy_stm32::timer::simple_pwm::PwmPin::new(
            $pin,
            ::embassy_stm32::gpio::OutputType::PushPull,
        ))
    };
}

/// On the host: see the MCU's `ecu_main!` above.
#[cfg(not(target_os = "none"))]
#[macro_export]
macro_rules! ecu_main {
    ($new_ecu:expr) => {
        fn main() {
            println!(
                "{bin} is firmware for the Nucleo-F446RE ({what}): build it with \
                 `cargo build --profile firmware --target thumbv7em-none-eabihf --bin {bin}`, then run \
                 it on a board (the runner flashes it through probe-rs) or on the emulated one \
                 (autoplug-emu target/thumbv7em-none-eabihf/firmware/{bin})",
                bin = env!("CARGO_BIN_NAME"),
                what = env!("CARGO_PKG_DESCRIPTION"),
            );
        }
    };
}

// The defmt transport: RTT, read by probe-rs.
#[cfg(target_os = "none")]
use defmt_rtt as _;
