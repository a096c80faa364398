//! The fleet's data behind one interface, on PostgreSQL or SQLite: vehicles and what they
//! carry, their trips with the verdicts and trouble codes, and the recall queries over them.
//! Every statement is written once and runs on both engines.

use std::collections::BTreeMap;
use std::path::Path;

use autoplug_image::Version;
use serde::{Deserialize, Serialize};

use crate::db::{transaction, Db, DbError, PostgresDb, Row, SqliteDb, Value};
use crate::migrations::migrate;
use crate::report::{InventoryReport, ReportError, TripReport};

/// Why the store could not do something.
#[derive(Debug, Clone, PartialEq)]
pub enum StoreError {
    /// The database failed (unreachable, full, a constraint).
    Db(DbError),
    /// What was given is not valid.
    Invalid(String),
}

impl std::fmt::Display for StoreError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            StoreError::Db(e) => e.fmt(f),
            StoreError::Invalid(e) => f.write_str(e),
        }
    }
}

impl std::error::Error for StoreError {}

impl From<DbError> for StoreError {
    fn from(e: DbError) -> Self {
        StoreError::Db(e)
    }
}

impl From<ReportError> for StoreError {
    fn from(e: ReportError) -> Self {
        StoreError::Invalid(e.0)
    }
}

/// The fleet's database.
pub struct FleetStore {
    db: Box<dyn Db>,
}

/// A recall by what vehicles carry: every filter given must hold for one ECU of the
/// vehicle.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct InventoryQuery {
    /// The ECU (`cruise`...).
    pub ecu: Option<String>,
    /// Its part number, exactly.
    pub part_number: Option<String>,
    /// Lowest software version, inclusive.
    #[serde(default, with = "version_text")]
    pub software_from: Option<Version>,
    /// Highest software version, inclusive.
    #[serde(default, with = "version_text")]
    pub software_to: Option<Version>,
    /// Its hardware version, exactly.
    pub hardware_version: Option<String>,
    /// Lowest serial number, inclusive (serials compare as text: same-length serials of
    /// one supplier order as their numbers do).
    pub serial_from: Option<String>,
    /// Highest serial number, inclusive.
    pub serial_to: Option<String>,
}

/// One ECU that matched an inventory recall: the evidence that the vehicle carries it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct InventoryHit {
    /// The vehicle.
    pub vin: String,
    /// The ECU.
    pub ecu: String,
    /// What it reported.
    pub part_number: Option<String>,
    /// See `part_number`.
    pub software_version: Option<String>,
    /// See `part_number`.
    pub hardware_version: Option<String>,
    /// See `part_number`.
    pub serial: Option<String>,
    /// When the vehicle reported it, ms since the Unix epoch.
    pub reported_at_ms: i64,
}

impl InventoryHit {
    /// A row of `vin, ecu, part_number, software_version, hardware_version, serial,
    /// reported_at_ms` (the inventory queries' columns).
    fn from_row(r: &Row) -> Self {
        InventoryHit {
            vin: text(r, 0).unwrap_or_default(),
            ecu: text(r, 1).unwrap_or_default(),
            part_number: text(r, 2),
            software_version: text(r, 3),
            hardware_version: text(r, 4),
            serial: text(r, 5),
            reported_at_ms: int(r, 6),
        }
    }
}

/// What evidence a recall asks for.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Finding {
    /// A diagnostic routine judged the ECU faulty at the end of a trip.
    Faulty,
    /// The ECU reported this trouble code (`U0140` matches every failure type,
    /// `U0140-87` only that one).
    Dtc(String),
}

/// A recall by what the drives showed, within a period.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EvidenceQuery {
    /// The finding.
    pub finding: Finding,
    /// Only this ECU's.
    pub ecu: Option<String>,
    /// From (inclusive), ms since the Unix epoch.
    pub since_ms: i64,
    /// Until (exclusive).
    pub until_ms: i64,
}

/// One piece of evidence against a vehicle.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Evidence {
    /// The vehicle's trip it comes from.
    pub trip: i64,
    /// When the trip ended (the verdict) or the code was read, ms since the Unix epoch.
    pub at_ms: i64,
    /// The ECU.
    pub ecu: String,
    /// `faulty: cruise hold (12.5 km/h)` or `U0140-87 (status 0x09)`.
    pub what: String,
    /// The routine's words, or the code's description.
    pub detail: String,
}

