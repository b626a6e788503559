-- compatible-from: 12
-- A commit whose answer was lost (issue 53): each job writer upserts its row here in
-- every group's transaction, in the same message as the COMMIT, with a count of its
-- commits and the time. When the COMMIT's answer is lost, the writer reads its row on a
-- fresh connection to tell whether the group landed (src/store/writer/unsure.rs). A
-- writer's id is drawn at random when it starts; rows untouched for a week are removed
-- when a writer starts.
CREATE TABLE rackd_commits (
    writer BIGINT PRIMARY KEY,
    token BIGINT NOT NULL,
    at TIMESTAMPTZ NOT NULL DEFAULT now()
);
