//! Nearest-neighbour search: a thin wrapper over kiddo's `ImmutableKdTree`.
//!
//! The tree stores `f32` coordinates: queries are about twice as fast as in
//! `f64`, and in a scan's or a local map's frame (|p| < 10 km) `f32` resolves
//! positions to < 1 mm, far below the 0.1-0.5 m voxels that GICP works on.
//! Callers keep their own `f64` copy of the points for the maths; the tree
//! only answers "which index is nearest, and how far (squared, m²)".

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use std::num::NonZeroUsize;

/// A static kd-tree over a point set; indices refer to the slice it was built from.
pub struct KdTree {
    /// `None` for an empty point set (kiddo cannot build an empty tree).
    tree: Option<ImmutableKdTree<f32, 3>>,
    len: usize,
}

impl std::fmt::Debug for KdTree {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("KdTree").field("len", &self.len).finish()
    }
}

/// `f32` copy of an `f64` point, as stored in the tree.
#[inline]
pub fn to_f32(p: &[f64; 3]) -> [f32; 3] {
    [p[0] as f32, p[1] as f32, p[2] as f32]
}

impl KdTree {
    /// Builds the tree over `points` (index i of a result is `points[i]`).
    pub fn build(points: &[[f64; 3]]) -> KdTree {
        let pts: Vec<[f32; 3]> = points.iter().map(to_f32).collect();
        // Construction only fails for an empty slice or more than u32::MAX
        // points; both leave a tree that answers "no neighbour".
        let tree = if pts.is_empty() || pts.len() > u32::MAX as usize {
            None
        } else {
            ImmutableKdTree::<f32, 3>::new_from_slice(&pts).ok()
        };
        KdTree { tree, len: points.len() }
    }

    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.tree.is_none()
    }

    /// The nearest point to `q`: `(index, squared distance in m²)`.
    #[inline]
    pub fn nearest(&self, q: &[f32; 3]) -> Option<(usize, f32)> {
        let tree = self.tree.as_ref()?;
        let nn = tree.query(q).nearest_one::<SquaredEuclidean<f32>>().execute();
        Some((nn.item as usize, nn.distance))
    }

    /// The `k` nearest points to `q`, nearest first, written into `out`
    /// (cleared first): `(index, squared distance in m²)`.
    pub fn knn(&self, q: &[f32; 3], k: usize, out: &mut Vec<(usize, f32)>) {
        self.knn_unsorted(q, k, out);
        out.sort_unstable_by(|a, b| a.1.total_cmp(&b.1));
    }

    /// The `k` nearest points to `q` in no particular order (faster when the
    /// order does not matter, as for a covariance).
    pub fn knn_unsorted(&self, q: &[f32; 3], k: usize, out: &mut Vec<(usize, f32)>) {
        out.clear();
        let (Some(tree), Some(k)) = (self.tree.as_ref(), NonZeroUsize::new(k)) else {
            return;
        };
        let found = tree.query(q).nearest_n::<SquaredEuclidean<f32>>(k).unsorted().execute();
        out.extend(found.into_iter().map(|r| (r.item as usize, r.distance)));
    }

    /// Like [`Self::knn_unsorted`], but only among points within
    /// `max_dist2` (squared, m²) of `q`: a bound known to hold `k` points
    /// prunes the search from the start. May return fewer than `k`.
    pub fn knn_unsorted_within(&self, q: &[f32; 3], k: usize, max_dist2: f32, out: &mut Vec<(usize, f32)>) {
        out.clear();
        let (Some(tree), Some(k)) = (self.tree.as_ref(), NonZeroUsize::new(k)) else {
            return;
        };
        let found = tree.query(q).nearest_n::<SquaredEuclidean<f32>>(k).within(max_dist2).unsorted().execute();
        out.extend(found.into_iter().map(|r| (r.item as usize, r.distance)));
    }

    /// Every point within `max_dist2` (squared, m²) of `q`, in no particular
    /// order, into `out` (cleared first): `(index, squared distance in m²)`.
    /// Indices are `u32`, as kiddo stores them, to keep large neighbour lists small.
    pub fn within_unsorted(&self, q: &[f32; 3], max_dist2: f32, out: &mut Vec<(u32, f32)>) {
        out.clear();
        let Some(tree) = self.tree.as_ref() else { return };
        tree.query(q).within::<SquaredEuclidean<f32>>(max_dist2).unsorted().visit(|r| out.push((r.item, r.distance)));
    }
}

/// Brute-force k nearest neighbours, the reference the kd-tree is tested against.
pub fn brute_force_knn(points: &[[f64; 3]], q: &[f64; 3], k: usize) -> Vec<(usize, f64)> {
    let mut all: Vec<(usize, f64)> =
        points.iter().enumerate().map(|(i, p)| (i, (0..3).map(|a| (p[a] - q[a]) * (p[a] - q[a])).sum())).collect();
    all.sort_by(|a, b| a.1.total_cmp(&b.1));
    all.truncate(k);
    all
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    fn random_cloud(n: usize, seed: u64) -> Vec<[f64; 3]> {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        (0..n)
            .map(|_| [rng.random_range(-20.0..20.0), rng.random_range(-20.0..20.0), rng.random_range(-2.0..2.0)])
            .collect()
    }

    #[test]
    fn knn_agrees_with_brute_force() {
        let pts = random_cloud(3000, 1);
        let tree = KdTree::build(&pts);
        let queries = random_cloud(200, 2);
        let mut out = Vec::new();
        for q in &queries {
            let want = brute_force_knn(&pts, q, 20);
            tree.knn(&to_f32(q), 20, &mut out);
            assert_eq!(out.len(), 20);
            for (g, w) in out.iter().zip(&want) {
                // Distances agree to f32 precision; indices agree unless two
                // points are equally far, which random floats never are.
                assert!((g.1 as f64 - w.1).abs() < 1e-3 * (1.0 + w.1), "{g:?} vs {w:?}");
                assert_eq!(g.0, w.0);
            }
            let nn = tree.nearest(&to_f32(q)).unwrap();
            assert_eq!(nn.0, want[0].0);
        }
    }

    #[test]
    fn empty_tree_answers_nothing() {
        let tree = KdTree::build(&[]);
        assert!(tree.is_empty());
        assert!(tree.nearest(&[0.0; 3]).is_none());
        let mut out = vec![(1, 1.0)];
        tree.knn(&[0.0; 3], 5, &mut out);
        assert!(out.is_empty());
    }

    #[test]
    fn k_larger_than_cloud_returns_all() {
        let pts = random_cloud(7, 3);
        let tree = KdTree::build(&pts);
        let mut out = Vec::new();
        tree.knn(&[0.0; 3], 20, &mut out);
        assert_eq!(out.len(), 7);
    }
}
