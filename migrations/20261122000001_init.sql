-- The coordinator's store: workers, jobs (train and eval), their metric series, episode
-- summaries and checkpoints. Times are Unix milliseconds.

CREATE TABLE workers (
    id TEXT PRIMARY KEY,
    name TEXT NOT NULL,
    cores INTEGER NOT NULL,
    version TEXT NOT NULL,
    registered_at INTEGER NOT NULL,
    last_heartbeat INTEGER NOT NULL
);

CREATE TABLE jobs (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    kind TEXT NOT NULL CHECK (kind IN ('train', 'eval')),
    state TEXT NOT NULL CHECK (state IN ('queued', 'running', 'succeeded', 'failed', 'cancelled')),
    algorithm TEXT NOT NULL,
    task TEXT,
    -- The job's parameters as JSON (crm_api::TrainSpec or crm_api::EvalSpec).
    spec TEXT NOT NULL,
    -- Eval jobs: the checkpoint evaluated.
    checkpoint_id INTEGER REFERENCES checkpoints (id),
    -- A re-run names the job it copies.
    rerun_of INTEGER REFERENCES jobs (id),
    worker_id TEXT,
    attempts INTEGER NOT NULL DEFAULT 0,
    lease_expires_at INTEGER,
    progress REAL NOT NULL DEFAULT 0,
    steps INTEGER NOT NULL DEFAULT 0,
    steps_per_s REAL,
    result TEXT,
    error TEXT,
    created_at INTEGER NOT NULL,
    started_at INTEGER,
    finished_at INTEGER
);

CREATE INDEX jobs_by_state ON jobs (state, id);

CREATE TABLE metrics (
    job_id INTEGER NOT NULL REFERENCES jobs (id),
    steps INTEGER NOT NULL,
    iteration INTEGER NOT NULL,
    wall_s REAL NOT NULL,
    -- crm_api::Iteration as JSON.
    data TEXT NOT NULL,
    PRIMARY KEY (job_id, steps)
);

CREATE TABLE episodes (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    job_id INTEGER NOT NULL REFERENCES jobs (id),
    data TEXT NOT NULL,
    created_at INTEGER NOT NULL
);

CREATE INDEX episodes_by_job ON episodes (job_id, id);

CREATE TABLE checkpoints (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    job_id INTEGER NOT NULL REFERENCES jobs (id),
    algorithm TEXT NOT NULL,
    steps INTEGER NOT NULL,
    size INTEGER NOT NULL,
    -- File name under <data dir>/checkpoints/.
    file TEXT NOT NULL,
    created_at INTEGER NOT NULL
);

CREATE INDEX checkpoints_by_job ON checkpoints (job_id, id);
