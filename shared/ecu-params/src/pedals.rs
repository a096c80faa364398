//! The pedals ECU's published parameters (node 0x04): when a pedal counts as pressed.

/// A pedal counts as pressed above this many pedal units: enough to ignore a foot resting
/// on it and sensor noise, small enough that any deliberate press cancels cruise (and a
/// deliberate brake press overrides the accelerator).
pub const PEDAL_PRESSED_THRESHOLD: f32 = 5.0;
