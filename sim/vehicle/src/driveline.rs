//! Clutch, gearbox and the AWD driveline, and the spin dynamics of engine and wheels.
//!
//! **Layout (EVO VI).** Engine → clutch → 6-speed gearbox → open 50:50 centre
//! differential with a viscous coupling → open front differential and the rear Active
//! Yaw Control differential. Both axles share the final drive ratio, so the gearbox input
//! turns at `G·mean(ω_wheels)` and the clutch torque `T_c` reaches each wheel as
//! `η·G·T_c/4` (open differentials split torque equally). On top of that the viscous
//! coupling moves torque from the faster to the slower axle, and the AYC moves its
//! commanded torque from the left to the right rear wheel (or back).
//!
//! **Clutch.** Automated, with three regimes:
//! - *launch*: from the moment the gearbox input turns slower than `clutch_release_rpm`
//!   (starting off, or slowing down in gear: anti-stall) until the input has caught up
//!   with the engine within `clutch_lock_slip_rpm`, the clutch capacity rises with
//!   engine speed (like a centrifugal clutch) between `launch_bite_rpm` and
//!   `launch_full_rpm`: idle never drives the car (no creep), full throttle launches at
//!   ≈ 4200 rpm with the clutch slipping;
//! - *closing*: otherwise, with the input above `clutch_lock_rpm`, the clutch closes to
//!   full capacity within `clutch_engage_time_s` (also after every shift);
//! - *open*: in neutral, during a shift, and under hard braking (a wheel's brake command
//!   at `declutch_brake_command` or more) until the brakes have been released for
//!   `declutch_hold_s` or the accelerator is pressed with the brakes released, as a driver
//!   declutches in an emergency stop and automated gearboxes do, so that engine drag and
//!   downshifts do not brake the wheels behind the ABS's back.
//!
//! It is solved as a friction constraint at velocity level: the torque that would make
//! engine and input speeds equal at the end of the step, limited to the capacity. That
//! is exact for stick and slip alike and stable at any step.
//!
//! **Gearbox.** Obeys the gear command: a shift to another gear opens the clutch, cuts
//! the engine torque and spends `shift_time_s` in neutral before engaging. A gear only
//! engages if it would not overspeed the engine past `max_engage_rpm`, and not against
//! the direction of travel above `max_reversal_speed_mps` (reverse at speed); until then
//! the box waits in neutral.
//!
//! **Brakes and rolling resistance** act as Coulomb friction on the wheels: they slow a
//! wheel by at most what stops it, so a braked wheel sits at exactly zero speed.

use crate::engine::{rad_s_to_rpm, Engine};
use crate::interface::{Actuators, Gear, FL, FR, RL, RR};
use crate::params::{DrivelineParams, EngineParams};

/// Overall signed ratio engine/wheel of a gearbox position (0 in neutral).
pub(crate) fn signed_ratio(p: &DrivelineParams, gear: Gear) -> f64 {
    match gear {
        Gear::Forward(n) => p.overall_ratio(n),
        Gear::Reverse => -p.reverse_ratio * p.final_drive_ratio,
        Gear::Neutral => 0.0,
    }
}

#[derive(Clone, Debug)]
pub(crate) struct Gearbox {
    engaged: Gear,
    target: Gear,
    shift_timer_s: f64,
}

impl Gearbox {
    /// A gearbox in `gear`; if that gear cannot be engaged at `mean_wheel_omega` and
    /// `speed`, the box starts in neutral waiting to engage it.
    pub(crate) fn new(p: &DrivelineParams, gear: Gear, mean_wheel_omega: f64, speed: f64) -> Self {
        let gear = gear.normalised();
        let engaged = if can_engage(p, gear, mean_wheel_omega, speed) {
            gear
        } else {
            Gear::Neutral
        };
        Self {
            engaged,
            target: gear,
            shift_timer_s: 0.0,
        }
    }

    pub(crate) fn update(
        &mut self,
        p: &DrivelineParams,
        command: Gear,
        mean_wheel_omega: f64,
        speed: f64,
        dt: f64,
    ) {
        let command = command.normalised();
        if command != self.target {
            self.target = command;
            self.engaged = Gear::Neutral;
            self.shift_timer_s = if command == Gear::Neutral {
                0.0
            } else {
                p.shift_time_s
            };
        }
        if self.engaged != self.target {
            self.shift_timer_s = (self.shift_timer_s - dt).max(0.0);
            if self.shift_timer_s == 0.0 && can_engage(p, self.target, mean_wheel_omega, speed) {
                self.engaged = self.target;
            }
        }
    }

    pub(crate) fn engaged(&self) -> Gear {
        self.engaged
    }

    pub(crate) fn shifting(&self) -> bool {
        self.engaged != self.target
    }
}

/// Whether `gear` can engage with the wheels at `mean_wheel_omega` and the car at
/// longitudinal `speed`.
fn can_engage(p: &DrivelineParams, gear: Gear, mean_wheel_omega: f64, speed: f64) -> bool {
    let ratio = signed_ratio(p, gear);
    if ratio == 0.0 {
        return true;
    }
    let implied_rpm = rad_s_to_rpm(ratio * mean_wheel_omega);
    implied_rpm <= p.max_engage_rpm && speed * ratio.signum() >= -p.max_reversal_speed_mps
}

