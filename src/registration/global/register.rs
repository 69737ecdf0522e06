//! [`register_maps`]: the steps of the module doc as one page, and the verdict.

use std::time::Instant;

use nalgebra::{Point3, Vector3};

use super::bev::{BevParams, bev_hypotheses};
use super::clique::consistency_graph;
use super::cloud::MapCloud;
use super::fpfh::compute_fpfh;
use super::matching::{Correspondence, mutual_matches};
use super::robust::{Dof, RobustParams, hypotheses};
use super::verify::{RefineParams, Score, coverage, pose_distance, refine, score, v3};
use super::{GlobalConfig, GlobalResult, GlobalTimings, Verdict};
use crate::geometry::Pose;
use crate::registration::downsample::voxel_downsample;

/// Fewer descriptors than this on either map cannot be matched meaningfully.
const MIN_DESCRIPTORS: usize = 20;

/// A hypothesis after refinement, with its score.
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

    // 5. Refine every hypothesis on the maps and score it.
    let sample = voxel_downsample(&src.points, 2.0 * cfg.voxel_size_m, true);
    let cells = coverage(&tgt, cfg.coverage_cell_m);
    let refine_params = RefineParams {
        max_dist_start_m: cfg.refine_start_m,
        max_dist_end_m: cfg.voxel_size_m,
        iterations: cfg.refine_iterations,
        dof,
    };
    let checked: Vec<Checked> = hyps
        .iter()
        .map(|&(init, clique)| {
            let pose = refine(&tgt, &sample, &init, &refine_params);
            let score = score(&tgt, &cells, cfg.coverage_cell_m, &src, &pose, cfg.match_distance_m);
            Checked { pose, clique, score }
        })
        .collect();
    tick(&mut timings.verify_s);
    if std::env::var("SEAM_GLOBAL_DEBUG").is_ok() {
        for (h, c) in hyps.iter().zip(&checked) {
            let e = c.pose.rotation.euler_angles();
            let e0 = h.0.rotation.euler_angles();
            eprintln!(
                "hyp clique {} init yaw {:.1} t {:.2?} -> yaw {:.1} rp {:.2} {:.2} t {:.2?} score {:?} fit {:.3}",
                c.clique,
                e0.2.to_degrees(),
                h.0.translation.vector.as_slice(),
                e.2.to_degrees(),
                e.0.to_degrees(),
                e.1.to_degrees(),
                c.pose.translation.vector.as_slice(),
                c.score,
                c.score.structure_fit()
            );
        }
    }

    // 6. The winner, its evidence, and the verdict.
    let best = checked
        .iter()
        .enumerate()
        .max_by(|(ia, a), (ib, b)| a.score.matched.cmp(&b.score.matched).then(a.clique.cmp(&b.clique)).then(ib.cmp(ia)))
        .map(|(i, _)| i)
        .unwrap_or(0);
    let win = &checked[best];
    let runner_up = checked
        .iter()
        .filter(|c| {
            let (dt, dr) = pose_distance(&c.pose, &win.pose);
            dt > cfg.same_answer_m || dr > cfg.same_answer_deg.to_radians()
        })
        .map(|c| c.score.matched)
        .max()
        .unwrap_or(0);
    result.t_target_source = win.pose;
    result.clique_size = win.clique;
    result.inliers = count_inliers(&corr, &cs, &ct, &win.pose, cfg.noise_bound_m);
    result.inlier_ratio = result.inliers as f64 / corr.len().max(1) as f64;
    result.overlap_fraction = win.score.overlap_fraction();
    result.structure_fit = win.score.structure_fit();
    result.matched_structure = win.score.matched;
    result.runner_up_ratio = if win.score.matched > 0 { runner_up as f64 / win.score.matched as f64 } else { 0.0 };
    match verdict(&result, cfg) {
        Some(reason) => fail(result, start, timings, reason),
        None => {
            result.verdict = Verdict::Success;
            result.elapsed_s = start.elapsed().as_secs_f64();
            result.timings = timings;
            result
        }
    }
}

/// `Some(reason)` when the evidence does not support the estimate.
fn verdict(r: &GlobalResult, cfg: &GlobalConfig) -> Option<String> {
    let hint = "the maps may not overlap, or overlap too little";
    if r.inliers < cfg.min_inliers {
        return Some(format!(
            "only {} of {} feature matches agree with the best estimate (need {}): {hint}",
            r.inliers, r.correspondences, cfg.min_inliers
        ));
    }
    if r.structure_fit < cfg.min_structure_fit {
        return Some(format!(
            "after alignment only {:.0} % of the new map's structure lies on the old map where both surveyed \
             (need {:.0} %): {hint}, or the site changed a lot",
            100.0 * r.structure_fit,
            100.0 * cfg.min_structure_fit
        ));
    }
    if r.matched_structure < cfg.min_matched_structure {
        return Some(format!(
            "only {} structure voxels of the new map match the old map (need {}): {hint}",
            r.matched_structure, cfg.min_matched_structure
        ));
    }
    if r.runner_up_ratio > cfg.max_runner_up_ratio {
        return Some(format!(
            "ambiguous: a different transform explains {:.0} % as much of the map as the best one \
             (allowed {:.0} %); repetitive or symmetric structure?",
            100.0 * r.runner_up_ratio,
            100.0 * cfg.max_runner_up_ratio
        ));
    }
    None
}

fn count_inliers(corr: &[Correspondence], cs: &[Vector3<f64>], ct: &[Vector3<f64>], t: &Pose, bound_m: f64) -> usize {
    (0..corr.len()).filter(|&k| (t * Point3::from(cs[k]) - Point3::from(ct[k])).norm() <= bound_m).count()
}

fn empty_result(tgt: &MapCloud, src: &MapCloud) -> GlobalResult {
    GlobalResult {
        t_target_source: Pose::identity(),
        verdict: Verdict::Failure { reason: String::new() },
        correspondences: 0,
        inliers: 0,
        inlier_ratio: 0.0,
        overlap_fraction: 0.0,
        structure_fit: 0.0,
        matched_structure: 0,
        clique_size: 0,
        runner_up_ratio: 0.0,
        hypotheses: 0,
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
