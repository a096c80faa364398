//! Tyre forces: Pacejka magic formula, combined slip by the similarity method, and a
//! first-order carcass model that makes the forces well behaved down to standstill.
//!
//! **Steady state.** Pure-slip forces follow the magic formula
//! `F = D·g(B·s)`, `g(z) = sin(C·atan(z − E·(z − atan z)))`, with `D = μ·Fz` (μ with a
//! mild load sensitivity), longitudinal slip `s_x = (ω·r − v_x)/|v_x|` and lateral slip
//! `s_y = −v_y/|v_x|` (= −tan α). `B` is set so the slip stiffness `B·C·D` is a fixed
//! multiple of the load whatever the road friction: a tyre on ice is as stiff as on
//! asphalt, it just saturates earlier. Longitudinal and lateral curves share `C` and `E`
//! and differ in stiffness, i.e. in `B`.
//!
//! **Combined slip (Pacejka's similarity method).** The shape is evaluated once, at the
//! combined argument `z = |(B_x·s_x, B_y·s_y)|` (each slip relative to its own peak
//! slip), and the force `D·g(z)` is split in proportion to the two components. That is a
//! friction circle: a locked wheel has no cornering force left, a wheel at the cornering
//! limit none for braking.
//!
//! **Carcass dynamics (Rill, "Road Vehicle Dynamics", 2012, §3.10).** The contact patch
//! deflects by `x_e` against a carcass spring `c` and damper `d`; the force is
//! `c·x_e + d·ẋ_e`, and `ẋ_e` follows from equating it with the steady-state force
//! linearised as `f·s` (`f` = secant slip stiffness). This gives the relaxation length
//! at speed and, at standstill, a damped spring instead of a slip that divides by zero:
//! a braked car on a slope stands still, and a stopping car does not jitter. The
//! deflection update is backward Euler, so it is stable for any step.

use crate::params::{TyreParams, VehicleParams, GRAVITY};

/// The magic-formula shape `g(z) = sin(C·atan(z − E·(z − atan z)))`, peak value 1.
#[derive(Clone, Copy, Debug)]
pub(crate) struct MagicFormula {
    c: f64,
    e: f64,
}

impl MagicFormula {
    /// # Panics
    /// If `C` is outside (1, 2) (no peak, or a force that reverses) or `E >= 1`.
    pub(crate) fn new(c: f64, e: f64) -> Self {
        assert!(c > 1.0 && c < 2.0, "magic formula: C must be in (1, 2)");
        assert!(e < 1.0, "magic formula: E must be below 1");
        Self { c, e }
    }

    /// Whether this is the shape `C = 1.5, E = 0`, which has a closed form without
    /// trigonometry (see [`MagicFormula::secant_ratio_c15`]).
    fn is_c15(&self) -> bool {
        self.c == 1.5 && self.e == 0.0
    }

    /// `g(z)/(C·z)` for `C = 1.5`, `E = 0`, `z >= 0`. With θ = atan z and r = √(1 + z²):
    /// cos θ = 1/r, and the half-angle formulas give sin(3θ/2) = sin θ·cos(θ/2) +
    /// cos θ·sin(θ/2) = z·(r + 2) / (r·√(2r·(r + 1))). Two square roots instead of an
    /// arctangent and a sine, four times per step of the vehicle model (the largest
    /// single cost of a virtual-car tick), and no cancellation at small z.
    fn secant_ratio_c15(z: f64) -> f64 {
        let r = (1.0 + z * z).sqrt();
        (r + 2.0) / (1.5 * r * (2.0 * r * (r + 1.0)).sqrt())
    }

    pub(crate) fn value(&self, z: f64) -> f64 {
        if self.is_c15() {
            return 1.5 * z * Self::secant_ratio_c15(z);
        }
        let argument = if self.e == 0.0 {
            z
        } else {
            z - self.e * (z - z.atan())
        };
        (self.c * argument.atan()).sin()
    }

