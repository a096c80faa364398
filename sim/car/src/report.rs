//! What a run produces: the 10 ms trace, the bus log, the summary figures and the plots.
//! Every number is written with a fixed precision and no wall-clock time, so the same
//! scenario gives byte-identical files.

use crate::car::{BrakePress, LoggedFrame, TraceRow, VirtualCar};
use crate::decimal;
use crate::plot::{Axis, Plot, Series};
use crate::scenario::Scenario;
use autoplug_can::Node;
use serde::Serialize;
use std::collections::BTreeMap;
use std::fs;
use std::io::{self, BufWriter, Write};
use std::path::Path;

/// Trace sample period, µs.
pub const TRACE_PERIOD_US: u64 = 10_000;

/// Standard gravity, m/s², for the stopping-distance reference.
const G: f64 = 9.80665;

/// A run's complete record.
#[derive(Clone)]
pub struct RunRecord {
    /// One row per 10 ms.
    pub trace: Vec<TraceRow>,
    /// Every frame on the bus.
    pub log: Vec<LoggedFrame>,
    /// The figures.
    pub summary: Summary,
    /// The road the car drove on, if any (`path.svg` draws it).
    pub track: Option<std::sync::Arc<autoplug_road::file::NamedRoad>>,
}

/// Runs a scenario as fast as possible and records it.
pub fn run(scenario: &Scenario) -> RunRecord {
    run_with(scenario, |_| {})
}

/// Runs a scenario, calling `each_tick` after every tick (for pacing and for serving the
/// bus to tools), and records it.
pub fn run_with(scenario: &Scenario, each_tick: impl FnMut(&mut VirtualCar)) -> RunRecord {
    run_car(VirtualCar::new(scenario), each_tick)
}

/// [`run_with`] on a car already built (one with emulated ECUs, say).
pub fn run_car(car: VirtualCar, each_tick: impl FnMut(&mut VirtualCar)) -> RunRecord {
    run_observed(car, each_tick, |_| {})
}

/// [`run_with`], also handing every trace row to `each_row` as it is recorded.
fn run_observed(
    mut car: VirtualCar,
    mut each_tick: impl FnMut(&mut VirtualCar),
    mut each_row: impl FnMut(&TraceRow),
) -> RunRecord {
    let scenario = &car.scenario().clone();
    let rows = (scenario.duration_s * 1e6 / TRACE_PERIOD_US as f64).ceil() as usize + 1;
    let mut trace = Vec::with_capacity(rows);
    while !car.finished() {
        if car.time_us() % TRACE_PERIOD_US == 0 {
            let row = car.trace_row();
            each_row(&row);
            trace.push(row);
        }
        car.tick();
        each_tick(&mut car);
    }
    let row = car.trace_row();
    each_row(&row);
    trace.push(row);
    let summary = Summary::compute(scenario, &trace, &car);
    let log = car.take_log();
    RunRecord {
        trace,
        log,
        summary,
        track: scenario.track.clone(),
    }
}

/// A braking from speed to standstill.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct Stop {
    /// When the brake pedal was pressed, s.
    pub start_s: f64,
    /// Speed then, km/h.
    pub from_kmh: f64,
    /// Distance to standstill (the car at rest: not moving and not turning), m.
    pub distance_m: f64,
    /// Time to standstill, s.
    pub duration_s: f64,
    /// The physical limit v²/(2·µ·g) with the road's mean friction, m.
    pub limit_m: f64,
    /// distance / limit.
    pub ratio_to_limit: f64,
    /// Heading change during the stop, degrees.
    pub heading_change_deg: f64,
    /// Longest time a wheel was locked (below 10 % of the vehicle speed, above 10 km/h), s.
    pub longest_wheel_lock_s: f64,
}

/// Cruise control figures.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct CruiseFigures {
    /// When it engaged, s.
    pub engaged_at_s: f64,
    /// Set speed, km/h.
    pub set_speed_kmh: f64,
    /// Time from engagement until the speed stays within ±1 km/h of the set speed for
    /// 10 s (or until cruise ends), s; absent if it never settles.
    pub settle_time_s: Option<f64>,
    /// Largest deviation from the set speed from 8 s after engagement on, km/h.
    pub max_error_after_8s_kmh: f64,
    /// Root-mean-square deviation from 8 s after engagement on, km/h.
    pub rms_error_after_8s_kmh: f64,
}

