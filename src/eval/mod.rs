//! Evaluation against ground truth: what `seam eval` prints.
//!
//! - [`align`]: Umeyama fits, ATE, the per-session rigid residual (Table II).
//! - [`align_report`]: those numbers for a store against a simulator's
//!   output folder, and optionally the Table II comparison of anchor modes
//!   replayed on the store's own loops.
//! - [`dor`]: dynamic object removal scored against SemanticKITTI labels
//!   (PR, RR, F1, precision of removal; point-wise and voxel-wise).

pub mod align;
pub mod changes;
pub mod dor;
mod dor_store;
pub use dor_store::{DorReport, dor_report};

pub use dor::{DorAccumulator, DorBlock, DorScores, is_moving_label, render_table};

use crate::align::{self as alignment, SessionState, graph};
use crate::geometry::Pose;
use crate::graph::{AnchorMode, GraphConfig};
use crate::sim::{GroundTruth, SimError, read_ground_truth};
use crate::store::{self, SessionId, Store, StoreError};
use nalgebra::Vector3;
use std::collections::HashMap;
use std::path::Path;

#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    #[error(transparent)]
    Store(#[from] StoreError),
    #[error(transparent)]
    Truth(#[from] SimError),
    #[error("{0}")]
    Mismatch(String),
    #[error("re-solving the graph failed: {0}")]
    Solve(#[from] crate::graph::SolveError),
}

/// One row of the anchor comparison: after `sessions` ingests, in `mode`.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct AnchorStep {
    pub sessions: usize,
    pub mode: String,
    /// Mean over the sessions of the odometry's rigid residual (a session
    /// moved as one rigid body), m: the same for every mode.
    pub mean_rigid_session_residual_m: f64,
    /// Mean over the sessions of the per-session rigid residual, m.
    pub mean_rigid_residual_m: f64,
    /// Largest per-session ATE RMSE, m.
    pub max_ate_rmse_m: f64,
    pub per_session: Vec<align::SessionAlignment>,
}

#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct AlignReport {
    /// Names of the store's sessions, in order.
    pub names: Vec<String>,
    /// The newest graph version against the truth.
    pub sessions: Vec<align::SessionAlignment>,
    /// Per session, the rigid residual of its raw odometry: what remains
    /// when a session can only move as one rigid body (its shape frozen).
    pub odometry_residual_m: Vec<f64>,
    /// Accepted loops measured against the true relative poses.
    pub loops: LoopAccuracy,
    /// Filled by `compare_anchors`.
    pub anchor_steps: Vec<AnchorStep>,
}

/// How right the accepted loop edges are.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct LoopAccuracy {
    pub accepted: usize,
    /// Accepted edges off the truth by more than 0.3 m or 1°.
    pub wrong: usize,
    pub median_error_m: f64,
    pub max_error_m: f64,
    pub median_error_deg: f64,
}

/// Threshold of a wrong loop edge.
const WRONG_LOOP_M: f64 = 0.3;
const WRONG_LOOP_DEG: f64 = 1.0;

fn loop_accuracy(sessions: &[SessionState], truth: &GroundTruth, loops: &[store::LoopRow]) -> LoopAccuracy {
    let mut true_pose: HashMap<store::KeyframeId, Pose> = HashMap::new();
    for (i, s) in sessions.iter().enumerate() {
        if let Some(g) = truth_for(truth, s, i) {
            for kf in &s.keyframes {
                if let Some(p) = g.poses.get(kf.row.keyframe_index as usize) {
                    true_pose.insert(kf.row.keyframe_id, *p);
                }
            }
        }
    }
    let mut errs: Vec<(f64, f64)> = loops
        .iter()
        .filter(|l| l.accepted)
        .filter_map(|l| {
            let (t, s) = (true_pose.get(&l.target_keyframe)?, true_pose.get(&l.source_keyframe)?);
            let d = (t.inverse() * s).inverse() * l.t_target_source;
            Some((d.translation.vector.norm(), d.rotation.angle().to_degrees()))
        })
        .collect();
    if errs.is_empty() {
        return LoopAccuracy::default();
    }
    let wrong = errs.iter().filter(|e| e.0 > WRONG_LOOP_M || e.1 > WRONG_LOOP_DEG).count();
    let max_error_m = errs.iter().map(|e| e.0).fold(0.0, f64::max);
    let n = errs.len();
    errs.sort_by(|a, b| a.0.total_cmp(&b.0));
    let median_error_m = errs[n / 2].0;
    errs.sort_by(|a, b| a.1.total_cmp(&b.1));
    LoopAccuracy { accepted: n, wrong, median_error_m, max_error_m, median_error_deg: errs[n / 2].1 }
}

