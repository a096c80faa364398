//! The car on a road (issue 32): the path-following driver keeps it between the edges,
//! and the surface under each tyre comes from where the tyre is.

use autoplug_host_tests::scenario;
use autoplug_virtual_car::car::VirtualCar;

#[test]
fn the_path_following_driver_laps_the_handling_circuit_within_its_edges() {
    let s = scenario("circuit-lap");
    let track = s.track.clone().expect("the scenario names a track");
    let half_width = track.road.width_m() / 2.0;
    let mut car = VirtualCar::new(&s);
    let mut widest = 0.0f64;
    let mut fastest = 0.0f64;
    let mut slowest_in_hairpin = f64::INFINITY;
    let mut fastest_in_hairpin = 0.0f64;
    let mut on_pad = 0;
    let mut on_hill = 0;
    while !car.finished() {
        car.tick();
        let on = car.track().expect("on its track");
        for (i, wheel) in on.wheels().iter().enumerate() {
            widest = widest.max(wheel.location.lateral_m.abs());
            assert!(
                wheel.on_road,
                "t = {:.2} s: wheel {i} off the road at station {:.1} m, {:.2} m from the centreline",
                car.time_us() as f64 * 1e-6,
                wheel.location.station_m,
                wheel.location.lateral_m
            );
        }
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
        // The first hairpin's arc (R 60 m) lies between 640 and 788 m.
        if (660.0..770.0).contains(&station) {
            slowest_in_hairpin = slowest_in_hairpin.min(f64::from(v));
            fastest_in_hairpin = fastest_in_hairpin.max(f64::from(v));
        }
    }
    let distance = car.vehicle().distance_m;
    println!(
        "circuit: {distance:.0} m in {:.0} s, top {fastest:.1} km/h, hairpin {slowest_in_hairpin:.1}..{fastest_in_hairpin:.1} km/h, widest wheel {widest:.2} m of {half_width} m, {on_pad} ms on the pad, {on_hill} ms uphill",
        s.duration_s
    );
    assert!(distance > 1.3 * track.road.length_m(), "{distance} m");
    assert!(fastest > 95.0 && fastest < 105.0, "top speed {fastest}");
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
                "t = {:.2} s: wheel {i} off the road at station {:.1} m",
                car.time_us() as f64 * 1e-6,
                wheel.location.station_m
            );
        }
    }
    println!("drive cycle: widest wheel {widest:.2} m from the centreline");
    assert!(car.vehicle().distance_m > 3000.0);
}
