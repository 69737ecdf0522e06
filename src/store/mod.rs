//! The store: the only module that touches SQLite and Parquet.
//!
//! A store is a directory (`site.seam/`) holding `seam.db` (SQLite, WAL mode,
//! schema from `schema.sql` applied as forward migrations keyed by
//! `PRAGMA user_version`), immutable zstd Parquet files under `data/`, and a
//! lock file `seam.lock`.
//!
//! # Promises
//! - **Nothing half-written is visible.** A Parquet file is written under a
//!   temporary name, fsynced, renamed into place, and only then are the SQLite
//!   rows that reference it committed ([`Store::write_parquet`] +
//!   [`files::insert_file`]). A crash leaves at worst an orphan file, which
//!   `seam check` lists and `seam check --repair` removes; never a row that
//!   points at nothing.
//! - **One writer.** [`Store::open`] takes an exclusive OS lock on
//!   `seam.lock` (released by the kernel if the process dies, so a `kill -9`
//!   never leaves a stale lock) and records its pid there, so a second writer
//!   fails at once with "store in use by pid N".
//! - **Readers never block** and never see a half step: [`Store::open_read_only`]
//!   uses a read-only connection, and SQLite's WAL gives it a consistent snapshot.
//!   (Once, on a store an older seam wrote, it applies the pending
//!   migrations first, as a writer.)
//!
//! Not here: what the rows mean (the pipeline decides that), printing (cli).

mod alignment;
mod check;
pub mod evidence_files;
mod evidence_rows;
mod files;
pub mod geoparquet;
pub mod las_export;
mod lifelong;
pub mod map_export;
mod render_rows;
mod rows;
mod schema;
pub mod trajectory_export;
mod zones;

pub use alignment::*;
pub use check::{CheckReport, FileProblem};
pub use evidence_rows::*;
pub use files::{FileRecord, ScanWriter, file_paths, insert_file, read_scan_row_group};
pub use lifelong::*;
pub use render_rows::{MapExtent, for_each_map_voxel, has_table, map_extent};
pub use rows::*;
pub use schema::{SCHEMA_SQL, SCHEMA_VERSION};
pub use zones::{Zone, ZoneShape, insert_zone, remove_zone, zones};

use rusqlite::{Connection, OpenFlags, Transaction};
use std::fs::{File, OpenOptions};
use std::io::{Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

/// Name of the SQLite database inside a store directory.
pub const DB_FILE: &str = "seam.db";
/// Name of the writer lock file inside a store directory.
pub const LOCK_FILE: &str = "seam.lock";
/// Folder for Parquet files inside a store directory.
pub const DATA_DIR: &str = "data";

/// Errors of the store layer. Each message says what to do next.
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    #[error("{path}: not a seam store (no {DB_FILE})\n  hint: create one with `seam init {path}`")]
    NotAStore { path: PathBuf },
    #[error("{path}: already exists and is not empty\n  hint: choose a new folder, or open the existing store")]
    AlreadyExists { path: PathBuf },
    #[error(
        "{path}: store schema version {found} is newer than this seam understands ({supported})\n  hint: upgrade seam; this store was written by a newer version"
    )]
    NewerSchema { path: PathBuf, found: i64, supported: i64 },
    #[error("{path}: {DB_FILE} is not a seam database ({reason})\n  hint: is this the right folder?")]
    NotSeamDb { path: PathBuf, reason: String },
    #[error(
        "{path}: store in use by pid {pid}\n  hint: wait for that seam process to finish (one writer at a time; readers are fine)"
    )]
    Busy { path: PathBuf, pid: String },
    #[error("{path}: {source}")]
    Io { path: PathBuf, source: std::io::Error },
    #[error("{path}: SQLite: {source}")]
    Sql { path: PathBuf, source: rusqlite::Error },
    #[error("{path}: Parquet: {message}")]
    Parquet { path: PathBuf, message: String },
    #[error("{path}: store content is inconsistent: {message}\n  hint: run `seam check` to see what is wrong")]
    Corrupt { path: PathBuf, message: String },
}

impl StoreError {
    pub(crate) fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        StoreError::Io { path: path.into(), source }
    }
}

/// Settings fixed when a store is created.
#[derive(Debug, Clone, PartialEq)]
pub struct InitOptions {
    pub site_name: String,
    /// An EPSG code such as `EPSG:32652`, or `local` for a local engineering frame.
    pub crs: String,
    pub voxel_size_m: f64,
}

