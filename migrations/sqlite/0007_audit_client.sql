-- Hardened for a plant network (issue 41): every change made through the API is audited
-- (submissions, cancels and priorities too), with the address of the client that sent it.
-- Null for entries written before. Numbered as PostgreSQL's: 0005 and 0006 are its cluster's.
ALTER TABLE audit ADD COLUMN client TEXT;
