//! Rust values to SQLite columns and back: `TripStats` as one column per field, NaN as
//! NULL, unsigned integers checked on the way in and out.

use autoplug_trips::TripStats;
use rusqlite::types::Value;
use rusqlite::Row;

/// The `trips` columns holding a [`TripStats`], in the order of [`stats_values`] and
/// [`stats_from_row`].
pub(super) const STATS_COLUMNS: &str = "start_us, end_us, distance_m, duration_s, \
    moving_time_s, fuel_used_l, max_speed_kmh, mean_speed_kmh, abs_interventions, \
    abs_time_s, hard_brakings, shifts, cruise_time_s, diff_interventions, diff_time_s";

/// `?, ?, ...` for the [`STATS_COLUMNS`].
pub(super) const STATS_PLACEHOLDERS: &str = "?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?";

/// A real number for a REAL column: NULL for NaN (SQLite would store NULL anyway; saying
/// so keeps it visible).
pub(super) fn real(x: f64) -> Value {
    if x.is_nan() {
        Value::Null
    } else {
        Value::Real(x)
    }
}

/// A REAL column read back: NULL is NaN (see [`real`]).
pub(super) fn real_at(row: &Row<'_>, i: usize) -> rusqlite::Result<f64> {
    Ok(row.get::<_, Option<f64>>(i)?.unwrap_or(f64::NAN))
}

/// An unsigned integer column read back, refusing a negative or too large value.
fn unsigned_at<T: TryFrom<i64>>(row: &Row<'_>, i: usize) -> rusqlite::Result<T> {
    let v: i64 = row.get(i)?;
    T::try_from(v).map_err(|_| rusqlite::Error::IntegralValueOutOfRange(i, v))
}

/// A time in µs for an INTEGER column; `None` if it does not fit an i64 (after 292 000
/// years of bus time).
fn micros(us: u64) -> Option<Value> {
    i64::try_from(us).ok().map(Value::Integer)
}

/// The values of the [`STATS_COLUMNS`]; `Err` names a field that cannot be stored.
pub(super) fn stats_values(s: &TripStats) -> Result<[Value; 15], String> {
    let start = micros(s.start_us).ok_or_else(|| format!("start_us {}", s.start_us))?;
    let end = micros(s.end_us).ok_or_else(|| format!("end_us {}", s.end_us))?;
    Ok([
        start,
        end,
        real(s.distance_m),
        real(s.duration_s),
        real(s.moving_time_s),
        real(s.fuel_used_l),
        real(s.max_speed_kmh),
        real(s.mean_speed_kmh),
        Value::Integer(s.abs_interventions.into()),
        real(s.abs_time_s),
        Value::Integer(s.hard_brakings.into()),
        Value::Integer(s.shifts.into()),
        real(s.cruise_time_s),
        Value::Integer(s.diff_interventions.into()),
        real(s.diff_time_s),
    ])
}

/// A [`TripStats`] from the [`STATS_COLUMNS`], the first at column `at`.
pub(super) fn stats_from_row(row: &Row<'_>, at: usize) -> rusqlite::Result<TripStats> {
    Ok(TripStats {
        start_us: unsigned_at(row, at)?,
        end_us: unsigned_at(row, at + 1)?,
        distance_m: real_at(row, at + 2)?,
        duration_s: real_at(row, at + 3)?,
        moving_time_s: real_at(row, at + 4)?,
        fuel_used_l: real_at(row, at + 5)?,
        max_speed_kmh: real_at(row, at + 6)?,
        mean_speed_kmh: real_at(row, at + 7)?,
        abs_interventions: unsigned_at(row, at + 8)?,
        abs_time_s: real_at(row, at + 9)?,
        hard_brakings: unsigned_at(row, at + 10)?,
        shifts: unsigned_at(row, at + 11)?,
        cruise_time_s: real_at(row, at + 12)?,
        diff_interventions: unsigned_at(row, at + 13)?,
        diff_time_s: real_at(row, at + 14)?,
    })
}

/// An unsigned integer column read back (for callers outside this module).
pub(super) fn u8_at(row: &Row<'_>, i: usize) -> rusqlite::Result<u8> {
    unsigned_at(row, i)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn column_lists_agree() {
        let columns = STATS_COLUMNS.split(',').count();
        let placeholders = STATS_PLACEHOLDERS.split(',').count();
        let values = stats_values(&TripStats::default()).unwrap().len();
        assert_eq!((columns, placeholders), (values, values));
    }

    #[test]
    fn nan_is_null_and_bus_time_past_i64_is_refused() {
        assert_eq!(real(f64::NAN), Value::Null);
        assert_eq!(real(f64::INFINITY), Value::Real(f64::INFINITY));
        let stats = TripStats {
            end_us: u64::MAX,
            ..TripStats::default()
        };
        assert_eq!(stats_values(&stats), Err(format!("end_us {}", u64::MAX)));
    }
}
