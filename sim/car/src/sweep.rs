//! The ABS braking sweep: full stops of the whole virtual car (driver, bus, nine ECUs,
//! vehicle model) over a grid of road friction and initial speed, each measured against
//! the physical limit v²/(2·µ·g), and split-friction stops for the heading.
//!
//! One full-brake scenario per point, built here rather than shipped as files: the grid is
//! the point, and the scenario differs only in its friction and speed.

use std::fmt::Write;

use autoplug_vehicle::shortest_braking_distance;

use crate::car::VirtualCar;
use crate::plot::{Axis, Plot, Series};
use crate::report::{self, Stop};
use crate::scenario::Scenario;

/// When the driver hits the brake, s: the ECUs have exchanged their first frames by then
/// and the speed reference is fresh, and drag has taken little of the speed.
pub const BRAKE_AT_S: f64 = 0.3;

/// Standard gravity, m/s² (as the stop figures use it).
const G: f64 = 9.80665;

/// The frictions of the sweep: ice and packed snow (0.2), wet and worn roads, dry asphalt.
pub const FRICTIONS: [f64; 7] = [0.2, 0.3, 0.4, 0.5, 0.6, 0.8, 1.0];

/// The initial speeds of the sweep, km/h.
pub const SPEEDS_KMH: [f64; 8] = [40.0, 50.0, 60.0, 80.0, 100.0, 130.0, 160.0, 200.0];

/// The sweep's bound on an even-friction stop, × v²/(2µg): from [`BOUND_FAST_FROM_KMH`] up ...
pub const BOUND_FAST: f64 = 1.05;

/// ... and below it, where the brake system's pressure build-up weighs more.
pub const BOUND_SLOW: f64 = 1.10;

/// Where the bound changes, km/h.
pub const BOUND_FAST_FROM_KMH: f64 = 50.0;

/// The bound on a stop from `from_kmh` (the speed measured at the brake: drag has taken
/// a few tenths of a km/h off the scenario's speed by then, so 49.5 counts as 50).
pub fn ratio_bound(from_kmh: f64) -> f64 {
    if from_kmh >= BOUND_FAST_FROM_KMH - 0.5 {
        BOUND_FAST
    } else {
        BOUND_SLOW
    }
}

/// Split friction (left, right) for the heading check: ice beside asphalt, snow beside wet.
pub const SPLIT_FRICTIONS: [(f64, f64); 2] = [(0.2, 1.0), (0.3, 0.8)];

/// Speeds of the split-friction stops, km/h.
pub const SPLIT_SPEEDS_KMH: [f64; 4] = [50.0, 100.0, 130.0, 160.0];

/// One stop of the sweep.
#[derive(Clone, Debug, PartialEq)]
pub struct SweepStop {
    /// Friction of the left wheels.
    pub mu_left: f64,
    /// Friction of the right wheels.
    pub mu_right: f64,
    /// The speed the scenario started at, km/h.
    pub speed_kmh: f64,
    /// The stop as measured (`None`: the car did not come to rest within the scenario).
    pub stop: Option<Stop>,
}

impl SweepStop {
    /// Whether both sides have the same friction.
    pub fn even(&self) -> bool {
        self.mu_left == self.mu_right
    }
}

/// Full braking from `speed_kmh` on a road of friction `mu_left` / `mu_right`, wheel held
/// straight, long enough to come to rest with room to spare. Declutched (neutral), as
/// stopping-distance tests brake (ISO 21994), so the engine's drag does not count.
pub fn braking_scenario(mu_left: f64, mu_right: f64, speed_kmh: f64) -> Result<Scenario, String> {
    let v = speed_kmh / 3.6;
    let low = mu_left.min(mu_right).max(0.05);
    // Half as long again as the stop at the low side's limit, plus the pressure build-up.
    let duration_s = BRAKE_AT_S + 1.5 * v / (low * G) + 1.0;
    // Through the scenario parser, so a sweep point is checked as a scenario file is.
    let text = format!(
        "name = \"abs-sweep-mu{l}-{r}-from-{v}\"\n\
         description = \"Full braking from {speed_kmh} km/h, friction left {mu_left} / right {mu_right}.\"\n\
         duration_s = {duration_s:.2}\n\
         [road]\nmu_left = {mu_left:?}\nmu_right = {mu_right:?}\n\
         [initial]\nspeed_kmh = {speed_kmh:?}\ngear = \"N\"\n\
         [[at]]\nt_s = {BRAKE_AT_S:?}\nbrake = 100.0\n",
        l = (mu_left * 100.0).round(),
        r = (mu_right * 100.0).round(),
        v = speed_kmh.round(),
    );
    Scenario::parse(&text, "abs sweep").map_err(|e| e.to_string())
}

/// Runs one stop (`Err`: a friction or speed no scenario may have).
pub fn run_stop(mu_left: f64, mu_right: f64, speed_kmh: f64) -> Result<SweepStop, String> {
    let record = report::run(&braking_scenario(mu_left, mu_right, speed_kmh)?);
    Ok(SweepStop {
        mu_left,
        mu_right,
        speed_kmh,
        stop: record.summary.stops.into_iter().next(),
    })
}

