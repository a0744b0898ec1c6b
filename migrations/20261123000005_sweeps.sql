-- Sweeps: a grid of training jobs made from one base spec and the axes it varies, with an
-- evaluation spec run on every final checkpoint. `spec` is the validated request as JSON
-- ({"name", "base", "axes", "eval"}); jobs name their sweep.
CREATE TABLE sweeps (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    name TEXT NOT NULL,
    spec TEXT NOT NULL,
    created_at INTEGER NOT NULL
);

ALTER TABLE jobs ADD COLUMN sweep_id INTEGER REFERENCES sweeps (id);
CREATE INDEX jobs_by_sweep ON jobs (sweep_id, id);
