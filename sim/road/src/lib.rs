//! Roads for the AutoPlug virtual car: a centreline of straights, arcs and
//! clothoids, the road's width, grade sections and friction patches (wet, icy, split
//! friction), and the queries the simulation asks of it every step: where a point lies on
//! the road (station along it, lateral offset, the road's heading there) and what surface
//! is under it.
//!
//! Every [`Segment`]'s curvature varies linearly with the distance along it: zero for a
//! straight, constant for an arc, from one to the other for a clothoid, the transition road
//! design puts between a straight and an arc so that the steering wheel turns at a steady
//! rate rather than in a step. The heading along a segment is then exact (a quadratic in
//! the distance); positions are its integral, taken by Simpson's rule every
//! [`SAMPLE_M`] (clothoids have no closed form: Fresnel integrals), and kept as samples
//! that queries interpolate. Written here rather than taken from a crate: the geometry is
//! a heading integral and a nearest-point search, and what the simulation needs from it
//! (warm-started searches, patches across part of the width, closed circuits) is its own.
//!
//! Conventions: x east, y north, metres; headings in radians from +x, counter-clockwise;
//! a positive radius or curvature turns left; lateral offsets are positive to the left of
//! the direction of travel.

use std::f64::consts::PI;
use std::fmt;

pub mod file;
pub mod follow;
pub mod shipped;

/// Spacing of the centreline's samples, m: the integration's step, and the grid the
/// nearest-point search walks (a pose between samples is integrated from the one before,
/// and a located point is refined onto the exact centreline).
pub const SAMPLE_M: f64 = 0.25;

/// The tightest radius a segment may have, m: below a car's own turning circle (the Evo
/// VI's is about 5.4 m at the kerb) a road makes no sense.
pub const MIN_RADIUS_M: f64 = 5.0;

/// The longest road, m (a bound on the samples kept: 400,000).
pub const MAX_LENGTH_M: f64 = 100_000.0;

/// How far a closed road's end may lie from its start and still close: position, m.
pub const CLOSURE_GAP_M: f64 = 0.05;

/// ... and heading, radians (0.1°).
pub const CLOSURE_HEADING_RAD: f64 = 0.1 * PI / 180.0;

/// Peak friction of dry asphalt, the road's own surface unless a patch says otherwise
/// (the vehicle model's reference: `autoplug_vehicle::Environment::mu`).
pub const DRY_ASPHALT_MU: f64 = 1.0;

/// Peak friction beyond the road's edges: grass, about 0.35 (dry) to 0.2 (wet) in the
/// tyre literature; the dry value.
pub const GRASS_MU: f64 = 0.35;

/// How far a warm-started search looks either side of its hint, m: a car at 300 km/h
/// moves 0.083 m in the simulation's 1 ms step.
const SEARCH_WINDOW_M: f64 = 8.0;

/// One piece of the centreline: its curvature goes linearly from `curvature_start` to
/// `curvature_end` (1/m, positive left) over `length_m`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Segment {
    /// Length along the centreline, m.
    pub length_m: f64,
    /// Curvature where it starts, 1/m.
    pub curvature_start: f64,
    /// Curvature where it ends, 1/m.
    pub curvature_end: f64,
}

impl Segment {
    /// A straight of `length_m`.
    pub fn straight(length_m: f64) -> Self {
        Self {
            length_m,
            curvature_start: 0.0,
            curvature_end: 0.0,
        }
    }

    /// An arc of `length_m` on `radius_m` (positive: a left-hand bend).
    pub fn arc(length_m: f64, radius_m: f64) -> Self {
        Self {
            length_m,
            curvature_start: 1.0 / radius_m,
            curvature_end: 1.0 / radius_m,
        }
    }

    /// A clothoid of `length_m` from radius `from_radius_m` to `to_radius_m` (positive
    /// left; `f64::INFINITY` for a straight's end).
    pub fn clothoid(length_m: f64, from_radius_m: f64, to_radius_m: f64) -> Self {
        Self {
            length_m,
            curvature_start: 1.0 / from_radius_m,
            curvature_end: 1.0 / to_radius_m,
        }
    }

    /// The curvature `s` metres into the segment.
    pub fn curvature_at(&self, s: f64) -> f64 {
        self.curvature_start + (self.curvature_end - self.curvature_start) * s / self.length_m
    }

