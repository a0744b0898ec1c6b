-- Idempotency keys of job submissions (`Idempotency-Key` on POST /api/v1/jobs): a retried
-- submit with the same key and the same request gets the job the first one created, across
-- coordinator restarts. `request` is the canonical form of the validated submission.

CREATE TABLE idempotency_keys (
    key TEXT PRIMARY KEY,
    request TEXT NOT NULL,
    job_id INTEGER NOT NULL REFERENCES jobs (id),
    created_at INTEGER NOT NULL
);
