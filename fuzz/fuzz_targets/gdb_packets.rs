//! The emulated MCU's GDB server on arbitrary client bytes: the whole packet path
//! (framing, gdbstub's parsing, the target's registers, memory, breakpoints, watchpoints,
//! flash programming, monitor commands and reverse execution) never panics, and a session
//! over leaves the MCU as a detach does.
#![no_main]

use autoplug_flash::sim::SimFlash;
use autoplug_mcu::map::FLASH;
use autoplug_mcu::mcu::Mcu;
use libfuzzer_sys::fuzz_target;

/// An MCU with a short program in flash: a loop that counts in SRAM.
fn mcu() -> Mcu {
    let code: [u16; 8] = [
        0xF240, 0x0000, 0xF2C2, 0x0000, // r0 = 0x2000_0000
        0x6801, 0x3101, 0x6001, 0xE7FB, // loop: [r0] += 1
    ];
    let mut image = vec![0u8; 0x60];
    image[..4].copy_from_slice(&0x2002_0000u32.to_le_bytes());
    image[4..8].copy_from_slice(&(FLASH.start + 0x41).to_le_bytes());
    for (i, halfword) in code.iter().enumerate() {
        image[0x40 + 2 * i..0x42 + 2 * i].copy_from_slice(&halfword.to_le_bytes());
    }
    let mut flash = SimFlash::new(1);
    flash.program(FLASH.start, &image).expect("a fresh flash takes the image");
    Mcu::power_on(flash, [1, 2, 3]).expect("the image starts")
}

fuzz_target!(|data: &[u8]| {
    let mut mcu = mcu();
    autoplug_mcu::gdb::fuzz_session(&mut mcu, data);
    assert!(mcu.debug.hw_breakpoints.is_empty() && mcu.cpu.debug.is_none());
    assert!(mcu.history.is_none());
});
