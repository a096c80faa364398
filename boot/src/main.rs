//! The AutoPlug bootloader for the STM32F446RE (sectors 0–1): at every reset it lets
//! embassy-boot finish what the application asked for — swap in a new image from the DFU
//! slot, or revert one that did not confirm itself — and then starts the application in
//! the active slot, whose vector table follows the 512-byte image header.
//!
//! The swap erases and copies 128 KiB sectors (about 3 s in all on the F446). An
//! application that started the independent watchdog leaves it running across the reset
//! (nothing can stop it), so the bootloader stretches its timeout to
//! [`WATCHDOG_TIMEOUT_US`], longer than the slowest sector erase of the datasheet (2 s), and
//! feeds it before every flash operation.
//!
//! Flash once with probe-rs: `cargo flash-boot` (README, "Firmware upgrades over CAN").
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(not(target_os = "none"))]
fn main() {
    println!(
        "boot is the ECUs' bootloader for the Nucleo-F446RE: build it with \
         `cargo build --release --target thumbv7em-none-eabihf -p autoplug-boot`"
    );
}

#[cfg(target_os = "none")]
mod boot {
    use core::cell::RefCell;

    use autoplug_flash::twin::Twin;
    use autoplug_flash::{
        ACTIVE, APP_VECTOR_TABLE, BOOT_SWAP_BUFFER_SIZE, DFU, LARGE_SECTORS, SMALL_SECTORS,
        STATE_COPIES,
    };
    use cortex_m_rt::{entry, exception, ExceptionFrame};
    use defmt_rtt as _;
    use embassy_boot_stm32::{BootLoader, BootLoaderConfig, State};
    use embassy_embedded_hal::flash::partition::BlockingPartition;
    use embassy_stm32::flash::{Blocking, Flash};
    use embassy_stm32::wdg::IndependentWatchdog;
    use embassy_sync::blocking_mutex::raw::NoopRawMutex;
    use embassy_sync::blocking_mutex::Mutex;
    use embedded_storage::nor_flash::{ErrorType, NorFlash, ReadNorFlash};

    /// Watchdog timeout while the bootloader works: above the F446's worst-case 128 KiB
    /// sector erase (2 s, DS10693), so a running watchdog never fires mid-erase.
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

    #[entry]
    fn main() -> ! {
        // Default clocks (16 MHz HSI): the bootloader waits on the flash, not the core.
        let p = embassy_stm32::init(Default::default());
        let _watchdog = IndependentWatchdog::new(p.IWDG, WATCHDOG_TIMEOUT_US);
        feed();

        let layout = Flash::<Blocking>::new_blocking(p.FLASH).into_blocking_regions();
        let small = Mutex::<NoopRawMutex, _>::new(RefCell::new(Fed(layout.bank1_region1)));
        let large = Mutex::<NoopRawMutex, _>::new(RefCell::new(Fed(layout.bank1_region3)));
        // embassy-boot's state lives in the two-copy persistent state: its erase of the
        // state prepares the other copy, so a power cut there never loses a rollback.
        let copies = STATE_COPIES.map(|copy| {
            BlockingPartition::new(&small, copy.start - SMALL_SECTORS.start, copy.size)
        });
        let mut twin = match Twin::open(copies) {
            Ok(twin) => twin,
            Err(_) => {
                defmt::error!("boot: the state copies cannot be read: starting the active slot");
                feed();
                // SAFETY: as below; nothing is pending that the bootloader could finish.
                unsafe { cortex_m::asm::bootload(APP_VECTOR_TABLE as *const u32) }
            }
        };
        let config = BootLoaderConfig {
            active: BlockingPartition::new(&large, ACTIVE.start - LARGE_SECTORS.start, ACTIVE.size),
            dfu: BlockingPartition::new(&large, DFU.start - LARGE_SECTORS.start, DFU.size),
            state: twin.boot_state(),
        };
        let loader = BootLoader::prepare::<_, _, _, { BOOT_SWAP_BUFFER_SIZE }>(config);
        match loader.state {
            State::Swap => defmt::info!("boot: new image swapped in, starting it unconfirmed"),
            State::Revert => defmt::warn!("boot: the last image did not confirm itself: reverted"),
            _ => defmt::info!("boot: starting the application"),
        }
        feed();
        // SAFETY: the active slot holds an image (its vector table after the header); the
        // bootloader hands over the whole MCU and never runs again until the next reset.
        unsafe { loader.load(APP_VECTOR_TABLE) }
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
