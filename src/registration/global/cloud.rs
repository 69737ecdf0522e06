//! A map prepared once for global registration: voxel centroids, a kd-tree
//! for radius and nearest-neighbour search, and a surface normal per point.
//!
//! Normals come from the PCA of the neighbours within `normal_radius_m`
//! (smallest eigenvector of their covariance). Their sign is arbitrary: a map
//! merged from many viewpoints has no consistent "towards the sensor" side,
//! so everything downstream (descriptors, point-to-plane residuals, the
//! structure test) is written to be invariant to the sign.

use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;

use crate::registration::covariance::smallest_eigenvector;
use crate::registration::downsample::{Point3Like, voxel_downsample};
use crate::registration::kdtree::KdTree;
pub use crate::registration::kdtree::to_f32;

/// Fewer neighbours than this (the point included) within the normal radius
/// leave the local plane undetermined: the point gets no normal.
pub const MIN_NORMAL_NEIGHBORS: usize = 5;

/// A static kd-tree over 3-D points with an `f64` query interface; results
/// index the slice it was built from. A thin front of [`KdTree`], which owns
/// the kiddo plumbing.
#[derive(Debug)]
pub struct PointTree {
    tree: KdTree,
}

impl PointTree {
    pub fn build(points: &[[f64; 3]]) -> PointTree {
        PointTree { tree: KdTree::build(points) }
    }

    /// Every point within `radius_m` of `q` (unsorted) into `out` (cleared
    /// first): `(index, squared distance m²)`.
    pub fn within(&self, q: &[f64; 3], radius_m: f64, out: &mut Vec<(u32, f32)>) {
        self.tree.within_unsorted(&to_f32(q), (radius_m * radius_m) as f32, out);
    }

    /// The nearest point to `q`: `(index, squared distance m²)`.
    #[inline]
    pub fn nearest(&self, q: &[f64; 3]) -> Option<(usize, f64)> {
        self.tree.nearest(&to_f32(q)).map(|(i, d2)| (i, d2 as f64))
    }
}

/// A voxel-downsampled map with its search tree and normals.
#[derive(Debug)]
pub struct MapCloud {
    pub points: Vec<[f64; 3]>,
    /// Unit normal per point (arbitrary sign), `None` where fewer than
    /// [`MIN_NORMAL_NEIGHBORS`] points lie within the normal radius.
    pub normals: Vec<Option<Vector3<f64>>>,
    pub tree: PointTree,
}

impl MapCloud {
    /// Downsamples `points` to `voxel_size_m` centroids and estimates normals.
    pub fn new<P: Point3Like>(points: &[P], voxel_size_m: f64, normal_radius_m: f64) -> MapCloud {
        let points = voxel_downsample(points, voxel_size_m, true);
        let tree = PointTree::build(&points);
        let normals = points
            .par_iter()
            .map_init(Vec::new, |nbrs, p| {
                tree.within(p, normal_radius_m, nbrs);
                normal_of(&points, nbrs)
            })
            .collect();
        MapCloud { points, normals, tree }
    }

    pub fn len(&self) -> usize {
        self.points.len()
    }

    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }
}

/// The PCA normal of the points at `nbrs`, or `None` if there are too few.
fn normal_of(points: &[[f64; 3]], nbrs: &[(u32, f32)]) -> Option<Vector3<f64>> {
    if nbrs.len() < MIN_NORMAL_NEIGHBORS {
        return None;
    }
    let n = nbrs.len() as f64;
    let mean = nbrs.iter().fold(Vector3::zeros(), |s, &(i, _)| s + Vector3::from(points[i as usize])) / n;
    let cov = nbrs.iter().fold(Matrix3::zeros(), |s, &(i, _)| {
        let d = Vector3::from(points[i as usize]) - mean;
        s + d * d.transpose()
    }) / n;
    let normal = smallest_eigenvector(&cov);
    normal.iter().all(|c| c.is_finite()).then_some(normal)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normals_of_a_plane_are_its_normal() {
        // A tilted plane z = 0.3 x, sampled densely.
        let mut pts = Vec::new();
        for i in 0..40 {
            for j in 0..40 {
                let (x, y) = (i as f64 * 0.1, j as f64 * 0.1);
                pts.push([x, y, 0.3 * x]);
            }
        }
        let cloud = MapCloud::new(&pts, 0.1, 0.35);
        let want = Vector3::new(-0.3, 0.0, 1.0).normalize();
        let valid: Vec<_> = cloud.normals.iter().flatten().collect();
        assert!(valid.len() > cloud.len() * 9 / 10);
        for n in valid {
            assert!(n.dot(&want).abs() > 0.999, "{n:?}");
        }
    }

    #[test]
    fn radius_search_matches_brute_force() {
        let pts: Vec<[f64; 3]> = (0..500)
            .map(|i| {
                let t = i as f64;
                [(t * 0.37).sin() * 5.0, (t * 0.11).cos() * 5.0, (t * 0.07).sin()]
            })
            .collect();
        let tree = PointTree::build(&pts);
        let mut out = Vec::new();
        for q in pts.iter().step_by(17) {
            tree.within(q, 1.5, &mut out);
            let mut got: Vec<u32> = out.iter().map(|r| r.0).collect();
            got.sort_unstable();
            let want: Vec<u32> = (0..pts.len() as u32)
                .filter(|&i| {
                    let p = pts[i as usize];
                    (0..3).map(|a| (p[a] - q[a]).powi(2)).sum::<f64>() <= 1.5 * 1.5 - 1e-6
                })
                .collect();
            // Points exactly on the boundary may fall either way in f32.
            assert!(want.iter().all(|i| got.contains(i)), "{want:?} vs {got:?}");
            assert!(got.len() <= want.len() + 2);
        }
    }
}