/// The run's figures.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct Summary {
    /// Scenario name.
    pub scenario: String,
    /// Scenario description.
    pub description: String,
    /// Simulated time, s.
    pub duration_s: f64,
    /// Random seed.
    pub seed: u64,
    /// Software of the ECUs with variants.
    pub software: BTreeMap<String, String>,
    /// Distance, m.
    pub distance_m: f64,
    /// Highest speed, km/h.
    pub max_speed_kmh: f64,
    /// Speed at the end, km/h.
    pub final_speed_kmh: f64,
    /// Fuel used, L.
    pub fuel_used_l: f64,
    /// Shifts: changes of engaged gear (reverse or a forward gear) to another; the pass
    /// through neutral inside a shift, and engaging a gear from neutral, are not shifts.
    pub shifts: usize,
    /// Engaged gears in order (-1 reverse, 0 neutral).
    pub gear_sequence: Vec<i32>,
    /// Braking manoeuvres to standstill.
    pub stops: Vec<Stop>,
    /// Cruise control, if it engaged.
    pub cruise: Option<CruiseFigures>,
    /// Time the ABS was acting, s.
    pub abs_active_s: f64,
    /// ABS interventions: stretches of the ABS releasing brake pressure on any wheel,
    /// those less than [`autoplug_ecus::abs::INTERVENTION_MERGE_GAP_US`] apart counted as one.
    pub abs_interventions: usize,
    /// Largest yaw-rate error, rad/s.
    pub peak_yaw_rate_error_rad_s: f64,
    /// Largest torque split, N·m.
    pub peak_torque_split_nm: f64,
    /// Cabin temperature at the end, °F.
    pub final_cabin_temp_f: f64,
    /// Bus load over the run.
    pub bus_load: f64,
    /// Highest bus load over a 100 ms window.
    pub bus_load_peak_100ms: f64,
    /// Frames on the bus.
    pub frames: u64,
    /// Error frames.
    pub error_frames: u64,
    /// DTCs each ECU recorded ("U0126-87 status 0x2F").
    pub dtcs: BTreeMap<String, Vec<String>>,
    /// The ECUs that ran as their firmware on emulated MCUs (none: all on host logic).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub firmware: Vec<String>,
    /// Emulated ECUs that stopped, with when and why.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub firmware_stops: Vec<String>,
}

/// Shifts in a sequence of gears (-1 reverse, 0 neutral, 1..6): a change from one engaged
/// gear to another, whatever neutral lies between them.
pub fn shifts(gears: &[i32]) -> usize {
    let mut engaged = gears.iter().filter(|g| **g != 0);
    let Some(mut last) = engaged.next() else {
        return 0;
    };
    let mut count = 0;
    for gear in engaged {
        if gear != last {
            count += 1;
            last = gear;
        }
    }
    count
}

/// ABS interventions in a trace: stretches of rows with a release on any wheel, merged when
/// closer than [`autoplug_ecus::abs::INTERVENTION_MERGE_GAP_US`].
pub fn abs_interventions(trace: &[TraceRow]) -> usize {
    let mut count = 0;
    let mut last_release_s: Option<f64> = None;
    let merge_gap_s = autoplug_ecus::abs::INTERVENTION_MERGE_GAP_US as f64 * 1e-6;
    for row in trace
        .iter()
        .filter(|r| r.abs_release.iter().any(|x| *x > 0.0))
    {
        if last_release_s.is_none_or(|t| row.t_s - t > merge_gap_s) {
            count += 1;
        }
        last_release_s = Some(row.t_s);
    }
    count
}

fn round(x: f64, decimals: i32) -> f64 {
    let k = 10f64.powi(decimals);
    (x * k).round() / k
}

