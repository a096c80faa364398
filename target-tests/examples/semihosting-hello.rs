//! The Embedded Rust Book's first program: "Hello, world!" over semihosting with
//! cortex-m-semihosting's `hprintln!`, then a semihosting exit. Plain text, not defmt: a
//! runner must print it as it is (`autoplug-emu` does; scripts/target-test --emulator
//! checks it).
#![no_std]
#![no_main]

// The panic handler, defmt's logger and the link-time pieces (memory.x).
use autoplug_target_tests as _;
use cortex_m_rt::entry;
use cortex_m_semihosting::{debug, hprintln};

#[entry]
fn main() -> ! {
    hprintln!("Hello, world!");
    debug::exit(debug::EXIT_SUCCESS);
    #[allow(clippy::empty_loop)]
    loop {}
}
