//! `seam export site.seam OUT [--tables point_labels] [--overwrite]`
//!
//! Writes tables of a store as Hive-partitioned Parquet for analysts:
//! `OUT/<table>/session=<id>/part-<k>.parquet`, plus `OUT/_catalog.json`
//! naming every table's columns, types, partitions and row counts. DuckDB
//! reads a table with `read_parquet('OUT/point_labels/*/*.parquet',
//! hive_partitioning = true)`, pandas with `pd.read_parquet('OUT/point_labels')`.
//!
//! The store is opened read-only, so an export may run beside an ingest.
//! Each table is built in a hidden folder `OUT/.<table>.tmp-<pid>` (every
//! file in it written under a temporary name, fsynced and renamed) and then
//! renamed into place whole: an interrupted export never leaves a half file
//! or a half table under the final names, only the hidden folder.

use super::output::{json, log, print_json, print_table, thousands};
use super::{Ctx, UsageError};
use crate::store::evidence_files::{
    SessionFile, export_point_labels, point_labels_schema, read_point_labels, session_files,
};
use crate::store::{Store, StoreError, now_utc};
use arrow_schema::{DataType, Schema};
use clap::Args;
use std::fs::File;
use std::path::{Path, PathBuf};

/// Tables `seam export` knows, in catalog order.
pub const KNOWN_TABLES: &[&str] = &["point_labels"];

#[derive(Debug, Args)]
pub struct ExportArgs {
    /// The store (opened read-only).
    pub store: PathBuf,
    /// Folder to write into (created if missing).
    pub out: PathBuf,
    /// Comma-separated tables to export [known: point_labels].
    #[arg(long, value_delimiter = ',', default_value = "point_labels")]
    pub tables: Vec<String>,
    /// Replace tables OUT already holds (otherwise an existing OUT/<table> is refused).
    #[arg(long)]
    pub overwrite: bool,
}

/// One written partition file.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
struct Partition {
    session: i64,
    session_name: String,
    /// Relative to OUT, `/`-separated.
    path: String,
    row_count: u64,
    size_bytes: u64,
    blake3: String,
}

#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
struct Column {
    name: String,
    #[serde(rename = "type")]
    type_name: String,
    nullable: bool,
}

#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
struct TableEntry {
    name: String,
    /// Relative to OUT.
    path: String,
    partition_by: Vec<String>,
    columns: Vec<Column>,
    row_count: u64,
    partitions: Vec<Partition>,
}

pub fn run(ctx: &Ctx, a: ExportArgs) -> anyhow::Result<()> {
    // Everything the user can get wrong is refused before anything is written.
    let tables = parse_tables(&a.tables)?;
    let store = Store::open_read_only(&a.store)?;
    for t in &tables {
        let dir = a.out.join(t);
        if dir.exists() && !a.overwrite {
            return Err(UsageError(format!(
                "{} already exists\n  hint: pass --overwrite to replace it, or choose another OUT folder",
                dir.display()
            ))
            .into());
        }
    }
    std::fs::create_dir_all(&a.out).map_err(|e| StoreError::io(&a.out, e))?;

    let mut entries = Vec::new();
    for t in &tables {
        let entry = match t.as_str() {
            "point_labels" => export_table(ctx, &store, &a.out, t, &point_labels_schema())?,
            other => return Err(UsageError(format!("unknown table {other:?}")).into()),
        };
        entries.push(entry);
    }
    write_catalog(&store, &a, &entries)?;

    let parts: Vec<(&str, &Partition)> =
        entries.iter().flat_map(|e| e.partitions.iter().map(move |p| (e.name.as_str(), p))).collect();
    if json(ctx) {
        let list: Vec<serde_json::Value> = parts
            .iter()
            .map(|(t, p)| {
                serde_json::json!({
                    "table": t, "session": p.session, "session_name": p.session_name,
                    "rows": p.row_count, "bytes": p.size_bytes, "path": p.path,
                })
            })
            .collect();
        return print_json(&serde_json::json!({
            "out": a.out.display().to_string(),
            "catalog": "_catalog.json",
            "partitions": list,
        }));
    }
    let rows: Vec<Vec<String>> = parts
        .iter()
        .map(|(t, p)| vec![t.to_string(), p.session.to_string(), thousands(p.row_count), thousands(p.size_bytes)])
        .collect();
    print_table(&["table", "session", "rows", "bytes"], &rows);
    Ok(())
}

