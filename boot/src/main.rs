//! The AutoPlug bootloader for the STM32F446RE (sectors 0–1): at every reset it reads the
//! boot record (`autoplug_flash::ab`) and starts the image slot it names — the confirmed
//! one, or once, on trial, the slot an update has just written — in place, where the
//! image was linked to run, its vector table right after the 512-byte image header.
//!
//! Nothing is copied, so a start costs the record's one word program at most. A trial that
//! never confirmed itself (a crash, the watchdog, a power cut) is reverted at the next
//! reset. A slot whose vector table cannot be an application for it (erased, half written,
//! linked elsewhere) is never started.
//!
//! The bootloader starts the independent watchdog, with [`WATCHDOG_TIMEOUT_US`] (longer than
//! the slowest sector erase of the datasheet, 2 s, which the two-copy state's switch may
//! need), feeds it before every flash operation, and leaves it running for the image it
//! starts, which sets its own timeout once it runs. A reset stops the watchdog, so without
//! this an image that locks up or hangs before it starts its own (a trial image that is not
//! a program for this board, say) would never be reset, and so never reverted: now the
//! watchdog resets it within the timeout, and the next start reverts the trial.
//!
//! Flash once with probe-rs: `cargo flash-boot` (docs/src/updates-over-can.md, "On a bench").
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(not(target_os = "none"))]
fn main() {
    println!(
        "boot is the ECUs' bootloader for the Nucleo-F446RE: build it with \
         `cargo build --profile firmware --target thumbv7em-none-eabihf -p autoplug-boot`"
    );
}

#[cfg(target_os = "none")]
mod boot {
    use core::cell::RefCell;

    use autoplug_flash::ab::{self, BootAction, ImageSlot};
    use autoplug_flash::twin::Twin;
    use autoplug_flash::{SMALL_SECTORS, STATE_COPIES};
    use cortex_m_rt::{entry, exception, ExceptionFrame};
    use defmt_rtt as _;
    use embassy_embedded_hal::flash::partition::BlockingPartition;
    use embassy_stm32::flash::{Blocking, Flash};
    use embassy_stm32::wdg::IndependentWatchdog;
    use embassy_sync::blocking_mutex::raw::NoopRawMutex;
    use embassy_sync::blocking_mutex::Mutex;
    use embedded_storage::nor_flash::{ErrorType, NorFlash, ReadNorFlash};

    /// Watchdog timeout while the bootloader works: above the F446's worst-case sector
    /// erase (2 s for 128 KiB, DS10693), so a running watchdog never fires mid-erase.
    pub const WATCHDOG_TIMEOUT_US: u32 = 4_000_000;

    /// A flash region that feeds the watchdog before each operation.
    struct Fed<F>(F);

    fn feed() {
        embassy_stm32::pac::IWDG
            .kr()
            .write(|w| w.set_key(embassy_stm32::pac::iwdg::vals::Key::RESET));
    }

    impl<F: ErrorType> ErrorType for Fed<F> {
        type Error = F::Error;
    }

    impl<F: ReadNorFlash> ReadNorFlash for Fed<F> {
        const READ_SIZE: usize = F::READ_SIZE;
        fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
            self.0.read(offset, bytes)
        }
        fn capacity(&self) -> usize {
            self.0.capacity()
        }
    }

    impl<F: NorFlash> NorFlash for Fed<F> {
        const WRITE_SIZE: usize = F::WRITE_SIZE;
        const ERASE_SIZE: usize = F::ERASE_SIZE;
        fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
            // One sector at a time, so the watchdog is fed between sectors.
            let mut at = from;
            while at < to {
                feed();
                self.0.erase(at, at + F::ERASE_SIZE as u32)?;
                at += F::ERASE_SIZE as u32;
            }
            Ok(())
        }
        fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
            feed();
            self.0.write(offset, bytes)
        }
    }

    /// Whether `slot` starts with a vector table an application linked for it would have.
    fn startable(slot: ImageSlot) -> bool {
        let table = slot.vector_table() as *const u32;
        // SAFETY: both words lie in the MCU's memory-mapped flash, always readable.
        let (sp, reset) = unsafe {
            (
                core::ptr::read_volatile(table),
                core::ptr::read_volatile(table.add(1)),
            )
        };
        ab::plausible_vector_table(slot, sp, reset)
    }

    #[entry]
    fn main() -> ! {
        // Default clocks (16 MHz HSI): the bootloader waits on the flash, not the core.
        let p = embassy_stm32::init(Default::default());
        let mut watchdog = IndependentWatchdog::new(p.IWDG, WATCHDOG_TIMEOUT_US);
        watchdog.unleash();
        feed();

        let layout = Flash::<Blocking>::new_blocking(p.FLASH).into_blocking_regions();
        let small = Mutex::<NoopRawMutex, _>::new(RefCell::new(Fed(layout.bank1_region1)));
        let copies = STATE_COPIES.map(|copy| {
            BlockingPartition::new(&small, copy.start - SMALL_SECTORS.start, copy.size)
        });
        let choice = match Twin::open(copies) {
            Ok(mut twin) => ab::choose(&mut twin, startable),
            Err(_) => {
                defmt::error!("boot: the state copies cannot be read");
                let slot = if startable(ImageSlot::A) {
                    ImageSlot::A
                } else {
                    ImageSlot::B
                };
                ab::BootChoice {
                    slot,
                    action: BootAction::Fallback,
                }
            }
        };
        let letter = choice.slot.letter();
        match choice.action {
            BootAction::Normal => defmt::info!("boot: starting slot {=char}", letter),
            BootAction::Trial => {
                defmt::info!("boot: starting slot {=char} on trial (new image)", letter)
            }
            BootAction::Reverted => defmt::warn!(
                "boot: the image on trial did not confirm itself: back to slot {=char}",
                letter
            ),
            BootAction::Fallback => defmt::warn!(
                "boot: no usable boot record or confirmed image: trying slot {=char}",
                letter
            ),
        }
        feed();
        let table = choice.slot.vector_table();
        // SAFETY: the slot holds a vector table linked for it (checked above, unless neither
        // slot has one, when nothing better can be done); the bootloader hands over the
        // whole MCU and never runs again until the next reset. The application's
        // interrupts need VTOR on its table before its first instruction.
        unsafe {
            (*cortex_m::peripheral::SCB::PTR).vtor.write(table);
            cortex_m::asm::bootload(table as *const u32)
        }
    }

    #[panic_handler]
    fn panic(info: &core::panic::PanicInfo) -> ! {
        defmt::error!("boot: panic: {}", defmt::Display2Format(info));
        cortex_m::peripheral::SCB::sys_reset()
    }

    #[exception]
    unsafe fn HardFault(frame: &ExceptionFrame) -> ! {
        defmt::error!("boot: HardFault at PC {=u32:#010x}", frame.pc());
        cortex_m::peripheral::SCB::sys_reset()
    }
}
