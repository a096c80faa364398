//! The core's architectural state as a debugger sees it: what the differential tests compare
//! between the emulated core and an independent one.

/// r0–r15, xPSR, s0–s31 and FPSCR, in the order and width of GDB's `arm-m-profile` and
/// `arm-vfp` register sets (d0–d15 there are s0–s31 in pairs, low word first).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ArchState {
    /// r0–r12, SP (r13), LR (r14), PC (r15).
    pub r: [u32; 16],
    /// The combined program status register: N Z C V Q in bits 31–27, the IT bits, the
    /// Thumb bit (24), GE in bits 19–16, the exception number in bits 8–0.
    pub xpsr: u32,
    /// The single-precision registers s0–s31 as raw bits.
    pub s: [u32; 32],
    /// The floating-point status and control register.
    pub fpscr: u32,
}
