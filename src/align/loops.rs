//! Loop candidates (MATH.md §3) and their verification.
//!
//! - **Inter-session**: every `keyframe_stride`-th keyframe of the new
//!   session is paired with the nearest keyframe of each earlier aligned
//!   session in the current world estimate, if within `radius_m` (the
//!   `max_sessions_per_keyframe` nearest of those). Not for
//!   an unaligned session: its estimate says nothing about where it is.
//! - **Intra-session**: the same keyframes are paired with the nearest
//!   keyframe of their own session's past that is at least
//!   `intra_min_travel_m` of travel behind (a revisit, not a neighbour),
//!   and with the first keyframe `local_travel_m` of travel behind (a local
//!   edge: it measures the input odometry's drift where nothing is
//!   revisited).
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

/// Intra-session candidates of session `new`: revisits, and the local edge
/// of each stride-th keyframe (`LoopConfig::local_travel_m`), revisit first.
pub fn intra_candidates(sessions: &[SessionState], new: usize, cfg: &LoopConfig) -> Vec<Candidate> {
    let kfs = &sessions[new].keyframes;
    let distance = |i: usize, j: usize| {
        (kfs[i].t_world_keyframe.translation.vector - kfs[j].t_world_keyframe.translation.vector).norm()
    };
    let mut out = Vec::new();
    for j in (0..kfs.len()).step_by(cfg.keyframe_stride.max(1)) {
        let behind = |i: usize| kfs[j].travel_m - kfs[i].travel_m;
        let revisit = (0..j)
            .take_while(|&i| behind(i) >= cfg.intra_min_travel_m)
            .map(|i| (i, distance(i, j)))
            .filter(|&(_, d)| d <= cfg.radius_m)
            .min_by(|a, b| a.1.total_cmp(&b.1));
        if let Some((i, d)) = revisit {
            out.push(Candidate { kind: LoopKind::Intra, source: (new, j), target: (new, i), distance_m: d });
        }
        if cfg.local_travel_m > 0.0
            && let Some(i) = (0..j).rev().find(|&i| behind(i) >= cfg.local_travel_m)
            && revisit.is_none_or(|(r, _)| r != i)
            && distance(i, j) <= cfg.radius_m
        {
            out.push(Candidate {
                kind: LoopKind::Intra,
                source: (new, j),
                target: (new, i),
                distance_m: distance(i, j),
            });
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::align::KeyframeState;
    use crate::store::{KeyframeId, KeyframeRow, SessionRow};
    use nalgebra::Isometry3;

    /// A session walking `xy` (one keyframe per point), travel along it.
    fn session(xy: &[[f64; 2]]) -> SessionState {
        let mut travel = 0.0;
        let keyframes = xy
            .iter()
            .enumerate()
            .map(|(i, p)| {
                if i > 0 {
                    travel += ((p[0] - xy[i - 1][0]).powi(2) + (p[1] - xy[i - 1][1]).powi(2)).sqrt();
                }
                let pose = Isometry3::translation(p[0], p[1], 0.0);
                let row = KeyframeRow {
                    keyframe_id: KeyframeId(i as i64 + 1),
                    session_id: SessionId(1),
                    keyframe_index: i as i64,
                    source_file: String::new(),
                    stamp_s: None,
                    point_count: 0,
                    scan_file_id: 0,
                    scan_row_group: 0,
                    t_session_keyframe: pose,
                    submap_id: None,
                };
                KeyframeState { row, t_world_keyframe: pose, travel_m: travel }
            })
            .collect();
        let row = SessionRow {
            session_id: SessionId(1),
            name: "s1".into(),
            content_hash: String::new(),
            source_dir: String::new(),
            layout: "kitti".into(),
            date: None,
            sensor_model: None,
            fov_json: None,
            keyframe_count: xy.len() as i64,
            point_count: 0,
            status: "ingesting".into(),
            created_at: String::new(),
            completed_at: None,
        };
        SessionState { row, keyframes, aligned: true }
    }

    fn pairs(c: &[Candidate]) -> Vec<(usize, usize)> {
        c.iter().map(|c| (c.source.1, c.target.1)).collect()
    }

    #[test]
    fn a_straight_walk_gets_local_edges_the_set_travel_back() {
        // 1 m apart along x: keyframe j's local edge goes to j - 8.
        let walk: Vec<[f64; 2]> = (0..20).map(|i| [i as f64, 0.0]).collect();
        let s = [session(&walk)];
        let cfg = LoopConfig { keyframe_stride: 2, ..LoopConfig::default() };
        let c = intra_candidates(&s, 0, &cfg);
        assert_eq!(pairs(&c), (8..20).step_by(2).map(|j| (j, j - 8)).collect::<Vec<_>>());
        assert!(c.iter().all(|c| c.kind == LoopKind::Intra && (c.distance_m - 8.0).abs() < 1e-9));
        // Off: a straight walk has no revisit, so no candidate at all.
        let off = LoopConfig { local_travel_m: 0.0, ..cfg };
        assert!(intra_candidates(&s, 0, &off).is_empty());
    }

    #[test]
    fn a_revisit_keeps_its_candidate_beside_the_local_edge() {
        // Out 20 m along x, 2 m over, back: the way back passes the way out.
        let mut walk: Vec<[f64; 2]> = (0..=20).map(|i| [i as f64, 0.0]).collect();
        walk.extend((0..=20).map(|i| [20.0 - i as f64, 2.0]));
        let s = [session(&walk)];
        let cfg = LoopConfig { keyframe_stride: 1, ..LoopConfig::default() };
        let c = intra_candidates(&s, 0, &cfg);
        // The last keyframe (back at x = 0, 42 m of travel): revisit of
        // keyframe 0 (2 m away) and the local edge 8 m of travel back.
        let last = walk.len() - 1;
        let of_last: Vec<(usize, usize)> = pairs(&c).into_iter().filter(|p| p.0 == last).collect();
        assert_eq!(of_last, vec![(last, 0), (last, last - 8)]);
        // Local edges never reach farther than `radius_m`: around the turn
        // the keyframe 8 m of travel back is within 8 m, so all are kept.
        assert!(c.iter().all(|c| c.distance_m <= cfg.radius_m));
    }
}
