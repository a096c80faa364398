//! Where the security seeds' unpredictability comes from on the F446, which has no random
//! number generator (the RNG peripheral is on other STM32F4 parts, not this one).
//!
//! The pool of the ECU's [`SeedSource`] takes:
//! - the MCU's 96-bit unique ID: different per chip, but not secret (a tester can read it,
//!   UDS F18C): it separates ECUs, it does not make seeds unpredictable;
//! - the seed epoch, a counter in flash raised at every start ([`crate::diag::EcuFlash::next_seed_epoch`]):
//!   no two starts draw under the same number, so a seed sniffed before a reset never comes
//!   back after it, whatever else the pool holds;
//! - jitter between two independent oscillators: the core runs from the ST-LINK's crystal
//!   through the PLL, the independent watchdog from the 32 kHz LSI RC oscillator. How many
//!   core cycles the watchdog takes to take over a new reload value (`IWDG_SR.RVU`) depends
//!   on the LSI's phase and period jitter, [`LSI_SAMPLES`] times at start-up;
//! - the core cycle at which each CAN frame arrives and each seed is asked for: set by the
//!   other nodes' own crystals, their software and the tester, measured to the cycle.
//!
//! Limits: the jitter's entropy is not characterised on the bench (no health tests as NIST
//! SP 800-90B asks of a certified source); right after a reset, before any frame arrived,
//! the pool holds the UID, the epoch and the LSI samples only. Against an attacker who
//! cannot read the flash or probe the board this makes seeds unpredictable from earlier
//! seeds; it is not a certified random source.

use autoplug_uds::security::SeedSource;
use cortex_m::peripheral::DWT;
use embassy_stm32::pac;

/// LSI handshake samples taken at start-up.
pub const LSI_SAMPLES: usize = 64;

/// Longest wait for one LSI handshake (here and for the watchdog's register updates), in
/// polls: about 5 LSI cycles (156 µs) take a few thousand polls at 168 MHz; a stopped LSI
/// must not hang the firmware.
pub(crate) const MAX_POLLS: u32 = 100_000;

/// The seed source of a start numbered `epoch`: UID, epoch and the LSI samples.
pub fn seed_source(epoch: u32) -> SeedSource {
    if let Some(mut core) = cortex_m::Peripherals::take() {
        core.DCB.enable_trace();
        core.DWT.enable_cycle_counter();
    }
    let mut seeds = SeedSource::new(&embassy_stm32::uid::uid(), epoch);
    start_lsi();
    for _ in 0..LSI_SAMPLES {
        seeds.add_entropy(&lsi_handshake_cycles().to_le_bytes());
    }
    seeds
}

/// Adds the cycle a CAN frame arrived at.
pub fn note_frame(seeds: &mut SeedSource) {
    seeds.add_entropy(&DWT::cycle_count().to_le_bytes());
}

/// Switches the LSI on (the watchdog would anyway) and waits for it, bounded.
fn start_lsi() {
    pac::RCC.csr().modify(|w| w.set_lsion(true));
    let mut polls = 0;
    while !pac::RCC.csr().read().lsirdy() && polls < MAX_POLLS {
        polls += 1;
    }
}

/// Core cycles until the watchdog's LSI domain takes over its (unchanged) reload value.
fn lsi_handshake_cycles() -> u32 {
    let iwdg = pac::IWDG;
    let reload = iwdg.rlr().read();
    iwdg.kr().write(|w| w.set_key(pac::iwdg::vals::Key::ENABLE));
    let start = DWT::cycle_count();
    iwdg.rlr().write_value(reload);
    let mut polls = 0;
    while iwdg.sr().read().rvu() && polls < MAX_POLLS {
        polls += 1;
    }
    DWT::cycle_count().wrapping_sub(start) ^ polls.rotate_left(16)
}