/// Every point of the grid (`frictions` × `speeds`, even friction) and the split-friction
/// stops, on `threads` threads (each stop is independent and deterministic, so the result
/// does not depend on the threads). In grid order, the split stops last.
pub fn run_sweep(
    frictions: &[f64],
    speeds_kmh: &[f64],
    splits: &[(f64, f64)],
    split_speeds_kmh: &[f64],
    threads: usize,
) -> Result<Vec<SweepStop>, String> {
    let mut points: Vec<(f64, f64, f64)> = Vec::new();
    for &mu in frictions {
        for &v in speeds_kmh {
            points.push((mu, mu, v));
        }
    }
    for &(l, r) in splits {
        for &v in split_speeds_kmh {
            points.push((l, r, v));
        }
    }
    let threads = threads.clamp(1, points.len().max(1));
    let mut results: Vec<Option<Result<SweepStop, String>>> = vec![None; points.len()];
    std::thread::scope(|scope| {
        let chunks: Vec<_> = results
            .chunks_mut(points.len().div_ceil(threads))
            .zip(points.chunks(points.len().div_ceil(threads)))
            .map(|(out, work)| {
                scope.spawn(move || {
                    for (slot, &(l, r, v)) in out.iter_mut().zip(work) {
                        *slot = Some(run_stop(l, r, v));
                    }
                })
            })
            .collect();
        for handle in chunks {
            if let Err(panic) = handle.join() {
                std::panic::resume_unwind(panic);
            }
        }
    });
    results.into_iter().flatten().collect()
}

/// The shortest stop the car itself allows from `from_kmh` on friction `mu`, m
/// ([`shortest_braking_distance`]): the brake pressure building up over its 40 ms, each
/// wheel spun down against its inertia to the tyre's peak slip and held there exactly,
/// under the braking load transfer, drag and rolling resistance included. Longer than
/// v²/(2µg) by the tyres' load sensitivity (3.7 % on µ = 1), the pressure build-up and the
/// spin-down, so a stop's excess over this is what the ABS costs.
pub fn car_limit_m(mu: f64, from_kmh: f64) -> f64 {
    shortest_braking_distance(&VirtualCar::vehicle_params(), mu, from_kmh / 3.6)
}

/// The sweep as a Markdown table: one row per stop, distance against the limit v²/(2µg)
/// and against the shortest stop the car allows ([`car_limit_m`]), the longest wheel lock
/// and the heading change.
pub fn table(stops: &[SweepStop]) -> String {
    let mut t = String::new();
    t.push_str("| µ left / right | from km/h | distance m | limit m | × limit | × car's limit | longest lock s | heading ° |\n");
    t.push_str("|---|---:|---:|---:|---:|---:|---:|---:|\n");
    for s in stops {
        let mu = if s.even() {
            format!("{}", s.mu_left)
        } else {
            format!("{} / {}", s.mu_left, s.mu_right)
        };
        match &s.stop {
            Some(stop) => {
                let car = if s.even() {
                    format!(
                        "{:.3}",
                        stop.distance_m / car_limit_m(s.mu_left, stop.from_kmh)
                    )
                } else {
                    String::new()
                };
                let _ = writeln!(
                    t,
                    "| {mu} | {:.0} | {:.1} | {:.1} | {:.3} | {car} | {:.2} | {:+.1} |",
                    stop.from_kmh,
                    stop.distance_m,
                    stop.limit_m,
                    stop.ratio_to_limit,
                    stop.longest_wheel_lock_s,
                    stop.heading_change_deg
                );
            }
            None => {
                let _ = writeln!(t, "| {mu} | {:.0} | no stop | | | | | |", s.speed_kmh);
            }
        }
    }
    t
}

/// The even-friction stops as a figure: distance / limit over the initial speed, a line
/// per friction.
pub fn plot(stops: &[SweepStop]) -> Plot {
    let mut frictions: Vec<f64> = stops
        .iter()
        .filter(|s| s.even())
        .map(|s| s.mu_left)
        .collect();
    frictions.dedup();
    let series = frictions
        .iter()
        .map(|&mu| Series {
            name: format!("µ {mu}"),
            points: stops
                .iter()
                .filter(|s| s.even() && s.mu_left == mu)
                .filter_map(|s| s.stop.as_ref().map(|st| (st.from_kmh, st.ratio_to_limit)))
                .collect(),
            axis: Axis::Left,
            steps: false,
        })
        .chain(std::iter::once(Series {
            name: "bound".into(),
            points: vec![
                (SPEEDS_KMH[0].min(BOUND_FAST_FROM_KMH), BOUND_SLOW),
                (BOUND_FAST_FROM_KMH, BOUND_FAST),
                (SPEEDS_KMH[SPEEDS_KMH.len() - 1], BOUND_FAST),
            ],
            axis: Axis::Left,
            steps: true,
        }))
        .collect();
    Plot {
        title: "Full braking with ABS: stopping distance / v²/(2µg)".into(),
        x_label: "speed at the brake, km/h".into(),
        left_label: "distance / limit".into(),
        right_label: String::new(),
        series,
    }
}
