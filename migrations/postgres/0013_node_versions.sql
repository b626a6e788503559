-- compatible-from: 12
-- Upgrades without stopping the machines (issue 53): each node tells its binary's version
-- and the schema it knows (the newest migration compiled into it), so that a site
-- upgrading one node at a time sees both releases in `GET /api/v1/cluster`. Empty and 0
-- for a node that has not told them (one of an earlier release).
ALTER TABLE cluster_nodes ADD COLUMN version TEXT NOT NULL DEFAULT '';
ALTER TABLE cluster_nodes ADD COLUMN schema_version BIGINT NOT NULL DEFAULT 0;