/// A vehicle a recall found, with every piece of evidence.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EvidenceHit {
    /// The vehicle.
    pub vin: String,
    /// Oldest first.
    pub evidence: Vec<Evidence>,
}

/// The fleet in figures.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct FleetSummary {
    /// Vehicles known.
    pub vehicles: i64,
    /// Trips stored.
    pub trips: i64,
    /// Kilometres driven in them.
    pub distance_km: f64,
    /// Faulty verdicts.
    pub faulty_verdicts: i64,
}

/// What a store write did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stored {
    /// It was new and is stored.
    New,
    /// It was there already (a report delivered twice): nothing changed.
    Duplicate,
}

/// A version as its text (`"1.2.0"`) in JSON.
mod version_text {
    use autoplug_image::Version;
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(v: &Option<Version>, s: S) -> Result<S::Ok, S::Error> {
        match v {
            Some(v) => s.serialize_str(&v.to_string()),
            None => s.serialize_none(),
        }
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Option<Version>, D::Error> {
        Option::<String>::deserialize(d)?
            .map(|t| t.parse().map_err(serde::de::Error::custom))
            .transpose()
    }
}

pub(crate) fn now_ms() -> i64 {
    crate::unix_ms()
}

pub(crate) fn text(row: &Row, i: usize) -> Option<String> {
    row.get(i).and_then(Value::text).map(str::to_string)
}

pub(crate) fn int(row: &Row, i: usize) -> i64 {
    row.get(i).and_then(Value::int).unwrap_or(0)
}

pub(crate) fn float(row: &Row, i: usize) -> Option<f64> {
    row.get(i).and_then(Value::float)
}

/// The parsed version columns of a version text (`None` for text that is no version).
fn version_parts(text: Option<&str>) -> [Value; 3] {
    match text.and_then(|t| t.trim().parse::<Version>().ok()) {
        Some(v) => [
            Value::Int(v.major.into()),
            Value::Int(v.minor.into()),
            Value::Int(v.patch.into()),
        ],
        None => [Value::Null, Value::Null, Value::Null],
    }
}

/// SQL and its parameters, built up filter by filter.
struct Sql {
    text: String,
    params: Vec<Value>,
}

impl Sql {
    fn new(text: &str) -> Self {
        Self {
            text: text.to_string(),
            params: Vec::new(),
        }
    }

    /// Appends `clause`, whose `?` placeholders take the next parameters in turn.
    fn and(&mut self, clause: &str, values: impl IntoIterator<Item = Value>) {
        let mut values = values.into_iter();
        self.text.push_str(" AND ");
        for c in clause.chars() {
            if c == '?' {
                self.params.push(values.next().unwrap_or(Value::Null));
                self.text.push_str(&format!("${}", self.params.len()));
            } else {
                self.text.push(c);
            }
        }
    }
}

impl FleetStore {
    /// Opens the fleet database at `address` and brings its schema up to date:
    /// `postgresql://...` or `postgres://...` (or libpq's `host=... dbname=...`) for a
    /// PostgreSQL server; `sqlite:FILE` or a file path for SQLite.
    pub fn open(address: &str) -> Result<Self, StoreError> {
        let db: Box<dyn Db> = if address.starts_with("postgresql://")
            || address.starts_with("postgres://")
            || address.contains("host=")
        {
            Box::new(PostgresDb::connect(address)?)
        } else {
            let path = address.strip_prefix("sqlite:").unwrap_or(address);
            if path.is_empty() {
                return Err(StoreError::Invalid(
                    "no database given: postgresql://HOST/DB or a SQLite file".into(),
                ));
            }
            Box::new(SqliteDb::open(Path::new(path))?)
        };
        Self::with_db(db)
    }

    /// The store over an open connection; migrates it.
    pub fn with_db(mut db: Box<dyn Db>) -> Result<Self, StoreError> {
        migrate(db.as_mut())?;
        Ok(Self { db })
    }

    /// The database (for the benchmark's plans and the tests).
    pub fn db(&mut self) -> &mut dyn Db {
        self.db.as_mut()
    }

    /// Where the data is.
    pub fn name(&self) -> &str {
        self.db.name()
    }

