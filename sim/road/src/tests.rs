use super::*;
use proptest::prelude::*;

const ORIGIN: Pose = Pose {
    x_m: 0.0,
    y_m: 0.0,
    heading_rad: 0.0,
};

fn close(a: f64, b: f64, tolerance: f64) -> bool {
    (a - b).abs() <= tolerance
}

/// A stadium: two straights of `straight_m` joined by two left hairpins of radius
/// `radius_m`, each eased in and out by clothoids of `transition_m`. Symmetric hairpins
/// bring the road back exactly where it started.
fn stadium(straight_m: f64, radius_m: f64, transition_m: f64) -> Vec<Segment> {
    let arc_m = PI * radius_m - transition_m;
    let hairpin = [
        Segment::clothoid(transition_m, f64::INFINITY, radius_m),
        Segment::arc(arc_m, radius_m),
        Segment::clothoid(transition_m, radius_m, f64::INFINITY),
    ];
    let mut segments = vec![Segment::straight(straight_m)];
    segments.extend(hairpin);
    segments.push(Segment::straight(straight_m));
    segments.extend(hairpin);
    segments
}

#[test]
fn a_straight_is_where_its_heading_points() {
    let start = Pose {
        x_m: 10.0,
        y_m: -5.0,
        heading_rad: PI / 2.0,
    };
    let road = Road::new(start, vec![Segment::straight(100.0)], 8.0).unwrap();
    assert_eq!(road.length_m(), 100.0);
    let p = road.pose_at(40.0);
    assert!(
        close(p.x_m, 10.0, 1e-9) && close(p.y_m, 35.0, 1e-9),
        "{p:?}"
    );
    // North-bound: west is on the left.
    let at = road.locate(7.0, 20.0, None);
    assert!(close(at.station_m, 25.0, 1e-9), "{at:?}");
    assert!(close(at.lateral_m, 3.0, 1e-9), "{at:?}");
    assert!(close(at.heading_rad, PI / 2.0, 1e-12));
    // An open road clamps: beyond its end, the end.
    assert_eq!(road.pose_at(150.0), road.pose_at(100.0));
    assert_eq!(road.locate(10.0, 200.0, None).station_m, 100.0);
}

#[test]
fn a_full_circle_closes_and_passes_through_its_quarter_points() {
    let radius = 50.0;
    let road = Road::new(ORIGIN, vec![Segment::arc(2.0 * PI * radius, radius)], 7.0)
        .unwrap()
        .closed()
        .expect("a full circle ends where it starts");
    // A left circle from the origin heading east has its centre at (0, R).
    let quarter = road.pose_at(PI * radius / 2.0);
    assert!(
        close(quarter.x_m, radius, 1e-6) && close(quarter.y_m, radius, 1e-6),
        "{quarter:?}"
    );
    assert!(close(quarter.heading_rad, PI / 2.0, 1e-12));
    let half = road.pose_at(PI * radius);
    assert!(
        close(half.x_m, 0.0, 1e-6) && close(half.y_m, 2.0 * radius, 1e-6),
        "{half:?}"
    );
    // A point inside the circle is left of the road, by its distance to the arc.
    let at = road.locate(radius - 2.0, radius, None);
    assert!(close(at.lateral_m, 2.0, 1e-6), "{at:?}");
    assert!(close(at.station_m, PI * radius / 2.0, 1e-3), "{at:?}");
    // Closed, stations wrap around.
    let lap = road.length_m();
    let a = road.pose_at(10.0);
    let b = road.pose_at(10.0 + lap);
    assert!(close(a.x_m, b.x_m, 1e-9) && close(a.y_m, b.y_m, 1e-9));
    assert!(close(road.wrap(-1.0), lap - 1.0, 1e-9));
}

