//! Sessions, their optimised keyframe poses and every loop candidate as
//! analyst GeoParquet (`seam export --tables sessions,keyframes,loop_edges`).
//!
//! Everything is read in the caller's read transaction ([`read_export`]
//! reads it together with the map tables), positions on the newest graph
//! version, in the world frame of `seam poses`.
//!
//! | table | rows | geometry |
//! |-------|------|----------|
//! | `sessions` | one per session: name, date, sensor, counts, status, `created_at`/`completed_at` (UTC timestamps), the coarse alignment's verdict, loops tried and accepted in its ingest, trajectory length | the trajectory, `LineString Z` (null before the session has poses) |
//! | `keyframes` (per session) | one per keyframe with a pose: index, submap, scan file, stamp, `x_m y_m z_m`, `qx qy qz qw` (`t_world_keyframe`) | `Point Z` |
//! | `loop_edges` (per session: the ingest that evaluated them) | every loop candidate, accepted or not, with ρ, the reason, GICP's diagnostics and its measured `t_target_source` | `LineString Z` from the source keyframe to the target keyframe |
//!
//! Keyframes keep trajectory order (consecutive rows are metres apart, and a
//! session's keyframes fit one row group); loop edges are sorted by the
//! Z-order of their midpoint's 1 m cell.

use super::evidence_files::WrittenFile;
use super::geoparquet::{
    Crs, GeoSummary, Geometry, GeometryType, geo_columns, geometry_fields, parse_utc_micros, write_geoparquet,
};
use super::map_export::{MapExport, read_map_export_in, z_order};
use super::rows::{e, pose_at};
use super::{AlignmentRow, SessionId, SessionRow, Store, StoreError, alignment, latest_graph_version, sessions, sql};
use crate::geometry::pose_to_tum_quat;
use arrow_array::{
    ArrayRef, BooleanArray, Float64Array, Int32Array, Int64Array, RecordBatch, StringArray, TimestampMicrosecondArray,
};
use arrow_schema::{DataType, Field, Schema, SchemaRef, TimeUnit};
use rusqlite::Connection;
use std::collections::HashMap;
use std::path::Path;
use std::sync::Arc;

/// A keyframe's optimised world pose and what the store knows of its scan.
#[derive(Debug, Clone, PartialEq)]
pub struct KeyframePose {
    pub keyframe_id: i64,
    pub keyframe_index: i64,
    pub submap_index: Option<i64>,
    pub source_file: String,
    pub stamp_s: Option<f64>,
    pub point_count: i64,
    /// `t_world_keyframe` translation, metres.
    pub xyz_m: [f64; 3],
    /// `t_world_keyframe` rotation as `[qx, qy, qz, qw]`.
    pub quat: [f64; 4],
}

/// A session with its alignment, poses and loop counts.
#[derive(Debug, Clone, PartialEq)]
pub struct SessionExport {
    pub row: SessionRow,
    pub alignment: Option<AlignmentRow>,
    /// Keyframes with a pose on the graph version, by index.
    pub keyframes: Vec<KeyframePose>,
    /// Loop candidates its ingest evaluated, and how many it accepted.
    pub loops_tried: i64,
    pub loops_accepted: i64,
}

/// A loop candidate with both ends placed on the graph version.
#[derive(Debug, Clone, PartialEq)]
pub struct LoopEdge {
    pub candidate_id: i64,
    /// The ingest that evaluated it (its partition).
    pub session_id: i64,
    pub kind: String,
    /// `(session, keyframe_index)` of each end.
    pub source: (i64, i64),
    pub target: (i64, i64),
    pub distance_m: f64,
    /// Measured `t_target_source`: x, y, z, qx, qy, qz, qw.
    pub t_target_source: [f64; 7],
    pub converged: bool,
    pub iterations: i64,
    pub inliers: i64,
    pub fitness: f64,
    pub inlier_ratio: f64,
    pub rho_scan: Option<f64>,
    pub rho_corr: Option<f64>,
    pub accepted: bool,
    pub reason: String,
    /// World positions of the two keyframes; `None` if one has no pose.
    pub ends_m: Option<[[f64; 3]; 2]>,
}

