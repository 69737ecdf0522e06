//! Typed rows of the store's tables and the statements that read and write
//! them. Functions take a `&Connection`; a `Transaction` derefs to one, so the
//! pipeline decides the transaction boundaries.

use super::{StoreError, now_utc};
use crate::geometry::Pose;
use nalgebra::{Quaternion, Translation3, UnitQuaternion};
use rusqlite::{Connection, OptionalExtension, Row, params};

/// Turns a rusqlite error into a store error naming the database.
pub(super) fn e(conn: &Connection) -> impl Fn(rusqlite::Error) -> StoreError + '_ {
    move |source| StoreError::Sql { path: conn.path().unwrap_or("seam.db").into(), source }
}

/// A session's id: its 1-based position in ingest order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize)]
pub struct SessionId(pub i64);
/// A keyframe's store-wide id.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize)]
pub struct KeyframeId(pub i64);
/// A submap's store-wide id.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize)]
pub struct SubmapId(pub i64);

#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct SessionRow {
    pub session_id: SessionId,
    pub name: String,
    pub content_hash: String,
    pub source_dir: String,
    pub layout: String,
    pub date: Option<String>,
    pub sensor_model: Option<String>,
    pub fov_json: Option<String>,
    pub keyframe_count: i64,
    pub point_count: i64,
    pub status: String,
    pub created_at: String,
    pub completed_at: Option<String>,
}

/// The session named `arg`, or else the one numbered `arg` (`3` or `s3`): how
/// every command's `--session` names a session.
pub fn find_session(sessions: &[SessionRow], arg: &str) -> Option<SessionId> {
    let by_name = sessions.iter().find(|s| s.name == arg);
    let by_number = || {
        let n = arg.trim_start_matches(['s', 'S']).parse::<i64>().ok()?;
        sessions.iter().find(|s| s.session_id.0 == n)
    };
    by_name.or_else(by_number).map(|s| s.session_id)
}

/// `1 (s1), 2 (north walk)`, or `empty` when there are none: the sessions an
/// error lists when `--session` names none of them.
pub fn session_list(sessions: &[SessionRow], empty: &str) -> String {
    if sessions.is_empty() {
        return empty.to_string();
    }
    sessions.iter().map(|s| format!("{} ({})", s.session_id.0, s.name)).collect::<Vec<_>>().join(", ")
}

const SESSION_COLS: &str = "session_id, name, content_hash, source_dir, layout, date, sensor_model, fov_json, \
     keyframe_count, point_count, status, created_at, completed_at";

fn session_from(r: &Row<'_>) -> rusqlite::Result<SessionRow> {
    Ok(SessionRow {
        session_id: SessionId(r.get(0)?),
        name: r.get(1)?,
        content_hash: r.get(2)?,
        source_dir: r.get(3)?,
        layout: r.get(4)?,
        date: r.get(5)?,
        sensor_model: r.get(6)?,
        fov_json: r.get(7)?,
        keyframe_count: r.get(8)?,
        point_count: r.get(9)?,
        status: r.get(10)?,
        created_at: r.get(11)?,
        completed_at: r.get(12)?,
    })
}

/// What the pipeline knows of a session before it is stored.
#[derive(Debug, Clone)]
pub struct NewSession<'a> {
    pub name: &'a str,
    pub content_hash: &'a str,
    pub source_dir: &'a str,
    pub layout: &'a str,
    pub date: Option<&'a str>,
    pub sensor_model: Option<&'a str>,
    pub fov_json: Option<&'a str>,
    pub keyframe_count: i64,
    pub point_count: i64,
}

pub fn insert_session(conn: &Connection, s: &NewSession<'_>) -> Result<SessionId, StoreError> {
    conn.execute(
        "INSERT INTO sessions(name, content_hash, source_dir, layout, date, sensor_model, fov_json,
                              keyframe_count, point_count, status, created_at)
         VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, 'ingesting', ?10)",
        params![
            s.name,
            s.content_hash,
            s.source_dir,
            s.layout,
            s.date,
            s.sensor_model,
            s.fov_json,
            s.keyframe_count,
            s.point_count,
            now_utc()
        ],
    )
    .map_err(e(conn))?;
    Ok(SessionId(conn.last_insert_rowid()))
}

