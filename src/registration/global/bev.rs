//! Gravity-aligned exhaustive search: every yaw, every horizontal offset,
//! scored by how many bird's-eye-view structure cells coincide.
//!
//! Why it exists: local descriptors are only as good as their repeatability,
//! and two sessions that walk different routes sample the same wall from
//! different sides, ranges and angles. On the simulated site the true
//! counterpart of a source voxel ranks in the middle of all target FPFH
//! descriptors, and mutual matches are > 99.7 % wrong; KISS-Matcher fails on
//! the same pairs. When both maps are gravity-aligned the unknown motion is
//! only yaw and a translation, small enough to search exhaustively, and the
//! *layout* of walls, poles and objects seen from above is what both
//! sessions agree on.
//!
//! 1. Structure voxels (normal more than ~45° from vertical) are projected
//!    into `cell_m` horizontal cells; each map becomes a set of occupied cells.
//! 2. For each yaw (steps of `yaw_step_deg`), every pair of a target cell and
//!    a rotated source cell votes for the offset that superposes them; votes
//!    land in a 2-D accumulator of `cell_m` bins. The true offset collects a
//!    vote from every cell both maps share; a wrong one only chance overlaps.
//!    This is the cross-correlation of the two occupancy images, computed by
//!    voting (no FFT needed at these sizes: 2-4 million votes per yaw).
//! 3. Each yaw's best 3×3 window of bins (a true offset straddles bins) is a
//!    candidate; the best candidates, one per yaw/offset neighbourhood, are
//!    the hypotheses. The height offset is the median difference of the
//!    lowest point (ground) of the cells the hypothesis superposes.
//!
//! The result is coarse (a cell, a yaw step); ICP in [`super::verify`]
//! refines it and the same verification judges it as any other hypothesis.

use std::collections::HashMap;

use nalgebra::{Translation3, UnitQuaternion, Vector3};
use rayon::prelude::*;

use super::cloud::MapCloud;
use super::verify::STRUCTURE_MAX_ABS_NZ;
use crate::geometry::Pose;

/// Settings of [`bev_hypotheses`].
#[derive(Debug, Clone, Copy)]
pub struct BevParams {
    pub cell_m: f64,
    pub yaw_step_deg: f64,
    /// Hypotheses returned at most.
    pub max_hypotheses: usize,
    /// Candidates closer than this in yaw (deg)…
    pub suppress_yaw_deg: f64,
    /// …and offset (m) to a better one are the same peak.
    pub suppress_m: f64,
}

/// Height slices of a cell's vertical profile, m.
const SLICE_M: f64 = 1.0;

/// A map seen from above: occupied structure cells and each cell's lowest z.
struct Bev {
    /// Centres (x, y) of the cells holding structure, and which `SLICE_M`
    /// slices above the local ground hold structure (bit k: k to k+1 slices).
    structure: Vec<([f64; 2], u32)>,
    /// Lowest z of any point per cell (all points, not only structure).
    ground: HashMap<(i32, i32), f64>,
}

fn cell(x: f64, y: f64, c: f64) -> (i32, i32) {
    ((x / c).floor() as i32, (y / c).floor() as i32)
}

impl Bev {
    fn new(cloud: &MapCloud, c: f64) -> Bev {
        let mut ground: HashMap<(i32, i32), f64> = HashMap::new();
        for p in &cloud.points {
            let g = ground.entry(cell(p[0], p[1], c)).or_insert(p[2]);
            *g = g.min(p[2]);
        }
        // The local ground: lowest point of the 3×3 cells around (under a
        // container or a wall's foot the cell itself may have no ground).
        let local_ground = |(i, j): (i32, i32)| {
            (i - 1..=i + 1)
                .flat_map(|x| (j - 1..=j + 1).map(move |y| (x, y)))
                .filter_map(|k| ground.get(&k))
                .copied()
                .fold(f64::INFINITY, f64::min)
        };
        let mut profiles: HashMap<(i32, i32), u32> = HashMap::new();
        for (p, n) in cloud.points.iter().zip(&cloud.normals) {
            if n.is_some_and(|n| n.z.abs() < STRUCTURE_MAX_ABS_NZ) {
                let k = cell(p[0], p[1], c);
                let slice = ((p[2] - local_ground(k)) / SLICE_M).floor().clamp(0.0, 31.0) as u32;
                *profiles.entry(k).or_insert(0) |= 1 << slice;
            }
        }
        let mut cells: Vec<((i32, i32), u32)> = profiles.into_iter().collect();
        cells.sort_unstable();
        let structure =
            cells.iter().map(|&((i, j), bits)| ([(i as f64 + 0.5) * c, (j as f64 + 0.5) * c], bits)).collect();
        Bev { structure, ground }
    }
}

/// A scored (yaw, offset) candidate.
#[derive(Debug, Clone, Copy)]
struct Candidate {
    votes: u32,
    yaw: f64,
    offset: [f64; 2],
}

