//! The console ECU's published parameters (node 0x0B): the brake-light thresholds.

/// Brake command above which the brake lights come on, %: above the noise of a foot
/// resting on the pedal, below any braking a follower would need to know about.
pub const BRAKE_LIGHTS_ON_PCT: f32 = 2.0;

/// Brake command at or below which the brake lights go off again, %: one catalogue step
/// below the on threshold (hysteresis).
pub const BRAKE_LIGHTS_OFF_PCT: f32 = 1.0;
