//! Every number of the vehicle in one place, with where it comes from.
//!
//! [`VehicleParams::evo_vi`] is the 1999–2001 Mitsubishi Lancer Evolution VI (CP9A GSR)
//! the 2011 project modelled in TORCS. Published figures are marked *published*; figures
//! no public specification gives (inertias, tyre carcass, CG height, brake torque...) are
//! marked *estimate* with the reasoning behind them. Units are SI unless the name says
//! otherwise (`_rpm`, `_deg`, `_kmh`, `_c` for °C, `_l` for litres).

/// Standard gravity, m/s².
pub const GRAVITY: f64 = 9.806_65;

/// Complete parameter set of the vehicle model.
#[derive(Clone, Debug, PartialEq)]
pub struct VehicleParams {
    /// Mass, inertia and geometry of the body.
    pub chassis: ChassisParams,
    /// Wheels and tyres.
    pub tyre: TyreParams,
    /// Friction brakes.
    pub brakes: BrakeParams,
    /// Steering gear.
    pub steering: SteeringParams,
    /// Engine and fuel system.
    pub engine: EngineParams,
    /// Clutch, gearbox, differentials.
    pub driveline: DrivelineParams,
    /// Aerodynamic drag.
    pub aero: AeroParams,
    /// Cabin thermal model and HVAC.
    pub cabin: CabinParams,
}

/// Mass, inertia and geometry of the body.
#[derive(Clone, Debug, PartialEq)]
pub struct ChassisParams {
    /// Total mass in running order, kg.
    pub mass_kg: f64,
    /// Yaw moment of inertia about the CG, kg·m².
    pub yaw_inertia_kgm2: f64,
    /// Wheelbase, m.
    pub wheelbase_m: f64,
    /// Fraction of the static weight on the front axle.
    pub front_weight_fraction: f64,
    /// Front track, m.
    pub track_front_m: f64,
    /// Rear track, m.
    pub track_rear_m: f64,
    /// CG height above the road, m.
    pub cg_height_m: f64,
    /// Share of the lateral load transfer taken by the front axle (roll-stiffness split).
    pub front_roll_stiffness_fraction: f64,
    /// Time constant with which load transfer follows the accelerations, s (stands in for
    /// the pitch and roll dynamics of the suspension, which the planar model lacks).
    pub load_transfer_time_constant_s: f64,
    /// Length of the body, m (what the world view and the path plot draw).
    pub body_length_m: f64,
    /// Width of the body without mirrors, m.
    pub body_width_m: f64,
    /// From the front axle to the front of the body, m.
    pub front_overhang_m: f64,
}

/// Wheels and tyres: a Pacejka magic formula for the steady-state forces, combined slip
/// by normalised slip, and a first-order carcass model for the force build-up.
#[derive(Clone, Debug, PartialEq)]
pub struct TyreParams {
    /// Effective rolling radius, m.
    pub rolling_radius_m: f64,
    /// Spin inertia of one wheel with tyre, brake disc, hub and half shaft, kg·m².
    pub wheel_inertia_kgm2: f64,
    /// Longitudinal slip stiffness per newton of load, N per unit slip per N.
    pub longitudinal_stiffness_per_load: f64,
    /// Cornering stiffness of a front tyre per newton of load, N/rad per N.
    pub front_cornering_stiffness_per_load: f64,
    /// Cornering stiffness of a rear tyre per newton of load, N/rad per N.
    pub rear_cornering_stiffness_per_load: f64,
    /// Magic-formula shape factor C (both directions), in (1, 2).
    pub shape_c: f64,
    /// Magic-formula curvature factor E (both directions), below 1.
    pub curvature_e: f64,
    /// Drop of the friction coefficient per unit of relative load above the nominal load
    /// (the nominal load is the static average wheel load, m·g/4).
    pub friction_load_sensitivity: f64,
    /// Longitudinal carcass stiffness, N/m.
    pub longitudinal_carcass_stiffness_n_per_m: f64,
    /// Longitudinal carcass damping, N·s/m.
    pub longitudinal_carcass_damping_n_s_per_m: f64,
    /// Lateral carcass stiffness, N/m.
    pub lateral_carcass_stiffness_n_per_m: f64,
    /// Lateral carcass damping, N·s/m.
    pub lateral_carcass_damping_n_s_per_m: f64,
    /// Small speed added to the slip denominators so that slip stays finite at standstill,
    /// m/s.
    pub slip_regularisation_speed_mps: f64,
    /// Rolling-resistance coefficient at low speed.
    pub rolling_resistance_coefficient: f64,
    /// Speed at which the rolling resistance has doubled, km/h.
    pub rolling_resistance_doubling_speed_kmh: f64,
}

