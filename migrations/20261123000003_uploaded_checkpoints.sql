-- Checkpoints that no job of this coordinator trained: uploads (POST /api/v1/checkpoints) and
-- the shipped models registered at start. `job_id` becomes nullable, `sha256` names the
-- content (an upload of bytes already uploaded gets the existing row) and `name` is the
-- uploader's label. SQLite cannot drop a NOT NULL in place, so the table is rebuilt the way
-- https://sqlite.org/lang_altertable.html#otheralter prescribes: a new table, copy, drop,
-- rename, in the migration's transaction. The store applies migrations on a connection with
-- foreign keys off, as that procedure requires (dropping the old table would otherwise fail
-- on the jobs that name its rows).
CREATE TABLE checkpoints_new (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    -- The training job that saved it; NULL for an uploaded checkpoint.
    job_id INTEGER REFERENCES jobs (id),
    algorithm TEXT NOT NULL,
    steps INTEGER NOT NULL,
    size INTEGER NOT NULL,
    -- File name under <data dir>/checkpoints/.
    file TEXT NOT NULL,
    created_at INTEGER NOT NULL,
    -- Hex SHA-256 of the file (NULL for rows stored before this migration).
    sha256 TEXT,
    -- An uploaded checkpoint's label (the file name it came from).
    name TEXT
);
INSERT INTO checkpoints_new (id, job_id, algorithm, steps, size, file, created_at)
    SELECT id, job_id, algorithm, steps, size, file, created_at FROM checkpoints;
DROP TABLE checkpoints;
ALTER TABLE checkpoints_new RENAME TO checkpoints;
CREATE INDEX checkpoints_by_job ON checkpoints (job_id, id);
CREATE UNIQUE INDEX uploads_by_hash ON checkpoints (sha256) WHERE job_id IS NULL;
