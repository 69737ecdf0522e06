//! The lifelong map and its change events as analyst Parquet (`seam export
//! --tables static_map,lifelong_map,changes`), written with the evidence
//! files' writer ([`super::evidence_files::write_batch_with`]: zstd, row
//! groups, split floats, publish protocol) as GeoParquet.
//!
//! The three tables are read from SQLite in one read transaction
//! ([`read_map_export`]), so a static map, lifelong map and change list
//! exported together are the same snapshot even while an ingest commits.
//!
//! | table | columns |
//! |-------|---------|
//! | `map_voxels` (`static_map`, `lifelong_map`) | `voxel_id` int64, `kx ky kz` int32, `x_m y_m z_m` float64, `eps_g eps_l` float32, `points` int32, `first_session last_seen_session` int32, `category` string, `category_session owner_session owner_keyframe` int32 |
//! | `changes` (one file per session) | `event_id` int64, `voxel_id` int64, `x_m y_m z_m` float64, `category` string, `eps_g_before` float32 (null: new voxel), `eps_g_after` float32, `volume_m3` float64 |
//!
//! Both end with the GeoParquet `geometry` (the centroid as a WKB `Point Z`)
//! and `bbox` covering columns ([`super::geoparquet`]).
//!
//! Rows are sorted spatially: by the Z-order (Morton) code of the voxel key
//! on the map's grid, then by id, so a row group covers a compact box and a
//! reader filtering on `x_m`/`y_m`/`z_m` statistics skips most of them.

use super::evidence_files::WrittenFile;
use super::geoparquet::{Crs, GeoSummary, Geometry, GeometryType, geo_columns, geometry_fields, write_geoparquet};
use super::{ChangeEventRow, MapState, SessionId, Store, StoreError, WorldBox, change_events_in, map_state, sql};
use crate::change::MapVoxel;
use arrow_array::{ArrayRef, Float32Array, Float64Array, Int32Array, Int64Array, RecordBatch, StringArray};
use arrow_schema::{DataType, Field, Schema, SchemaRef};
use rusqlite::Connection;
use std::collections::HashMap;
use std::path::Path;
use std::sync::Arc;

/// A session change detection has run for (or that has change events).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ChangeSession {
    pub session_id: SessionId,
    pub name: String,
    /// The graph version its change events' positions are on (its
    /// `session_changes` row); `None` if it has events but no such row.
    pub graph_version: Option<i64>,
}

/// What the map tables are written from: one snapshot of the store.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct MapExport {
    /// `None`: no session has been through change detection yet.
    pub state: Option<MapState>,
    /// Every map voxel, spatially sorted.
    pub voxels: Vec<MapVoxel>,
    /// Every change event, by session, each session's spatially sorted.
    pub events: Vec<ChangeEventRow>,
    /// One per `changes` partition, by id.
    pub sessions: Vec<ChangeSession>,
    /// Grid of the spatial sort: the map's voxel size, else the store's.
    pub voxel_m: f64,
}

impl MapExport {
    /// The voxels of the static map: ε_g below `threshold`.
    pub fn static_voxels(&self, threshold: f64) -> Vec<&MapVoxel> {
        self.voxels.iter().filter(|v| (v.eps_g as f64) < threshold).collect()
    }

    /// The change events of one session (a slice: events are by session).
    pub fn events_of(&self, session: SessionId) -> &[ChangeEventRow] {
        let lo = self.events.partition_point(|e| e.event.session_id < session.0);
        let hi = self.events.partition_point(|e| e.event.session_id <= session.0);
        &self.events[lo..hi]
    }
}

/// Reads the lifelong map, its change events and the sessions they belong
/// to in one read transaction. A store whose schema predates the lifelong
/// map (opened read-only, so not migrated) reads as an empty map.
pub fn read_map_export(store: &Store) -> Result<MapExport, StoreError> {
    // A deferred transaction on a read-only connection: every read below
    // sees the same WAL snapshot. Dropping it rolls back, which is a no-op.
    let tx = store.conn().unchecked_transaction().map_err(|e| sql(store.root(), e))?;
    read_map_export_in(store, &tx)
}

