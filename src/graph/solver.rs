//! Levenberg-Marquardt on the sparse normal equations, solved with faer's
//! sparse Cholesky. Robust kernels enter as IRLS weights `ρ'(s)`.

use super::factors::{between_residual_and_jacobians, prior_residual_and_jacobian};
use super::{GraphConfig, PoseGraph};
use crate::geometry::se3::se3_exp;
use faer::linalg::solvers::Solve;
use faer::sparse::{SparseColMat, Triplet};
use faer::{Mat, Side};
use nalgebra::{Matrix6, Vector6};
use rayon::prelude::*;
use std::collections::HashMap;

#[derive(Debug, thiserror::Error)]
pub enum SolveError {
    #[error("pose graph has no free variable")]
    NothingToSolve,
    #[error(
        "the normal equations are not positive definite even with damping {lambda:e}: the graph is under-constrained"
    )]
    NotPositiveDefinite { lambda: f64 },
    #[error("sparse matrix assembly failed: {0}")]
    Assembly(String),
}

/// What an optimisation did.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct OptimizeReport {
    pub iterations: usize,
    pub initial_cost: f64,
    pub final_cost: f64,
    pub converged: bool,
    pub free_variables: usize,
    pub factors: usize,
}

/// One factor linearised: the free variable blocks it touches, `Jᵀ W J` and `Jᵀ W r` pieces.
struct Linearized {
    cost: f64,
    blocks: Vec<(usize, Matrix6<f64>)>,
    weighted_r: Vector6<f64>,
    weight_info: Matrix6<f64>,
}

/// Maps variables to free block indices (`None` when held constant).
struct Layout {
    anchor_block: Vec<Option<usize>>,
    local_block: Vec<Option<usize>>,
    n_blocks: usize,
}

impl Layout {
    fn new(g: &PoseGraph) -> Layout {
        let mut n = 0;
        let mut next = |fixed: bool| {
            if fixed {
                None
            } else {
                n += 1;
                Some(n - 1)
            }
        };
        let anchor_block = g.anchor_fixed.iter().map(|&f| next(f)).collect();
        let local_block = g.local_fixed.iter().map(|&f| next(f)).collect();
        Layout { anchor_block, local_block, n_blocks: n }
    }
}

fn linearize_all(g: &PoseGraph, lay: &Layout) -> Vec<Linearized> {
    let betweens = g.betweens.par_iter().map(|f| {
        let (ai, aj) = (g.keyframe_anchor[f.i], g.keyframe_anchor[f.j]);
        let (r, jac) =
            between_residual_and_jacobians(&f.z, &g.anchors[ai], &g.locals[f.i], &g.anchors[aj], &g.locals[f.j]);
        let s = r.dot(&(f.information * r));
        let (rho, w) = f.robust.eval(s);
        let mut blocks = Vec::with_capacity(4);
        if ai != aj {
            if let Some(b) = lay.anchor_block[ai] {
                blocks.push((b, jac.d_anchor_i));
            }
            if let Some(b) = lay.anchor_block[aj] {
                blocks.push((b, jac.d_anchor_j));
            }
        }
        if let Some(b) = lay.local_block[f.i] {
            blocks.push((b, jac.d_local_i));
        }
        if let Some(b) = lay.local_block[f.j] {
            blocks.push((b, jac.d_local_j));
        }
        let weight_info = f.information * w;
        Linearized { cost: rho, blocks, weighted_r: weight_info * r, weight_info }
    });
    let priors = g.priors.par_iter().map(|p| {
        let (r, j) = prior_residual_and_jacobian(&p.value, &g.anchors[p.anchor]);
        let s = r.dot(&(p.information * r));
        let blocks = lay.anchor_block[p.anchor].map(|b| vec![(b, j)]).unwrap_or_default();
        Linearized { cost: s, blocks, weighted_r: p.information * r, weight_info: p.information }
    });
    betweens.chain(priors).collect()
}

fn total_cost(g: &PoseGraph, lay: &Layout) -> f64 {
    linearize_all(g, lay).iter().map(|l| l.cost).sum()
}

