//! Writing each table: [`export_table`] stages a table in a hidden folder and
//! renames it into place whole; the `write_*` functions fill the staging
//! folder with a table's files and return their partitions.

use super::catalog::{Frame, Partition, TableEntry, columns, geometry_entry};
use super::{Job, sync_dir};
use crate::cli::output::{log, thousands};
use crate::store::evidence_files::{SessionFile, WrittenFile, export_point_labels, read_point_labels, session_files};
use crate::store::geoparquet::{GEOPARQUET_VERSION, GeoSummary, GeometryType};
use crate::store::map_export::{MapExport, export_changes, export_map_voxels};
use crate::store::trajectory_export::{TrajectoryExport, export_keyframes, export_loop_edges, export_sessions};
use crate::store::{SessionId, StoreError};
use arrow_schema::SchemaRef;
use std::path::Path;

/// What a table is, before its files are written.
pub struct TableSpec {
    pub name: &'static str,
    pub description: &'static str,
    pub schema: SchemaRef,
    pub partition_by: &'static [&'static str],
    pub sorted_by: Option<&'static str>,
    pub filter: Option<String>,
    pub frame: Option<Frame>,
    /// Empty: plain Parquet; else GeoParquet holding these types.
    pub geometry_types: &'static [GeometryType],
}

/// A partition of a written file.
pub fn partition(
    table: &str,
    rel: &str,
    w: &WrittenFile,
    session: Option<(SessionId, &str)>,
    graph_version: Option<i64>,
    geo: Option<&GeoSummary>,
) -> Partition {
    Partition {
        session: session.map(|s| s.0.0),
        session_name: session.map(|s| s.1.to_string()),
        graph_version,
        path: format!("{table}/{rel}"),
        row_count: w.row_count,
        size_bytes: w.size_bytes,
        blake3: w.blake3.clone(),
        bbox: geo.and_then(|g| g.bbox),
    }
}

/// Exports one table: `write` fills a hidden staging folder (returning the
/// partitions with their paths as they will be after the rename), which is
/// then renamed into place whole.
pub fn export_table(
    job: &Job<'_>,
    spec: TableSpec,
    write: impl FnOnce(&Path) -> anyhow::Result<Vec<Partition>>,
) -> anyhow::Result<TableEntry> {
    let table = spec.name;
    let parts = stage_and_swap(job.out, table, write)?;
    let geometry = (!spec.geometry_types.is_empty()).then(|| {
        let empty = GeoSummary { types: spec.geometry_types.to_vec(), bbox: None };
        let all = parts.iter().fold(empty, |acc, p| acc.union(&GeoSummary { types: vec![], bbox: p.bbox }));
        geometry_entry(&all, &job.crs)
    });
    Ok(TableEntry {
        name: table.to_string(),
        description: spec.description.to_string(),
        format: if geometry.is_some() { format!("GeoParquet {GEOPARQUET_VERSION}") } else { "Parquet".into() },
        path: table.to_string(),
        partition_by: spec.partition_by.iter().map(|p| p.to_string()).collect(),
        columns: columns(&spec.schema),
        row_count: parts.iter().map(|p| p.row_count).sum(),
        size_bytes: parts.iter().map(|p| p.size_bytes).sum(),
        sorted_by: spec.sorted_by.map(str::to_string),
        filter: spec.filter,
        frame: spec.frame,
        geometry,
        partitions: parts,
    })
}

/// Fills `OUT/.<name>.tmp-<pid>` with `write` and renames it to
/// `OUT/<name>` (replacing what was there: the caller checked --overwrite).
pub fn stage_and_swap<T>(out: &Path, name: &str, write: impl FnOnce(&Path) -> anyhow::Result<T>) -> anyhow::Result<T> {
    let pid = std::process::id();
    let staging = out.join(format!(".{name}.tmp-{pid}"));
    if staging.exists() {
        std::fs::remove_dir_all(&staging).map_err(|e| StoreError::io(&staging, e))?;
    }
    std::fs::create_dir_all(&staging).map_err(|e| StoreError::io(&staging, e))?;
    let result = match write(&staging) {
        Ok(p) => p,
        Err(e) => {
            let _ = std::fs::remove_dir_all(&staging);
            return Err(e);
        }
    };
    sync_dir(&staging)?;
    crate::fault::point("export:before_swap");
    let final_dir = out.join(name);
    if final_dir.exists() {
        // --overwrite (checked by the caller): swap, then drop the old table.
        let old = out.join(format!(".{name}.old-{pid}"));
        std::fs::rename(&final_dir, &old).map_err(|e| StoreError::io(&final_dir, e))?;
        std::fs::rename(&staging, &final_dir).map_err(|e| StoreError::io(&final_dir, e))?;
        sync_dir(out)?;
        std::fs::remove_dir_all(&old).map_err(|e| StoreError::io(&old, e))?;
    } else {
        std::fs::rename(&staging, &final_dir).map_err(|e| StoreError::io(&final_dir, e))?;
        sync_dir(out)?;
    }
    Ok(result)
}