impl Summary {
    /// Figures of a finished run.
    pub fn compute(scenario: &Scenario, trace: &[TraceRow], car: &VirtualCar) -> Self {
        let first = trace.first().copied().unwrap_or_default();
        let last = trace.last().copied().unwrap_or_default();
        let mut gear_sequence = vec![first.gear];
        for row in trace {
            if gear_sequence.last() != Some(&row.gear) {
                gear_sequence.push(row.gear);
            }
        }
        let dt = TRACE_PERIOD_US as f64 * 1e-6;
        let stats = car.bus().bus_stats();
        let mut dtcs = BTreeMap::new();
        for (node, store) in car.dtcs() {
            let list: Vec<String> = store
                .records()
                .map(|r| format!("{} status 0x{:02X}", r.dtc, r.status))
                .collect();
            if !list.is_empty() {
                dtcs.insert(node.name().to_string(), list);
            }
        }
        let mut software = BTreeMap::new();
        software.insert(
            "cruise".into(),
            format!("{:?}", scenario.ecus.cruise).to_lowercase(),
        );
        software.insert(
            "abs".into(),
            format!("{:?}", scenario.ecus.abs).to_lowercase(),
        );
        software.insert(
            "differential".into(),
            format!("{:?}", scenario.ecus.differential).to_lowercase(),
        );
        let mu = (scenario.road.mu_left + scenario.road.mu_right) / 2.0;
        Self {
            scenario: scenario.name.clone(),
            description: scenario.description.clone(),
            duration_s: scenario.duration_s,
            seed: scenario.seed,
            software,
            distance_m: round(last.distance_m, 2),
            max_speed_kmh: round(trace.iter().map(|r| r.speed_kmh).fold(0.0, f64::max), 2),
            final_speed_kmh: round(last.speed_kmh, 2),
            fuel_used_l: round(first.fuel_l - last.fuel_l, 3),
            shifts: shifts(&gear_sequence),
            gear_sequence,
            stops: stops(trace, car.brake_presses(), mu),
            // An emulated cruise ECU keeps its set speed to itself.
            cruise: if car.emulated(Node::Cruise) {
                None
            } else {
                cruise(trace)
            },
            abs_active_s: round(trace.iter().filter(|r| r.abs_active).count() as f64 * dt, 2),
            abs_interventions: abs_interventions(trace),
            peak_yaw_rate_error_rad_s: round(
                trace
                    .iter()
                    .map(|r| (r.yaw_rate_ref_rad_s - r.yaw_rate_rad_s).abs())
                    .fold(0.0, f64::max),
                3,
            ),
            peak_torque_split_nm: round(
                trace
                    .iter()
                    .map(|r| r.torque_split_nm.abs())
                    .fold(0.0, f64::max),
                2,
            ),
            final_cabin_temp_f: round(last.cabin_temp_f, 2),
            bus_load: round(stats.load, 4),
            bus_load_peak_100ms: round(stats.max_window_load.unwrap_or(stats.load), 4),
            frames: stats.frames,
            error_frames: stats.error_frames,
            dtcs,
            firmware: autoplug_can::ECUS
                .iter()
                .filter(|n| car.emulated(**n))
                .map(|n| autoplug_can::ecu_name(*n).to_string())
                .collect(),
            firmware_stops: car
                .firmware_stops()
                .iter()
                .map(|stop| {
                    format!(
                        "{} at {:.3} s: {}",
                        autoplug_can::ecu_name(stop.node),
                        stop.t_us as f64 * 1e-6,
                        stop.reason
                    )
                })
                .collect(),
        }
    }

    /// The summary as pretty JSON.
    pub fn to_json(&self) -> String {
        let mut text = serde_json::to_string_pretty(self)
            .unwrap_or_else(|e| format!("{{\"error\": \"{e}\"}}"));
        text.push('\n');
        text
    }