/// The end of a clothoid from a straight into radius R over L, against Fresnel's integrals
/// by their power series: x = a·C(w), y = a·S(w) with a = sqrt(2RL), w = L/a and
/// C(w) = ∫0^w cos u² du, S(w) = ∫0^w sin u² du.
#[test]
fn a_clothoid_ends_where_fresnels_integrals_put_it() {
    for (length, radius) in [(40.0, 60.0), (100.0, 30.0), (25.0, -80.0)] {
        let road = Road::new(
            ORIGIN,
            vec![Segment::clothoid(length, f64::INFINITY, radius)],
            7.0,
        )
        .unwrap();
        let a = (2.0 * radius.abs() * length).sqrt();
        let w: f64 = length / a;
        let (mut c, mut s) = (0.0, 0.0);
        let mut factorial = 1.0; // (2n)! then (2n+1)!
        for n in 0..20 {
            let sign = if n % 2 == 0 { 1.0 } else { -1.0 };
            if n > 0 {
                factorial *= (2 * n - 1) as f64 * (2 * n) as f64;
            }
            c += sign * w.powi(4 * n + 1) / (factorial * (4 * n + 1) as f64);
            s += sign * w.powi(4 * n + 3) / (factorial * (2 * n + 1) as f64 * (4 * n + 3) as f64);
        }
        let end = road.pose_at(length);
        assert!(close(end.x_m, a * c, 1e-6), "{end:?} against x {}", a * c);
        assert!(
            close(end.y_m, a * s * radius.signum(), 1e-6),
            "{end:?} against y {}",
            a * s
        );
        assert!(close(end.heading_rad, length / (2.0 * radius), 1e-12));
        assert!(close(road.curvature_at(length / 2.0), 0.5 / radius, 1e-12));
    }
}

#[test]
fn a_stadium_with_eased_hairpins_closes_and_one_cut_short_does_not() {
    let road = Road::new(ORIGIN, stadium(400.0, 60.0, 40.0), 9.0)
        .unwrap()
        .closed()
        .expect("symmetric hairpins close the lap");
    // Each hairpin: the arc's πr less one transition, and two transitions.
    assert!(close(
        road.length_m(),
        800.0 + 2.0 * (PI * 60.0 + 40.0),
        1e-9
    ));
    let mut short = stadium(400.0, 60.0, 40.0);
    short[4] = Segment::straight(399.0);
    let refused = Road::new(ORIGIN, short, 9.0).unwrap().closed().unwrap_err();
    assert!(matches!(refused, RoadError::NotClosed { gap_m, .. } if close(gap_m, 1.0, 1e-3)));
    assert_eq!(
        refused.to_string(),
        "a closed road must end where it starts: its end is 1.00 m and 0.00° off (at most 0.05 m and 0.1°)"
    );
}

#[test]
fn a_split_friction_patch_covers_its_half_of_the_road_and_grass_lies_beyond_the_edges() {
    let road = Road::new(ORIGIN, vec![Segment::straight(300.0)], 8.0)
        .unwrap()
        .with_patch(Patch {
            name: "split-μ pad".into(),
            from_m: 100.0,
            to_m: 200.0,
            right_m: -4.0,
            left_m: 0.0,
            mu: 0.15,
        })
        .unwrap();
    // Heading east: the right half is south of the centreline.
    let right = road.surface(150.0, -1.0, None);
    let left = road.surface(150.0, 1.0, None);
    assert_eq!((right.mu, right.on_road), (0.15, true));
    assert_eq!((left.mu, left.on_road), (DRY_ASPHALT_MU, true));
    assert_eq!(road.surface(50.0, -1.0, None).mu, DRY_ASPHALT_MU);
    let grass = road.surface(150.0, -4.5, None);
    assert_eq!((grass.mu, grass.on_road), (GRASS_MU, false));
    // Past either end of an open road there is no road, whatever the offset.
    for (x, y) in [(300.5, 0.0), (-0.5, 1.0), (310.0, -2.0)] {
        let beyond = road.surface(x, y, None);
        assert_eq!((beyond.mu, beyond.on_road), (GRASS_MU, false), "({x}, {y})");
    }
    assert!(road.surface(299.5, 0.0, None).on_road);
}

