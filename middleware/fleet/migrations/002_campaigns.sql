-- Fleet schema 2: update campaigns, each vehicle's part in them, and what happened.

-- A campaign: a signed image for one ECU, rolled out in stages to the vehicles its
-- target query found when it was created.
CREATE TABLE campaigns (
    id {id},
    name TEXT NOT NULL UNIQUE,
    ecu TEXT NOT NULL,
    image_sha256 TEXT NOT NULL,
    image_version TEXT NOT NULL,
    image_bytes BIGINT NOT NULL,
    -- The query that chose the vehicles (JSON), kept as evidence of why these.
    target TEXT NOT NULL,
    -- Cumulative shares of the vehicles per stage, percent (JSON list, last 100).
    stages TEXT NOT NULL,
    -- A stage pauses the campaign when its failures pass this share of its vehicles.
    failure_threshold DOUBLE PRECISION NOT NULL,
    max_attempts BIGINT NOT NULL,
    -- An instruction unanswered this long is sent again (or, after the last attempt,
    -- the vehicle is reported as not answering).
    answer_within_ms BIGINT NOT NULL,
    -- How long an instruction holds from when it is sent.
    valid_for_ms BIGINT NOT NULL,
    message TEXT NOT NULL,
    -- running, paused, finished, cancelled.
    state TEXT NOT NULL,
    stage BIGINT NOT NULL,
    paused_reason TEXT,
    created_at_ms BIGINT NOT NULL,
    updated_at_ms BIGINT NOT NULL
);

-- Each target vehicle of a campaign: its stage and where it stands.
CREATE TABLE campaign_vehicles (
    campaign BIGINT NOT NULL REFERENCES campaigns (id),
    vin TEXT NOT NULL REFERENCES vehicles (vin),
    stage BIGINT NOT NULL,
    -- waiting, sent, received, installing, installed, declined, refused, failed, no_answer.
    state TEXT NOT NULL,
    attempts BIGINT NOT NULL,
    sent_at_ms BIGINT,
    updated_at_ms BIGINT NOT NULL,
    reason TEXT,
    version_running TEXT,
    PRIMARY KEY (campaign, vin)
);
CREATE INDEX campaign_vehicles_by_state ON campaign_vehicles (campaign, state, stage);

-- Every report and every instruction of a campaign, in order: the audit trail.
CREATE TABLE campaign_events (
    id {id},
    campaign BIGINT NOT NULL REFERENCES campaigns (id),
    vin TEXT NOT NULL,
    at_ms BIGINT NOT NULL,
    attempt BIGINT NOT NULL,
    state TEXT NOT NULL,
    reason TEXT
);
CREATE INDEX campaign_events_by_vehicle ON campaign_events (campaign, vin, id);
