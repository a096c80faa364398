//! Deterministic fixed-step model of the 1999–2001 Mitsubishi Lancer Evolution VI, the
//! car the AutoPlug ECUs drive in host tests and in the virtual car.
//!
//! It replaces the 2011 project's TORCS simulation with what the nine ECUs need:
//! a planar body with load transfer, four wheels with their own spin and Pacejka tyres
//! (combined slip, friction per wheel for split-μ), per-wheel brakes whose pressure
//! follows the command with a lag, the 4G63T engine with idle control, rev limiter and
//! fuel, a 6-speed gearbox with an automated clutch (which also declutches under hard
//! braking), the AWD driveline with the Active Yaw Control rear differential, steering, a
//! single-track yaw-rate reference, a cabin thermal model with a noisy sensor, and the
//! lights.
//!
//! ```
//! use autoplug_vehicle::{Actuators, Environment, Gear, InitialState, Vehicle, VehicleParams};
//!
//! let mut car = Vehicle::new(
//!     VehicleParams::evo_vi(),
//!     Environment::default(),
//!     InitialState::default(),
//!     42,
//! );
//! let act = Actuators { accelerator: 1.0, gear: Gear::Forward(1), ..Actuators::default() };
//! for _ in 0..2000 {
//!     car.step(&act, 1e-3);
//! }
//! assert!(car.state().speed_mps > 5.0);
//! ```
//!
//! Module map: [`params`] (every number and its source), `tyre`, `engine`, `driveline`,
//! `body` (planar body, load transfer, yaw reference), [`thermal`] (cabin), `rng`.
//!
//! `step` allocates nothing and costs a few hundred nanoseconds; the model is stable at
//! the nominal 1 ms step (larger steps are split into 1 ms sub-steps).
#![deny(missing_docs)]

mod body;
pub mod controls;
mod driveline;
mod engine;
mod interface;
pub mod params;
mod rng;
pub mod thermal;
mod tyre;

pub use body::reference_yaw_rate;
pub use interface::{
    Actuators, Environment, Gear, GearCommand, InitialState, VehicleState, FL, FR, RL, RR,
};
pub use params::{VehicleParams, GRAVITY};
pub use tyre::{
    longitudinal_friction_coefficient, peak_braking_deceleration, shortest_braking_distance,
};

use body::{flush_tiny, Body, BodyForces, Geometry};
use driveline::{signed_ratio, Driveline, Gearbox, WheelLoads};
use engine::{rad_s_to_rpm, rpm_to_rad_s, Engine};
use thermal::Cabin;
use tyre::{ContactKinematics, TyreModel, TyreState};

/// Longest step the model integrates in one go, s; longer steps are split.
pub const MAX_SUBSTEP_S: f64 = 1e-3;

/// Road friction coefficients are held in this range.
const MU_RANGE: (f64, f64) = (0.01, 2.0);

/// The vehicle: parameters, environment and the complete dynamic state.
#[derive(Clone, Debug)]
pub struct Vehicle {
    params: VehicleParams,
    environment: Environment,
    // Derived once from the parameters and the environment.
    geometry: Geometry,
    tyre_model: TyreModel,
    cornering_stiffness_per_load: [f64; 4],
    max_brake_torque_nm: [f64; 4],
    /// Brake torque acting on each wheel (it follows the command with a lag), N·m.
    brake_torque_nm: [f64; 4],
    /// Sine and cosine of the slope under each wheel.
    grade_sin: [f64; 4],
    grade_cos: [f64; 4],
    mean_mu: f64,
    // Dynamic state.
    body: Body,
    tyres: [TyreState; 4],
    engine: Engine,
    driveline: Driveline,
    cabin: Cabin,
    road_wheel_angle: f64,
    /// Sine and cosine of `road_wheel_angle`, recomputed only when it changes.
    steer_sin_cos: (f64, f64),
    state: VehicleState,
}