/// Per-wheel torques the driveline needs from the rest of the model.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct WheelLoads {
    /// Torque of the road on each wheel (−r·F_x), N·m.
    pub(crate) tyre_torque_nm: [f64; 4],
    /// Coulomb friction torque of brake and rolling resistance on each wheel, N·m (≥ 0).
    pub(crate) friction_torque_nm: [f64; 4],
}

#[derive(Clone, Debug)]
pub(crate) struct Driveline {
    pub(crate) gearbox: Gearbox,
    /// Clutch capacity as a fraction of its maximum.
    clutch_engagement: f64,
    /// True from a start (input turning slower than the release speed) until the input
    /// has caught up with the engine.
    launching: bool,
    /// Time left before a clutch opened by hard braking may close again, s (0: not
    /// declutched).
    declutch_timer_s: f64,
    /// Torque-split command after the AYC's hydraulic lag, N·m.
    ayc_command_nm: f64,
    /// Wheel spin speeds, rad/s, FL FR RL RR.
    pub(crate) wheel_omega: [f64; 4],
    /// Driveline torque delivered to each wheel in the last step, N·m.
    pub(crate) drive_torque_nm: [f64; 4],
}

impl Driveline {
    pub(crate) fn new(gearbox: Gearbox, clutch_engagement: f64, wheel_omega: f64) -> Self {
        Self {
            gearbox,
            clutch_engagement,
            launching: clutch_engagement < 1.0,
            declutch_timer_s: 0.0,
            ayc_command_nm: 0.0,
            wheel_omega: [wheel_omega; 4],
            drive_torque_nm: [0.0; 4],
        }
    }

    pub(crate) fn mean_wheel_omega(&self) -> f64 {
        0.25 * self.wheel_omega.iter().sum::<f64>()
    }

    pub(crate) fn clutch_engagement(&self) -> f64 {
        self.clutch_engagement
    }

    pub(crate) fn ayc_command_nm(&self) -> f64 {
        self.ayc_command_nm
    }

    /// Clutch capacity fraction of the launch regime at engine speed `engine_rpm`.
    pub(crate) fn launch_engagement(p: &DrivelineParams, engine_rpm: f64) -> f64 {
        let x = ((engine_rpm - p.launch_bite_rpm) / (p.launch_full_rpm - p.launch_bite_rpm))
            .clamp(0.0, 1.0);
        // Quadratic: a gentle bite, firm near full.
        x * x
    }

    /// Moves the gearbox and the clutch on by `dt` under the gear command and pedals of
    /// `act`.
    pub(crate) fn update_gear_and_clutch(
        &mut self,
        p: &DrivelineParams,
        act: &Actuators,
        engine_omega: f64,
        speed: f64,
        dt: f64,
    ) {
        let mean_wheel_omega = self.mean_wheel_omega();
        self.gearbox
            .update(p, act.gear, mean_wheel_omega, speed, dt);
        let hardest_brake = act.brake.iter().fold(0.0f64, |a, b| a.max(*b));
        let accelerator = act.accelerator;
        if hardest_brake >= p.declutch_brake_command {
            self.declutch_timer_s = p.declutch_hold_s;
        } else if hardest_brake < p.declutch_release_command {
            // Brakes released: the clutch closes after the hold, or at once when the
            // driver asks for drive again.
            self.declutch_timer_s = if accelerator > p.declutch_release_command {
                0.0
            } else {
                (self.declutch_timer_s - dt).max(0.0)
            };
        } else if self.declutch_timer_s > 0.0 {
            self.declutch_timer_s = p.declutch_hold_s;
        }
        let ratio = signed_ratio(p, self.gearbox.engaged());
        if self.gearbox.shifting() {
            // A shift ends a launch: the new gear's clutch closes like after any shift
            // (the launch regime comes back only if the input is then below
            // `clutch_release_rpm`). Without this, a gearbox that upshifts before the
            // input has caught up with the engine (economy at full throttle) would slip
            // the clutch through every gear.
            self.launching = false;
        }
        if self.gearbox.shifting() || ratio == 0.0 || self.declutch_timer_s > 0.0 {
            self.clutch_engagement = 0.0;
            return;
        }
        let input_rpm = rad_s_to_rpm(ratio * mean_wheel_omega);
        let engine_rpm = rad_s_to_rpm(engine_omega);
        if input_rpm < p.clutch_release_rpm {
            self.launching = true;
        } else if self.launching && (engine_rpm - input_rpm).abs() < p.clutch_lock_slip_rpm {
            // The input has caught up with the engine: the launch is over.
            self.launching = false;
        }
        self.clutch_engagement = if self.launching {
            Self::launch_engagement(p, engine_rpm)
        } else if input_rpm >= p.clutch_lock_rpm {
            (self.clutch_engagement + dt / p.clutch_engage_time_s).min(1.0)
        } else {
            self.clutch_engagement
        };
    }

