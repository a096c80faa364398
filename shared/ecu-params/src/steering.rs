//! The steering ECU's published parameters (node 0x05): the paddles' shift pulse.

/// How long a shift request stays on ShiftMsg after a paddle press: 5 frames at 20 ms, so
/// the transmission sees it even if a frame is lost, and short enough to be one shift.
pub const SHIFT_PULSE_MS: u64 = 100;