    /// Where `g` peaks: `z − E·(z − atan z) = tan(π/(2C))`, solved by bisection (the left
    /// side grows with `z` for `E < 1`).
    fn peak_z(&self) -> f64 {
        let argument = (core::f64::consts::FRAC_PI_2 / self.c).tan();
        let (mut lo, mut hi) = (0.0f64, 1.0f64);
        while hi - self.e * (hi - hi.atan()) < argument {
            hi *= 2.0;
        }
        for _ in 0..100 {
            let mid = 0.5 * (lo + hi);
            if mid - self.e * (mid - mid.atan()) < argument {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        0.5 * (lo + hi)
    }

    /// `g(z)/(C·z)` for `z >= 0`: the secant stiffness relative to the initial slope,
    /// 1 at `z = 0`.
    fn secant_ratio(&self, z: f64) -> f64 {
        if self.is_c15() {
            Self::secant_ratio_c15(z)
        } else if z < 1e-4 {
            // g(z) = C·z·(1 + O(z²)).
            1.0
        } else {
            self.value(z) / (self.c * z)
        }
    }
}

/// Tyre characteristics shared by the four wheels (derived once from [`TyreParams`]).
#[derive(Clone, Debug)]
pub(crate) struct TyreModel {
    shape: MagicFormula,
    longitudinal_stiffness_per_load: f64,
    nominal_load_n: f64,
    load_sensitivity: f64,
    carcass_long_stiffness: f64,
    carcass_long_damping: f64,
    carcass_lat_stiffness: f64,
    carcass_lat_damping: f64,
    slip_regularisation_speed: f64,
}

/// Contact-patch deflections of one tyre, m.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct TyreState {
    deflection_long_m: f64,
    deflection_lat_m: f64,
}

/// What one tyre update yields.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct ContactForces {
    /// In the wheel plane, N, positive forward.
    pub(crate) longitudinal_n: f64,
    /// Perpendicular to the wheel plane, N, positive to the left.
    pub(crate) lateral_n: f64,
    /// Longitudinal slip `(ω·r − v_x)/(|v_x| + v_reg)`.
    pub(crate) slip: f64,
}

/// Contact-patch kinematics of one wheel, in the wheel's own axes.
#[derive(Clone, Copy, Debug)]
pub(crate) struct ContactKinematics {
    /// Normal load, N.
    pub(crate) load_n: f64,
    /// Road friction coefficient under the wheel.
    pub(crate) mu: f64,
    /// Velocity of the wheel centre along the wheel plane, m/s.
    pub(crate) v_long: f64,
    /// Velocity of the wheel centre across the wheel plane, m/s.
    pub(crate) v_lat: f64,
    /// Circumferential speed ω·r, m/s.
    pub(crate) surface_speed: f64,
    /// Cornering stiffness per newton of load of this wheel's axle, 1/rad.
    pub(crate) cornering_stiffness_per_load: f64,
}

impl TyreModel {
    pub(crate) fn new(p: &TyreParams, nominal_load_n: f64) -> Self {
        Self {
            shape: MagicFormula::new(p.shape_c, p.curvature_e),
            longitudinal_stiffness_per_load: p.longitudinal_stiffness_per_load,
            nominal_load_n,
            load_sensitivity: p.friction_load_sensitivity,
            carcass_long_stiffness: p.longitudinal_carcass_stiffness_n_per_m,
            carcass_long_damping: p.longitudinal_carcass_damping_n_s_per_m,
            carcass_lat_stiffness: p.lateral_carcass_stiffness_n_per_m,
            carcass_lat_damping: p.lateral_carcass_damping_n_s_per_m,
            slip_regularisation_speed: p.slip_regularisation_speed_mps,
        }
    }

    /// Friction coefficient under `load_n`: drops with load, so the four tyres together
    /// never give more than μ·m·g (the nominal load is the average static wheel load).
    fn effective_mu(&self, mu: f64, load_n: f64) -> f64 {
        let relative_load = (load_n - self.nominal_load_n) / self.nominal_load_n;
        mu * (1.0 - self.load_sensitivity * relative_load).max(0.2)
    }

