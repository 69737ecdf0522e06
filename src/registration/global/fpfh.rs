//! Fast Point Feature Histograms (Rusu, Blodow, Beetz 2009), made invariant
//! to the sign of the normals.
//!
//! For a point `p` with normal `n_p` and a neighbour `q` with normal `n_q`
//! within the feature radius, `d = (q − p) / |q − p|`, the pair features are
//!
//! ```text
//! f1 = |n_p · n_q|     f2 = |n_p · d|     f3 = |n_q · d|
//! ```
//!
//! Each is binned into [`BINS`] bins over `[0, 1]`; the three histograms of a
//! point over all its neighbours, each scaled to sum to 100, are its SPFH.
//! The FPFH of `p` is its SPFH plus the distance-weighted mean of its
//! neighbours' SPFHs (each third rescaled to 100), as in PCL's
//! `FPFHEstimation::weightPointSPFHSignature`: 3 × 11 = 33 numbers.
//!
//! Why not PCL's signed angles: they need consistently oriented normals,
//! which a map merged from many viewpoints does not have (flip `n_p` and
//! PCL's `α`, `φ` change sign). The absolute cosines above are the
//! point-pair-feature angles of Drost et al. with the sign folded out, so the
//! descriptor is invariant to any rotation, any translation and to normal
//! flips — tested below on a rotated, translated, re-sampled cloud.

use nalgebra::Vector3;
use rayon::prelude::*;

use super::cloud::MapCloud;

/// Bins per pair feature.
pub const BINS: usize = 11;
/// Length of a descriptor.
pub const DIM: usize = 3 * BINS;
pub type Descriptor = [f32; DIM];

/// Points with fewer neighbours with a normal than this within the feature
/// radius get no descriptor (their histograms would be mostly noise).
pub const MIN_FEATURE_NEIGHBORS: usize = 8;

/// Points whose neighbours' normals are this parallel to their own
/// (`|n_p · n_q|` in the last bin, above 0.91) more often than this are on
/// a flat patch: ground, a wall's middle. Their descriptors all look alike and
/// only ever match at random, so they get none (in a map, most points; this
/// halves the matching time and removes mostly hopeless matches).
pub const MAX_FLAT_FRACTION: f32 = 0.9;

/// Descriptors of the points of `cloud` that have one (a normal, enough
/// neighbours, not on a flat patch): `(point index, FPFH)`, in ascending
/// point order.
pub fn compute_fpfh(cloud: &MapCloud, feature_radius_m: f64) -> Vec<(u32, Descriptor)> {
    // 1. SPFH of every point with a normal and enough neighbours.
    let spfh: Vec<Option<Descriptor>> = (0..cloud.len())
        .into_par_iter()
        .map_init(Vec::new, |nbrs, i| {
            let n_p = cloud.normals[i]?;
            cloud.tree.within(&cloud.points[i], feature_radius_m, nbrs);
            spfh_of(cloud, i, &n_p, nbrs)
        })
        .collect();
    // 2. FPFH: own SPFH plus the 1/distance weighted neighbours' SPFHs.
    (0..cloud.len())
        .into_par_iter()
        .map_init(Vec::new, |nbrs, i| {
            let own = spfh[i].as_ref()?;
            if own[BINS - 1] > 100.0 * MAX_FLAT_FRACTION {
                return None;
            }
            cloud.tree.within(&cloud.points[i], feature_radius_m, nbrs);
            let mut acc = [0.0f64; DIM];
            for &(j, d2) in nbrs.iter() {
                let Some(h) = spfh[j as usize].as_ref() else { continue };
                if j as usize == i || d2 <= 0.0 {
                    continue;
                }
                let w = 1.0 / (d2 as f64).sqrt();
                for (a, &v) in acc.iter_mut().zip(h.iter()) {
                    *a += w * v as f64;
                }
            }
            let mut out = *own;
            for block in 0..3 {
                let range = block * BINS..(block + 1) * BINS;
                let sum: f64 = acc[range.clone()].iter().sum();
                if sum > 0.0 {
                    for k in range {
                        out[k] += (acc[k] * 100.0 / sum) as f32;
                    }
                }
            }
            Some((i as u32, out))
        })
        .flatten()
        .collect()
}

/// The simplified point feature histogram of point `i` over `nbrs`.
fn spfh_of(cloud: &MapCloud, i: usize, n_p: &Vector3<f64>, nbrs: &[(u32, f32)]) -> Option<Descriptor> {
    let p = Vector3::from(cloud.points[i]);
    let mut hist = [0.0f32; DIM];
    let mut count = 0usize;
    for &(j, _) in nbrs {
        let j = j as usize;
        let Some(n_q) = cloud.normals[j] else { continue };
        let d = Vector3::from(cloud.points[j]) - p;
        let len = d.norm();
        if j == i || len <= 0.0 {
            continue;
        }
        let d = d / len;
        let f = [n_p.dot(&n_q).abs(), n_p.dot(&d).abs(), n_q.dot(&d).abs()];
        for (block, v) in f.iter().enumerate() {
            hist[block * BINS + bin(*v)] += 1.0;
        }
        count += 1;
    }
    if count < MIN_FEATURE_NEIGHBORS {
        return None;
    }
    let scale = 100.0 / count as f32;
    hist.iter_mut().for_each(|h| *h *= scale);
    Some(hist)
}

