//! Rows of the alignment steps: each session's coarse alignment and every
//! loop candidate with its verdict.

use super::StoreError;
use super::rows::{KeyframeId, SessionId, e, pose_at, pose_cols};
use crate::geometry::Pose;
use rusqlite::{Connection, OptionalExtension, params};

/// How a session's frame was placed in the world.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct AlignmentRow {
    pub session_id: SessionId,
    /// `reference` (the first session defines the world), `global`,
    /// `initial_guess`, or `unaligned`.
    pub method: String,
    pub success: bool,
    pub reason: String,
    #[serde(skip)]
    pub t_world_session: Pose,
    pub correspondences: i64,
    pub inliers: i64,
    pub inlier_ratio: f64,
    pub overlap_fraction: f64,
    pub elapsed_s: f64,
}

pub fn insert_alignment(conn: &Connection, a: &AlignmentRow) -> Result<(), StoreError> {
    let c = pose_cols(&a.t_world_session);
    conn.execute(
        "INSERT OR REPLACE INTO session_alignment(session_id, method, verdict, reason, x_m, y_m, z_m, qx, qy, qz, qw,
             correspondences, inliers, inlier_ratio, overlap_fraction, elapsed_s)
         VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11, ?12, ?13, ?14, ?15, ?16)",
        params![
            a.session_id.0,
            a.method,
            if a.success { "success" } else { "failure" },
            a.reason,
            c[0],
            c[1],
            c[2],
            c[3],
            c[4],
            c[5],
            c[6],
            a.correspondences,
            a.inliers,
            a.inlier_ratio,
            a.overlap_fraction,
            a.elapsed_s
        ],
    )
    .map_err(e(conn))?;
    Ok(())
}

pub fn alignment(conn: &Connection, session: SessionId) -> Result<Option<AlignmentRow>, StoreError> {
    conn.query_row(
        "SELECT session_id, method, verdict, reason, x_m, y_m, z_m, qx, qy, qz, qw,
                correspondences, inliers, inlier_ratio, overlap_fraction, elapsed_s
         FROM session_alignment WHERE session_id = ?1",
        [session.0],
        |r| {
            Ok(AlignmentRow {
                session_id: SessionId(r.get(0)?),
                method: r.get(1)?,
                success: r.get::<_, String>(2)? == "success",
                reason: r.get(3)?,
                t_world_session: pose_at(r, 4)?,
                correspondences: r.get(11)?,
                inliers: r.get(12)?,
                inlier_ratio: r.get(13)?,
                overlap_fraction: r.get(14)?,
                elapsed_s: r.get(15)?,
            })
        },
    )
    .optional()
    .map_err(e(conn))
}

/// One evaluated loop candidate.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct LoopRow {
    pub session_id: SessionId,
    /// `intra` (within a session) or `inter` (to an earlier session).
    pub kind: String,
    pub source_keyframe: KeyframeId,
    pub target_keyframe: KeyframeId,
    pub distance_m: f64,
    #[serde(skip)]
    pub t_target_source: Pose,
    pub converged: bool,
    pub iterations: i64,
    pub inliers: i64,
    pub fitness: f64,
    pub inlier_ratio: f64,
    /// `None` when infinite (degenerate geometry).
    pub rho_scan: Option<f64>,
    pub rho_corr: Option<f64>,
    pub accepted: bool,
    pub reason: String,
}

pub fn insert_loops(conn: &Connection, loops: &[LoopRow]) -> Result<(), StoreError> {
    let mut st = conn
        .prepare(
            "INSERT INTO loop_candidates(session_id, kind, source_keyframe, target_keyframe, distance_m,
                 x_m, y_m, z_m, qx, qy, qz, qw, converged, iterations, inliers, fitness, inlier_ratio,
                 rho_scan, rho_corr, accepted, reason)
             VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11, ?12, ?13, ?14, ?15, ?16, ?17, ?18, ?19, ?20, ?21)",
        )
        .map_err(e(conn))?;
    for l in loops {
        let c = pose_cols(&l.t_target_source);
        st.execute(params![
            l.session_id.0,
            l.kind,
            l.source_keyframe.0,
            l.target_keyframe.0,
            l.distance_m,
            c[0],
            c[1],
            c[2],
            c[3],
            c[4],
            c[5],
            c[6],
            l.converged,
            l.iterations,
            l.inliers,
            l.fitness,
            l.inlier_ratio,
            l.rho_scan.filter(|v| v.is_finite()),
            l.rho_corr.filter(|v| v.is_finite()),
            l.accepted,
            l.reason
        ])
        .map_err(e(conn))?;
    }
    Ok(())
}

/// Loop candidates, all or only the accepted ones, in insertion order.
pub fn loops(conn: &Connection, accepted_only: bool) -> Result<Vec<LoopRow>, StoreError> {
    let mut st = conn
        .prepare(
            "SELECT session_id, kind, source_keyframe, target_keyframe, distance_m, x_m, y_m, z_m, qx, qy, qz, qw,
                    converged, iterations, inliers, fitness, inlier_ratio, rho_scan, rho_corr, accepted, reason
             FROM loop_candidates WHERE (?1 = 0 OR accepted = 1) ORDER BY candidate_id",
        )
        .map_err(e(conn))?;
    let rows = st
        .query_map([accepted_only as i64], |r| {
            Ok(LoopRow {
                session_id: SessionId(r.get(0)?),
                kind: r.get(1)?,
                source_keyframe: KeyframeId(r.get(2)?),
                target_keyframe: KeyframeId(r.get(3)?),
                distance_m: r.get(4)?,
                t_target_source: pose_at(r, 5)?,
                converged: r.get(12)?,
                iterations: r.get(13)?,
                inliers: r.get(14)?,
                fitness: r.get(15)?,
                inlier_ratio: r.get(16)?,
                rho_scan: r.get(17)?,
                rho_corr: r.get(18)?,
                accepted: r.get(19)?,
                reason: r.get(20)?,
            })
        })
        .map_err(e(conn))?;
    rows.collect::<Result<_, _>>().map_err(e(conn))
}
