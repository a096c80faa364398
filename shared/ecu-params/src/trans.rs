//! The transmission ECU's published parameters (node 0x06): its gearbox calibration, shift timing, shift schedules and trouble code.

use autoplug_can::{EngineMode, Gear};
use autoplug_ecu::{Dtc, DtcSystem};

/// Ratios of 1st to 6th gear: the transmission's calibration of the gearbox it controls,
/// the six-speed box of `VehicleParams::evo_vi()` in the vehicle model (a host test in
/// `host-tests/` checks the two agree; the model documents the source).
pub const GEAR_RATIOS: [f32; 6] = [2.909, 1.944, 1.434, 1.100, 0.868, 0.693];

/// Reverse gear ratio, as a magnitude (same calibration source).
pub const REVERSE_RATIO: f32 = 3.3;

/// Final drive ratio (EVO VI).
pub const FINAL_DRIVE_RATIO: f32 = 4.529;

/// Rolling radius of the tyres (225/45 ZR17), m: converts road speed to engine speed.
pub const TYRE_RADIUS_M: f32 = 0.31;

/// Highest engine speed a driver's downshift may give, rpm: a margin under the ~7500 rpm
/// redline, for the RPM signal's 35 rpm resolution and its 20 ms age.
pub const OVER_REV_LIMIT_RPM: f32 = 7000.0;

/// At most one shift per this time, µs: lets the gearbox complete a shift and the engine
/// speed settle before the next decision. Short enough for 1st to 6th while accelerating
/// to 150 km/h in about 12 s at full throttle (the report's figure).
pub const SHIFT_TIMEOUT_US: u64 = 800_000;

/// At or below this road speed the car counts as stopped, km/h: automatic engages 1st from
/// Neutral, and Reverse may be engaged. VehicleSpeedMsg has 1 km/h resolution.
pub const STANDSTILL_KMH: f32 = 3.0;

/// Economy upshift point, rpm: upshift early, near peak torque, for low consumption.
pub const ECONOMY_UPSHIFT_RPM: f32 = 3200.0;
/// Economy downshift point, rpm in the current gear: let the engine lug down to here.
pub const ECONOMY_DOWNSHIFT_RPM: f32 = 1400.0;
/// Sport upshift point, rpm: near peak power (~6500 rpm), under the over-rev limit.
pub const SPORT_UPSHIFT_RPM: f32 = 6800.0;
/// Sport downshift point, rpm in the current gear: drop a gear to stay in the power band.
pub const SPORT_DOWNSHIFT_RPM: f32 = 3500.0;

/// Smallest gap between a gear's upshift speed and the next gear's downshift speed, km/h:
/// with less, speed noise could make the gearbox hunt. Checked at compile time.
pub const MIN_HYSTERESIS_KMH: f32 = 5.0;

/// After this time, µs, an engaged gear still different from the command is a fault.
pub const GEAR_ENGAGE_TIMEOUT_US: u64 = 1_000_000;

/// DTC P0730-00, "incorrect gear ratio": the gearbox did not engage the commanded gear.
pub const GEAR_NOT_ENGAGED: Dtc = Dtc::new(DtcSystem::P, 0x0730, 0x00);

/// Road speed, km/h, at an engine speed in a gear of `ratio`:
/// `rpm / 60 × 2π r / (ratio × final drive) × 3.6`.
pub const fn road_speed_kmh(engine_rpm: f32, ratio: f32) -> f32 {
    engine_rpm * (2.0 * core::f32::consts::PI * TYRE_RADIUS_M * 0.06) / (ratio * FINAL_DRIVE_RATIO)
}

/// Engine speed, rpm, at a road speed in a gear of `ratio` (inverse of [`road_speed_kmh`]).
pub const fn engine_rpm_at(speed_kmh: f32, ratio: f32) -> f32 {
    speed_kmh * ratio * FINAL_DRIVE_RATIO / (2.0 * core::f32::consts::PI * TYRE_RADIUS_M * 0.06)
}

/// The ratio of a gear (reverse as a magnitude); `None` for Neutral.
pub const fn gear_ratio(gear: Gear) -> Option<f32> {
    let [first, second, third, fourth, fifth, sixth] = GEAR_RATIOS;
    match gear {
        Gear::Reverse => Some(REVERSE_RATIO),
        Gear::Neutral => None,
        Gear::First => Some(first),
        Gear::Second => Some(second),
        Gear::Third => Some(third),
        Gear::Fourth => Some(fourth),
        Gear::Fifth => Some(fifth),
        Gear::Sixth => Some(sixth),
    }
}

/// 0 for 1st .. 5 for 6th; `None` for Reverse and Neutral.
pub const fn forward_index(gear: Gear) -> Option<usize> {
    match gear {
        Gear::First => Some(0),
        Gear::Second => Some(1),
        Gear::Third => Some(2),
        Gear::Fourth => Some(3),
        Gear::Fifth => Some(4),
        Gear::Sixth => Some(5),
        Gear::Reverse | Gear::Neutral => None,
    }
}

/// The next gear up in the sequence R - N - 1st - ... - 6th.
pub const fn gear_up(gear: Gear) -> Option<Gear> {
    match gear {
        Gear::Reverse => Some(Gear::Neutral),
        Gear::Neutral => Some(Gear::First),
        Gear::First => Some(Gear::Second),
        Gear::Second => Some(Gear::Third),
        Gear::Third => Some(Gear::Fourth),
        Gear::Fourth => Some(Gear::Fifth),
        Gear::Fifth => Some(Gear::Sixth),
        Gear::Sixth => None,
    }
}

