//! The planar rigid body (longitudinal, lateral, yaw), its normal loads with quasi-static
//! load transfer, and the linear single-track reference for the yaw rate.

use crate::interface::{FL, FR, RL, RR};
use crate::params::{ChassisParams, VehicleParams, GRAVITY};

/// Geometry and mass properties derived once from [`ChassisParams`].
#[derive(Clone, Debug)]
pub(crate) struct Geometry {
    mass: f64,
    yaw_inertia: f64,
    cg_height: f64,
    wheelbase: f64,
    track_front: f64,
    track_rear: f64,
    front_roll_fraction: f64,
    /// Wheel positions relative to the CG in the body frame, m.
    pub(crate) wheel_x: [f64; 4],
    pub(crate) wheel_y: [f64; 4],
    /// Each wheel's share of the weight at rest on a level road (the four sum to 1).
    pub(crate) weight_share: [f64; 4],
    load_filter_time_constant: f64,
}

impl Geometry {
    pub(crate) fn new(p: &ChassisParams) -> Self {
        let a = p.cg_to_front_axle_m();
        let b = p.cg_to_rear_axle_m();
        let offsets = p.wheel_offsets();
        let wheel_x = offsets.map(|(x, _)| x);
        let wheel_y = offsets.map(|(_, y)| y);
        let wheelbase = p.wheelbase_m;
        let front = 0.5 * b / wheelbase;
        let rear = 0.5 * a / wheelbase;
        Self {
            mass: p.mass_kg,
            yaw_inertia: p.yaw_inertia_kgm2,
            cg_height: p.cg_height_m,
            wheelbase: p.wheelbase_m,
            track_front: p.track_front_m,
            track_rear: p.track_rear_m,
            front_roll_fraction: p.front_roll_stiffness_fraction,
            wheel_x,
            wheel_y,
            weight_share: [front, front, rear, rear],
            load_filter_time_constant: p.load_transfer_time_constant_s,
        }
    }

    pub(crate) fn mass(&self) -> f64 {
        self.mass
    }
}

/// Forces and moment acting on the body in one step, body frame.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct BodyForces {
    /// Sum of the tyre forces, N.
    pub(crate) tyre_x: f64,
    pub(crate) tyre_y: f64,
    /// Yaw moment of the tyre forces about the CG, N·m.
    pub(crate) yaw_moment: f64,
    /// Other longitudinal forces (drag, gravity on the grade), N.
    pub(crate) external_x: f64,
}

#[derive(Clone, Debug)]
pub(crate) struct Body {
    pub(crate) x: f64,
    pub(crate) y: f64,
    pub(crate) heading: f64,
    /// The heading's sine and cosine, kept with it: the wheels' positions and the road's
    /// queries need them every step.
    pub(crate) heading_sin_cos: (f64, f64),
    /// Velocity of the CG in the body frame, m/s.
    pub(crate) vx: f64,
    pub(crate) vy: f64,
    pub(crate) yaw_rate: f64,
    /// Acceleration of the CG in the body frame, m/s².
    pub(crate) ax: f64,
    pub(crate) ay: f64,
    pub(crate) distance: f64,
    /// Tyre-force accelerations filtered by the suspension's settling time; they set the
    /// load transfer.
    load_ax: f64,
    load_ay: f64,
}

impl Body {
    pub(crate) fn new(x: f64, y: f64, heading: f64, vx: f64) -> Self {
        Self {
            x,
            y,
            heading,
            heading_sin_cos: heading.sin_cos(),
            vx,
            vy: 0.0,
            yaw_rate: 0.0,
            ax: 0.0,
            ay: 0.0,
            distance: 0.0,
            load_ax: 0.0,
            load_ay: 0.0,
        }
    }

