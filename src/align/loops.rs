//! Loop candidates (MATH.md §3) and their verification.
//!
//! - **Inter-session**: every `keyframe_stride`-th keyframe of the new
//!   session is paired with the nearest keyframe of each earlier aligned
//!   session in the current world estimate, if within `radius_m` (the
//!   `max_sessions_per_keyframe` nearest of those). Not for
//!   an unaligned session: its estimate says nothing about where it is.
//! - **Intra-session**: the same keyframes are paired with the nearest
//!   keyframe of their own session's past that is at least
//!   `intra_min_travel_m` of travel behind (a revisit, not a neighbour).
//!
//! Each candidate registers the source keyframe's scan (sensor frame) against
//! the target keyframe's local map (it and its ±`neighbours` neighbours in
//! the target's frame, by current poses) from the current relative estimate,
//! then applies [`verify_loop`]. Work goes in batches of source keyframes
//! (each scan preprocessed once, each local map built once and kept while
//! the next batch still needs it), parallel within a batch.

use super::SessionState;
use super::maps::{ScanLoader, transformed};
use crate::geometry::Pose;
use crate::pipeline::Progress;
use crate::registration::downsample::voxel_downsample;
use crate::registration::kdtree::{KdTree, to_f32};
use crate::registration::{LoopConfig, PreparedCloud, preprocess, verify_loop};
use crate::sensor::Fov;
use crate::store::{LoopRow, SessionId, StoreError};
use rayon::prelude::*;
use std::collections::{BTreeMap, HashMap};

/// A keyframe by position: `(session index, keyframe index)` into the
/// `SessionState` slice.
pub type KfRef = (usize, usize);

#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum LoopKind {
    Intra,
    Inter,
}

impl LoopKind {
    pub fn name(self) -> &'static str {
        match self {
            LoopKind::Intra => "intra",
            LoopKind::Inter => "inter",
        }
    }
}

/// A pair to register: `source` of the new session against `target`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Candidate {
    pub kind: LoopKind,
    pub source: KfRef,
    pub target: KfRef,
    /// Distance between the two in the current estimate, m.
    pub distance_m: f64,
}

fn position(s: &[SessionState], k: KfRef) -> [f64; 3] {
    s[k.0].keyframes[k.1].t_world_keyframe.translation.vector.into()
}

/// Inter-session candidates of session `new`: for every
/// `keyframe_stride`-th keyframe, the nearest keyframe of each earlier
/// aligned session within `radius_m`, keeping the `max_sessions_per_keyframe`
/// nearest (MATH.md §3 names the nearest of the earlier sessions; more than
/// one ties more sessions in, not only the one that happens to be nearest).
pub fn inter_candidates(sessions: &[SessionState], new: usize, cfg: &LoopConfig) -> Vec<Candidate> {
    let r2 = (cfg.radius_m * cfg.radius_m) as f32;
    let mut out = Vec::new();
    for (s, other) in sessions.iter().enumerate() {
        if s == new || !other.aligned || other.keyframes.is_empty() {
            continue;
        }
        let positions: Vec<[f64; 3]> = (0..other.keyframes.len()).map(|k| position(sessions, (s, k))).collect();
        let tree = KdTree::build(&positions);
        for k in (0..sessions[new].keyframes.len()).step_by(cfg.keyframe_stride.max(1)) {
            let Some((i, d2)) = tree.nearest(&to_f32(&position(sessions, (new, k)))) else { continue };
            if d2 <= r2 {
                out.push(Candidate {
                    kind: LoopKind::Inter,
                    source: (new, k),
                    target: (s, i),
                    distance_m: (d2 as f64).sqrt(),
                });
            }
        }
    }
    // The nearest `max_sessions_per_keyframe` per source keyframe.
    out.sort_by(|a, b| a.source.1.cmp(&b.source.1).then(a.distance_m.total_cmp(&b.distance_m)));
    let mut kept: Vec<Candidate> = Vec::with_capacity(out.len());
    for c in out {
        let n = kept.iter().rev().take_while(|k| k.source == c.source).count();
        if n < cfg.max_sessions_per_keyframe.max(1) {
            kept.push(c);
        }
    }
    kept
}

/// Intra-session candidates (revisits) of session `new`.
pub fn intra_candidates(sessions: &[SessionState], new: usize, cfg: &LoopConfig) -> Vec<Candidate> {
    let kfs = &sessions[new].keyframes;
    let mut out = Vec::new();
    for j in (0..kfs.len()).step_by(cfg.keyframe_stride.max(1)) {
        let pj = kfs[j].t_world_keyframe.translation.vector;
        let best = (0..j)
            .take_while(|&i| kfs[j].travel_m - kfs[i].travel_m >= cfg.intra_min_travel_m)
            .map(|i| (i, (kfs[i].t_world_keyframe.translation.vector - pj).norm()))
            .filter(|&(_, d)| d <= cfg.radius_m)
            .min_by(|a, b| a.1.total_cmp(&b.1));
        if let Some((i, d)) = best {
            out.push(Candidate { kind: LoopKind::Intra, source: (new, j), target: (new, i), distance_m: d });
        }
    }
    out
}