/// Friction brakes.
#[derive(Clone, Debug, PartialEq)]
pub struct BrakeParams {
    /// Brake torque of one front wheel at full command, N·m.
    pub max_torque_front_nm: f64,
    /// Brake torque of one rear wheel at full command, N·m.
    pub max_torque_rear_nm: f64,
    /// Time constant of the brake pressure rising to a higher command (booster, master
    /// cylinder and the ABS inlet valves feeding the calipers), s.
    pub pressure_apply_time_constant_s: f64,
    /// Time constant of the brake pressure falling to a lower command (ABS outlet valves
    /// dumping into the low-pressure accumulator, or the pedal released), s.
    pub pressure_release_time_constant_s: f64,
}

/// Steering gear.
#[derive(Clone, Debug, PartialEq)]
pub struct SteeringParams {
    /// Steering-wheel angle per road-wheel angle.
    pub ratio: f64,
    /// Steering-wheel angle at the rack's end stop, degrees.
    pub max_steering_wheel_deg: f64,
}

/// Engine and fuel system.
#[derive(Clone, Debug, PartialEq)]
pub struct EngineParams {
    /// Full-load brake torque at 0, 500, 1000, ... 8000 rpm, N·m.
    pub full_load_torque_nm: [f64; 17],
    /// Spacing of the full-load table, rpm.
    pub torque_table_step_rpm: f64,
    /// Friction and pumping torque at zero speed, N·m.
    pub friction_torque_nm: f64,
    /// Friction and pumping torque per rad/s of engine speed, N·m·s.
    pub friction_torque_per_rad_s: f64,
    /// Inertia of crankshaft, flywheel and clutch, kg·m².
    pub inertia_kgm2: f64,
    /// Idle speed the idle controller holds, rpm.
    pub idle_rpm: f64,
    /// Idle controller gain, N·m per rad/s of speed error.
    pub idle_gain_nm_per_rad_s: f64,
    /// Most torque the idle controller may ask for, N·m.
    pub idle_max_torque_nm: f64,
    /// Rev limiter: fuel is cut progressively over the last 100 rpm below this, rpm.
    pub rev_limit_rpm: f64,
    /// Time constant of the torque response to the pedal (turbo and manifold fill), s.
    pub torque_response_time_constant_s: f64,
    /// Indicated specific fuel consumption, g/kWh of combustion (indicated) work.
    pub indicated_sfc_g_per_kwh: f64,
    /// Fuel density, kg/L.
    pub fuel_density_kg_per_l: f64,
    /// Fuel tank capacity, L.
    pub tank_capacity_l: f64,
}

