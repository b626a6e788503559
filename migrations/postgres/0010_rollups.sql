-- Rollups (issue 39, `src/store/rollups`): the KPIs added up per minute, hour and day
-- (`grain`, ms), per bucket (`bucket`: its start, Unix ms) and scope (`device:ID`,
-- `aisle:N`), as JSON. Filled from the history by the first start after this migration.
CREATE TABLE rollups (
    grain   BIGINT NOT NULL,
    bucket  BIGINT NOT NULL,
    scope   TEXT    NOT NULL,
    figures TEXT    NOT NULL,
    PRIMARY KEY (grain, bucket, scope)
);
-- Where `rackd db rollups --rebuild` builds, before it takes the place of `rollups`.
CREATE TABLE rollups_rebuild (
    grain   BIGINT NOT NULL,
    bucket  BIGINT NOT NULL,
    scope   TEXT    NOT NULL,
    figures TEXT    NOT NULL,
    PRIMARY KEY (grain, bucket, scope)
);
-- Each scope's jobs on it and since when it has been busy.
CREATE TABLE rollup_busy (
    scope  TEXT    NOT NULL PRIMARY KEY,
    active BIGINT NOT NULL,
    since  BIGINT NOT NULL
);
-- `built`: the rollups were filled; `history_from`: the store holds every job's whole
-- history, and the minute rows, from this time on.
CREATE TABLE rollup_marks (
    name TEXT    NOT NULL PRIMARY KEY,
    at   BIGINT NOT NULL
);
