-- Schema version 1: trips with their statistics, verdicts, trouble codes and series, and the
-- history of each vehicle's ECU identities.
--
-- REAL columns hold NULL where the value was NaN (SQLite cannot store NaN), so SQL
-- aggregates skip them. STRICT tables: SQLite refuses a value of the wrong type.

-- 'APLG': tells an AutoPlug database from another program's that also uses user_version.
PRAGMA application_id = 1095781447;

CREATE TABLE vehicles (
    id   INTEGER PRIMARY KEY,
    -- The VIN, or a name the user gives.
    name TEXT NOT NULL UNIQUE
) STRICT;

CREATE TABLE trips (
    id                 INTEGER PRIMARY KEY,
    vehicle_id         INTEGER NOT NULL REFERENCES vehicles (id),
    -- bus.log, socketcand://...
    source             TEXT    NOT NULL,
    -- Wall clock when the gateway saw the trip start (for a replayed log: when it ran).
    started_at_unix_ms INTEGER NOT NULL,
    status             TEXT    NOT NULL CHECK (status IN ('open', 'closed', 'interrupted')),
    -- TripEnd::name(): parked, bus silent, end of input. Set exactly when closed.
    end_reason         TEXT,
    -- TripStats, a column per field: final when closed, else the last checkpoint's.
    start_us           INTEGER NOT NULL CHECK (start_us >= 0),
    end_us             INTEGER NOT NULL CHECK (end_us >= 0),
    distance_m         REAL,
    duration_s         REAL,
    moving_time_s      REAL,
    fuel_used_l        REAL,
    max_speed_kmh      REAL,
    mean_speed_kmh     REAL,
    abs_interventions  INTEGER NOT NULL CHECK (abs_interventions >= 0),
    abs_time_s         REAL,
    hard_brakings      INTEGER NOT NULL CHECK (hard_brakings >= 0),
    shifts             INTEGER NOT NULL CHECK (shifts >= 0),
    cruise_time_s      REAL,
    diff_interventions INTEGER NOT NULL CHECK (diff_interventions >= 0),
    diff_time_s        REAL,
    CHECK ((status = 'closed') = (end_reason IS NOT NULL))
) STRICT;

CREATE INDEX trips_by_vehicle ON trips (vehicle_id, started_at_unix_ms);
CREATE INDEX trips_by_start ON trips (started_at_unix_ms);
-- Only the trips under way: the sweep on open finds them without a scan.
CREATE INDEX trips_open ON trips (status) WHERE status = 'open';

CREATE TABLE trip_verdicts (
    trip_id        INTEGER NOT NULL REFERENCES trips (id) ON DELETE CASCADE,
    -- Position in the list given.
    seq            INTEGER NOT NULL,
    ecu            TEXT    NOT NULL,
    -- ok, suspect, faulty, no data
    verdict        TEXT    NOT NULL,
    routine        TEXT    NOT NULL,
    number         REAL,
    unit           TEXT    NOT NULL,
    suspect_above  REAL,
    faulty_above   REAL,
    -- The evidence window, s from the trip's start: both or neither.
    window_start_s REAL,
    window_end_s   REAL,
    evidence       TEXT    NOT NULL,
    PRIMARY KEY (trip_id, seq)
) STRICT;

CREATE INDEX trip_verdicts_by_routine ON trip_verdicts (ecu, routine, verdict);

CREATE TABLE trip_dtcs (
    trip_id     INTEGER NOT NULL REFERENCES trips (id) ON DELETE CASCADE,
    seq         INTEGER NOT NULL,
    ecu         TEXT    NOT NULL,
    -- e.g. U0126-87
    code        TEXT    NOT NULL,
    status      INTEGER NOT NULL CHECK (status BETWEEN 0 AND 255),
    description TEXT    NOT NULL,
    PRIMARY KEY (trip_id, seq)
) STRICT;

CREATE INDEX trip_dtcs_by_code ON trip_dtcs (code);

-- The VSS paths, stored once rather than in every series point.
CREATE TABLE signals (
    id   INTEGER PRIMARY KEY,
    path TEXT NOT NULL UNIQUE
) STRICT;

-- One bucket of one signal. The primary key is the index the plots read by; a bucket sent
-- again (it was still filling at the last checkpoint) replaces the stored one.
CREATE TABLE trip_series (
    trip_id   INTEGER NOT NULL REFERENCES trips (id) ON DELETE CASCADE,
    signal_id INTEGER NOT NULL REFERENCES signals (id),
    t_s       REAL    NOT NULL,
    mean      REAL,
    min       REAL,
    max       REAL,
    PRIMARY KEY (trip_id, signal_id, t_s)
) STRICT, WITHOUT ROWID;

-- History: a row per identity an ECU of a vehicle has shown; a new row when it changes
-- (a reflash is a new software_version, first seen on its date).
CREATE TABLE ecu_inventory (
    id                 INTEGER PRIMARY KEY,
    vehicle_id         INTEGER NOT NULL REFERENCES vehicles (id),
    ecu                TEXT    NOT NULL,
    node               INTEGER NOT NULL CHECK (node BETWEEN 0 AND 255),
    -- NULL: the ECU did not answer that identifier.
    part_number        TEXT,
    software_version   TEXT,
    hardware_version   TEXT,
    serial_number      TEXT,
    first_seen_unix_ms INTEGER NOT NULL,
    last_seen_unix_ms  INTEGER NOT NULL
) STRICT;

CREATE INDEX ecu_inventory_by_vehicle ON ecu_inventory (vehicle_id, ecu, id);
CREATE INDEX ecu_inventory_by_part ON ecu_inventory (part_number);
CREATE INDEX ecu_inventory_by_software ON ecu_inventory (software_version);

-- The current identity of every ECU of every vehicle (its newest history row): the fleet
-- asks it "which vehicles carry part X / software Y".
CREATE VIEW ecu_current AS
SELECT v.name AS vehicle, i.ecu, i.node, i.part_number, i.software_version,
       i.hardware_version, i.serial_number, i.first_seen_unix_ms, i.last_seen_unix_ms
FROM ecu_inventory AS i
JOIN vehicles AS v ON v.id = i.vehicle_id
WHERE i.id = (SELECT max(j.id) FROM ecu_inventory AS j
              WHERE j.vehicle_id = i.vehicle_id AND j.ecu = i.ecu);
