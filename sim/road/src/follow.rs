//! Following a road: the steering a scripted driver applies to keep the car on it.
//!
//! Pure pursuit (R. C. Coulter, "Implementation of the Pure Pursuit Path Tracking
//! Algorithm", CMU-RI-TR-92-01, 1992): aim at a point a look-ahead distance further along
//! the road, and steer the front wheels so that the rear axle would run on the circle
//! through that point, tangent to the car's heading. On a bend of constant radius with the
//! car on its line that circle is the bend itself, so the angle is the bend's own
//! (atan(wheelbase / radius)); off the line the circle bends back onto it. A longer
//! look-ahead is smoother and cuts corners more; drivers look further ahead at speed, so
//! the look-ahead grows with it ([`lookahead_m`]).

use crate::{Pose, Road};

/// The look-ahead at standstill, m.
pub const MIN_LOOKAHEAD_M: f64 = 6.0;

/// Seconds of travel the look-ahead adds at speed.
pub const LOOKAHEAD_TIME_S: f64 = 0.8;

/// How far ahead a driver aims at `speed_mps`: [`MIN_LOOKAHEAD_M`] plus
/// [`LOOKAHEAD_TIME_S`] of travel.
pub fn lookahead_m(speed_mps: f64) -> f64 {
    MIN_LOOKAHEAD_M + LOOKAHEAD_TIME_S * speed_mps.max(0.0)
}

/// The front-wheel angle, radians (positive left), that pure pursuit asks of a car whose
/// rear axle is at `rear_axle` and which is at `station_m` on the road, aiming
/// `lookahead_m` ahead on the line `lane_m` to the left of the centreline (negative:
/// right of it).
pub fn pure_pursuit(
    road: &Road,
    rear_axle: Pose,
    station_m: f64,
    wheelbase_m: f64,
    lookahead_m: f64,
    lane_m: f64,
) -> f64 {
    let (aim, (cos, sin)) = road.pose_and_direction_at(station_m + lookahead_m);
    let (tx, ty) = (aim.x_m - lane_m * sin, aim.y_m + lane_m * cos);
    let (dx, dy) = (tx - rear_axle.x_m, ty - rear_axle.y_m);
    // Metres on a road: no overflow for `hypot` to guard against.
    let distance = (dx * dx + dy * dy).sqrt();
    if distance < 1e-6 {
        return 0.0;
    }
    let alpha = dy.atan2(dx) - rear_axle.heading_rad;
    (2.0 * wheelbase_m * alpha.sin() / distance).atan()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Segment;
    use std::f64::consts::PI;

    const WHEELBASE_M: f64 = 2.51;

    #[test]
    fn on_a_bend_it_steers_the_bends_own_angle_and_straight_on_a_straight() {
        for radius in [40.0f64, -120.0] {
            let start = Pose {
                x_m: 0.0,
                y_m: 0.0,
                heading_rad: 0.0,
            };
            let road = Road::new(
                start,
                vec![Segment::arc(2.0 * PI * radius.abs(), radius)],
                8.0,
            )
            .unwrap()
            .closed()
            .unwrap();
            let at = road.pose_at(30.0);
            for lookahead in [6.0, 20.0] {
                let steer = pure_pursuit(&road, at, 30.0, WHEELBASE_M, lookahead, 0.0);
                let expected = (WHEELBASE_M / radius).atan();
                assert!(
                    (steer - expected).abs() < 1e-4,
                    "{steer} against {expected}"
                );
            }
        }
        let road = Road::new(
            Pose {
                x_m: 0.0,
                y_m: 0.0,
                heading_rad: 0.0,
            },
            vec![Segment::straight(200.0)],
            8.0,
        )
        .unwrap();
        let on_line = Pose {
            x_m: 50.0,
            y_m: 0.0,
            heading_rad: 0.0,
        };
        assert_eq!(
            pure_pursuit(&road, on_line, 50.0, WHEELBASE_M, 10.0, 0.0),
            0.0
        );
        // Left of the line it steers right, back onto it; aiming at a lane on the left it
        // steers left.
        let left = Pose {
            y_m: 1.5,
            ..on_line
        };
        assert!(pure_pursuit(&road, left, 50.0, WHEELBASE_M, 10.0, 0.0) < -0.01);
        assert!(pure_pursuit(&road, on_line, 50.0, WHEELBASE_M, 10.0, 2.5) > 0.01);
    }

    #[test]
    fn the_look_ahead_grows_with_speed() {
        assert_eq!(lookahead_m(0.0), MIN_LOOKAHEAD_M);
        assert_eq!(lookahead_m(-3.0), MIN_LOOKAHEAD_M);
        assert!((lookahead_m(25.0) - 26.0).abs() < 1e-12);
    }
}