impl Vehicle {
    /// A car with `params` on `environment`, starting as `initial` says; `seed` seeds the
    /// sensor noise (the same seed and inputs reproduce a run bit for bit).
    ///
    /// # Panics
    /// If a parameter is not physical (a non-positive mass, inertia, length, ratio or
    /// time constant, or magic-formula factors outside C ∈ (1, 2), E < 1).
    pub fn new(
        params: VehicleParams,
        environment: Environment,
        initial: InitialState,
        seed: u64,
    ) -> Self {
        check_params(&params);
        let geometry = Geometry::new(&params.chassis);
        let nominal_load = params.chassis.mass_kg * GRAVITY / 4.0;
        let tyre_model = TyreModel::new(&params.tyre, nominal_load);
        let front_k = params.tyre.front_cornering_stiffness_per_load;
        let rear_k = params.tyre.rear_cornering_stiffness_per_load;
        let front_brake = params.brakes.max_torque_front_nm;
        let rear_brake = params.brakes.max_torque_rear_nm;

        let speed = finite_or_zero(initial.speed_kmh) / 3.6;
        let wheel_omega = speed / params.tyre.rolling_radius_m;
        let gearbox = Gearbox::new(&params.driveline, initial.gear, wheel_omega, speed);
        let fuel_l = finite_or_zero(initial.fuel_l).clamp(0.0, params.engine.tank_capacity_l);
        // In gear at a speed the clutch can hold, the engine turns with the wheels;
        // otherwise it idles (or stands, with an empty tank).
        let locked_omega = signed_ratio(&params.driveline, gearbox.engaged()) * wheel_omega;
        let (engine_omega, clutch) =
            if rad_s_to_rpm(locked_omega) >= params.driveline.clutch_lock_rpm {
                (locked_omega, 1.0)
            } else if fuel_l > 0.0 {
                (rpm_to_rad_s(params.engine.idle_rpm), 0.0)
            } else {
                (0.0, 0.0)
            };
        let cabin_temp = finite_or_zero(initial.cabin_temp_c);

        let mut vehicle = Self {
            geometry,
            tyre_model,
            cornering_stiffness_per_load: [front_k, front_k, rear_k, rear_k],
            max_brake_torque_nm: [front_brake, front_brake, rear_brake, rear_brake],
            brake_torque_nm: [0.0; 4],
            grade_sin: [0.0; 4],
            grade_cos: [1.0; 4],
            mean_mu: 1.0,
            body: Body::new(
                finite_or_zero(initial.x_m),
                finite_or_zero(initial.y_m),
                finite_or_zero(initial.heading_rad),
                speed,
            ),
            tyres: [TyreState::default(); 4],
            engine: Engine::new(engine_omega, fuel_l),
            driveline: Driveline::new(gearbox, clutch, wheel_omega),
            cabin: Cabin::new(cabin_temp, seed),
            road_wheel_angle: 0.0,
            steer_sin_cos: (0.0, 1.0),
            state: VehicleState::default(),
            environment,
            params,
        };
        vehicle.set_environment(environment);
        vehicle.publish(&Actuators::default());
        vehicle
    }

    /// Changes road and weather from the next step on (friction, grade, ambient, sun).
    pub fn set_environment(&mut self, environment: Environment) {
        let mut env = environment;
        for mu in &mut env.mu {
            *mu = if mu.is_finite() {
                mu.clamp(MU_RANGE.0, MU_RANGE.1)
            } else {
                1.0
            };
        }
        env.grade_percent = env.grade_percent.map(finite_or_zero);
        env.ambient_c = finite_or_zero(env.ambient_c);
        env.sun_load_w = finite_or_zero(env.sun_load_w);
        for (i, percent) in env.grade_percent.iter().enumerate() {
            (self.grade_sin[i], self.grade_cos[i]) = (percent / 100.0).atan().sin_cos();
        }
        self.mean_mu = 0.25 * env.mu.iter().sum::<f64>();
        self.environment = env;
    }

    /// The environment in force (after clamping).
    pub fn environment(&self) -> &Environment {
        &self.environment
    }

    /// The parameters the car was built with.
    pub fn params(&self) -> &VehicleParams {
        &self.params
    }

    /// The state after the last step.
    pub fn state(&self) -> &VehicleState {
        &self.state
    }

