//! What happens when the firmware cannot go on: a panic or a HardFault is logged through
//! defmt, then the MCU resets (the ECU restarts from its power-up state, which is what the
//! watchdog would do a little later anyway). panic-probe is not used: it ends in a HardFault
//! loop, which suits a test under a debugger but not an ECU.

use core::panic::PanicInfo;

use cortex_m::peripheral::SCB;
use cortex_m_rt::{exception, ExceptionFrame};

/// Time for an attached probe to read the last RTT log lines before the reset, in CPU
/// cycles (about 20 ms at 168 MHz).
const FLUSH_CYCLES: u32 = 3_360_000;

fn reset() -> ! {
    cortex_m::asm::delay(FLUSH_CYCLES);
    SCB::sys_reset()
}

/// Logs where the panic happened and its message when that is a plain string. A message
/// with arguments (an index out of bounds, say) is logged as its location only: formatting
/// it would take `core::fmt`, about 4 KB of every firmware's flash that nothing else needs,
/// and the location plus the ELF is what one debugs a panic with.
#[panic_handler]
fn panic(info: &PanicInfo) -> ! {
    let message = info
        .message()
        .as_str()
        .unwrap_or("(message with arguments)");
    match info.location() {
        Some(at) => defmt::error!(
            "panic at {=str}:{=u32}: {=str}",
            at.file(),
            at.line(),
            message
        ),
        None => defmt::error!("panic: {=str}", message),
    }
    reset()
}

#[defmt::panic_handler]
fn defmt_panic() -> ! {
    // `defmt::panic!` and failed `defmt::assert!`s end here after logging their message.
    reset()
}

#[exception]
unsafe fn HardFault(frame: &ExceptionFrame) -> ! {
    defmt::error!(
        "HardFault at PC {=u32:#010x} (LR {=u32:#010x})",
        frame.pc(),
        frame.lr()
    );
    reset()
}