/// The `meta` key of the configuration the sessions were ingested with.
const CONFIG_KEY: &str = "config_json";

/// [`Store::recorded_config`] inside a transaction.
pub fn recorded_config(conn: &Connection, root: &Path) -> Result<Option<String>, StoreError> {
    use rusqlite::OptionalExtension;
    conn.query_row("SELECT value FROM meta WHERE key = ?1", [CONFIG_KEY], |r| r.get::<_, String>(0))
        .optional()
        .map_err(|e| sql(root, e))
}

/// [`Store::record_config`] inside a transaction (`root` names the store in
/// errors): the first session's `scans` step records its configuration in
/// the transaction that creates the session.
pub fn record_config(conn: &Connection, root: &Path, json: &str) -> Result<(), StoreError> {
    conn.execute("INSERT OR REPLACE INTO meta(key, value) VALUES (?1, ?2)", (CONFIG_KEY, json))
        .map(|_| ())
        .map_err(|e| sql(root, e))
}

/// What `meta` holds.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct StoreMeta {
    pub schema_version: i64,
    pub site_name: String,
    pub crs: String,
    pub voxel_size_m: f64,
    pub tool_version: String,
    pub created_at: String,
}

/// An open store: a SQLite connection plus, for writers, the lock.
pub struct Store {
    root: PathBuf,
    conn: Connection,
    /// Held for the life of a writer; the OS releases it if the process dies.
    _lock: Option<File>,
}

impl Store {
    /// Creates a new store at `root` (which must not exist or be empty) and
    /// opens it for writing.
    pub fn create(root: &Path, opts: &InitOptions) -> Result<Store, StoreError> {
        if root.exists() {
            let mut entries = std::fs::read_dir(root).map_err(|e| StoreError::io(root, e))?;
            if entries.next().is_some() {
                return Err(StoreError::AlreadyExists { path: root.to_path_buf() });
            }
        }
        std::fs::create_dir_all(root.join(DATA_DIR)).map_err(|e| StoreError::io(root, e))?;
        let lock = acquire_lock(root)?;
        let mut conn = open_conn(root, false)?;
        schema::migrate(&mut conn, root)?;
        let now = now_utc();
        let tx = conn.transaction().map_err(|e| sql(root, e))?;
        for (k, v) in [
            ("site_name", opts.site_name.clone()),
            ("crs", opts.crs.clone()),
            ("voxel_size_m", opts.voxel_size_m.to_string()),
            ("tool_version", env!("CARGO_PKG_VERSION").to_string()),
            ("created_at", now),
        ] {
            tx.execute("INSERT INTO meta(key, value) VALUES (?1, ?2)", (k, v)).map_err(|e| sql(root, e))?;
        }
        tx.commit().map_err(|e| sql(root, e))?;
        Ok(Store { root: root.to_path_buf(), conn, _lock: Some(lock) })
    }

    /// Opens an existing store for writing: takes the writer lock and applies
    /// pending migrations.
    pub fn open(root: &Path) -> Result<Store, StoreError> {
        check_is_store(root)?;
        let lock = acquire_lock(root)?;
        let mut conn = open_conn(root, false)?;
        schema::check_version(&conn, root)?;
        schema::migrate(&mut conn, root)?;
        let store = Store { root: root.to_path_buf(), conn, _lock: Some(lock) };
        store.sweep_temp_files()?;
        Ok(store)
    }

    /// Opens an existing store for reading. Never blocks on a writer, and
    /// writes only to upgrade a store an older seam wrote, once: its pending
    /// migrations (each one transaction, columns and tables added, nothing
    /// rewritten) under the writer lock. A reader of the old schema would
    /// otherwise fail on the first column it lacks.
    pub fn open_read_only(root: &Path) -> Result<Store, StoreError> {
        check_is_store(root)?;
        let conn = open_conn(root, true)?;
        if schema::check_version(&conn, root)? < schema::SCHEMA_VERSION {
            drop(conn);
            drop(Store::open(root)?);
            return Store::open_read_only(root);
        }
        Ok(Store { root: root.to_path_buf(), conn, _lock: None })
    }

    pub fn root(&self) -> &Path {
        &self.root
    }

