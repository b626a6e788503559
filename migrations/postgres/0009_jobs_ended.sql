-- `rackd db archive` (and the retention to come) finds ended jobs by the time they ended:
-- an index on it, for ended jobs only (an ended job's updated_at never changes again).
CREATE INDEX jobs_ended ON jobs (updated_at) WHERE state IN ('completed', 'failed', 'cancelled');
