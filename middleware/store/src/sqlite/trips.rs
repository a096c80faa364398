//! Trips: the [`TripStore`] of [`SqliteStore`], and the statements it runs.

use std::collections::HashMap;

use autoplug_trips::{SeriesPoint, TripEnd, TripStats};
use rusqlite::types::{Type, Value};
use rusqlite::{params, params_from_iter, Connection, OptionalExtension, Row};

use super::columns::{
    real, real_at, stats_from_row, stats_values, u8_at, STATS_COLUMNS, STATS_PLACEHOLDERS,
};
use super::inventory::{current, put_identity};
use super::{vehicle_id, Fail, SqliteStore};
use crate::error::{StoreError, StoreErrorKind};
use crate::model::{
    DtcRecord, EcuIdentity, FinishedTrip, NewTrip, TripDetail, TripId, TripRow, TripStatus,
    VerdictRecord,
};
use crate::store::TripStore;

impl TripStore for SqliteStore {
    fn begin_trip(&mut self, trip: &NewTrip) -> Result<TripId, StoreError> {
        let result = (|| -> Result<_, Fail> {
            let stats = TripStats {
                start_us: trip.start_us,
                end_us: trip.start_us,
                ..TripStats::default()
            };
            let stats = stats_of(None, &stats)?;
            let tx = self.write()?;
            let vehicle = vehicle_id(&tx, &trip.vehicle)?;
            let sql = format!(
                "INSERT INTO trips (vehicle_id, source, started_at_unix_ms, status, \
                 {STATS_COLUMNS}) VALUES (?, ?, ?, 'open', {STATS_PLACEHOLDERS})"
            );
            let head = [
                Value::Integer(vehicle),
                Value::Text(trip.source.clone()),
                Value::Integer(trip.started_at_unix_ms),
            ];
            tx.prepare_cached(&sql)?
                .execute(params_from_iter(head.into_iter().chain(stats)))?;
            let id = TripId(tx.last_insert_rowid());
            tx.commit()?;
            Ok(id)
        })();
        self.named(result)
    }

    fn checkpoint_trip(
        &mut self,
        id: TripId,
        stats: &TripStats,
        series: &[SeriesPoint],
    ) -> Result<(), StoreError> {
        let result = (|| -> Result<_, Fail> {
            let stats = stats_of(Some(id), stats)?;
            check_series(id, series)?;
            let tx = self.write()?;
            require_open(&tx, id)?;
            update_trip(&tx, id, stats, TripStatus::Open, None)?;
            put_series(&tx, id, series)?;
            tx.commit()?;
            Ok(())
        })();
        self.named(result)
    }

    fn finish_trip(
        &mut self,
        id: TripId,
        trip: &FinishedTrip,
        series: &[SeriesPoint],
    ) -> Result<(), StoreError> {
        let result = (|| -> Result<_, Fail> {
            let stats = stats_of(Some(id), &trip.stats)?;
            check_series(id, series)?;
            let tx = self.write()?;
            require_open(&tx, id)?;
            update_trip(&tx, id, stats, TripStatus::Closed, Some(trip.end))?;
            put_series(&tx, id, series)?;
            put_verdicts(&tx, id, &trip.verdicts)?;
            put_dtcs(&tx, id, &trip.dtcs)?;
            tx.commit()?;
            Ok(())
        })();
        self.named(result)
    }

    fn record_inventory(
        &mut self,
        vehicle: &str,
        seen_at_unix_ms: i64,
        ecus: &[EcuIdentity],
    ) -> Result<(), StoreError> {
        let result = (|| -> Result<_, Fail> {
            let tx = self.write()?;
            let vehicle = vehicle_id(&tx, vehicle)?;
            for e in ecus {
                put_identity(&tx, vehicle, seen_at_unix_ms, e)?;
            }
            tx.commit()?;
            Ok(())
        })();
        self.named(result)
    }