/// What the session tables are written from.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TrajectoryExport {
    /// The graph version positions are on; `None`: nothing optimised yet.
    pub graph_version: Option<i64>,
    pub sessions: Vec<SessionExport>,
    /// Every loop candidate, by session, each session's spatially sorted.
    pub loops: Vec<LoopEdge>,
}

impl TrajectoryExport {
    /// The loop edges a session's ingest evaluated.
    pub fn loops_of(&self, session: SessionId) -> &[LoopEdge] {
        let lo = self.loops.partition_point(|l| l.session_id < session.0);
        let hi = self.loops.partition_point(|l| l.session_id <= session.0);
        &self.loops[lo..hi]
    }
}

/// Reads, in one read transaction, the map tables if `map` and the session
/// tables if `trajectory`, so that every table of one export is the same
/// snapshot even while an ingest commits.
pub fn read_export(
    store: &Store,
    map: bool,
    trajectory: bool,
) -> Result<(Option<MapExport>, Option<TrajectoryExport>), StoreError> {
    let tx = store.conn().unchecked_transaction().map_err(|e| sql(store.root(), e))?;
    let m = if map { Some(read_map_export_in(store, &tx)?) } else { None };
    let t = if trajectory { Some(read_trajectory_in(&tx)?) } else { None };
    Ok((m, t))
}

fn has_table(conn: &Connection, name: &str) -> Result<bool, StoreError> {
    conn.query_row("SELECT count(*) FROM sqlite_master WHERE name = ?1", [name], |r| r.get::<_, i64>(0))
        .map(|n| n > 0)
        .map_err(e(conn))
}

/// The session tables inside the caller's transaction. Tables of later
/// migrations that a read-only store lacks read as empty.
pub fn read_trajectory_in(conn: &Connection) -> Result<TrajectoryExport, StoreError> {
    let graph_version = latest_graph_version(conn)?;
    let has_alignment = has_table(conn, "session_alignment")?;
    let has_loops = has_table(conn, "loop_candidates")?;
    let mut out = TrajectoryExport { graph_version, ..TrajectoryExport::default() };
    let mut position: HashMap<i64, [f64; 3]> = HashMap::new();
    for row in sessions(conn)? {
        let keyframes = match graph_version {
            Some(v) => keyframe_poses(conn, v, row.session_id)?,
            None => Vec::new(),
        };
        position.extend(keyframes.iter().map(|k| (k.keyframe_id, k.xyz_m)));
        let alignment = if has_alignment { alignment(conn, row.session_id)? } else { None };
        let (loops_tried, loops_accepted) = if has_loops {
            conn.query_row(
                "SELECT count(*), coalesce(sum(accepted), 0) FROM loop_candidates WHERE session_id = ?1",
                [row.session_id.0],
                |r| Ok((r.get(0)?, r.get(1)?)),
            )
            .map_err(e(conn))?
        } else {
            (0, 0)
        };
        out.sessions.push(SessionExport { row, alignment, keyframes, loops_tried, loops_accepted });
    }
    if has_loops {
        out.loops = loop_edges(conn, &position)?;
    }
    Ok(out)
}

fn keyframe_poses(conn: &Connection, version: i64, session: SessionId) -> Result<Vec<KeyframePose>, StoreError> {
    let mut st = conn
        .prepare(
            "SELECT k.keyframe_id, k.keyframe_index, s.submap_index, k.source_file, k.stamp_s, k.point_count,
                    a.x_m, a.y_m, a.z_m, a.qx, a.qy, a.qz, a.qw,
                    l.x_m, l.y_m, l.z_m, l.qx, l.qy, l.qz, l.qw
             FROM keyframes k
             JOIN local_poses l ON l.keyframe_id = k.keyframe_id AND l.graph_version = ?1
             JOIN anchor_poses a ON a.submap_id = k.submap_id AND a.graph_version = ?1
             LEFT JOIN submaps s ON s.submap_id = k.submap_id
             WHERE k.session_id = ?2 ORDER BY k.keyframe_index",
        )
        .map_err(e(conn))?;
    let rows = st
        .query_map(rusqlite::params![version, session.0], |r| {
            let pose = pose_at(r, 6)? * pose_at(r, 13)?;
            let t = pose.translation.vector;
            Ok(KeyframePose {
                keyframe_id: r.get(0)?,
                keyframe_index: r.get(1)?,
                submap_index: r.get(2)?,
                source_file: r.get(3)?,
                stamp_s: r.get(4)?,
                point_count: r.get(5)?,
                xyz_m: [t.x, t.y, t.z],
                quat: pose_to_tum_quat(&pose),
            })
        })
        .map_err(e(conn))?;
    rows.collect::<Result<_, _>>().map_err(e(conn))
}