pub fn sessions(conn: &Connection) -> Result<Vec<SessionRow>, StoreError> {
    let mut st = conn.prepare(&format!("SELECT {SESSION_COLS} FROM sessions ORDER BY session_id")).map_err(e(conn))?;
    let rows = st.query_map([], session_from).map_err(e(conn))?;
    rows.collect::<Result<_, _>>().map_err(e(conn))
}

pub fn session_by_hash(conn: &Connection, hash: &str) -> Result<Option<SessionRow>, StoreError> {
    conn.query_row(&format!("SELECT {SESSION_COLS} FROM sessions WHERE content_hash = ?1"), [hash], session_from)
        .optional()
        .map_err(e(conn))
}

pub fn session_name_taken(conn: &Connection, name: &str) -> Result<bool, StoreError> {
    conn.query_row("SELECT count(*) FROM sessions WHERE name = ?1", [name], |r| r.get::<_, i64>(0))
        .map(|n| n > 0)
        .map_err(e(conn))
}

pub fn next_session_id(conn: &Connection) -> Result<i64, StoreError> {
    conn.query_row("SELECT coalesce(max(session_id), 0) + 1 FROM sessions", [], |r| r.get(0)).map_err(e(conn))
}

pub fn set_session_complete(conn: &Connection, id: SessionId) -> Result<(), StoreError> {
    conn.execute(
        "UPDATE sessions SET status = 'complete', completed_at = ?2 WHERE session_id = ?1",
        params![id.0, now_utc()],
    )
    .map_err(e(conn))?;
    Ok(())
}

/// A keyframe row.
#[derive(Debug, Clone, PartialEq)]
pub struct KeyframeRow {
    pub keyframe_id: KeyframeId,
    pub session_id: SessionId,
    pub keyframe_index: i64,
    pub source_file: String,
    pub stamp_s: Option<f64>,
    pub point_count: i64,
    pub scan_file_id: i64,
    pub scan_row_group: i64,
    /// Odometry pose of the sensor in the session's own frame.
    pub t_session_keyframe: Pose,
    pub submap_id: Option<SubmapId>,
}

/// A keyframe before insertion.
#[derive(Debug, Clone)]
pub struct NewKeyframe {
    pub keyframe_index: i64,
    pub source_file: String,
    pub stamp_s: Option<f64>,
    pub point_count: i64,
    pub scan_row_group: i64,
    pub t_session_keyframe: Pose,
}

/// The 7 numbers `x, y, z, qx, qy, qz, qw` of a pose.
pub fn pose_cols(p: &Pose) -> [f64; 7] {
    let t = p.translation.vector;
    let q = p.rotation.quaternion();
    [t.x, t.y, t.z, q.i, q.j, q.k, q.w]
}

/// The pose from 7 numbers `x, y, z, qx, qy, qz, qw`.
pub fn pose_from_cols(c: [f64; 7]) -> Pose {
    Pose::from_parts(
        Translation3::new(c[0], c[1], c[2]),
        UnitQuaternion::from_quaternion(Quaternion::new(c[6], c[3], c[4], c[5])),
    )
}

pub(super) fn pose_at(r: &Row<'_>, first: usize) -> rusqlite::Result<Pose> {
    let mut c = [0.0; 7];
    for (k, v) in c.iter_mut().enumerate() {
        *v = r.get(first + k)?;
    }
    Ok(pose_from_cols(c))
}

pub fn insert_keyframes(
    conn: &Connection,
    session: SessionId,
    scan_file_id: i64,
    kfs: &[NewKeyframe],
) -> Result<(), StoreError> {
    let mut st = conn
        .prepare(
            "INSERT INTO keyframes(session_id, keyframe_index, source_file, stamp_s, point_count, scan_file_id,
                 scan_row_group, odom_x_m, odom_y_m, odom_z_m, odom_qx, odom_qy, odom_qz, odom_qw)
             VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11, ?12, ?13, ?14)",
        )
        .map_err(e(conn))?;
    for k in kfs {
        let c = pose_cols(&k.t_session_keyframe);
        st.execute(params![
            session.0,
            k.keyframe_index,
            k.source_file,
            k.stamp_s,
            k.point_count,
            scan_file_id,
            k.scan_row_group,
            c[0],
            c[1],
            c[2],
            c[3],
            c[4],
            c[5],
            c[6]
        ])
        .map_err(e(conn))?;
    }
    Ok(())
}