/// Clutch, gearbox and differentials.
#[derive(Clone, Debug, PartialEq)]
pub struct DrivelineParams {
    /// Ratios of 1st to 6th gear.
    pub gear_ratios: [f64; 6],
    /// Reverse ratio (positive number; the direction is applied by the model).
    pub reverse_ratio: f64,
    /// Final drive ratio, front and rear.
    pub final_drive_ratio: f64,
    /// Efficiency of gearbox, transfer, differentials and shafts.
    pub efficiency: f64,
    /// Time the gearbox spends in neutral during a shift (torque interrupt), s.
    pub shift_time_s: f64,
    /// Clutch torque capacity when fully engaged, N·m.
    pub clutch_max_torque_nm: f64,
    /// Time to close the clutch from open to fully engaged after a shift, s.
    pub clutch_engage_time_s: f64,
    /// Launch: engine speed at which the clutch starts to bite, rpm.
    pub launch_bite_rpm: f64,
    /// Launch: engine speed at which the clutch transmits its full capacity, rpm.
    pub launch_full_rpm: f64,
    /// Input-shaft speed above which the clutch closes fully, rpm.
    pub clutch_lock_rpm: f64,
    /// Input-shaft speed below which the clutch returns to the launch regime
    /// (anti-stall), rpm.
    pub clutch_release_rpm: f64,
    /// A launch ends when engine and input-shaft speed are this close, rpm.
    pub clutch_lock_slip_rpm: f64,
    /// A gear engages only if the engine speed it implies stays below this, rpm.
    pub max_engage_rpm: f64,
    /// A gear engages only if the car rolls against the gear's direction slower than
    /// this, m/s.
    pub max_reversal_speed_mps: f64,
    /// Centre viscous coupling: torque between the axles per rad/s of axle speed
    /// difference, N·m·s.
    pub centre_viscous_nm_per_rad_s: f64,
    /// Active Yaw Control: wheel torque moved from the left to the right rear wheel per
    /// N·m of torque-split command.
    pub ayc_wheel_torque_per_command: f64,
    /// Largest torque-split command the AYC accepts, N·m (the catalogue's range).
    pub ayc_max_command_nm: f64,
    /// Time constant of the AYC hydraulics, s.
    pub ayc_time_constant_s: f64,
    /// Below this speed the AYC's effect fades out linearly to nothing at rest, m/s (its
    /// transfer clutches need the rear wheels turning).
    pub ayc_full_effect_speed_mps: f64,
    /// Hard braking: when a wheel's brake command (0..1) reaches this, the automated clutch
    /// opens (the engine is declutched) until the brakes are released.
    pub declutch_brake_command: f64,
    /// The clutch closes again once every brake command has stayed below
    /// [`DrivelineParams::declutch_release_command`] for this long, s (or at once when the
    /// accelerator is pressed past it with the brakes released).
    pub declutch_hold_s: f64,
    /// Brake (and accelerator) command (0..1) below which the pedal counts as released for
    /// the declutch.
    pub declutch_release_command: f64,
}

/// Aerodynamic drag.
#[derive(Clone, Debug, PartialEq)]
pub struct AeroParams {
    /// Drag coefficient.
    pub drag_coefficient: f64,
    /// Frontal area, m².
    pub frontal_area_m2: f64,
    /// Air density, kg/m³.
    pub air_density_kg_per_m3: f64,
}

/// Cabin thermal model and HVAC.
#[derive(Clone, Debug, PartialEq)]
pub struct CabinParams {
    /// Heat capacity of cabin air and interior trim, J/K.
    pub heat_capacity_j_per_k: f64,
    /// Heat conductance from cabin to ambient through the body and glass, W/K.
    pub ambient_conductance_w_per_k: f64,
    /// Heat conductance of the HVAC air stream at full fan power, W/K.
    pub hvac_conductance_w_per_k: f64,
    /// Temperature of the conditioned air leaving the vents, °C.
    pub hvac_outlet_temp_c: f64,
    /// Standard deviation of the cabin temperature sensor's noise, K.
    pub sensor_noise_std_k: f64,
}