    fn inventory(&self, vehicle: &str) -> Result<Vec<(EcuIdentity, i64, i64)>, StoreError> {
        self.named(current(&self.conn, vehicle).map_err(Fail::from))
    }

    fn trips(&self, vehicle: Option<&str>) -> Result<Vec<TripRow>, StoreError> {
        let result = (|| -> Result<_, Fail> {
            let sql = format!(
                "{} WHERE ?1 IS NULL OR v.name = ?1 \
                 ORDER BY t.started_at_unix_ms DESC, t.id DESC",
                trips_select()
            );
            let mut stmt = self.conn.prepare_cached(&sql)?;
            let rows = stmt.query_map([vehicle], trip_row)?;
            Ok(rows.collect::<rusqlite::Result<Vec<_>>>()?)
        })();
        self.named(result)
    }

    fn trip(&self, id: TripId) -> Result<Option<TripDetail>, StoreError> {
        let result = (|| -> Result<_, Fail> {
            let tx = self.read()?;
            let sql = format!("{} WHERE t.id = ?", trips_select());
            let Some(row) = tx
                .prepare_cached(&sql)?
                .query_row([id.0], trip_row)
                .optional()?
            else {
                return Ok(None);
            };
            let verdicts = tx
                .prepare_cached(
                    "SELECT ecu, verdict, routine, number, unit, suspect_above, faulty_above, \
                     window_start_s, window_end_s, evidence \
                     FROM trip_verdicts WHERE trip_id = ? ORDER BY seq",
                )?
                .query_map([id.0], verdict_row)?
                .collect::<rusqlite::Result<Vec<_>>>()?;
            let dtcs = tx
                .prepare_cached(
                    "SELECT ecu, code, status, description FROM trip_dtcs \
                     WHERE trip_id = ? ORDER BY seq",
                )?
                .query_map([id.0], dtc_row)?
                .collect::<rusqlite::Result<Vec<_>>>()?;
            let series_signals = tx
                .prepare_cached(
                    "SELECT s.path FROM signals AS s WHERE EXISTS \
                     (SELECT 1 FROM trip_series AS p WHERE p.trip_id = ? AND p.signal_id = s.id) \
                     ORDER BY s.path",
                )?
                .query_map([id.0], |r| r.get(0))?
                .collect::<rusqlite::Result<Vec<_>>>()?;
            tx.finish()?;
            Ok(Some(TripDetail {
                row,
                verdicts,
                dtcs,
                series_signals,
            }))
        })();
        self.named(result)
    }

    fn series(&self, id: TripId, signal: &str) -> Result<Vec<SeriesPoint>, StoreError> {
        let result = (|| -> Result<_, Fail> {
            let tx = self.read()?;
            if !trip_exists(&tx, id)? {
                return Err(StoreErrorKind::NoSuchTrip(id).into());
            }
            let points = tx
                .prepare_cached(
                    "SELECT p.t_s, p.mean, p.min, p.max FROM trip_series AS p \
                     JOIN signals AS s ON s.id = p.signal_id \
                     WHERE p.trip_id = ? AND s.path = ? ORDER BY p.t_s",
                )?
                .query_map(params![id.0, signal], |r| {
                    Ok(SeriesPoint {
                        signal: signal.to_owned(),
                        t_s: r.get(0)?,
                        mean: real_at(r, 1)?,
                        min: real_at(r, 2)?,
                        max: real_at(r, 3)?,
                    })
                })?
                .collect::<rusqlite::Result<Vec<_>>>()?;
            tx.finish()?;
            Ok(points)
        })();
        self.named(result)
    }
}

