//! `seam export site.seam OUT [--tables point_labels,static_map,lifelong_map,changes] [--overwrite]`
//!
//! Writes tables of a store as Parquet for analysts, plus `OUT/_catalog.json`
//! naming every table's columns, types, partitions, frame and row counts:
//!
//! | table | files | rows |
//! |-------|-------|------|
//! | `point_labels` | `point_labels/session=<id>/part-<k>.parquet` | every scan point's DOR label |
//! | `static_map` | `static_map/part-0.parquet` | map voxels with `eps_g < [change] static_threshold` |
//! | `lifelong_map` | `lifelong_map/part-0.parquet` | every map voxel |
//! | `changes` | `changes/session=<id>/part-0.parquet` | every change event, one file per session change detection ran for |
//!
//! Session-partitioned tables follow DESIGN.md's Hive layout; the session is
//! the partition key, not a column in the files. The two maps are one current
//! state (on the newest graph version), not per session, so they are one file
//! each. DuckDB reads `read_parquet('OUT/changes/*/*.parquet', hive_partitioning
//! = true)` or `read_parquet('OUT/static_map/*.parquet')`, pandas
//! `pd.read_parquet('OUT/changes')`.
//!
//! The store is opened read-only, so an export may run beside an ingest; the
//! map tables are read in one snapshot. Each table is built in a hidden folder
//! `OUT/.<table>.tmp-<pid>` (every file in it written under a temporary name,
//! fsynced and renamed) and then renamed into place whole: an interrupted
//! export never leaves a half file or a half table under the final names,
//! only the hidden folder.

use super::output::{json, log, print_json, print_table, thousands};
use super::{Ctx, UsageError};
use crate::store::evidence_files::{
    SessionFile, export_point_labels, point_labels_schema, read_point_labels, session_files,
};
use crate::store::map_export::{
    MapExport, changes_schema, export_changes, export_map_voxels, map_voxels_schema, read_map_export,
};
use crate::store::{Store, StoreError, now_utc};
use arrow_schema::{DataType, SchemaRef};
use clap::Args;
use std::fs::File;
use std::path::{Path, PathBuf};

/// Tables `seam export` knows, in catalog order.
pub const KNOWN_TABLES: &[&str] = &["point_labels", "static_map", "lifelong_map", "changes"];

#[derive(Debug, Args)]
pub struct ExportArgs {
    /// The store (opened read-only).
    pub store: PathBuf,
    /// Folder to write into (created if missing).
    pub out: PathBuf,
    /// Comma-separated tables to export [known: point_labels, static_map, lifelong_map, changes].
    #[arg(long, value_delimiter = ',', default_value = "point_labels")]
    pub tables: Vec<String>,
    /// Replace tables OUT already holds (otherwise an existing OUT/<table> is refused).
    #[arg(long)]
    pub overwrite: bool,
}

/// One written file.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
struct Partition {
    /// The Hive partition; `None` for tables that are not partitioned.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    session: Option<i64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    session_name: Option<String>,
    /// The graph version the file's positions are on, for positional tables.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    graph_version: Option<i64>,
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
    #[serde(default, skip_serializing_if = "Option::is_none")]
    description: Option<String>,
}

/// The frame positional columns (`x_m`, `y_m`, `z_m`) are in.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
struct Frame {
    /// Always `world`: the store's world frame (what `seam poses` prints).
    name: String,
    /// The store's CRS (`local` or an EPSG code).
    crs: String,
    /// The graph version positions are on; `None` where it differs per
    /// partition (each partition names its own).
    graph_version: Option<i64>,
    /// Edge of the voxel grid `kx`/`ky`/`kz` count in, metres.
    voxel_m: f64,
}

#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
struct TableEntry {
    name: String,
    description: String,
    /// Relative to OUT.
    path: String,
    partition_by: Vec<String>,
    columns: Vec<Column>,
    row_count: u64,
    /// How rows are ordered within each file.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    sorted_by: Option<String>,
    /// The row filter that defines the table, if any.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    filter: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    frame: Option<Frame>,
    partitions: Vec<Partition>,
}

