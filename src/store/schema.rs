//! Applying `schema.sql` as forward migrations keyed by `PRAGMA user_version`.

use super::{DB_FILE, StoreError, sql};
use rusqlite::Connection;
use std::path::Path;

/// The schema, embedded at build time from the repository's `schema.sql`.
pub const SCHEMA_SQL: &str = include_str!("../../schema.sql");

/// The newest migration in `schema.sql`.
pub const SCHEMA_VERSION: i64 = 6;

/// The migrations of `schema.sql` as `(version, sql)`, in file order.
pub fn migrations() -> Vec<(i64, &'static str)> {
    // A migration starts at a line that is exactly `-- @migration N`.
    let mut out: Vec<(i64, String)> = Vec::new();
    for line in SCHEMA_SQL.lines() {
        if let Some(v) = line.strip_prefix("-- @migration ") {
            out.push((v.trim().parse().unwrap_or(-1), String::new()));
        } else if let Some((_, body)) = out.last_mut() {
            body.push_str(line);
            body.push('\n');
        }
    }
    // The schema is a compile-time constant: leaking its few KiB once is the
    // simplest way to hand out `&'static str` slices of normalised text.
    out.into_iter().map(|(v, b)| (v, &*Box::leak(b.into_boxed_str()))).collect()
}

pub fn user_version(conn: &Connection, root: &Path) -> Result<i64, StoreError> {
    conn.query_row("PRAGMA user_version", [], |r| r.get(0)).map_err(|e| sql(root, e))
}

/// Refuses databases written by a newer seam, or that are not seam's at all;
/// returns the database's schema version.
pub fn check_version(conn: &Connection, root: &Path) -> Result<i64, StoreError> {
    let v = user_version(conn, root)
        .map_err(|e| StoreError::NotSeamDb { path: root.to_path_buf(), reason: e.to_string() })?;
    if v > SCHEMA_VERSION {
        return Err(StoreError::NewerSchema { path: root.to_path_buf(), found: v, supported: SCHEMA_VERSION });
    }
    let has_meta: bool = conn
        .query_row("SELECT count(*) FROM sqlite_master WHERE type = 'table' AND name = 'meta'", [], |r| {
            r.get::<_, i64>(0)
        })
        .map(|n| n == 1)
        .map_err(|e| StoreError::NotSeamDb { path: root.to_path_buf(), reason: e.to_string() })?;
    if v < 1 || !has_meta {
        return Err(StoreError::NotSeamDb {
            path: root.to_path_buf(),
            reason: format!("{DB_FILE} has no seam schema (user_version {v})"),
        });
    }
    Ok(v)
}

/// Applies every migration newer than the database, each in its own transaction.
pub fn migrate(conn: &mut Connection, root: &Path) -> Result<(), StoreError> {
    let current = user_version(conn, root)?;
    for (version, body) in migrations() {
        if version <= current {
            continue;
        }
        let tx = conn.transaction().map_err(|e| sql(root, e))?;
        tx.execute_batch(body).map_err(|e| sql(root, e))?;
        tx.pragma_update(None, "user_version", version).map_err(|e| sql(root, e))?;
        tx.commit().map_err(|e| sql(root, e))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn migrations_are_numbered_one_up_and_end_at_schema_version() {
        let m = migrations();
        assert!(!m.is_empty());
        for (i, (v, body)) in m.iter().enumerate() {
            assert_eq!(*v, i as i64 + 1);
            assert!(body.contains("CREATE") || body.contains("ALTER"), "migration {v} is empty");
        }
        assert_eq!(m.last().map(|x| x.0), Some(SCHEMA_VERSION));
    }

    #[test]
    fn fresh_database_migrates_and_is_idempotent() {
        let mut conn = Connection::open_in_memory().unwrap();
        let root = Path::new("mem");
        migrate(&mut conn, root).unwrap();
        assert_eq!(user_version(&conn, root).unwrap(), SCHEMA_VERSION);
        migrate(&mut conn, root).unwrap();
        check_version(&conn, root).unwrap();
    }

    /// A store written by the first release opens, migrates, and keeps its rows.
    #[test]
    fn version_1_store_migrates_forward_with_its_data() {
        let mut conn = Connection::open_in_memory().unwrap();
        let root = Path::new("mem");
        let (v1, body) = migrations()[0];
        conn.execute_batch(body).unwrap();
        conn.pragma_update(None, "user_version", v1).unwrap();
        conn.execute("INSERT INTO meta VALUES ('site_name', 'old')", []).unwrap();
        conn.execute(
            "INSERT INTO sessions(name, content_hash, source_dir, layout, keyframe_count, point_count, status, created_at)
             VALUES ('s1', 'h', '/d', 'kitti', 3, 30, 'complete', 't')",
            [],
        )
        .unwrap();
        check_version(&conn, root).unwrap();
        migrate(&mut conn, root).unwrap();
        assert_eq!(user_version(&conn, root).unwrap(), SCHEMA_VERSION);
        let n: i64 = conn.query_row("SELECT count(*) FROM sessions WHERE name = 's1'", [], |r| r.get(0)).unwrap();
        assert_eq!(n, 1);
        let site: String = conn.query_row("SELECT value FROM meta WHERE key = 'site_name'", [], |r| r.get(0)).unwrap();
        assert_eq!(site, "old");
    }

    #[test]
    fn newer_schema_is_refused() {
        let mut conn = Connection::open_in_memory().unwrap();
        let root = Path::new("mem");
        migrate(&mut conn, root).unwrap();
        conn.pragma_update(None, "user_version", SCHEMA_VERSION + 1).unwrap();
        let err = check_version(&conn, root).unwrap_err();
        assert!(err.to_string().contains("newer than this seam understands"), "{err}");
    }
}
