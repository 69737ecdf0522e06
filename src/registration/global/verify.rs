//! Dense refinement and scoring of a hypothesis, the evidence for the verdict.
//!
//! Refinement is point-to-plane ICP of a subsample of the source map against
//! the target map and its normals, with a shrinking correspondence distance
//! and Cauchy weights; with gravity the first half of the iterations only
//! moves x, y, z and yaw, so a sparse or one-sided overlap cannot tilt the
//! estimate before the horizontal motion has settled. Increments are applied
//! on the left, `T ← Exp(δ) T`, so that the 4-DoF step (rotation about the
//! target's vertical) is a sub-vector of the 6-DoF one.
//!
//! The score of a transform is computed on the source's *structure* points —
//! voxels whose normal, rotated into the target frame, is more than ~45° from
//! vertical (walls, poles, stacks, vehicles) — because ground matches ground
//! under any horizontal shift and would vouch for a wrong transform. A
//! structure point is *covered* when it lands in a horizontal cell where the
//! target has points (the target surveyed that place), and *matched* when a
//! target point lies within the match distance. `matched / covered` is the
//! structure fit: high when the two maps agree where both looked, low for a
//! wrong transform however large the overlap.

use std::collections::HashSet;

use nalgebra::{Matrix4, Matrix6, Point3, Vector3, Vector4, Vector6};
use rayon::prelude::*;

use super::cloud::MapCloud;
use super::robust::Dof;
use crate::geometry::Pose;
use crate::registration::se3::se3_exp;

/// A normal with `|n_z|` below this (rotated into the target frame) marks a
/// structure point: more than ~45° from vertical.
pub const STRUCTURE_MAX_ABS_NZ: f64 = 0.7;

/// Settings of [`refine`].
#[derive(Debug, Clone, Copy)]
pub struct RefineParams {
    pub max_dist_start_m: f64,
    pub max_dist_end_m: f64,
    pub iterations: usize,
    pub dof: Dof,
}

/// Point-to-plane ICP of `source` against `target` from `init`.
pub fn refine(target: &MapCloud, source: &[[f64; 3]], init: &Pose, p: &RefineParams) -> Pose {
    let mut t = *init;
    let shrink = if p.iterations > 1 {
        (p.max_dist_end_m / p.max_dist_start_m).powf(1.0 / (p.iterations as f64 / 2.0).max(1.0))
    } else {
        1.0
    };
    for it in 0..p.iterations {
        let max_dist = (p.max_dist_start_m * shrink.powi(it as i32)).max(p.max_dist_end_m);
        let four = p.dof == Dof::Four || it < p.iterations / 2;
        let (h, b, n) = source
            .par_iter()
            .fold(
                || (Matrix6::<f64>::zeros(), Vector6::<f64>::zeros(), 0usize),
                |(mut h, mut b, mut n), s| {
                    let q = t * Point3::from(*s);
                    let Some((j, d2)) = target.tree.nearest(&q.into()) else { return (h, b, n) };
                    let Some(normal) = target.normals[j] else { return (h, b, n) };
                    if d2 > max_dist * max_dist {
                        return (h, b, n);
                    }
                    let r = normal.dot(&(q - Point3::from(target.points[j])));
                    // Cauchy weight with a scale of a quarter of the distance gate.
                    let c = 0.25 * max_dist;
                    let w = 1.0 / (1.0 + (r / c) * (r / c));
                    let jr = q.coords.cross(&normal);
                    let jac = Vector6::new(jr.x, jr.y, jr.z, normal.x, normal.y, normal.z);
                    h += w * jac * jac.transpose();
                    b += w * jac * r;
                    n += 1;
                    (h, b, n)
                },
            )
            .reduce(|| (Matrix6::zeros(), Vector6::zeros(), 0), |a, o| (a.0 + o.0, a.1 + o.1, a.2 + o.2));
        if n < 6 {
            break;
        }
        let delta = if four { solve_four(&h, &b) } else { solve_six(&h, &b) };
        let Some(delta) = delta else { break };
        t = se3_exp(&delta) * t;
        if delta.norm() < 1e-5 && max_dist <= p.max_dist_end_m {
            break;
        }
    }
    t
}

