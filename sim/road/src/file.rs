//! Roads as files (`roads/*.toml`), the form scenarios name them in:
//!
//! ```toml
//! name = "handling circuit"
//! width_m = 10
//! closed = true                                  # the end must meet the start
//! start = { x_m = 0, y_m = 0, heading_deg = 0 }  # optional: the origin, heading east
//!
//! [[segment]]
//! straight_m = 600
//! [[segment]]
//! bend = { radius_m = 60, turn_deg = 180, transition_m = 40 }  # eased in and out
//! [[segment]]
//! arc = { radius_m = -90, turn_deg = 35 }        # negative radius: a right-hand bend
//! [[segment]]
//! clothoid = { length_m = 25, from_radius_m = 90 }  # a missing radius: straight
//!
//! [[patch]]                                      # friction across part of the width
//! name = "split-μ pad"
//! from_m = 250
//! to_m = 370
//! right_m = -5                                   # lateral offsets, positive left
//! left_m = 0
//! mu = 0.15
//!
//! [[grade]]
//! from_m = 760
//! to_m = 860
//! percent = 6
//! ```
//!
//! A `bend` is a clothoid of `transition_m` into the radius, the arc, and a clothoid out,
//! `turn_deg` in all: the usual road curve, and symmetric, so two equal hairpins and two
//! equal straights close a lap exactly.

use std::path::Path;

use serde::Deserialize;

