//! The simulator's view of the car in its world, apart from the bus: where the car is, how
//! it is turned and steered, which wheels mark the road, and the road itself. The
//! dashboard's world view draws it (on a channel of its own: the gateway knows only the
//! bus), a recording keeps it beside its candump file, and `path.svg` draws the same
//! tyre marks.

use autoplug_road::file::NamedRoad;
use autoplug_vehicle::{VehicleParams, VehicleState};
use serde_json::{json, Value};

use crate::car::VirtualCar;

/// A wheel leaves a mark when its longitudinal slip is beyond this (locked or spinning).
pub const MARK_SLIP: f64 = 0.2;
/// ... or when it slides sideways at more than this slip angle, radians (about 7°: past
/// the peak of the tyre's lateral force).
pub const MARK_SLIP_ANGLE_RAD: f64 = 0.12;
/// Slower than this nothing leaves a mark, m/s.
pub const MARK_MIN_SPEED_MPS: f64 = 2.0;

/// Which wheels mark the road now, FL FR RL RR: locked, spinning or sliding sideways.
pub fn wheel_marks(state: &VehicleState, params: &VehicleParams) -> [bool; 4] {
    let offsets = params.chassis.wheel_offsets();
    let (vx, vy, r) = (
        state.speed_mps,
        state.lateral_velocity_mps,
        state.yaw_rate_rad_s,
    );
    std::array::from_fn(|i| {
        let (x, y) = offsets[i];
        // The wheel's velocity over the ground, body axes.
        let (along, across) = (vx - r * y, vy + r * x);
        if along.hypot(across) <= MARK_MIN_SPEED_MPS {
            return false;
        }
        let steer = if i < 2 {
            state.road_wheel_angle_rad
        } else {
            0.0
        };
        let slip_angle = across.atan2(along.abs()) - steer * along.signum();
        state.wheel_slip[i].abs() > MARK_SLIP || slip_angle.abs() > MARK_SLIP_ANGLE_RAD
    })
}

/// The car at one moment, as the world view draws it.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct WorldPose {
    /// Simulated time, s (the bus's: the candump file's timestamps).
    pub t_s: f64,
    /// Position of the centre of gravity, east, m.
    pub x_m: f64,
    /// Position north, m.
    pub y_m: f64,
    /// Heading, radians from east, counter-clockwise (not wrapped: a spin shows as
    /// turns).
    pub heading_rad: f64,
    /// Speed, m/s.
    pub speed_mps: f64,
    /// Road-wheel angle of the front wheels, radians, positive left.
    pub steer_rad: f64,
    /// Which wheels mark the road, FL FR RL RR.
    pub marks: [bool; 4],
}

impl WorldPose {
    /// The car's pose now.
    pub fn of(car: &VirtualCar) -> Self {
        let s = car.vehicle();
        Self {
            t_s: car.time_us() as f64 * 1e-6,
            x_m: s.x_m,
            y_m: s.y_m,
            heading_rad: s.heading_rad,
            speed_mps: s.speed_mps,
            steer_rad: s.road_wheel_angle_rad,
            marks: wheel_marks(s, &VirtualCar::vehicle_params()),
        }
    }

    /// The pose as the compact JSON array the world channel and its recording carry:
    /// `[t, x, y, heading, speed, steer, marks]`, marks a 4-bit number (bit 0 FL … bit 3
    /// RR), positions to the millimetre.
    pub fn to_json(&self) -> String {
        let marks = self
            .marks
            .iter()
            .enumerate()
            .fold(0u8, |bits, (i, &m)| bits | (u8::from(m) << i));
        let finite = |v: f64| if v.is_finite() { v } else { 0.0 };
        format!(
            "[{:.3},{:.3},{:.3},{:.5},{:.3},{:.5},{marks}]",
            finite(self.t_s),
            finite(self.x_m),
            finite(self.y_m),
            finite(self.heading_rad),
            finite(self.speed_mps),
            finite(self.steer_rad),
        )
    }