/// What a table is, before its files are written.
struct TableSpec {
    name: &'static str,
    description: &'static str,
    schema: SchemaRef,
    partition_by: &'static [&'static str],
    sorted_by: Option<&'static str>,
    filter: Option<String>,
    frame: Option<Frame>,
}

const SPATIAL_SORT: &str = "z-order (Morton) of the voxel key, then id";

pub fn run(ctx: &Ctx, a: ExportArgs) -> anyhow::Result<()> {
    // Everything the user can get wrong is refused, and everything read,
    // before anything is written.
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
    let meta = store.meta()?;
    let map = if tables.iter().any(|t| t != "point_labels") { Some(read_map_export(&store)?) } else { None };
    std::fs::create_dir_all(&a.out).map_err(|e| StoreError::io(&a.out, e))?;

    let threshold = ctx.config.change.static_threshold;
    let mut entries = Vec::new();
    for t in &tables {
        let entry = match (t.as_str(), &map) {
            ("point_labels", _) => {
                let spec = TableSpec {
                    name: "point_labels",
                    description: "DOR label of every scan point of each session (keyframe, index in its scan)",
                    schema: point_labels_schema(),
                    partition_by: &["session"],
                    sorted_by: Some("keyframe, point_index"),
                    filter: None,
                    frame: None,
                };
                export_table(&a.out, spec, |staging| write_point_labels(ctx, &store, staging))?
            }
            ("static_map", Some(map)) => {
                let voxels = map.static_voxels(threshold);
                let spec = TableSpec {
                    name: "static_map",
                    description: "voxels of the lifelong map that are static: global ephemerality below the threshold",
                    schema: map_voxels_schema(),
                    partition_by: &[],
                    sorted_by: Some(SPATIAL_SORT),
                    filter: Some(format!("eps_g < {threshold}")),
                    frame: Some(map_frame(&meta.crs, map)),
                };
                export_table(&a.out, spec, |staging| write_map(ctx, map, staging, "static_map", &voxels))?
            }
            ("lifelong_map", Some(map)) => {
                let voxels: Vec<_> = map.voxels.iter().collect();
                let spec = TableSpec {
                    name: "lifelong_map",
                    description: "every voxel any session's cleaned map had, with its global ephemerality and history",
                    schema: map_voxels_schema(),
                    partition_by: &[],
                    sorted_by: Some(SPATIAL_SORT),
                    filter: None,
                    frame: Some(map_frame(&meta.crs, map)),
                };
                export_table(&a.out, spec, |staging| write_map(ctx, map, staging, "lifelong_map", &voxels))?
            }
            ("changes", Some(map)) => {
                let spec = TableSpec {
                    name: "changes",
                    description: "every change a session saw at a map voxel (emerged, deleted, back again)",
                    schema: changes_schema(),
                    partition_by: &["session"],
                    sorted_by: Some(SPATIAL_SORT),
                    filter: None,
                    // Events keep the positions of their own session's ingest.
                    frame: Some(Frame { graph_version: None, ..map_frame(&meta.crs, map) }),
                };
                export_table(&a.out, spec, |staging| write_changes(ctx, map, staging))?
            }
            (other, _) => return Err(UsageError(format!("unknown table {other:?}")).into()),
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
        .map(|(t, p)| {
            let session = p.session.map_or_else(|| "-".to_string(), |s| s.to_string());
            vec![t.to_string(), session, thousands(p.row_count), thousands(p.size_bytes)]
        })
        .collect();
    print_table(&["table", "session", "rows", "bytes"], &rows);
    Ok(())
}

/// The frame of the map tables: the world frame of the map's graph version.
fn map_frame(crs: &str, map: &MapExport) -> Frame {
    Frame {
        name: "world".into(),
        crs: crs.to_string(),
        graph_version: map.state.map(|s| s.graph_version),
        voxel_m: map.voxel_m,
    }
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

/// Arrow type names as analysts know them (`int32`, `float32`, `boolean`, `string`).
fn type_name(t: &DataType) -> String {
    match t {
        DataType::Int32 => "int32".into(),
        DataType::Int64 => "int64".into(),
        DataType::Float32 => "float32".into(),
        DataType::Float64 => "float64".into(),
        DataType::Boolean => "boolean".into(),
        DataType::Utf8 => "string".into(),
        other => other.to_string().to_lowercase(),
    }
}

/// Exports one table: `write` fills a hidden staging folder (returning the
/// partitions with their paths as they will be after the rename), which is
/// then renamed into place whole.
fn export_table(
    out: &Path,
    spec: TableSpec,
    write: impl FnOnce(&Path) -> anyhow::Result<Vec<Partition>>,
) -> anyhow::Result<TableEntry> {
    let table = spec.name;
    let pid = std::process::id();
    let staging = out.join(format!(".{table}.tmp-{pid}"));
    if staging.exists() {
        std::fs::remove_dir_all(&staging).map_err(|e| StoreError::io(&staging, e))?;
    }
    std::fs::create_dir_all(&staging).map_err(|e| StoreError::io(&staging, e))?;
    let parts = match write(&staging) {
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
    let columns = spec
        .schema
        .fields()
        .iter()
        .map(|f| Column {
            name: f.name().clone(),
            type_name: type_name(f.data_type()),
            nullable: f.is_nullable(),
            description: f.metadata().get("description").cloned(),
        })
        .collect();
    Ok(TableEntry {
        name: table.to_string(),
        description: spec.description.to_string(),
        path: table.to_string(),
        partition_by: spec.partition_by.iter().map(|p| p.to_string()).collect(),
        columns,
        row_count: parts.iter().map(|p| p.row_count).sum(),
        sorted_by: spec.sorted_by.map(str::to_string),
        filter: spec.filter,
        frame: spec.frame,
        partitions: parts,
    })
}

/// Writes `staging/session=<id>/part-<k>.parquet` for every stored point
/// labels file; paths in the result are as they will be after the rename.
fn write_point_labels(ctx: &Ctx, store: &Store, staging: &Path) -> anyhow::Result<Vec<Partition>> {
    let table = "point_labels";
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
            session: Some(session_id.0),
            session_name: Some(session_name.clone()),
            graph_version: None,
            path: format!("{table}/{rel}"),
            row_count: written.row_count,
            size_bytes: written.size_bytes,
            blake3: written.blake3,
        });
    }
    Ok(parts)
}

/// Writes `staging/part-0.parquet` with `voxels`, even none (an empty file
/// still carries the schema).
fn write_map(
    ctx: &Ctx,
    map: &MapExport,
    staging: &Path,
    table: &str,
    voxels: &[&crate::change::MapVoxel],
) -> anyhow::Result<Vec<Partition>> {
    if map.state.is_none() {
        log(ctx, format!("{table}: the store has no lifelong map yet; writing an empty table"));
    }
    let rel = "part-0.parquet";
    let written = export_map_voxels(&staging.join(rel), voxels)?;
    log(ctx, format!("{table}: {} rows", thousands(written.row_count)));
    Ok(vec![Partition {
        session: None,
        session_name: None,
        graph_version: map.state.map(|s| s.graph_version),
        path: format!("{table}/{rel}"),
        row_count: written.row_count,
        size_bytes: written.size_bytes,
        blake3: written.blake3,
    }])
}

/// Writes `staging/session=<id>/part-0.parquet` for every session change
/// detection ran for, even one without events (the first session never has
/// any: there was nothing to compare it with).
fn write_changes(ctx: &Ctx, map: &MapExport, staging: &Path) -> anyhow::Result<Vec<Partition>> {
    let table = "changes";
    if map.sessions.is_empty() {
        log(ctx, format!("{table}: no session has been through change detection yet; writing an empty table"));
    }
    let mut parts = Vec::new();
    for s in &map.sessions {
        let rel = format!("session={}/part-0.parquet", s.session_id.0);
        let written = export_changes(&staging.join(&rel), map.events_of(s.session_id))?;
        log(ctx, format!("{table}: session {} ({}): {} rows", s.session_id.0, s.name, thousands(written.row_count)));
        parts.push(Partition {
            session: Some(s.session_id.0),
            session_name: Some(s.name.clone()),
            graph_version: s.graph_version,
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
        assert_eq!(type_name(&DataType::Utf8), "string");
        let err = parse_tables(&s(&["changes", "lifelong"])).unwrap_err().to_string();
        assert!(err.contains("known tables: point_labels, static_map, lifelong_map, changes"), "{err}");
    }
}