    pub fn conn(&self) -> &Connection {
        &self.conn
    }

    /// Runs `f` in one SQLite transaction: committed if `f` returns `Ok`,
    /// rolled back otherwise.
    pub fn transaction<T, E: From<StoreError>>(
        &mut self,
        f: impl FnOnce(&Transaction<'_>) -> Result<T, E>,
    ) -> Result<T, E> {
        let root = self.root.clone();
        let tx = self.conn.transaction().map_err(|e| sql(&root, e))?;
        let out = f(&tx)?;
        tx.commit().map_err(|e| sql(&root, e))?;
        Ok(out)
    }

    pub fn meta(&self) -> Result<StoreMeta, StoreError> {
        let get = |k: &str| -> Result<String, StoreError> {
            self.conn
                .query_row("SELECT value FROM meta WHERE key = ?1", [k], |r| r.get::<_, String>(0))
                .map_err(|e| sql(&self.root, e))
        };
        let voxel = get("voxel_size_m")?;
        Ok(StoreMeta {
            schema_version: schema::user_version(&self.conn, &self.root)?,
            site_name: get("site_name")?,
            crs: get("crs")?,
            voxel_size_m: voxel.parse().map_err(|_| StoreError::Corrupt {
                path: self.root.join(DB_FILE),
                message: format!("meta voxel_size_m = {voxel:?} is not a number"),
            })?,
            tool_version: get("tool_version")?,
            created_at: get("created_at")?,
        })
    }

    /// The configuration the store's sessions were ingested with, as the
    /// JSON [`record_config`](Self::record_config) wrote; `None` before
    /// the first ingest (or in a store from before seam recorded it).
    pub fn recorded_config(&self) -> Result<Option<String>, StoreError> {
        recorded_config(&self.conn, &self.root)
    }

    /// Records (or replaces) the configuration the store's sessions are
    /// ingested with: `json` is the whole configuration, every key.
    pub fn record_config(&self, json: &str) -> Result<(), StoreError> {
        record_config(&self.conn, &self.root, json)
    }

    /// Removes `*.tmp-<pid>` files under `data/`: half-written files of a
    /// process that died. Safe because only the lock holder writes files.
    fn sweep_temp_files(&self) -> Result<(), StoreError> {
        let mut files = Vec::new();
        check::walk(&self.root.join(DATA_DIR), &mut files).map_err(|e| StoreError::io(self.root.join(DATA_DIR), e))?;
        for f in files {
            let is_tmp = f.extension().and_then(|e| e.to_str()).is_some_and(|e| e.starts_with("tmp-"));
            if is_tmp {
                std::fs::remove_file(&f).map_err(|e| StoreError::io(&f, e))?;
            }
        }
        Ok(())
    }

    /// Absolute path of a file given its path relative to the store root.
    pub fn path_of(&self, rel_path: &str) -> PathBuf {
        self.root.join(rel_path)
    }
}

pub(crate) fn sql(root: &Path, source: rusqlite::Error) -> StoreError {
    StoreError::Sql { path: root.join(DB_FILE), source }
}

fn check_is_store(root: &Path) -> Result<(), StoreError> {
    if !root.join(DB_FILE).is_file() {
        return Err(StoreError::NotAStore { path: root.to_path_buf() });
    }
    Ok(())
}

fn open_conn(root: &Path, read_only: bool) -> Result<Connection, StoreError> {
    let db = root.join(DB_FILE);
    let flags = if read_only {
        OpenFlags::SQLITE_OPEN_READ_ONLY | OpenFlags::SQLITE_OPEN_NO_MUTEX
    } else {
        OpenFlags::SQLITE_OPEN_READ_WRITE | OpenFlags::SQLITE_OPEN_CREATE | OpenFlags::SQLITE_OPEN_NO_MUTEX
    };
    let conn = Connection::open_with_flags(&db, flags).map_err(|e| sql(root, e))?;
    conn.busy_timeout(std::time::Duration::from_secs(10)).map_err(|e| sql(root, e))?;
    if !read_only {
        // WAL: readers keep a consistent snapshot while the writer commits.
        // synchronous=FULL: a committed step survives power loss, not only a crash.
        conn.pragma_update(None, "journal_mode", "WAL").map_err(|e| sql(root, e))?;
        conn.pragma_update(None, "synchronous", "FULL").map_err(|e| sql(root, e))?;
    }
    conn.pragma_update(None, "foreign_keys", "ON").map_err(|e| sql(root, e))?;
    Ok(conn)
}

/// Takes the exclusive writer lock and writes our pid into the lock file.
fn acquire_lock(root: &Path) -> Result<File, StoreError> {
    let path = root.join(LOCK_FILE);
    let mut f = OpenOptions::new()
        .read(true)
        .write(true)
        .create(true)
        .truncate(false)
        .open(&path)
        .map_err(|e| StoreError::io(&path, e))?;
    match f.try_lock() {
        Ok(()) => {}
        Err(std::fs::TryLockError::WouldBlock) => {
            let mut pid = String::new();
            let _ = f.read_to_string(&mut pid);
            let pid = pid.trim();
            return Err(StoreError::Busy {
                path: root.to_path_buf(),
                pid: if pid.is_empty() { "unknown".into() } else { pid.to_string() },
            });
        }
        Err(std::fs::TryLockError::Error(e)) => return Err(StoreError::io(&path, e)),
    }
    f.set_len(0).map_err(|e| StoreError::io(&path, e))?;
    f.seek(SeekFrom::Start(0)).map_err(|e| StoreError::io(&path, e))?;
    write!(f, "{}", std::process::id()).map_err(|e| StoreError::io(&path, e))?;
    f.flush().map_err(|e| StoreError::io(&path, e))?;
    Ok(f)
}

/// Current UTC time as ISO-8601 with seconds, e.g. `2026-11-23T19:25:25Z`.
pub fn now_utc() -> String {
    let secs =
        std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map(|d| d.as_secs() as i64).unwrap_or(0);
    format_utc(secs)
}

/// Formats seconds since the Unix epoch as ISO-8601 UTC.
pub fn format_utc(secs: i64) -> String {
    let days = secs.div_euclid(86_400);
    let rem = secs.rem_euclid(86_400);
    // Civil-from-days (H. Hinnant's algorithm).
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!("{y:04}-{m:02}-{d:02}T{:02}:{:02}:{:02}Z", rem / 3600, rem % 3600 / 60, rem % 60)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn utc_formatting_matches_known_dates() {
        assert_eq!(format_utc(0), "1970-01-01T00:00:00Z");
        assert_eq!(format_utc(951_782_400), "2000-02-29T00:00:00Z");
        assert_eq!(format_utc(1_795_461_925), "2026-11-23T19:25:25Z");
    }

    fn opts() -> InitOptions {
        InitOptions { site_name: "t".into(), crs: "local".into(), voxel_size_m: 0.2 }
    }

    #[test]
    fn second_writer_is_told_the_pid() {
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path().join("s.seam");
        let _w = Store::create(&root, &opts()).unwrap();
        let err = Store::open(&root).err().unwrap();
        let msg = err.to_string();
        assert!(msg.contains(&format!("in use by pid {}", std::process::id())), "{msg}");
        // Readers are fine while the writer holds the lock.
        let r = Store::open_read_only(&root).unwrap();
        assert_eq!(r.meta().unwrap().voxel_size_m, 0.2);
    }

    /// A reader of a store an older seam wrote upgrades it once: here a
    /// schema-5 store (before lifelong voxels had `spread_m2`), which a
    /// reader of the lifelong map would otherwise fail on.
    #[test]
    fn reader_upgrades_an_older_store() {
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path().join("s.seam");
        drop(Store::create(&root, &opts()).unwrap());
        {
            let conn = rusqlite::Connection::open(root.join(DB_FILE)).unwrap();
            conn.execute_batch("ALTER TABLE map_voxels DROP COLUMN spread_m2; PRAGMA user_version = 5;").unwrap();
        }
        let r = Store::open_read_only(&root).unwrap();
        assert_eq!(schema::user_version(r.conn(), &root).unwrap(), schema::SCHEMA_VERSION);
        assert!(map_voxels_in(r.conn(), &WorldBox::ALL, None).unwrap().is_empty());
    }

    #[test]
    fn create_refuses_non_empty_folder_and_open_refuses_non_store() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("x"), b"1").unwrap();
        assert!(matches!(Store::create(dir.path(), &opts()), Err(StoreError::AlreadyExists { .. })));
        assert!(matches!(Store::open(dir.path()), Err(StoreError::NotAStore { .. })));
    }
}