    /// How far the heading has turned `s` metres into the segment, radians.
    pub fn turn_at(&self, s: f64) -> f64 {
        self.curvature_start * s
            + (self.curvature_end - self.curvature_start) * s * s / (2.0 * self.length_m)
    }

    /// The whole segment's turn, radians.
    pub fn turn(&self) -> f64 {
        self.turn_at(self.length_m)
    }

    fn check(&self, index: usize) -> Result<(), RoadError> {
        let bad = |what: String| Err(RoadError::Segment { index, what });
        if !self.length_m.is_finite() || self.length_m <= 0.0 {
            return bad(format!(
                "length {} m: a length above 0 is needed",
                self.length_m
            ));
        }
        for curvature in [self.curvature_start, self.curvature_end] {
            if !curvature.is_finite() || curvature.abs() > 1.0 / MIN_RADIUS_M {
                return bad(format!(
                    "radius {:.2} m: radii of at least {MIN_RADIUS_M} m (or a straight) are needed",
                    1.0 / curvature
                ));
            }
        }
        Ok(())
    }
}

/// A position and heading on the plane.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose {
    /// East, m.
    pub x_m: f64,
    /// North, m.
    pub y_m: f64,
    /// Heading, radians from east, counter-clockwise.
    pub heading_rad: f64,
}

/// A stretch of the road with a friction of its own, across part or all of its width.
#[derive(Clone, Debug, PartialEq)]
pub struct Patch {
    /// What it is (shown on the world view): "wet", "ice", "split-μ pad"...
    pub name: String,
    /// Where it starts and ends along the road, m (on a closed road it may run over the
    /// start: `from_m` > `to_m`).
    pub from_m: f64,
    /// See `from_m`.
    pub to_m: f64,
    /// Its right and left edges, m from the centreline (positive left): the right half of
    /// the road is `-width/2 ..= 0`.
    pub right_m: f64,
    /// See `right_m`.
    pub left_m: f64,
    /// Its peak friction coefficient.
    pub mu: f64,
}

/// A stretch of constant grade.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Grade {
    /// Where it starts along the road, m.
    pub from_m: f64,
    /// Where it ends, m.
    pub to_m: f64,
    /// Rise per 100 m of run, positive uphill in the road's direction.
    pub percent: f64,
}

/// Where a point lies relative to the road.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Location {
    /// Distance along the centreline of the nearest centreline point, m.
    pub station_m: f64,
    /// Offset from the centreline, m, positive to the left.
    pub lateral_m: f64,
    /// The road's heading there, radians.
    pub heading_rad: f64,
}

/// The surface under a point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Surface {
    /// Where the point is.
    pub location: Location,
    /// Whether it is between the road's edges.
    pub on_road: bool,
    /// Peak friction coefficient.
    pub mu: f64,
    /// The patch it is on (an index into [`Road::patches`]); `None` on the plain road
    /// and off it.
    pub patch: Option<usize>,
    /// The road's grade there, percent, in the road's direction.
    pub grade_percent: f64,
}

impl Surface {
    /// The grade a car heading `heading_rad` meets, percent: the road's grade times the
    /// cosine between the car's heading and the road's (uphill ahead positive), which is
    /// what `autoplug_vehicle::Environment::grade_percent` takes.
    pub fn grade_along(&self, heading_rad: f64) -> f64 {
        if self.grade_percent == 0.0 {
            // Most of a road is level: no cosine to take.
            return 0.0;
        }
        self.grade_percent * (heading_rad - self.location.heading_rad).cos()
    }
}

/// Why a road description was refused.
#[derive(Clone, Debug, PartialEq)]
pub enum RoadError {
    /// No segments.
    Empty,
    /// A segment that cannot be driven.
    Segment {
        /// Its index, from 0.
        index: usize,
        /// What is wrong.
        what: String,
    },
    /// The width.
    Width(f64),
    /// The whole road is too long.
    TooLong(f64),
    /// The start pose has a non-finite number.
    Start,
    /// A patch.
    Patch {
        /// Its index, from 0.
        index: usize,
        /// What is wrong.
        what: String,
    },
    /// A grade section.
    Grade {
        /// Its index, from 0.
        index: usize,
        /// What is wrong.
        what: String,
    },
    /// A closed road whose end does not meet its start.
    NotClosed {
        /// The gap, m.
        gap_m: f64,
        /// The heading error, degrees.
        heading_deg: f64,
    },
    /// A closed road whose grades do not come back to its start's height.
    HeightNotClosed {
        /// The rise over the lap, m.
        rise_m: f64,
    },
}

