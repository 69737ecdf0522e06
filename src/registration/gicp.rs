//! Generalized ICP (Segal, Haehnel, Thrun 2009) on SE(3), MATH.md §3.
//!
//! Written by hand, because no Rust crate gives what seam needs. The Rust ICP
//! crates are point-to-point or point-to-plane; `fast-gicp` binds the C++
//! fast_gicp (a C++/OpenMP build in our dependency tree); the GICP inside the
//! general-purpose `threecrate-algorithms` works in `f32` and returns a pose,
//! an MSE and correspondences but no Hessian. The loop closures need the
//! final 6×6 Hessian (edge information), the source points that found a
//! correspondence (DOP test), `f64` poses and the shrinking correspondence
//! distance of MATH.md §3; with kiddo doing the neighbour search, the rest
//! is a few hundred lines that are tested here against small_gicp.
//! The structure follows small_gicp (Koide 2024): preprocess once, then
//! linearise in parallel with per-thread `H, b` reduced, Levenberg-Marquardt
//! steps evaluated on the fixed correspondences.
//!
//! Cost, for source point `a_i` with covariance `C_i` matched to target point
//! `b_j` with covariance `C_j`, pose `T = (R, t) = t_target_source`:
//!
//! ```text
//! r_i = b_j − T a_i,   M_i = (C_j + R C_i Rᵀ)⁻¹,   E(T) = ½ Σ r_iᵀ M_i r_i
//! ```
//!
//! With the right perturbation `T ← T Exp([ω; v])`, `∂r_i/∂[ω; v] = [R [a_i]×, −R]`.
//! `M_i` is held fixed while differentiating (as Segal and small_gicp do).

use super::covariance::estimate_covariances;
use super::downsample::{Point3Like, voxel_downsample};
use super::kdtree::{KdTree, to_f32};
use crate::geometry::Pose;
use crate::geometry::se3::se3_exp;
use nalgebra::{Matrix3, Matrix6, Vector3, Vector6};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// GICP settings (MATH.md §3). Every field has a default; a TOML section
/// names only what it changes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GicpConfig {
    /// Voxel size of the downsampling before everything else (choice: 0.25 m,
    /// small_gicp's default; the KITTI/HDL-32E benchmarks in
    /// `bench/gicp_vs_small_gicp.py` are run at this size).
    pub voxel_size_m: f64,
    /// Neighbours per covariance (MATH.md: 20).
    pub k_neighbors: usize,
    /// Smallest eigenvalue of the plane-regularised covariances (MATH.md: 1e-3).
    pub plane_epsilon: f64,
    /// Correspondences farther than this are rejected in the first iteration…
    pub max_corr_dist_start_m: f64,
    /// …and the distance shrinks to this (MATH.md: 2 m → 0.5 m).
    pub max_corr_dist_end_m: f64,
    /// Each iteration multiplies the max distance by this factor until it
    /// reaches `max_corr_dist_end_m` (choice: 0.5, i.e. 2 → 1 → 0.5 m. On the
    /// HDL-32E test pair, 0.7 reached the same poses, within 0.05°, from 24
    /// perturbed starts but took 7 iterations instead of 5.)
    pub max_corr_dist_shrink: f64,
    /// Outer (linearisation) iterations at most.
    pub max_iterations: usize,
    /// Converged when a step rotates less than this… (small_gicp: 0.1°)
    pub rotation_eps_rad: f64,
    /// …and translates less than this, at the final max distance (small_gicp: 1 mm).
    pub translation_eps_m: f64,
    /// Use rayon for preprocessing and linearisation.
    pub parallel: bool,
}

impl Default for GicpConfig {
    fn default() -> Self {
        GicpConfig {
            voxel_size_m: 0.25,
            k_neighbors: 20,
            plane_epsilon: 1e-3,
            max_corr_dist_start_m: 2.0,
            max_corr_dist_end_m: 0.5,
            max_corr_dist_shrink: 0.5,
            max_iterations: 30,
            rotation_eps_rad: 0.1f64.to_radians(),
            translation_eps_m: 1e-3,
            parallel: true,
        }
    }
}

/// Levenberg-Marquardt constants (small_gicp's): λ starts tiny, so a good
/// step is a Gauss-Newton step; a rejected one is retried with λ × 10.
const LM_INIT_LAMBDA: f64 = 1e-3;
const LM_FACTOR: f64 = 10.0;
const LM_MAX_INNER: usize = 10;
/// Fewer correspondences than this cannot constrain 6 degrees of freedom.
const MIN_INLIERS: usize = 6;
/// Source points per parallel work item; the partial sums are added in
/// chunk order, so the parallel result does not depend on the thread count.
const CHUNK: usize = 512;
const NO_MATCH: u32 = u32::MAX;

