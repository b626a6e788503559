-- Device alarms: raised when a device reports one (a crane's alarm code) or stops answering,
-- cleared when it goes away. An alarm is active while cleared_at is NULL.

CREATE TABLE alarms (
    id         INTEGER PRIMARY KEY,
    device     TEXT    NOT NULL,
    code       INTEGER NOT NULL,
    class      TEXT    NOT NULL,                -- business, hardware or link
    text       TEXT    NOT NULL,
    raised_at  INTEGER NOT NULL,
    cleared_at INTEGER
);
CREATE INDEX alarms_active ON alarms (device, code) WHERE cleared_at IS NULL;
