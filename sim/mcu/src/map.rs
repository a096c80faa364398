//! The STM32F446's memory map (RM0390, section 2.2.2, and the Cortex-M4 system address
//! map): where the emulated core finds flash, SRAM, the device signature, the peripherals
//! and the private peripheral bus.

pub use autoplug_flash::{FLASH_BASE, FLASH_SIZE, SRAM_SIZE, SRAM_START};

/// With BOOT0 low the flash is also seen from address 0: the core fetches its initial
/// stack pointer and reset vector there.
pub const BOOT_ALIAS: u32 = 0x0000_0000;

/// The 96-bit unique device ID (RM0390, section 39.1).
pub const UID_BASE: u32 = 0x1FFF_7A10;

/// The flash size in KiB, a 16-bit word (RM0390, section 39.2).
pub const FLASH_SIZE_WORD: u32 = 0x1FFF_7A22;

/// The peripherals on APB1, APB2, AHB1 and AHB2.
pub const PERIPHERALS: core::ops::Range<u32> = 0x4000_0000..0x6000_0000;

/// The Cortex-M4's private peripheral bus: NVIC, SCB, SysTick, DWT, ITM, the FPU's
/// registers, the debug registers.
pub const PRIVATE_PERIPHERALS: core::ops::Range<u32> = 0xE000_0000..0xE010_0000;

/// The flash's address range.
pub const FLASH: core::ops::Range<u32> = FLASH_BASE..FLASH_BASE + FLASH_SIZE;

/// The SRAM's address range (SRAM1 and SRAM2 as one block).
pub const SRAM: core::ops::Range<u32> = SRAM_START..SRAM_START + SRAM_SIZE;
