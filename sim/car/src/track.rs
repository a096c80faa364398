//! The car on its track: the surface under each tyre, found every tick from where the
//! tyre is, and where on the track the car is (for the driver that follows it).

use std::sync::Arc;

use autoplug_road::file::NamedRoad;
use autoplug_road::{Pose, Road, Surface};
use autoplug_vehicle::{Environment, Vehicle};

/// A car's track and what it knows of the car's place on it.
#[derive(Clone, Debug)]
pub struct OnTrack {
    track: Arc<NamedRoad>,
    /// Each wheel's surface at the last tick (its station warm-starts the next search).
    wheels: [Surface; 4],
    /// The rear axle's station at the last tick.
    rear_axle_station: f64,
    /// How far along the road each wheel, then the rear axle, moved in the last tick, m:
    /// the next search starts where that motion would take it, so that one Newton step
    /// usually settles it.
    moved: [f64; 5],
}

impl OnTrack {
    /// `track` with the car (`vehicle`) placed on it.
    pub fn new(track: Arc<NamedRoad>, vehicle: &Vehicle) -> Self {
        let road = &track.road;
        let wheels = vehicle
            .wheel_positions()
            .map(|(x, y)| road.surface(x, y, None));
        let rear = rear_axle(vehicle);
        let rear_axle_station = road.locate(rear.x_m, rear.y_m, None).station_m;
        Self {
            track,
            wheels,
            rear_axle_station,
            moved: [0.0; 5],
        }
    }

    /// The road.
    pub fn road(&self) -> &Road {
        &self.track.road
    }

    /// The track as read, with its name.
    pub fn track(&self) -> &Arc<NamedRoad> {
        &self.track
    }

    /// The surface under each wheel at the last [`OnTrack::update`], FL FR RL RR.
    pub fn wheels(&self) -> &[Surface; 4] {
        &self.wheels
    }

    /// The rear axle's station at the last update, m.
    pub fn rear_axle_station(&self) -> f64 {
        self.rear_axle_station
    }

    /// Finds the surface under each of `vehicle`'s wheels and returns the environment it
    /// makes of `base` (its weather, and the friction of the asphalt's left and right
    /// halves, `base.mu[0]` and `base.mu[1]`): per wheel, the patch's or the verge's
    /// friction, else its half's asphalt; the grade along the car.
    pub fn update(&mut self, vehicle: &Vehicle, base: &Environment) -> Environment {
        let road = &self.track.road;
        let heading = vehicle.state().heading_rad;
        let mut env = *base;
        for (i, (x, y)) in vehicle.wheel_positions().into_iter().enumerate() {
            let was = self.wheels[i].location.station_m;
            let surface = road.surface(x, y, Some(was + self.moved[i]));
            self.moved[i] = moved_along(road, was, surface.location.station_m);
            env.mu[i] = match (surface.on_road, surface.patch) {
                (true, None) if surface.location.lateral_m >= 0.0 => base.mu[0],
                (true, None) => base.mu[1],
                _ => surface.mu,
            };
            env.grade_percent[i] = surface.grade_along(heading);
            self.wheels[i] = surface;
        }
        let rear = rear_axle(vehicle);
        let was = self.rear_axle_station;
        self.rear_axle_station = road
            .locate(rear.x_m, rear.y_m, Some(was + self.moved[4]))
            .station_m;
        self.moved[4] = moved_along(road, was, self.rear_axle_station);
        env
    }
}

/// How far a point moved along `road` from station `from_m` to `to_m`, m (the short way
/// round a closed road's start).
fn moved_along(road: &Road, from_m: f64, to_m: f64) -> f64 {
    let moved = to_m - from_m;
    if road.is_closed() {
        let lap = road.length_m();
        moved - (moved / lap).round() * lap
    } else {
        moved
    }
}

/// The middle of the rear axle, with the car's heading: the point pure pursuit steers.
pub fn rear_axle(vehicle: &Vehicle) -> Pose {
    let s = vehicle.state();
    let b = vehicle.params().chassis.cg_to_rear_axle_m();
    let (sin, cos) = vehicle.heading_sin_cos();
    Pose {
        x_m: s.x_m - b * cos,
        y_m: s.y_m - b * sin,
        heading_rad: s.heading_rad,
    }
}

/// Where the car starts on `road`: `start_m` along it, `lane_m` left of the centreline,
/// heading along it (the CG there).
pub fn start_pose(road: &Road, start_m: f64, lane_m: f64) -> Pose {
    let p = road.pose_at(start_m);
    let (sin, cos) = p.heading_rad.sin_cos();
    Pose {
        x_m: p.x_m - lane_m * sin,
        y_m: p.y_m + lane_m * cos,
        heading_rad: p.heading_rad,
    }
}
