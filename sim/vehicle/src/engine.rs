//! The 4G63T engine: full-load torque curve, pedal as a fraction of the available
//! torque, idle speed control, rev limiter, friction (engine braking) and fuel.
//!
//! The engine's speed is integrated by the driveline, which couples it to the wheels
//! through the clutch; this module says what torque the engine makes at its speed.
//!
//! The engine does not stall: below idle the idle controller always catches it (the
//! model stands for a driver who restarts a stalled engine at once). It stops for good
//! when the tank is empty: no fuel, no combustion torque, no fuel flow.

use crate::params::EngineParams;

const RAD_S_PER_RPM: f64 = core::f64::consts::TAU / 60.0;

/// Converts an engine speed in rpm to rad/s.
pub(crate) fn rpm_to_rad_s(rpm: f64) -> f64 {
    rpm * RAD_S_PER_RPM
}

/// Converts rad/s to rpm.
pub(crate) fn rad_s_to_rpm(rad_s: f64) -> f64 {
    rad_s / RAD_S_PER_RPM
}

#[derive(Clone, Debug)]
pub(crate) struct Engine {
    /// Crankshaft speed, rad/s, never negative.
    pub(crate) omega: f64,
    /// Pedal after the air-path lag, 0..=1.
    pedal_response: f64,
    /// Torque of combustion (before friction) this step, N·m.
    combustion_torque_nm: f64,
    /// Brake torque at the crankshaft this step, N·m.
    net_torque_nm: f64,
    fuel_l: f64,
    fuel_used_l: f64,
    fuel_flow_l_per_s: f64,
}

impl Engine {
    pub(crate) fn new(omega: f64, fuel_l: f64) -> Self {
        Self {
            omega,
            pedal_response: 0.0,
            combustion_torque_nm: 0.0,
            net_torque_nm: 0.0,
            fuel_l,
            fuel_used_l: 0.0,
            fuel_flow_l_per_s: 0.0,
        }
    }

    /// Full-load brake torque at `rpm`, linearly interpolated in the table and held
    /// beyond its ends.
    pub(crate) fn full_load_torque_nm(p: &EngineParams, rpm: f64) -> f64 {
        let table = &p.full_load_torque_nm;
        let position = (rpm / p.torque_table_step_rpm).clamp(0.0, (table.len() - 1) as f64);
        let index = (position as usize).min(table.len() - 2);
        let fraction = position - index as f64;
        table[index] + fraction * (table[index + 1] - table[index])
    }

    /// Friction and pumping torque at speed `omega`, N·m (what engine braking is).
    fn friction_torque_nm(p: &EngineParams, omega: f64) -> f64 {
        p.friction_torque_nm + p.friction_torque_per_rad_s * omega
    }

    /// Works out this step's torque from the accelerator (0..=1); `torque_cut` is the
    /// gearbox's torque interrupt during a shift. Returns the net crank torque, N·m.
    pub(crate) fn update_torque(
        &mut self,
        p: &EngineParams,
        accelerator: f64,
        torque_cut: bool,
        dt: f64,
    ) -> f64 {
        let lag = dt / (p.torque_response_time_constant_s + dt);
        self.pedal_response += (accelerator - self.pedal_response) * lag;

        let rpm = rad_s_to_rpm(self.omega);
        let friction = Self::friction_torque_nm(p, self.omega);
        // The full-load curve is brake torque, so combustion has to cover friction too.
        let available = Self::full_load_torque_nm(p, rpm) + friction;
        let pedal_torque = if torque_cut {
            0.0
        } else {
            self.pedal_response * available
        };
        let idle_omega = rpm_to_rad_s(p.idle_rpm);
        let idle_torque = (Self::friction_torque_nm(p, idle_omega)
            + p.idle_gain_nm_per_rad_s * (idle_omega - self.omega))
            .clamp(0.0, p.idle_max_torque_nm);
        // Fuel is cut over the last 100 rpm below the limit.
        let limiter = ((p.rev_limit_rpm - rpm) / 100.0).clamp(0.0, 1.0);
        self.combustion_torque_nm = if self.fuel_l > 0.0 {
            pedal_torque.max(idle_torque).min(available) * limiter
        } else {
            0.0
        };
        self.net_torque_nm = self.combustion_torque_nm - friction;
        self.net_torque_nm
    }

    /// Burns the fuel of this step's combustion work.
    pub(crate) fn consume_fuel(&mut self, p: &EngineParams, dt: f64) {
        let kg_per_joule = p.indicated_sfc_g_per_kwh * 1e-3 / 3.6e6;
        let power_w = self.combustion_torque_nm * self.omega;
        self.fuel_flow_l_per_s = (power_w * kg_per_joule / p.fuel_density_kg_per_l).max(0.0);
        let burnt_l = (self.fuel_flow_l_per_s * dt).min(self.fuel_l);
        self.fuel_l -= burnt_l;
        self.fuel_used_l += burnt_l;
    }

    pub(crate) fn net_torque_nm(&self) -> f64 {
        self.net_torque_nm
    }

    pub(crate) fn fuel_l(&self) -> f64 {
        self.fuel_l
    }

    pub(crate) fn fuel_used_l(&self) -> f64 {
        self.fuel_used_l
    }

    pub(crate) fn fuel_flow_l_per_h(&self) -> f64 {
        self.fuel_flow_l_per_s * 3600.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::VehicleParams;

    #[test]
    fn published_torque_and_power() {
        let p = VehicleParams::evo_vi().engine;
        assert_eq!(Engine::full_load_torque_nm(&p, 3000.0), 373.0);
        let power_kw = Engine::full_load_torque_nm(&p, 6500.0) * rpm_to_rad_s(6500.0) / 1e3;
        assert!((power_kw - 206.0).abs() < 1.0, "{power_kw}");
        // Peak power is at 6500 rpm.
        for rpm in (1000..8000).step_by(100) {
            let rpm = f64::from(rpm);
            let kw = Engine::full_load_torque_nm(&p, rpm) * rpm_to_rad_s(rpm) / 1e3;
            assert!(kw <= power_kw + 1e-9, "{rpm} rpm: {kw} kW");
        }
    }

    #[test]
    fn idle_controller_balances_friction_at_idle() {
        let p = VehicleParams::evo_vi().engine;
        let mut engine = Engine::new(rpm_to_rad_s(p.idle_rpm), 10.0);
        assert!(engine.update_torque(&p, 0.0, false, 1e-3).abs() < 1e-9);
        engine.omega = rpm_to_rad_s(p.idle_rpm - 100.0);
        assert!(engine.update_torque(&p, 0.0, false, 1e-3) > 0.0);
    }

    #[test]
    fn no_fuel_no_torque_no_flow() {
        let p = VehicleParams::evo_vi().engine;
        let mut engine = Engine::new(rpm_to_rad_s(3000.0), 0.0);
        let net = engine.update_torque(&p, 1.0, false, 1e-3);
        engine.consume_fuel(&p, 1e-3);
        assert!(net < 0.0);
        assert_eq!(engine.fuel_flow_l_per_h(), 0.0);
        assert_eq!(engine.fuel_l(), 0.0);
    }
}