    /// Advances the tyre's deflections by `dt` (`inv_dt` = 1/`dt`) and returns the
    /// forces it transmits.
    pub(crate) fn update(
        &self,
        state: &mut TyreState,
        k: &ContactKinematics,
        dt: f64,
        inv_dt: f64,
    ) -> ContactForces {
        let inv_speed = 1.0 / (k.v_long.abs() + self.slip_regularisation_speed);
        let slip_long = (k.surface_speed - k.v_long) * inv_speed;
        let slip_lat = -k.v_lat * inv_speed;

        // Steady state as secant stiffnesses f = F/s. With B = k/(C·μ) the magic
        // formula's D·B·g(z)/z is Fz·k·g(z)/(C·z): μ only enters through z.
        let (secant_long, secant_lat) = if k.load_n > 0.0 {
            let stiff_long = self.longitudinal_stiffness_per_load * slip_long;
            let stiff_lat = k.cornering_stiffness_per_load * slip_lat;
            let z = (stiff_long * stiff_long + stiff_lat * stiff_lat).sqrt()
                / (self.shape.c * self.effective_mu(k.mu, k.load_n));
            let secant = k.load_n * self.shape.secant_ratio(z);
            (
                secant * self.longitudinal_stiffness_per_load,
                secant * k.cornering_stiffness_per_load,
            )
        } else {
            (0.0, 0.0)
        };

        let longitudinal_n = carcass_force(
            &mut state.deflection_long_m,
            secant_long * inv_speed,
            k.v_long - k.surface_speed,
            self.carcass_long_stiffness,
            self.carcass_long_damping,
            dt,
            inv_dt,
        );
        let lateral_n = carcass_force(
            &mut state.deflection_lat_m,
            secant_lat * inv_speed,
            k.v_lat,
            self.carcass_lat_stiffness,
            self.carcass_lat_damping,
            dt,
            inv_dt,
        );
        ContactForces {
            longitudinal_n,
            lateral_n,
            slip: slip_long,
        }
    }
}

/// One direction of Rill's first-order carcass model.
///
/// `slip_damping` is `f/(|v_x| + v_reg)` (the steady-state force is
/// `−slip_damping · sliding_speed`); the deflection obeys
/// `ẋ_e = −(slip_damping·sliding_speed + c·x_e)/(slip_damping + d)`, integrated by
/// backward Euler. Returns `c·x_e + d·ẋ_e`.
fn carcass_force(
    deflection: &mut f64,
    slip_damping: f64,
    sliding_speed: f64,
    stiffness: f64,
    damping: f64,
    dt: f64,
    inv_dt: f64,
) -> f64 {
    let total_damping = slip_damping + damping;
    let previous = *deflection;
    let mut next = (total_damping * previous - dt * slip_damping * sliding_speed)
        / (total_damping + dt * stiffness);
    // A deflection this small is zero; flushing keeps subnormals out of the arithmetic.
    if next.abs() < 1e-15 {
        next = 0.0;
    }
    *deflection = next;
    stiffness * next + damping * (next - previous) * inv_dt
}

/// Steady-state pure-slip longitudinal force per newton of load at the nominal load
/// (the average static wheel load), for road friction `mu` and slip `slip`
/// (−1 = locked wheel). For the locked-wheel stopping distance `v²/(2·μ_slide·g)`.
pub fn longitudinal_friction_coefficient(p: &TyreParams, mu: f64, slip: f64) -> f64 {
    let shape = MagicFormula::new(p.shape_c, p.curvature_e);
    let b = p.longitudinal_stiffness_per_load / (p.shape_c * mu);
    mu * shape.value(b * slip.abs()) * slip.signum()
}

/// The largest steady deceleration the four tyres can give a car braking in a straight
/// line on a road of friction `mu`, m/s²: every tyre at its friction peak under the loads
/// that this deceleration itself moves onto the front axle, with the tyres' load
/// sensitivity (a more loaded tyre has a lower friction coefficient, so the car gets less
/// than µ·g). The tyres alone: no rolling resistance, drag or grade. It bounds what any
/// ABS can reach once the brake pressure is built; `v²/(2·µ·g)` assumes µ·g.
pub fn peak_braking_deceleration(p: &VehicleParams, mu: f64) -> f64 {
    let c = &p.chassis;
    let weight = c.mass_kg * GRAVITY;
    let model = TyreModel::new(&p.tyre, weight / 4.0);
    // A fixed point: the load transfer grows with the deceleration, which falls with it
    // (by a few per cent at most), so a few dozen rounds settle it to machine precision.
    let mut decel = mu * GRAVITY;
    for _ in 0..64 {
        let transfer = c.mass_kg * decel * c.cg_height_m / c.wheelbase_m;
        let front = 0.5 * (weight * c.cg_to_rear_axle_m() / c.wheelbase_m + transfer);
        let rear = (0.5 * (weight * c.cg_to_front_axle_m() / c.wheelbase_m - transfer)).max(0.0);
        let force =
            2.0 * (model.effective_mu(mu, front) * front + model.effective_mu(mu, rear) * rear);
        decel = force / c.mass_kg;
    }
    decel
}