/// [`read_map_export`] inside the caller's read transaction `tx` (on
/// `store`'s connection), so other tables can be read in the same snapshot.
pub fn read_map_export_in(store: &Store, tx: &Connection) -> Result<MapExport, StoreError> {
    let root = store.root();
    let voxel_size_m = store.meta()?.voxel_size_m;
    // Every table the reads below touch (`map_tiles` is their spatial index).
    let needed = ["map_voxels", "map_tiles", "map_state", "change_events", "session_changes"];
    let present: i64 = tx
        .query_row(
            &format!(
                "SELECT count(*) FROM sqlite_master WHERE name IN ({})",
                needed.map(|n| format!("'{n}'")).join(", ")
            ),
            [],
            |r| r.get(0),
        )
        .map_err(|e| sql(root, e))?;
    if present < needed.len() as i64 {
        return Ok(MapExport { voxel_m: voxel_size_m, ..MapExport::default() });
    }
    let state = map_state(tx)?;
    let voxel_m = state.map(|s| s.voxel_m).filter(|v| *v > 0.0).unwrap_or(voxel_size_m);
    let mut voxels = super::map_voxels_in(tx, &WorldBox::ALL, None)?;
    voxels.sort_unstable_by_key(|v| (z_order(v.key.0), v.voxel_id));
    let mut events = change_events_in(tx, &WorldBox::ALL, i64::MIN)?;
    events.sort_unstable_by_key(|e| (e.event.session_id, z_order(key_of(&e.event.xyz_m, voxel_m)), e.event_id));

    let mut st = tx
        .prepare(
            "SELECT s.session_id, s.name, c.graph_version FROM sessions s
             LEFT JOIN session_changes c ON c.session_id = s.session_id
             WHERE c.session_id IS NOT NULL OR s.session_id IN (SELECT session_id FROM change_events)
             ORDER BY s.session_id",
        )
        .map_err(|e| sql(root, e))?;
    let rows = st
        .query_map([], |r| {
            Ok(ChangeSession { session_id: SessionId(r.get(0)?), name: r.get(1)?, graph_version: r.get(2)? })
        })
        .map_err(|e| sql(root, e))?;
    let sessions = rows.collect::<Result<Vec<_>, _>>().map_err(|e| sql(root, e))?;
    Ok(MapExport { state, voxels, events, sessions, voxel_m })
}

/// The key of the voxel holding `p` on a grid of `voxel_m`.
fn key_of(p: &[f64; 3], voxel_m: f64) -> [i32; 3] {
    p.map(|c| (c / voxel_m).floor() as i32)
}

/// Z-order (Morton) code of a voxel key: its three coordinates, offset to be
/// non-negative and clamped to 21 bits (±1,048,576 voxels, ±210 km at
/// 0.2 m), bit-interleaved. Nearby keys get nearby codes.
pub fn z_order(key: [i32; 3]) -> u64 {
    const BITS: u32 = 21;
    const OFFSET: i64 = 1 << (BITS - 1);
    let spread = |c: i32| -> u64 {
        let mut x = (c as i64 + OFFSET).clamp(0, (1 << BITS) - 1) as u64;
        // Spread 21 bits to every third bit of 63.
        x = (x | (x << 32)) & 0x001f_0000_0000_ffff;
        x = (x | (x << 16)) & 0x001f_0000_ff00_00ff;
        x = (x | (x << 8)) & 0x100f_00f0_0f00_f00f;
        x = (x | (x << 4)) & 0x10c3_0c30_c30c_30c3;
        x = (x | (x << 2)) & 0x1249_2492_4924_9249;
        x
    };
    (spread(key[0]) << 2) | (spread(key[1]) << 1) | spread(key[2])
}

// ---------------------------------------------------------------------------
// Schemas and batches

fn field(name: &str, t: DataType, nullable: bool, description: &str) -> Field {
    Field::new(name, t, nullable).with_metadata(HashMap::from([("description".to_string(), description.to_string())]))
}

fn xyz_fields(what: &str) -> [Field; 3] {
    ["x", "y", "z"].map(|a| field(&format!("{a}_m"), DataType::Float64, false, &format!("{what}, world frame, metres")))
}

