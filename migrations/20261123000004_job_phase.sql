-- The phase a job is in before its first training iteration (building demonstrations,
-- behaviour cloning), as JSON {"name", "done", "total"}; NULL once training reports.
ALTER TABLE jobs ADD COLUMN phase TEXT;