fn loop_edges(conn: &Connection, position: &HashMap<i64, [f64; 3]>) -> Result<Vec<LoopEdge>, StoreError> {
    let mut st = conn
        .prepare(
            "SELECT c.candidate_id, c.session_id, c.kind, ks.session_id, ks.keyframe_index,
                    kt.session_id, kt.keyframe_index, c.distance_m,
                    c.x_m, c.y_m, c.z_m, c.qx, c.qy, c.qz, c.qw,
                    c.converged, c.iterations, c.inliers, c.fitness, c.inlier_ratio, c.rho_scan, c.rho_corr,
                    c.accepted, c.reason, c.source_keyframe, c.target_keyframe
             FROM loop_candidates c
             JOIN keyframes ks ON ks.keyframe_id = c.source_keyframe
             JOIN keyframes kt ON kt.keyframe_id = c.target_keyframe
             ORDER BY c.candidate_id",
        )
        .map_err(e(conn))?;
    let rows = st
        .query_map([], |r| {
            let mut t = [0.0; 7];
            for (k, v) in t.iter_mut().enumerate() {
                *v = r.get(8 + k)?;
            }
            let ends = (position.get(&r.get::<_, i64>(24)?), position.get(&r.get::<_, i64>(25)?));
            Ok(LoopEdge {
                candidate_id: r.get(0)?,
                session_id: r.get(1)?,
                kind: r.get(2)?,
                source: (r.get(3)?, r.get(4)?),
                target: (r.get(5)?, r.get(6)?),
                distance_m: r.get(7)?,
                t_target_source: t,
                converged: r.get(15)?,
                iterations: r.get(16)?,
                inliers: r.get(17)?,
                fitness: r.get(18)?,
                inlier_ratio: r.get(19)?,
                rho_scan: r.get(20)?,
                rho_corr: r.get(21)?,
                accepted: r.get(22)?,
                reason: r.get(23)?,
                ends_m: match ends {
                    (Some(a), Some(b)) => Some([*a, *b]),
                    _ => None,
                },
            })
        })
        .map_err(e(conn))?;
    let mut loops: Vec<LoopEdge> = rows.collect::<Result<_, _>>().map_err(e(conn))?;
    // Edges without a position sort last in their session.
    loops.sort_by_key(|l| {
        let code =
            l.ends_m.map_or(u64::MAX, |[a, b]| z_order(std::array::from_fn(|i| ((a[i] + b[i]) / 2.0).floor() as i32)));
        (l.session_id, code, l.candidate_id)
    });
    Ok(loops)
}

// ---------------------------------------------------------------------------
// Schemas and batches

fn field(name: &str, t: DataType, nullable: bool, description: &str) -> Field {
    Field::new(name, t, nullable).with_metadata(HashMap::from([("description".to_string(), description.to_string())]))
}

fn utc() -> DataType {
    DataType::Timestamp(TimeUnit::Microsecond, Some("UTC".into()))
}

