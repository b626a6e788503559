-- rackd's first schema: jobs, their history, locations and the event log.
-- Times are Unix milliseconds (UTC).

CREATE TABLE jobs (
    id            INTEGER PRIMARY KEY,
    reference     TEXT UNIQUE,
    kind          TEXT    NOT NULL,
    priority      INTEGER NOT NULL CHECK (priority BETWEEN 0 AND 20),
    barcode       TEXT,
    spec          TEXT    NOT NULL,            -- JSON: the kind's own fields (locations, light)
    request       TEXT    NOT NULL,            -- canonical request, for idempotent re-POSTs
    device        TEXT,                        -- the device named in the request or routed to
    state         TEXT    NOT NULL,
    forced        INTEGER NOT NULL DEFAULT 0,
    failure_kind  TEXT,
    failure_code  INTEGER,
    failure_text  TEXT,
    device_ref    TEXT,                        -- the device's handle on the job (slot, task no.)
    created_at    INTEGER NOT NULL,
    updated_at    INTEGER NOT NULL
);
CREATE INDEX jobs_state ON jobs (state, priority, id);
CREATE INDEX jobs_device ON jobs (device, state);
CREATE INDEX jobs_created ON jobs (created_at);

CREATE TABLE job_history (
    id        INTEGER PRIMARY KEY,
    job_id    INTEGER NOT NULL REFERENCES jobs (id),
    state     TEXT    NOT NULL,
    cause     TEXT    NOT NULL,
    detail    TEXT,                             -- JSON, optional
    at        INTEGER NOT NULL
);
CREATE INDEX job_history_job ON job_history (job_id, id);

CREATE TABLE locations (
    aisle       INTEGER NOT NULL,
    row         INTEGER NOT NULL,
    bay         INTEGER NOT NULL,
    level       INTEGER NOT NULL,
    position    INTEGER NOT NULL,
    occupied    INTEGER NOT NULL DEFAULT 0,
    barcode     TEXT,
    red         INTEGER NOT NULL DEFAULT 0,
    green       INTEGER NOT NULL DEFAULT 0,
    reserved_by INTEGER REFERENCES jobs (id),
    updated_at  INTEGER NOT NULL,
    PRIMARY KEY (aisle, row, bay, level, position)
) WITHOUT ROWID;

-- Every event published to WebSocket subscribers, for replay with ?since=SEQ.
-- seq is the rowid: gapless, since only committed rows take a number.
CREATE TABLE events (
    seq   INTEGER PRIMARY KEY,
    at    INTEGER NOT NULL,
    type  TEXT    NOT NULL,
    data  TEXT    NOT NULL
);
CREATE INDEX events_at ON events (at);