    fn touch_vehicle(db: &mut dyn Db, vin: &str, seen_ms: i64) -> Result<(), DbError> {
        db.execute(
            "INSERT INTO vehicles (vin, first_seen_ms, last_seen_ms) VALUES ($1, $2, $2)
             ON CONFLICT (vin) DO UPDATE SET last_seen_ms =
                 CASE WHEN excluded.last_seen_ms > vehicles.last_seen_ms
                      THEN excluded.last_seen_ms ELSE vehicles.last_seen_ms END",
            &[Value::from(vin), Value::Int(seen_ms)],
        )?;
        Ok(())
    }

    /// Stores a vehicle's inventory: each ECU's row becomes what it reported now; an
    /// identity that changed (a flash, a replaced ECU) is also added to its history. ECUs
    /// that did not answer keep what they last reported.
    pub fn record_inventory(
        &mut self,
        report: &InventoryReport,
    ) -> Result<Vec<String>, StoreError> {
        let vin = report.check()?;
        let vin = vin.as_str();
        let received = now_ms();
        transaction(self.db.as_mut(), |db| -> Result<_, StoreError> {
            Self::touch_vehicle(db, vin, received)?;
            // A vehicle sends a report again until its receipt comes: an older inventory
            // arriving after a newer one (its receipt was lost) must not undo it.
            let newer = db.query(
                "SELECT 1 FROM vehicles WHERE vin = $1 AND inventory_at_ms > $2",
                &[Value::from(vin), Value::Int(report.read_at_ms)],
            )?;
            if !newer.is_empty() {
                return Ok(Vec::new());
            }
            db.execute(
                "UPDATE vehicles SET inventory_at_ms = $2 WHERE vin = $1",
                &[Value::from(vin), Value::Int(report.read_at_ms)],
            )?;
            // What the vehicle's ECUs reported last, in one query (the inventory's ECUs are
            // distinct: `check` refuses one listed twice).
            let stored: BTreeMap<String, Row> = db
                .query(
                    "SELECT ecu, part_number, software_version, hardware_version, serial
                     FROM ecus WHERE vin = $1",
                    &[Value::from(vin)],
                )?
                .into_iter()
                .filter_map(|row| Some((text(&row, 0)?, row[1..].to_vec())))
                .collect();
            let mut changed = Vec::new();
            let mut rows = Vec::with_capacity(report.ecus.len());
            let mut history = Vec::new();
            for ecu in &report.ecus {
                let identity = [
                    Value::from(ecu.part_number.clone()),
                    Value::from(ecu.software_version.clone()),
                    Value::from(ecu.hardware_version.clone()),
                    Value::from(ecu.serial_number.clone()),
                ];
                let same = stored
                    .get(&ecu.ecu)
                    .is_some_and(|row| row[..] == identity[..]);
                let [major, minor, patch] = version_parts(ecu.software_version.as_deref());
                rows.push(vec![
                    Value::from(vin),
                    Value::from(ecu.ecu.as_str()),
                    Value::Int(ecu.node.into()),
                    identity[0].clone(),
                    identity[1].clone(),
                    major,
                    minor,
                    patch,
                    identity[2].clone(),
                    identity[3].clone(),
                ]);
                if !same {
                    let [p, s, h, n] = identity;
                    history.push(vec![
                        Value::from(vin),
                        Value::from(ecu.ecu.as_str()),
                        p,
                        s,
                        h,
                        n,
                    ]);
                    changed.push(ecu.ecu.clone());
                }
            }
            insert_rows(
                db,
                "INSERT INTO ecus (vin, ecu, node, part_number, software_version,
                     sw_major, sw_minor, sw_patch, hardware_version, serial, reported_at_ms)
                 VALUES ",
                "($P, $0)",
                " ON CONFLICT (vin, ecu) DO UPDATE SET node = excluded.node,
                     part_number = excluded.part_number,
                     software_version = excluded.software_version,
                     sw_major = excluded.sw_major, sw_minor = excluded.sw_minor,
                     sw_patch = excluded.sw_patch,
                     hardware_version = excluded.hardware_version,
                     serial = excluded.serial, reported_at_ms = excluded.reported_at_ms",
                &[Value::Int(report.read_at_ms)],
                &rows,
                false,
            )?;
            insert_rows(
                db,
                "INSERT INTO ecu_history (vin, ecu, part_number, software_version,
                     hardware_version, serial, reported_at_ms) VALUES ",
                "($P, $0)",
                "",
                &[Value::Int(report.read_at_ms)],
                &history,
                false,
            )?;
            Ok(changed)
        })
    }

    /// Stores a trip with its verdicts and trouble codes, once: the same trip again (a
    /// redelivered message) changes nothing.
    pub fn record_trip(&mut self, report: &TripReport) -> Result<Stored, StoreError> {
        report.check()?;
        // A batch of one, in a transaction of its own (a savepoint inside a batch's).
        self.db.begin()?;
        match self.record_trips_in_batch(&[report]) {
            Ok(stored) => {
                self.db.commit()?;
                self.touch_vehicles(&[report.vin.as_str()], now_ms())?;
                Ok(stored.into_iter().next().unwrap_or(Stored::Duplicate))
            }
            Err(error) => {
                let _ = self.db.rollback();
                Err(error)
            }
        }
    }

    /// Marks `vins` seen at `at_ms` (never earlier than they were), in a statement of its
    /// own after a batch's commit: each row's lock lasts that statement only.
    pub fn touch_vehicles(&mut self, vins: &[&str], at_ms: i64) -> Result<(), StoreError> {
        for chunk in vins.chunks(500) {
            let list: Vec<String> = (0..chunk.len()).map(|i| format!("${}", i + 2)).collect();
            let mut params = vec![Value::Int(at_ms)];
            params.extend(chunk.iter().map(|v| Value::from(*v)));
            self.db.execute(
                &format!(
                    "UPDATE vehicles SET last_seen_ms = $1 WHERE last_seen_ms < $1 AND vin IN ({})",
                    list.join(", ")
                ),
                &params,
            )?;
        }
        Ok(())
    }

    /// Stores trips (each already [`TripReport::check`]ed) in the transaction open, a
    /// batch's: the vehicles touched in one statement, the trips in one (each once: those
    /// there already, or twice in the batch, are [`Stored::Duplicate`]), the new trips'
    /// verdicts and trouble codes in one each. A report's own statements (a dozen for a
    /// trip with nine verdicts) would cost a round trip to the server each, which is what
    /// bounds a service's intake, not the database's work.
    pub fn record_trips_in_batch(
        &mut self,
        reports: &[&TripReport],
    ) -> Result<Vec<Stored>, StoreError> {
        if reports.is_empty() {
            return Ok(Vec::new());
        }
        let received = now_ms();
        let db = self.db.as_mut();
        // New vehicles first, in VIN order (see `Ingest::take_batch`). A vehicle there
        // already is left alone: updating its row here would lock it until the commit,
        // and two services' batches of the same cars would then take turns instead of
        // running side by side; when it was last seen is written after the commit
        // ([`Self::touch_vehicles`]).
        let vins: std::collections::BTreeSet<&str> =
            reports.iter().map(|r| r.vin.as_str()).collect();
        let rows: Vec<Vec<Value>> = vins.iter().map(|v| vec![Value::from(*v)]).collect();
        insert_rows(
            db,
            "INSERT INTO vehicles (vin, first_seen_ms, last_seen_ms) VALUES ",
            "($P, $0, $0)",
            " ON CONFLICT (vin) DO NOTHING",
            &[Value::Int(received)],
            &rows,
            false,
        )?;
        // Each trip once: a second copy in the batch is a duplicate without asking.
        let mut first_of: BTreeMap<(&str, i64), usize> = BTreeMap::new();
        let mut rows = Vec::new();
        for (i, r) in reports.iter().enumerate() {
            if first_of.contains_key(&(r.vin.as_str(), r.trip)) {
                continue;
            }
            first_of.insert((r.vin.as_str(), r.trip), i);
            let s = &r.stats;
            let stats = serde_json::to_string(s)
                .map_err(|e| StoreError::Invalid(format!("trip statistics: {e}")))?;
            rows.push(vec![
                Value::from(r.vin.as_str()),
                Value::Int(r.trip),
                Value::Int(r.started_at_ms),
                Value::Int(r.ended_at_ms),
                Value::from(r.end.name()),
                Value::Float(s.distance_m),
                Value::Float(s.duration_s),
                Value::Float(s.fuel_used_l),
                Value::Float(s.max_speed_kmh),
                Value::Int(s.abs_interventions.into()),
                Value::Int(s.shifts.into()),
                Value::Float(s.cruise_time_s),
                Value::Text(stats),
            ]);
        }
        let inserted = insert_rows(
            db,
            "INSERT INTO trips (vin, trip, started_at_ms, ended_at_ms, end_reason,
                 distance_m, duration_s, fuel_used_l, max_speed_kmh, abs_interventions,
                 shifts, cruise_time_s, stats, received_at_ms) VALUES ",
            "($P, $0)",
            " ON CONFLICT (vin, trip) DO NOTHING RETURNING vin, trip",
            &[Value::Int(received)],
            &rows,
            true,
        )?;
        let mut outcome = vec![Stored::Duplicate; reports.len()];
        for row in inserted {
            let key = (
                text(&row, 0).unwrap_or_default(),
                row.get(1).and_then(Value::int),
            );
            if let (vin, Some(trip)) = key {
                if let Some(&i) = first_of.get(&(vin.as_str(), trip)) {
                    outcome[i] = Stored::New;
                }
            }
        }
        let new = || {
            reports
                .iter()
                .zip(&outcome)
                .filter(|(_, o)| **o == Stored::New)
                .map(|(r, _)| *r)
        };
        let verdicts: Vec<Vec<Value>> = new()
            .flat_map(|r| {
                r.verdicts.iter().map(move |v| {
                    vec![
                        Value::from(r.vin.as_str()),
                        Value::Int(r.trip),
                        Value::from(v.ecu.as_str()),
                        Value::from(v.routine.as_str()),
                        Value::from(v.verdict.as_str()),
                        Value::from(v.number.filter(|n| n.is_finite())),
                        Value::from(v.unit.as_str()),
                        Value::from(v.evidence.as_str()),
                        Value::Int(r.ended_at_ms),
                    ]
                })
            })
            .collect();
        insert_rows(
            db,
            "INSERT INTO verdicts (vin, trip, ecu, routine, verdict, number, unit,
                 evidence, judged_at_ms) VALUES ",
            "($P)",
            " ON CONFLICT (vin, trip, ecu, routine) DO NOTHING",
            &[],
            &verdicts,
            false,
        )?;
        let dtcs: Vec<Vec<Value>> = new()
            .flat_map(|r| {
                r.dtcs.iter().map(move |d| {
                    vec![
                        Value::from(r.vin.as_str()),
                        Value::Int(r.trip),
                        Value::from(d.ecu.as_str()),
                        Value::from(d.code.as_str()),
                        Value::Int(d.status.into()),
                        Value::from(d.description.as_str()),
                        Value::Int(r.ended_at_ms),
                    ]
                })
            })
            .collect();
        insert_rows(
            db,
            "INSERT INTO dtcs (vin, trip, ecu, code, status, description, reported_at_ms)
             VALUES ",
            "($P)",
            " ON CONFLICT (vin, trip, ecu, code) DO NOTHING",
            &[],
            &dtcs,
            false,
        )?;
        Ok(outcome)
    }

    /// The SQL and parameters of an inventory recall (the benchmark shows its plan).
    pub fn inventory_sql(query: &InventoryQuery) -> (String, Vec<Value>) {
        let mut sql = Sql::new(
            "SELECT vin, ecu, part_number, software_version, hardware_version, serial,
                    reported_at_ms
             FROM ecus WHERE 1 = 1",
        );
        if let Some(ecu) = &query.ecu {
            sql.and("ecu = ?", [Value::from(ecu.as_str())]);
        }
        if let Some(part) = &query.part_number {
            sql.and("part_number = ?", [Value::from(part.as_str())]);
        }
        let parts = |v: &Version| {
            [
                Value::Int(v.major.into()),
                Value::Int(v.minor.into()),
                Value::Int(v.patch.into()),
            ]
        };
        if let Some(from) = &query.software_from {
            sql.and("(sw_major, sw_minor, sw_patch) >= (?, ?, ?)", parts(from));
        }
        if let Some(to) = &query.software_to {
            sql.and("(sw_major, sw_minor, sw_patch) <= (?, ?, ?)", parts(to));
        }
        if let Some(hw) = &query.hardware_version {
            sql.and("hardware_version = ?", [Value::from(hw.as_str())]);
        }
        if let Some(from) = &query.serial_from {
            sql.and("serial >= ?", [Value::from(from.as_str())]);
        }
        if let Some(to) = &query.serial_to {
            sql.and("serial <= ?", [Value::from(to.as_str())]);
        }
        sql.text.push_str(" ORDER BY vin, ecu");
        (sql.text, sql.params)
    }

    /// The vehicles that carry what `query` describes, each ECU that matched with what it
    /// reported: exactly those, in VIN order. A query without any filter is refused (it
    /// would recall the whole fleet).
    pub fn recall_by_inventory(
        &mut self,
        query: &InventoryQuery,
    ) -> Result<Vec<InventoryHit>, StoreError> {
        if *query == InventoryQuery::default() {
            return Err(StoreError::Invalid(
                "a recall needs at least one of: ECU, part number, software version, \
                 hardware version, serial range"
                    .into(),
            ));
        }
        if let (Some(from), Some(to)) = (&query.software_from, &query.software_to) {
            if from > to {
                return Err(StoreError::Invalid(format!(
                    "software range {from} to {to} is empty"
                )));
            }
        }
        let (sql, params) = Self::inventory_sql(query);
        let rows = self.db.query(&sql, &params)?;
        Ok(rows.iter().map(InventoryHit::from_row).collect())
    }

    /// The SQL and parameters of an evidence recall.
    pub fn evidence_sql(query: &EvidenceQuery) -> (String, Vec<Value>) {
        let mut sql = match &query.finding {
            Finding::Faulty => {
                let mut sql = Sql::new(
                    "SELECT vin, trip, judged_at_ms, ecu, routine, number, unit, evidence
                     FROM verdicts WHERE 1 = 1",
                );
                sql.and("verdict = ?", [Value::from("faulty")]);
                sql
            }
            Finding::Dtc(code) => {
                let mut sql = Sql::new(
                    "SELECT vin, trip, reported_at_ms, ecu, code, status, description
                     FROM dtcs WHERE 1 = 1",
                );
                if code.contains('-') {
                    sql.and("code = ?", [Value::from(code.as_str())]);
                } else {
                    // The base code with any failure type: a range over the index.
                    sql.and(
                        "code >= ? AND code < ?",
                        [
                            Value::from(format!("{code}-")),
                            Value::from(format!("{code}.")),
                        ],
                    );
                }
                sql
            }
        };
        let time = match query.finding {
            Finding::Faulty => "judged_at_ms",
            Finding::Dtc(_) => "reported_at_ms",
        };
        if let Some(ecu) = &query.ecu {
            sql.and("ecu = ?", [Value::from(ecu.as_str())]);
        }
        sql.and(
            &format!("{time} >= ? AND {time} < ?"),
            [Value::Int(query.since_ms), Value::Int(query.until_ms)],
        );
        sql.text.push_str(&format!(" ORDER BY vin, {time}, trip"));
        (sql.text, sql.params)
    }

    /// The vehicles whose drives showed the finding within the period, each with every
    /// piece of evidence: exactly those, in VIN order.
    pub fn recall_by_evidence(
        &mut self,
        query: &EvidenceQuery,
    ) -> Result<Vec<EvidenceHit>, StoreError> {
        if query.since_ms >= query.until_ms {
            return Err(StoreError::Invalid("the period is empty".into()));
        }
        if let Finding::Dtc(code) = &query.finding {
            if code.is_empty()
                || code.len() > 16
                || !code.chars().all(|c| c.is_ascii_alphanumeric() || c == '-')
            {
                return Err(StoreError::Invalid(format!(
                    "'{code}' is not a trouble code (like U0140 or U0140-87)"
                )));
            }
        }
        let (sql, params) = Self::evidence_sql(query);
        let rows = self.db.query(&sql, &params)?;
        let mut by_vin: BTreeMap<String, Vec<Evidence>> = BTreeMap::new();
        for r in &rows {
            let evidence = match query.finding {
                Finding::Faulty => Evidence {
                    trip: int(r, 1),
                    at_ms: int(r, 2),
                    ecu: text(r, 3).unwrap_or_default(),
                    what: match float(r, 5) {
                        Some(n) => format!(
                            "faulty: {} ({n:.1} {})",
                            text(r, 4).unwrap_or_default(),
                            text(r, 6).unwrap_or_default()
                        ),
                        None => format!("faulty: {}", text(r, 4).unwrap_or_default()),
                    },
                    detail: text(r, 7).unwrap_or_default(),
                },
                Finding::Dtc(_) => Evidence {
                    trip: int(r, 1),
                    at_ms: int(r, 2),
                    ecu: text(r, 3).unwrap_or_default(),
                    what: format!(
                        "{} (status 0x{:02X})",
                        text(r, 4).unwrap_or_default(),
                        int(r, 5)
                    ),
                    detail: text(r, 6).unwrap_or_default(),
                },
            };
            by_vin
                .entry(text(r, 0).unwrap_or_default())
                .or_default()
                .push(evidence);
        }
        Ok(by_vin
            .into_iter()
            .map(|(vin, evidence)| EvidenceHit { vin, evidence })
            .collect())
    }

    /// The current inventory of one vehicle, by ECU.
    pub fn vehicle_inventory(&mut self, vin: &str) -> Result<Vec<InventoryHit>, StoreError> {
        let rows = self.db.query(
            "SELECT vin, ecu, part_number, software_version, hardware_version, serial,
                    reported_at_ms
             FROM ecus WHERE vin = $1 ORDER BY ecu",
            &[Value::from(vin)],
        )?;
        Ok(rows.iter().map(InventoryHit::from_row).collect())
    }

    /// The fleet in figures.
    pub fn summary(&mut self) -> Result<FleetSummary, StoreError> {
        let count = |db: &mut dyn Db, sql: &str| -> Result<i64, DbError> {
            Ok(db.query(sql, &[])?.first().map_or(0, |r| int(r, 0)))
        };
        let db = self.db.as_mut();
        let distance = db
            .query("SELECT sum(distance_m) FROM trips", &[])?
            .first()
            .and_then(|r| float(r, 0))
            .unwrap_or(0.0);
        Ok(FleetSummary {
            vehicles: count(db, "SELECT count(*) FROM vehicles")?,
            trips: count(db, "SELECT count(*) FROM trips")?,
            distance_km: distance / 1000.0,
            faulty_verdicts: count(db, "SELECT count(*) FROM verdicts WHERE verdict = 'faulty'")?,
        })
    }
}

