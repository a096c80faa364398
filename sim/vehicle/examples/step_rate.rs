//! Step-rate benchmark: 600 simulated seconds of hard driving at the nominal 1 ms step.
//!
//! ```sh
//! cargo run --release -p autoplug-vehicle --example step_rate
//! ```
//!
//! The driver repeats a 30 s lap: full-throttle acceleration through the gears with a
//! slalom on the steering wheel, then a hard stop with the wheels on the edge of locking
//! while still steering, then a short standstill.

use std::hint::black_box;
use std::time::Instant;

use autoplug_vehicle::{Actuators, Environment, Gear, InitialState, Vehicle, VehicleParams};

const DT: f64 = 1e-3;
const SIMULATED_S: f64 = 600.0;
const LAP_S: f64 = 30.0;

fn main() {
    let mut car = Vehicle::new(
        VehicleParams::evo_vi(),
        Environment {
            ambient_c: 30.0,
            sun_load_w: 600.0,
            ..Environment::default()
        },
        InitialState::default(),
        1,
    );
    let steps = (SIMULATED_S / DT) as u64;
    let mut gear = 1u8;
    let mut max_speed_kmh: f64 = 0.0;

    let start = Instant::now();
    for _ in 0..steps {
        let s = car.state();
        let lap_t = s.t_s % LAP_S;
        let act = if lap_t < 18.0 {
            // Accelerate, upshifting at 7000 rpm, slaloming ±60°.
            if s.engine_rpm > 7000.0 && gear < 6 && s.clutch_engagement >= 1.0 {
                gear += 1;
            }
            Actuators {
                accelerator: 1.0,
                steering_wheel_deg: 60.0 * (lap_t * 1.5).sin(),
                gear: Gear::Forward(gear),
                fan: 0.6,
                headlights: true,
                ..Actuators::default()
            }
        } else if lap_t < 26.0 {
            // Brake hard and keep steering.
            gear = 1;
            Actuators {
                brake: [0.9, 0.9, 0.8, 0.8],
                steering_wheel_deg: 30.0 * (lap_t * 2.0).sin(),
                gear: Gear::Neutral,
                fan: 0.6,
                headlights: true,
                brake_lights: true,
                ..Actuators::default()
            }
        } else {
            // Stand, then select 1st for the next lap.
            Actuators {
                brake: [0.3; 4],
                gear: Gear::Forward(1),
                fan: 0.6,
                headlights: true,
                brake_lights: true,
                ..Actuators::default()
            }
        };
        car.step(black_box(&act), DT);
        max_speed_kmh = max_speed_kmh.max(car.state().speed_mps * 3.6);
    }
    let elapsed = start.elapsed().as_secs_f64();
    black_box(car.state());

    let steps_per_s = steps as f64 / elapsed;
    println!(
        "{steps} steps of {} ms ({SIMULATED_S} s simulated) in {elapsed:.3} s wall",
        DT * 1e3
    );
    println!(
        "{steps_per_s:.0} steps/s, {:.0} ns/step, {:.0}x real time",
        1e9 / steps_per_s,
        SIMULATED_S / elapsed
    );
    println!(
        "max speed {max_speed_kmh:.0} km/h, distance {:.1} km, fuel used {:.2} L",
        car.state().distance_m / 1e3,
        car.state().fuel_used_l
    );
}