    /// The summary as a table for the terminal.
    pub fn table(&self) -> String {
        let mut t = String::new();
        let mut row = |k: &str, v: String| t.push_str(&format!("  {k:<28} {v}\n"));
        row("scenario", self.scenario.clone());
        row("simulated time", format!("{:.1} s", self.duration_s));
        row(
            "software",
            format!(
                "cruise {}, ABS {}, differential {}",
                self.software["cruise"], self.software["abs"], self.software["differential"]
            ),
        );
        if !self.firmware.is_empty() {
            row("firmware (emulated MCUs)", self.firmware.join(", "));
        }
        for stop in &self.firmware_stops {
            row("firmware stopped", stop.clone());
        }
        row("distance", format!("{:.1} m", self.distance_m));
        row(
            "max / final speed",
            format!(
                "{:.1} / {:.1} km/h",
                self.max_speed_kmh, self.final_speed_kmh
            ),
        );
        row("fuel used", format!("{:.3} L", self.fuel_used_l));
        row(
            "gears",
            format!("{:?} ({} shifts)", self.gear_sequence, self.shifts),
        );
        for stop in &self.stops {
            row(
                "stop",
                format!(
                    "from {:.0} km/h at {:.1} s: {:.1} m ({:.2} x limit {:.1} m), heading {:+.1} deg, longest wheel lock {:.2} s",
                    stop.from_kmh, stop.start_s, stop.distance_m, stop.ratio_to_limit, stop.limit_m, stop.heading_change_deg, stop.longest_wheel_lock_s
                ),
            );
        }
        if let Some(c) = &self.cruise {
            row(
                "cruise",
                format!(
                    "set {:.1} km/h at {:.1} s, settled {}, max error after 8 s {:.2} km/h (rms {:.2})",
                    c.set_speed_kmh,
                    c.engaged_at_s,
                    c.settle_time_s.map_or("never".into(), |s| format!("in {s:.1} s")),
                    c.max_error_after_8s_kmh,
                    c.rms_error_after_8s_kmh
                ),
            );
        }
        row(
            "ABS active",
            format!(
                "{:.2} s ({} interventions)",
                self.abs_active_s, self.abs_interventions
            ),
        );
        row(
            "peak yaw-rate error",
            format!(
                "{:.3} rad/s (torque split up to {:.1} N.m)",
                self.peak_yaw_rate_error_rad_s, self.peak_torque_split_nm
            ),
        );
        row(
            "cabin at the end",
            format!("{:.1} degF", self.final_cabin_temp_f),
        );
        row(
            "bus load",
            format!(
                "{:.1} % (peak {:.1} % over 100 ms), {} frames, {} error frames",
                self.bus_load * 100.0,
                self.bus_load_peak_100ms * 100.0,
                self.frames,
                self.error_frames
            ),
        );
        if self.dtcs.is_empty() {
            row("DTCs", "none".into());
        }
        for (node, list) in &self.dtcs {
            row(&format!("DTCs {node}"), list.join(", "));
        }
        t
    }
}

/// The stops of a run: from the tick the pedal went down (`presses`; the last sample
/// before it when a press is missing, which never makes a stop shorter) to the first
/// sample at rest.
fn stops(trace: &[TraceRow], presses: &[BrakePress], mu: f64) -> Vec<Stop> {
    let dt = TRACE_PERIOD_US as f64 * 1e-6;
    let mut found = Vec::new();
    let mut i = 1;
    while i < trace.len() {
        let pressed = trace[i].brake_pedal > 0.0 && trace[i - 1].brake_pedal <= 0.0;
        if !(pressed && trace[i].speed_kmh > 20.0) {
            i += 1;
            continue;
        }
        // A row holds the pedal of the tick before it, so the press came at or after the
        // previous row's time and before this one's (the presses are in time order).
        let (before, after) = (trace[i - 1].t_us(), trace[i].t_us());
        let next = presses.partition_point(|p| p.t_us < after);
        let start = match next.checked_sub(1).map(|k| presses[k]) {
            Some(press) if press.t_us >= before => press,
            _ => BrakePress::at(&trace[i - 1]),
        };
        let mut j = i;
        let (mut lock, mut longest_lock) = (0.0f64, 0.0f64);
        // At rest, not only at no forward speed: a spinning car passes through zero
        // forward speed each time it slides sideways, and goes on turning and sliding.
        let at_rest = |k: usize| {
            let (r, before) = (&trace[k], &trace[k - 1]);
            r.speed_kmh.abs() <= 0.5
                && (r.x_m - before.x_m).hypot(r.y_m - before.y_m) <= 0.5 / 3.6 * dt
                && r.yaw_rate_rad_s.abs() < 0.01
        };
        while j < trace.len() && !at_rest(j) && trace[j].brake_pedal > 0.0 {
            let r = &trace[j];
            let locked =
                r.speed_kmh > 10.0 && r.wheel_speed_kmh.iter().any(|w| *w < 0.1 * r.speed_kmh);
            lock = if locked { lock + dt } else { 0.0 };
            longest_lock = longest_lock.max(lock);
            j += 1;
        }
        if j < trace.len() && at_rest(j) {
            let end = trace[j];
            let v = start.speed_kmh / 3.6;
            let limit = v * v / (2.0 * mu * G);
            let distance = end.distance_m - start.distance_m;
            found.push(Stop {
                start_s: round(start.t_us as f64 * 1e-6, 2),
                from_kmh: round(start.speed_kmh, 2),
                distance_m: round(distance, 2),
                duration_s: round(end.t_s - start.t_us as f64 * 1e-6, 2),
                limit_m: round(limit, 2),
                ratio_to_limit: round(distance / limit, 3),
                heading_change_deg: round((end.heading_rad - start.heading_rad).to_degrees(), 2),
                longest_wheel_lock_s: round(longest_lock, 2),
            });
        }
        i = j.max(i + 1);
    }
    found
}