impl fmt::Display for RoadError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            RoadError::Empty => write!(f, "a road needs at least one segment"),
            RoadError::Segment { index, what } => write!(f, "segment {}: {what}", index + 1),
            RoadError::Width(w) => write!(f, "width {w} m: a width from 2 to 50 m is needed"),
            RoadError::TooLong(l) => write!(
                f,
                "the road is {l:.0} m long: at most {MAX_LENGTH_M:.0} m"
            ),
            RoadError::Start => write!(f, "the start position and heading must be numbers"),
            RoadError::Patch { index, what } => write!(f, "patch {}: {what}", index + 1),
            RoadError::Grade { index, what } => write!(f, "grade {}: {what}", index + 1),
            RoadError::NotClosed { gap_m, heading_deg } => write!(
                f,
                "a closed road must end where it starts: its end is {gap_m:.2} m and {:.2}° off (at most {CLOSURE_GAP_M} m and 0.1°)",
                heading_deg.abs()
            ),
            RoadError::HeightNotClosed { rise_m } => write!(
                f,
                "a closed road's grades must bring it back to its start's height: a lap rises {rise_m:.2} m"
            ),
        }
    }
}

impl std::error::Error for RoadError {}

/// A centreline sample, with its heading's cosine and sine (a query turns them by the
/// small angle to its station rather than calling the trigonometric functions).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Sample {
    s: f64,
    x: f64,
    y: f64,
    heading: f64,
    cos: f64,
    sin: f64,
}

impl Sample {
    fn new(s: f64, x: f64, y: f64, heading: f64) -> Self {
        let (sin, cos) = heading.sin_cos();
        Self {
            s,
            x,
            y,
            heading,
            cos,
            sin,
        }
    }

    /// The direction (cosine, sine) at `delta` radians from this sample's heading, for
    /// the small angles a query turns by within a sample step (at most the tightest
    /// curvature times [`SAMPLE_M`], 0.05 rad): Taylor series to the 9th power, whose
    /// remainder (below 3e-20) is far under an f64's rounding.
    fn turned(&self, delta: f64) -> (f64, f64) {
        // Horner's form with the reciprocals as constants: divisions would chain.
        const C: [f64; 4] = [1.0 / 2.0, 1.0 / 12.0, 1.0 / 30.0, 1.0 / 56.0];
        const S: [f64; 4] = [1.0 / 6.0, 1.0 / 20.0, 1.0 / 42.0, 1.0 / 72.0];
        let d2 = delta * delta;
        let cos_d = 1.0 - d2 * C[0] * (1.0 - d2 * C[1] * (1.0 - d2 * C[2] * (1.0 - d2 * C[3])));
        let sin_d =
            delta * (1.0 - d2 * S[0] * (1.0 - d2 * S[1] * (1.0 - d2 * S[2] * (1.0 - d2 * S[3]))));
        (
            self.cos * cos_d - self.sin * sin_d,
            self.sin * cos_d + self.cos * sin_d,
        )
    }
}

/// Where a segment's samples are: the index of the sample at its start and the spacing
/// of those after it (a station's sample is then found by division, not a search).
#[derive(Clone, Copy, Debug, PartialEq)]
struct SampleRun {
    first: usize,
    steps: usize,
    /// 1 / the spacing, 1/m.
    per_m: f64,
    /// How fast the curvature changes, halved: (κ_end − κ_start) / (2·length), 1/m².
    half_rate: f64,
}

/// A road: its centreline, width, surfaces and grades.
#[derive(Clone, Debug, PartialEq)]
pub struct Road {
    start: Pose,
    segments: Vec<Segment>,
    /// Where each segment starts along the road, m.
    segment_starts: Vec<f64>,
    /// The heading where each segment starts, radians (queries run every step).
    segment_headings: Vec<f64>,
    /// Each segment's samples.
    segment_samples: Vec<SampleRun>,
    width_m: f64,
    closed: bool,
    patches: Vec<Patch>,
    grades: Vec<Grade>,
    samples: Vec<Sample>,
    length_m: f64,
}

