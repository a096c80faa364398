//! Scenario files: what to drive, on what road, with which ECU software (TOML).
//!
//! ```toml
//! name = "cruise-hold"
//! description = "Cruise engaged at 90 km/h on a level road, then a 6 % grade."
//! duration_s = 40.0
//! seed = 1                      # sensor noise and fault injection
//! vin = "JA3AP47H0YF000042"     # the car's VIN (F190 of every ECU); else one from the seed
//!
//! [road]
//! track = "handling-circuit"    # optional: a road to drive on (a shipped one, roads/*.toml,
//!                               # or a road file's path from this file's folder)
//! start_m = 0.0                 # where on it the car starts, m along it
//! lane_m = 0.0                  # and how far left of its centreline (negative: right)
//! mu_left = 1.0                 # friction, left wheels (on a track: the left half's asphalt)
//! mu_right = 1.0                # friction, right wheels (split-µ when different)
//! grade_percent = 0.0           # without a track only: on one, the road sets the grade
//! ambient_c = 25.0
//! sun_load_w = 300.0
//!
//! [initial]
//! speed_kmh = 90.0
//! gear = "4"                    # "R", "N" or "1".."6"
//! fuel_l = 40.0
//! cabin_temp_f = 80.0
//!
//! [ecus]
//! cruise = "correct"            # or "faulty"
//! abs = "correct"               # or "faulty"
//! differential = "enabled"      # or "disabled" (open differential, for comparisons)
//!
//! [factory]                     # the software version each ECU left the factory with
//! cruise = "1.1.0"              # (any of the nine; 1.0.0 when not given)
//!
//! [driver]                      # the driver's controls at t = 0
//! accelerator = 20.0            # pedal %, 0..100
//! set_temp_f = 72.0
//! follow_road = false           # on a track: steer along it (path following)
//! speed_kmh = 80.0              # hold this speed with the pedals, slowing for bends
//!
//! [[at]]                        # timeline: changes at a time, in order
//! t_s = 2.0
//! press = ["cruise_on"]         # momentary buttons: cruise_on, cruise_off, shift_up, shift_down
//! accelerator = 0.0
//!
//! [[at]]
//! t_s = 20.0
//! grade_percent = 6.0           # the road can change too
//!
//! [[at]]
//! t_s = 60.0
//! to_start = true               # the car put back, standing, where it started
//! ```
//!
//! Unknown keys are errors (a typo must not silently do nothing), and every value is
//! checked against its range with an error that names the field.

use autoplug_image::Version;
use autoplug_road::file::NamedRoad;
use autoplug_vin::Vin;
use serde::Deserialize;
use std::collections::BTreeMap;
use std::fmt;
use std::path::Path;
use std::sync::Arc;

/// A whole scenario.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    /// Short name, used for output folders.
    pub name: String,
    /// What it shows.
    #[serde(default)]
    pub description: String,
    /// Simulated time to run.
    pub duration_s: f64,
    /// Seed of every random process (sensor noise, fault injection).
    #[serde(default = "default_seed")]
    pub seed: u64,
    /// The road.
    #[serde(default)]
    pub road: Road,
    /// The car at t = 0.
    #[serde(default)]
    pub initial: Initial,
    /// The vehicle identification number every ECU holds (UDS F190); `None`: one made
    /// from the seed ([`Scenario::vin`]).
    #[serde(default, rename = "vin")]
    pub vin_text: Option<String>,
    /// Which software the ECUs run.
    #[serde(default)]
    pub ecus: EcuVariants,
    /// The software version each ECU left the factory with, by ECU name (`cruise`,
    /// `abs`...); [`crate::diag::FACTORY_VERSION`] for the others.
    #[serde(default)]
    pub factory: BTreeMap<String, String>,
    /// The driver's controls at t = 0.
    #[serde(default)]
    pub driver: DriverSettings,
    /// Changes over time, in time order.
    #[serde(default)]
    pub at: Vec<Event>,
    /// The road `road.track` names, read when the scenario is.
    #[serde(skip)]
    pub track: Option<Arc<NamedRoad>>,
}

fn default_seed() -> u64 {
    1
}

