//! The store's migrations (`migrations/*.sql`), compiled into the binary and resolved as
//! sqlx's `migrate!` resolves a folder (version and description from the file name, the
//! checksum of the text), so a store made by either accepts the other. Listed here instead of
//! read by `migrate!` because that macro's crate builds a second sqlx and SQLite for the host;
//! a test holds the list to the folder.

use std::borrow::Cow;
use std::future::Future;
use std::pin::Pin;

use sqlx::error::BoxDynError;
use sqlx::migrate::{Migration, MigrationSource, MigrationType, Migrator};

/// Every migration file, by name, with its text.
const FILES: [(&str, &str); 9] = [
    (
        "20261122000001_init.sql",
        include_str!("../../../migrations/20261122000001_init.sql"),
    ),
    (
        "20261123000001_recordings.sql",
        include_str!("../../../migrations/20261123000001_recordings.sql"),
    ),
    (
        "20261123000002_idempotency.sql",
        include_str!("../../../migrations/20261123000002_idempotency.sql"),
    ),
    (
        "20261123000003_uploaded_checkpoints.sql",
        include_str!("../../../migrations/20261123000003_uploaded_checkpoints.sql"),
    ),
    (
        "20261123000004_job_phase.sql",
        include_str!("../../../migrations/20261123000004_job_phase.sql"),
    ),
    (
        "20261123000005_sweeps.sql",
        include_str!("../../../migrations/20261123000005_sweeps.sql"),
    ),
    (
        "20261127000001_lease_tokens.sql",
        include_str!("../../../migrations/20261127000001_lease_tokens.sql"),
    ),
    (
        "20261128000001_eval_progress.sql",
        include_str!("../../../migrations/20261128000001_eval_progress.sql"),
    ),
    (
        "20261129000001_videos.sql",
        include_str!("../../../migrations/20261129000001_videos.sql"),
    ),
];

/// The compiled-in files as a migration source.
#[derive(Debug)]
struct Compiled;

impl<'s> MigrationSource<'s> for Compiled {
    fn resolve(
        self,
    ) -> Pin<Box<dyn Future<Output = Result<Vec<Migration>, BoxDynError>> + Send + 's>> {
        Box::pin(async move { resolve() })
    }
}

/// `FILES` as sqlx's folder source reads files: `<VERSION>_<DESCRIPTION>.sql`, underscores of
/// the description as spaces, `-- no-transaction` first to run outside a transaction.
fn resolve() -> Result<Vec<Migration>, BoxDynError> {
    let mut migrations = FILES
        .iter()
        .map(|(name, sql)| {
            let (version, rest) = name
                .split_once('_')
                .ok_or_else(|| format!("migration {name}: no version"))?;
            let version: i64 = version
                .parse()
                .map_err(|_| format!("migration {name}: the version is not an integer"))?;
            let kind = MigrationType::from_filename(rest);
            let description = rest.trim_end_matches(kind.suffix()).replace('_', " ");
            Ok(Migration::new(
                version,
                Cow::Owned(description),
                kind,
                Cow::Borrowed(*sql),
                sql.starts_with("-- no-transaction"),
            ))
        })
        .collect::<Result<Vec<_>, BoxDynError>>()?;
    migrations.sort_by_key(|m| m.version);
    Ok(migrations)
}

/// The store's migrator.
pub async fn migrator() -> Result<Migrator, sqlx::migrate::MigrateError> {
    Migrator::new(Compiled).await
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_list_is_the_folder_and_reads_as_sqlx_reads_it() {
        let folder = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../migrations");
        let from_folder = sqlx::migrate::resolve_blocking(&folder).expect("the folder");
        let compiled = resolve().expect("the list");
        assert_eq!(
            compiled.len(),
            from_folder.len(),
            "a migration file is not in FILES"
        );
        for (ours, (theirs, _)) in compiled.iter().zip(&from_folder) {
            assert_eq!(
                (ours.version, &ours.description, &ours.checksum, ours.no_tx),
                (
                    theirs.version,
                    &theirs.description,
                    &theirs.checksum,
                    theirs.no_tx
                )
            );
        }
    }
}