/// The shortest stop the car can make braking in a straight line on a road of friction
/// `mu` from `from_mps`, m, the brake pressed fully at the start: what an ABS that knew
/// every wheel's slip and the tyres' curve, and could cut the brake torque at once, would
/// do. Each wheel brakes with the torque its brake pressure has built up to (the apply
/// lag of the brake parameters); that torque first spins the wheel down against its
/// inertia, and the tyre's force grows with the slip along its steady curve until the
/// slip reaches the curve's peak, where it is then held exactly. The peak is the tyre's
/// under its present load (the braking load transfer with the body's lag, the tyres' load
/// sensitivity); rolling resistance and drag help. No carcass lag and no sensing or valve
/// delay, so no ABS can stop shorter: a measured stop's excess over this is what the
/// control costs, not the brakes, the wheels or the tyres.
pub fn shortest_braking_distance(p: &VehicleParams, mu: f64, from_mps: f64) -> f64 {
    // Fine against the 40–50 ms of the brake and load-transfer lags and the wheels'
    // spin-down (≈ 2 ms for the slip to settle at speed).
    const DT: f64 = 1e-4;
    // Ends the loop without friction, where drag alone never quite stops the car.
    const MAX_T: f64 = 600.0;
    let c = &p.chassis;
    let b = &p.brakes;
    let weight = c.mass_kg * GRAVITY;
    let model = TyreModel::new(&p.tyre, weight / 4.0);
    let radius = p.tyre.rolling_radius_m;
    let inertia = p.tyre.wheel_inertia_kgm2;
    let v_reg = p.tyre.slip_regularisation_speed_mps;
    let stiffness = p.tyre.longitudinal_stiffness_per_load;
    let peak_z = model.shape.peak_z();
    let drag_per_v2 =
        0.5 * p.aero.air_density_kg_per_m3 * p.aero.drag_coefficient * p.aero.frontal_area_m2;
    let static_front = 0.5 * weight * c.cg_to_rear_axle_m() / c.wheelbase_m;
    let static_rear = 0.5 * weight * c.cg_to_front_axle_m() / c.wheelbase_m;
    // One wheel of an axle: its spin, and whether its slip has reached the peak.
    struct Wheel {
        omega: f64,
        at_peak: bool,
        max_torque_nm: f64,
    }
    let mut wheels = [
        Wheel {
            omega: from_mps / radius,
            at_peak: false,
            max_torque_nm: b.max_torque_front_nm,
        },
        Wheel {
            omega: from_mps / radius,
            at_peak: false,
            max_torque_nm: b.max_torque_rear_nm,
        },
    ];
    let (mut v, mut x, mut t, mut transfer) = (from_mps, 0.0, 0.0, 0.0);
    while v > 0.0 && t < MAX_T {
        let built = 1.0 - (-t / b.pressure_apply_time_constant_s).exp();
        let loads = [
            static_front + 0.5 * transfer,
            (static_rear - 0.5 * transfer).max(0.0),
        ];
        let mut tyres = 0.0;
        for (wheel, load) in wheels.iter_mut().zip(loads) {
            let mu_load = model.effective_mu(mu, load);
            // Rolling resistance is a torque at the wheel in the model, growing with speed.
            let rolling = p.tyre.rolling_resistance_coefficient
                * (1.0 + v * 3.6 / p.tyre.rolling_resistance_doubling_speed_kmh)
                * load;
            let slip_at_peak = peak_z * model.shape.c * mu_load / stiffness;
            let tyre = if wheel.at_peak {
                // Held at the peak slip: the wheel turns with the car at that slip.
                wheel.omega = (v - slip_at_peak * (v + v_reg)).max(0.0) / radius;
                mu_load * load
            } else {
                let slip = ((v - wheel.omega * radius) / (v + v_reg)).max(0.0);
                let z = stiffness * slip / (model.shape.c * mu_load);
                let tyre = mu_load * load * model.shape.value(z.min(peak_z));
                // The brake (and the rolling resistance) against the tyre, on the wheel.
                let torque = built * wheel.max_torque_nm + rolling * radius;
                wheel.omega = (wheel.omega + (tyre * radius - torque) / inertia * DT).max(0.0);
                wheel.at_peak = z >= peak_z;
                tyre
            };
            tyres += 2.0 * tyre;
        }
        let decel = (tyres + drag_per_v2 * v * v) / c.mass_kg;
        // The axle load transfer follows the tyres' forces (they act at the road; drag
        // acts near the CG's height) with the body's lag.
        let steady = tyres * c.cg_height_m / c.wheelbase_m;
        transfer += (steady - transfer) * DT / (c.load_transfer_time_constant_s + DT);
        let v_next = (v - decel * DT).max(0.0);
        x += 0.5 * (v + v_next) * DT;
        v = v_next;
        t += DT;
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::VehicleParams;

    fn steady_force(model: &TyreModel, k: &ContactKinematics) -> ContactForces {
        let mut state = TyreState::default();
        let mut forces = ContactForces::default();
        for _ in 0..5000 {
            forces = model.update(&mut state, k, 1e-3, 1e3);
        }
        forces
    }

    fn kinematics(v_long: f64, v_lat: f64, surface_speed: f64) -> ContactKinematics {
        ContactKinematics {
            load_n: 4000.0,
            mu: 1.0,
            v_long,
            v_lat,
            surface_speed,
            cornering_stiffness_per_load: 14.0,
        }
    }

    #[test]
    fn peak_braking_is_below_mu_g_by_the_load_transfer() {
        let p = VehicleParams::evo_vi();
        let g = GRAVITY;
        let dry = peak_braking_deceleration(&p, 1.0);
        // Front wheels at ≈ 1.6× and rear at ≈ 0.4× the nominal load near 1 g, friction
        // 0.1 × the relative load lower (higher): ≈ 3.6 % less than µ·g on dry asphalt.
        assert!(dry > 0.95 * g && dry < 0.975 * g, "{}", dry / g);
        // The static front bias alone costs under 1 %; the transfer grows with µ.
        let ice = peak_braking_deceleration(&p, 0.2);
        assert!(ice < 0.2 * g && ice > 0.99 * 0.2 * g, "{}", ice / g);
        let losses: Vec<f64> = [0.2, 0.4, 0.6, 0.8, 1.0]
            .iter()
            .map(|&mu| 1.0 - peak_braking_deceleration(&p, mu) / (mu * g))
            .collect();
        assert!(losses.windows(2).all(|w| w[0] < w[1]), "{losses:?}");
    }

    #[test]
    fn closed_form_of_c15_is_the_trigonometric_one() {
        let shape = MagicFormula::new(1.5, 0.0);
        assert!(shape.is_c15());
        for i in 0..=4000 {
            // 0 to 400: far past the peak (z ≈ 1.73) and the locked wheel on ice.
            let z = f64::from(i) * 0.1 * (1.0 + f64::from(i) * 0.001);
            let trig = (1.5 * z.atan()).sin();
            assert!((shape.value(z) - trig).abs() < 1e-12, "g({z})");
            if z >= 1e-3 {
                let secant = trig / (1.5 * z);
                assert!(
                    (shape.secant_ratio(z) - secant).abs() < 1e-12,
                    "g({z})/(Cz)"
                );
            }
        }
        assert_eq!(shape.secant_ratio(0.0), 1.0);
    }

    #[test]
    fn shape_peaks_at_one_and_saturates() {
        let shape = MagicFormula::new(1.5, 0.0);
        // E = 0: the peak is where C·atan(z) = π/2.
        let peak_z = (core::f64::consts::FRAC_PI_2 / 1.5).tan();
        assert!((shape.value(peak_z) - 1.0).abs() < 1e-12);
        assert!(shape.value(0.9 * peak_z) < 1.0 && shape.value(1.1 * peak_z) < 1.0);
        assert!((shape.secant_ratio(1e-6) - 1.0).abs() < 1e-9);
        assert!((shape.secant_ratio(2e-4) - 1.0).abs() < 1e-6);
        // A non-zero E moves the peak but keeps its height.
        let curved = MagicFormula::new(1.5, 0.5);
        let max = (1..2000)
            .map(|i| curved.value(f64::from(i) * 0.005))
            .fold(0.0, f64::max);
        assert!((max - 1.0).abs() < 1e-6);
    }

    #[test]
    fn steady_state_matches_the_magic_formula_and_stiffness() {
        let p = VehicleParams::evo_vi().tyre;
        let model = TyreModel::new(&p, 4000.0);
        // Small slip: F = k·Fz·s.
        let f = steady_force(&model, &kinematics(20.0, 0.0, 20.0 * 1.005));
        assert!((f.longitudinal_n / (20.0 * 4000.0 * 0.005) - 1.0).abs() < 0.01);
        // Locked wheel: the sliding friction of the pure formula.
        let f = steady_force(&model, &kinematics(20.0, 0.0, 0.0));
        let mu_slide = longitudinal_friction_coefficient(&p, 1.0, -1.0);
        assert!((f.longitudinal_n / 4000.0 - mu_slide).abs() < 0.002);
        assert!((-0.85..-0.75).contains(&mu_slide), "{mu_slide}");
        // Small slip angle: F = k·Fz·tan α, opposing the lateral velocity.
        let f = steady_force(&model, &kinematics(20.0, -0.1, 20.0));
        assert!((f.lateral_n / (14.0 * 4000.0 * 0.005) - 1.0).abs() < 0.01);
    }

    #[test]
    fn combined_slip_stays_inside_the_friction_circle() {
        let p = VehicleParams::evo_vi().tyre;
        let model = TyreModel::new(&p, 4000.0);
        for (slip, angle) in [
            (0.05, 0.05),
            (0.2, 0.1),
            (-0.5, 0.3),
            (-1.0, 0.05),
            (0.1, 1.0),
        ] {
            let v = 20.0;
            let f = steady_force(
                &model,
                &kinematics(v, -v * f64::tan(angle), v * (1.0 + slip)),
            );
            let total = f.longitudinal_n.hypot(f.lateral_n);
            assert!(
                total <= 4000.0 * 1.0001,
                "slip {slip} angle {angle}: {total}"
            );
        }
    }

    #[test]
    fn carcass_holds_a_standing_tyre_like_a_spring() {
        let p = VehicleParams::evo_vi().tyre;
        let model = TyreModel::new(&p, 4000.0);
        let mut state = TyreState::default();
        // Push the contact patch 1 mm backwards relative to the locked wheel, then hold.
        let k_moving = kinematics(-0.01, 0.0, 0.0);
        for _ in 0..100 {
            model.update(&mut state, &k_moving, 1e-3, 1e3);
        }
        let k_still = kinematics(0.0, 0.0, 0.0);
        let held = model.update(&mut state, &k_still, 1e-3, 1e3).longitudinal_n;
        // ≈ c·x = 350 N (the secant damping lets the patch slide a little while pushed).
        assert!((held - 350.0).abs() < 35.0, "{held}");
        let mut later = held;
        for _ in 0..5000 {
            later = model.update(&mut state, &k_still, 1e-3, 1e3).longitudinal_n;
        }
        // The regularisation leaks the deflection only very slowly.
        assert!(later > 0.5 * held, "{later}");
    }

    #[test]
    fn shortest_stop_is_the_tyres_limit_plus_the_brake_build_up() {
        let p = VehicleParams::evo_vi();
        let v = 100.0 / 3.6;
        for mu in [0.2, 0.5, 1.0] {
            let tyres_only = v * v / (2.0 * peak_braking_deceleration(&p, mu));
            // Instant brakes and load transfer, no drag: the tyres' limit itself.
            let mut ideal = p.clone();
            ideal.brakes.pressure_apply_time_constant_s = 1e-9;
            ideal.chassis.load_transfer_time_constant_s = 1e-9;
            ideal.aero.drag_coefficient = 0.0;
            let instant = shortest_braking_distance(&ideal, mu, v);
            assert!(
                (instant / tyres_only - 1.0).abs() < 2e-3,
                "µ {mu}: {instant} vs {tyres_only}"
            );
            // The real brakes build their pressure over 40 ms: a few tenths of a metre,
            // never more than driving on for one time constant. Drag gives a little back.
            let real = shortest_braking_distance(&p, mu, v);
            let mut no_drag = p.clone();
            no_drag.aero.drag_coefficient = 0.0;
            let build_up = shortest_braking_distance(&no_drag, mu, v) - tyres_only;
            let tau = p.brakes.pressure_apply_time_constant_s;
            assert!(
                build_up > 0.0 && build_up < v * tau,
                "µ {mu}: build-up {build_up} m"
            );
            assert!(real < tyres_only + build_up, "µ {mu}: drag helps");
            // The brake first spins each wheel down to the tyre's peak slip against its
            // inertia: a light wheel gets there sooner (from 100 km/h: 0.42 m on µ 1.0,
            // 0.13 m on µ 0.2).
            let mut light = p.clone();
            light.tyre.wheel_inertia_kgm2 = 1e-3;
            let spin_down = real - shortest_braking_distance(&light, mu, v);
            assert!(
                spin_down > 0.0 && spin_down < 0.02 * real,
                "µ {mu}: spin-down {spin_down} m"
            );
        }
        // Nothing to stop ends at once; no friction to stop with ends too.
        assert_eq!(shortest_braking_distance(&p, 1.0, 0.0), 0.0);
        assert!(shortest_braking_distance(&p, 0.0, v).is_finite());
    }
}