/// Applies `X ← X · Exp(δ)` to every free variable.
fn retract(g: &PoseGraph, lay: &Layout, delta: &Mat<f64>) -> PoseGraph {
    let mut out = g.clone();
    let step = |b: usize| Vector6::from_fn(|k, _| delta[(6 * b + k, 0)]);
    for (a, blk) in lay.anchor_block.iter().enumerate() {
        if let Some(b) = blk {
            out.anchors[a] = g.anchors[a] * se3_exp(&step(*b));
        }
    }
    for (i, blk) in lay.local_block.iter().enumerate() {
        if let Some(b) = blk {
            out.locals[i] = g.locals[i] * se3_exp(&step(*b));
        }
    }
    out
}

/// Optimises `g` in place with Levenberg-Marquardt.
pub fn optimize(g: &mut PoseGraph, cfg: &GraphConfig) -> Result<OptimizeReport, SolveError> {
    let lay = Layout::new(g);
    if lay.n_blocks == 0 {
        return Err(SolveError::NothingToSolve);
    }
    let n = 6 * lay.n_blocks;
    let mut lambda = 1e-4;
    let mut lin = linearize_all(g, &lay);
    let initial_cost: f64 = lin.iter().map(|l| l.cost).sum();
    let mut cost = initial_cost;
    let mut converged = false;
    let mut iterations = 0;

    while iterations < cfg.max_iterations {
        iterations += 1;
        // Normal equations, lower triangle in 6×6 blocks.
        let mut h_blocks: HashMap<(usize, usize), Matrix6<f64>> = HashMap::new();
        let mut b = vec![0.0; n];
        for l in &lin {
            for (p, (bp, jp)) in l.blocks.iter().enumerate() {
                let jtw = jp.transpose() * l.weight_info;
                let g_p = jp.transpose() * l.weighted_r;
                for k in 0..6 {
                    b[6 * bp + k] += g_p[k];
                }
                for (bq, jq) in &l.blocks[..=p] {
                    let block = jtw * jq;
                    let (row, col, m) = if bp >= bq { (*bp, *bq, block) } else { (*bq, *bp, block.transpose()) };
                    *h_blocks.entry((row, col)).or_insert_with(Matrix6::zeros) += m;
                }
            }
        }
        let mut accepted = false;
        for _attempt in 0..12 {
            let mut triplets = Vec::with_capacity(h_blocks.len() * 36);
            for (&(br, bc), m) in &h_blocks {
                for r in 0..6 {
                    for c in 0..6 {
                        let (row, col) = (6 * br + r, 6 * bc + c);
                        if row < col {
                            continue;
                        }
                        let mut v = m[(r, c)];
                        if row == col {
                            v += lambda * (v.abs() + 1e-9);
                        }
                        triplets.push(Triplet::new(row, col, v));
                    }
                }
            }
            let h = SparseColMat::<usize, f64>::try_new_from_triplets(n, n, &triplets)
                .map_err(|e| SolveError::Assembly(format!("{e:?}")))?;
            let llt = match h.sp_cholesky(Side::Lower) {
                Ok(l) => l,
                Err(_) => {
                    lambda *= 10.0;
                    continue;
                }
            };
            let rhs = Mat::from_fn(n, 1, |i, _| -b[i]);
            let delta = llt.solve(&rhs);
            let candidate = retract(g, &lay, &delta);
            let new_cost = total_cost(&candidate, &lay);
            if new_cost.is_finite() && new_cost <= cost {
                let decrease = (cost - new_cost) / cost.max(1e-300);
                *g = candidate;
                cost = new_cost;
                lambda = (lambda / 3.0).max(1e-12);
                accepted = true;
                let step_norm = (0..n).map(|i| delta[(i, 0)] * delta[(i, 0)]).sum::<f64>().sqrt();
                if decrease < cfg.relative_cost_tolerance || step_norm < 1e-10 {
                    converged = true;
                }
                break;
            }
            lambda *= 4.0;
        }
        if !accepted {
            // No step decreases the cost: we are at a minimum (or stuck).
            converged = lambda > 1e6;
            if !converged {
                return Err(SolveError::NotPositiveDefinite { lambda });
            }
            break;
        }
        if converged {
            break;
        }
        lin = linearize_all(g, &lay);
    }
    Ok(OptimizeReport {
        iterations,
        initial_cost,
        final_cost: cost,
        converged,
        free_variables: lay.n_blocks,
        factors: g.betweens.len() + g.priors.len(),
    })
}