impl Road {
    /// An open road from `start` along `segments`, `width_m` wide (2 to 50 m), dry
    /// asphalt, level.
    pub fn new(start: Pose, segments: Vec<Segment>, width_m: f64) -> Result<Self, RoadError> {
        if segments.is_empty() {
            return Err(RoadError::Empty);
        }
        if ![start.x_m, start.y_m, start.heading_rad]
            .iter()
            .all(|v| v.is_finite())
        {
            return Err(RoadError::Start);
        }
        if !(2.0..=50.0).contains(&width_m) {
            return Err(RoadError::Width(width_m));
        }
        for (index, segment) in segments.iter().enumerate() {
            segment.check(index)?;
        }
        let length_m: f64 = segments.iter().map(|s| s.length_m).sum();
        if length_m > MAX_LENGTH_M {
            return Err(RoadError::TooLong(length_m));
        }
        let mut segment_starts = Vec::with_capacity(segments.len());
        let mut segment_headings = Vec::with_capacity(segments.len());
        let mut segment_samples = Vec::with_capacity(segments.len());
        let mut samples = Vec::with_capacity((length_m / SAMPLE_M) as usize + segments.len() + 1);
        let (mut x, mut y, mut heading, mut s0) = (start.x_m, start.y_m, start.heading_rad, 0.0);
        samples.push(Sample::new(0.0, x, y, heading));
        for segment in &segments {
            segment_starts.push(s0);
            segment_headings.push(heading);
            let steps = (segment.length_m / SAMPLE_M).ceil().max(1.0) as usize;
            let step = segment.length_m / steps as f64;
            segment_samples.push(SampleRun {
                first: samples.len() - 1,
                steps,
                per_m: 1.0 / step,
                half_rate: (segment.curvature_end - segment.curvature_start)
                    / (2.0 * segment.length_m),
            });
            let base = heading;
            for i in 0..steps {
                let (a, b) = (i as f64 * step, (i + 1) as f64 * step);
                let m = 0.5 * (a + b);
                // Simpson's rule on each step: the heading is a quadratic in s, its cosine
                // and sine smooth; the error per step is O(step^5 k^4).
                let h = |s: f64| base + segment.turn_at(s);
                let (ha, hm, hb) = (h(a), h(m), h(b));
                x += step / 6.0 * (ha.cos() + 4.0 * hm.cos() + hb.cos());
                y += step / 6.0 * (ha.sin() + 4.0 * hm.sin() + hb.sin());
                samples.push(Sample::new(s0 + b, x, y, hb));
            }
            heading = base + segment.turn();
            s0 += segment.length_m;
        }
        Ok(Self {
            start,
            segments,
            segment_starts,
            segment_headings,
            segment_samples,
            width_m,
            closed: false,
            patches: Vec::new(),
            grades: Vec::new(),
            samples,
            length_m,
        })
    }

    /// The same road as a closed circuit: its end must meet its start (within
    /// [`CLOSURE_GAP_M`] and 0.1°, the heading modulo a full turn), and its grades must
    /// bring it back to the start's height.
    pub fn closed(mut self) -> Result<Self, RoadError> {
        let end = self.samples[self.samples.len() - 1];
        let gap_m = (end.x - self.start.x_m).hypot(end.y - self.start.y_m);
        let turned = end.heading - self.start.heading_rad;
        let heading_error = turned - (turned / (2.0 * PI)).round() * 2.0 * PI;
        if gap_m > CLOSURE_GAP_M || heading_error.abs() > CLOSURE_HEADING_RAD {
            return Err(RoadError::NotClosed {
                gap_m,
                heading_deg: heading_error.to_degrees(),
            });
        }
        // Before it is closed, the end's station is the lap's length (closed, it wraps to 0).
        let rise_m = self.height_at(self.length_m);
        if rise_m.abs() > 0.01 {
            return Err(RoadError::HeightNotClosed { rise_m });
        }
        self.closed = true;
        Ok(self)
    }