    /// Advances engine and wheel speeds by `dt` under the engine's net torque, the
    /// road, the brakes and the differentials; `torque_split_nm` is the AYC command and
    /// `speed` the car's longitudinal speed.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn advance_spin(
        &mut self,
        p: &DrivelineParams,
        engine_params: &EngineParams,
        engine: &mut Engine,
        loads: &WheelLoads,
        torque_split_nm: f64,
        speed: f64,
        wheel_inertia: f64,
        dt: f64,
    ) {
        let omega = &mut self.wheel_omega;
        let front = 0.5 * (omega[FL] + omega[FR]);
        let rear = 0.5 * (omega[RL] + omega[RR]);
        let viscous = p.centre_viscous_nm_per_rad_s * (front - rear);
        self.ayc_command_nm +=
            (torque_split_nm - self.ayc_command_nm) * dt / (p.ayc_time_constant_s + dt);
        let ayc_effect = (speed.abs() / p.ayc_full_effect_speed_mps).min(1.0);
        let ayc_transfer = self.ayc_command_nm * p.ayc_wheel_torque_per_command * ayc_effect;
        let mut drive = [0.0; 4];
        drive[FL] = -0.5 * viscous;
        drive[FR] = -0.5 * viscous;
        drive[RL] = 0.5 * viscous - ayc_transfer;
        drive[RR] = 0.5 * viscous + ayc_transfer;

        // Free motion of wheels and engine over the step.
        let mut free = [0.0; 4];
        for i in 0..4 {
            free[i] = omega[i] + dt * (loads.tyre_torque_nm[i] + drive[i]) / wheel_inertia;
        }
        let engine_inertia = engine_params.inertia_kgm2;
        let mut engine_omega = engine.omega + dt * engine.net_torque_nm() / engine_inertia;

        // Clutch: the torque that equalises engine and input speed, within capacity.
        let ratio = signed_ratio(p, self.gearbox.engaged());
        let capacity = self.clutch_engagement * p.clutch_max_torque_nm;
        if ratio != 0.0 && capacity > 0.0 {
            let input_omega = ratio * 0.25 * free.iter().sum::<f64>();
            let slip = engine_omega - input_omega;
            // Losses are taken from the power flow in either direction.
            let efficiency = if slip >= 0.0 {
                p.efficiency
            } else {
                1.0 / p.efficiency
            };
            let response =
                dt * (1.0 / engine_inertia + efficiency * ratio * ratio / (4.0 * wheel_inertia));
            let clutch_torque = (slip / response).clamp(-capacity, capacity);
            engine_omega -= dt * clutch_torque / engine_inertia;
            let per_wheel = 0.25 * efficiency * ratio * clutch_torque;
            for i in 0..4 {
                drive[i] += per_wheel;
                free[i] += dt * per_wheel / wheel_inertia;
            }
        }
        engine.omega = engine_omega.max(0.0);

        // Brakes and rolling resistance: Coulomb friction that cannot reverse a wheel.
        for i in 0..4 {
            let max_change = dt * loads.friction_torque_nm[i] / wheel_inertia;
            omega[i] = if free[i].abs() <= max_change {
                0.0
            } else {
                free[i] - max_change.copysign(free[i])
            };
        }
        self.drive_torque_nm = drive;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::VehicleParams;

    #[test]
    fn shift_waits_in_neutral_then_engages() {
        let p = VehicleParams::evo_vi().driveline;
        let mut gearbox = Gearbox::new(&p, Gear::Neutral, 0.0, 0.0);
        gearbox.update(&p, Gear::Forward(1), 0.0, 0.0, 0.1);
        assert!(gearbox.shifting());
        assert_eq!(gearbox.engaged(), Gear::Neutral);
        gearbox.update(&p, Gear::Forward(1), 0.0, 0.0, 0.1);
        assert_eq!(gearbox.engaged(), Gear::Forward(1));
        assert!(!gearbox.shifting());
    }

    #[test]
    fn reverse_refused_while_rolling_forward() {
        let p = VehicleParams::evo_vi().driveline;
        let omega = 10.0 / 0.31;
        let mut gearbox = Gearbox::new(&p, Gear::Neutral, omega, 10.0);
        for _ in 0..10 {
            gearbox.update(&p, Gear::Reverse, omega, 10.0, 0.1);
        }
        assert_eq!(gearbox.engaged(), Gear::Neutral);
        gearbox.update(&p, Gear::Reverse, 0.0, 0.0, 0.1);
        assert_eq!(gearbox.engaged(), Gear::Reverse);
    }

    #[test]
    fn downshift_refused_when_it_would_overspeed_the_engine() {
        let p = VehicleParams::evo_vi().driveline;
        // 150 km/h in 1st would be ≈ 17 000 rpm.
        let omega = 150.0 / 3.6 / 0.31;
        let mut gearbox = Gearbox::new(&p, Gear::Forward(4), omega, 150.0 / 3.6);
        for _ in 0..10 {
            gearbox.update(&p, Gear::Forward(1), omega, 150.0 / 3.6, 0.1);
        }
        assert_eq!(gearbox.engaged(), Gear::Neutral);
    }
}
