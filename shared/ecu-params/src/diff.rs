//! The differential ECU's published parameters (node 0x0C): when yaw control acts.

/// Below this speed, km/h, no yaw control: at parking speeds the yaw-rate reference means
/// little and torque vectoring only fights the steering.
pub const MIN_SPEED_KMH: f32 = 20.0;

/// Below this steering wheel angle either way, degrees, the car is going straight: no yaw
/// control (SteeringMsg has 3.375° resolution).
pub const MIN_STEERING_DEG: f32 = 10.0;

/// Control starts when |yaw-rate error| exceeds this, rad/s: below it the error is sensor
/// noise, normal tyre slip and the few hundredths of a rad/s by which a car cornering at
/// the friction limit stays under the steady-state reference (which assumes the road's
/// full friction), not instability (YawErrorMsg resolution is 0.02 rad/s). Starting
/// lower, the controller would switch on and off every half second in a long limit
/// corner, correcting what it cannot correct.
pub const YAW_DEAD_BAND_RAD_S: f32 = 0.08;

/// Control stops when |yaw-rate error| falls below this, rad/s: hysteresis under
/// [`YAW_DEAD_BAND_RAD_S`] so the split does not chatter at the band's edge.
pub const YAW_DEAD_BAND_EXIT_RAD_S: f32 = 0.03;

/// An applied brake above this on any wheel, %, holds the split at 0: braking (and ABS)
/// has priority over yaw control through the drive torque.
pub const BRAKE_HOLD_PCT: f32 = 20.0;