    /// Adds a friction patch (later patches lie on top of earlier ones).
    pub fn with_patch(mut self, patch: Patch) -> Result<Self, RoadError> {
        let index = self.patches.len();
        let bad = |what: String| RoadError::Patch { index, what };
        if !patch.mu.is_finite() || !(0.01..=2.0).contains(&patch.mu) {
            return Err(bad(format!(
                "friction {}: from 0.01 to 2 is needed",
                patch.mu
            )));
        }
        let half = self.width_m / 2.0;
        if !(patch.right_m.is_finite() && patch.left_m.is_finite())
            || patch.right_m >= patch.left_m
            || patch.right_m < -half
            || patch.left_m > half
        {
            return Err(bad(format!(
                "from {} m to {} m across: a range within the road's {} m, right edge first",
                patch.right_m, patch.left_m, self.width_m
            )));
        }
        self.check_stretch(patch.from_m, patch.to_m, self.closed)
            .map_err(bad)?;
        self.patches.push(patch);
        Ok(self)
    }

    /// Adds a grade section (later sections replace earlier ones where they overlap).
    pub fn with_grade(mut self, grade: Grade) -> Result<Self, RoadError> {
        let index = self.grades.len();
        let bad = |what: String| RoadError::Grade { index, what };
        if !grade.percent.is_finite() || grade.percent.abs() > 30.0 {
            return Err(bad(format!("{} %: at most 30 % either way", grade.percent)));
        }
        self.check_stretch(grade.from_m, grade.to_m, false)
            .map_err(bad)?;
        self.grades.push(grade);
        Ok(self)
    }

    fn check_stretch(&self, from_m: f64, to_m: f64, may_wrap: bool) -> Result<(), String> {
        let within = |s: f64| s.is_finite() && (0.0..=self.length_m).contains(&s);
        if !within(from_m) || !within(to_m) || (from_m >= to_m && !may_wrap) || from_m == to_m {
            return Err(format!(
                "from {from_m} m to {to_m} m along: a stretch within the road's {:.1} m",
                self.length_m
            ));
        }
        Ok(())
    }

    /// Length of the centreline, m.
    pub fn length_m(&self) -> f64 {
        self.length_m
    }

    /// Width, m.
    pub fn width_m(&self) -> f64 {
        self.width_m
    }

    /// Whether it is a closed circuit.
    pub fn is_closed(&self) -> bool {
        self.closed
    }

    /// Its segments.
    pub fn segments(&self) -> &[Segment] {
        &self.segments
    }

    /// Its friction patches.
    pub fn patches(&self) -> &[Patch] {
        &self.patches
    }

    /// Its grade sections.
    pub fn grades(&self) -> &[Grade] {
        &self.grades
    }

    /// A station on the road: wrapped onto the lap on a closed road, clamped to the ends
    /// on an open one.
    pub fn wrap(&self, station_m: f64) -> f64 {
        if self.closed {
            station_m.rem_euclid(self.length_m)
        } else {
            station_m.clamp(0.0, self.length_m)
        }
    }

    /// The centreline's pose at `station_m` (see [`Road::wrap`]): from the sample before it,
    /// one step of Simpson's rule (samples fall on every segment's ends, so the step lies
    /// within one segment).
    pub fn pose_at(&self, station_m: f64) -> Pose {
        self.pose_and_direction_at(station_m).0
    }

    /// The centreline's position at `station_m` (see [`Road::wrap`]) with its direction's
    /// cosine and sine: [`Road::pose_at`] without the trigonometry a caller would do.
    pub(crate) fn pose_and_direction_at(&self, station_m: f64) -> (Pose, (f64, f64)) {
        let s = self.wrap(station_m);
        let point = self.centre_at(self.segment_index(s), s);
        (
            Pose {
                x_m: point.x,
                y_m: point.y,
                heading_rad: point.heading,
            },
            (point.cos, point.sin),
        )
    }

    /// The road's heading at `station_m`, exact (from the segment's curvature).
    pub fn heading_at(&self, station_m: f64) -> f64 {
        let s = self.wrap(station_m);
        let k = self.segment_index(s);
        self.segment_headings[k] + self.segments[k].turn_at(s - self.segment_starts[k])
    }

    /// The curvature at `station_m`, 1/m.
    pub fn curvature_at(&self, station_m: f64) -> f64 {
        let s = self.wrap(station_m);
        let k = self.segment_index(s);
        self.segments[k].curvature_at(s - self.segment_starts[k])
    }