/// Up to `max_hypotheses` 4-DoF hypotheses `t_target_source`, best first.
pub fn bev_hypotheses(target: &MapCloud, source: &MapCloud, p: &BevParams) -> Vec<Pose> {
    let c = p.cell_m;
    let (tb, sb) = (Bev::new(target, c), Bev::new(source, c));
    if tb.structure.is_empty() || sb.structure.is_empty() {
        return Vec::new();
    }
    // Offsets range over the target's extent grown by the source's radius.
    let rho = sb.structure.iter().map(|(s, _)| s[0].hypot(s[1])).fold(0.0, f64::max) + c;
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for (t, _) in &tb.structure {
        for a in 0..2 {
            lo[a] = lo[a].min(t[a] - rho);
            hi[a] = hi[a].max(t[a] + rho);
        }
    }
    let dims = [((hi[0] - lo[0]) / c).ceil() as usize + 1, ((hi[1] - lo[1]) / c).ceil() as usize + 1];
    let steps = (360.0 / p.yaw_step_deg).round().max(1.0) as usize;
    let mut candidates: Vec<Candidate> = (0..steps)
        .into_par_iter()
        .map_init(
            || vec![0u32; dims[0] * dims[1]],
            |acc, k| {
                let yaw = (k as f64 * 360.0 / steps as f64).to_radians();
                best_offset(acc, &tb.structure, &sb.structure, yaw, lo, dims, c)
            },
        )
        .collect();
    candidates.sort_by(|a, b| b.votes.cmp(&a.votes).then(a.yaw.total_cmp(&b.yaw)));
    let mut kept: Vec<Candidate> = Vec::new();
    for cand in candidates {
        let near = kept.iter().any(|k| {
            let dyaw =
                (cand.yaw - k.yaw + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI;
            dyaw.abs().to_degrees() < p.suppress_yaw_deg
                && (cand.offset[0] - k.offset[0]).hypot(cand.offset[1] - k.offset[1]) < p.suppress_m
        });
        if !near {
            kept.push(cand);
            if kept.len() == p.max_hypotheses {
                break;
            }
        }
    }
    kept.iter().map(|k| to_pose(k, &tb, &sb, c)).collect()
}

/// Votes of every (target cell, rotated source cell) pair for one yaw,
/// weighted by the height slices both cells' structure occupies; the best
/// 2×2 window of the accumulator (a true offset straddles bins).
fn best_offset(
    acc: &mut [u32],
    tgt: &[([f64; 2], u32)],
    src: &[([f64; 2], u32)],
    yaw: f64,
    lo: [f64; 2],
    dims: [usize; 2],
    c: f64,
) -> Candidate {
    acc.iter_mut().for_each(|v| *v = 0);
    let (sn, cs) = yaw.sin_cos();
    let inv = 1.0 / c;
    let rotated: Vec<([f64; 2], u32)> =
        src.iter().map(|(s, bits)| ([(cs * s[0] - sn * s[1]) * inv, (sn * s[0] + cs * s[1]) * inv], *bits)).collect();
    for (t, tbits) in tgt {
        // Offset t − R s as a bin index; never negative nor past the end,
        // because lo and dims were grown by the source's radius.
        let (bx, by) = ((t[0] - lo[0]) * inv, (t[1] - lo[1]) * inv);
        for (r, sbits) in &rotated {
            let w = (tbits & sbits).count_ones();
            if w == 0 {
                continue;
            }
            let (ix, iy) = ((bx - r[0]) as usize, (by - r[1]) as usize);
            if let Some(v) = acc.get_mut(iy * dims[0] + ix) {
                *v += w;
            }
        }
    }
    let mut best = (0u32, 0usize, 0usize);
    for iy in 0..dims[1].saturating_sub(1) {
        for ix in 0..dims[0].saturating_sub(1) {
            let i = iy * dims[0] + ix;
            let sum = acc[i] + acc[i + 1] + acc[i + dims[0]] + acc[i + dims[0] + 1];
            if sum > best.0 {
                best = (sum, ix, iy);
            }
        }
    }
    // The window's centre is the shared corner of its four bins.
    let offset = [lo[0] + (best.1 as f64 + 1.0) * c, lo[1] + (best.2 as f64 + 1.0) * c];
    Candidate { votes: best.0, yaw, offset }
}

/// The candidate as a pose, with the height offset from the ground.
fn to_pose(k: &Candidate, tb: &Bev, sb: &Bev, c: f64) -> Pose {
    let rot = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), k.yaw);
    let mut dz: Vec<f64> = sb
        .ground
        .iter()
        .filter_map(|(&(i, j), &zs)| {
            let s = Vector3::new((i as f64 + 0.5) * c, (j as f64 + 0.5) * c, 0.0);
            let q = rot * s;
            let zt = tb.ground.get(&cell(q.x + k.offset[0], q.y + k.offset[1], c))?;
            Some(zt - zs)
        })
        .collect();
    dz.sort_by(f64::total_cmp);
    let tz = dz.get(dz.len() / 2).copied().unwrap_or(0.0);
    Pose::from_parts(Translation3::new(k.offset[0], k.offset[1], tz), rot)
}
