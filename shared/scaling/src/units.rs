//! Unit conversions between the SI units of the vehicle model and the units the
//! catalogue and the driver use (km/h, rpm, °F, degrees, pedal units).

/// Pedal units at full travel: the catalogue sends commands as the simulator's normalised
/// value × 100 (spec section 3).
pub const PEDAL_UNITS_FULL: f32 = 100.0;

/// km/h to m/s.
pub fn kmh_to_mps(kmh: f32) -> f32 {
    kmh / 3.6
}

/// m/s to km/h.
pub fn mps_to_kmh(mps: f32) -> f32 {
    mps * 3.6
}

/// Engine speed in rpm to rad/s.
pub fn rpm_to_rad_s(rpm: f32) -> f32 {
    rpm * (core::f32::consts::TAU / 60.0)
}

/// rad/s to rpm.
pub fn rad_s_to_rpm(rad_s: f32) -> f32 {
    rad_s * (60.0 / core::f32::consts::TAU)
}

/// Degrees to radians.
pub fn deg_to_rad(deg: f32) -> f32 {
    deg * (core::f32::consts::PI / 180.0)
}

/// Radians to degrees.
pub fn rad_to_deg(rad: f32) -> f32 {
    rad * (180.0 / core::f32::consts::PI)
}

/// °F to °C.
pub fn fahrenheit_to_celsius(f: f32) -> f32 {
    (f - 32.0) * (5.0 / 9.0)
}

/// °C to °F.
pub fn celsius_to_fahrenheit(c: f32) -> f32 {
    c * (9.0 / 5.0) + 32.0
}

/// A normalised command (0 = released, 1 = full) to pedal units, clamped to 0..=100.
pub fn fraction_to_pedal_units(fraction: f32) -> f32 {
    crate::clamp_finite(fraction * PEDAL_UNITS_FULL, 0.0, PEDAL_UNITS_FULL)
}

/// Pedal units to a normalised command, clamped to 0..=1.
pub fn pedal_units_to_fraction(units: f32) -> f32 {
    crate::clamp_finite(units / PEDAL_UNITS_FULL, 0.0, 1.0)
}