#[test]
fn grades_raise_the_road_and_a_closed_lap_must_come_back_down() {
    let uphill = Grade {
        from_m: 100.0,
        to_m: 200.0,
        percent: 6.0,
    };
    let downhill = Grade {
        from_m: 300.0,
        to_m: 400.0,
        percent: -6.0,
    };
    let road = Road::new(ORIGIN, stadium(400.0, 60.0, 40.0), 9.0)
        .unwrap()
        .with_grade(uphill)
        .unwrap()
        .with_grade(downhill)
        .unwrap()
        .closed()
        .unwrap();
    assert!(close(road.height_at(150.0), 3.0, 1e-9));
    assert!(close(road.height_at(250.0), 6.0, 1e-9));
    assert!(close(road.height_at(road.length_m() - 1.0), 0.0, 1e-9));
    assert_eq!(road.grade_at(150.0), 6.0);
    // The car meets the grade by the cosine between its heading and the road's.
    let on_hill = road.surface(150.0, 0.0, None);
    assert!(close(on_hill.grade_along(0.0), 6.0, 1e-9));
    assert!(close(on_hill.grade_along(PI), -6.0, 1e-9));
    assert!(close(on_hill.grade_along(PI / 2.0), 0.0, 1e-9));

    let one_way = Road::new(ORIGIN, stadium(400.0, 60.0, 40.0), 9.0)
        .unwrap()
        .with_grade(uphill)
        .unwrap()
        .closed()
        .unwrap_err();
    assert_eq!(
        one_way.to_string(),
        "a closed road's grades must bring it back to its start's height: a lap rises 6.00 m"
    );
}

#[test]
fn a_road_that_cannot_be_driven_is_refused_with_what_is_wrong() {
    let refuse = |segments: Vec<Segment>, width: f64| {
        Road::new(ORIGIN, segments, width).unwrap_err().to_string()
    };
    assert_eq!(refuse(Vec::new(), 8.0), "a road needs at least one segment");
    assert_eq!(
        refuse(vec![Segment::straight(10.0), Segment::straight(0.0)], 8.0),
        "segment 2: length 0 m: a length above 0 is needed"
    );
    assert_eq!(
        refuse(vec![Segment::arc(10.0, 2.0)], 8.0),
        "segment 1: radius 2.00 m: radii of at least 5 m (or a straight) are needed"
    );
    assert_eq!(
        refuse(vec![Segment::straight(f64::NAN)], 8.0),
        "segment 1: length NaN m: a length above 0 is needed"
    );
    assert_eq!(
        refuse(vec![Segment::straight(10.0)], 0.5),
        "width 0.5 m: a width from 2 to 50 m is needed"
    );
    assert_eq!(
        refuse(vec![Segment::straight(60_000.0); 2], 8.0),
        "the road is 120000 m long: at most 100000 m"
    );
    let road = Road::new(ORIGIN, vec![Segment::straight(100.0)], 8.0).unwrap();
    let patch = Patch {
        name: "ice".into(),
        from_m: 10.0,
        to_m: 20.0,
        right_m: -4.0,
        left_m: 4.0,
        mu: 0.1,
    };
    let bad = |patch: Patch| road.clone().with_patch(patch).unwrap_err().to_string();
    assert_eq!(
        bad(Patch {
            to_m: 120.0,
            ..patch.clone()
        }),
        "patch 1: from 10 m to 120 m along: a stretch within the road's 100.0 m"
    );
    assert_eq!(
        bad(Patch {
            left_m: 5.0,
            ..patch.clone()
        }),
        "patch 1: from -4 m to 5 m across: a range within the road's 8 m, right edge first"
    );
    assert_eq!(
        bad(Patch { mu: 0.0, ..patch }),
        "patch 1: friction 0: from 0.01 to 2 is needed"
    );
    assert_eq!(
        road.with_grade(Grade {
            from_m: 0.0,
            to_m: 50.0,
            percent: 45.0
        })
        .unwrap_err()
        .to_string(),
        "grade 1: 45 %: at most 30 % either way"
    );
}

