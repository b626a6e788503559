-- Hot standby (issue 17): the nodes of a cluster as each last told of itself, for
-- `GET /api/v1/cluster` and for a standby to find the active node's API (it forwards what
-- only the active node does). Display and routing only: who drives is the lease's to say.
CREATE TABLE cluster_nodes (
    name TEXT PRIMARY KEY,
    url TEXT NOT NULL,
    role TEXT NOT NULL,
    started_at BIGINT NOT NULL,
    seen_at BIGINT NOT NULL
);