/// Columns of the `static_map` and `lifelong_map` exports. Each field's
/// `description` metadata is what `_catalog.json` says about it.
pub fn map_voxels_schema() -> SchemaRef {
    let key =
        |a: &str| field(&format!("k{a}"), DataType::Int32, false, &format!("{a} of the voxel key on the world grid"));
    let mut f = vec![
        field("voxel_id", DataType::Int64, false, "stable id while the voxel lives"),
        key("x"),
        key("y"),
        key("z"),
    ];
    f.extend(xyz_fields("centroid of the voxel's points"));
    f.extend([
        field("eps_g", DataType::Float32, false, "global ephemerality in [0, 1]; below the static threshold: static"),
        field("eps_l", DataType::Float32, false, "local ephemerality in the last session that saw the voxel"),
        field("points", DataType::Int32, false, "points behind the centroid in the last session that saw it"),
        field("first_session", DataType::Int32, false, "session that first saw the voxel"),
        field("last_seen_session", DataType::Int32, false, "last session that saw the voxel"),
        field("category", DataType::Utf8, false, "change category: initial, coexist, deleted_overlap, deleted_non_overlap, emerged_overlap, emerged_non_overlap"),
        field("category_session", DataType::Int32, false, "session that set the category"),
        field("owner_session", DataType::Int32, false, "the voxel moves with this session's keyframe owner_keyframe"),
        field("owner_keyframe", DataType::Int32, false, "keyframe index in owner_session"),
    ]);
    f.extend(geometry_fields(false, "the centroid as a Point Z"));
    Arc::new(Schema::new(f))
}

/// Columns of a `changes` export file (the session is its partition).
pub fn changes_schema() -> SchemaRef {
    let mut f = vec![
        field("event_id", DataType::Int64, false, "event id, increasing with ingest order"),
        field("voxel_id", DataType::Int64, false, "lifelong_map voxel_id at the time of the event"),
    ];
    f.extend(xyz_fields("voxel centroid on the graph version of the session's ingest"));
    f.extend([
        field(
            "category",
            DataType::Utf8,
            false,
            "coexist, deleted_overlap, deleted_non_overlap, emerged_overlap, emerged_non_overlap",
        ),
        field("eps_g_before", DataType::Float32, true, "eps_g before the session; null: the voxel was new to the map"),
        field("eps_g_after", DataType::Float32, false, "eps_g after the session"),
        field("volume_m3", DataType::Float64, false, "volume of the voxel that changed (the map's voxel edge cubed)"),
    ]);
    f.extend(geometry_fields(false, "the centroid as a Point Z"));
    Arc::new(Schema::new(f))
}

/// An int32 column of values that must fit, naming the first that does not.
fn i32_col<T: Copy + TryInto<i32> + std::fmt::Display>(
    path: &Path,
    name: &str,
    v: impl Iterator<Item = T>,
) -> Result<ArrayRef, StoreError> {
    let mut out = Vec::with_capacity(v.size_hint().0);
    for (row, x) in v.enumerate() {
        out.push(x.try_into().map_err(|_| StoreError::Parquet {
            path: path.to_path_buf(),
            message: format!("column {name}: value {x} in row {row} does not fit int32"),
        })?);
    }
    Ok(Arc::new(Int32Array::from(out)))
}

fn f64_col(v: impl Iterator<Item = f64>) -> ArrayRef {
    Arc::new(Float64Array::from_iter_values(v))
}

fn f32_col(v: impl Iterator<Item = f32>) -> ArrayRef {
    Arc::new(Float32Array::from_iter_values(v))
}

fn i64_col(v: impl Iterator<Item = i64>) -> ArrayRef {
    Arc::new(Int64Array::from_iter_values(v))
}

fn str_col<'a>(v: impl Iterator<Item = &'a str>) -> ArrayRef {
    Arc::new(StringArray::from_iter_values(v))
}

fn batch(path: &Path, schema: SchemaRef, cols: Vec<ArrayRef>) -> Result<RecordBatch, StoreError> {
    RecordBatch::try_new(schema, cols)
        .map_err(|e| StoreError::Parquet { path: path.to_path_buf(), message: e.to_string() })
}

