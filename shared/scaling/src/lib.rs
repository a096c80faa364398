//! Saturating conversions between physical values and the raw integers that travel on
//! the CAN bus, plus the handful of unit conversions the ECUs and the vehicle model need.
//!
//! The numbers of every catalogue conversion (factor, offset, valid raw range) live in the
//! DBC file only; the generated codec in `autoplug-can` instantiates a [`LinearScale`] per
//! signal from them. This crate owns the arithmetic, so that rounding, clamping and the
//! handling of non-finite values are written once.
//!
//! Nothing here panics or allocates: conversions towards the bus saturate (a sender never
//! puts an out-of-range value on the wire), conversions from the bus report an
//! out-of-range raw value as an error (a receiver keeps its last good value).
#![no_std]
#![deny(missing_docs)]

pub mod units;

use core::fmt;

/// `physical = raw * factor + offset`, valid for `raw_min..=raw_max`.
///
/// This is the DBC signal model: the factor and offset come from the `SG_` line, and the
/// raw range from the signal's minimum and maximum (intersected with what its bits hold).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LinearScale {
    factor: f32,
    offset: f32,
    raw_min: i32,
    raw_max: i32,
}

/// A raw value outside the valid range of its signal.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RawOutOfRange {
    /// The value that was received.
    pub raw: i32,
    /// Smallest valid raw value.
    pub min: i32,
    /// Largest valid raw value.
    pub max: i32,
}

impl fmt::Display for RawOutOfRange {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "raw value {} outside the valid range {}..={}",
            self.raw, self.min, self.max
        )
    }
}

impl LinearScale {
    /// A scale with the given factor, offset and valid raw range.
    ///
    /// `raw_min <= raw_max` and a non-zero, finite factor are required; the check runs at
    /// compile time when the scale is built in a `const` (as the generated codec does).
    pub const fn new(factor: f32, offset: f32, raw_min: i32, raw_max: i32) -> Self {
        assert!(raw_min <= raw_max, "LinearScale: raw_min > raw_max");
        assert!(
            factor != 0.0 && factor.is_finite(),
            "LinearScale: factor must be finite and non-zero"
        );
        assert!(offset.is_finite(), "LinearScale: offset must be finite");
        Self {
            factor,
            offset,
            raw_min,
            raw_max,
        }
    }

    /// Physical units per raw step.
    pub const fn factor(&self) -> f32 {
        self.factor
    }

    /// Physical value of raw 0.
    pub const fn offset(&self) -> f32 {
        self.offset
    }

    /// Smallest valid raw value.
    pub const fn raw_min(&self) -> i32 {
        self.raw_min
    }

    /// Largest valid raw value.
    pub const fn raw_max(&self) -> i32 {
        self.raw_max
    }

    /// Whether `raw` is a valid value of this signal.
    pub const fn contains_raw(&self, raw: i32) -> bool {
        raw >= self.raw_min && raw <= self.raw_max
    }

    /// Smallest physical value that can be sent.
    pub fn physical_min(&self) -> f32 {
        let a = self.to_physical_unchecked(self.raw_min);
        let b = self.to_physical_unchecked(self.raw_max);
        if a < b {
            a
        } else {
            b
        }
    }

    /// Largest physical value that can be sent.
    pub fn physical_max(&self) -> f32 {
        let a = self.to_physical_unchecked(self.raw_min);
        let b = self.to_physical_unchecked(self.raw_max);
        if a > b {
            a
        } else {
            b
        }
    }

    /// Physical value of a raw value, without checking its range.
    pub fn to_physical_unchecked(&self, raw: i32) -> f32 {
        raw as f32 * self.factor + self.offset
    }

    /// Physical value of a received raw value; an out-of-range raw value is an error.
    pub fn to_physical(&self, raw: i32) -> Result<f32, RawOutOfRange> {
        if self.contains_raw(raw) {
            Ok(self.to_physical_unchecked(raw))
        } else {
            Err(RawOutOfRange {
                raw,
                min: self.raw_min,
                max: self.raw_max,
            })
        }
    }

    /// Raw value to send for a physical value: rounded to the nearest step and clamped to
    /// the valid range.
    ///
    /// A NaN has no meaningful nearest value; it is sent as physical zero (clamped), the
    /// neutral value of every catalogue signal (straight steering, no command, 0 km/h).
    pub fn to_raw_saturating(&self, physical: f32) -> i32 {
        let physical = if physical.is_nan() { 0.0 } else { physical };
        let steps = (physical - self.offset) / self.factor;
        // max/min rather than `Ord::clamp`: the latter's `min <= max` assertion formats
        // both bounds with core::fmt, which cost every firmware image 0.3 KB of flash
        // (`raw_min <= raw_max` holds by construction, so the result is the same).
        round_half_away_from_zero(steps)
            .max(self.raw_min)
            .min(self.raw_max)
    }

    /// The physical value that will actually arrive when `physical` is sent: what the
    /// quantisation and clamping of the bus do to it.
    pub fn quantize(&self, physical: f32) -> f32 {
        self.to_physical_unchecked(self.to_raw_saturating(physical))
    }
}

/// Rounds half-way cases away from zero, saturating at the `i32` range (`as` saturates and
/// maps NaN to 0, so this never panics). `core` has no `f32::round` without `std`.
pub fn round_half_away_from_zero(x: f32) -> i32 {
    if x >= 0.0 {
        (x + 0.5) as i32
    } else {
        (x - 0.5) as i32
    }
}

/// Clamps `x` into `[lo, hi]`, mapping NaN to `lo`. For actuator commands, where a NaN
/// must never reach an output stage.
pub fn clamp_finite(x: f32, lo: f32, hi: f32) -> f32 {
    if x.is_nan() || x < lo {
        lo
    } else if x > hi {
        hi
    } else {
        x
    }
}

#[cfg(any(test, feature = "test-cases"))]
pub mod test_cases;

#[cfg(test)]
mod tests;
