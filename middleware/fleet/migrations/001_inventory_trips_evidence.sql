-- Fleet schema 1: the vehicles, what each carries, and what their drives showed.
-- One text for PostgreSQL and SQLite: {id} and {blob} are each engine's own spelling of
-- an auto-numbered key and of bytes; every other type means the same in both.

-- A vehicle as the fleet knows it: by its VIN (ISO 3779, check digit verified).
CREATE TABLE vehicles (
    vin TEXT PRIMARY KEY,
    first_seen_ms BIGINT NOT NULL,
    last_seen_ms BIGINT NOT NULL,
    -- When its current inventory was reported (the vehicle's clock).
    inventory_at_ms BIGINT
);

-- What each vehicle carries now: one row per ECU, replaced by each inventory report.
-- The software version is kept parsed as well, so a version range is an index range.
CREATE TABLE ecus (
    vin TEXT NOT NULL REFERENCES vehicles (vin),
    ecu TEXT NOT NULL,
    node BIGINT NOT NULL,
    part_number TEXT,
    software_version TEXT,
    sw_major BIGINT,
    sw_minor BIGINT,
    sw_patch BIGINT,
    hardware_version TEXT,
    serial TEXT,
    reported_at_ms BIGINT NOT NULL,
    PRIMARY KEY (vin, ecu)
);
-- Recall by part and software version; by hardware version; by serial range.
CREATE INDEX ecus_by_part_version ON ecus (part_number, sw_major, sw_minor, sw_patch);
CREATE INDEX ecus_by_ecu_version ON ecus (ecu, sw_major, sw_minor, sw_patch);
CREATE INDEX ecus_by_hardware ON ecus (hardware_version);
CREATE INDEX ecus_by_part_serial ON ecus (part_number, serial);

-- Every identity an ECU of a vehicle has shown, oldest first: a flash leaves a trace.
CREATE TABLE ecu_history (
    id {id},
    vin TEXT NOT NULL REFERENCES vehicles (vin),
    ecu TEXT NOT NULL,
    part_number TEXT,
    software_version TEXT,
    hardware_version TEXT,
    serial TEXT,
    reported_at_ms BIGINT NOT NULL
);
CREATE INDEX ecu_history_by_vehicle ON ecu_history (vin, ecu, id);

-- A trip as its vehicle reported it at the end: the vehicle's own trip number, the
-- figures the recall and the fleet page use, and the whole statistics as JSON.
CREATE TABLE trips (
    vin TEXT NOT NULL REFERENCES vehicles (vin),
    trip BIGINT NOT NULL,
    started_at_ms BIGINT NOT NULL,
    ended_at_ms BIGINT NOT NULL,
    end_reason TEXT NOT NULL,
    distance_m DOUBLE PRECISION NOT NULL,
    duration_s DOUBLE PRECISION NOT NULL,
    fuel_used_l DOUBLE PRECISION NOT NULL,
    max_speed_kmh DOUBLE PRECISION NOT NULL,
    abs_interventions BIGINT NOT NULL,
    shifts BIGINT NOT NULL,
    cruise_time_s DOUBLE PRECISION NOT NULL,
    stats TEXT NOT NULL,
    received_at_ms BIGINT NOT NULL,
    PRIMARY KEY (vin, trip)
);
CREATE INDEX trips_by_end ON trips (ended_at_ms);

-- Each diagnostic routine's verdict at the end of a trip: the evidence of a recall.
CREATE TABLE verdicts (
    vin TEXT NOT NULL,
    trip BIGINT NOT NULL,
    ecu TEXT NOT NULL,
    routine TEXT NOT NULL,
    verdict TEXT NOT NULL,
    number DOUBLE PRECISION,
    unit TEXT NOT NULL,
    evidence TEXT NOT NULL,
    judged_at_ms BIGINT NOT NULL,
    PRIMARY KEY (vin, trip, ecu, routine),
    FOREIGN KEY (vin, trip) REFERENCES trips (vin, trip)
);
CREATE INDEX verdicts_by_ecu_verdict ON verdicts (ecu, verdict, judged_at_ms);

-- The trouble codes read from the ECUs at the end of a trip.
CREATE TABLE dtcs (
    vin TEXT NOT NULL,
    trip BIGINT NOT NULL,
    ecu TEXT NOT NULL,
    code TEXT NOT NULL,
    status BIGINT NOT NULL,
    description TEXT NOT NULL,
    reported_at_ms BIGINT NOT NULL,
    PRIMARY KEY (vin, trip, ecu, code),
    FOREIGN KEY (vin, trip) REFERENCES trips (vin, trip)
);
CREATE INDEX dtcs_by_code ON dtcs (code, reported_at_ms);