/// A downsampled cloud with per-point plane covariances and a kd-tree.
///
/// Any prepared cloud can serve as source or as target, and a target can be
/// reused across many sources (see [`GicpTarget`]).
#[derive(Debug)]
pub struct PreparedCloud {
    points: Vec<[f64; 3]>,
    covs: Vec<Matrix3<f64>>,
    tree: KdTree,
}

/// A preprocessed target: the same thing as a [`PreparedCloud`].
pub type GicpTarget = PreparedCloud;

impl PreparedCloud {
    /// Downsampled points, in the cloud's own frame.
    pub fn points(&self) -> &[[f64; 3]] {
        &self.points
    }
    /// Plane-regularised covariances, one per point.
    pub fn covariances(&self) -> &[Matrix3<f64>] {
        &self.covs
    }
    pub fn tree(&self) -> &KdTree {
        &self.tree
    }
    pub fn len(&self) -> usize {
        self.points.len()
    }
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }
}

/// Downsamples `points` (`cfg.voxel_size_m`), builds the kd-tree and estimates
/// the covariances: everything GICP needs of a cloud, done once.
pub fn preprocess<P: Point3Like>(points: &[P], cfg: &GicpConfig) -> PreparedCloud {
    let points = voxel_downsample(points, cfg.voxel_size_m, cfg.parallel);
    let tree = KdTree::build(&points);
    let covs = estimate_covariances(&points, &tree, cfg.k_neighbors, cfg.plane_epsilon, cfg.parallel);
    PreparedCloud { points, covs, tree }
}

/// The outcome of [`align`], with the diagnostics the loop-closure test needs.
#[derive(Debug, Clone)]
pub struct GicpResult {
    /// The estimate: moves source points into the target frame.
    pub t_target_source: Pose,
    /// True when a step fell below the epsilons at the final max distance.
    pub converged: bool,
    /// Outer iterations run (linearisations).
    pub iterations: usize,
    /// Correspondences in the last linearisation.
    pub num_inliers: usize,
    /// Mean squared **Euclidean** distance (m²) of the inlier pairs in the last
    /// linearisation (the Mahalanobis cost is in [`Self::error`]).
    pub fitness: f64,
    /// `num_inliers / source.len()`.
    pub inlier_ratio: f64,
    /// The GICP cost `½ Σ rᵀ M r` at the last linearisation.
    pub error: f64,
    /// Gauss-Newton Hessian `Σ Jᵀ M J` of the last linearisation, in the
    /// tangent space `[ω; v]` at the estimate. Its scale follows the
    /// plane-regularised covariances (unit variance in the plane, ε along the
    /// normal), not the sensor's noise: scale it before using it as an
    /// information matrix.
    pub hessian: Matrix6<f64>,
    /// Indices into `source_points` of the points with a correspondence in
    /// the last linearisation (ascending).
    pub corresponded_source: Vec<usize>,
    /// The preprocessed source, in the source frame.
    pub source_points: Vec<[f64; 3]>,
    /// The max correspondence distance of the last linearisation (m).
    pub final_max_corr_dist_m: f64,
}

/// `H`, `b`, cost and counts of one linearisation (or of a part of one).
#[derive(Debug, Clone, Copy)]
struct LinearSystem {
    h: Matrix6<f64>,
    b: Vector6<f64>,
    error: f64,
    inliers: usize,
    sq_dist_sum: f64,
}

impl LinearSystem {
    fn zero() -> Self {
        LinearSystem { h: Matrix6::zeros(), b: Vector6::zeros(), error: 0.0, inliers: 0, sq_dist_sum: 0.0 }
    }
    fn add(mut self, o: &LinearSystem) -> Self {
        self.h += o.h;
        self.b += o.b;
        self.error += o.error;
        self.inliers += o.inliers;
        self.sq_dist_sum += o.sq_dist_sum;
        self
    }
}

/// A source point's correspondence, kept between linearisation and the LM
/// error evaluations. `mahalanobis` is `M' = Rᵀ M R = (Rᵀ C_j R + C_i)⁻¹`,
/// in the source frame rotated by the linearisation's `R`.
#[derive(Debug, Clone, Copy)]
struct Correspondence {
    target: u32,
    mahalanobis: Matrix3<f64>,
}

impl Correspondence {
    const NONE: Correspondence =
        Correspondence { target: NO_MATCH, mahalanobis: Matrix3::new(0., 0., 0., 0., 0., 0., 0., 0., 0.) };
}