pub fn keyframes(conn: &Connection, session: SessionId) -> Result<Vec<KeyframeRow>, StoreError> {
    let mut st = conn
        .prepare(
            "SELECT keyframe_id, session_id, keyframe_index, source_file, stamp_s, point_count, scan_file_id,
                    scan_row_group, odom_x_m, odom_y_m, odom_z_m, odom_qx, odom_qy, odom_qz, odom_qw, submap_id
             FROM keyframes WHERE session_id = ?1 ORDER BY keyframe_index",
        )
        .map_err(e(conn))?;
    let rows = st
        .query_map([session.0], |r| {
            Ok(KeyframeRow {
                keyframe_id: KeyframeId(r.get(0)?),
                session_id: SessionId(r.get(1)?),
                keyframe_index: r.get(2)?,
                source_file: r.get(3)?,
                stamp_s: r.get(4)?,
                point_count: r.get(5)?,
                scan_file_id: r.get(6)?,
                scan_row_group: r.get(7)?,
                t_session_keyframe: pose_at(r, 8)?,
                submap_id: r.get::<_, Option<i64>>(15)?.map(SubmapId),
            })
        })
        .map_err(e(conn))?;
    rows.collect::<Result<_, _>>().map_err(e(conn))
}

/// A submap: keyframes `first_keyframe..=last_keyframe` of a session.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct SubmapRow {
    pub submap_id: SubmapId,
    pub session_id: SessionId,
    pub submap_index: i64,
    pub first_keyframe: i64,
    pub last_keyframe: i64,
    pub length_m: f64,
}

/// Inserts the submaps of a session and points its keyframes at them.
/// `spans` are `(first_keyframe, last_keyframe, length_m)` in order.
pub fn insert_submaps(
    conn: &Connection,
    session: SessionId,
    spans: &[(i64, i64, f64)],
) -> Result<Vec<SubmapId>, StoreError> {
    let mut ids = Vec::with_capacity(spans.len());
    for (i, (first, last, len)) in spans.iter().enumerate() {
        conn.execute(
            "INSERT INTO submaps(session_id, submap_index, first_keyframe, last_keyframe, length_m)
             VALUES (?1, ?2, ?3, ?4, ?5)",
            params![session.0, i as i64, first, last, len],
        )
        .map_err(e(conn))?;
        let id = conn.last_insert_rowid();
        conn.execute(
            "UPDATE keyframes SET submap_id = ?1 WHERE session_id = ?2 AND keyframe_index BETWEEN ?3 AND ?4",
            params![id, session.0, first, last],
        )
        .map_err(e(conn))?;
        ids.push(SubmapId(id));
    }
    Ok(ids)
}

pub fn submaps(conn: &Connection, session: SessionId) -> Result<Vec<SubmapRow>, StoreError> {
    let mut st = conn
        .prepare(
            "SELECT submap_id, session_id, submap_index, first_keyframe, last_keyframe, length_m
             FROM submaps WHERE session_id = ?1 ORDER BY submap_index",
        )
        .map_err(e(conn))?;
    let rows = st
        .query_map([session.0], |r| {
            Ok(SubmapRow {
                submap_id: SubmapId(r.get(0)?),
                session_id: SessionId(r.get(1)?),
                submap_index: r.get(2)?,
                first_keyframe: r.get(3)?,
                last_keyframe: r.get(4)?,
                length_m: r.get(5)?,
            })
        })
        .map_err(e(conn))?;
    rows.collect::<Result<_, _>>().map_err(e(conn))
}

/// Records a new graph version: every anchor and local pose of `base` (if
/// given) that `anchors` / `locals` do not replace, plus those.
pub fn insert_graph_version(
    conn: &Connection,
    session: SessionId,
    mode: &str,
    details_json: &str,
    base: Option<i64>,
    anchors: &[(SubmapId, Pose)],
    locals: &[(KeyframeId, Pose)],
) -> Result<i64, StoreError> {
    conn.execute(
        "INSERT INTO graph_versions(session_id, mode, created_at, details_json) VALUES (?1, ?2, ?3, ?4)",
        params![session.0, mode, now_utc(), details_json],
    )
    .map_err(e(conn))?;
    let version = conn.last_insert_rowid();
    if let Some(base) = base {
        conn.execute(
            "INSERT INTO anchor_poses SELECT ?1, submap_id, x_m, y_m, z_m, qx, qy, qz, qw
             FROM anchor_poses WHERE graph_version = ?2",
            params![version, base],
        )
        .map_err(e(conn))?;
        conn.execute(
            "INSERT INTO local_poses SELECT ?1, keyframe_id, x_m, y_m, z_m, qx, qy, qz, qw
             FROM local_poses WHERE graph_version = ?2",
            params![version, base],
        )
        .map_err(e(conn))?;
    }
    let mut a = conn
        .prepare("INSERT OR REPLACE INTO anchor_poses VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9)")
        .map_err(e(conn))?;
    for (id, p) in anchors {
        let c = pose_cols(p);
        a.execute(params![version, id.0, c[0], c[1], c[2], c[3], c[4], c[5], c[6]]).map_err(e(conn))?;
    }
    let mut l = conn
        .prepare("INSERT OR REPLACE INTO local_poses VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9)")
        .map_err(e(conn))?;
    for (id, p) in locals {
        let c = pose_cols(p);
        l.execute(params![version, id.0, c[0], c[1], c[2], c[3], c[4], c[5], c[6]]).map_err(e(conn))?;
    }
    Ok(version)
}

