-- compatible-from: 11
-- Sequences (issue 52, `src/service/dispatch/gate.rs`): the jobs of one sequence reach
-- their destination in position order. A sequence's row is written with its first member;
-- `station` is the `[[site.stations]]` id its first member named (NULL: none), `last` the
-- last position once known (a member posted with `last: true`, or the WMS completed it),
-- `completed_at` when the WMS said no member would join any more, `cancelled_at` when it
-- cancelled the sequence as a whole. Each member's position is in `sequence_members`, written in the
-- same commit as the member's job (the job's own `spec` keeps its name and position too).
CREATE TABLE sequences (
    name TEXT PRIMARY KEY,
    station INTEGER,
    last INTEGER,
    completed_at INTEGER,
    cancelled_at INTEGER,
    created_at INTEGER NOT NULL,
    updated_at INTEGER NOT NULL
);

CREATE TABLE sequence_members (
    name TEXT NOT NULL,
    position INTEGER NOT NULL,
    job INTEGER NOT NULL,
    PRIMARY KEY (name, position)
);

CREATE INDEX sequence_members_job ON sequence_members (job);