impl VehicleParams {
    /// The 1999–2001 Mitsubishi Lancer Evolution VI GSR (CP9A) with a driver.
    pub fn evo_vi() -> Self {
        Self {
            chassis: ChassisParams {
                // Published GSR kerb weight 1360 kg (with fuel) + 75 kg driver.
                mass_kg: 1435.0,
                // Estimate: I_z ≈ m·a·b (a, b = CG to axles) is the usual rule for saloons:
                // 1435 · 1.004 · 1.506 ≈ 2170; rounded up for the long front overhang.
                yaw_inertia_kgm2: 2200.0,
                // Published: 2510 mm.
                wheelbase_m: 2.51,
                // Estimate: front-engined AWD saloon, about 60:40 as road tests weigh it.
                front_weight_fraction: 0.60,
                // Published: 1510 mm front, 1505 mm rear.
                track_front_m: 1.51,
                track_rear_m: 1.505,
                // Estimate: typical of a 1.4 m tall saloon (about 37 % of its height).
                cg_height_m: 0.52,
                // Estimate: front-heavy car with a stiff front anti-roll bar.
                front_roll_stiffness_fraction: 0.60,
                // Estimate: a damped 1.5–2 Hz pitch/roll mode settles in about this time.
                load_transfer_time_constant_s: 0.05,
                // Published: 4350 mm long, 1770 mm wide.
                body_length_m: 4.35,
                body_width_m: 1.77,
                // Estimate: of the 1.84 m of overhangs, the longer at the front (engine
                // ahead of the axle, intercooler in the bumper).
                front_overhang_m: 1.0,
            },
            tyre: TyreParams {
                // 225/45 ZR17 (published): unloaded radius 0.2159 + 0.225·0.45 = 0.317 m;
                // the effective rolling radius is about 2 % smaller.
                rolling_radius_m: 0.31,
                // Estimate: tyre ≈ 10 kg at 0.29 m, 17" alloy ≈ 9 kg at 0.19 m, disc, hub
                // and half shaft: ≈ 1.2 kg·m².
                wheel_inertia_kgm2: 1.2,
                // Estimate: passenger tyres have a slip stiffness of 15–25 × Fz.
                longitudinal_stiffness_per_load: 20.0,
                // Estimate: cornering coefficient of a performance tyre ≈ 0.25/deg
                // = 14/rad. The rear value is the effective axle stiffness including
                // compliance and roll steer; together they give an understeer gradient
                // (1/14 − 1/19)/g ≈ 1.1 deg/g, typical of a sporty AWD saloon.
                front_cornering_stiffness_per_load: 14.0,
                rear_cornering_stiffness_per_load: 19.0,
                // One shape for both directions (Pacejka's similarity method). With the
                // stiffnesses above, on μ = 1: longitudinal peak at 13 % slip, locked-wheel
                // friction 0.78 of the peak (dry asphalt: 0.75–0.85); lateral peak at
                // 10.5° front, 7.8° rear. C = 1.5 lies within Pacejka's typical 1.3
                // (lateral) to 1.65 (longitudinal), Tyre and Vehicle Dynamics, ch. 4.
                // E = 0 also saves an arctangent per wheel and step.
                shape_c: 1.5,
                curvature_e: 0.0,
                // Estimate: friction drops ~10 % per doubling of load (typical).
                friction_load_sensitivity: 0.10,
                // Estimate: relaxation length σ = slip stiffness / carcass stiffness;
                // measured σ ≈ 0.2 m longitudinal and 0.4 m lateral for car tyres.
                longitudinal_carcass_stiffness_n_per_m: 350_000.0,
                longitudinal_carcass_damping_n_s_per_m: 2_500.0,
                lateral_carcass_stiffness_n_per_m: 150_000.0,
                lateral_carcass_damping_n_s_per_m: 1_500.0,
                // Small against any speed that matters; keeps slips finite at rest. A
                // braked tyre at rest creeps at F·v_reg/(slip stiffness): ≈ 0.01 mm/s
                // on a 15 % slope.
                slip_regularisation_speed_mps: 0.001,
                // Wong, Theory of Ground Vehicles: f = 0.01·(1 + v/160 km/h) on asphalt;
                // 0.011 for the wide low-profile tyre.
                rolling_resistance_coefficient: 0.011,
                rolling_resistance_doubling_speed_kmh: 160.0,
            },
            brakes: BrakeParams {
                // Estimate from the Brembo 4-pot front / 2-pot rear calipers: ≈ 100 bar
                // on 2.8e-3 m² per side, pad μ 0.42, effective radius 0.135 m ≈ 3 kN·m.
                // Either axle locks on μ = 1 (front needs ≈ 2 kN·m at 1 g); front bias 68 %.
                max_torque_front_nm: 3000.0,
                max_torque_rear_nm: 1400.0,
                // Estimate: the pressure follows the command like a first-order lag. It
                // builds through the booster, master cylinder and the ABS inlet valves
                // (gradients of the order of 1000–1500 bar/s at the wheel: 40 ms) and
                // falls faster through the outlet valves into the ABS's low-pressure
                // accumulator (20 ms). A full-pedal step reaches lock pressure on dry
                // asphalt in ≈ 40 ms instead of at once; ABS simulation studies use
                // actuator lags of 10–50 ms, the ABS ECU's own test plant 20 ms.
                pressure_apply_time_constant_s: 0.04,
                pressure_release_time_constant_s: 0.02,
            },
            steering: SteeringParams {
                // Estimate: quick rack, ≈ 2.2 turns lock to lock over ±28° road wheel.
                ratio: 14.0,
                max_steering_wheel_deg: 396.0,
            },
            engine: EngineParams {
                // 4G63T: published 373 N·m at 3000 rpm and 206 kW (280 PS) at 6500 rpm
                // (303 N·m). The shape between follows typical 4G63T dyno curves.
                full_load_torque_nm: [
                    100.0, // 0 rpm (only reached when the engine is stopped)
                    130.0, // 500
                    170.0, // 1000
                    205.0, // 1500
                    265.0, // 2000
                    335.0, // 2500
                    373.0, // 3000: peak torque
                    373.0, // 3500
                    368.0, // 4000
                    360.0, // 4500
                    350.0, // 5000
                    336.0, // 5500
                    320.0, // 6000
                    303.0, // 6500: peak power 206 kW
                    275.0, // 7000
                    240.0, // 7500
                    200.0, // 8000
                ],
                torque_table_step_rpm: 500.0,
                // Estimate: friction mean effective pressure of a 2.0 L engine ≈ 1 bar at
                // idle, ≈ 2.7 bar at 7000 rpm: T = 15 + 0.04·ω N·m.
                friction_torque_nm: 15.0,
                friction_torque_per_rad_s: 0.04,
                // Estimate: crankshaft, dual-mass-free flywheel and clutch of a 2.0 L.
                inertia_kgm2: 0.20,
                // Published 4G63 idle speed: 850 rpm.
                idle_rpm: 850.0,
                // Settles an idle disturbance in ≈ 0.1 s (inertia / gain).
                idle_gain_nm_per_rad_s: 2.0,
                idle_max_torque_nm: 80.0,
                // Published red line 7000 rpm; fuel cut a little above it.
                rev_limit_rpm: 7500.0,
                // Estimate: turbo spool and manifold fill.
                torque_response_time_constant_s: 0.10,
                // Estimate: ≈ 270 g/kWh indicated, which with friction gives the 290–330
                // g/kWh brake figures of turbo petrol engines at full load.
                indicated_sfc_g_per_kwh: 270.0,
                // Premium petrol, EN 228.
                fuel_density_kg_per_l: 0.745,
                // Published EVO VI tank: 48 L.
                tank_capacity_l: 48.0,
            },
            driveline: DrivelineParams {
                // The EVO VI has a 5-speed box; the 2011 report's figures show six gears,
                // so the ratios are those published for the later 6-speed EVO (W6MGA).
                gear_ratios: [2.909, 1.944, 1.434, 1.100, 0.868, 0.693],
                // Estimate for the 6-speed's reverse.
                reverse_ratio: 3.3,
                // Published EVO VI GSR final drive: 4.529.
                final_drive_ratio: 4.529,
                // Estimate: manual AWD drivelines lose 12–18 %.
                efficiency: 0.85,
                // Short automated shift; the torque is interrupted this long.
                shift_time_s: 0.15,
                // Estimate: ≈ 1.5 × peak engine torque, the usual clutch design margin.
                clutch_max_torque_nm: 550.0,
                clutch_engage_time_s: 0.2,
                // Launch: the clutch bites above idle so a car in gear never creeps, and
                // at full throttle balances the engine at ≈ 4200 rpm.
                launch_bite_rpm: 1200.0,
                launch_full_rpm: 5000.0,
                clutch_lock_rpm: 1100.0,
                clutch_release_rpm: 1000.0,
                clutch_lock_slip_rpm: 200.0,
                // The catalogue's EngineMsg spans 0..9000 rpm.
                max_engage_rpm: 9000.0,
                // ≈ 5 km/h: a box does not change direction at speed.
                max_reversal_speed_mps: 1.5,
                // Estimate: EVO VI centre differential is open 50:50 with a viscous
                // coupling; ≈ 45 N·m at the propeller shaft per 100 rpm of slip.
                centre_viscous_nm_per_rad_s: 200.0,
                // Estimate (no published transfer figure was found for the EVO IV–VII
                // AYC; Mitsubishi states that the Super AYC of the EVO VIII doubled it:
                // Ushiroda, Sawase et al., "Development of Super AYC", Mitsubishi Motors
                // Technical Review 15, 2003). The catalogue's ±50 N·m is read as the
                // command to the AYC's transfer clutches, multiplied by its speed-
                // increasing gear set. The clutches are sized for the rear tyres' grip: a
                // rear wheel carries about μ·Fz·r ≈ 1.0 · 2.8 kN · 0.31 m ≈ 870 N·m, less
                // the part its side force uses in a corner. Full command moving ±600 N·m
                // from one rear wheel to the other (1.2 kN·m between them) uses most of
                // that grip and gives a yaw moment of ≈ ±2.9 kN·m (the front tyres' side
                // force gives ≈ 7.5 kN·m about the centre of gravity at the limit): enough
                // to damp the yaw overshoot of a limit step steer or catch a lift-off
                // oversteer, as the AYC is credited with, not enough to spin the car by
                // itself (held on a straight road at 100 km/h it would curve it at
                // ≈ 0.15 rad/s). The former ±300 N·m (≈ ±1.5 kN·m) hardly changed a limit
                // manoeuvre.
                ayc_wheel_torque_per_command: 12.0,
                ayc_max_command_nm: 50.0,
                ayc_time_constant_s: 0.05,
                ayc_full_effect_speed_mps: 2.0,
                // The automated clutch stands in for the driver's left foot: in an
                // emergency stop a driver declutches, and automated manual gearboxes open
                // the clutch under hard braking, so that engine drag (≈ 50–175 N·m per
                // wheel on the overrun in 4th to 1st gear) and the clutch closing after
                // each downshift do not brake the wheels behind the ABS's back: on μ = 0.2
                // a wheel carries only 150–300 N·m. Half of full brake is hard braking
                // (≈ 1 g with all four brakes at it); the hold bridges the ABS releasing
                // all wheels at once.
                declutch_brake_command: 0.5,
                declutch_hold_s: 0.5,
                declutch_release_command: 0.02,
            },
            aero: AeroParams {
                // Estimate: boxy rally saloon with intercooler opening and wing.
                drag_coefficient: 0.36,
                // 0.82 × width 1.77 m × height 1.405 m (published dimensions).
                frontal_area_m2: 2.04,
                // ISA sea level.
                air_density_kg_per_m3: 1.225,
            },
            cabin: CabinParams {
                // Estimate: ≈ 3 m³ of air (3.6 kJ/K) plus the trim that follows it.
                heat_capacity_j_per_k: 40_000.0,
                // Estimate: body and glass of a small saloon; time constant ≈ 17 min.
                ambient_conductance_w_per_k: 40.0,
                // ≈ 0.12 kg/s of air at full blower, c_p = 1005 J/(kg·K).
                hvac_conductance_w_per_k: 120.0,
                // A/C evaporator outlet.
                hvac_outlet_temp_c: 8.0,
                // Estimate: thermistor and 8-bit ADC noise.
                sensor_noise_std_k: 0.2,
            },
        }
    }
}