#[cfg(test)]
mod tests {
    use super::super::{Between, GraphConfig, PoseGraph, Robust, information};
    use super::*;
    use crate::geometry::Pose;
    use nalgebra::{Translation3, UnitQuaternion, Vector3};

    fn t(x: f64, y: f64, yaw: f64) -> Pose {
        Pose::from_parts(Translation3::new(x, y, 0.0), UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw))
    }

    /// A wrong loop closure under a Cauchy kernel barely moves the graph.
    #[test]
    fn cauchy_kernel_discounts_a_wrong_loop() {
        let mut g = PoseGraph::default();
        let a0 = g.add_anchor(Pose::identity(), true);
        let a1 = g.add_anchor(t(10.0, 0.0, 0.0), false);
        for k in 0..20 {
            let a = if k < 10 { a0 } else { a1 };
            let origin = if k < 10 { 0.0 } else { 10.0 };
            g.add_keyframe(a, t(k as f64 - origin, 0.0, 0.0), k % 10 == 0);
        }
        let info = information(0.01, 0.01);
        for k in 0..19 {
            g.betweens.push(Between { i: k, j: k + 1, z: t(1.0, 0.0, 0.0), information: info, robust: Robust::None });
        }
        // Claims keyframe 19 sits 5 m to the side of keyframe 0.
        g.betweens.push(Between {
            i: 0,
            j: 19,
            z: t(19.0, 5.0, 0.0),
            information: information(0.01, 0.1),
            robust: Robust::Cauchy { k: 1.0 },
        });
        optimize(&mut g, &GraphConfig::default()).unwrap();
        let moved = (g.world_pose(19).translation.vector - Vector3::new(19.0, 0.0, 0.0)).norm();
        assert!(moved < 0.05, "a wrong loop moved the trajectory by {moved} m");
    }

    /// A square loop of 40 keyframes in 4 submaps, odometry with a yaw bias,
    /// and one loop closure: the optimised loop must close.
    #[test]
    fn loop_closure_removes_drift_across_submaps() {
        let truth: Vec<Pose> = (0..40)
            .map(|k| {
                let side = k / 10;
                let s = (k % 10) as f64;
                let yaw = side as f64 * std::f64::consts::FRAC_PI_2;
                let corner = [(0.0, 0.0), (10.0, 0.0), (10.0, 10.0), (0.0, 10.0)][side];
                t(corner.0 + s * yaw.cos(), corner.1 + s * yaw.sin(), yaw)
            })
            .collect();
        let bias = t(0.0, 0.0, 0.01);
        let odo: Vec<Pose> = truth.windows(2).map(|w| w[0].inverse() * w[1] * bias).collect();
        let mut g = PoseGraph::default();
        // Initial values by dead reckoning; submaps of 10 keyframes.
        let mut dr = vec![truth[0]];
        for z in &odo {
            let last = *dr.last().unwrap();
            dr.push(last * z);
        }
        for m in 0..4 {
            let a = g.add_anchor(dr[10 * m], m == 0);
            for k in 10 * m..10 * m + 10 {
                g.add_keyframe(a, dr[10 * m].inverse() * dr[k], k == 10 * m);
            }
        }
        let info = information(0.01, 0.01);
        for (k, z) in odo.iter().enumerate() {
            g.betweens.push(Between { i: k, j: k + 1, z: *z, information: info, robust: Robust::None });
        }
        g.betweens.push(Between {
            i: 39,
            j: 0,
            z: truth[39].inverse() * truth[0],
            information: information(0.01, 0.1),
            robust: Robust::None,
        });
        let local10 = g.locals[10];
        let before = (g.world_pose(39).translation.vector - truth[39].translation.vector).norm();
        let report = optimize(&mut g, &GraphConfig::default()).unwrap();
        let after = (g.world_pose(39).translation.vector - truth[39].translation.vector).norm();
        assert!(report.converged, "{report:?}");
        assert!(report.final_cost < report.initial_cost * 0.05, "{report:?}");
        assert!(before > 0.5, "the test has no drift to remove ({before})");
        assert!(after < before * 0.2, "drift {before} m -> {after} m");
        // Gauge: the first anchor and each submap's first local pose did not move.
        assert_eq!(g.anchors[0], dr[0]);
        assert_eq!(g.locals[10], local10);
    }
}