/// Fails unless trip `id` exists and is open.
pub(super) fn require_open(conn: &Connection, id: TripId) -> Result<(), Fail> {
    let status: Option<String> = conn
        .prepare_cached("SELECT status FROM trips WHERE id = ?")?
        .query_row([id.0], |r| r.get(0))
        .optional()?;
    match status.as_deref().map(|s| (s, TripStatus::from_name(s))) {
        None => Err(StoreErrorKind::NoSuchTrip(id).into()),
        Some((_, Some(TripStatus::Open))) => Ok(()),
        Some((_, Some(status))) => Err(StoreErrorKind::TripNotOpen(id, status).into()),
        Some((s, None)) => {
            Err(StoreErrorKind::UnexpectedValue(format!("trip {id} has status {s:?}")).into())
        }
    }
}

pub(super) fn trip_exists(conn: &Connection, id: TripId) -> rusqlite::Result<bool> {
    conn.prepare_cached("SELECT EXISTS (SELECT 1 FROM trips WHERE id = ?)")?
        .query_row([id.0], |r| r.get(0))
}

/// The values of a trip's statistics, or why they cannot be stored.
pub(super) fn stats_of(id: Option<TripId>, stats: &TripStats) -> Result<[Value; 15], Fail> {
    stats_values(stats).map_err(|field| {
        let of = id.map_or_else(|| "a new trip".to_owned(), |id| format!("trip {id}"));
        StoreErrorKind::InvalidArgument(format!("{field} of {of} (over the largest integer)"))
            .into()
    })
}

/// Refuses series points without a time (before anything is written).
pub(super) fn check_series(id: TripId, series: &[SeriesPoint]) -> Result<(), Fail> {
    match series.iter().find(|p| p.t_s.is_nan()) {
        Some(p) => Err(StoreErrorKind::InvalidArgument(format!(
            "a point of {} with time NaN in trip {id}",
            p.signal
        ))
        .into()),
        None => Ok(()),
    }
}

/// Writes a trip's statistics, status and end.
pub(super) fn update_trip(
    conn: &Connection,
    id: TripId,
    stats: [Value; 15],
    status: TripStatus,
    end: Option<TripEnd>,
) -> rusqlite::Result<()> {
    let sql = format!(
        "UPDATE trips SET ({STATS_COLUMNS}) = ({STATS_PLACEHOLDERS}), status = ?, \
         end_reason = ? WHERE id = ?"
    );
    let tail = [
        Value::Text(status.name().to_owned()),
        end.map_or(Value::Null, |e| Value::Text(e.name().to_owned())),
        Value::Integer(id.0),
    ];
    conn.prepare_cached(&sql)?
        .execute(params_from_iter(stats.into_iter().chain(tail)))?;
    Ok(())
}

/// Adds (or replaces, same signal and time) series points of trip `id`.
pub(super) fn put_series(
    conn: &Connection,
    id: TripId,
    series: &[SeriesPoint],
) -> rusqlite::Result<()> {
    let mut add_signal =
        conn.prepare_cached("INSERT INTO signals (path) VALUES (?) ON CONFLICT (path) DO NOTHING")?;
    let mut get_signal = conn.prepare_cached("SELECT id FROM signals WHERE path = ?")?;
    let mut put = conn.prepare_cached(
        "INSERT INTO trip_series (trip_id, signal_id, t_s, mean, min, max) \
         VALUES (?, ?, ?, ?, ?, ?) \
         ON CONFLICT (trip_id, signal_id, t_s) \
         DO UPDATE SET mean = excluded.mean, min = excluded.min, max = excluded.max",
    )?;
    // Ids looked up in this transaction only: a cache kept across transactions could
    // hold the id of a signal whose insertion was rolled back.
    let mut signal_ids: HashMap<&str, i64> = HashMap::new();
    for p in series {
        let signal_id = match signal_ids.get(p.signal.as_str()) {
            Some(&sid) => sid,
            None => {
                add_signal.execute([&p.signal])?;
                let sid: i64 = get_signal.query_row([&p.signal], |r| r.get(0))?;
                signal_ids.insert(&p.signal, sid);
                sid
            }
        };
        put.execute(params![
            id.0,
            signal_id,
            p.t_s,
            real(p.mean),
            real(p.min),
            real(p.max)
        ])?;
    }
    Ok(())
}

