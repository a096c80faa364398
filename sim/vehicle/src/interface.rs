//! What goes into the model (actuator commands, road and weather, the initial state)
//! and what comes out (the vehicle state).
//!
//! Sign conventions follow ISO 8855: x forward, y left, z up; a positive steering angle,
//! yaw rate and lateral acceleration mean a left turn. Wheel arrays are ordered
//! FL, FR, RL, RR (indices [`FL`], [`FR`], [`RL`], [`RR`]).

use autoplug_scaling::units::{celsius_to_fahrenheit, mps_to_kmh};

/// Index of the front-left wheel in every per-wheel array.
pub const FL: usize = 0;
/// Index of the front-right wheel.
pub const FR: usize = 1;
/// Index of the rear-left wheel.
pub const RL: usize = 2;
/// Index of the rear-right wheel.
pub const RR: usize = 3;

/// A gearbox position: what the transmission commands and what is engaged.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Gear {
    /// Reverse.
    Reverse,
    /// Neutral.
    #[default]
    Neutral,
    /// Forward gear 1..=6. Out-of-range commands are read as the nearest valid position
    /// (`Forward(0)` as neutral, above 6 as 6th).
    Forward(u8),
}

/// The gear the transmission asks for.
pub type GearCommand = Gear;

impl Gear {
    /// The same position with an out-of-range forward gear mapped to a valid one.
    pub fn normalised(self) -> Self {
        match self {
            Gear::Forward(0) => Gear::Neutral,
            Gear::Forward(n) if n > 6 => Gear::Forward(6),
            other => other,
        }
    }
}

/// Commands the ECUs apply to the car; all are clamped to their range and a non-finite
/// value is read as 0.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Actuators {
    /// Accelerator, 0 (released) ..= 1 (full).
    pub accelerator: f64,
    /// Brake command per wheel, 0 ..= 1 (1 = full brake pressure), FL FR RL RR.
    pub brake: [f64; 4],
    /// Steering-wheel angle, degrees, positive = left (counter-clockwise).
    pub steering_wheel_deg: f64,
    /// Gear the transmission asks for.
    pub gear: GearCommand,
    /// Active-differential torque split, N·m, −50 ..= 50; positive moves drive torque to
    /// the right rear wheel, which yaws the car to the left.
    pub torque_split_nm: f64,
    /// HVAC fan power, 0 ..= 1.
    pub fan: f64,
    /// Headlights on.
    pub headlights: bool,
    /// Brake lights on.
    pub brake_lights: bool,
}

/// Road and weather; may be changed at any time with
/// [`Vehicle::set_environment`](crate::Vehicle::set_environment).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Environment {
    /// Peak road friction coefficient under each wheel, FL FR RL RR (dry asphalt ≈ 1,
    /// wet ≈ 0.6, snow ≈ 0.3, ice ≈ 0.1). Clamped to 0.01 ..= 2; a non-finite value is
    /// read as 1.
    pub mu: [f64; 4],
    /// Road grade under each wheel along the car's longitudinal axis, percent (rise per
    /// 100 m run), FL FR RL RR; positive = uphill ahead. Each wheel carries its share of
    /// the weight on the slope under it: the slope tilts that share's normal load and
    /// pulls the car back along it (a car straddling the foot of a hill feels the part of
    /// the hill its front wheels are on). A non-finite value is read as 0.
    pub grade_percent: [f64; 4],
    /// Ambient air temperature, °C.
    pub ambient_c: f64,
    /// Solar heat entering the cabin, W (0 at night, ≈ 500–800 in summer sun).
    pub sun_load_w: f64,
}

impl Environment {
    /// The same grade under every wheel, percent: a car wholly on one slope.
    pub fn with_grade(self, percent: f64) -> Self {
        Self {
            grade_percent: [percent; 4],
            ..self
        }
    }
}

impl Default for Environment {
    /// Dry, level road at 20 °C without sun.
    fn default() -> Self {
        Self {
            mu: [1.0; 4],
            grade_percent: [0.0; 4],
            ambient_c: 20.0,
            sun_load_w: 0.0,
        }
    }
}

/// Where and how the car starts.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InitialState {
    /// Forward speed, km/h; the wheels start rolling at this speed.
    pub speed_kmh: f64,
    /// Engaged gear; with a forward gear at speed the clutch starts closed.
    pub gear: Gear,
    /// Fuel in the tank, L (clamped to the tank's capacity).
    pub fuel_l: f64,
    /// Cabin air temperature, °C.
    pub cabin_temp_c: f64,
    /// Position east, m.
    pub x_m: f64,
    /// Position north, m.
    pub y_m: f64,
    /// Heading, rad, counter-clockwise from the x axis.
    pub heading_rad: f64,
}