/// The next gear down in the sequence R - N - 1st - ... - 6th.
pub const fn gear_down(gear: Gear) -> Option<Gear> {
    match gear {
        Gear::Reverse => None,
        Gear::Neutral => Some(Gear::Reverse),
        Gear::First => Some(Gear::Neutral),
        Gear::Second => Some(Gear::First),
        Gear::Third => Some(Gear::Second),
        Gear::Fourth => Some(Gear::Third),
        Gear::Fifth => Some(Gear::Fourth),
        Gear::Sixth => Some(Gear::Fifth),
    }
}

/// The road speeds of an automatic shift schedule.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(any(feature = "defmt", target_os = "none"), derive(defmt::Format))]
pub struct ShiftSchedule {
    /// `upshift_kmh[i]`: at or above this speed, shift from gear `i + 1` to `i + 2`
    /// (index 0: 1st to 2nd, ..., 4: 5th to 6th), km/h.
    pub upshift_kmh: [f32; 5],
    /// `downshift_kmh[i]`: at or below this speed, shift from gear `i + 2` to `i + 1`
    /// (index 0: 2nd to 1st, ..., 4: 6th to 5th), km/h.
    pub downshift_kmh: [f32; 5],
}

impl ShiftSchedule {
    /// Upshift where the engine reaches `upshift_rpm` in the current gear, downshift where
    /// it falls to `downshift_rpm` in the current gear.
    pub const fn from_rpm(upshift_rpm: f32, downshift_rpm: f32) -> Self {
        let mut upshift_kmh = [0.0; 5];
        let mut downshift_kmh = [0.0; 5];
        let mut i = 0;
        while i < 5 {
            upshift_kmh[i] = road_speed_kmh(upshift_rpm, GEAR_RATIOS[i]);
            downshift_kmh[i] = road_speed_kmh(downshift_rpm, GEAR_RATIOS[i + 1]);
            i += 1;
        }
        Self {
            upshift_kmh,
            downshift_kmh,
        }
    }

    /// Whether the schedule can be used: upshift speeds rising gear by gear, and each
    /// downshift at least [`MIN_HYSTERESIS_KMH`] below the upshift into that gear (and
    /// above 0, so 2nd is left before stopping).
    pub const fn is_valid(&self) -> bool {
        let mut i = 0;
        while i < 5 {
            if self.downshift_kmh[i] <= 0.0
                || self.downshift_kmh[i] > self.upshift_kmh[i] - MIN_HYSTERESIS_KMH
            {
                return false;
            }
            if i > 0 && self.upshift_kmh[i] <= self.upshift_kmh[i - 1] {
                return false;
            }
            i += 1;
        }
        true
    }

    /// The speed at or above which `gear` shifts up; `None` for 6th, Neutral, Reverse.
    pub fn upshift_speed(&self, gear: Gear) -> Option<f32> {
        forward_index(gear).and_then(|i| self.upshift_kmh.get(i).copied())
    }

    /// The speed at or below which `gear` shifts down; `None` for 1st, Neutral, Reverse.
    pub fn downshift_speed(&self, gear: Gear) -> Option<f32> {
        forward_index(gear)
            .and_then(|i| i.checked_sub(1))
            .and_then(|i| self.downshift_kmh.get(i).copied())
    }

    /// The gear the schedule wants next from `gear` at `speed_kmh`: one gear up or down,
    /// or `gear` itself. Neutral and Reverse are not the schedule's business.
    pub fn next_gear(&self, gear: Gear, speed_kmh: f32) -> Gear {
        if let Some(up) = self.upshift_speed(gear) {
            if speed_kmh >= up {
                return gear_up(gear).unwrap_or(gear);
            }
        }
        if let Some(down) = self.downshift_speed(gear) {
            if speed_kmh <= down {
                return gear_down(gear).unwrap_or(gear);
            }
        }
        gear
    }
}

/// Economy schedule (engine mode economy, and whenever EngineMsg is lost). Upshifts at
/// 30.2, 43.2, 59.8, 81.6, 110.6 km/h (1-2 .. 5-6); downshifts at 18.9, 26.2, 35.7, 48.4,
/// 61.4 km/h (2-1 .. 6-5).
pub const ECONOMY: ShiftSchedule =
    ShiftSchedule::from_rpm(ECONOMY_UPSHIFT_RPM, ECONOMY_DOWNSHIFT_RPM);

/// Sport schedule: every shift point later than economy's. Upshifts at 64.2, 91.7, 127.1,
/// 173.5, 235.0 km/h; downshifts at 47.2, 65.4, 89.3, 121.0, 153.4 km/h.
pub const SPORT: ShiftSchedule = ShiftSchedule::from_rpm(SPORT_UPSHIFT_RPM, SPORT_DOWNSHIFT_RPM);

const _: () = assert!(ECONOMY.is_valid() && SPORT.is_valid());
const _: () = assert!(SPORT_UPSHIFT_RPM <= OVER_REV_LIMIT_RPM);
const _: () =
    assert!(ECONOMY_UPSHIFT_RPM < SPORT_UPSHIFT_RPM && ECONOMY_DOWNSHIFT_RPM < SPORT_DOWNSHIFT_RPM);

/// The schedule for an engine mode.
pub const fn schedule(mode: EngineMode) -> &'static ShiftSchedule {
    match mode {
        EngineMode::Sport => &SPORT,
        EngineMode::Economy => &ECONOMY,
    }
}
