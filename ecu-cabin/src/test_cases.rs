//! Test cases shared by the host test suite and the on-target (defmt-test) suite. Each case
//! panics on failure. The closed loop runs against a first-order cabin plant with seeded
//! sensor noise; the closed loop against the vehicle model lives in `host-tests/`.

use crate::*;

fn ms(t: u64) -> Instant {
    Instant::from_millis(t)
}

/// Outside air, °F.
pub const PLANT_AMBIENT_F: f32 = 85.0;
/// Solar load, as a rise of the cabin's passive equilibrium, °F.
pub const PLANT_SUN_F: f32 = 10.0;
/// Passive time constant of the cabin (fan off), s.
pub const PLANT_TAU_PASSIVE_S: f32 = 600.0;
/// Temperature of the air-conditioned air at the outlet, °F.
pub const PLANT_OUTLET_F: f32 = 46.0;
/// Cooling rate per °F above the outlet at full fan, 1/s: full fan holds the sunny cabin
/// at 60 °F.
pub const PLANT_FAN_GAIN_PER_S: f32 = 35.0 / 600.0 / 14.0;
/// Sensor noise amplitude, °F (uniform).
pub const PLANT_NOISE_F: f32 = 0.2;

/// dT/dt of the cabin, °F/s: `(T_amb + sun − T)/τ_passive − k·fan·(T − T_outlet)`.
pub fn plant_rate(cabin_f: f32, fan_pct: f32) -> f32 {
    (PLANT_AMBIENT_F + PLANT_SUN_F - cabin_f) / PLANT_TAU_PASSIVE_S
        - PLANT_FAN_GAIN_PER_S * fan_pct / 100.0 * (cabin_f - PLANT_OUTLET_F)
}

/// Deterministic noise: xorshift32, uniform in ±`PLANT_NOISE_F`.
pub struct Noise(u32);

impl Noise {
    /// A generator from a seed (not 0).
    pub fn new(seed: u32) -> Self {
        Self(seed | 1)
    }

    /// The next sample.
    pub fn sample(&mut self) -> f32 {
        let mut x = self.0;
        x ^= x << 13;
        x ^= x >> 17;
        x ^= x << 5;
        self.0 = x;
        ((x >> 8) as f32 / (1u32 << 24) as f32 * 2.0 - 1.0) * PLANT_NOISE_F
    }
}

/// The cabin in closed loop.
pub struct Cabin {
    /// The ECU.
    pub ecu: CabinEcu,
    /// True cabin temperature, °F.
    pub temp_f: f32,
    /// Knob, °F.
    pub set_f: f32,
    /// Time, ms.
    pub t: u64,
    /// Last fan command, %.
    pub fan: f32,
    noise: Noise,
}

/// What a stretch of closed loop did.
#[derive(Clone, Copy, Debug, Default)]
pub struct Trace {
    /// Lowest true temperature, °F.
    pub min_f: f32,
    /// Highest true temperature, °F.
    pub max_f: f32,
    /// Lowest fan power, %.
    pub fan_min: f32,
    /// Highest fan power, %.
    pub fan_max: f32,
    /// Largest fan change from one step to the next, %.
    pub fan_max_step: f32,
    /// First time (ms since the stretch began) from which the true temperature stayed
    /// within ±1 °F of the set point.
    pub settled_after_ms: Option<u64>,
}

impl Cabin {
    /// A cabin at `temp_f`, the knob at `set_f`, noise from `seed`.
    pub fn new(temp_f: f32, set_f: f32, seed: u32) -> Self {
        Self {
            ecu: CabinEcu::new(),
            temp_f,
            set_f,
            t: 0,
            fan: 0.0,
            noise: Noise::new(seed),
        }
    }

    /// Runs `seconds` of closed loop.
    pub fn run(&mut self, seconds: u64) -> Trace {
        let mut trace = Trace {
            min_f: f32::MAX,
            max_f: f32::MIN,
            fan_min: f32::MAX,
            fan_max: f32::MIN,
            ..Trace::default()
        };
        let start = self.t;
        let mut previous_fan = self.fan;
        let mut inside_since = None;
        for _ in 0..seconds * 10 {
            let reading = self.temp_f + self.noise.sample();
            let out = self.ecu.step(
                ms(self.t),
                &Sensors {
                    cabin_temp_f: reading,
                    set_temp_f: self.set_f,
                },
            );
            assert!((0.0..=100.0).contains(&out.fan));
            self.fan = out.fan;
            // The plant integrates at 10 ms within the 100 ms control step.
            for _ in 0..10 {
                self.temp_f += plant_rate(self.temp_f, self.fan) * 0.01;
            }
            self.t += 100;
            trace.min_f = trace.min_f.min(self.temp_f);
            trace.max_f = trace.max_f.max(self.temp_f);
            trace.fan_min = trace.fan_min.min(self.fan);
            trace.fan_max = trace.fan_max.max(self.fan);
            trace.fan_max_step = trace.fan_max_step.max((self.fan - previous_fan).abs());
            previous_fan = self.fan;
            if (self.temp_f - self.set_f).abs() <= 1.0 {
                inside_since.get_or_insert(self.t - start);
            } else {
                inside_since = None;
            }
        }
        trace.settled_after_ms = inside_since;
        trace
    }
}