/// The requested tables, deduplicated in the order given; unknown names are
/// a usage error listing the known ones.
fn parse_tables(raw: &[String]) -> Result<Vec<String>, UsageError> {
    let mut out: Vec<String> = Vec::new();
    for t in raw.iter().map(|t| t.trim()) {
        if !KNOWN_TABLES.contains(&t) {
            return Err(UsageError(format!(
                "--tables: unknown table {t:?}\n  hint: known tables: {}",
                KNOWN_TABLES.join(", ")
            )));
        }
        if !out.iter().any(|o| o == t) {
            out.push(t.to_string());
        }
    }
    if out.is_empty() {
        return Err(UsageError(format!("--tables is empty\n  hint: known tables: {}", KNOWN_TABLES.join(", "))));
    }
    Ok(out)
}

/// Arrow type names as analysts know them (`int32`, `float32`, `boolean`).
fn type_name(t: &DataType) -> String {
    match t {
        DataType::Int32 => "int32".into(),
        DataType::Int64 => "int64".into(),
        DataType::Float32 => "float32".into(),
        DataType::Float64 => "float64".into(),
        DataType::Boolean => "boolean".into(),
        other => other.to_string().to_lowercase(),
    }
}

/// Exports one table, staged in a hidden folder and renamed into place.
fn export_table(ctx: &Ctx, store: &Store, out: &Path, table: &str, schema: &Schema) -> anyhow::Result<TableEntry> {
    let pid = std::process::id();
    let staging = out.join(format!(".{table}.tmp-{pid}"));
    if staging.exists() {
        std::fs::remove_dir_all(&staging).map_err(|e| StoreError::io(&staging, e))?;
    }
    std::fs::create_dir_all(&staging).map_err(|e| StoreError::io(&staging, e))?;
    let parts = match write_partitions(ctx, store, &staging, table) {
        Ok(p) => p,
        Err(e) => {
            let _ = std::fs::remove_dir_all(&staging);
            return Err(e);
        }
    };
    sync_dir(&staging)?;
    crate::fault::point("export:before_swap");
    let final_dir = out.join(table);
    if final_dir.exists() {
        // --overwrite (checked by the caller): swap, then drop the old table.
        let old = out.join(format!(".{table}.old-{pid}"));
        std::fs::rename(&final_dir, &old).map_err(|e| StoreError::io(&final_dir, e))?;
        std::fs::rename(&staging, &final_dir).map_err(|e| StoreError::io(&final_dir, e))?;
        sync_dir(out)?;
        std::fs::remove_dir_all(&old).map_err(|e| StoreError::io(&old, e))?;
    } else {
        std::fs::rename(&staging, &final_dir).map_err(|e| StoreError::io(&final_dir, e))?;
        sync_dir(out)?;
    }
    let columns = schema
        .fields()
        .iter()
        .map(|f| Column { name: f.name().clone(), type_name: type_name(f.data_type()), nullable: f.is_nullable() })
        .collect();
    Ok(TableEntry {
        name: table.to_string(),
        path: table.to_string(),
        partition_by: vec!["session".into()],
        columns,
        row_count: parts.iter().map(|p| p.row_count).sum(),
        partitions: parts,
    })
}

