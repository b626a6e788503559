-- Hardened for a plant network (issue 41): every change made through the API is audited
-- (submissions, cancels and priorities too), with the address of the client that sent it.
-- Null for entries written before. (0005 and 0006 are the cluster's, PostgreSQL only.)
ALTER TABLE audit ADD COLUMN client TEXT;
