-- An evaluation given back before it finished: where it stood (the worker's JSON, which the
-- next lease goes on from) and the newest of its episode summaries then; the summaries after
-- that mark came from a lease that was lost, and the next lease sends them again.
ALTER TABLE jobs ADD COLUMN eval_progress TEXT;
ALTER TABLE jobs ADD COLUMN eval_episodes_mark INTEGER;