    /// The height of the centreline at `station_m` over the start's, m (the grades'
    /// integral).
    pub fn height_at(&self, station_m: f64) -> f64 {
        let s = self.wrap(station_m);
        // Later sections replace earlier ones: walk the stretch in pieces between the
        // sections' ends and take each piece's grade from its middle.
        let mut cuts: Vec<f64> = self
            .grades
            .iter()
            .flat_map(|g| [g.from_m, g.to_m])
            .filter(|&c| c > 0.0 && c < s)
            .collect();
        cuts.push(0.0);
        cuts.push(s);
        cuts.sort_by(f64::total_cmp);
        cuts.windows(2)
            .map(|w| (w[1] - w[0]) * self.grade_at(0.5 * (w[0] + w[1])) / 100.0)
            .sum()
    }

    /// The grade at `station_m`, percent.
    pub fn grade_at(&self, station_m: f64) -> f64 {
        let s = self.wrap(station_m);
        self.grades
            .iter()
            .rev()
            .find(|g| (g.from_m..g.to_m).contains(&s))
            .map_or(0.0, |g| g.percent)
    }

    /// Where the point (`x_m`, `y_m`) lies: the nearest point of the centreline. `near`: a
    /// station it was near a moment ago (a car moves millimetres in a step, so the search
    /// starts there and takes a few Newton steps; when the point has left that
    /// neighbourhood, the samples around it are searched, and without one, or when the
    /// point is further still, the whole road).
    pub fn locate(&self, x_m: f64, y_m: f64, near: Option<f64>) -> Location {
        let near = near.filter(|s| s.is_finite()).map(|s| self.wrap(s));
        if let Some(near) = near {
            if let Some(found) = self.refine(x_m, y_m, near) {
                if self.distance_along(found.station_m, near) < SEARCH_WINDOW_M {
                    return found;
                }
            }
        }
        let n = self.samples.len();
        let nearest = |range: &mut dyn Iterator<Item = usize>| {
            range
                .map(|i| {
                    let p = self.samples[i];
                    (i, (p.x - x_m).powi(2) + (p.y - y_m).powi(2))
                })
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .map(|(i, _)| i)
        };
        let window = (SEARCH_WINDOW_M / SAMPLE_M) as isize;
        let mut best = None;
        if let Some(near) = near {
            let centre = self.sample_index(near) as isize;
            let mut indices = (centre - window..=centre + window).filter_map(|i| {
                if self.closed {
                    Some(i.rem_euclid(n as isize - 1) as usize)
                } else {
                    (0..n as isize).contains(&i).then_some(i as usize)
                }
            });
            let found = nearest(&mut indices);
            // At the window's edge the point may be nearer elsewhere: search it all.
            best = found.filter(|&i| {
                let offset = (i as isize - centre).rem_euclid(n as isize - 1);
                let offset = offset.min(n as isize - 1 - offset);
                offset < window || (!self.closed && (i == 0 || i == n - 1))
            });
        }
        let i = best.unwrap_or_else(|| nearest(&mut (0..n)).unwrap_or(0));
        let on_chord = self.project(i, x_m, y_m);
        // The chord leaves the curve by up to Δs²/8r (1.6 mm on a 5 m radius): Newton's
        // steps onto the exact centreline, then the offset along its normal.
        self.refine(x_m, y_m, on_chord)
            .unwrap_or_else(|| self.location_at(x_m, y_m, on_chord))
    }

