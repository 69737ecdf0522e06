//! Multi-session alignment (paper III-B, MATH.md §2-5): what the ingest's
//! `coarse_align`, `loops` and `optimize` steps compute, as plain functions
//! over the store's rows.
//!
//! ```text
//!  new session (odometry)          earlier sessions (newest graph version)
//!        │ merged map                      │ merged world map
//!        └──────────► coarse::coarse_align ◄┘      registration::global
//!                          │ t_world_session (or unaligned)
//!                          ▼
//!   loops::inter_candidates + intra_candidates     nearest keyframes ≤ 10 m
//!                          │ GICP vs local map, acceptance + DOP (registration::loop_check)
//!                          ▼  every candidate stored, accepted or not
//!   graph::solve(all sessions, odometry + accepted loops, mode)
//!                          │ submap anchors + local poses
//!                          ▼
//!                 a new graph version in the store
//! ```
//!
//! [`graph::replay`] re-solves the stored graph for a prefix of the sessions
//! in any [`AnchorMode`](crate::graph::AnchorMode): the comparison of the
//! paper's Table II (`seam eval align --compare-anchors`). What this module
//! does not own: transactions and the step log (pipeline), GICP and the
//! solver themselves (registration, graph).

pub mod coarse;
pub mod graph;
pub mod loops;
pub mod maps;

use crate::geometry::Pose;
use crate::registration::estimate_fov;
use crate::sensor::{Fov, SensorModel};
use crate::store::{self, KeyframeRow, SessionId, SessionRow, Store, StoreError};
use serde::{Deserialize, Serialize};

/// Coarse-alignment settings beyond those of the global registration itself.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CoarseConfig {
    /// Every n-th keyframe goes into the maps that are registered (choice: 2;
    /// at 1 m keyframe spacing neighbours see nearly the same thing).
    pub map_keyframe_stride: usize,
    /// Voxel of those maps before registration (the registration then
    /// downsamples to its own `voxel_size_m`), m.
    pub map_voxel_m: f64,
}

impl Default for CoarseConfig {
    fn default() -> Self {
        CoarseConfig { map_keyframe_stride: 2, map_voxel_m: 0.2 }
    }
}

/// A keyframe as alignment sees it.
#[derive(Debug, Clone)]
pub struct KeyframeState {
    pub row: KeyframeRow,
    /// Current world pose estimate.
    pub t_world_keyframe: Pose,
    /// Odometry travel from the session's first keyframe, m.
    pub travel_m: f64,
}

/// A session with its keyframes (in keyframe order) and current poses.
#[derive(Debug, Clone)]
pub struct SessionState {
    pub row: SessionRow,
    pub keyframes: Vec<KeyframeState>,
    /// Placed in the world (reference, global or initial guess). Unaligned
    /// sessions are neither part of the map others are registered against
    /// nor loop targets.
    pub aligned: bool,
}

impl SessionState {
    pub fn id(&self) -> SessionId {
        self.row.session_id
    }
}

/// The FoV of a session: as stored (`session.toml`), else its sensor model's,
/// else estimated from `scan` (read only then).
pub fn session_fov(row: &SessionRow, scan: impl FnOnce() -> Option<Vec<[f32; 3]>>) -> Fov {
    if let Some(f) = row.fov_json.as_deref().and_then(|j| serde_json::from_str::<Fov>(j).ok()) {
        return f;
    }
    if let Some(m) = row.sensor_model.as_deref().and_then(SensorModel::parse) {
        return m.fov();
    }
    scan().map(|p| estimate_fov(&p)).unwrap_or(Fov::Band { elev_min_deg: -90.0, elev_max_deg: 90.0 })
}

/// Every session (ingest order) with its keyframes' world poses: from graph
/// `version` where it has them, else their odometry (a session not yet
/// placed sits at the world origin until `coarse_align` moves it).
pub fn load_sessions(store: &Store, version: Option<i64>) -> Result<Vec<SessionState>, StoreError> {
    let conn = store.conn();
    let mut out = Vec::new();
    for row in store::sessions(conn)? {
        let kfs = store::keyframes(conn, row.session_id)?;
        let stored: std::collections::HashMap<i64, Pose> = match version {
            Some(v) => store::world_poses(conn, v, row.session_id)?.into_iter().collect(),
            None => Default::default(),
        };
        let mut travel = 0.0;
        let mut keyframes: Vec<KeyframeState> = Vec::with_capacity(kfs.len());
        for kf in kfs {
            if let Some(prev) = keyframes.last() {
                travel +=
                    (kf.t_session_keyframe.translation.vector - prev.row.t_session_keyframe.translation.vector).norm();
            }
            let t_world_keyframe = stored.get(&kf.keyframe_index).copied().unwrap_or(kf.t_session_keyframe);
            keyframes.push(KeyframeState { row: kf, t_world_keyframe, travel_m: travel });
        }
        let aligned = store::alignment(conn, row.session_id)?.is_some_and(|a| a.success);
        out.push(SessionState { row, keyframes, aligned });
    }
    Ok(out)
}