    /// Normal load on each wheel, N, with longitudinal and lateral load transfer.
    ///
    /// The tyre forces act at the road, `h` below the CG, so they pitch and roll the
    /// body: ΔFz_axle = m·a_x·h/L, ΔFz_side = m·a_y·h·share/track. A wheel that would
    /// lift carries 0. Each wheel's static share of the weight stands on the slope under
    /// it (`cos_grade`), which carries its cosine.
    pub(crate) fn normal_loads(&self, g: &Geometry, cos_grade: &[f64; 4]) -> [f64; 4] {
        let weight = g.mass * GRAVITY;
        let stat = |i: usize| weight * g.weight_share[i] * cos_grade[i];
        let pitch_transfer = g.mass * self.load_ax * g.cg_height / g.wheelbase;
        let roll_moment = g.mass * self.load_ay * g.cg_height;
        // A left turn (a_y > 0) loads the right-hand wheels.
        let front_shift = roll_moment * g.front_roll_fraction / g.track_front;
        let rear_shift = roll_moment * (1.0 - g.front_roll_fraction) / g.track_rear;
        let mut loads = [0.0; 4];
        loads[FL] = stat(FL) - 0.5 * pitch_transfer - front_shift;
        loads[FR] = stat(FR) - 0.5 * pitch_transfer + front_shift;
        loads[RL] = stat(RL) + 0.5 * pitch_transfer - rear_shift;
        loads[RR] = stat(RR) + 0.5 * pitch_transfer + rear_shift;
        loads.map(|load| load.max(0.0))
    }

    /// Velocity of the point of wheel `i` over the ground, body frame.
    pub(crate) fn wheel_velocity(&self, g: &Geometry, i: usize) -> (f64, f64) {
        (
            self.vx - self.yaw_rate * g.wheel_y[i],
            self.vy + self.yaw_rate * g.wheel_x[i],
        )
    }

    /// Semi-implicit Euler step of the planar rigid body.
    pub(crate) fn integrate(&mut self, g: &Geometry, f: &BodyForces, dt: f64) {
        let inv_mass = 1.0 / g.mass;
        self.ax = (f.tyre_x + f.external_x) * inv_mass;
        self.ay = f.tyre_y * inv_mass;
        // Body-frame equations: v̇x = ax + r·vy, v̇y = ay − r·vx, ṙ = Mz/Iz.
        let vx = self.vx + dt * (self.ax + self.yaw_rate * self.vy);
        let vy = self.vy + dt * (self.ay - self.yaw_rate * self.vx);
        self.yaw_rate = flush_tiny(self.yaw_rate + dt * f.yaw_moment / g.yaw_inertia);
        self.vx = flush_tiny(vx);
        self.vy = flush_tiny(vy);

        self.heading += dt * self.yaw_rate;
        self.heading_sin_cos = self.heading.sin_cos();
        let (sin, cos) = self.heading_sin_cos;
        self.x += dt * (self.vx * cos - self.vy * sin);
        self.y += dt * (self.vx * sin + self.vy * cos);
        self.distance += dt * (self.vx * self.vx + self.vy * self.vy).sqrt();

        let lag = dt / (g.load_filter_time_constant + dt);
        self.load_ax += (f.tyre_x * inv_mass - self.load_ax) * lag;
        self.load_ay += (f.tyre_y * inv_mass - self.load_ay) * lag;
    }
}

/// Zero for magnitudes far below anything physical, to keep subnormal numbers (slow on
/// most CPUs) out of a car that has come to rest.
pub(crate) fn flush_tiny(value: f64) -> f64 {
    if value.abs() < 1e-12 {
        0.0
    } else {
        value
    }
}

/// Yaw rate of the linear single-track (bicycle) model in steady state at longitudinal
/// speed `speed_mps` and road-wheel angle `road_wheel_angle_rad`:
/// `r = v·δ/(L + K_us·v²)`, limited to what friction `mu` allows, `μ·g/|v|`.
pub fn reference_yaw_rate(
    params: &VehicleParams,
    speed_mps: f64,
    road_wheel_angle_rad: f64,
    mu: f64,
) -> f64 {
    let understeer = params.tyre.understeer_gradient_rad_per_mps2();
    let linear = speed_mps * road_wheel_angle_rad
        / (params.chassis.wheelbase_m + understeer * speed_mps * speed_mps);
    let speed = speed_mps.abs();
    if speed > 0.1 {
        let limit = mu * GRAVITY / speed;
        linear.clamp(-limit, limit)
    } else {
        linear
    }
}