impl Default for InitialState {
    /// At rest at the origin, in neutral, with a full 48 L tank and a 20 °C cabin.
    fn default() -> Self {
        Self {
            speed_kmh: 0.0,
            gear: Gear::Neutral,
            fuel_l: 48.0,
            cabin_temp_c: 20.0,
            x_m: 0.0,
            y_m: 0.0,
            heading_rad: 0.0,
        }
    }
}

/// Everything the model exposes after a step, in SI units unless a name says otherwise.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct VehicleState {
    /// Simulated time, s.
    pub t_s: f64,
    /// Position east, m.
    pub x_m: f64,
    /// Position north, m.
    pub y_m: f64,
    /// Heading, rad, counter-clockwise from the x axis (not wrapped).
    pub heading_rad: f64,
    /// Longitudinal velocity of the CG in the body frame, m/s (negative when reversing).
    pub speed_mps: f64,
    /// Lateral velocity of the CG in the body frame, m/s, positive to the left.
    pub lateral_velocity_mps: f64,
    /// Yaw rate, rad/s, positive = turning left.
    pub yaw_rate_rad_s: f64,
    /// Yaw rate of the linear single-track reference model at the current speed and
    /// steering angle, limited to μ·g/v, rad/s.
    pub yaw_rate_ref_rad_s: f64,
    /// Reference minus actual yaw rate, rad/s (what the differential ECU reads).
    pub yaw_rate_error_rad_s: f64,
    /// Longitudinal acceleration of the CG in the body frame, m/s².
    pub ax_mps2: f64,
    /// Lateral acceleration of the CG in the body frame, m/s², positive to the left.
    pub ay_mps2: f64,
    /// Road-wheel steering angle, rad, positive = left.
    pub road_wheel_angle_rad: f64,
    /// Circumferential speed of each wheel, ω·r, m/s.
    pub wheel_speed_mps: [f64; 4],
    /// Longitudinal slip of each wheel, (ω·r − v)/|v| (regularised at rest); −1 = locked.
    pub wheel_slip: [f64; 4],
    /// Normal load on each wheel, N.
    pub wheel_load_n: [f64; 4],
    /// Longitudinal tyre force of each wheel in its own plane, N.
    pub tyre_force_longitudinal_n: [f64; 4],
    /// Lateral tyre force of each wheel, N, positive to the left.
    pub tyre_force_lateral_n: [f64; 4],
    /// Brake torque each caliper applies, N·m (from the brake command).
    pub brake_torque_nm: [f64; 4],
    /// Driveline torque delivered to each wheel (engine share, viscous coupling and
    /// AYC transfer), N·m.
    pub drive_torque_nm: [f64; 4],
    /// Engine speed, rpm.
    pub engine_rpm: f64,
    /// Engine brake torque at the crankshaft (combustion minus friction), N·m.
    pub engine_torque_nm: f64,
    /// Gear actually engaged (neutral during a shift).
    pub gear: Gear,
    /// True while a shift is in progress.
    pub shifting: bool,
    /// Clutch engagement, 0 (open) ..= 1 (full capacity).
    pub clutch_engagement: f64,
    /// Torque-split command the AYC currently follows (after its hydraulic lag), N·m;
    /// the wheel torque it moves fades out below walking pace.
    pub torque_split_nm: f64,
    /// Fuel in the tank, L.
    pub fuel_l: f64,
    /// Fuel used since the start, L.
    pub fuel_used_l: f64,
    /// Current fuel flow, L/h.
    pub fuel_flow_l_per_h: f64,
    /// True cabin air temperature, °C.
    pub cabin_temp_c: f64,
    /// Cabin temperature as the cabin ECU's sensor reads it (with noise), °C.
    pub cabin_temp_sensor_c: f64,
    /// Headlights on.
    pub headlights: bool,
    /// Brake lights on.
    pub brake_lights: bool,
    /// Distance travelled over ground, m.
    pub distance_m: f64,
}

impl VehicleState {
    /// Longitudinal speed in km/h, as the catalogue carries it.
    pub fn speed_kmh(&self) -> f32 {
        mps_to_kmh(self.speed_mps as f32)
    }

    /// Wheel speeds in km/h, FL FR RL RR, as the catalogue carries them.
    pub fn wheel_speeds_kmh(&self) -> [f32; 4] {
        self.wheel_speed_mps.map(|v| mps_to_kmh(v as f32))
    }

    /// The cabin sensor's reading in °F, the catalogue's unit.
    pub fn cabin_temp_sensor_f(&self) -> f32 {
        celsius_to_fahrenheit(self.cabin_temp_sensor_c as f32)
    }
}
