-- Hot standby (issue 17): the lease that makes one node of a cluster the active one
-- (src/service/cluster). PostgreSQL only: a cluster shares one server.
--
-- One row per lease. `epoch` is the fencing token: it grows by one at every takeover, and
-- the active node's dispatch writes are conditional on it. `beat` grows at every renewal:
-- a standby watches it change on its own clock, so no two clocks need to agree.
-- `released` is set by an active node that stops cleanly, so a standby need not wait.
-- `renewed_at` (ms, the server's clock) is for display only.
CREATE TABLE cluster_lease (
    name TEXT PRIMARY KEY,
    holder TEXT NOT NULL,
    epoch BIGINT NOT NULL,
    beat BIGINT NOT NULL,
    released BOOLEAN NOT NULL DEFAULT FALSE,
    renewed_at BIGINT NOT NULL
);
