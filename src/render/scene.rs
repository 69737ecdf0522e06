//! What a picture is drawn from, read from the store in one snapshot: the
//! store's metadata, its sessions, the lifelong map's extent, every
//! session's trajectory on the newest graph version, and which sessions the
//! picture is about (the session window).

use super::RenderError;
use super::frame::Extent;
use crate::store::{self, MapExtent, SessionId, SessionRow, StoreMeta};
use rusqlite::Connection;

/// A session's keyframe positions in the world frame, in keyframe order.
#[derive(Debug, Clone, PartialEq)]
pub struct Trajectory {
    pub session: SessionId,
    pub name: String,
    pub xy_m: Vec<[f64; 2]>,
    pub length_m: f64,
    /// Stored unaligned: its own frame, not the world's.
    pub unaligned: bool,
}

/// The sessions a picture is about, inclusive, by id.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Window {
    pub from: SessionId,
    pub to: SessionId,
}

impl Window {
    pub fn contains(&self, s: i64) -> bool {
        self.from.0 <= s && s <= self.to.0
    }
}

pub struct Scene {
    pub meta: StoreMeta,
    pub sessions: Vec<SessionRow>,
    /// `None` while no session has been through change detection.
    pub map: Option<MapExtent>,
    /// Voxel edge of the lifelong map (else the store's), metres.
    pub voxel_m: f64,
    pub graph_version: Option<i64>,
    /// Every complete session's trajectory, in session order.
    pub trajectories: Vec<Trajectory>,
}

impl Scene {
    pub fn read(conn: &Connection, meta: StoreMeta) -> Result<Scene, RenderError> {
        let sessions = store::sessions(conn)?;
        let map = store::map_extent(conn)?;
        let state = if store::has_table(conn, "map_state")? { store::map_state(conn)? } else { None };
        let voxel_m = state.map(|s| s.voxel_m).filter(|v| *v > 0.0).unwrap_or(meta.voxel_size_m);
        let graph_version = store::latest_graph_version(conn)?;
        let mut trajectories = Vec::new();
        if let Some(v) = graph_version {
            for s in sessions.iter().filter(|s| s.status == "complete") {
                let xy_m: Vec<[f64; 2]> = store::world_poses(conn, v, s.session_id)?
                    .iter()
                    .map(|(_, p)| [p.translation.vector.x, p.translation.vector.y])
                    .collect();
                if xy_m.is_empty() {
                    continue;
                }
                let length_m = xy_m.windows(2).map(|w| (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1])).sum();
                let unaligned = store::alignment(conn, s.session_id)?.is_some_and(|a| a.method == "unaligned");
                trajectories.push(Trajectory {
                    session: s.session_id,
                    name: s.name.clone(),
                    xy_m,
                    length_m,
                    unaligned,
                });
            }
        }
        Ok(Scene { meta, sessions, map, voxel_m, graph_version, trajectories })
    }

    /// Everything there is to see: the map and every trajectory.
    pub fn content_extent(&self) -> Extent {
        let mut e = Extent::EMPTY;
        if let Some(m) = &self.map {
            e.include(m.min_m[0], m.min_m[1]);
            e.include(m.max_m[0], m.max_m[1]);
        }
        for t in &self.trajectories {
            for p in &t.xy_m {
                e.include(p[0], p[1]);
            }
        }
        e
    }

    pub fn name_of(&self, s: SessionId) -> String {
        self.sessions.iter().find(|r| r.session_id == s).map_or_else(|| format!("session {}", s.0), |r| r.name.clone())
    }

    /// Resolves `--session` (that session only) or `--since` (from it on)
    /// against the stored sessions; neither means every session, or for
    /// changes every session from the second on (the first has nothing to
    /// differ from).
    pub fn window(&self, session: Option<&str>, since: Option<&str>, changes: bool) -> Result<Window, RenderError> {
        let first = self.sessions.first().map_or(SessionId(1), |s| s.session_id);
        let last = self.sessions.last().map_or(SessionId(0), |s| s.session_id);
        match (session, since) {
            (Some(_), Some(_)) => {
                Err(RenderError::Usage("pass --session (one session) or --since (from it on), not both".into()))
            }
            (Some(a), None) => {
                let s = resolve_session(&self.sessions, a)?;
                Ok(Window { from: s, to: s })
            }
            (None, Some(a)) => Ok(Window { from: resolve_session(&self.sessions, a)?, to: last }),
            (None, None) if changes && self.sessions.len() >= 2 => {
                Ok(Window { from: self.sessions[1].session_id, to: last })
            }
            (None, None) => Ok(Window { from: first, to: last }),
        }
    }

    /// "s2", "s2–s4", or "no sessions".
    pub fn window_label(&self, w: &Window) -> String {
        if w.from > w.to {
            "no sessions".into()
        } else if w.from == w.to {
            self.name_of(w.from)
        } else {
            format!("{}–{}", self.name_of(w.from), self.name_of(w.to))
        }
    }
}

/// A session by name, or by number (`3` or `s3`) when no session has that
/// name; otherwise an error listing the sessions that exist.
pub fn resolve_session(sessions: &[SessionRow], arg: &str) -> Result<SessionId, RenderError> {
    crate::store::find_session(sessions, arg).ok_or_else(|| RenderError::NoSuchSession {
        arg: arg.to_string(),
        known: crate::store::session_list(sessions, "none yet"),
    })
}