/// Writes `staging/session=<id>/part-<k>.parquet` for every stored point
/// labels file; paths in the result are as they will be after the rename.
pub fn write_point_labels(job: &Job<'_>, staging: &Path) -> anyhow::Result<Vec<Partition>> {
    let table = "point_labels";
    let files = session_files(job.store, table)?;
    if files.is_empty() {
        log(job.ctx, format!("{table}: no session has this table yet; writing an empty table"));
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
        let labels = read_point_labels(&job.store.path_of(rel_path))?;
        let written = export_point_labels(&staging.join(&rel), &labels)?;
        log(
            job.ctx,
            format!("{table}: session {} ({session_name}): {} rows", session_id.0, thousands(written.row_count)),
        );
        parts.push(partition(table, &rel, &written, Some((*session_id, session_name)), None, None));
    }
    Ok(parts)
}

/// Writes `staging/part-0.parquet` with `voxels`, even none (an empty file
/// still carries the schema).
pub fn write_map(
    job: &Job<'_>,
    map: &MapExport,
    staging: &Path,
    table: &str,
    voxels: &[&crate::change::MapVoxel],
) -> anyhow::Result<Vec<Partition>> {
    if map.state.is_none() {
        log(job.ctx, format!("{table}: the store has no lifelong map yet; writing an empty table"));
    }
    let rel = "part-0.parquet";
    let (written, geo) = export_map_voxels(&staging.join(rel), voxels, &job.crs)?;
    log(job.ctx, format!("{table}: {} rows", thousands(written.row_count)));
    Ok(vec![partition(table, rel, &written, None, map.state.map(|s| s.graph_version), Some(&geo))])
}

/// Writes `staging/session=<id>/part-0.parquet` for every session change
/// detection ran for, even one without events (the first session never has
/// any: there was nothing to compare it with).
pub fn write_changes(job: &Job<'_>, map: &MapExport, staging: &Path) -> anyhow::Result<Vec<Partition>> {
    let table = "changes";
    if map.sessions.is_empty() {
        log(job.ctx, format!("{table}: no session has been through change detection yet; writing an empty table"));
    }
    let mut parts = Vec::new();
    for s in &map.sessions {
        let rel = format!("session={}/part-0.parquet", s.session_id.0);
        let (written, geo) = export_changes(&staging.join(&rel), map.events_of(s.session_id), map.voxel_m, &job.crs)?;
        log(
            job.ctx,
            format!("{table}: session {} ({}): {} rows", s.session_id.0, s.name, thousands(written.row_count)),
        );
        parts.push(partition(table, &rel, &written, Some((s.session_id, &s.name)), s.graph_version, Some(&geo)));
    }
    Ok(parts)
}

/// Writes `staging/part-0.parquet`: one row per session.
pub fn write_sessions(job: &Job<'_>, t: &TrajectoryExport, staging: &Path) -> anyhow::Result<Vec<Partition>> {
    let rel = "part-0.parquet";
    let (written, geo) = export_sessions(&staging.join(rel), t, &job.crs)?;
    log(job.ctx, format!("sessions: {} rows", thousands(written.row_count)));
    Ok(vec![partition("sessions", rel, &written, None, t.graph_version, Some(&geo))])
}

/// Writes `staging/session=<id>/part-0.parquet` for every session, even one
/// without poses yet (the file still carries the schema).
pub fn write_keyframes(job: &Job<'_>, t: &TrajectoryExport, staging: &Path) -> anyhow::Result<Vec<Partition>> {
    let table = "keyframes";
    let mut parts = Vec::new();
    for s in &t.sessions {
        let rel = format!("session={}/part-0.parquet", s.row.session_id.0);
        let (written, geo) = export_keyframes(&staging.join(&rel), &s.keyframes, &job.crs)?;
        let session = Some((s.row.session_id, s.row.name.as_str()));
        parts.push(partition(table, &rel, &written, session, t.graph_version, Some(&geo)));
    }
    log(job.ctx, format!("{table}: {} rows", thousands(parts.iter().map(|p| p.row_count).sum())));
    Ok(parts)
}

/// Writes `staging/session=<id>/part-0.parquet` for every session: the loop
/// candidates its ingest evaluated (none for a first session).
pub fn write_loop_edges(job: &Job<'_>, t: &TrajectoryExport, staging: &Path) -> anyhow::Result<Vec<Partition>> {
    let table = "loop_edges";
    let mut parts = Vec::new();
    for s in &t.sessions {
        let rel = format!("session={}/part-0.parquet", s.row.session_id.0);
        let (written, geo) = export_loop_edges(&staging.join(&rel), t.loops_of(s.row.session_id), &job.crs)?;
        let session = Some((s.row.session_id, s.row.name.as_str()));
        parts.push(partition(table, &rel, &written, session, t.graph_version, Some(&geo)));
    }
    log(job.ctx, format!("{table}: {} rows", thousands(parts.iter().map(|p| p.row_count).sum())));
    Ok(parts)
}