/// Writes `staging/session=<id>/part-<k>.parquet` for every stored file of
/// the table; paths in the result are as they will be after the rename.
fn write_partitions(ctx: &Ctx, store: &Store, staging: &Path, table: &str) -> anyhow::Result<Vec<Partition>> {
    let files = session_files(store, table)?;
    if files.is_empty() {
        log(ctx, format!("{table}: no session has this table yet; writing an empty table"));
    }
    let mut parts = Vec::new();
    let mut part_no = 0;
    for (i, f) in files.iter().enumerate() {
        let SessionFile { rel_path, session_id, session_name } = f;
        // Part numbers count up within a session.
        if i > 0 && files[i - 1].session_id != *session_id {
            part_no = 0;
        }
        let rel = format!("session={}/part-{part_no}.parquet", session_id.0);
        part_no += 1;
        let labels = read_point_labels(&store.path_of(rel_path))?;
        let written = export_point_labels(&staging.join(&rel), &labels)?;
        log(ctx, format!("{table}: session {} ({session_name}): {} rows", session_id.0, thousands(written.row_count)));
        parts.push(Partition {
            session: session_id.0,
            session_name: session_name.clone(),
            path: format!("{table}/{rel}"),
            row_count: written.row_count,
            size_bytes: written.size_bytes,
            blake3: written.blake3,
        });
    }
    Ok(parts)
}

/// Writes `OUT/_catalog.json` under a temporary name and renames it into
/// place. Tables of an earlier export that this one did not touch stay
/// listed while their folders exist.
fn write_catalog(store: &Store, a: &ExportArgs, entries: &[TableEntry]) -> anyhow::Result<()> {
    let path = a.out.join("_catalog.json");
    let mut tables: Vec<serde_json::Value> = Vec::new();
    if let Ok(text) = std::fs::read_to_string(&path)
        && let Ok(old) = serde_json::from_str::<serde_json::Value>(&text)
        && let Some(list) = old.get("tables").and_then(|t| t.as_array())
    {
        for t in list {
            let name = t.get("name").and_then(|n| n.as_str()).unwrap_or_default();
            let kept = !name.is_empty() && !entries.iter().any(|e| e.name == name) && a.out.join(name).is_dir();
            if kept {
                tables.push(t.clone());
            }
        }
    }
    for e in entries {
        tables.push(serde_json::to_value(e)?);
    }
    let order = |t: &serde_json::Value| {
        let name = t.get("name").and_then(|n| n.as_str()).unwrap_or_default();
        KNOWN_TABLES.iter().position(|k| *k == name).unwrap_or(usize::MAX)
    };
    tables.sort_by_key(order);
    let meta = store.meta()?;
    let catalog = serde_json::json!({
        "format": "seam-export",
        "version": 1,
        "seam_version": env!("CARGO_PKG_VERSION"),
        "store": std::fs::canonicalize(&a.store).unwrap_or_else(|_| a.store.clone()).display().to_string(),
        "site_name": meta.site_name,
        "crs": meta.crs,
        "exported_at": now_utc(),
        "tables": tables,
    });
    let tmp = path.with_extension(format!("json.tmp-{}", std::process::id()));
    let write = || -> std::io::Result<()> {
        let mut f = File::create(&tmp)?;
        serde_json::to_writer_pretty(&mut f, &catalog)?;
        std::io::Write::write_all(&mut f, b"\n")?;
        f.sync_all()?;
        std::fs::rename(&tmp, &path)
    };
    if let Err(e) = write() {
        let _ = std::fs::remove_file(&tmp);
        return Err(StoreError::io(&path, e).into());
    }
    sync_dir(&a.out)?;
    Ok(())
}

/// Makes renames in `dir` durable.
fn sync_dir(dir: &Path) -> Result<(), StoreError> {
    File::open(dir).and_then(|d| d.sync_all()).map_err(|e| StoreError::io(dir, e))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tables_are_checked_and_deduplicated() {
        let s = |v: &[&str]| v.iter().map(|x| x.to_string()).collect::<Vec<_>>();
        assert_eq!(parse_tables(&s(&["point_labels", " point_labels"])).unwrap(), ["point_labels"]);
        let err = parse_tables(&s(&["point_labels", "bogus"])).unwrap_err().to_string();
        assert!(err.contains("\"bogus\"") && err.contains("known tables: point_labels"), "{err}");
        assert!(parse_tables(&s(&[""])).is_err());
        assert_eq!(type_name(&DataType::Boolean), "boolean");
    }
}
