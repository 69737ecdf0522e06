//! The joint pose graph of all sessions, built from the store's rows for an
//! [`AnchorMode`], solved, and turned back into submap anchors and local
//! poses (MATH.md §5).
//!
//! - `submap`: one anchor per submap, at its first keyframe (held `p = I`).
//! - `session`: one anchor per session, at its first keyframe.
//! - `fixed`: as `submap`, but every variable of the sessions in `frozen`
//!   is held constant (LT-mapper's assumption: earlier sessions do not move).
//!
//! Factors: odometry between consecutive keyframes of each session (σ from
//! `GraphConfig`), every accepted loop (Cauchy, σ scaled by `max(1, ρ_corr)`,
//! MATH.md §5), a loose prior on every anchor at its initial value, and the
//! first anchor of the first session held constant (the gauge).
//!
//! Whatever the mode, the store keeps submap anchors: [`to_version_rows`]
//! re-expresses any solution as `A_m = world pose of the submap's first
//! keyframe`, `p_i = A_m⁻¹ · world_i`.

use super::SessionState;
use crate::geometry::Pose;
use crate::graph::{AnchorMode, AnchorPrior, Between, GraphConfig, OptimizeReport, PoseGraph, Robust, SolveError};
use crate::graph::{information, optimize};
use crate::store::{KeyframeId, LoopRow, SessionId, SubmapId};
use std::collections::{HashMap, HashSet};

/// World poses per session (indexed like `SessionState::keyframes`).
pub type WorldPoses = Vec<Vec<Pose>>;

/// Builds and solves the graph of `sessions` with initial values `initial`
/// and the accepted `loops` whose keyframes are all in `sessions`.
pub fn solve(
    sessions: &[SessionState],
    initial: &WorldPoses,
    loops: &[LoopRow],
    mode: AnchorMode,
    frozen: &HashSet<SessionId>,
    cfg: &GraphConfig,
) -> Result<(WorldPoses, OptimizeReport, usize), SolveError> {
    let mut g = PoseGraph::default();
    let mut index: Vec<Vec<usize>> = Vec::with_capacity(sessions.len());
    let mut by_id: HashMap<KeyframeId, usize> = HashMap::new();
    let prior_info = information(cfg.anchor_prior_sigma_rot_rad, cfg.anchor_prior_sigma_trans_m);
    for (s, sess) in sessions.iter().enumerate() {
        let is_frozen = mode == AnchorMode::Fixed && frozen.contains(&sess.id());
        let world = &initial[s];
        let mut ids = Vec::with_capacity(sess.keyframes.len());
        let mut anchor = usize::MAX;
        let mut anchor_value = Pose::identity();
        let mut current_submap: Option<SubmapId> = None;
        for (k, kf) in sess.keyframes.iter().enumerate() {
            let starts = match mode {
                AnchorMode::Session => k == 0,
                AnchorMode::Submap | AnchorMode::Fixed => k == 0 || kf.row.submap_id != current_submap,
            };
            if starts {
                current_submap = kf.row.submap_id;
                anchor_value = world[k];
                let gauge = g.anchors.is_empty();
                anchor = g.add_anchor(anchor_value, gauge || is_frozen);
                if !gauge && !is_frozen {
                    g.priors.push(AnchorPrior { anchor, value: anchor_value, information: prior_info });
                }
            }
            let i = g.add_keyframe(anchor, anchor_value.inverse() * world[k], starts || is_frozen);
            by_id.insert(kf.row.keyframe_id, i);
            if k > 0 {
                let prev = &sess.keyframes[k - 1].row.t_session_keyframe;
                let scale = if starts { cfg.submap_boundary_sigma_scale.max(1.0) } else { 1.0 };
                g.betweens.push(Between {
                    i: ids[k - 1],
                    j: i,
                    z: prev.inverse() * kf.row.t_session_keyframe,
                    information: information(cfg.odom_sigma_rot_rad * scale, cfg.odom_sigma_trans_m * scale),
                    robust: Robust::None,
                });
            }
            ids.push(i);
        }
        index.push(ids);
    }
    let mut used = 0;
    for l in loops.iter().filter(|l| l.accepted) {
        let (Some(&i), Some(&j)) = (by_id.get(&l.target_keyframe), by_id.get(&l.source_keyframe)) else { continue };
        let scale = l.rho_corr.unwrap_or(1.0).max(1.0);
        g.betweens.push(Between {
            i,
            j,
            z: l.t_target_source,
            information: information(cfg.loop_sigma_rot_rad * scale, cfg.loop_sigma_trans_m * scale),
            robust: Robust::Cauchy { k: cfg.loop_cauchy_k },
        });
        used += 1;
    }
    let report = optimize(&mut g, cfg)?;
    let out = index.iter().map(|ids| ids.iter().map(|&i| g.world_pose(i)).collect()).collect();
    Ok((out, report, used))
}

