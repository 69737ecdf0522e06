//! [`register_maps`]: the steps of the module doc as one page, and the verdict.

use std::time::Instant;

use nalgebra::{Point3, Vector3};

use super::bev::{BevParams, bev_hypotheses};
use super::clique::consistency_graph;
use super::cloud::MapCloud;
use super::fpfh::compute_fpfh;
use super::matching::mutual_matches;
use super::robust::{Dof, RobustParams, hypotheses};
use super::verify::{RefineParams, Score, Verifier, pose_distance, refine, v3};
use super::{GlobalConfig, GlobalResult, GlobalTimings, Verdict};
use crate::geometry::Pose;
use crate::registration::downsample::voxel_downsample;

/// Fewer descriptors than this on either map cannot be matched meaningfully.
const MIN_DESCRIPTORS: usize = 20;

/// A hypothesis with its score.
struct Checked {
    pose: Pose,
    /// Size of the clique it came from (0 for the BEV search).
    clique: usize,
    score: Score,
}

/// Registers `source` (the new session's map) to `target` (the earlier
/// sessions' map): `t_target_source` and a verdict (see the module doc).
pub fn register_maps(target: &[[f32; 3]], source: &[[f32; 3]], cfg: &GlobalConfig) -> GlobalResult {
    let start = Instant::now();
    let mut timings = GlobalTimings::default();
    let mut lap = Instant::now();
    let mut tick = |slot: &mut f64| {
        *slot = lap.elapsed().as_secs_f64();
        lap = Instant::now();
    };
    let dof = if cfg.gravity_aligned { Dof::Four } else { Dof::Six };
    if let Err(e) = cfg.validate() {
        let empty = MapCloud::new(&[] as &[[f32; 3]], 1.0, 1.0);
        return fail(
            empty_result(&empty, &empty),
            start,
            timings,
            format!("invalid global registration settings: {e}"),
        );
    }

    // 1. Voxel centroids and normals of both maps (MATH.md §2: 0.5-1.0 m).
    let (tgt, src) = rayon::join(
        || MapCloud::new(target, cfg.voxel_size_m, cfg.normal_radius_m),
        || MapCloud::new(source, cfg.voxel_size_m, cfg.normal_radius_m),
    );
    tick(&mut timings.preprocess_s);
    let mut result = empty_result(&tgt, &src);

    // 2. FPFH descriptors.
    let (tgt_desc, src_desc) =
        rayon::join(|| compute_fpfh(&tgt, cfg.feature_radius_m), || compute_fpfh(&src, cfg.feature_radius_m));
    tick(&mut timings.features_s);
    if tgt_desc.len() < MIN_DESCRIPTORS || src_desc.len() < MIN_DESCRIPTORS {
        return fail(
            result,
            start,
            timings,
            format!(
                "too little structure to describe: {} target and {} source voxels have a descriptor (need {MIN_DESCRIPTORS}); \
             are the maps empty or nearly so?",
                tgt_desc.len(),
                src_desc.len()
            ),
        );
    }

    // 3. Mutual nearest neighbours in descriptor space, most distinctive first.
    let corr = mutual_matches(&src_desc, &tgt_desc, cfg.max_correspondences);
    let (cs, ct): (Vec<Vector3<f64>>, Vec<Vector3<f64>>) =
        corr.iter().map(|c| (v3(&src.points[c.source as usize]), v3(&tgt.points[c.target as usize]))).unzip();
    result.correspondences = corr.len();
    tick(&mut timings.matching_s);

    // 4. Consistency graph, max clique + GNC-TLS, runner-ups; with gravity,
    //    also the exhaustive yaw × offset search of the structure layout.
    let tilt = cfg.gravity_aligned.then(|| cfg.max_tilt_deg.to_radians());
    let graph = consistency_graph(&cs, &ct, cfg.noise_bound_m, tilt);
    let params = RobustParams {
        noise_bound_m: cfg.noise_bound_m,
        dof,
        max_hypotheses: cfg.max_hypotheses,
        min_clique: 3,
        node_budget: cfg.clique_node_budget,
    };
    let mut hyps: Vec<(Pose, usize)> =
        hypotheses(&cs, &ct, &graph, &params).into_iter().map(|h| (h.t_target_source, h.clique.len())).collect();
    if cfg.gravity_aligned && cfg.bev_hypotheses > 0 {
        let bev = BevParams {
            cell_m: cfg.bev_cell_m,
            yaw_step_deg: cfg.bev_yaw_step_deg,
            max_hypotheses: cfg.bev_hypotheses,
            suppress_yaw_deg: 10.0,
            suppress_m: 5.0,
        };
        hyps.extend(bev_hypotheses(&tgt, &src, &bev).into_iter().map(|pose| (pose, 0)));
    }
    result.hypotheses = hyps.len();
    tick(&mut timings.solver_s);
    if hyps.is_empty() {
        return fail(
            result,
            start,
            timings,
            format!(
                "no three of the {} feature matches agree on a motion: the maps do not seem to overlap",
                corr.len()
            ),
        );
    }

    // 5. Score every hypothesis as it is, refine the best distinct ones by
    //    ICP on the maps, and score them again.
    let verifier = Verifier::new(&tgt, &src, cfg.coverage_cell_m, cfg.match_distance_m);
    let mut initial: Vec<Checked> =
        hyps.iter().map(|&(pose, clique)| Checked { pose, clique, score: verifier.score(&pose) }).collect();
    initial.sort_by(|a, b| b.score.evidence().total_cmp(&a.score.evidence()));
    let sample = voxel_downsample(&src.points, 2.0 * cfg.voxel_size_m, true);
    let refine_params = RefineParams {
        max_dist_start_m: cfg.refine_start_m,
        max_dist_end_m: cfg.voxel_size_m,
        iterations: cfg.refine_iterations,
        dof,
    };
    let mut checked: Vec<Checked> = distinct(initial, cfg)
        .into_iter()
        .take(cfg.refine_top.max(1))
        .map(|h| {
            let pose = refine(&tgt, &sample, &h.pose, &refine_params);
            Checked { pose, clique: h.clique, score: verifier.score(&pose) }
        })
        .collect();
    checked.sort_by(|a, b| b.score.evidence().total_cmp(&a.score.evidence()));
    let checked = distinct(checked, cfg);
    result.refined = checked.len();
    tick(&mut timings.verify_s);

    // 6. The winner, its evidence against the runner-up, and the verdict.
    let win = &checked[0];
    let best = win.score.evidence();
    let runner_up = checked.get(1).map_or(0.0, |c| c.score.evidence());
    result.t_target_source = win.pose;
    result.clique_size = win.clique;
    result.feature_inliers = count_inliers(&cs, &ct, &win.pose, cfg.noise_bound_m);
    result.inliers = win.score.matched();
    result.inlier_ratio = win.score.fit();
    result.overlap_fraction = win.score.overlap_fraction();
    result.runner_up_ratio = if best > 0.0 { runner_up / best } else { 0.0 };
    result.elapsed_s = start.elapsed().as_secs_f64();
    result.timings = timings;
    match verdict(&result, cfg) {
        Some(reason) => fail(result, start, timings, reason),
        None => GlobalResult { verdict: Verdict::Success, ..result },
    }
}