use crate::{Grade, Patch, Pose, Road, RoadError, Segment};

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RoadFile {
    name: String,
    width_m: f64,
    #[serde(default)]
    closed: bool,
    #[serde(default)]
    start: Option<StartFile>,
    #[serde(default)]
    segment: Vec<SegmentFile>,
    #[serde(default)]
    patch: Vec<PatchFile>,
    #[serde(default)]
    grade: Vec<GradeFile>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct StartFile {
    x_m: f64,
    y_m: f64,
    heading_deg: f64,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SegmentFile {
    straight_m: Option<f64>,
    arc: Option<ArcFile>,
    bend: Option<BendFile>,
    clothoid: Option<ClothoidFile>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ArcFile {
    radius_m: f64,
    turn_deg: f64,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct BendFile {
    radius_m: f64,
    turn_deg: f64,
    transition_m: f64,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ClothoidFile {
    length_m: f64,
    from_radius_m: Option<f64>,
    to_radius_m: Option<f64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct PatchFile {
    name: String,
    from_m: f64,
    to_m: f64,
    right_m: f64,
    left_m: f64,
    mu: f64,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct GradeFile {
    from_m: f64,
    to_m: f64,
    percent: f64,
}

/// A road read from a file, with its name.
#[derive(Clone, Debug, PartialEq)]
pub struct NamedRoad {
    /// What the file calls it.
    pub name: String,
    /// The road.
    pub road: Road,
}

/// Why a road file was refused: the file, and what is wrong.
#[derive(Debug)]
pub struct RoadFileError {
    /// The file (or the name given to [`parse`]).
    pub origin: String,
    /// What is wrong.
    pub message: String,
}

impl std::fmt::Display for RoadFileError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}: {}", self.origin, self.message)
    }
}

impl std::error::Error for RoadFileError {}

/// Largest road file read, bytes: a road of a few hundred segments and patches is a few
/// tens of kilobytes, and a larger file is not worth parsing to refuse it.
pub const MAX_ROAD_FILE_BYTES: u64 = 1 << 20;

/// Reads a road file.
pub fn load(path: &Path) -> Result<NamedRoad, RoadFileError> {
    use std::io::Read as _;
    let origin = path.display().to_string();
    let error = |message: String| RoadFileError {
        origin: origin.clone(),
        message,
    };
    // At most one byte more than allowed: a device or a growing file reports no size.
    let file = std::fs::File::open(path).map_err(|e| error(format!("cannot read: {e}")))?;
    let mut text = String::new();
    file.take(MAX_ROAD_FILE_BYTES + 1)
        .read_to_string(&mut text)
        .map_err(|e| error(format!("cannot read: {e}")))?;
    if text.len() as u64 > MAX_ROAD_FILE_BYTES {
        return Err(error(format!(
            "more than {MAX_ROAD_FILE_BYTES} bytes: a road file is at most that"
        )));
    }
    parse(&text, &origin)
}

/// Parses a road file's text; `origin` names it in errors.
pub fn parse(text: &str, origin: &str) -> Result<NamedRoad, RoadFileError> {
    let error = |message: String| RoadFileError {
        origin: origin.to_string(),
        message,
    };
    let file: RoadFile = toml::from_str(text).map_err(|e| error(e.to_string()))?;
    let start = file.start.map_or(
        Pose {
            x_m: 0.0,
            y_m: 0.0,
            heading_rad: 0.0,
        },
        |s| Pose {
            x_m: s.x_m,
            y_m: s.y_m,
            heading_rad: s.heading_deg.to_radians(),
        },
    );
    let mut segments = Vec::new();
    for (index, segment) in file.segment.into_iter().enumerate() {
        let entry = pieces(segment)
            .map_err(|what| error(RoadError::Segment { index, what }.to_string()))?;
        for piece in &entry {
            piece.check(index).map_err(|e| error(e.to_string()))?;
        }
        segments.extend(entry);
    }
    let road_error = |e: RoadError| error(e.to_string());
    let mut road = Road::new(start, segments, file.width_m).map_err(road_error)?;
    for grade in file.grade {
        road = road
            .with_grade(Grade {
                from_m: grade.from_m,
                to_m: grade.to_m,
                percent: grade.percent,
            })
            .map_err(road_error)?;
    }
    if file.closed {
        road = road.closed().map_err(road_error)?;
    }
    for patch in file.patch {
        road = road
            .with_patch(Patch {
                name: patch.name,
                from_m: patch.from_m,
                to_m: patch.to_m,
                right_m: patch.right_m,
                left_m: patch.left_m,
                mu: patch.mu,
            })
            .map_err(road_error)?;
    }
    Ok(NamedRoad {
        name: file.name,
        road,
    })
}

/// The segments one entry of the file stands for.
fn pieces(segment: SegmentFile) -> Result<Vec<Segment>, String> {
    let radius = |r: f64| -> Result<f64, String> {
        if r.is_finite() && r != 0.0 {
            Ok(r)
        } else {
            Err(format!("radius {r} m: a radius other than 0 is needed"))
        }
    };
    let turn = |deg: f64| -> Result<f64, String> {
        if deg.is_finite() && deg > 0.0 && deg <= 360.0 {
            Ok(deg.to_radians())
        } else {
            Err(format!("turn {deg}°: from above 0 to 360° is needed"))
        }
    };
    match segment {
        SegmentFile {
            straight_m: Some(length),
            arc: None,
            bend: None,
            clothoid: None,
        } => Ok(vec![Segment::straight(length)]),
        SegmentFile {
            straight_m: None,
            arc: Some(arc),
            bend: None,
            clothoid: None,
        } => {
            let r = radius(arc.radius_m)?;
            Ok(vec![Segment::arc(r.abs() * turn(arc.turn_deg)?, r)])
        }
        SegmentFile {
            straight_m: None,
            arc: None,
            bend: Some(bend),
            clothoid: None,
        } => {
            let r = radius(bend.radius_m)?;
            let total = turn(bend.turn_deg)?;
            let transition = bend.transition_m;
            // The two clothoids turn transition/r between them; the arc does the rest.
            let arc = r.abs() * total - transition;
            if !transition.is_finite() || transition <= 0.0 || arc <= 0.0 {
                return Err(format!(
                    "transition {transition} m: above 0 and below {:.1} m (the bend's length on its radius) is needed",
                    r.abs() * total
                ));
            }
            Ok(vec![
                Segment::clothoid(transition, f64::INFINITY, r),
                Segment::arc(arc, r),
                Segment::clothoid(transition, r, f64::INFINITY),
            ])
        }
        SegmentFile {
            straight_m: None,
            arc: None,
            bend: None,
            clothoid: Some(c),
        } => {
            let from = c
                .from_radius_m
                .map(radius)
                .transpose()?
                .unwrap_or(f64::INFINITY);
            let to = c
                .to_radius_m
                .map(radius)
                .transpose()?
                .unwrap_or(f64::INFINITY);
            Ok(vec![Segment::clothoid(c.length_m, from, to)])
        }
        _ => Err("give exactly one of straight_m, arc, bend or clothoid".into()),
    }
}
