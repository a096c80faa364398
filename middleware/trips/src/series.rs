//! The downsampled series of a trip: every signal of the catalogue in buckets of
//! [`BUCKET_US`], each keeping mean, min and max, so a plot of a long trip stays small and
//! still shows every peak (a 10 ms signal is 100 values a second; its series is one).

use autoplug_can::MESSAGES;
use autoplug_gateway::CarState;

use crate::record::SeriesPoint;

/// Width of a bucket, µs.
pub const BUCKET_US: u64 = 1_000_000;

#[derive(Clone, Copy, Debug)]
struct Bucket {
    sum: f64,
    min: f64,
    max: f64,
    count: u32,
}

impl Bucket {
    const EMPTY: Bucket = Bucket {
        sum: 0.0,
        min: f64::INFINITY,
        max: f64::NEG_INFINITY,
        count: 0,
    };
}

/// Buckets of every signal for the trip in progress; full buckets wait in `ready` until the
/// store takes them.
pub struct Downsampler {
    trip_start_us: u64,
    /// Index of the bucket being filled (from the trip's start).
    current: u64,
    buckets: Vec<Bucket>,
    /// Index of each message's first signal in `buckets`.
    first_signal: Vec<usize>,
    ready: Vec<SeriesPoint>,
}

impl Downsampler {
    /// Series for a trip starting at bus time `trip_start_us`.
    pub fn new(trip_start_us: u64) -> Self {
        let mut first_signal = Vec::with_capacity(MESSAGES.len());
        let mut n = 0;
        for m in MESSAGES {
            first_signal.push(n);
            n += m.signals.len();
        }
        Self {
            trip_start_us,
            current: 0,
            buckets: vec![Bucket::EMPTY; n],
            first_signal,
            ready: Vec::new(),
        }
    }

    /// The values of message `index`'s signals, as the car state holds them after a frame
    /// at bus time `t_us`.
    pub fn add(&mut self, t_us: u64, index: usize, state: &CarState) {
        let bucket = t_us.saturating_sub(self.trip_start_us) / BUCKET_US;
        if bucket > self.current {
            self.close_bucket();
            self.current = bucket;
        }
        let first = self.first_signal[index];
        let n = MESSAGES[index].signals.len();
        let values = state.signals()[first..first + n].iter().map(|s| s.value);
        for (b, v) in self.buckets[first..first + n].iter_mut().zip(values) {
            b.sum += v;
            b.min = b.min.min(v);
            b.max = b.max.max(v);
            b.count += 1;
        }
    }

    fn close_bucket(&mut self) {
        let t_s = (self.current * BUCKET_US) as f64 * 1e-6;
        let signals = MESSAGES.iter().flat_map(|m| m.signals.iter());
        for (b, spec) in self.buckets.iter_mut().zip(signals) {
            if b.count > 0 {
                self.ready.push(SeriesPoint {
                    signal: spec.vss.to_string(),
                    t_s,
                    mean: b.sum / f64::from(b.count),
                    min: b.min,
                    max: b.max,
                });
            }
            *b = Bucket::EMPTY;
        }
    }

    /// The full buckets not taken yet.
    pub fn take_ready(&mut self) -> Vec<SeriesPoint> {
        std::mem::take(&mut self.ready)
    }

    /// Closes the bucket being filled (the trip ended) and gives everything not taken.
    pub fn finish(&mut self) -> Vec<SeriesPoint> {
        self.close_bucket();
        self.take_ready()
    }
}