fn cruise(trace: &[TraceRow]) -> Option<CruiseFigures> {
    let start = trace.iter().position(|r| r.cruise_on)?;
    let engaged: Vec<&TraceRow> = trace[start..].iter().take_while(|r| r.cruise_on).collect();
    let set = engaged[0].cruise_set_kmh;
    let t0 = engaged[0].t_s;
    // Settled: from the first moment the speed stays within ±1 km/h for 10 s (or until
    // cruise ends), so a later disturbance (a grade) does not move it.
    let hold = (10.0 / (TRACE_PERIOD_US as f64 * 1e-6)) as usize;
    let mut run = 0usize;
    let mut settle = None;
    for (k, r) in engaged.iter().enumerate() {
        run = if (r.speed_kmh - set).abs() <= 1.0 {
            run + 1
        } else {
            0
        };
        if run > 0 && (run >= hold || k + 1 == engaged.len()) {
            settle = Some(engaged[k + 1 - run].t_s - t0);
            break;
        }
    }
    let late: Vec<f64> = engaged
        .iter()
        .filter(|r| r.t_s >= t0 + 8.0)
        .map(|r| r.speed_kmh - set)
        .collect();
    let max_error = late.iter().map(|e| e.abs()).fold(0.0, f64::max);
    let rms = if late.is_empty() {
        0.0
    } else {
        (late.iter().map(|e| e * e).sum::<f64>() / late.len() as f64).sqrt()
    };
    Some(CruiseFigures {
        engaged_at_s: round(t0, 2),
        set_speed_kmh: round(set, 2),
        settle_time_s: settle.map(|s| round(s, 2)),
        max_error_after_8s_kmh: round(max_error, 3),
        rms_error_after_8s_kmh: round(rms, 3),
    })
}

/// Columns of `trace.csv`, in order.
pub const TRACE_COLUMNS: &str = "t_s,x_m,y_m,heading_rad,speed_kmh,yaw_rate_rad_s,yaw_rate_ref_rad_s,wheel_speed_fl_kmh,wheel_speed_fr_kmh,wheel_speed_rl_kmh,wheel_speed_rr_kmh,brake_fl,brake_fr,brake_rl,brake_rr,abs_release_fl,abs_release_fr,abs_release_rl,abs_release_rr,accel_pedal,brake_pedal,accel_cmd,brake_cmd,steering_deg,gear,engine_rpm,fuel_l,cabin_temp_f,cabin_set_f,fan,cruise_on,cruise_set_kmh,cruise_cmd,torque_split_nm,headlights,brake_lights,abs_active,traction_cut,ax_mps2,ay_mps2,distance_m";

/// Writes the trace as CSV.
pub fn write_trace(out: &mut impl Write, trace: &[TraceRow]) -> io::Result<()> {
    writeln!(out, "{TRACE_COLUMNS}")?;
    write_trace_rows(out, trace)
}

