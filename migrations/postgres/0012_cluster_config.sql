-- Reloading the configuration (issue 43): each node tells the hash of the `[site]` and
-- `[[devices]]` it runs, so that nodes running different sites show in
-- `GET /api/v1/cluster` and raise `config_drift`. Empty for a node that has not told it
-- (one of an earlier version).
ALTER TABLE cluster_nodes ADD COLUMN config_hash TEXT NOT NULL DEFAULT '';