    /// A pose read back from [`WorldPose::to_json`]'s form; `None` if it is not one.
    pub fn from_json(value: &Value) -> Option<Self> {
        let items = value.as_array().filter(|a| a.len() == 7)?;
        let number = |i: usize| items[i].as_f64().filter(|v| v.is_finite());
        let marks = items[6].as_u64().filter(|&m| m < 16)?;
        Some(Self {
            t_s: number(0)?,
            x_m: number(1)?,
            y_m: number(2)?,
            heading_rad: number(3)?,
            speed_mps: number(4)?,
            steer_rad: number(5)?,
            marks: std::array::from_fn(|i| marks & (1 << i) != 0),
        })
    }
}

/// Spacing of the centreline points the road description carries, m.
const CENTRE_STEP_M: f64 = 2.0;
/// Spacing of a patch outline's points, m.
const PATCH_STEP_M: f64 = 2.0;

/// What the world view needs to draw the road and the car, as JSON: the road's name,
/// width, whether it is closed, its centreline (`[x, y, heading, height]` every 2 m and
/// at its end; the height from the road's grades, m above its start), its patches (name, μ, outline), the verge's friction, and the car's outline and
/// wheels. `road` is `null` on the endless plane.
pub fn description(track: Option<&NamedRoad>, params: &VehicleParams) -> Value {
    let c = &params.chassis;
    let car = json!({
        "length_m": c.body_length_m,
        "width_m": c.body_width_m,
        "cg_to_front_m": c.cg_to_front_axle_m() + c.front_overhang_m,
        "wheels": c.wheel_offsets().map(|(x, y)| [x, y]),
        "wheel_radius_m": params.tyre.rolling_radius_m,
    });
    let road = track.map(|track| {
        let road = &track.road;
        let length = road.length_m();
        let mut centre = Vec::new();
        let mut s: f64 = 0.0;
        loop {
            let p = road.pose_at(s.min(length));
            centre.push(json!([
                round(p.x_m, 3),
                round(p.y_m, 3),
                round(p.heading_rad, 5),
                round(road.height_at(s.min(length)), 3)
            ]));
            if s >= length {
                break;
            }
            s += CENTRE_STEP_M;
        }
        let patches: Vec<Value> = road
            .patches()
            .iter()
            .map(|patch| {
                let stations = patch_stations(road, patch.from_m, patch.to_m);
                let side = |lateral: f64, stations: &mut dyn Iterator<Item = &f64>| {
                    stations
                        .map(|&s| {
                            let p = road.pose_at(s);
                            let (sin, cos) = p.heading_rad.sin_cos();
                            json!([
                                round(p.x_m - lateral * sin, 3),
                                round(p.y_m + lateral * cos, 3)
                            ])
                        })
                        .collect::<Vec<_>>()
                };
                let mut outline = side(patch.left_m, &mut stations.iter());
                outline.extend(side(patch.right_m, &mut stations.iter().rev()));
                json!({ "name": patch.name, "mu": patch.mu, "outline": outline })
            })
            .collect();
        json!({
            "name": track.name,
            "width_m": road.width_m(),
            "closed": road.is_closed(),
            "length_m": round(length, 3),
            "centre": centre,
            "patches": patches,
            "verge_mu": autoplug_road::GRASS_MU,
        })
    });
    json!({ "road": road, "car": car })
}

/// Stations along a patch, every [`PATCH_STEP_M`] and at both ends (over the start of a
/// closed road when it runs over it).
fn patch_stations(road: &autoplug_road::Road, from: f64, to: f64) -> Vec<f64> {
    let span = if from <= to {
        to - from
    } else {
        road.length_m() - from + to
    };
    let n = (span / PATCH_STEP_M).ceil().max(1.0) as usize;
    (0..=n)
        .map(|k| road.wrap(from + span * k as f64 / n as f64))
        .collect()
}

fn round(v: f64, decimals: i32) -> f64 {
    let scale = 10f64.powi(decimals);
    (v * scale).round() / scale
}