/// Writes rows of `trace.csv` (no header).
fn write_trace_rows(out: &mut impl Write, trace: &[TraceRow]) -> io::Result<()> {
    // Each row is put together in one buffer, numbers by `decimal::push_fixed` (what
    // `{:.N}` writes, faster), then written at once.
    let mut line = Vec::with_capacity(512);
    for r in trace {
        line.clear();
        let mut number = |v: f64, decimals: usize| {
            if !line.is_empty() {
                line.push(b',');
            }
            decimal::push_fixed(&mut line, v, decimals);
        };
        let flag = |v: bool| f64::from(u8::from(v));
        number(r.t_s, 2);
        number(r.x_m, 3);
        number(r.y_m, 3);
        number(r.heading_rad, 5);
        number(r.speed_kmh, 3);
        number(r.yaw_rate_rad_s, 5);
        number(r.yaw_rate_ref_rad_s, 5);
        for w in r.wheel_speed_kmh {
            number(w, 3);
        }
        for v in r.brake.into_iter().chain(r.abs_release) {
            number(v, 2);
        }
        for v in [
            r.accel_pedal,
            r.brake_pedal,
            r.accel_cmd,
            r.brake_cmd,
            r.steering_deg,
        ] {
            number(v, 2);
        }
        number(f64::from(r.gear), 0);
        number(r.engine_rpm, 1);
        number(r.fuel_l, 3);
        for v in [r.cabin_temp_f, r.cabin_set_f, r.fan] {
            number(v, 2);
        }
        number(flag(r.cruise_on), 0);
        for v in [r.cruise_set_kmh, r.cruise_cmd, r.torque_split_nm] {
            number(v, 2);
        }
        for v in [r.headlights, r.brake_lights, r.abs_active] {
            number(flag(v), 0);
        }
        number(r.traction_cut, 2);
        number(r.ax_mps2, 3);
        number(r.ay_mps2, 3);
        number(r.distance_m, 3);
        line.push(b'\n');
        out.write_all(&line)?;
    }
    Ok(())
}

/// Writes the bus log in candump format (`(seconds.micros) can0 ID#DATA`, as
/// `candump -l` writes it), which `autoplug_logs` reads back.
pub fn write_bus_log(out: &mut impl Write, log: &[LoggedFrame]) -> io::Result<()> {
    let mut writer = autoplug_logs::CandumpWriter::new(out);
    for entry in log {
        writer.write(&autoplug_logs::LogFrame::from_can(
            entry.t_us,
            0,
            &entry.frame,
        ))?;
    }
    Ok(())
}

fn series(trace: &[TraceRow], name: &str, axis: Axis, f: impl Fn(&TraceRow) -> f64) -> Series {
    // Every 50 ms is plenty for a figure and keeps the files small.
    let points = trace.iter().step_by(5).map(|r| (r.t_s, f(r))).collect();
    Series {
        name: name.into(),
        points,
        axis,
        steps: false,
    }
}

