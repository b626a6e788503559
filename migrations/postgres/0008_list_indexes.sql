-- History that stays fast and bounded (issue 39): every list pages by an index that matches
-- its filter and its order, and `/metrics` reads no table at a scrape. The same indexes as
-- SQLite's 0008, each ending with `id` (SQLite's end with the rowid by themselves).
--
-- Lists come in id order, a page at a time from a cursor (`id > $n` or `id < $n`), so each
-- filter has an index whose entries for one value are in id order, and a page reads as
-- many entries as it shows. Created on an existing store, each index is one pass over its
-- table, at the upgrade.

-- Jobs: by state (was (state, priority, id), which no query ordered by), by kind, by device,
-- and by device and state (the dispatcher's window, a device's unfinished jobs, and a
-- list filtered on both). `created_at` is sought on jobs_created, its ties in id order.
DROP INDEX jobs_state;
CREATE INDEX jobs_state ON jobs (state, id);
CREATE INDEX jobs_kind ON jobs (kind, id);
DROP INDEX jobs_device;
CREATE INDEX jobs_device ON jobs (device, id);
CREATE INDEX jobs_device_state ON jobs (device, state, id);
DROP INDEX jobs_created;
CREATE INDEX jobs_created ON jobs (created_at, id);

-- Alarms, newest first: by device, and the active ones (all, or a device's); the export's
-- period sought on alarms_raised, its ties in id order.
CREATE INDEX alarms_device ON alarms (device, id);
CREATE INDEX alarms_open ON alarms (id) WHERE cleared_at IS NULL;
CREATE INDEX alarms_device_open ON alarms (device, id) WHERE cleared_at IS NULL;
DROP INDEX alarms_raised;
CREATE INDEX alarms_raised ON alarms (raised_at, id);

-- Jobs counted by device ('' for none) and state, for `rackd_jobs`: the writer adds each
-- commit's changes in the same commit (src/store/counts.rs), so the count is as durable as
-- the jobs. Filled here from the jobs stored before, once (one pass over `jobs`).
CREATE TABLE job_counts (
    device TEXT   NOT NULL,
    state  TEXT   NOT NULL,
    n      BIGINT NOT NULL,
    PRIMARY KEY (device, state)
);
INSERT INTO job_counts (device, state, n)
    SELECT COALESCE(device, ''), state, COUNT(*) FROM jobs GROUP BY COALESCE(device, ''), state;
