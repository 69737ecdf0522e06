//! `seam check`: proves the store is whole.
//!
//! SQLite's own `integrity_check` and `foreign_key_check`, then every file the
//! store references must exist with the recorded size and blake3 hash, and
//! every file under `data/` must be referenced (else it is an orphan, left by
//! a crash between publishing a file and committing its rows; harmless, and
//! removed by `--repair`). Interrupted ingests are reported as notes: they are
//! a valid state that `seam ingest` resumes.

use super::{DATA_DIR, Store, StoreError, sql};
use std::io::Read;
use std::path::{Path, PathBuf};

/// A referenced file that is not as recorded.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct FileProblem {
    pub rel_path: String,
    pub problem: String,
}

#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct CheckReport {
    /// `ok`, or what SQLite's integrity and foreign key checks found.
    pub sqlite: Vec<String>,
    pub files_checked: usize,
    pub bad_files: Vec<FileProblem>,
    /// Unreferenced files under `data/` (paths relative to the store root).
    pub orphans: Vec<String>,
    /// Orphans removed by `--repair`.
    pub removed: Vec<String>,
    /// Sessions whose ingest has not finished (resumable).
    pub incomplete_sessions: Vec<String>,
}

impl CheckReport {
    /// True when nothing is wrong. Orphans are not wrong, only untidy.
    pub fn is_ok(&self) -> bool {
        self.sqlite == ["ok"] && self.bad_files.is_empty()
    }
}

fn hash_file(path: &Path) -> std::io::Result<(u64, String)> {
    let mut f = std::fs::File::open(path)?;
    let mut h = blake3::Hasher::new();
    let mut buf = vec![0u8; 1 << 20];
    let mut n = 0u64;
    loop {
        let k = f.read(&mut buf)?;
        if k == 0 {
            break;
        }
        h.update(&buf[..k]);
        n += k as u64;
    }
    Ok((n, h.finalize().to_hex().to_string()))
}

pub(super) fn walk(dir: &Path, out: &mut Vec<PathBuf>) -> std::io::Result<()> {
    if !dir.exists() {
        return Ok(());
    }
    for entry in std::fs::read_dir(dir)? {
        let p = entry?.path();
        if p.is_dir() { walk(&p, out)? } else { out.push(p) }
    }
    Ok(())
}

impl Store {
    /// Checks the store; with `repair`, removes orphan files.
    pub fn check(&self, repair: bool) -> Result<CheckReport, StoreError> {
        let root = self.root().to_path_buf();
        let conn = self.conn();
        let mut report = CheckReport::default();
        let mut st = conn.prepare("PRAGMA integrity_check").map_err(|e| sql(&root, e))?;
        report.sqlite = st
            .query_map([], |r| r.get::<_, String>(0))
            .map_err(|e| sql(&root, e))?
            .collect::<Result<_, _>>()
            .map_err(|e| sql(&root, e))?;
        let mut fk = conn.prepare("PRAGMA foreign_key_check").map_err(|e| sql(&root, e))?;
        let fk_rows: Vec<String> = fk
            .query_map([], |r| {
                Ok(format!(
                    "foreign key violation in {} rowid {:?}",
                    r.get::<_, String>(0)?,
                    r.get::<_, Option<i64>>(1)?
                ))
            })
            .map_err(|e| sql(&root, e))?
            .collect::<Result<_, _>>()
            .map_err(|e| sql(&root, e))?;
        if !fk_rows.is_empty() {
            report.sqlite.retain(|s| s != "ok");
            report.sqlite.extend(fk_rows);
        }

        let mut st = conn
            .prepare("SELECT rel_path, size_bytes, blake3 FROM files ORDER BY rel_path")
            .map_err(|e| sql(&root, e))?;
        let files: Vec<(String, i64, String)> = st
            .query_map([], |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?)))
            .map_err(|e| sql(&root, e))?
            .collect::<Result<_, _>>()
            .map_err(|e| sql(&root, e))?;
        let referenced: std::collections::HashSet<&str> = files.iter().map(|f| f.0.as_str()).collect();
        for (rel, size, hash) in &files {
            report.files_checked += 1;
            let problem = match hash_file(&root.join(rel)) {
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => Some("missing".to_string()),
                Err(e) => Some(format!("unreadable: {e}")),
                Ok((n, _)) if n as i64 != *size => Some(format!("size {n} bytes, recorded {size}")),
                Ok((_, h)) if &h != hash => Some("content hash differs from the recorded one".to_string()),
                Ok(_) => None,
            };
            if let Some(problem) = problem {
                report.bad_files.push(FileProblem { rel_path: rel.clone(), problem });
            }
        }

        let mut on_disk = Vec::new();
        walk(&root.join(DATA_DIR), &mut on_disk).map_err(|e| StoreError::io(root.join(DATA_DIR), e))?;
        on_disk.sort();
        for p in on_disk {
            let rel = p.strip_prefix(&root).unwrap_or(&p).to_string_lossy().replace('\\', "/");
            if !referenced.contains(rel.as_str()) {
                if repair {
                    std::fs::remove_file(&p).map_err(|e| StoreError::io(&p, e))?;
                    report.removed.push(rel.clone());
                }
                report.orphans.push(rel);
            }
        }

        let mut st = conn
            .prepare("SELECT name FROM sessions WHERE status <> 'complete' ORDER BY session_id")
            .map_err(|e| sql(&root, e))?;
        report.incomplete_sessions = st
            .query_map([], |r| r.get(0))
            .map_err(|e| sql(&root, e))?
            .collect::<Result<_, _>>()
            .map_err(|e| sql(&root, e))?;
        Ok(report)
    }
}
