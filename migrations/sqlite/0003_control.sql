-- Safety under faults: alarm kinds, control state that lasts, location locks, retries.

-- An alarm is one of a device's own codes (kind `device`) or one rackd raises about the
-- device (`link`, `heartbeat`, `degraded`, `memory_lost`, code 0); `detail` holds the
-- protocol's words where the text is for people.
ALTER TABLE alarms ADD COLUMN kind TEXT NOT NULL DEFAULT 'device';
ALTER TABLE alarms ADD COLUMN detail TEXT;
UPDATE alarms SET kind = 'link' WHERE class = 'link';
DROP INDEX alarms_active;
CREATE INDEX alarms_active ON alarms (device, kind, code) WHERE cleared_at IS NULL;

-- What operators set, restored at start: `device:ID` or `aisle:N` paused.
CREATE TABLE controls (
    target  TEXT    PRIMARY KEY,
    paused  INTEGER NOT NULL,
    by      TEXT    NOT NULL,
    reason  TEXT,
    at      INTEGER NOT NULL
);

-- Every operator action (pause, resume, lock, unlock, retry): who, when, why.
CREATE TABLE audit (
    id      INTEGER PRIMARY KEY,
    at      INTEGER NOT NULL,
    by      TEXT    NOT NULL,
    action  TEXT    NOT NULL,
    target  TEXT    NOT NULL,
    reason  TEXT
);
CREATE INDEX audit_at ON audit (at);

-- A locked location gets no work until a person unlocks it.
ALTER TABLE locations ADD COLUMN locked_at INTEGER;
ALTER TABLE locations ADD COLUMN locked_by TEXT;
ALTER TABLE locations ADD COLUMN lock_reason TEXT;
ALTER TABLE locations ADD COLUMN lock_job INTEGER;

-- A failed job put back in the queue is a new attempt of the same job.
ALTER TABLE jobs ADD COLUMN attempt INTEGER NOT NULL DEFAULT 1;
