//! Rows that record the evidence stage's files and per-session DOR summary.

use super::rows::e;
use super::{SessionId, StoreError, SubmapId};
use crate::evidence::session::GenerationStats;
use rusqlite::{Connection, params};

/// One evidence-stage file of a session.
#[derive(Debug, Clone, PartialEq)]
pub struct EvidenceFileRow {
    pub file_id: i64,
    pub session_id: SessionId,
    pub submap_id: Option<SubmapId>,
    pub kind: String,
    pub graph_version: i64,
    pub row_count: i64,
    pub rel_path: String,
}

pub fn insert_evidence_file(
    conn: &Connection,
    file_id: i64,
    session: SessionId,
    submap: Option<SubmapId>,
    kind: &str,
    graph_version: i64,
    row_count: usize,
) -> Result<(), StoreError> {
    conn.execute(
        "INSERT OR REPLACE INTO evidence_files(file_id, session_id, submap_id, kind, graph_version, row_count)
         VALUES (?1, ?2, ?3, ?4, ?5, ?6)",
        params![file_id, session.0, submap.map(|s| s.0), kind, graph_version, row_count as i64],
    )
    .map_err(e(conn))?;
    Ok(())
}

/// The files of `kind` of a session, by submap.
pub fn evidence_files(conn: &Connection, session: SessionId, kind: &str) -> Result<Vec<EvidenceFileRow>, StoreError> {
    let mut st = conn
        .prepare(
            "SELECT e.file_id, e.session_id, e.submap_id, e.kind, e.graph_version, e.row_count, f.rel_path
             FROM evidence_files e JOIN files f ON f.file_id = e.file_id
             WHERE e.session_id = ?1 AND e.kind = ?2 ORDER BY e.submap_id, e.file_id",
        )
        .map_err(e(conn))?;
    let rows = st
        .query_map(params![session.0, kind], |r| {
            Ok(EvidenceFileRow {
                file_id: r.get(0)?,
                session_id: SessionId(r.get(1)?),
                submap_id: r.get::<_, Option<i64>>(2)?.map(SubmapId),
                kind: r.get(3)?,
                graph_version: r.get(4)?,
                row_count: r.get(5)?,
                rel_path: r.get(6)?,
            })
        })
        .map_err(e(conn))?;
    rows.collect::<Result<_, _>>().map_err(e(conn))
}

/// The DOR summary of a session.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct SessionDorRow {
    pub session_id: i64,
    pub graph_version: i64,
    pub model: String,
    pub points: i64,
    pub dynamic_points: i64,
    pub interest_voxels: i64,
    pub generated_voxels: i64,
    pub dynamic_voxels: i64,
    pub cleaned_voxels: i64,
    pub raycast_s: f64,
    pub total_s: f64,
}

pub fn insert_session_dor(
    conn: &Connection,
    session: SessionId,
    graph_version: i64,
    model: &str,
    s: &GenerationStats,
) -> Result<(), StoreError> {
    conn.execute(
        "INSERT OR REPLACE INTO session_dor VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11)",
        params![
            session.0,
            graph_version,
            model,
            s.points as i64,
            s.dynamic_points as i64,
            s.interest_voxels as i64,
            s.generated_voxels as i64,
            s.dynamic_voxels as i64,
            s.cleaned_voxels as i64,
            s.raycast_s,
            s.total_s
        ],
    )
    .map_err(e(conn))?;
    Ok(())
}

pub fn session_dor(conn: &Connection, session: SessionId) -> Result<Option<SessionDorRow>, StoreError> {
    let mut st = conn.prepare("SELECT * FROM session_dor WHERE session_id = ?1").map_err(e(conn))?;
    let mut rows = st
        .query_map([session.0], |r| {
            Ok(SessionDorRow {
                session_id: r.get(0)?,
                graph_version: r.get(1)?,
                model: r.get(2)?,
                points: r.get(3)?,
                dynamic_points: r.get(4)?,
                interest_voxels: r.get(5)?,
                generated_voxels: r.get(6)?,
                dynamic_voxels: r.get(7)?,
                cleaned_voxels: r.get(8)?,
                raycast_s: r.get(9)?,
                total_s: r.get(10)?,
            })
        })
        .map_err(e(conn))?;
    rows.next().transpose().map_err(e(conn))
}