/// The true session of each stored one: the simulator folder it was ingested
/// from (`session_NN`), else the same position.
fn truth_for<'a>(truth: &'a GroundTruth, s: &SessionState, position: usize) -> Option<&'a crate::sim::GtSession> {
    let name = Path::new(&s.row.source_dir).file_name().map(|f| f.to_owned());
    truth
        .sessions
        .iter()
        .find(|g| name.is_some() && g.dir.file_name().map(|f| f.to_owned()) == name)
        .or_else(|| truth.sessions.get(position))
}

/// Keyframe positions, per session.
type Positions = Vec<Vec<Vector3<f64>>>;

/// Estimated and true positions of the keyframes both know, per session.
fn pairs(
    sessions: &[SessionState],
    world: &graph::WorldPoses,
    truth: &GroundTruth,
) -> Result<(Positions, Positions), EvalError> {
    let mut est = Vec::new();
    let mut tru = Vec::new();
    for (i, s) in sessions.iter().enumerate() {
        let g = truth_for(truth, s, i).ok_or_else(|| {
            EvalError::Mismatch(format!(
                "no ground truth for session {} ({:?}, from {}); the truth folder has {} sessions",
                s.id().0,
                s.row.name,
                s.row.source_dir,
                truth.sessions.len()
            ))
        })?;
        let (mut e, mut t) = (Vec::new(), Vec::new());
        for (k, kf) in s.keyframes.iter().enumerate() {
            if let Some(p) = g.poses.get(kf.row.keyframe_index as usize) {
                e.push(world[i][k].translation.vector);
                t.push(p.translation.vector);
            }
        }
        est.push(e);
        tru.push(t);
    }
    Ok((est, tru))
}

/// `seam eval align`: the store's newest poses against the simulator's truth
/// in `gt_dir`; with `compare_anchors`, also every ingest step re-solved in
/// `fixed`, `session` and `submap` mode on the store's loops (Table II).
pub fn align_report(
    store: &Store,
    gt_dir: &Path,
    compare_anchors: bool,
    cfg: &GraphConfig,
) -> Result<AlignReport, EvalError> {
    let truth = read_ground_truth(gt_dir)?;
    let version = store::latest_graph_version(store.conn())?;
    let mut sessions = alignment::load_sessions(store, version)?;
    sessions.retain(|s| s.row.status == "complete");
    if sessions.is_empty() {
        return Err(EvalError::Mismatch("the store has no complete session to evaluate".into()));
    }
    let (est, tru) = pairs(&sessions, &graph::current(&sessions), &truth)?;
    let odometry: graph::WorldPoses =
        sessions.iter().map(|s| s.keyframes.iter().map(|k| k.row.t_session_keyframe).collect()).collect();
    let (odo, odo_true) = pairs(&sessions, &odometry, &truth)?;
    let odometry_residual_m: Vec<f64> = odo.iter().zip(&odo_true).map(|(e, t)| align::rigid_residual(e, t)).collect();
    let loops = store::loops(store.conn(), true)?;
    let mut report = AlignReport {
        names: sessions.iter().map(|s| s.row.name.clone()).collect(),
        sessions: align::evaluate(&est, &tru),
        odometry_residual_m: odometry_residual_m.clone(),
        loops: loop_accuracy(&sessions, &truth, &loops),
        anchor_steps: Vec::new(),
    };
    if compare_anchors {
        let conn = store.conn();
        let mut placements: HashMap<SessionId, Pose> = HashMap::new();
        for s in &sessions {
            if let Some(a) = store::alignment(conn, s.id())? {
                placements.insert(s.id(), a.t_world_session);
            }
        }
        for k in 2..=sessions.len() {
            for mode in [AnchorMode::Fixed, AnchorMode::Session, AnchorMode::Submap] {
                let world = graph::replay(&sessions, &placements, &loops, k, mode, cfg)?;
                let (est, tru) = pairs(&sessions[..k], &world, &truth)?;
                let per_session = align::evaluate(&est, &tru);
                report.anchor_steps.push(AnchorStep {
                    sessions: k,
                    mode: mode.name().into(),
                    mean_rigid_session_residual_m: odometry_residual_m[..k].iter().sum::<f64>() / k as f64,
                    mean_rigid_residual_m: per_session.iter().map(|s| s.rigid_residual_m).sum::<f64>()
                        / per_session.len() as f64,
                    max_ate_rmse_m: per_session.iter().map(|s| s.ate_rmse_m).fold(0.0, f64::max),
                    per_session,
                });
            }
        }
    }
    Ok(report)
}