/// Columns of the `sessions` export.
pub fn sessions_schema() -> SchemaRef {
    let s = DataType::Utf8;
    let mut f = vec![
        field(
            "session_id",
            DataType::Int64,
            false,
            "1, 2, ... in ingest order; the session partition key of other tables",
        ),
        field("name", s.clone(), false, "session name (session.toml or the folder name)"),
        field("date", s.clone(), true, "survey date as given in session.toml"),
        field("sensor_model", s.clone(), true, "LiDAR model from session.toml"),
        field("layout", s.clone(), false, "folder layout it was read from: kitti, scans-pcd, dynamic-map-benchmark"),
        field("source_dir", s.clone(), false, "the session folder at ingest"),
        field("keyframe_count", DataType::Int64, false, "keyframes (scans) of the session"),
        field("point_count", DataType::Int64, false, "points of all its scans"),
        field("status", s.clone(), false, "ingesting or complete"),
        field("created_at", utc(), true, "when its ingest started, UTC"),
        field("completed_at", utc(), true, "when its ingest completed, UTC; null while ingesting"),
        field("alignment_method", s.clone(), true, "reference, global, initial_guess or unaligned"),
        field(
            "alignment_success",
            DataType::Boolean,
            true,
            "whether the coarse alignment placed it in the world frame",
        ),
        field("alignment_reason", s.clone(), true, "why the alignment failed, or how it was placed"),
        field("alignment_inlier_ratio", DataType::Float64, true, "inlier ratio of the global registration"),
        field("alignment_overlap_fraction", DataType::Float64, true, "overlap with the earlier sessions' map"),
        field("loops_tried", DataType::Int64, false, "loop candidates its ingest evaluated (loop_edges rows)"),
        field("loops_accepted", DataType::Int64, false, "of those, accepted by the DOP test"),
        field("graph_version", DataType::Int64, true, "graph version of the trajectory; null: no poses yet"),
        field("path_length_m", DataType::Float64, false, "length of the optimised trajectory, metres"),
    ];
    f.extend(geometry_fields(true, "the optimised trajectory as a LineString Z"));
    Arc::new(Schema::new(f))
}

/// Columns of a `keyframes` export file (the session is its partition).
pub fn keyframes_schema() -> SchemaRef {
    let q = |a: &str| field(&format!("q{a}"), DataType::Float64, false, "t_world_keyframe rotation quaternion");
    let mut f = vec![
        field("keyframe_id", DataType::Int64, false, "store-wide keyframe id"),
        field("keyframe_index", DataType::Int32, false, "index of the scan in its session (owner_keyframe elsewhere)"),
        field("submap_index", DataType::Int32, true, "submap of the session the keyframe belongs to"),
        field("source_file", DataType::Utf8, false, "scan file in the session folder"),
        field("stamp_s", DataType::Float64, true, "sensor time stamp as given (times.txt, PCD), seconds"),
        field("point_count", DataType::Int64, false, "points of its scan"),
    ];
    f.extend(["x", "y", "z"].map(|a| {
        field(&format!("{a}_m"), DataType::Float64, false, "t_world_keyframe translation, world frame, metres")
    }));
    f.extend(["x", "y", "z", "w"].map(q));
    f.extend(geometry_fields(false, "the keyframe position as a Point Z"));
    Arc::new(Schema::new(f))
}

/// Columns of a `loop_edges` export file (the evaluating session is its partition).
pub fn loop_edges_schema() -> SchemaRef {
    let t = |a: &str, unit: &str| {
        field(&format!("t_target_source_{a}{unit}"), DataType::Float64, false, "measured t_target_source (GICP)")
    };
    let mut f = vec![
        field("candidate_id", DataType::Int64, false, "loop candidate id, increasing with evaluation order"),
        field("kind", DataType::Utf8, false, "intra (within a session) or inter (to an earlier session)"),
        field("source_session", DataType::Int64, false, "session of the source keyframe"),
        field("source_keyframe", DataType::Int32, false, "keyframe_index of the source keyframe"),
        field("target_session", DataType::Int64, false, "session of the target keyframe"),
        field("target_keyframe", DataType::Int32, false, "keyframe_index of the target keyframe"),
        field("accepted", DataType::Boolean, false, "accepted into the pose graph"),
        field("reason", DataType::Utf8, false, "why it was accepted or rejected"),
        field("rho_scan", DataType::Float64, true, "DOP reliability of the scan geometry; null: infinite (degenerate)"),
        field("rho_corr", DataType::Float64, true, "DOP reliability of the correspondences; null: infinite"),
        field("converged", DataType::Boolean, false, "GICP converged"),
        field("iterations", DataType::Int32, false, "GICP iterations"),
        field("inliers", DataType::Int64, false, "GICP inlier correspondences"),
        field("fitness", DataType::Float64, false, "GICP fitness (mean squared inlier distance)"),
        field("inlier_ratio", DataType::Float64, false, "GICP inliers over source points"),
        field(
            "distance_m",
            DataType::Float64,
            false,
            "distance between the keyframes in the estimate before GICP, metres",
        ),
        field(
            "length_m",
            DataType::Float64,
            true,
            "distance between the keyframes on the exported graph version, metres",
        ),
    ];
    f.extend(["x", "y", "z"].map(|a| t(a, "_m")));
    f.extend(["qx", "qy", "qz", "qw"].map(|a| t(a, "")));
    f.extend(geometry_fields(true, "source keyframe to target keyframe as a LineString Z"));
    Arc::new(Schema::new(f))
}