/// The bin of a value in `[0, 1]` (clamped).
#[inline]
fn bin(v: f64) -> usize {
    ((v * BINS as f64) as usize).min(BINS - 1)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Pose;
    use rand::{Rng, SeedableRng};

    /// A small scene: ground, two walls at a corner, a pole and a box.
    fn scene(seed: u64) -> Vec<[f64; 3]> {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let mut pts = Vec::new();
        for _ in 0..60_000 {
            let (x, y) = (rng.random_range(-10.0..10.0), rng.random_range(-10.0..10.0));
            pts.push([x, y, 0.02 * x]);
        }
        for _ in 0..15_000 {
            let (t, z) = (rng.random_range(-8.0..8.0), rng.random_range(0.0..4.0));
            pts.push([t, 6.0, z]);
            pts.push([-6.0, t, z]);
        }
        for _ in 0..3000 {
            let (a, z) = (rng.random_range(0.0..std::f64::consts::TAU), rng.random_range(0.0..5.0));
            pts.push([3.0 + 0.2 * a.cos(), -2.0 + 0.2 * a.sin(), z]);
        }
        for _ in 0..8000 {
            let (u, v) = (rng.random_range(-1.0..1.0), rng.random_range(0.0..1.5));
            pts.push([u, -5.0, v]);
            pts.push([u, -3.0, v]);
            pts.push([-1.0, -4.0 + u, v]);
            pts.push([1.0, -4.0 + u, v]);
            pts.push([u, -4.0 + rng.random_range(-1.0..1.0), 1.5]);
        }
        pts
    }

    fn dist(a: &Descriptor, b: &Descriptor) -> f32 {
        a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum::<f32>().sqrt()
    }

    #[test]
    fn descriptors_are_invariant_to_rotation_translation_and_resampling() {
        let a = scene(1);
        // An arbitrary 3-D rotation (not only yaw) and a large offset; the
        // second cloud is an independent sample of the same surfaces.
        let t = Pose::new(Vector3::new(35.0, -20.0, 4.0), Vector3::new(0.4, -0.3, 2.5));
        let b: Vec<[f64; 3]> = scene(2).iter().map(|p| (t * nalgebra::Point3::from(*p)).into()).collect();
        let (ca, cb) = (MapCloud::new(&a, 0.5, 1.5), MapCloud::new(&b, 0.5, 1.5));
        let (fa, fb) = (compute_fpfh(&ca, 2.5), compute_fpfh(&cb, 2.5));
        assert!(fa.len() > 500 && fb.len() > 500, "{} {}", fa.len(), fb.len());
        // For every descriptor of b, the descriptor of a at the same place
        // (nearest point after undoing t) must be much closer than the
        // descriptor of a random other place, on average.
        let a_tree =
            super::super::cloud::PointTree::build(&fa.iter().map(|(i, _)| ca.points[*i as usize]).collect::<Vec<_>>());
        let t_inv = t.inverse();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let (mut same, mut other, mut n) = (0.0, 0.0, 0);
        for (j, db) in &fb {
            let p = t_inv * nalgebra::Point3::from(cb.points[*j as usize]);
            let Some((k, d2)) = a_tree.nearest(&p.into()) else { continue };
            if d2 > 0.25 * 0.25 {
                continue;
            }
            same += dist(&fa[k].1, db);
            other += dist(&fa[rng.random_range(0..fa.len())].1, db);
            n += 1;
        }
        assert!(n > 300, "{n}");
        let (same, other) = (same / n as f32, other / n as f32);
        assert!(same < 0.5 * other, "same place {same:.1} vs random place {other:.1}");
    }

    #[test]
    fn descriptors_are_identical_under_exact_rigid_motion() {
        // The same points moved rigidly: every histogram count is identical
        // up to floating-point rounding at bin edges and voxel boundaries, so
        // compare with the voxel grid disabled (voxel 0 keeps the points).
        let a: Vec<[f64; 3]> = scene(4).into_iter().step_by(8).collect();
        let t = Pose::new(Vector3::new(-12.0, 7.0, 1.0), Vector3::new(-0.2, 0.5, -1.9));
        let b: Vec<[f64; 3]> = a.iter().map(|p| (t * nalgebra::Point3::from(*p)).into()).collect();
        let (ca, cb) = (MapCloud::new(&a, 0.0, 1.5), MapCloud::new(&b, 0.0, 1.5));
        let (fa, fb) = (compute_fpfh(&ca, 2.5), compute_fpfh(&cb, 2.5));
        assert_eq!(fa.len(), fb.len());
        let mut worst = 0.0f32;
        for ((ia, da), (ib, db)) in fa.iter().zip(&fb) {
            assert_eq!(ia, ib);
            worst = worst.max(dist(da, db));
        }
        // A neighbour exactly on a bin edge may switch bins: a few units at most.
        assert!(worst < 15.0, "worst descriptor change {worst}");
    }
}