    /// Puts a standing car at (`x_m`, `y_m`) heading `heading_rad` (the simulator's hand:
    /// a car taken back to the start line). The body stops there (no velocity, no yaw
    /// rate, no load transfer); engine, driveline, fuel and cabin are left as they are.
    pub fn place(&mut self, x_m: f64, y_m: f64, heading_rad: f64) {
        if !(x_m.is_finite() && y_m.is_finite() && heading_rad.is_finite()) {
            return;
        }
        self.body = Body::new(x_m, y_m, heading_rad, 0.0);
        for omega in &mut self.driveline.wheel_omega {
            *omega = 0.0;
        }
        self.tyres = [TyreState::default(); 4];
        let distance = self.state.distance_m;
        self.body.distance = distance;
        self.publish(&Actuators::default());
    }

    /// Where each wheel touches the road, world frame (x, y), m, FL FR RL RR: what
    /// decides the surface under each tyre.
    pub fn wheel_positions(&self) -> [(f64, f64); 4] {
        let (sin, cos) = self.body.heading_sin_cos;
        std::array::from_fn(|i| {
            let (x, y) = (self.geometry.wheel_x[i], self.geometry.wheel_y[i]);
            (
                self.body.x + x * cos - y * sin,
                self.body.y + x * sin + y * cos,
            )
        })
    }

    /// The sine and cosine of the car's heading (`state().heading_rad`), as the model
    /// keeps them.
    pub fn heading_sin_cos(&self) -> (f64, f64) {
        self.body.heading_sin_cos
    }

    /// Advances the model by `dt` seconds under `actuators` (held for the whole step).
    /// Steps longer than [`MAX_SUBSTEP_S`] are split into equal sub-steps; a
    /// non-positive or non-finite `dt` does nothing.
    pub fn step(&mut self, actuators: &Actuators, dt: f64) {
        if !(dt.is_finite() && dt > 0.0) {
            return;
        }
        let act = self.sanitise(actuators);
        let substeps = (dt / MAX_SUBSTEP_S).ceil().max(1.0);
        let h = dt / substeps;
        for _ in 0..substeps as u64 {
            self.substep(&act, h);
        }
        self.publish(&act);
    }

    /// Actuator commands clamped to their ranges, non-finite values read as 0.
    fn sanitise(&self, act: &Actuators) -> Actuators {
        let max_steer = self.params.steering.max_steering_wheel_deg;
        let max_split = self.params.driveline.ayc_max_command_nm;
        Actuators {
            accelerator: finite_or_zero(act.accelerator).clamp(0.0, 1.0),
            brake: act.brake.map(|b| finite_or_zero(b).clamp(0.0, 1.0)),
            steering_wheel_deg: finite_or_zero(act.steering_wheel_deg).clamp(-max_steer, max_steer),
            gear: act.gear.normalised(),
            torque_split_nm: finite_or_zero(act.torque_split_nm).clamp(-max_split, max_split),
            fan: finite_or_zero(act.fan).clamp(0.0, 1.0),
            headlights: act.headlights,
            brake_lights: act.brake_lights,
        }
    }