/// `sorted` (best first) without the hypotheses that are the same answer as
/// a better one.
fn distinct(sorted: Vec<Checked>, cfg: &GlobalConfig) -> Vec<Checked> {
    let mut out: Vec<Checked> = Vec::new();
    for c in sorted {
        let same = out.iter().any(|k| {
            let (dt, dr) = pose_distance(&k.pose, &c.pose);
            dt <= cfg.same_answer_m && dr <= cfg.same_answer_deg.to_radians()
        });
        if !same {
            out.push(c);
        }
    }
    out
}

/// `Some(reason)` when the evidence does not support the estimate.
fn verdict(r: &GlobalResult, cfg: &GlobalConfig) -> Option<String> {
    let hint = "the maps may not overlap, or overlap too little";
    if r.inliers < cfg.min_inliers {
        return Some(format!(
            "after alignment only {} structure voxels of the new map lie on the old map (need {}): {hint}",
            r.inliers, cfg.min_inliers
        ));
    }
    if r.inlier_ratio < cfg.min_inlier_ratio {
        return Some(format!(
            "after alignment only {:.0} % of the structure lies on the other map where both surveyed \
             (need {:.0} %): {hint}, or the site changed a lot",
            100.0 * r.inlier_ratio,
            100.0 * cfg.min_inlier_ratio
        ));
    }
    if r.runner_up_ratio > cfg.max_runner_up_ratio {
        return Some(format!(
            "ambiguous: a different transform is supported {:.0} % as well as the best one \
             (allowed {:.0} %): repetitive or symmetric structure",
            100.0 * r.runner_up_ratio,
            100.0 * cfg.max_runner_up_ratio
        ));
    }
    None
}