pub(super) fn put_verdicts(
    conn: &Connection,
    id: TripId,
    verdicts: &[VerdictRecord],
) -> rusqlite::Result<()> {
    let mut put = conn.prepare_cached(
        "INSERT INTO trip_verdicts (trip_id, seq, ecu, verdict, routine, number, unit, \
         suspect_above, faulty_above, window_start_s, window_end_s, evidence) \
         VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
    )?;
    for (seq, v) in (0_i64..).zip(verdicts) {
        let (start, end) = v
            .window_s
            .map_or((Value::Null, Value::Null), |(a, b)| (real(a), real(b)));
        put.execute(params![
            id.0,
            seq,
            v.ecu,
            v.verdict,
            v.routine,
            v.number.map_or(Value::Null, real),
            v.unit,
            real(v.suspect_above),
            real(v.faulty_above),
            start,
            end,
            v.evidence,
        ])?;
    }
    Ok(())
}

pub(super) fn put_dtcs(conn: &Connection, id: TripId, dtcs: &[DtcRecord]) -> rusqlite::Result<()> {
    let mut put = conn.prepare_cached(
        "INSERT INTO trip_dtcs (trip_id, seq, ecu, code, status, description) \
         VALUES (?, ?, ?, ?, ?, ?)",
    )?;
    for (seq, d) in (0_i64..).zip(dtcs) {
        put.execute(params![id.0, seq, d.ecu, d.code, d.status, d.description])?;
    }
    Ok(())
}

/// `trips` joined with `vehicles`, the columns [`trip_row`] reads.
pub(super) fn trips_select() -> String {
    format!(
        "SELECT t.id, v.name, t.source, t.started_at_unix_ms, t.status, t.end_reason, \
         {STATS_COLUMNS} FROM trips AS t JOIN vehicles AS v ON v.id = t.vehicle_id"
    )
}

/// A value read that this program does not write.
pub(super) fn unexpected(column: usize, what: String) -> rusqlite::Error {
    rusqlite::Error::FromSqlConversionFailure(column, Type::Text, what.into())
}

pub(super) fn trip_row(r: &Row<'_>) -> rusqlite::Result<TripRow> {
    let status: String = r.get(4)?;
    let status = TripStatus::from_name(&status)
        .ok_or_else(|| unexpected(4, format!("trip status {status:?}")))?;
    let end = match r.get::<_, Option<String>>(5)? {
        None => None,
        Some(end) => Some(
            TripEnd::from_name(&end).ok_or_else(|| unexpected(5, format!("trip end {end:?}")))?,
        ),
    };
    Ok(TripRow {
        id: TripId(r.get(0)?),
        vehicle: r.get(1)?,
        source: r.get(2)?,
        started_at_unix_ms: r.get(3)?,
        status,
        end,
        stats: stats_from_row(r, 6)?,
    })
}

pub(super) fn verdict_row(r: &Row<'_>) -> rusqlite::Result<VerdictRecord> {
    let window = match (r.get::<_, Option<f64>>(7)?, r.get::<_, Option<f64>>(8)?) {
        (None, None) => None,
        (a, b) => Some((a.unwrap_or(f64::NAN), b.unwrap_or(f64::NAN))),
    };
    Ok(VerdictRecord {
        ecu: r.get(0)?,
        verdict: r.get(1)?,
        routine: r.get(2)?,
        number: r.get(3)?,
        unit: r.get(4)?,
        suspect_above: real_at(r, 5)?,
        faulty_above: real_at(r, 6)?,
        window_s: window,
        evidence: r.get(9)?,
    })
}

pub(super) fn dtc_row(r: &Row<'_>) -> rusqlite::Result<DtcRecord> {
    Ok(DtcRecord {
        ecu: r.get(0)?,
        code: r.get(1)?,
        status: u8_at(r, 2)?,
        description: r.get(3)?,
    })
}