/// A graph version's rows: `(anchors A_m, local poses p_i)`.
pub type VersionRows = (Vec<(SubmapId, Pose)>, Vec<(KeyframeId, Pose)>);

/// A solution as the store keeps it: submap anchors and local poses.
pub fn to_version_rows(sessions: &[SessionState], world: &WorldPoses) -> VersionRows {
    let mut anchors = Vec::new();
    let mut locals = Vec::new();
    for (s, sess) in sessions.iter().enumerate() {
        let mut anchor: Option<(SubmapId, Pose)> = None;
        for (k, kf) in sess.keyframes.iter().enumerate() {
            let Some(sm) = kf.row.submap_id else { continue };
            if anchor.map(|a| a.0) != Some(sm) {
                anchor = Some((sm, world[s][k]));
                anchors.push((sm, world[s][k]));
            }
            let a = anchor.map(|a| a.1).unwrap_or_else(Pose::identity);
            locals.push((kf.row.keyframe_id, a.inverse() * world[s][k]));
        }
    }
    (anchors, locals)
}

/// Current estimates of every session as `WorldPoses`.
pub fn current(sessions: &[SessionState]) -> WorldPoses {
    sessions.iter().map(|s| s.keyframes.iter().map(|k| k.t_world_keyframe).collect()).collect()
}

/// Re-solves the stored graph as it was after the first `k` ingests, in
/// `mode`, from the coarse placements (`t_world_session · odometry`) and the
/// loops those ingests accepted. `fixed` solves ingest by ingest, freezing
/// the earlier sessions each time, as a fixed-trajectory system would have.
/// Returns world poses of the first `k` sessions.
pub fn replay(
    sessions: &[SessionState],
    placements: &HashMap<SessionId, Pose>,
    loops: &[LoopRow],
    k: usize,
    mode: AnchorMode,
    cfg: &GraphConfig,
) -> Result<WorldPoses, SolveError> {
    let k = k.min(sessions.len());
    let coarse: WorldPoses = sessions[..k]
        .iter()
        .map(|s| {
            let t = placements.get(&s.id()).copied().unwrap_or_else(Pose::identity);
            s.keyframes.iter().map(|kf| t * kf.row.t_session_keyframe).collect()
        })
        .collect();
    let loops_upto = |n: usize| -> Vec<LoopRow> {
        let ids: HashSet<SessionId> = sessions[..n].iter().map(|s| s.id()).collect();
        loops.iter().filter(|l| ids.contains(&l.session_id)).cloned().collect()
    };
    if k < 2 {
        return Ok(coarse);
    }
    match mode {
        AnchorMode::Fixed => {
            let mut world: WorldPoses = vec![coarse[0].clone()];
            for n in 2..=k {
                world.push(coarse[n - 1].clone());
                let frozen: HashSet<SessionId> = sessions[..n - 1].iter().map(|s| s.id()).collect();
                world = solve(&sessions[..n], &world, &loops_upto(n), mode, &frozen, cfg)?.0;
            }
            Ok(world)
        }
        _ => Ok(solve(&sessions[..k], &coarse, &loops_upto(k), mode, &HashSet::new(), cfg)?.0),
    }
}