impl ChassisParams {
    /// Distance from the CG to the front axle, m.
    pub fn cg_to_front_axle_m(&self) -> f64 {
        self.wheelbase_m * (1.0 - self.front_weight_fraction)
    }

    /// Distance from the CG to the rear axle, m.
    pub fn cg_to_rear_axle_m(&self) -> f64 {
        self.wheelbase_m * self.front_weight_fraction
    }

    /// Each wheel's contact point relative to the CG in the body frame (x forward, y
    /// left), m, FL FR RL RR.
    pub fn wheel_offsets(&self) -> [(f64, f64); 4] {
        let (a, b) = (self.cg_to_front_axle_m(), self.cg_to_rear_axle_m());
        let (front, rear) = (0.5 * self.track_front_m, 0.5 * self.track_rear_m);
        [(a, front), (a, -front), (-b, rear), (-b, -rear)]
    }
}

impl TyreParams {
    /// Understeer gradient of the linear single-track model, rad per m/s² of lateral
    /// acceleration.
    ///
    /// With cornering stiffness proportional to the axle load, `m/L·(b/C_f − a/C_r)`
    /// reduces to `(1/k_f − 1/k_r)/g`.
    pub fn understeer_gradient_rad_per_mps2(&self) -> f64 {
        (1.0 / self.front_cornering_stiffness_per_load
            - 1.0 / self.rear_cornering_stiffness_per_load)
            / GRAVITY
    }
}

impl DrivelineParams {
    /// Overall ratio from the engine to the wheels for a forward gear `1..=6`.
    pub fn overall_ratio(&self, forward_gear: u8) -> f64 {
        let index = usize::from(forward_gear.clamp(1, 6) - 1);
        self.gear_ratios[index] * self.final_drive_ratio
    }
}