/// The three messages go out every 100 ms, in ID order, with the filtered temperature, the
/// set temperature and the fan power.
pub fn publishes_temperatures_and_fan_every_100_ms() {
    let mut ecu = CabinEcu::new();
    let mut counts = [0; 3];
    for t in (0..1000).step_by(100) {
        let fan = ecu
            .step(
                ms(t),
                &Sensors {
                    cabin_temp_f: 80.0,
                    set_temp_f: 72.0,
                },
            )
            .fan;
        let mut last_id = 0;
        while let Some(frame) = ecu.poll_transmit(ms(t)) {
            assert!(frame.id() > last_id, "lowest ID first");
            last_id = frame.id();
            match autoplug_can::Message::from_frame(&frame) {
                Ok(autoplug_can::Message::TempMsg(m)) => {
                    assert_eq!(m.cabin_temp, 80.0);
                    assert_eq!(frame.data(), &[160]);
                    counts[0] += 1;
                }
                Ok(autoplug_can::Message::TempRefMsg(m)) => {
                    assert_eq!(m.cabin_set_temp, 72.0);
                    counts[1] += 1;
                }
                Ok(autoplug_can::Message::FanMsg(m)) => {
                    assert!((m.fan_power - fan).abs() <= 0.5);
                    counts[2] += 1;
                }
                other => panic!("unexpected {:?}", other),
            }
        }
    }
    // Fan power grows with the integral: on change it may go out early, else every 100 ms.
    assert_eq!(&counts[..2], &[10, 10]);
    assert!(counts[2] >= 10);
}

/// The fan cools: a cabin warmer than set gets more fan the warmer it is; a colder cabin
/// gets none.
pub fn fan_rises_when_the_cabin_is_warmer_than_set() {
    let mut previous = -1.0;
    for cabin in [70.0, 71.0, 72.0, 74.0, 76.0] {
        let mut ecu = CabinEcu::new();
        let fan = ecu
            .step(
                ms(0),
                &Sensors {
                    cabin_temp_f: cabin,
                    set_temp_f: 70.0,
                },
            )
            .fan;
        assert!(fan > previous || fan == 100.0, "{} % at {} °F", fan, cabin);
        previous = fan;
    }
    assert_eq!(previous, 100.0, "6 °F too warm: full fan");
    let mut ecu = CabinEcu::new();
    for t in 0..100 {
        let fan = ecu
            .step(
                ms(t * 100),
                &Sensors {
                    cabin_temp_f: 65.0,
                    set_temp_f: 70.0,
                },
            )
            .fan;
        assert_eq!(fan, 0.0, "colder than set: no cooling");
    }
}

/// Closed loop on the cabin plant with ±0.2 °F seeded noise: after a step of the set
/// temperature down by 7 °F (and by 10 °F) the cabin is within ±1 °F in under 4 minutes
/// and stays there, with no sustained oscillation (the temperature band and the fan's
/// ripple stay small) and an undershoot under 1 °F.
pub fn set_point_step_down_settles_within_one_degree() {
    for (seed, step_f) in [(0x1234_5678, 7.0), (0xDEAD_BEEF, 10.0)] {
        let mut cabin = Cabin::new(75.0, 75.0, seed);
        cabin.run(20 * 60);
        assert!(
            (cabin.temp_f - 75.0).abs() < 0.3,
            "{} before the step",
            cabin.temp_f
        );
        cabin.set_f = 75.0 - step_f;
        let transient = cabin.run(10 * 60);
        let settled = transient.settled_after_ms.expect("settled");
        assert!(settled <= 240_000, "settled after {} s", settled / 1000);
        assert!(
            transient.min_f >= cabin.set_f - 1.0,
            "undershoot to {}",
            transient.min_f
        );
        let steady = cabin.run(10 * 60);
        assert!(steady.max_f - steady.min_f < 0.5, "{:?}", steady);
        assert!(
            (steady.max_f - cabin.set_f).abs() < 0.5 && (steady.min_f - cabin.set_f).abs() < 0.5
        );
        assert!(
            steady.fan_max - steady.fan_min < 10.0,
            "fan ripple {:?}",
            steady
        );
        assert!(steady.fan_max_step < 2.0, "fan chatter {:?}", steady);
    }
}