/// Road and weather.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Road {
    /// The road the car drives on: a shipped road's name (`handling-circuit`, see
    /// `autoplug_road::shipped`) or the path of a road file (`*.toml`) from the scenario
    /// file's folder. Without one the car drives on an endless plane, each side of the car
    /// on its own friction.
    pub track: Option<String>,
    /// Where on the track the car starts, m along it.
    pub start_m: f64,
    /// How far left of the track's centreline the car starts, m (negative: right); the
    /// line a driver that follows the road keeps.
    pub lane_m: f64,
    /// Tyre-road friction of the left wheels; on a track, of the asphalt of its left half
    /// (patches and the verge keep their own).
    pub mu_left: f64,
    /// Tyre-road friction of the right wheels; on a track, of its right half's asphalt.
    pub mu_right: f64,
    /// Grade in percent (positive uphill); on a track the track's grades apply instead.
    pub grade_percent: f64,
    /// Ambient temperature, °C.
    pub ambient_c: f64,
    /// Solar load on the cabin, W.
    pub sun_load_w: f64,
}

impl Default for Road {
    fn default() -> Self {
        Self {
            track: None,
            start_m: 0.0,
            lane_m: 0.0,
            mu_left: 1.0,
            mu_right: 1.0,
            grade_percent: 0.0,
            ambient_c: 20.0,
            sun_load_w: 0.0,
        }
    }
}

/// The car's state at t = 0.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Initial {
    /// Speed, km/h.
    pub speed_kmh: f64,
    /// Engaged gear.
    pub gear: GearName,
    /// Fuel in the tank, L.
    pub fuel_l: f64,
    /// Cabin temperature, °F.
    pub cabin_temp_f: f64,
}

impl Default for Initial {
    fn default() -> Self {
        Self {
            speed_kmh: 0.0,
            gear: GearName::Neutral,
            fuel_l: 40.0,
            cabin_temp_f: 72.0,
        }
    }
}

/// A gear as written in a scenario: "R", "N", "1".."6".
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GearName {
    /// Reverse.
    Reverse,
    /// Neutral.
    Neutral,
    /// Forward gear 1..=6.
    Forward(u8),
}

impl<'de> Deserialize<'de> for GearName {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let text = String::deserialize(d)?;
        match text.as_str() {
            "R" => Ok(GearName::Reverse),
            "N" => Ok(GearName::Neutral),
            "1" | "2" | "3" | "4" | "5" | "6" => Ok(GearName::Forward(text.as_bytes()[0] - b'0')),
            _ => Err(serde::de::Error::custom(format!(
                "gear \"{text}\": expected \"R\", \"N\" or \"1\" to \"6\""
            ))),
        }
    }
}

/// Software variants of the ECUs that have them.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EcuVariants {
    /// Cruise control software.
    pub cruise: Software,
    /// ABS software.
    pub abs: Software,
    /// Whether the differential ECU controls the torque split.
    pub differential: Activation,
}

impl Default for EcuVariants {
    fn default() -> Self {
        Self {
            cruise: Software::Correct,
            abs: Software::Correct,
            differential: Activation::Enabled,
        }
    }
}

/// Correct or faulty software (the report's demonstrations).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Software {
    /// The working software.
    Correct,
    /// The demonstration's broken software.
    Faulty,
}

/// Whether an ECU acts.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Activation {
    /// Working normally.
    Enabled,
    /// Its actuator output is held neutral (it still talks on the bus).
    Disabled,
}

/// The driver's controls. In `[driver]` they are the values at t = 0; in an `[[at]]`
/// event, only the ones given change.
#[derive(Clone, Debug, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DriverSettings {
    /// Accelerator pedal, % (0..100).
    pub accelerator: Option<f64>,
    /// Brake pedal, % (0..100).
    pub brake: Option<f64>,
    /// Steering wheel angle, degrees, positive to the left (−135..135).
    pub steering_deg: Option<f64>,
    /// Headlight switch.
    pub headlights: Option<bool>,
    /// Engine-mode switch: true for economy, false for sport.
    pub economy_mode: Option<bool>,
    /// Transmission-mode switch: true for manual, false for automatic.
    pub manual_mode: Option<bool>,
    /// Cabin set-temperature knob, °F.
    pub set_temp_f: Option<f64>,
    /// On a track: the driver steers along it ([`crate::driver::RoadDriver`]).
    pub follow_road: Option<bool>,
    /// A speed the driver holds with the pedals, km/h, slowing for the bends ahead when
    /// following the road.
    pub speed_kmh: Option<f64>,
}

pub use autoplug_vehicle::controls::Button;

