-- Webhooks (issue 40, `src/service/webhooks`): each subscription's cursor (the last event
-- seq it is done with: acknowledged with a 2xx, or not of a type it takes), moved in the
-- same commit as the deliveries that moved it; whether it is paused and why; its last
-- success and failure.
CREATE TABLE webhooks (
    name          TEXT    NOT NULL PRIMARY KEY,
    cursor        BIGINT  NOT NULL,
    paused        BIGINT  NOT NULL DEFAULT 0,
    paused_reason TEXT,
    last_ok_at    BIGINT,
    last_error    TEXT,
    last_error_at BIGINT,
    failing_since BIGINT,
    updated_at    BIGINT  NOT NULL
);
-- The delivery log: every try of every event, kept as long as the events are.
CREATE TABLE webhook_deliveries (
    id         BIGINT GENERATED ALWAYS AS IDENTITY PRIMARY KEY,
    name       TEXT    NOT NULL,
    seq        BIGINT  NOT NULL,
    attempt    BIGINT  NOT NULL,
    status     BIGINT,
    outcome    TEXT    NOT NULL,
    latency_ms BIGINT  NOT NULL,
    error      TEXT,
    at         BIGINT  NOT NULL
);
CREATE INDEX webhook_deliveries_name ON webhook_deliveries (name, id);
CREATE INDEX webhook_deliveries_at ON webhook_deliveries (at);