/// The run's figures, like the report's: (file name, plot); `path.svg` is drawn apart
/// ([`crate::path_plot`]).
pub fn plots(trace: &[TraceRow]) -> Vec<(&'static str, Plot)> {
    let time = "Time (s)".to_string();
    let mut gear = series(trace, "Gear", Axis::Right, |r| f64::from(r.gear));
    gear.steps = true;
    vec![
        (
            "speed.svg",
            Plot {
                title: "Speed and cruise control".into(),
                x_label: time.clone(),
                left_label: "Speed (km/h)".into(),
                right_label: "Cruise command (-100..100)".into(),
                series: vec![
                    series(trace, "Speed", Axis::Left, |r| r.speed_kmh),
                    series(trace, "Cruise set speed", Axis::Left, |r| {
                        if r.cruise_on {
                            r.cruise_set_kmh
                        } else {
                            f64::NAN
                        }
                    }),
                    series(trace, "Cruise command", Axis::Right, |r| r.cruise_cmd),
                ],
            },
        ),
        (
            "braking.svg",
            Plot {
                title: "Wheel speeds and brakes".into(),
                x_label: time.clone(),
                left_label: "Speed (km/h)".into(),
                right_label: "Brake (%)".into(),
                series: vec![
                    series(trace, "Vehicle speed", Axis::Left, |r| r.speed_kmh),
                    series(trace, "Wheel FL", Axis::Left, |r| r.wheel_speed_kmh[0]),
                    series(trace, "Wheel FR", Axis::Left, |r| r.wheel_speed_kmh[1]),
                    series(trace, "Wheel RL", Axis::Left, |r| r.wheel_speed_kmh[2]),
                    series(trace, "Wheel RR", Axis::Left, |r| r.wheel_speed_kmh[3]),
                    series(trace, "Brake FR applied", Axis::Right, |r| r.brake[1]),
                    series(trace, "Brake pedal", Axis::Right, |r| r.brake_pedal),
                ],
            },
        ),
        (
            "transmission.svg",
            Plot {
                title: "Transmission".into(),
                x_label: time.clone(),
                left_label: "Speed (km/h), engine (rpm / 50)".into(),
                right_label: "Gear".into(),
                series: vec![
                    series(trace, "Speed", Axis::Left, |r| r.speed_kmh),
                    series(trace, "Engine rpm / 50", Axis::Left, |r| {
                        r.engine_rpm / 50.0
                    }),
                    gear,
                ],
            },
        ),
        (
            "yaw.svg",
            Plot {
                title: "Active differential".into(),
                x_label: time.clone(),
                left_label: "Yaw-rate error (rad/s)".into(),
                right_label: "Torque split (N.m)".into(),
                series: vec![
                    series(trace, "Yaw-rate error", Axis::Left, |r| {
                        r.yaw_rate_ref_rad_s - r.yaw_rate_rad_s
                    }),
                    series(trace, "Torque split", Axis::Right, |r| r.torque_split_nm),
                ],
            },
        ),
        (
            "cabin.svg",
            Plot {
                title: "Cabin comfort".into(),
                x_label: time,
                left_label: "Temperature (degF)".into(),
                right_label: "Fan (%)".into(),
                series: vec![
                    series(trace, "Cabin", Axis::Left, |r| r.cabin_temp_f),
                    series(trace, "Set point", Axis::Left, |r| r.cabin_set_f),
                    series(trace, "Fan", Axis::Right, |r| r.fan),
                ],
            },
        ),
    ]
}

/// Writes trace.csv, bus.log, summary.json and the plots into `dir` (created if needed).
pub fn write_outputs(dir: &Path, record: &RunRecord) -> io::Result<()> {
    fs::create_dir_all(dir)?;
    let mut log = BufWriter::new(fs::File::create(dir.join("bus.log"))?);
    write_bus_log(&mut log, &record.log)?;
    log.flush()?;
    write_reports(dir, record)
}

/// Writes trace.csv, summary.json and the plots into `dir`: everything but the bus log.
pub fn write_reports(dir: &Path, record: &RunRecord) -> io::Result<()> {
    fs::create_dir_all(dir)?;
    let mut trace = BufWriter::new(fs::File::create(dir.join("trace.csv"))?);
    write_trace(&mut trace, &record.trace)?;
    trace.flush()?;
    write_summary_and_plots(dir, record)
}

/// Writes summary.json and the plots into `dir`, for callers that streamed the bus log and
/// the trace while the run went ([`run_streaming`]).
pub fn write_summary_and_plots(dir: &Path, record: &RunRecord) -> io::Result<()> {
    fs::create_dir_all(dir)?;
    fs::write(dir.join("summary.json"), record.summary.to_json())?;
    fs::write(
        dir.join("path.svg"),
        crate::path_plot::path_svg(
            &record.trace,
            record.track.as_deref(),
            &VirtualCar::vehicle_params(),
        ),
    )?;
    let plots = plots(&record.trace);
    let write = |part: &[(&str, Plot)]| -> io::Result<()> {
        for (name, plot) in part {
            fs::write(dir.join(name), plot.to_svg())?;
        }
        Ok(())
    };
    // Each plot renders thousands of points: half of them on a second core.
    let (first, second) = plots.split_at(plots.len() / 2);
    std::thread::scope(|scope| {
        let other = scope.spawn(|| write(first));
        let mine = write(second);
        match other.join() {
            Ok(theirs) => theirs.and(mine),
            Err(panic) => std::panic::resume_unwind(panic),
        }
    })
}