/// A fault injected on the bus.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Fault {
    /// Node whose transmissions stop (`"Cruise"`, `"ABS"`, ... as in the DBC).
    pub silence: Option<String>,
    /// Node whose transmissions resume.
    pub restore: Option<String>,
}

/// Changes at one point in time: any of the controls, road changes and faults.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Event {
    /// When, in seconds from the start.
    pub t_s: f64,
    /// How long the pedals and the steering wheel take to move to their new values
    /// (linear ramp), s.
    #[serde(default)]
    pub ramp_s: f64,
    /// Buttons pressed at this time (held for [`BUTTON_PRESS_S`]).
    #[serde(default)]
    pub press: Vec<Button>,
    /// Accelerator pedal, %.
    pub accelerator: Option<f64>,
    /// Brake pedal, %.
    pub brake: Option<f64>,
    /// Steering wheel angle, degrees.
    pub steering_deg: Option<f64>,
    /// Headlight switch.
    pub headlights: Option<bool>,
    /// Engine-mode switch (economy).
    pub economy_mode: Option<bool>,
    /// Transmission-mode switch (manual).
    pub manual_mode: Option<bool>,
    /// Cabin set temperature, °F.
    pub set_temp_f: Option<f64>,
    /// Start (true) or stop (false) steering along the track.
    pub follow_road: Option<bool>,
    /// A speed to hold with the pedals from now on, km/h; an `accelerator` or `brake`
    /// given later hands the pedals back to the timeline.
    pub speed_kmh: Option<f64>,
    /// New grade, %.
    pub grade_percent: Option<f64>,
    /// New friction, left wheels.
    pub mu_left: Option<f64>,
    /// New friction, right wheels.
    pub mu_right: Option<f64>,
    /// Bus faults.
    pub fault: Option<Fault>,
    /// The simulator's hand: the car is put back where it started, standing (on a track:
    /// its start line), as a person resetting a driving simulator does; for a second run
    /// of a demonstration on the same stretch of road.
    #[serde(default)]
    pub to_start: bool,
}

/// The friction a road may have: ice to a racing tyre's grip.
pub const FRICTION_RANGE: std::ops::RangeInclusive<f64> = 0.05..=1.5;

/// How long a scenario's button press is held.
pub const BUTTON_PRESS_S: f64 = 0.1;

/// Why a scenario was refused.
#[derive(Clone, Debug, PartialEq)]
pub struct ScenarioError {
    /// The file, when read from one.
    pub source: String,
    /// What is wrong.
    pub message: String,
}

impl fmt::Display for ScenarioError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.source, self.message)
    }
}

impl std::error::Error for ScenarioError {}

/// Longest scenario, s.
pub const MAX_DURATION_S: f64 = 3600.0;

/// Largest scenario file read, bytes: an hour-long scenario with an input every second is
/// about 100 KB, and a larger file is not worth parsing to refuse it.
pub const MAX_SCENARIO_BYTES: u64 = 1 << 20;

/// Longest error message, characters: whatever the input, an error stays a line or two.
pub const MAX_MESSAGE_CHARS: usize = 300;

/// Characters of the offending line shown: a line this short is shown whole, a longer one
/// around the place of the error.
const SNIPPET_CHARS: usize = 60;

/// `text` cut to at most `max` characters, with an ellipsis where it was cut.
fn cut(text: &str, max: usize) -> String {
    match text.char_indices().nth(max) {
        Some((end, _)) => format!("{}…", &text[..end]),
        None => text.to_string(),
    }
}

/// A TOML syntax or type error in a line or two: its place, the key it concerns (a type
/// error's place is the value, so the key is named apart), the parser's message (its own
/// excerpt of the file, which can be as long as the file's longest line, left out), and the
/// line: whole when it is short, else a snippet around the place.
fn syntax_error(text: &str, error: &toml::de::Error) -> String {
    let message = cut(error.message().trim(), 120);
    let Some(span) = error.span() else {
        return message;
    };
    let start = span.start.min(text.len());
    let start = (0..=start)
        .rev()
        .find(|&i| text.is_char_boundary(i))
        .unwrap_or(0);
    let line_start = text[..start].rfind('\n').map_or(0, |i| i + 1);
    let line_end = text[start..].find('\n').map_or(text.len(), |i| start + i);
    let line = text[..start].matches('\n').count() + 1;
    let column = text[line_start..start].chars().count() + 1;
    let whole = text[line_start..line_end].trim();
    let shown = if whole.chars().count() <= SNIPPET_CHARS {
        whole.to_string()
    } else {
        // Up to SNIPPET_CHARS characters of the line from a little before the place.
        let from = text[line_start..start]
            .char_indices()
            .rev()
            .nth(SNIPPET_CHARS / 4)
            .map_or(line_start, |(i, _)| line_start + i);
        cut(&text[from..line_end], SNIPPET_CHARS)
    };
    let key = key_before(&text[line_start..start])
        .map(|key| match table_of(&text[..line_start]) {
            Some(table) => format!(", key {}", cut(&format!("{table}.{key}"), 60)),
            None => format!(", key {}", cut(&key, 60)),
        })
        .unwrap_or_default();
    format!("line {line}, column {column}{key}: {message} (the line: {shown})")
}