/// The world file beside a recording's candump file: `drive.log` → `drive.world.jsonl`.
/// JSON Lines: `{"description":{…}}` (the road and the car, as [`description`] makes
/// it), then one pose a line as [`WorldPose::to_json`] writes it, in time order (bus
/// time, the candump file's timestamps); a later description starts a new world.
pub fn world_file_for(candump: &std::path::Path) -> std::path::PathBuf {
    candump.with_extension("world.jsonl")
}

/// Largest world file read, bytes: about 9 hours of driving at 20 poses a second.
pub const MAX_WORLD_FILE_BYTES: u64 = 256 << 20;

/// Writes a world file.
pub struct WorldFileWriter {
    out: std::io::BufWriter<std::fs::File>,
}

impl WorldFileWriter {
    /// Creates (or truncates) the file at `path`.
    pub fn create(path: &std::path::Path) -> std::io::Result<Self> {
        Ok(Self {
            out: std::io::BufWriter::new(std::fs::File::create(path)?),
        })
    }

    /// Writes a description line (`json`: the description object).
    pub fn describe(&mut self, json: &str) -> std::io::Result<()> {
        use std::io::Write as _;
        writeln!(self.out, "{{\"description\":{json}}}")
    }

    /// Writes a pose line (`json`: [`WorldPose::to_json`]'s form).
    pub fn pose(&mut self, json: &str) -> std::io::Result<()> {
        use std::io::Write as _;
        writeln!(self.out, "{json}")
    }

    /// Writes out what is buffered.
    pub fn flush(&mut self) -> std::io::Result<()> {
        use std::io::Write as _;
        self.out.flush()
    }
}

/// A world file as read: the last world it describes, its poses, and where and why the
/// reading stopped early (what precedes the damage is kept).
#[derive(Clone, Debug, PartialEq)]
pub struct WorldLog {
    /// The description (road and car).
    pub description: Value,
    /// The poses, in the file's order.
    pub poses: Vec<WorldPose>,
    /// The line the file was damaged at and what was wrong, if it was.
    pub damaged: Option<String>,
}

/// Reads a world file (at most [`MAX_WORLD_FILE_BYTES`]). A file with no description
/// first is refused; a damaged line ends the reading there, keeping what precedes it.
pub fn read_world_file(path: &std::path::Path) -> Result<WorldLog, String> {
    use std::io::{BufRead as _, Read as _};
    let name = path.display();
    let file = std::fs::File::open(path).map_err(|e| format!("{name}: cannot read: {e}"))?;
    let reader = std::io::BufReader::new(file.take(MAX_WORLD_FILE_BYTES));
    let mut log: Option<WorldLog> = None;
    for (i, line) in reader.split(b'\n').enumerate() {
        let number = i + 1;
        let damaged = |why: String| format!("{name}: line {number}: {why}");
        let line = match line {
            Ok(line) => line,
            Err(e) => {
                if let Some(log) = &mut log {
                    log.damaged = Some(damaged(e.to_string()));
                    break;
                }
                return Err(damaged(e.to_string()));
            }
        };
        if line.iter().all(u8::is_ascii_whitespace) {
            continue;
        }
        let value: Result<Value, String> = serde_json::from_slice(&line).map_err(|e| e.to_string());
        match (value, &mut log) {
            (Ok(Value::Object(mut object)), _) if object.contains_key("description") => {
                let description = object.remove("description").unwrap_or(Value::Null);
                log = Some(WorldLog {
                    description,
                    poses: Vec::new(),
                    damaged: None,
                });
            }
            (Ok(value), Some(log)) => match WorldPose::from_json(&value) {
                Some(pose) => log.poses.push(pose),
                None => {
                    log.damaged = Some(damaged(
                        "not a pose ([t, x, y, heading, speed, steer, marks])".into(),
                    ));
                    break;
                }
            },
            (Err(e), Some(log)) => {
                log.damaged = Some(damaged(e));
                break;
            }
            (_, None) => {
                return Err(damaged(
                    "a world file starts with its description ({\"description\":…})".into(),
                ))
            }
        }
    }
    log.ok_or_else(|| format!("{name}: empty: no description"))
}