fn batch(path: &Path, schema: SchemaRef, cols: Vec<ArrayRef>) -> Result<RecordBatch, StoreError> {
    RecordBatch::try_new(schema, cols)
        .map_err(|e| StoreError::Parquet { path: path.to_path_buf(), message: e.to_string() })
}

fn f64s(v: impl Iterator<Item = f64>) -> ArrayRef {
    Arc::new(Float64Array::from_iter_values(v))
}

fn opt_f64s(v: impl Iterator<Item = Option<f64>>) -> ArrayRef {
    Arc::new(Float64Array::from_iter(v))
}

fn i64s(v: impl Iterator<Item = i64>) -> ArrayRef {
    Arc::new(Int64Array::from_iter_values(v))
}

fn strs<'a>(v: impl Iterator<Item = Option<&'a str>>) -> ArrayRef {
    Arc::new(StringArray::from_iter(v))
}

fn bools(v: impl Iterator<Item = Option<bool>>) -> ArrayRef {
    Arc::new(BooleanArray::from_iter(v))
}

/// An int32 column of indices that must fit, naming the first that does not.
fn i32s(path: &Path, name: &str, v: impl Iterator<Item = Option<i64>>) -> Result<ArrayRef, StoreError> {
    let mut out = Vec::new();
    for (row, x) in v.enumerate() {
        out.push(
            x.map(|x| {
                i32::try_from(x).map_err(|_| StoreError::Parquet {
                    path: path.to_path_buf(),
                    message: format!("column {name}: value {x} in row {row} does not fit int32"),
                })
            })
            .transpose()?,
        );
    }
    Ok(Arc::new(Int32Array::from(out)))
}

fn timestamps<'a>(v: impl Iterator<Item = Option<&'a str>>) -> ArrayRef {
    Arc::new(TimestampMicrosecondArray::from_iter(v.map(|s| s.and_then(parse_utc_micros))).with_timezone("UTC"))
}

fn path_length(k: &[KeyframePose]) -> f64 {
    k.windows(2).map(|w| (0..3).map(|i| (w[1].xyz_m[i] - w[0].xyz_m[i]).powi(2)).sum::<f64>().sqrt()).sum()
}