/// The table the text after `before` is in: the last `[table]` or `[[array]]` header.
fn table_of(before: &str) -> Option<&str> {
    let header = before
        .lines()
        .rev()
        .map(str::trim)
        .find(|line| line.starts_with('['))?;
    let name = header.trim_start_matches('[');
    let name = name[..name.find(']')?].trim();
    (!name.is_empty()).then_some(name)
}

/// The key whose value starts at the end of `before` (the line up to the place), as in
/// `duration_s = ` or `{ t_s = 1, kmh = `; `None` where no `key =` leads to the place.
/// Inside an inline table the key is named with the table's own key (`fault.silence`).
fn key_before(before: &str) -> Option<String> {
    let head = before.trim_end().strip_suffix('=')?.trim_end();
    let start = head
        .rfind(|c: char| !(c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.' | '"')))
        .map_or(0, |i| i + 1);
    let key = head[start..].trim_matches('"');
    if key.is_empty() {
        return None;
    }
    // The inline table the key is in, if any: the last `{` not closed before it.
    let mut depth = 0usize;
    let open = head[..start].char_indices().rev().find(|&(_, c)| {
        match c {
            '}' => depth += 1,
            '{' if depth == 0 => return true,
            '{' => depth -= 1,
            _ => {}
        }
        false
    });
    Some(match open.and_then(|(at, _)| key_before(&head[..at])) {
        Some(table) => format!("{table}.{key}"),
        None => key.to_string(),
    })
}

/// The node names a fault may name: the ECUs', as the DBC spells them.
fn node_names() -> impl Iterator<Item = &'static str> {
    autoplug_can::ECUS.iter().map(|node| node.name())
}

impl Scenario {
    /// The car's VIN: the scenario's, else one made from the seed (a fixed test-bench
    /// prefix, the check digit, and the seed's last six decimal digits as the serial), so
    /// every car has one and cars of other seeds differ.
    pub fn vin(&self) -> Vin {
        self.vin_text
            .as_deref()
            .and_then(|text| Vin::parse(text).ok())
            .unwrap_or_else(|| vin_from_seed(self.seed))
    }

    /// The version `node` left the factory with.
    pub fn factory_version(&self, node: autoplug_can::Node) -> Version {
        self.factory
            .iter()
            .find(|(name, _)| autoplug_can::parse_ecu(name) == Some(node))
            .and_then(|(_, version)| version.parse().ok())
            .unwrap_or(crate::diag::FACTORY_VERSION)
    }

    /// Reads and checks a scenario file.
    pub fn load(path: &Path) -> Result<Self, ScenarioError> {
        let source = path.display().to_string();
        let fail = |message: String| ScenarioError {
            source: source.clone(),
            message,
        };
        // Read at most one byte more than allowed: a device or a growing file (`/dev/zero`)
        // reports no size, and must not be read for ever.
        use std::io::Read as _;
        let file = std::fs::File::open(path).map_err(|e| fail(format!("cannot read: {e}")))?;
        let mut text = String::new();
        file.take(MAX_SCENARIO_BYTES + 1)
            .read_to_string(&mut text)
            .map_err(|e| fail(format!("cannot read: {e}")))?;
        if text.len() as u64 > MAX_SCENARIO_BYTES {
            return Err(fail(format!(
                "more than {MAX_SCENARIO_BYTES} bytes: a scenario file is at most that"
            )));
        }
        Self::parse_in(&text, &source, path.parent())
    }

    /// Parses and checks scenario text; `source` names it in errors. A road file the
    /// scenario names by path is read from the working directory.
    pub fn parse(text: &str, source: &str) -> Result<Self, ScenarioError> {
        Self::parse_in(text, source, None)
    }

    /// [`Scenario::parse`], reading a road file named by path from `folder` (the
    /// scenario file's).
    pub fn parse_in(
        text: &str,
        source: &str,
        folder: Option<&Path>,
    ) -> Result<Self, ScenarioError> {
        let fail = |message: String| ScenarioError {
            source: cut(source, MAX_MESSAGE_CHARS),
            message: cut(&message, MAX_MESSAGE_CHARS),
        };
        let mut scenario: Scenario =
            toml::from_str(text).map_err(|e| fail(syntax_error(text, &e)))?;
        if let Some(name) = &scenario.road.track {
            scenario.track = Some(Arc::new(read_track(name, folder).map_err(fail)?));
        }
        scenario.check().map_err(fail)?;
        Ok(scenario)
    }

    fn check(&self) -> Result<(), String> {
        fn range(what: &str, v: f64, lo: f64, hi: f64) -> Result<(), String> {
            if v.is_finite() && (lo..=hi).contains(&v) {
                Ok(())
            } else {
                Err(format!("{what} = {v} is outside {lo}..={hi}"))
            }
        }
        fn controls(
            at: &str,
            accelerator: Option<f64>,
            brake: Option<f64>,
            steering: Option<f64>,
            set_temp: Option<f64>,
        ) -> Result<(), String> {
            if let Some(v) = accelerator {
                range(&format!("{at}accelerator"), v, 0.0, 100.0)?;
            }
            if let Some(v) = brake {
                range(&format!("{at}brake"), v, 0.0, 100.0)?;
            }
            if let Some(v) = steering {
                range(&format!("{at}steering_deg"), v, -135.0, 135.0)?;
            }
            if let Some(v) = set_temp {
                range(&format!("{at}set_temp_f"), v, 50.0, 100.0)?;
            }
            Ok(())
        }
        if self.name.is_empty()
            || !self
                .name
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
        {
            return Err(format!(
                "name \"{}\": use letters, digits, '-' and '_' (it names the output folder)",
                self.name
            ));
        }
        if let Some(text) = &self.vin_text {
            Vin::parse(text).map_err(|e| format!("vin \"{text}\": {e}"))?;
        }
        for (ecu, version) in &self.factory {
            if autoplug_can::parse_ecu(ecu).is_none() {
                return Err(format!(
                    "factory.{ecu}: no such ECU (one of {})",
                    autoplug_can::ECU_NAME_LIST
                ));
            }
            version
                .parse::<Version>()
                .map_err(|e| format!("factory.{ecu} = \"{version}\": {e}"))?;
        }
        // An hour of trace stays around 30 MB in memory; longer runs belong in pieces.
        range("duration_s", self.duration_s, 0.001, MAX_DURATION_S)?;
        range(
            "road.mu_left",
            self.road.mu_left,
            *FRICTION_RANGE.start(),
            *FRICTION_RANGE.end(),
        )?;
        range(
            "road.mu_right",
            self.road.mu_right,
            *FRICTION_RANGE.start(),
            *FRICTION_RANGE.end(),
        )?;
        range("road.grade_percent", self.road.grade_percent, -30.0, 30.0)?;
        self.check_track()?;
        if let Some(v) = self.driver.speed_kmh {
            range("driver.speed_kmh", v, 0.0, 250.0)?;
        }
        range("road.ambient_c", self.road.ambient_c, -40.0, 50.0)?;
        range("road.sun_load_w", self.road.sun_load_w, 0.0, 2000.0)?;
        range("initial.speed_kmh", self.initial.speed_kmh, 0.0, 250.0)?;
        range("initial.fuel_l", self.initial.fuel_l, 0.0, 48.0)?;
        range(
            "initial.cabin_temp_f",
            self.initial.cabin_temp_f,
            0.0,
            127.5,
        )?;
        let d = &self.driver;
        controls(
            "driver.",
            d.accelerator,
            d.brake,
            d.steering_deg,
            d.set_temp_f,
        )?;
        let mut previous = 0.0;
        let mut following = self.driver.follow_road == Some(true);
        for (i, event) in self.at.iter().enumerate() {
            let at = format!("at[{i}] (t_s = {}): ", event.t_s);
            range(&format!("at[{i}].t_s"), event.t_s, 0.0, self.duration_s)?;
            if event.t_s < previous {
                return Err(format!(
                    "{at}events must be in time order (the previous one is at {previous} s)"
                ));
            }
            previous = event.t_s;
            range(&format!("{at}ramp_s"), event.ramp_s, 0.0, 3600.0)?;
            let c = event;
            controls(&at, c.accelerator, c.brake, c.steering_deg, c.set_temp_f)?;
            if let Some(v) = c.grade_percent {
                range(&format!("{at}grade_percent"), v, -30.0, 30.0)?;
                if self.track.is_some() {
                    return Err(format!(
                        "{at}grade_percent: on a track the track sets the grade"
                    ));
                }
            }
            if let Some(v) = c.speed_kmh {
                range(&format!("{at}speed_kmh"), v, 0.0, 250.0)?;
            }
            if c.follow_road == Some(true) && self.track.is_none() {
                return Err(format!(
                    "{at}follow_road: there is no road to follow (road.track)"
                ));
            }
            following = c.follow_road.unwrap_or(following);
            if following && c.steering_deg.is_some() {
                return Err(format!(
                    "{at}steering_deg: the driver follows the road here (set follow_road = false first)"
                ));
            }
            if let Some(v) = c.mu_left {
                range(
                    &format!("{at}mu_left"),
                    v,
                    *FRICTION_RANGE.start(),
                    *FRICTION_RANGE.end(),
                )?;
            }
            if let Some(v) = c.mu_right {
                range(
                    &format!("{at}mu_right"),
                    v,
                    *FRICTION_RANGE.start(),
                    *FRICTION_RANGE.end(),
                )?;
            }
            if let Some(fault) = &c.fault {
                for name in fault.silence.iter().chain(fault.restore.iter()) {
                    if !node_names().any(|n| n == name) {
                        return Err(format!(
                            "{at}fault names node \"{name}\"; the nodes are {}",
                            node_names().collect::<Vec<_>>().join(", ")
                        ));
                    }
                }
            }
        }
        Ok(())
    }

    /// The track's settings agree with the track (and there is one when they need it).
    fn check_track(&self) -> Result<(), String> {
        let Some(track) = &self.track else {
            if self.driver.follow_road == Some(true) {
                return Err("driver.follow_road: there is no road to follow (road.track)".into());
            }
            if self.road.start_m != 0.0 || self.road.lane_m != 0.0 {
                return Err(
                    "road.start_m and road.lane_m place the car on a track: road.track names none"
                        .into(),
                );
            }
            return Ok(());
        };
        let road = &track.road;
        if self.road.grade_percent != 0.0 {
            return Err(format!(
                "road.grade_percent: on a track ({}) the track sets the grade",
                track.name
            ));
        }
        let length = road.length_m();
        if !(self.road.start_m.is_finite() && (0.0..=length).contains(&self.road.start_m)) {
            return Err(format!(
                "road.start_m = {} is outside the track (0..={length:.2} m)",
                self.road.start_m
            ));
        }
        let half = road.width_m() / 2.0 - 1.0;
        if !(self.road.lane_m.is_finite() && self.road.lane_m.abs() <= half) {
            return Err(format!(
                "road.lane_m = {}: the car must start on the road (-{half}..={half} m from its centreline)",
                self.road.lane_m
            ));
        }
        Ok(())
    }
}

/// The road `name` stands for: a shipped road, or a road file (a path ending in `.toml`)
/// from `folder`.
fn read_track(name: &str, folder: Option<&Path>) -> Result<NamedRoad, String> {
    if let Some(shipped) = autoplug_road::shipped::road(name) {
        return shipped.map_err(|e| format!("road.track \"{name}\": {e}"));
    }
    if !name.ends_with(".toml") {
        return Err(format!(
            "road.track \"{}\": no such road (the shipped ones: {}; or a road file's path, *.toml)",
            cut(name, 60),
            autoplug_road::shipped::names()
        ));
    }
    let path = folder.map_or_else(|| Path::new(name).to_path_buf(), |f| f.join(name));
    autoplug_road::file::load(&path).map_err(|e| format!("road.track: {e}"))
}

/// The VIN of a car whose scenario names none: WMI `JA3` and the EVO VI's descriptor as on
/// the report's car, model year 2000 (`Y`), plant `F`, and the seed as the serial.
pub fn vin_from_seed(seed: u64) -> Vin {
    let text = format!("JA3AP47H0YF{:06}", seed % 1_000_000);
    // 17 valid characters by construction; the placeholder check digit is replaced.
    Vin::with_check_digit(&text).unwrap_or_else(|_| unreachable!("a valid VIN pattern"))
}