    fn substep(&mut self, act: &Actuators, h: f64) {
        let p = &self.params;
        let radius = p.tyre.rolling_radius_m;
        let inv_h = 1.0 / h;
        let road_wheel_angle = act.steering_wheel_deg.to_radians() / p.steering.ratio;
        if road_wheel_angle != self.road_wheel_angle {
            self.road_wheel_angle = road_wheel_angle;
            self.steer_sin_cos = road_wheel_angle.sin_cos();
        }
        let (steer_sin, steer_cos) = self.steer_sin_cos;
        // Backward-Euler first-order lags of the brake pressure, stable for any step.
        let apply_lag = h / (p.brakes.pressure_apply_time_constant_s + h);
        let release_lag = h / (p.brakes.pressure_release_time_constant_s + h);

        // Tyres: forces from the body's motion and the wheels' spin.
        let loads = self.body.normal_loads(&self.geometry, &self.grade_cos);
        let rolling_resistance = p.tyre.rolling_resistance_coefficient
            * (1.0 + self.body.vx.abs() * 3.6 / p.tyre.rolling_resistance_doubling_speed_kmh);
        let mut forces = BodyForces::default();
        let mut wheel_loads = WheelLoads::default();
        for (i, &load) in loads.iter().enumerate() {
            let (vx, vy) = self.body.wheel_velocity(&self.geometry, i);
            let steered = i == FL || i == FR;
            // Velocity in the wheel's axes (front wheels turned by the steering angle).
            let (v_long, v_lat) = if steered {
                (
                    vx * steer_cos + vy * steer_sin,
                    vy * steer_cos - vx * steer_sin,
                )
            } else {
                (vx, vy)
            };
            let kinematics = ContactKinematics {
                load_n: load,
                mu: self.environment.mu[i],
                v_long,
                v_lat,
                surface_speed: self.driveline.wheel_omega[i] * radius,
                cornering_stiffness_per_load: self.cornering_stiffness_per_load[i],
            };
            let tyre = self
                .tyre_model
                .update(&mut self.tyres[i], &kinematics, h, inv_h);
            let (fx, fy) = if steered {
                (
                    tyre.longitudinal_n * steer_cos - tyre.lateral_n * steer_sin,
                    tyre.longitudinal_n * steer_sin + tyre.lateral_n * steer_cos,
                )
            } else {
                (tyre.longitudinal_n, tyre.lateral_n)
            };
            forces.tyre_x += fx;
            forces.tyre_y += fy;
            forces.yaw_moment += self.geometry.wheel_x[i] * fy - self.geometry.wheel_y[i] * fx;

            let brake_torque = &mut self.brake_torque_nm[i];
            let commanded = act.brake[i] * self.max_brake_torque_nm[i];
            let lag = if commanded > *brake_torque {
                apply_lag
            } else {
                release_lag
            };
            *brake_torque = flush_tiny(*brake_torque + (commanded - *brake_torque) * lag);
            let brake_torque = *brake_torque;
            wheel_loads.tyre_torque_nm[i] = -tyre.longitudinal_n * radius;
            wheel_loads.friction_torque_nm[i] = brake_torque + rolling_resistance * load * radius;

            self.state.wheel_load_n[i] = load;
            self.state.wheel_slip[i] = tyre.slip;
            self.state.tyre_force_longitudinal_n[i] = tyre.longitudinal_n;
            self.state.tyre_force_lateral_n[i] = tyre.lateral_n;
            self.state.brake_torque_nm[i] = brake_torque;
        }

        // Powertrain: gear and clutch, engine torque, then engine and wheel spin.
        self.driveline.update_gear_and_clutch(
            &p.driveline,
            act,
            self.engine.omega,
            self.body.vx,
            h,
        );
        let torque_cut = self.driveline.gearbox.shifting();
        self.engine
            .update_torque(&p.engine, act.accelerator, torque_cut, h);
        self.driveline.advance_spin(
            &p.driveline,
            &p.engine,
            &mut self.engine,
            &wheel_loads,
            act.torque_split_nm,
            self.body.vx,
            p.tyre.wheel_inertia_kgm2,
            h,
        );
        for omega in &mut self.driveline.wheel_omega {
            *omega = flush_tiny(*omega);
        }
        self.engine.consume_fuel(&p.engine, h);

        // Body: tyre forces, drag and the grade (each wheel's static share of the weight
        // on the slope under it).
        let mass = self.geometry.mass();
        let slope_pull: f64 = (0..4)
            .map(|i| self.geometry.weight_share[i] * self.grade_sin[i])
            .sum();
        let drag = 0.5
            * p.aero.air_density_kg_per_m3
            * p.aero.drag_coefficient
            * p.aero.frontal_area_m2
            * self.body.vx
            * self.body.vx.abs();
        forces.external_x = -drag - mass * GRAVITY * slope_pull;
        self.body.integrate(&self.geometry, &forces, h);

        self.cabin.step(
            &p.cabin,
            self.environment.ambient_c,
            self.environment.sun_load_w,
            act.fan,
            h,
        );
        self.state.t_s += h;
    }