/// The Gauss-Newton step `H δ = −b` over all six coordinates.
fn solve_six(h: &Matrix6<f64>, b: &Vector6<f64>) -> Option<Vector6<f64>> {
    let damped = h + Matrix6::identity() * 1e-6 * (1.0 + h.trace());
    damped.cholesky().map(|c| -c.solve(b))
}

/// The step restricted to `[ω_z, v_x, v_y, v_z]` (indices 2..6).
fn solve_four(h: &Matrix6<f64>, b: &Vector6<f64>) -> Option<Vector6<f64>> {
    let h4: Matrix4<f64> = h.fixed_view::<4, 4>(2, 2).into_owned();
    let b4: Vector4<f64> = b.fixed_rows::<4>(2).into_owned();
    let damped = h4 + Matrix4::identity() * 1e-6 * (1.0 + h4.trace());
    let d4 = -damped.cholesky()?.solve(&b4);
    Some(Vector6::new(0.0, 0.0, d4[0], d4[1], d4[2], d4[3]))
}

/// The horizontal cells (of `cell_m`) where `cloud` has points.
pub fn coverage(cloud: &MapCloud, cell_m: f64) -> HashSet<(i32, i32)> {
    cloud.points.iter().map(|p| cell_of(p, cell_m)).collect()
}

fn cell_of(p: &[f64; 3], cell_m: f64) -> (i32, i32) {
    ((p[0] / cell_m).floor() as i32, (p[1] / cell_m).floor() as i32)
}

/// How well a transform makes the source map agree with the target map.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Score {
    /// Source points (all voxels) with a target point within the match distance.
    pub matched_all: usize,
    pub source_points: usize,
    /// Source structure points, and of those the ones over the target's
    /// surveyed area and the ones matched.
    pub structure: usize,
    pub covered: usize,
    pub matched: usize,
    /// Covered structure points within half the match distance of a target
    /// point whose normal agrees with theirs (|cos| > 0.9).
    pub tight: usize,
}

impl Score {
    /// `matched / covered` over the structure points.
    pub fn structure_fit(&self) -> f64 {
        if self.covered == 0 { 0.0 } else { self.matched as f64 / self.covered as f64 }
    }

    /// Fraction of all source voxels with a target point within the match distance.
    pub fn overlap_fraction(&self) -> f64 {
        if self.source_points == 0 { 0.0 } else { self.matched_all as f64 / self.source_points as f64 }
    }
}

/// Scores `t_target_source` (see the module doc).
pub fn score(
    target: &MapCloud,
    covered_cells: &HashSet<(i32, i32)>,
    cell_m: f64,
    source: &MapCloud,
    t: &Pose,
    match_dist_m: f64,
) -> Score {
    let r = t.rotation;
    let md2 = match_dist_m * match_dist_m;
    source
        .points
        .par_iter()
        .zip(source.normals.par_iter())
        .map(|(p, n)| {
            let q: [f64; 3] = (t * Point3::from(*p)).into();
            let nn = target.tree.nearest(&q);
            let matched = nn.is_some_and(|(_, d2)| d2 <= md2);
            let structure = n.is_some_and(|n| (r * n).z.abs() < STRUCTURE_MAX_ABS_NZ);
            let covered = structure && covered_cells.contains(&cell_of(&q, cell_m));
            let tight = covered
                && nn.is_some_and(|(j, d2)| {
                    d2 <= md2 / 4.0 && target.normals[j].zip(*n).is_some_and(|(a, b)| a.dot(&(r * b)).abs() > 0.9)
                });
            Score {
                matched_all: matched as usize,
                source_points: 1,
                structure: structure as usize,
                covered: covered as usize,
                matched: (covered && matched) as usize,
                tight: tight as usize,
            }
        })
        .reduce(Score::default, |a, b| Score {
            matched_all: a.matched_all + b.matched_all,
            source_points: a.source_points + b.source_points,
            structure: a.structure + b.structure,
            covered: a.covered + b.covered,
            matched: a.matched + b.matched,
            tight: a.tight + b.tight,
        })
}

/// Translation (m) and rotation (rad) between two poses.
pub fn pose_distance(a: &Pose, b: &Pose) -> (f64, f64) {
    let d = a.inverse() * b;
    (d.translation.vector.norm(), d.rotation.angle())
}

/// `Vector3` of a point array, for the maths.
pub fn v3(p: &[f64; 3]) -> Vector3<f64> {
    Vector3::from(*p)
}