/// The newest graph version, if any.
pub fn latest_graph_version(conn: &Connection) -> Result<Option<i64>, StoreError> {
    conn.query_row("SELECT max(graph_version) FROM graph_versions", [], |r| r.get(0)).map_err(e(conn))
}

/// World poses `A_m · p_i` of every keyframe of a session in a graph version.
pub fn world_poses(conn: &Connection, graph_version: i64, session: SessionId) -> Result<Vec<(i64, Pose)>, StoreError> {
    let mut st = conn
        .prepare(
            "SELECT k.keyframe_index,
                    a.x_m, a.y_m, a.z_m, a.qx, a.qy, a.qz, a.qw,
                    l.x_m, l.y_m, l.z_m, l.qx, l.qy, l.qz, l.qw
             FROM keyframes k
             JOIN local_poses l ON l.keyframe_id = k.keyframe_id AND l.graph_version = ?1
             JOIN anchor_poses a ON a.submap_id = k.submap_id AND a.graph_version = ?1
             WHERE k.session_id = ?2 ORDER BY k.keyframe_index",
        )
        .map_err(e(conn))?;
    let rows = st
        .query_map(params![graph_version, session.0], |r| Ok((r.get::<_, i64>(0)?, pose_at(r, 1)? * pose_at(r, 8)?)))
        .map_err(e(conn))?;
    rows.collect::<Result<_, _>>().map_err(e(conn))
}

/// A committed step of a session's ingest.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct StepRow {
    pub step: String,
    pub seq: i64,
    pub started_at: String,
    pub finished_at: String,
    pub wall_s: f64,
    pub details_json: String,
}

pub fn steps(conn: &Connection, session: SessionId) -> Result<Vec<StepRow>, StoreError> {
    let mut st = conn
        .prepare(
            "SELECT step, seq, started_at, finished_at, wall_s, details_json FROM step_log
             WHERE session_id = ?1 ORDER BY seq",
        )
        .map_err(e(conn))?;
    let rows = st
        .query_map([session.0], |r| {
            Ok(StepRow {
                step: r.get(0)?,
                seq: r.get(1)?,
                started_at: r.get(2)?,
                finished_at: r.get(3)?,
                wall_s: r.get(4)?,
                details_json: r.get(5)?,
            })
        })
        .map_err(e(conn))?;
    rows.collect::<Result<_, _>>().map_err(e(conn))
}

pub fn log_step(
    conn: &Connection,
    session: SessionId,
    step: &str,
    seq: i64,
    started_at: &str,
    wall_s: f64,
    details_json: &str,
) -> Result<(), StoreError> {
    conn.execute(
        "INSERT INTO step_log(session_id, step, seq, started_at, finished_at, wall_s, details_json)
         VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7)",
        params![session.0, step, seq, started_at, now_utc(), wall_s, details_json],
    )
    .map_err(e(conn))?;
    Ok(())
}

/// Row counts of the main tables, for `seam info`.
pub fn table_counts(conn: &Connection) -> Result<Vec<(String, i64)>, StoreError> {
    let mut out = Vec::new();
    for t in ["sessions", "keyframes", "submaps", "graph_versions", "files", "step_log"] {
        let n: i64 = conn.query_row(&format!("SELECT count(*) FROM {t}"), [], |r| r.get(0)).map_err(e(conn))?;
        out.push((t.to_string(), n));
    }
    Ok(out)
}