/// The local map of `target`: it and its ±`cfg.neighbours` session
/// neighbours, in the target keyframe's frame, ready for GICP.
fn local_map(
    loader: &ScanLoader,
    sessions: &[SessionState],
    target: KfRef,
    cfg: &LoopConfig,
) -> Result<PreparedCloud, StoreError> {
    let kfs = &sessions[target.0].keyframes;
    let lo = target.1.saturating_sub(cfg.neighbours);
    let hi = (target.1 + cfg.neighbours).min(kfs.len() - 1);
    let t_target_world = kfs[target.1].t_world_keyframe.inverse();
    let mut pts: Vec<[f64; 3]> = Vec::new();
    for kf in &kfs[lo..=hi] {
        let scan = loader.load(&kf.row)?;
        pts.extend(voxel_downsample(
            &transformed(&scan.points, &(t_target_world * kf.t_world_keyframe)),
            cfg.gicp.voxel_size_m,
            false,
        ));
    }
    Ok(preprocess(&pts, &cfg.gicp))
}

/// Source keyframes registered per batch; their targets' local maps are
/// built once per batch (and kept for the next batch if it needs them).
const SOURCE_BATCH: usize = 16;

/// Registers and judges every candidate; `session` is the ingest that
/// evaluates them (stored with each row), `source_fov` the FoV of its
/// sensor (every source is one of its keyframes). Rows come back in
/// candidate order.
pub fn evaluate(
    loader: &ScanLoader,
    sessions: &[SessionState],
    candidates: &[Candidate],
    session: SessionId,
    source_fov: &Fov,
    cfg: &LoopConfig,
    progress: &dyn Progress,
) -> Result<Vec<LoopRow>, StoreError> {
    // Candidates grouped by source, sources in trajectory order.
    let mut by_source: BTreeMap<KfRef, Vec<usize>> = BTreeMap::new();
    for (i, c) in candidates.iter().enumerate() {
        by_source.entry(c.source).or_default().push(i);
    }
    let sources: Vec<(KfRef, Vec<usize>)> = by_source.into_iter().collect();
    let mut rows: Vec<Option<LoopRow>> = vec![None; candidates.len()];
    progress.begin("loops", candidates.len() as u64);
    // Parallelism is over scans and candidates; GICP itself is serial here
    // (`parallel` off) so that many registrations run at once.
    let mut gicp = cfg.gicp.clone();
    gicp.parallel = false;
    let cfg = &LoopConfig { gicp, ..cfg.clone() };
    let mut maps: HashMap<KfRef, PreparedCloud> = HashMap::new();
    for batch in sources.chunks(SOURCE_BATCH) {
        let mut wanted: Vec<KfRef> =
            batch.iter().flat_map(|(_, ids)| ids.iter().map(|&i| candidates[i].target)).collect();
        wanted.sort();
        wanted.dedup();
        maps.retain(|t, _| wanted.contains(t));
        let missing: Vec<KfRef> = wanted.iter().copied().filter(|t| !maps.contains_key(t)).collect();
        let built = missing
            .par_iter()
            .map(|&t| Ok((t, local_map(loader, sessions, t, cfg)?)))
            .collect::<Result<Vec<_>, StoreError>>()?;
        maps.extend(built);
        let prepared = batch
            .par_iter()
            .map(|(s, _)| Ok(preprocess(&loader.load(&sessions[s.0].keyframes[s.1].row)?.points, &cfg.gicp)))
            .collect::<Result<Vec<_>, StoreError>>()?;
        let jobs: Vec<(usize, usize)> =
            batch.iter().enumerate().flat_map(|(b, (_, ids))| ids.iter().map(move |&i| (b, i))).collect();
        let done: Vec<(usize, LoopRow)> = jobs
            .par_iter()
            .map(|&(b, i)| {
                let c = &candidates[i];
                let src = &sessions[c.source.0].keyframes[c.source.1];
                let tgt = &sessions[c.target.0].keyframes[c.target.1];
                let t_init: Pose = tgt.t_world_keyframe.inverse() * src.t_world_keyframe;
                let v = verify_loop(&maps[&c.target], &prepared[b], &t_init, source_fov, cfg);
                progress.advance(1);
                let finite = |x: f64| x.is_finite().then_some(x);
                (
                    i,
                    LoopRow {
                        session_id: session,
                        kind: c.kind.name().into(),
                        source_keyframe: src.row.keyframe_id,
                        target_keyframe: tgt.row.keyframe_id,
                        distance_m: c.distance_m,
                        t_target_source: v.gicp.t_target_source,
                        converged: v.gicp.converged,
                        iterations: v.gicp.iterations as i64,
                        inliers: v.gicp.num_inliers as i64,
                        fitness: v.gicp.fitness,
                        inlier_ratio: v.gicp.inlier_ratio,
                        rho_scan: finite(v.dop.rho_scan),
                        rho_corr: finite(v.dop.rho_corr),
                        accepted: v.accepted,
                        reason: v.describe(),
                    },
                )
            })
            .collect();
        for (i, row) in done {
            rows[i] = Some(row);
        }
    }
    progress.end();
    Ok(rows.into_iter().flatten().collect())
}