proptest! {
    /// A search started near where the point was finds what a search of the whole road
    /// finds, for points on and beside a circuit, a hint up to a few metres off.
    #[test]
    fn a_warm_started_search_finds_what_a_full_search_finds(
        station in 0.0f64..1177.0,
        lateral in -6.0f64..6.0,
        hint_off in -3.0f64..3.0,
    ) {
        let road = Road::new(ORIGIN, stadium(400.0, 60.0, 40.0), 9.0).unwrap().closed().unwrap();
        warm_against_full(&road, station, lateral, hint_off, 1e-9)?;
    }
}

/// The point `lateral_m` left of `station_m` located from a hint `hint_off_m` away and by
/// a search of the whole road: the same place, the lateral offsets within
/// `lateral_tolerance_m` of each other.
fn warm_against_full(
    road: &Road,
    station_m: f64,
    lateral_m: f64,
    hint_off_m: f64,
    lateral_tolerance_m: f64,
) -> Result<(), TestCaseError> {
    let centre = road.pose_at(station_m);
    let (x, y) = (
        centre.x_m - lateral_m * centre.heading_rad.sin(),
        centre.y_m + lateral_m * centre.heading_rad.cos(),
    );
    let full = road.locate(x, y, None);
    let warm = road.locate(x, y, Some(station_m + hint_off_m));
    prop_assert!(
        (full.lateral_m - lateral_m).abs() < 1e-6,
        "{full:?} against {lateral_m}"
    );
    prop_assert!(
        (warm.lateral_m - full.lateral_m).abs() < lateral_tolerance_m,
        "{warm:?} {full:?}"
    );
    let ds = (warm.station_m - full.station_m).abs();
    prop_assert!(
        ds < 1e-6 || (road.length_m() - ds) < 1e-6,
        "{warm:?} {full:?}"
    );
    prop_assert!(
        (warm.heading_rad - full.heading_rad).abs() < 1e-9,
        "{warm:?} {full:?}"
    );
    Ok(())
}

fn shipped(name: &str) -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../roads")
        .join(name)
}

#[test]
fn the_shipped_roads_load_and_close() {
    let circuit = file::load(&shipped("handling-circuit.toml")).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(circuit.name, "handling circuit");
    let road = circuit.road;
    assert!(road.is_closed());
    assert!(close(road.length_m(), 3221.69, 0.01), "{}", road.length_m());
    // The split-μ pad on the main straight's right half; the left half dry.
    assert_eq!(road.surface(360.0, -2.0, None).mu, 0.2);
    assert_eq!(road.surface(360.0, 2.0, None).mu, DRY_ASPHALT_MU);
    // The hill's top between its climb and its descent.
    assert!(close(road.height_at(2000.0), 6.0, 1e-9));
    assert!(close(road.height_at(2200.0), 0.0, 1e-9));
}

#[test]
fn a_road_file_with_a_mistake_names_the_entry_and_what_is_wrong() {
    let refuse = |text: &str| file::parse(text, "bad.toml").unwrap_err().to_string();
    let head = "name = \"r\"\nwidth_m = 8\n";
    assert_eq!(
        refuse(&format!(
            "{head}[[segment]]\nstraight_m = 10\narc = {{ radius_m = 20, turn_deg = 90 }}\n"
        )),
        "bad.toml: segment 1: give exactly one of straight_m, arc, bend or clothoid"
    );
    assert_eq!(
        refuse(&format!("{head}[[segment]]\nbend = {{ radius_m = 20, turn_deg = 90, transition_m = 40 }}\n")),
        "bad.toml: segment 1: transition 40 m: above 0 and below 31.4 m (the bend's length on its radius) is needed"
    );
    assert_eq!(
        refuse(&format!("{head}[[segment]]\nstraight_m = 10\n[[segment]]\narc = {{ radius_m = 3, turn_deg = 90 }}\n")),
        "bad.toml: segment 2: radius 3.00 m: radii of at least 5 m (or a straight) are needed"
    );
    assert_eq!(
        refuse(&format!(
            "{head}[[segment]]\narc = {{ radius_m = 30, turn_deg = 0 }}\n"
        )),
        "bad.toml: segment 1: turn 0°: from above 0 to 360° is needed"
    );
    assert_eq!(
        refuse(&format!("{head}closed = true\n[[segment]]\nstraight_m = 10\n")),
        "bad.toml: a closed road must end where it starts: its end is 10.00 m and 0.00° off (at most 0.05 m and 0.1°)"
    );
    assert!(refuse(&format!("{head}lanes = 2\n")).contains("unknown field `lanes`"));
    let missing = file::load(std::path::Path::new("no/such/road.toml")).unwrap_err();
    assert!(
        missing.to_string().starts_with("no/such/road.toml: "),
        "{missing}"
    );
}