/// The `map_voxels` columns of `voxels`, in the given order, and the
/// summary of their geometries.
pub fn map_voxels_batch(path: &Path, voxels: &[&MapVoxel]) -> Result<(RecordBatch, GeoSummary), StoreError> {
    let it = || voxels.iter().copied();
    let mut cols = vec![i64_col(it().map(|v| v.voxel_id))];
    cols.extend((0..3).map(|i| Arc::new(Int32Array::from_iter_values(it().map(|v| v.key.0[i]))) as ArrayRef));
    cols.extend((0..3).map(|i| f64_col(it().map(|v| v.xyz_m[i]))));
    cols.push(f32_col(it().map(|v| v.eps_g)));
    cols.push(f32_col(it().map(|v| v.eps_l)));
    cols.push(i32_col(path, "points", it().map(|v| v.points))?);
    cols.push(i32_col(path, "first_session", it().map(|v| v.first_session))?);
    cols.push(i32_col(path, "last_seen_session", it().map(|v| v.last_seen_session))?);
    cols.push(str_col(it().map(|v| v.category.as_str())));
    cols.push(i32_col(path, "category_session", it().map(|v| v.category_session))?);
    cols.push(i32_col(path, "owner_session", it().map(|v| v.owner_session))?);
    cols.push(i32_col(path, "owner_keyframe", it().map(|v| v.owner_keyframe))?);
    let geo = geo_columns(&[GeometryType::PointZ], it().map(|v| Some(Geometry::PointZ(v.xyz_m))));
    cols.extend([geo.geometry, geo.bbox]);
    Ok((batch(path, map_voxels_schema(), cols)?, geo.summary))
}

/// The `changes` columns of `events`, in the given order (each a voxel of
/// `voxel_m`), and the summary of their geometries.
pub fn changes_batch(
    path: &Path,
    events: &[ChangeEventRow],
    voxel_m: f64,
) -> Result<(RecordBatch, GeoSummary), StoreError> {
    let geo = geo_columns(&[GeometryType::PointZ], events.iter().map(|e| Some(Geometry::PointZ(e.event.xyz_m))));
    let cols = vec![
        i64_col(events.iter().map(|e| e.event_id)),
        i64_col(events.iter().map(|e| e.event.voxel_id)),
        f64_col(events.iter().map(|e| e.event.xyz_m[0])),
        f64_col(events.iter().map(|e| e.event.xyz_m[1])),
        f64_col(events.iter().map(|e| e.event.xyz_m[2])),
        str_col(events.iter().map(|e| e.event.category.as_str())),
        Arc::new(Float32Array::from_iter(events.iter().map(|e| e.event.eps_g_before))) as ArrayRef,
        f32_col(events.iter().map(|e| e.event.eps_g_after)),
        f64_col(events.iter().map(|_| voxel_m.powi(3))),
        geo.geometry,
        geo.bbox,
    ];
    Ok((batch(path, changes_schema(), cols)?, geo.summary))
}

/// Writes map voxels to `path` outside any store (`seam export`) as
/// GeoParquet in `crs`, with the publish protocol. Fault point
/// `export:before_rename`.
pub fn export_map_voxels(
    path: &Path,
    voxels: &[&MapVoxel],
    crs: &Crs,
) -> Result<(WrittenFile, GeoSummary), StoreError> {
    let (b, geo) = map_voxels_batch(path, voxels)?;
    Ok((write_geoparquet(path, &b, &geo, crs)?, geo))
}

/// Writes change events (voxels of `voxel_m`) to `path` outside any store
/// (`seam export`) as GeoParquet in `crs`.
pub fn export_changes(
    path: &Path,
    events: &[ChangeEventRow],
    voxel_m: f64,
    crs: &Crs,
) -> Result<(WrittenFile, GeoSummary), StoreError> {
    let (b, geo) = changes_batch(path, events, voxel_m)?;
    Ok((write_geoparquet(path, &b, &geo, crs)?, geo))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The bit-twiddled interleave equals the obvious loop.
    #[test]
    fn z_order_interleaves_offset_coordinates() {
        let slow = |k: [i32; 3]| {
            let c = k.map(|c| (c as i64 + (1 << 20)).clamp(0, (1 << 21) - 1) as u64);
            let mut out = 0u64;
            for bit in (0..21).rev() {
                for a in c {
                    out = (out << 1) | ((a >> bit) & 1);
                }
            }
            out
        };
        for k in [
            [0, 0, 0],
            [1, 0, 0],
            [0, 0, 1],
            [-1, -1, -1],
            [12345, -678, 9],
            [1 << 20, -(1 << 20), 5],
            [i32::MAX, i32::MIN, 0],
        ] {
            assert_eq!(z_order(k), slow(k), "{k:?}");
        }
        // x is the most significant axis at each level.
        assert!(z_order([1, 0, 0]) > z_order([0, 1, 1]));
    }
}
