//! The car on a road: the path-following driver keeps it between the edges,
//! and the surface under each tyre comes from where the tyre is.

use autoplug_host_tests::scenario;
use autoplug_virtual_car::car::VirtualCar;

/// Asserts every wheel of `car` is on its road; the farthest wheel from the centreline, m.
fn every_wheel_on_the_road(car: &VirtualCar) -> f64 {
    let mut widest = 0.0f64;
    for (i, wheel) in car
        .track()
        .expect("on its road")
        .wheels()
        .iter()
        .enumerate()
    {
        widest = widest.max(wheel.location.lateral_m.abs());
        assert!(
            wheel.on_road,
            "t = {:.2} s: wheel {i} off the road at station {:.1} m, {:.2} m from the centreline",
            car.time_us() as f64 * 1e-6,
            wheel.location.station_m,
            wheel.location.lateral_m
        );
    }
    widest
}

#[test]
fn the_path_following_driver_laps_the_handling_circuit_within_its_edges() {
    let s = scenario("circuit-lap");
    let track = s.track.clone().expect("the scenario names a track");
    let half_width = track.road.width_m() / 2.0;
    let mut car = VirtualCar::new(&s);
    let mut widest = 0.0f64;
    let mut fastest = 0.0f64;
    let mut slowest_in_sweeper = f64::INFINITY;
    let mut slowest_in_hairpin = f64::INFINITY;
    let mut fastest_in_hairpin = 0.0f64;
    let mut on_pad = 0;
    let mut on_hill = 0;
    while !car.finished() {
        car.tick();
        widest = widest.max(every_wheel_on_the_road(&car));
        let on = car.track().expect("on its track");
        let env = car.wheel_environment();
        if env.mu[1] < 0.5 {
            on_pad += 1;
            // The pad is on the right half: the left wheels stay on asphalt.
            assert_eq!(env.mu[0], 1.0);
        }
        if env.grade_percent.iter().all(|g| *g > 5.0) {
            on_hill += 1;
        }
        let v = car.vehicle().speed_kmh();
        fastest = fastest.max(f64::from(v));
        let station = on.rear_axle_station();
        // The sweeper's arc (R 250 m) lies between 1,060 and 1,785 m: taken at the
        // target speed.
        if (1080.0..1760.0).contains(&station) {
            slowest_in_sweeper = slowest_in_sweeper.min(f64::from(v));
        }
        // The hairpin's arc (R 60 m) lies between 3,033 and 3,182 m.
        if (3050.0..3165.0).contains(&station) {
            slowest_in_hairpin = slowest_in_hairpin.min(f64::from(v));
            fastest_in_hairpin = fastest_in_hairpin.max(f64::from(v));
        }
    }
    let distance = car.vehicle().distance_m;
    println!(
        "circuit: {distance:.0} m in {:.0} s, top {fastest:.1} km/h, sweeper from {slowest_in_sweeper:.1} km/h, hairpin {slowest_in_hairpin:.1}..{fastest_in_hairpin:.1} km/h, widest wheel {widest:.2} m of {half_width} m, {on_pad} ms on the pad, {on_hill} ms uphill",
        s.duration_s
    );
    assert!(distance > track.road.length_m(), "{distance} m");
    assert!(fastest > 95.0 && fastest < 105.0, "top speed {fastest}");
    // √(4 m/s² · 250 m) = 114 km/h allowed in the sweeper: the target holds.
    assert!(slowest_in_sweeper > 95.0, "sweeper {slowest_in_sweeper}");
    // √(4 m/s² · 60 m) = 55.8 km/h in the hairpin.
    assert!(fastest_in_hairpin < 60.0, "hairpin {fastest_in_hairpin}");
    assert!(slowest_in_hairpin > 45.0, "hairpin {slowest_in_hairpin}");
    assert!(
        on_pad > 500 && on_hill > 1000,
        "pad {on_pad} ms, hill {on_hill} ms"
    );
}

#[test]
fn the_drive_cycle_stays_on_its_country_road() {
    // Its pedals are scripted (up to 127 km/h through the 400 m bend); the driver steers.
    let s = scenario("drive-cycle");
    let mut car = VirtualCar::new(&s);
    let mut widest = 0.0f64;
    while !car.finished() {
        car.tick();
        widest = widest.max(every_wheel_on_the_road(&car));
    }
    println!("drive cycle: widest wheel {widest:.2} m from the centreline");
    assert!(car.vehicle().distance_m > 3000.0);
}

#[test]
fn the_simulator_steers_a_persons_car_along_the_road_through_the_sweeper() {
    use autoplug_virtual_car::driver::HeldControls;
    // The dashboard's car: a person on the pedals at 95 km/h, the simulator steering.
    let s = scenario("dashboard");
    let mut car = VirtualCar::new(&s);
    let mut held = HeldControls {
        accelerator: 0.0,
        brake: 0.0,
        // Held hard left: ignored while the simulator steers.
        steering_deg: 90.0,
        headlights: false,
        economy_mode: false,
        manual_mode: false,
        set_temp_f: 72.0,
    };
    car.take_wheel().hold(held).unwrap();
    car.set_steering_along_road(true).unwrap();
    assert!(car.steers_along_road());
    let mut widest = 0.0f64;
    let mut tick = 0u64;
    // Past the sweeper (1,000 to 1,845 m) to the back straight.
    while car.track().unwrap().rear_axle_station() < 2000.0 {
        assert!(
            tick < 150_000,
            "the car should reach the back straight within 150 s"
        );
        if tick % 100 == 0 {
            let v = f64::from(car.vehicle().speed_kmh());
            held.accelerator = ((95.0 - v) * 10.0).clamp(0.0, 100.0);
            car.take_wheel().hold(held).unwrap();
        }
        car.tick();
        tick += 1;
        widest = widest.max(every_wheel_on_the_road(&car));
    }
    let heading = car.vehicle().heading_rad.to_degrees();
    println!(
        "the person at 95 km/h, the simulator steering: back straight after {:.1} s, widest wheel {widest:.2} m, heading {heading:.1}°",
        tick as f64 * 1e-3
    );
    assert!((heading - 180.0).abs() < 5.0, "heading {heading}");
    assert!(f64::from(car.vehicle().speed_kmh()) > 90.0);

    // Turned off, the person's wheel (held left) steers again.
    car.set_steering_along_road(false).unwrap();
    for _ in 0..500 {
        car.tick();
    }
    assert_eq!(car.controls().held.steering_deg, 90.0);

    // On the endless plane there is no road to steer along.
    let plane = autoplug_virtual_car::scenario::Scenario::parse(
        "name = \"plane\"\nduration_s = 10\n",
        "plane",
    )
    .unwrap();
    let mut on_plane = VirtualCar::new(&plane);
    let refused = on_plane.set_steering_along_road(true).unwrap_err();
    assert!(refused.contains("no road"), "{refused}");
    assert!(!on_plane.steers_along_road());
}