    /// The nearest centreline point to (`x_m`, `y_m`) by Newton's method on the distance's
    /// derivative, from station `from_m`: `None` where it does not settle (the point near a
    /// bend's centre of curvature, where the nearest point is ill defined or far away).
    /// Along a straight one step is exact; in a bend each step squares the error.
    fn refine(&self, x_m: f64, y_m: f64, from_m: f64) -> Option<Location> {
        const MAX_STEPS: usize = 8;
        // Below this, a step moves the station by less than rounding moves the point.
        const SETTLED_M: f64 = 1e-9;
        // A step this small is the last one needed (see below).
        const FINAL_STEP_M: f64 = 1e-4;
        let mut s = from_m;
        let mut k = self.segment_index(s);
        for _ in 0..MAX_STEPS {
            let c = self.centre_at(k, s);
            let (dx, dy) = (x_m - c.x, y_m - c.y);
            let along = dx * c.cos + dy * c.sin;
            let lateral = dy * c.cos - dx * c.sin;
            // d(along)/ds = -(1 - κ·lateral): it vanishes at the centre of curvature.
            let stiffness = 1.0 - c.curvature * lateral;
            if stiffness < 0.25 {
                return None;
            }
            let step = along / stiffness;
            if step.abs() < FINAL_STEP_M {
                // The last step, taken without evaluating the centreline again: the
                // station's error after it is about κ·step² and the lateral offset is
                // stationary at the nearest point (its error about κ·step²/2), both far
                // below a micrometre.
                let station = s + step;
                if self.closed || (0.0..=self.length_m).contains(&station) {
                    return Some(Location {
                        station_m: if self.closed {
                            self.wrap(station)
                        } else {
                            station
                        },
                        lateral_m: lateral,
                        heading_rad: c.heading + c.curvature * step,
                    });
                }
            }
            let next = if self.closed {
                self.wrap(s + step)
            } else {
                (s + step).clamp(0.0, self.length_m)
            };
            let moved = if self.closed {
                step.abs()
            } else {
                (next - s).abs()
            };
            if moved < SETTLED_M {
                return Some(Location {
                    station_m: s,
                    lateral_m: lateral,
                    heading_rad: c.heading,
                });
            }
            s = next;
            k = self.segment_near(k, s);
        }
        None
    }

    /// Where the point lies seen from the centreline at station `s`.
    fn location_at(&self, x_m: f64, y_m: f64, s: f64) -> Location {
        let c = self.centre_at(self.segment_index(s), s);
        Location {
            station_m: s,
            lateral_m: (y_m - c.y) * c.cos - (x_m - c.x) * c.sin,
            heading_rad: c.heading,
        }
    }

    /// How far apart two stations are along the road (around the lap's end on a closed
    /// road).
    fn distance_along(&self, a: f64, b: f64) -> f64 {
        let d = (a - b).abs();
        if self.closed {
            d.min(self.length_m - d)
        } else {
            d
        }
    }

    /// The station of the point projected onto the chords either side of sample `i`.
    fn project(&self, i: usize, x_m: f64, y_m: f64) -> f64 {
        let n = self.samples.len();
        let mut best: Option<(f64, f64)> = None;
        for (a, b) in [
            (i.checked_sub(1), Some(i)),
            (Some(i), (i + 1 < n).then_some(i + 1)),
        ] {
            let (Some(a), Some(b)) = (a, b) else { continue };
            let (pa, pb) = (self.samples[a], self.samples[b]);
            let (dx, dy) = (pb.x - pa.x, pb.y - pa.y);
            let chord = dx * dx + dy * dy;
            if chord == 0.0 {
                continue;
            }
            let t = (((x_m - pa.x) * dx + (y_m - pa.y) * dy) / chord).clamp(0.0, 1.0);
            let distance = (x_m - pa.x - dx * t).hypot(y_m - pa.y - dy * t);
            if best.is_none_or(|(d, _)| distance < d) {
                best = Some((distance, pa.s + (pb.s - pa.s) * t));
            }
        }
        best.map_or(self.samples[i].s, |(_, station)| station)
    }

    /// The surface under the point (`x_m`, `y_m`); `near` as for [`Road::locate`].
    pub fn surface(&self, x_m: f64, y_m: f64, near: Option<f64>) -> Surface {
        let location = self.locate(x_m, y_m, near);
        let half = self.width_m / 2.0;
        let on_road = location.lateral_m.abs() <= half && !self.beyond_an_end(x_m, y_m, &location);
        let patch = if on_road {
            self.patches
                .iter()
                .rposition(|p| self.patch_covers(p, &location))
        } else {
            None
        };
        let mu = match patch {
            Some(i) => self.patches[i].mu,
            None if on_road => DRY_ASPHALT_MU,
            None => GRASS_MU,
        };
        Surface {
            location,
            on_road,
            mu,
            patch,
            grade_percent: self.grade_at(location.station_m),
        }
    }