/// Feature correspondences within `bound_m` under `t`.
fn count_inliers(cs: &[Vector3<f64>], ct: &[Vector3<f64>], t: &Pose, bound_m: f64) -> usize {
    cs.iter().zip(ct).filter(|&(s, d)| (t * Point3::from(*s) - Point3::from(*d)).norm() <= bound_m).count()
}

fn empty_result(tgt: &MapCloud, src: &MapCloud) -> GlobalResult {
    GlobalResult {
        t_target_source: Pose::identity(),
        verdict: Verdict::Failure { reason: String::new() },
        correspondences: 0,
        feature_inliers: 0,
        inliers: 0,
        inlier_ratio: 0.0,
        overlap_fraction: 0.0,
        clique_size: 0,
        runner_up_ratio: 0.0,
        hypotheses: 0,
        refined: 0,
        target_points: tgt.len(),
        source_points: src.len(),
        elapsed_s: 0.0,
        timings: GlobalTimings::default(),
    }
}

fn fail(mut r: GlobalResult, start: Instant, timings: GlobalTimings, reason: String) -> GlobalResult {
    r.verdict = Verdict::Failure {
        reason: format!("{reason}; the session stays unaligned (pass an initial guess to align it by hand)"),
    };
    r.elapsed_s = start.elapsed().as_secs_f64();
    r.timings = timings;
    r
}

#[cfg(test)]
mod tests {
    use super::*;

    fn reason(r: &GlobalResult) -> &str {
        match &r.verdict {
            Verdict::Failure { reason } => reason,
            Verdict::Success => "",
        }
    }

    #[test]
    fn empty_and_tiny_maps_fail_with_a_reason() {
        let cfg = GlobalConfig::default();
        let tiny: Vec<[f32; 3]> = (0..50).map(|i| [i as f32 * 0.1, 0.0, 0.0]).collect();
        for (t, s) in [(&[][..], &[][..]), (&tiny[..], &tiny[..])] {
            let r = register_maps(t, s, &cfg);
            assert!(reason(&r).contains("too little structure"), "{:?}", r.verdict);
            assert!(reason(&r).contains("unaligned"));
            assert_eq!(r.t_target_source, Pose::identity());
        }
    }

    #[test]
    fn invalid_settings_fail_before_any_work() {
        for cfg in [
            GlobalConfig { voxel_size_m: 0.0, ..GlobalConfig::default() },
            GlobalConfig { feature_radius_m: f64::NAN, ..GlobalConfig::default() },
            GlobalConfig { normal_radius_m: 0.6, ..GlobalConfig::default() },
            GlobalConfig { min_inlier_ratio: 62.0, ..GlobalConfig::default() },
        ] {
            let r = register_maps(&[[0.0; 3]], &[[0.0; 3]], &cfg);
            assert!(reason(&r).starts_with("invalid global registration settings"), "{:?}", r.verdict);
        }
    }

    #[test]
    fn config_reads_from_toml_naming_only_what_changes() {
        let cfg: GlobalConfig = toml::from_str("voxel_size_m = 0.7\ngravity_aligned = false").unwrap();
        assert_eq!(cfg.voxel_size_m, 0.7);
        assert!(!cfg.gravity_aligned);
        assert_eq!(cfg.feature_radius_m, GlobalConfig::default().feature_radius_m);
        assert!(toml::from_str::<GlobalConfig>("voxel_sise_m = 0.7").is_err());
        assert!(GlobalConfig::default().validate().is_ok());
    }
}
