//! Every signal's history since the session began, for the dashboard's plots: a page opened
//! an hour into a drive can still look back at its start.
//!
//! Memory is fixed whatever the session's length: each signal keeps at most
//! [`MAX_BUCKETS`] buckets of equal width in bus time. When the session outgrows them, the
//! width doubles and neighbouring buckets merge in pairs, so the whole session is always
//! there, at a resolution that halves as it doubles in length (recent detail at the full
//! rate comes from the live stream the page keeps). A bucket keeps its minimum and maximum,
//! and which came first, so a one-sample spike survives every merge and the drawn line
//! keeps its envelope (the min-max decimation plotting tools use for long records).
//!
//! Written here rather than taken from a crate: what it needs is a few dozen lines bound
//! to the live table's sampling, and the time-series crates found are databases.

use std::fmt::Write as _;
use std::sync::Mutex;

/// Buckets kept per signal: two points each, about one per pixel of a wide chart.
pub const MAX_BUCKETS: usize = 2048;

/// Width of a bucket at the start of a session, µs: the live table's publication period,
/// so that the first half minute is kept sample by sample.
pub const FIRST_WIDTH_US: u64 = crate::live::PUBLISH_EVERY_US;

/// One bucket of one signal: the extremes of its samples within the bucket's span.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Bucket {
    /// Which bucket of the session's grid (its start is `t0 + index × width`).
    index: u64,
    min: f64,
    max: f64,
    /// Whether the minimum came before the maximum (the order the line is drawn in).
    min_first: bool,
}

impl Bucket {
    fn take(&mut self, value: f64) {
        if value < self.min {
            self.min = value;
            self.min_first = false;
        }
        if value > self.max {
            self.max = value;
            self.min_first = true;
        }
    }

    /// `later` (the next bucket in time) merged into this one.
    fn merge(&mut self, later: &Bucket) {
        let min_first = match (later.min < self.min, later.max > self.max) {
            (false, false) => self.min_first,
            (true, true) => later.min_first,
            // A new minimum, the maximum still this bucket's: the maximum came first.
            (true, false) => false,
            (false, true) => true,
        };
        self.min = self.min.min(later.min);
        self.max = self.max.max(later.max);
        self.min_first = min_first;
    }
}

#[derive(Debug, Default)]
struct Series {
    buckets: Vec<Bucket>,
}

#[derive(Debug)]
struct Data {
    /// Bus time of the session's first sample, µs.
    t0_us: Option<u64>,
    last_us: u64,
    width_us: u64,
    series: Vec<Series>,
}

/// The history of every signal of the catalogue (see the module docs).
#[derive(Debug)]
pub struct History {
    data: Mutex<Data>,
}

/// One signal's history as points to draw: times in s of bus time, values; a `None`
/// value where the signal was missing (a gap in the line).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Points {
    /// Bus time, s.
    pub t: Vec<f64>,
    /// The values, in the signal's unit.
    pub v: Vec<Option<f64>>,
}