    /// Whether the point lies past the start or the end of an open road (where the
    /// nearest centreline point is the end itself): off the road, whatever its offset.
    fn beyond_an_end(&self, x_m: f64, y_m: f64, at: &Location) -> bool {
        // Between the ends (nearly every query) there is nothing to work out.
        if self.closed || (at.station_m > 0.0 && at.station_m < self.length_m) {
            return false;
        }
        let (sin, cos) = at.heading_rad.sin_cos();
        let end = |station: f64| {
            let p = self.pose_at(station);
            (x_m - p.x_m) * cos + (y_m - p.y_m) * sin
        };
        (at.station_m <= 0.0 && end(0.0) < -1e-6)
            || (at.station_m >= self.length_m && end(self.length_m) > 1e-6)
    }

    fn patch_covers(&self, patch: &Patch, at: &Location) -> bool {
        let s = at.station_m;
        let along = if patch.from_m < patch.to_m {
            (patch.from_m..=patch.to_m).contains(&s)
        } else {
            s >= patch.from_m || s <= patch.to_m
        };
        along && (patch.right_m..=patch.left_m).contains(&at.lateral_m)
    }

    /// The index of the last sample at or before `s` (a station within the road).
    fn sample_index(&self, s: f64) -> usize {
        self.sample_in(self.segment_index(s), s)
    }

    /// The index of the sample at or before `s` within segment `k` (by division: a
    /// segment's samples are evenly spaced).
    fn sample_in(&self, k: usize, s: f64) -> usize {
        let run = self.segment_samples[k];
        // `as` truncates towards 0 and saturates: below 0 (rounding at the segment's
        // start) and NaN give 0.
        let j = ((s - self.segment_starts[k]) * run.per_m) as usize;
        run.first + j.min(run.steps - 1)
    }

    /// The index of the segment `s` is in.
    fn segment_index(&self, s: f64) -> usize {
        self.segment_starts
            .partition_point(|&start| start <= s)
            .saturating_sub(1)
    }

    /// The segment `s` is in, looked for from segment `k` (a query's next station is
    /// almost always in the same segment or the next).
    fn segment_near(&self, k: usize, s: f64) -> usize {
        let last = self.segments.len() - 1;
        let starts = |k: usize| self.segment_starts[k];
        if s >= starts(k) && (k == last || s < starts(k + 1)) {
            k
        } else if k < last && s >= starts(k + 1) && (k + 1 == last || s < starts(k + 2)) {
            k + 1
        } else {
            self.segment_index(s)
        }
    }

    /// The centreline at station `s` (within the road) of segment `k`: Simpson's rule over
    /// the step from the sample before it, the directions turned from the sample's by the
    /// heading's exact change (a quadratic in the distance).
    fn centre_at(&self, k: usize, s: f64) -> CentrePoint {
        let k0 = self.segments[k].curvature_start;
        let run = self.segment_samples[k];
        let a = self.samples[self.sample_in(k, s)];
        let u = a.s - self.segment_starts[k];
        let h = s - a.s;
        if k0 == 0.0 && run.half_rate == 0.0 {
            // A straight: the sample's direction, carried on.
            return CentrePoint {
                x: a.x + h * a.cos,
                y: a.y + h * a.sin,
                heading: a.heading,
                cos: a.cos,
                sin: a.sin,
                curvature: 0.0,
            };
        }
        // The turn from the sample to `t` further on: κ0·t + rate/2·((u + t)² − u²).
        let turn = |t: f64| t * (k0 + run.half_rate * (2.0 * u + t));
        let (cos_m, sin_m) = a.turned(turn(0.5 * h));
        let end_turn = turn(h);
        let (cos, sin) = a.turned(end_turn);
        let sixth = h * (1.0 / 6.0);
        CentrePoint {
            x: a.x + sixth * (a.cos + 4.0 * cos_m + cos),
            y: a.y + sixth * (a.sin + 4.0 * sin_m + sin),
            heading: a.heading + end_turn,
            cos,
            sin,
            curvature: k0 + 2.0 * run.half_rate * (u + h),
        }
    }
}

/// A point of the centreline with its direction and curvature.
#[derive(Clone, Copy, Debug)]
struct CentrePoint {
    x: f64,
    y: f64,
    heading: f64,
    cos: f64,
    sin: f64,
    curvature: f64,
}

#[cfg(test)]
mod tests;
