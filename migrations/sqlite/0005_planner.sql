-- The crane planner (issue 18): a relocation is a `move` rackd makes for another job, and
-- names it.
ALTER TABLE jobs ADD COLUMN serves INTEGER;
