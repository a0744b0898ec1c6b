-- Rerun recordings (.rrd) of jobs: one file per job under <data dir>/recordings/, grown by
-- appends of whole recorded episodes.

CREATE TABLE recordings (
    job_id INTEGER PRIMARY KEY REFERENCES jobs (id),
    file TEXT NOT NULL,
    size INTEGER NOT NULL,
    episodes INTEGER NOT NULL,
    updated_at INTEGER NOT NULL
);
