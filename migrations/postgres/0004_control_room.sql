-- The control room (issue 14): alarms an operator can act on, and KPIs from the history.

-- What to do about an alarm, in plain words (null when nothing is to be done by hand), and
-- who acknowledged it when (audited as well).
ALTER TABLE alarms ADD COLUMN action TEXT;
ALTER TABLE alarms ADD COLUMN acknowledged_by TEXT;
ALTER TABLE alarms ADD COLUMN acknowledged_at BIGINT;
CREATE INDEX alarms_raised ON alarms (raised_at);

-- `/api/v1/stats` reads the transitions of a period.
CREATE INDEX job_history_at ON job_history (at);