/// Anti-windup: a sunny cabin at 95 °F with the knob at 68 °F runs the fan at 100 % for
/// minutes, yet does not undershoot by more than 1 °F when it gets there; a cabin colder
/// than set for half an hour (fan 0) leaves no negative integral: the fan responds at once
/// when it becomes too warm.
pub fn integrator_stays_within_the_fan_range() {
    let mut cabin = Cabin::new(95.0, 68.0, 42);
    let pull_down = cabin.run(20 * 60);
    assert_eq!(pull_down.fan_max, 100.0);
    assert!(pull_down.min_f >= 67.0, "undershoot to {}", pull_down.min_f);
    assert!((cabin.temp_f - 68.0).abs() < 0.5);

    // Half an hour 8 °F colder than set, then the cabin warms to 2 °F above set (door
    // opened in the sun): the fan follows exactly as in an ECU that was cold for a single
    // step, so nothing was wound down.
    let cold = Sensors {
        cabin_temp_f: 62.0,
        set_temp_f: 70.0,
    };
    let warm = Sensors {
        cabin_temp_f: 72.0,
        set_temp_f: 70.0,
    };
    let mut long_cold = CabinEcu::new();
    let mut short_cold = CabinEcu::new();
    for t in 0..18_000 {
        assert_eq!(long_cold.step(ms(t * 100), &cold).fan, 0.0);
    }
    short_cold.step(ms(17_999 * 100), &cold);
    let mut fan = 0.0;
    for t in 18_000..18_300 {
        fan = long_cold.step(ms(t * 100), &warm).fan;
        let reference = short_cold.step(ms(t * 100), &warm).fan;
        assert!((fan - reference).abs() < 1e-3, "{} vs {}", fan, reference);
    }
    assert!(fan >= TUNING.kp * 2.0 * 0.9, "fan {} after 30 s", fan);
}

/// Sensor noise of ±0.2 °F moves the fan by less than 1 % per step and the published
/// temperature by at most one 0.5 °F step.
pub fn sensor_noise_is_filtered() {
    let mut ecu = CabinEcu::new();
    let mut noise = Noise::new(7);
    let (mut fan_min, mut fan_max, mut previous) = (f32::MAX, f32::MIN, None::<f32>);
    let (mut raw_min, mut raw_max) = (u8::MAX, u8::MIN);
    for t in 0..3000u64 {
        // Half a degree above set, where the fan works in its linear range.
        let fan = ecu
            .step(
                ms(t * 100),
                &Sensors {
                    cabin_temp_f: 70.5 + noise.sample(),
                    set_temp_f: 70.0,
                },
            )
            .fan;
        if t >= 600 {
            if let Some(p) = previous {
                assert!((fan - p).abs() < 1.0, "fan {} -> {}", p, fan);
            }
            fan_min = fan_min.min(fan);
            fan_max = fan_max.max(fan);
            while let Some(frame) = ecu.poll_transmit(ms(t * 100)) {
                if frame.id() == TempMsg::ID {
                    let raw = frame.data().first().copied().unwrap_or(0);
                    raw_min = raw_min.min(raw);
                    raw_max = raw_max.max(raw);
                }
            }
        }
        previous = Some(fan);
    }
    assert!(
        raw_max - raw_min <= 1,
        "TempMsg raw {}..{}",
        raw_min,
        raw_max
    );
    assert!(fan_max > 0.0);
}

/// The knob is limited to 60..85 °F; a reading that is not a number or out of the sensor's
/// range is ignored (last good value kept, fan unchanged).
pub fn knob_limits_and_invalid_readings() {
    let mut ecu = CabinEcu::new();
    ecu.step(
        ms(0),
        &Sensors {
            cabin_temp_f: 75.0,
            set_temp_f: 40.0,
        },
    );
    assert_eq!(ecu.status().set_temp_f, SET_TEMP_MIN_F);
    ecu.step(
        ms(100),
        &Sensors {
            cabin_temp_f: 75.0,
            set_temp_f: 120.0,
        },
    );
    assert_eq!(ecu.status().set_temp_f, SET_TEMP_MAX_F);
    ecu.step(
        ms(200),
        &Sensors {
            cabin_temp_f: 75.0,
            set_temp_f: f32::NAN,
        },
    );
    assert_eq!(ecu.status().set_temp_f, SET_TEMP_MAX_F, "NaN knob: kept");
    let before = ecu.step(
        ms(300),
        &Sensors {
            cabin_temp_f: 78.0,
            set_temp_f: 72.0,
        },
    );
    let status = ecu.status();
    for (i, bad) in [f32::NAN, f32::INFINITY, -100.0, 400.0]
        .into_iter()
        .enumerate()
    {
        let out = ecu.step(
            ms(400 + i as u64 * 100),
            &Sensors {
                cabin_temp_f: bad,
                set_temp_f: 72.0,
            },
        );
        assert_eq!(out, before, "fan held");
        assert_eq!(ecu.status().cabin_temp_f, status.cabin_temp_f);
    }
    assert_eq!(ecu.dtcs().records().count(), 0);
}

autoplug_ecu::test_cases!(
    publishes_temperatures_and_fan_every_100_ms,
    fan_rises_when_the_cabin_is_warmer_than_set,
    set_point_step_down_settles_within_one_degree,
    integrator_stays_within_the_fan_range,
    sensor_noise_is_filtered,
    knob_limits_and_invalid_readings,
);