/// The centreline by brute force: Simpson's rule from the segment's start in steps of
/// 1 mm with the library's trigonometry, against the pose a query gets from the samples
/// (turned by series, not by `sin_cos`).
#[test]
fn poses_between_samples_match_a_fine_integration_with_trigonometry() {
    let road = file::load(&shipped("handling-circuit.toml")).unwrap().road;
    let origin = road.pose_at(0.0);
    let (mut start_s, mut x, mut y, mut heading) =
        (0.0, origin.x_m, origin.y_m, origin.heading_rad);
    for segment in road.segments() {
        let base = heading;
        let h = |s: f64| base + segment.turn_at(s);
        // Stations a third and two thirds between the samples, and the segment's end.
        let mut checks: Vec<f64> = (0..(segment.length_m / SAMPLE_M) as usize)
            .flat_map(|i| [(i as f64 + 0.37) * SAMPLE_M, (i as f64 + 0.81) * SAMPLE_M])
            .filter(|&s| s < segment.length_m)
            .step_by(97)
            .collect();
        checks.push(segment.length_m);
        let (mut s, mut px, mut py) = (0.0, x, y);
        for target in checks {
            while s < target {
                let step = (target - s).min(1e-3);
                let (a, m, b) = (h(s), h(s + step / 2.0), h(s + step));
                px += step / 6.0 * (a.cos() + 4.0 * m.cos() + b.cos());
                py += step / 6.0 * (a.sin() + 4.0 * m.sin() + b.sin());
                s += step;
            }
            if start_s + target >= road.length_m() {
                break; // a closed road's end is its start again
            }
            let pose = road.pose_at(start_s + target);
            assert!(
                close(pose.x_m, px, 1e-6) && close(pose.y_m, py, 1e-6),
                "at {:.3} m: {pose:?} against ({px}, {py})",
                start_s + target
            );
            assert!(close(pose.heading_rad, h(target), 1e-9), "{pose:?}");
        }
        (x, y, heading) = (px, py, base + segment.turn());
        start_s += segment.length_m;
    }
}

proptest! {
    /// On the shipped circuit (straights, arcs, clothoids, both directions), a search from
    /// where a tyre was a step ago, or a few metres off, finds what a search of the whole
    /// road finds, on the road and on the grass beside it.
    #[test]
    fn a_search_from_where_the_tyre_was_finds_what_a_full_search_finds(
        station in 0.0f64..3221.0,
        lateral in -8.0f64..8.0,
        hint_off in prop_oneof![-0.1f64..0.1, -5.0f64..5.0],
    ) {
        let road = file::load(&shipped("handling-circuit.toml")).unwrap().road;
        warm_against_full(&road, station, lateral, hint_off, 1e-8)?;
    }
}

/// The series a query turns a sample's direction by agrees with `sin_cos` to within
/// rounding over every angle a sample step can turn (and a margin beyond).
#[test]
fn a_samples_direction_turns_as_sin_cos_would() {
    for heading in [0.0, 0.7, 2.0, -2.9, 4.5] {
        let sample = Sample::new(0.0, 0.0, 0.0, heading);
        for i in -600..=600 {
            let delta = f64::from(i) * 1e-4; // ±0.06 rad: κ 0.2/m over 0.25 m is 0.05
            let (cos, sin) = sample.turned(delta);
            let (sin_ref, cos_ref) = (heading + delta).sin_cos();
            assert!(
                close(cos, cos_ref, 2e-15) && close(sin, sin_ref, 2e-15),
                "{heading} + {delta}: ({cos}, {sin}) against ({cos_ref}, {sin_ref})"
            );
        }
    }
}