/// Frames (or trace rows) the simulation hands the writer at a time: one channel operation
/// per about half a second of bus traffic instead of one per tick.
const WRITER_BATCH: usize = 512;

/// Batches queued for the writer at most: memory stays bounded if the disk is slow.
const WRITER_QUEUE: usize = 16;

/// What the simulation hands the writer thread.
enum Batch {
    Frames(Vec<LoggedFrame>),
    Rows(Vec<TraceRow>),
}

/// Runs a scenario, writing each tick's frames to `bus_log` and each trace row to `trace`
/// (as `trace.csv`) as they happen, so a long run does not hold its bus log in memory, and
/// handing the frames to `each_tick` with the car. The returned record has an empty `log`
/// (its trace is complete, for the summary and the plots). Both files are formatted and
/// written (and flushed) on a thread of its own beside the simulation, in batches through
/// a bounded queue; a write error ends the writing and is returned once the run is over.
/// `after_run` gets the record as soon as the simulation ends, while the writer finishes
/// (the summary and the plots need only the record).
pub fn run_streaming<W: Write + Send, T: Write + Send>(
    scenario: &Scenario,
    bus_log: &mut W,
    trace: &mut T,
    each_tick: impl FnMut(&mut VirtualCar, &[LoggedFrame]),
    after_run: impl FnOnce(&RunRecord) -> io::Result<()>,
) -> io::Result<RunRecord> {
    run_car_streaming(
        VirtualCar::new(scenario),
        bus_log,
        trace,
        each_tick,
        after_run,
    )
}

/// [`run_streaming`] on a car already built (one with emulated ECUs, say).
pub fn run_car_streaming<W: Write + Send, T: Write + Send>(
    car: VirtualCar,
    bus_log: &mut W,
    trace: &mut T,
    mut each_tick: impl FnMut(&mut VirtualCar, &[LoggedFrame]),
    after_run: impl FnOnce(&RunRecord) -> io::Result<()>,
) -> io::Result<RunRecord> {
    std::thread::scope(|scope| {
        let (batches, queue) = std::sync::mpsc::sync_channel::<Batch>(WRITER_QUEUE);
        let writer = scope.spawn(move || -> io::Result<()> {
            write_trace(trace, &[])?;
            for batch in queue {
                match batch {
                    Batch::Frames(frames) => write_bus_log(bus_log, &frames)?,
                    Batch::Rows(rows) => write_trace_rows(trace, &rows)?,
                }
            }
            bus_log.flush()?;
            trace.flush()
        });
        // A failed send means the writer stopped on an error, reported below.
        let send = |batch| {
            let _ = batches.send(batch);
        };
        let mut frames_batch = Vec::with_capacity(WRITER_BATCH);
        let mut rows_batch = Vec::with_capacity(WRITER_BATCH);
        let mut frames = Vec::new();
        let record = run_observed(
            car,
            |car| {
                car.swap_log(&mut frames);
                each_tick(car, &frames);
                frames_batch.extend_from_slice(&frames);
                if frames_batch.len() >= WRITER_BATCH {
                    send(Batch::Frames(std::mem::replace(
                        &mut frames_batch,
                        Vec::with_capacity(WRITER_BATCH),
                    )));
                }
            },
            |row| {
                rows_batch.push(*row);
                if rows_batch.len() >= WRITER_BATCH {
                    send(Batch::Rows(std::mem::replace(
                        &mut rows_batch,
                        Vec::with_capacity(WRITER_BATCH),
                    )));
                }
            },
        );
        send(Batch::Frames(frames_batch));
        send(Batch::Rows(rows_batch));
        drop(batches);
        // While the writer catches up with the last batches.
        let finished = after_run(&record);
        match writer.join() {
            Ok(written) => written.and(finished).map(|()| record),
            Err(panic) => std::panic::resume_unwind(panic),
        }
    })
}