/// The `sessions` rows, by id, and the summary of their trajectories.
pub fn sessions_batch(path: &Path, t: &TrajectoryExport) -> Result<(RecordBatch, GeoSummary), StoreError> {
    let s = &t.sessions;
    let paths: Vec<Vec<[f64; 3]>> = s.iter().map(|s| s.keyframes.iter().map(|k| k.xyz_m).collect()).collect();
    let geo = geo_columns(
        &[GeometryType::LineStringZ],
        paths.iter().map(|p| (!p.is_empty()).then_some(Geometry::LineStringZ(p))),
    );
    let al = |f: &dyn Fn(&AlignmentRow) -> Option<f64>| opt_f64s(s.iter().map(|x| x.alignment.as_ref().and_then(f)));
    let cols = vec![
        i64s(s.iter().map(|x| x.row.session_id.0)),
        strs(s.iter().map(|x| Some(x.row.name.as_str()))),
        strs(s.iter().map(|x| x.row.date.as_deref())),
        strs(s.iter().map(|x| x.row.sensor_model.as_deref())),
        strs(s.iter().map(|x| Some(x.row.layout.as_str()))),
        strs(s.iter().map(|x| Some(x.row.source_dir.as_str()))),
        i64s(s.iter().map(|x| x.row.keyframe_count)),
        i64s(s.iter().map(|x| x.row.point_count)),
        strs(s.iter().map(|x| Some(x.row.status.as_str()))),
        timestamps(s.iter().map(|x| Some(x.row.created_at.as_str()))),
        timestamps(s.iter().map(|x| x.row.completed_at.as_deref())),
        strs(s.iter().map(|x| x.alignment.as_ref().map(|a| a.method.as_str()))),
        bools(s.iter().map(|x| x.alignment.as_ref().map(|a| a.success))),
        strs(s.iter().map(|x| x.alignment.as_ref().map(|a| a.reason.as_str()))),
        al(&|a| Some(a.inlier_ratio)),
        al(&|a| Some(a.overlap_fraction)),
        i64s(s.iter().map(|x| x.loops_tried)),
        i64s(s.iter().map(|x| x.loops_accepted)),
        Arc::new(Int64Array::from_iter(
            s.iter().map(|x| (!x.keyframes.is_empty()).then_some(t.graph_version).flatten()),
        )),
        f64s(s.iter().map(|x| path_length(&x.keyframes))),
        geo.geometry,
        geo.bbox,
    ];
    Ok((batch(path, sessions_schema(), cols)?, geo.summary))
}

/// The `keyframes` rows of one session, in trajectory order.
pub fn keyframes_batch(path: &Path, k: &[KeyframePose]) -> Result<(RecordBatch, GeoSummary), StoreError> {
    let geo = geo_columns(&[GeometryType::PointZ], k.iter().map(|k| Some(Geometry::PointZ(k.xyz_m))));
    let mut cols = vec![
        i64s(k.iter().map(|k| k.keyframe_id)),
        i32s(path, "keyframe_index", k.iter().map(|k| Some(k.keyframe_index)))?,
        i32s(path, "submap_index", k.iter().map(|k| k.submap_index))?,
        strs(k.iter().map(|k| Some(k.source_file.as_str()))),
        opt_f64s(k.iter().map(|k| k.stamp_s)),
        i64s(k.iter().map(|k| k.point_count)),
    ];
    cols.extend((0..3).map(|i| f64s(k.iter().map(|k| k.xyz_m[i]))));
    cols.extend((0..4).map(|i| f64s(k.iter().map(|k| k.quat[i]))));
    cols.extend([geo.geometry, geo.bbox]);
    Ok((batch(path, keyframes_schema(), cols)?, geo.summary))
}

/// The `loop_edges` rows of one session, in the given order.
pub fn loop_edges_batch(path: &Path, l: &[LoopEdge]) -> Result<(RecordBatch, GeoSummary), StoreError> {
    let ends: Vec<Option<[[f64; 3]; 2]>> = l.iter().map(|l| l.ends_m).collect();
    let geo =
        geo_columns(&[GeometryType::LineStringZ], ends.iter().map(|e| e.as_ref().map(|e| Geometry::LineStringZ(e))));
    let mut cols = vec![
        i64s(l.iter().map(|l| l.candidate_id)),
        strs(l.iter().map(|l| Some(l.kind.as_str()))),
        i64s(l.iter().map(|l| l.source.0)),
        i32s(path, "source_keyframe", l.iter().map(|l| Some(l.source.1)))?,
        i64s(l.iter().map(|l| l.target.0)),
        i32s(path, "target_keyframe", l.iter().map(|l| Some(l.target.1)))?,
        bools(l.iter().map(|l| Some(l.accepted))),
        strs(l.iter().map(|l| Some(l.reason.as_str()))),
        opt_f64s(l.iter().map(|l| l.rho_scan)),
        opt_f64s(l.iter().map(|l| l.rho_corr)),
        bools(l.iter().map(|l| Some(l.converged))),
        i32s(path, "iterations", l.iter().map(|l| Some(l.iterations)))?,
        i64s(l.iter().map(|l| l.inliers)),
        f64s(l.iter().map(|l| l.fitness)),
        f64s(l.iter().map(|l| l.inlier_ratio)),
        f64s(l.iter().map(|l| l.distance_m)),
        opt_f64s(l.iter().map(|l| l.ends_m.map(|[a, b]| (0..3).map(|i| (a[i] - b[i]).powi(2)).sum::<f64>().sqrt()))),
    ];
    cols.extend((0..7).map(|i| f64s(l.iter().map(|l| l.t_target_source[i]))));
    cols.extend([geo.geometry, geo.bbox]);
    Ok((batch(path, loop_edges_schema(), cols)?, geo.summary))
}

