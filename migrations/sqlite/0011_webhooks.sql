-- Webhooks (issue 40, `src/service/webhooks`): each subscription's cursor (the last event
-- seq it is done with: acknowledged with a 2xx, or not of a type it takes), moved in the
-- same commit as the deliveries that moved it; whether it is paused and why; its last
-- success and failure.
CREATE TABLE webhooks (
    name          TEXT    NOT NULL PRIMARY KEY,
    cursor        INTEGER  NOT NULL,
    paused        INTEGER  NOT NULL DEFAULT 0,
    paused_reason TEXT,
    last_ok_at    INTEGER,
    last_error    TEXT,
    last_error_at INTEGER,
    failing_since INTEGER,
    updated_at    INTEGER  NOT NULL
);
-- The delivery log: every try of every event, kept as long as the events are.
CREATE TABLE webhook_deliveries (
    id         INTEGER PRIMARY KEY AUTOINCREMENT,
    name       TEXT    NOT NULL,
    seq        INTEGER  NOT NULL,
    attempt    INTEGER  NOT NULL,
    status     INTEGER,
    outcome    TEXT    NOT NULL,
    latency_ms INTEGER  NOT NULL,
    error      TEXT,
    at         INTEGER  NOT NULL
);
CREATE INDEX webhook_deliveries_name ON webhook_deliveries (name, id);
CREATE INDEX webhook_deliveries_at ON webhook_deliveries (at);
