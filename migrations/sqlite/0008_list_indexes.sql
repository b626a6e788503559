-- History that stays fast and bounded (issue 39): every list pages by an index that matches
-- its filter and its order, and `/metrics` reads no table at a scrape.
--
-- Lists come in id order, a page at a time from a cursor (`id > ?` or `id < ?`), so each
-- filter has an index whose entries for one value are in id order, and a page reads as
-- many entries as it shows. On SQLite every index ends with the rowid (`id`) already, so an
-- index on (state) reads as (state, id); the PostgreSQL migration names `id` explicitly.
-- Created on an existing store, each index is one pass over its table, at the upgrade.

-- Jobs: by state (was (state, priority, id), which no query ordered by), by kind, by device,
-- and by device and state (the dispatcher's window, a device's unfinished jobs, and a
-- list filtered on both). `created_at` is sought on jobs_created (see src/store/jobs.rs).
DROP INDEX jobs_state;
CREATE INDEX jobs_state ON jobs (state);
CREATE INDEX jobs_kind ON jobs (kind);
DROP INDEX jobs_device;
CREATE INDEX jobs_device ON jobs (device);
CREATE INDEX jobs_device_state ON jobs (device, state);

-- Alarms, newest first: by device, and the active ones (all, or a device's). The export's
-- period is sought on alarms_raised (0004).
CREATE INDEX alarms_device ON alarms (device);
CREATE INDEX alarms_open ON alarms (id) WHERE cleared_at IS NULL;
CREATE INDEX alarms_device_open ON alarms (device) WHERE cleared_at IS NULL;

-- Jobs counted by device ('' for none) and state, for `rackd_jobs`: the writer adds each
-- commit's changes in the same commit (src/store/counts.rs), so the count is as durable as
-- the jobs. Filled here from the jobs stored before, once (one pass over `jobs`).
CREATE TABLE job_counts (
    device TEXT    NOT NULL,
    state  TEXT    NOT NULL,
    n      INTEGER NOT NULL,
    PRIMARY KEY (device, state)
) WITHOUT ROWID;
INSERT INTO job_counts (device, state, n)
    SELECT COALESCE(device, ''), state, COUNT(*) FROM jobs GROUP BY COALESCE(device, ''), state;