impl History {
    /// An empty history of `signals` signals.
    pub fn new(signals: usize) -> Self {
        Self {
            data: Mutex::new(Data {
                t0_us: None,
                last_us: 0,
                width_us: FIRST_WIDTH_US,
                series: (0..signals).map(|_| Series::default()).collect(),
            }),
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Data> {
        // A panic elsewhere while holding the lock leaves plain data: go on with it.
        self.data.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Takes one sample of every signal at bus time `t_us` (`None`: missing or stale).
    /// Time going back (a replay started over) starts the history over.
    pub fn record(&self, t_us: u64, values: &[Option<f64>]) {
        let mut data = self.lock();
        if data.t0_us.is_some() && t_us < data.last_us {
            data.t0_us = None;
            data.width_us = FIRST_WIDTH_US;
            for s in &mut data.series {
                s.buckets.clear();
            }
        }
        let t0 = *data.t0_us.get_or_insert(t_us);
        data.last_us = t_us;
        while (t_us - t0) / data.width_us >= MAX_BUCKETS as u64 {
            data.width_us *= 2;
            for s in &mut data.series {
                merge_pairs(&mut s.buckets);
            }
        }
        let index = (t_us - t0) / data.width_us;
        for (series, value) in data.series.iter_mut().zip(values) {
            let Some(value) = value.filter(|v| v.is_finite()) else {
                continue;
            };
            match series.buckets.last_mut() {
                Some(last) if last.index == index => last.take(value),
                _ => series.buckets.push(Bucket {
                    index,
                    min: value,
                    max: value,
                    min_first: true,
                }),
            }
        }
    }

    /// The points of signal `index` (in the catalogue's order), `None` for no such signal.
    /// Every signal's points are on the same grid, two per bucket of the session (a
    /// quarter and three quarters into its span): the bucket's minimum and maximum in the
    /// order they came, or `None` twice where the signal has no sample (a gap in the
    /// line). The same times for every signal let a chart of several share one time axis.
    pub fn points(&self, index: usize) -> Option<Points> {
        let data = self.lock();
        let series = data.series.get(index)?;
        let Some(t0_us) = data.t0_us else {
            return Some(Points::default());
        };
        let t0 = t0_us as f64 * 1e-6;
        let width = data.width_us as f64 * 1e-6;
        let buckets = (data.last_us - t0_us) / data.width_us + 1;
        let mut points = Points {
            t: Vec::with_capacity(2 * buckets as usize),
            v: Vec::with_capacity(2 * buckets as usize),
        };
        let mut kept = series.buckets.iter().peekable();
        for index in 0..buckets {
            let start = t0 + index as f64 * width;
            points.t.push(start + 0.25 * width);
            points.t.push(start + 0.75 * width);
            match kept.next_if(|b| b.index == index) {
                Some(b) if b.min_first => points.v.extend([Some(b.min), Some(b.max)]),
                Some(b) => points.v.extend([Some(b.max), Some(b.min)]),
                None => points.v.extend([None, None]),
            }
        }
        Some(points)
    }

    /// Bus time of the session's first sample and the buckets' width now, s.
    pub fn span(&self) -> (Option<f64>, f64) {
        let data = self.lock();
        (
            data.t0_us.map(|t| t as f64 * 1e-6),
            data.width_us as f64 * 1e-6,
        )
    }
}

/// Merges neighbouring buckets in pairs, for a grid of twice the width.
fn merge_pairs(buckets: &mut Vec<Bucket>) {
    let mut merged: Vec<Bucket> = Vec::with_capacity(buckets.len() / 2 + 1);
    for b in buckets.drain(..) {
        let index = b.index / 2;
        match merged.last_mut() {
            Some(last) if last.index == index => last.merge(&b),
            _ => merged.push(Bucket { index, ..b }),
        }
    }
    *buckets = merged;
}

/// `points` as the JSON object the history API sends: `{"t": [...], "v": [...]}`.
pub fn points_json(points: &Points) -> String {
    let mut json = String::with_capacity(32 + 24 * points.t.len());
    json.push_str("{\"t\":[");
    for (i, t) in points.t.iter().enumerate() {
        if i > 0 {
            json.push(',');
        }
        let _ = write!(json, "{t:.4}");
    }
    json.push_str("],\"v\":[");
    for (i, v) in points.v.iter().enumerate() {
        if i > 0 {
            json.push(',');
        }
        match v {
            Some(v) => {
                let _ = write!(json, "{v}");
            }
            None => json.push_str("null"),
        }
    }
    json.push_str("]}");
    json
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_first_samples_are_kept_one_by_one() {
        let history = History::new(2);
        for i in 0..100u64 {
            history.record(5_000_000 + i * 10_000, &[Some(i as f64), None]);
        }
        let points = history.points(0).unwrap();
        assert_eq!(points.t.len(), 200, "two points a bucket");
        assert_eq!((points.v[84], points.v[85]), (Some(42.0), Some(42.0)));
        assert!((points.t[0] - 5.0025).abs() < 1e-9, "{}", points.t[0]);
        let missing = history.points(1).unwrap();
        assert_eq!(missing.t, points.t, "every signal on the same grid");
        assert!(missing.v.iter().all(Option::is_none));
        assert!(history.points(2).is_none());
    }

    #[test]
    fn a_long_session_stays_within_its_buckets_from_its_first_second_on() {
        let history = History::new(1);
        // Ten hours at the publication rate, a spike of one sample in the middle.
        let samples = 10 * 3600 * 100u64;
        for i in 0..samples {
            let value = if i == samples / 2 {
                1000.0
            } else {
                (i % 7) as f64
            };
            history.record(i * 10_000, &[Some(value)]);
        }
        let points = history.points(0).unwrap();
        assert!(
            points.t.len() <= 2 * MAX_BUCKETS,
            "{} points",
            points.t.len()
        );
        assert!(
            points.t[0] < 10.0,
            "the start is still there: {}",
            points.t[0]
        );
        assert!(*points.t.last().unwrap() > 35_000.0);
        let top = points.v.iter().flatten().fold(f64::MIN, |a, &b| a.max(b));
        assert_eq!(top, 1000.0, "the spike survived every merge");
        assert!(points.v.iter().flatten().any(|&v| v == 0.0));
        let (t0, width) = history.span();
        assert_eq!(t0, Some(0.0));
        assert!(width * MAX_BUCKETS as f64 >= 36_000.0);
    }

    #[test]
    fn missing_values_are_gaps_and_time_going_back_starts_over() {
        let history = History::new(1);
        for i in 0..30u64 {
            let value = (!(10..20).contains(&i)).then_some(1.0);
            history.record(i * 10_000, &[value]);
        }
        let points = history.points(0).unwrap();
        assert_eq!(points.v.iter().filter(|v| v.is_none()).count(), 20);
        assert_eq!(points.v.len(), 60);
        history.record(0, &[Some(2.0)]);
        assert_eq!(history.points(0).unwrap().v, vec![Some(2.0), Some(2.0)]);
    }

    #[test]
    fn merged_extremes_keep_their_order() {
        let mut a = Bucket {
            index: 0,
            min: 1.0,
            max: 5.0,
            min_first: true,
        };
        a.merge(&Bucket {
            index: 1,
            min: -3.0,
            max: 2.0,
            min_first: true,
        });
        assert_eq!((a.min, a.max, a.min_first), (-3.0, 5.0, false));
        let json = points_json(&Points {
            t: vec![0.0, 1.0],
            v: vec![Some(1.5), None],
        });
        assert_eq!(json, r#"{"t":[0.0000,1.0000],"v":[1.5,null]}"#);
    }
}