    /// Writes the outputs that do not come straight out of the sub-step.
    fn publish(&mut self, act: &Actuators) {
        let p = &self.params;
        let s = &mut self.state;
        let body = &self.body;
        s.x_m = body.x;
        s.y_m = body.y;
        s.heading_rad = body.heading;
        s.speed_mps = body.vx;
        s.lateral_velocity_mps = body.vy;
        s.yaw_rate_rad_s = body.yaw_rate;
        s.yaw_rate_ref_rad_s = reference_yaw_rate(p, body.vx, self.road_wheel_angle, self.mean_mu);
        s.yaw_rate_error_rad_s = s.yaw_rate_ref_rad_s - body.yaw_rate;
        s.ax_mps2 = body.ax;
        s.ay_mps2 = body.ay;
        s.distance_m = body.distance;
        s.road_wheel_angle_rad = self.road_wheel_angle;
        s.wheel_speed_mps = self
            .driveline
            .wheel_omega
            .map(|omega| omega * p.tyre.rolling_radius_m);
        s.drive_torque_nm = self.driveline.drive_torque_nm;
        s.engine_rpm = rad_s_to_rpm(self.engine.omega);
        s.engine_torque_nm = self.engine.net_torque_nm();
        s.gear = self.driveline.gearbox.engaged();
        s.shifting = self.driveline.gearbox.shifting();
        s.clutch_engagement = self.driveline.clutch_engagement();
        s.torque_split_nm = self.driveline.ayc_command_nm();
        s.fuel_l = self.engine.fuel_l();
        s.fuel_used_l = self.engine.fuel_used_l();
        s.fuel_flow_l_per_h = self.engine.fuel_flow_l_per_h();
        s.cabin_temp_c = self.cabin.temp_c();
        s.cabin_temp_sensor_c = self.cabin.sensor_c();
        s.headlights = act.headlights;
        s.brake_lights = act.brake_lights;
    }
}

fn finite_or_zero(value: f64) -> f64 {
    if value.is_finite() {
        value
    } else {
        0.0
    }
}

/// Rejects parameter sets the integration cannot work with.
fn check_params(p: &VehicleParams) {
    let positive = [
        ("mass", p.chassis.mass_kg),
        ("yaw inertia", p.chassis.yaw_inertia_kgm2),
        ("wheelbase", p.chassis.wheelbase_m),
        ("front track", p.chassis.track_front_m),
        ("rear track", p.chassis.track_rear_m),
        ("rolling radius", p.tyre.rolling_radius_m),
        ("wheel inertia", p.tyre.wheel_inertia_kgm2),
        (
            "longitudinal slip stiffness",
            p.tyre.longitudinal_stiffness_per_load,
        ),
        (
            "front cornering stiffness",
            p.tyre.front_cornering_stiffness_per_load,
        ),
        (
            "rear cornering stiffness",
            p.tyre.rear_cornering_stiffness_per_load,
        ),
        (
            "carcass damping",
            p.tyre.longitudinal_carcass_damping_n_s_per_m,
        ),
        ("carcass damping", p.tyre.lateral_carcass_damping_n_s_per_m),
        (
            "slip regularisation speed",
            p.tyre.slip_regularisation_speed_mps,
        ),
        ("steering ratio", p.steering.ratio),
        ("engine inertia", p.engine.inertia_kgm2),
        ("torque table step", p.engine.torque_table_step_rpm),
        ("fuel density", p.engine.fuel_density_kg_per_l),
        ("final drive", p.driveline.final_drive_ratio),
        ("driveline efficiency", p.driveline.efficiency),
        ("clutch engage time", p.driveline.clutch_engage_time_s),
        (
            "brake pressure apply time constant",
            p.brakes.pressure_apply_time_constant_s,
        ),
        (
            "brake pressure release time constant",
            p.brakes.pressure_release_time_constant_s,
        ),
        ("cabin heat capacity", p.cabin.heat_capacity_j_per_k),
    ];
    for (name, value) in positive {
        assert!(
            value.is_finite() && value > 0.0,
            "vehicle parameter {name} must be > 0"
        );
    }
    assert!(
        p.driveline.launch_full_rpm > p.driveline.launch_bite_rpm,
        "launch_full_rpm must exceed launch_bite_rpm"
    );
    assert!(
        p.driveline.efficiency <= 1.0,
        "driveline efficiency must be at most 1"
    );
}
