-- An evaluation's video of its first episodes (a GIF the worker renders), one per job, kept
-- beside the rerun recordings as `<data dir>/recordings/job<ID>.gif`; a later upload for the
-- same job (a re-leased evaluation) replaces it.
CREATE TABLE videos (
    job_id INTEGER PRIMARY KEY REFERENCES jobs (id),
    file TEXT NOT NULL,
    size INTEGER NOT NULL,
    episodes INTEGER NOT NULL,
    frames INTEGER NOT NULL,
    width INTEGER NOT NULL,
    height INTEGER NOT NULL,
    updated_at INTEGER NOT NULL
);