#[inline]
fn cross_columns(a: &Vector3<f64>, m: &Matrix3<f64>) -> Matrix3<f64> {
    Matrix3::from_columns(&[a.cross(&m.column(0)), a.cross(&m.column(1)), a.cross(&m.column(2))])
}

/// Linearises the source points of one slice: nearest target point within
/// `max_d2` (squared), Mahalanobis matrix, and `H`, `b`, cost.
///
/// The algebra runs in the source frame rotated by `R` (`J = R [[a]×, −I]`,
/// `M' = Rᵀ M R`), where the blocks of `Jᵀ M J` are cross products:
/// `H_vv = M'`, `H_ωv = [a]× M'`, `H_ωω = −[a]× M' [a]×`, and with
/// `g = M' Rᵀ r`: `b = [g × a; −g]`. Half the flops of the plain product
/// (tested against it and against central differences).
fn linearize_slice(
    target: &PreparedCloud,
    points: &[[f64; 3]],
    covs: &[Matrix3<f64>],
    corr: &mut [Correspondence],
    t: &Pose,
    max_d2: f64,
) -> LinearSystem {
    let r = t.rotation.to_rotation_matrix().into_inner();
    let rt = r.transpose();
    let tr = t.translation.vector;
    let (mut h_ww, mut h_wv, mut h_vv) = (Matrix3::zeros(), Matrix3::zeros(), Matrix3::zeros());
    let (mut b_w, mut b_v) = (Vector3::zeros(), Vector3::zeros());
    let mut sys = LinearSystem::zero();
    for ((a, c_s), out) in points.iter().zip(covs).zip(corr.iter_mut()) {
        let a = Vector3::from(*a);
        let q = r * a + tr;
        *out = Correspondence::NONE;
        let Some((j, d2)) = target.tree.nearest(&to_f32(&[q.x, q.y, q.z])) else { continue };
        if d2 as f64 > max_d2 {
            continue;
        }
        let Some(m) = (rt * target.covs[j] * r + c_s).try_inverse() else { continue };
        let res_world = Vector3::from(target.points[j]) - q;
        let res = rt * res_world;
        let g = m * res;
        let x = cross_columns(&a, &m); // [a]× M'
        // Row i of −[a]× M' [a]× is a × (row i of [a]× M'), i.e. column i of
        // −(x [a]×)ᵀ; M' symmetric makes the block symmetric.
        let xt = x.transpose();
        h_ww += cross_columns(&a, &xt).transpose();
        h_wv += x;
        h_vv += m;
        b_w += g.cross(&a);
        b_v -= g;
        sys.error += 0.5 * res.dot(&g);
        sys.inliers += 1;
        sys.sq_dist_sum += res_world.norm_squared();
        *out = Correspondence { target: j as u32, mahalanobis: m };
    }
    sys.h.fixed_view_mut::<3, 3>(0, 0).copy_from(&h_ww);
    sys.h.fixed_view_mut::<3, 3>(0, 3).copy_from(&h_wv);
    sys.h.fixed_view_mut::<3, 3>(3, 0).copy_from(&h_wv.transpose());
    sys.h.fixed_view_mut::<3, 3>(3, 3).copy_from(&h_vv);
    sys.b.fixed_rows_mut::<3>(0).copy_from(&b_w);
    sys.b.fixed_rows_mut::<3>(3).copy_from(&b_v);
    sys
}

/// The cost `½ Σ rᵀ M r` at pose `t` on fixed correspondences linearised at
/// rotation `r_lin` (so `rᵀ M r = (r_linᵀ r)ᵀ M' (r_linᵀ r)`).
fn error_slice(
    target: &PreparedCloud,
    points: &[[f64; 3]],
    corr: &[Correspondence],
    r_lin: &Matrix3<f64>,
    t: &Pose,
) -> f64 {
    // Fold r_linᵀ into the pose: r_linᵀ (b − R a − t) = r_linᵀ b − (r_linᵀ R) a − r_linᵀ t.
    let r_lin_t = r_lin.transpose();
    let r = r_lin_t * t.rotation.to_rotation_matrix().into_inner();
    let tr = r_lin_t * t.translation.vector;
    let mut e = 0.0;
    for (a, c) in points.iter().zip(corr) {
        if c.target == NO_MATCH {
            continue;
        }
        let res = r_lin_t * Vector3::from(target.points[c.target as usize]) - (r * Vector3::from(*a) + tr);
        e += 0.5 * res.dot(&(c.mahalanobis * res));
    }
    e
}