/// Writes the `sessions` table file at `path` as GeoParquet in `crs`.
pub fn export_sessions(path: &Path, t: &TrajectoryExport, crs: &Crs) -> Result<(WrittenFile, GeoSummary), StoreError> {
    let (b, geo) = sessions_batch(path, t)?;
    Ok((write_geoparquet(path, &b, &geo, crs)?, geo))
}

/// Writes one session's `keyframes` file at `path` as GeoParquet in `crs`.
pub fn export_keyframes(path: &Path, k: &[KeyframePose], crs: &Crs) -> Result<(WrittenFile, GeoSummary), StoreError> {
    let (b, geo) = keyframes_batch(path, k)?;
    Ok((write_geoparquet(path, &b, &geo, crs)?, geo))
}

/// Writes one session's `loop_edges` file at `path` as GeoParquet in `crs`.
pub fn export_loop_edges(path: &Path, l: &[LoopEdge], crs: &Crs) -> Result<(WrittenFile, GeoSummary), StoreError> {
    let (b, geo) = loop_edges_batch(path, l)?;
    Ok((write_geoparquet(path, &b, &geo, crs)?, geo))
}

#[cfg(test)]
mod tests {
    use super::*;
    use arrow_array::Array;

    #[test]
    fn session_with_one_keyframe_has_a_two_vertex_path_and_none_has_null() {
        let k = KeyframePose {
            keyframe_id: 7,
            keyframe_index: 0,
            submap_index: Some(0),
            source_file: "000000.bin".into(),
            stamp_s: None,
            point_count: 10,
            xyz_m: [1.0, 2.0, 3.0],
            quat: [0.0, 0.0, 0.0, 1.0],
        };
        let row = |id: i64| SessionRow {
            session_id: SessionId(id),
            name: format!("s{id}"),
            content_hash: "h".into(),
            source_dir: "/x".into(),
            layout: "kitti".into(),
            date: None,
            sensor_model: None,
            fov_json: None,
            keyframe_count: 1,
            point_count: 10,
            status: "complete".into(),
            created_at: "2026-11-23T19:25:25Z".into(),
            completed_at: None,
        };
        let s = |id: i64, keyframes: Vec<KeyframePose>| SessionExport {
            row: row(id),
            alignment: None,
            keyframes,
            loops_tried: 0,
            loops_accepted: 0,
        };
        let t = TrajectoryExport { graph_version: Some(3), sessions: vec![s(1, vec![k]), s(2, vec![])], loops: vec![] };
        let (b, geo) = sessions_batch(Path::new("x"), &t).unwrap();
        assert_eq!(geo.bbox, Some([1.0, 2.0, 3.0, 1.0, 2.0, 3.0]));
        let g = b.column_by_name("geometry").unwrap();
        assert_eq!(g.null_count(), 1);
        let wkb = g.as_any().downcast_ref::<arrow_array::BinaryArray>().unwrap().value(0);
        assert_eq!(wkb.len(), 9 + 2 * 24, "one keyframe: its vertex twice");
        let created = b.column_by_name("created_at").unwrap();
        let created = created.as_any().downcast_ref::<TimestampMicrosecondArray>().unwrap();
        assert_eq!(created.value(0), 1_795_461_925_000_000);
        assert_eq!(created.timezone(), Some("UTC"));
        let gv = b.column_by_name("graph_version").unwrap().as_any().downcast_ref::<Int64Array>().unwrap();
        assert_eq!((gv.value(0), gv.is_null(1)), (3, true));
    }
}
