-- Credentials a worker cannot forge (docs/SECURITY.md): a worker's secret, given once at
-- registration, and each lease's secret, given when the job is leased. Only their SHA-256
-- hashes (hex) are stored. A worker registered before has no secret and must register again.
ALTER TABLE workers ADD COLUMN secret_hash TEXT;
ALTER TABLE jobs ADD COLUMN lease_hash TEXT;