fn linearize(
    target: &PreparedCloud,
    source: &PreparedCloud,
    corr: &mut [Correspondence],
    t: &Pose,
    max_d2: f64,
    parallel: bool,
) -> LinearSystem {
    if !parallel {
        return linearize_slice(target, &source.points, &source.covs, corr, t, max_d2);
    }
    let parts: Vec<LinearSystem> = source
        .points
        .par_chunks(CHUNK)
        .zip(source.covs.par_chunks(CHUNK))
        .zip(corr.par_chunks_mut(CHUNK))
        .map(|((p, c), out)| linearize_slice(target, p, c, out, t, max_d2))
        .collect();
    parts.iter().fold(LinearSystem::zero(), |acc, s| acc.add(s))
}

fn total_error(
    target: &PreparedCloud,
    source: &PreparedCloud,
    corr: &[Correspondence],
    t_lin: &Pose,
    t: &Pose,
    parallel: bool,
) -> f64 {
    let r_lin = t_lin.rotation.to_rotation_matrix().into_inner();
    if !parallel {
        return error_slice(target, &source.points, corr, &r_lin, t);
    }
    let parts: Vec<f64> = source
        .points
        .par_chunks(CHUNK)
        .zip(corr.par_chunks(CHUNK))
        .map(|(p, c)| error_slice(target, p, c, &r_lin, t))
        .collect();
    parts.iter().sum()
}

/// One Levenberg-Marquardt step from `t`: the first damped Gauss-Newton step
/// that does not increase the cost on the current correspondences.
fn lm_step(
    target: &PreparedCloud,
    source: &PreparedCloud,
    corr: &[Correspondence],
    sys: &LinearSystem,
    t: &Pose,
    lambda: &mut f64,
    parallel: bool,
) -> Option<(Pose, Vector6<f64>)> {
    for _ in 0..LM_MAX_INNER {
        let damped = sys.h + Matrix6::identity() * *lambda;
        let step = damped.cholesky().map(|c| c.solve(&-sys.b));
        if let Some(delta) = step.filter(|d| d.iter().all(|v| v.is_finite())) {
            let t_new = t * se3_exp(&delta);
            if total_error(target, source, corr, t, &t_new, parallel) <= sys.error {
                *lambda /= LM_FACTOR;
                return Some((t_new, delta));
            }
        }
        *lambda *= LM_FACTOR;
    }
    None
}

/// Registers `source` to `target` from `t_init` (an estimate of
/// `t_target_source`).
pub fn align(target: &GicpTarget, source: &PreparedCloud, t_init: &Pose, cfg: &GicpConfig) -> GicpResult {
    let mut corr = vec![Correspondence::NONE; source.len()];
    let mut t = *t_init;
    let end = cfg.max_corr_dist_end_m.min(cfg.max_corr_dist_start_m);
    let mut max_dist = cfg.max_corr_dist_start_m;
    let mut lambda = LM_INIT_LAMBDA;
    let mut converged = false;
    let mut iterations = 0;
    let mut last = LinearSystem::zero();
    let mut last_dist = max_dist;
    while iterations < cfg.max_iterations {
        iterations += 1;
        last = linearize(target, source, &mut corr, &t, max_dist * max_dist, cfg.parallel);
        last_dist = max_dist;
        if last.inliers < MIN_INLIERS {
            break;
        }
        let at_end = max_dist <= end;
        let small = |d: &Vector6<f64>| {
            d.fixed_rows::<3>(0).norm() < cfg.rotation_eps_rad && d.fixed_rows::<3>(3).norm() < cfg.translation_eps_m
        };
        match lm_step(target, source, &corr, &last, &t, &mut lambda, cfg.parallel) {
            Some((t_new, delta)) => {
                t = t_new;
                if at_end && small(&delta) {
                    converged = true;
                    break;
                }
            }
            // No damped step lowers the cost: a minimum for these correspondences.
            None if at_end => {
                converged = true;
                break;
            }
            None => {}
        }
        max_dist = (max_dist * cfg.max_corr_dist_shrink).max(end);
    }
    let corresponded_source: Vec<usize> =
        corr.iter().enumerate().filter(|(_, c)| c.target != NO_MATCH).map(|(i, _)| i).collect();
    GicpResult {
        t_target_source: t,
        converged,
        iterations,
        num_inliers: last.inliers,
        fitness: if last.inliers > 0 { last.sq_dist_sum / last.inliers as f64 } else { f64::INFINITY },
        inlier_ratio: if source.is_empty() { 0.0 } else { last.inliers as f64 / source.len() as f64 },
        error: last.error,
        hessian: last.h,
        corresponded_source,
        source_points: source.points.clone(),
        final_max_corr_dist_m: last_dist,
    }
}

#[cfg(test)]
#[path = "gicp_tests.rs"]
mod tests;