/// Rows inserted by one statement per chunk: `head`, then each row as `row` with `$P`
/// standing for the row's own parameters and `$0` for the first of `shared` (bound once
/// per statement; at most ten), then `tail`. Chunks are powers of two up to [`MAX_ROWS_PER_STATEMENT`],
/// so a batch of any size uses one of a few statement shapes, each prepared once per
/// connection. Returns the rows the statements return when `returning`.
fn insert_rows(
    db: &mut dyn Db,
    head: &str,
    row: &str,
    tail: &str,
    shared: &[Value],
    rows: &[Vec<Value>],
    returning: bool,
) -> Result<Vec<Row>, DbError> {
    let mut template = row.to_string();
    for k in 0..shared.len() {
        template = template.replace(&format!("${k}"), &format!("${}", k + 1));
    }
    let mut returned = Vec::new();
    let mut rest = rows;
    while !rest.is_empty() {
        let take = chunk_len(rest.len());
        let (chunk, tail_rows) = rest.split_at(take);
        rest = tail_rows;
        let width = chunk[0].len();
        let mut sql = String::from(head);
        let mut params: Vec<Value> = shared.to_vec();
        for (i, values) in chunk.iter().enumerate() {
            if i > 0 {
                sql.push_str(", ");
            }
            let first = shared.len() + i * width + 1;
            let own: Vec<String> = (first..first + width).map(|n| format!("${n}")).collect();
            sql.push_str(&template.replace("$P", &own.join(", ")));
            params.extend(values.iter().cloned());
        }
        sql.push_str(tail);
        if returning {
            returned.extend(db.query(&sql, &params)?);
        } else {
            db.execute(&sql, &params)?;
        }
    }
    Ok(returned)
}

/// Most rows one insert statement carries (64 verdicts of 9 values: 576 parameters).
const MAX_ROWS_PER_STATEMENT: usize = 64;

/// The rows the next statement takes of `left`: the largest power of two up to both.
fn chunk_len(left: usize) -> usize {
    let cap = left.min(MAX_ROWS_PER_STATEMENT);
    1 << (usize::BITS - 1 - cap.leading_zeros())
}
