//! Feature correspondences: mutual nearest neighbours in descriptor space,
//! ranked by Lowe's ratio.
//!
//! A source descriptor `a` and a target descriptor `b` correspond when `b` is
//! `a`'s nearest target descriptor and `a` is `b`'s nearest source
//! descriptor. On a map most descriptors are flat ground or wall and match
//! one of thousands of look-alikes at random; the ratio `d₁ / d₂` of the
//! distances to the nearest and the second-nearest target descriptor is
//! close to 1 for those and small for distinctive places (poles, corners,
//! clutter), so the `max_correspondences` with the smallest ratio are kept.
//! The robust estimator then has fewer, better candidates: its cost grows
//! with the square of their number.
//!
//! Nearest-neighbour search in 33 dimensions defeats a kd-tree (a query
//! visits most leaves: 5-20 s for two 40 000-voxel maps). The descriptors are
//! therefore projected on their [`SEARCH_DIM`] principal components (computed
//! over both sets, so both are projected alike), the [`CANDIDATES`] nearest
//! in that space are fetched from a kd-tree and re-ranked by the full
//! 33-dimensional distance. FPFH variance concentrates in a few components,
//! so this finds the exact nearest neighbour almost always (tested against
//! brute force below) at a fraction of the cost.

use std::num::NonZeroUsize;

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use nalgebra::{DMatrix, SymmetricEigen};
use rayon::prelude::*;

use super::fpfh::{DIM, Descriptor};

/// Principal components the kd-tree searches in.
pub const SEARCH_DIM: usize = 10;
/// Candidates fetched in the reduced space and re-ranked in the full one.
pub const CANDIDATES: usize = 10;

/// One feature correspondence: indices into the source and target point
/// sets, and its Lowe ratio (smaller is more distinctive).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Correspondence {
    pub source: u32,
    pub target: u32,
    pub ratio: f32,
}

/// Mutual nearest neighbours between `source` and `target` descriptors
/// (`(point index, descriptor)` pairs), at most `max_correspondences`, the
/// most distinctive first (ties broken by point index, so the result does not
/// depend on the thread count).
pub fn mutual_matches(
    source: &[(u32, Descriptor)],
    target: &[(u32, Descriptor)],
    max_correspondences: usize,
) -> Vec<Correspondence> {
    if source.is_empty() || target.len() < 2 {
        return Vec::new();
    }
    let basis = principal_axes(source, target);
    let (Some(src_index), Some(tgt_index)) = (Index::new(source, &basis), Index::new(target, &basis)) else {
        return Vec::new();
    };
    // Source → target: nearest and second nearest.
    let forward: Vec<[(u32, f32); 2]> = source.par_iter().map(|(_, d)| tgt_index.nearest_two(d, target)).collect();
    // Target → source: nearest only.
    let backward: Vec<u32> = target.par_iter().map(|(_, d)| src_index.nearest_two(d, source)[0].0).collect();
    let mut out: Vec<Correspondence> = forward
        .iter()
        .enumerate()
        .filter(|&(i, nn)| nn[0].0 != u32::MAX && backward[nn[0].0 as usize] as usize == i)
        .map(|(i, nn)| {
            let (d1, d2) = (nn[0].1, nn[1].1);
            let ratio = if d2 > 0.0 && d2.is_finite() { (d1 / d2).sqrt() } else { 1.0 };
            Correspondence { source: source[i].0, target: target[nn[0].0 as usize].0, ratio }
        })
        .collect();
    out.sort_by(|a, b| a.ratio.total_cmp(&b.ratio).then(a.source.cmp(&b.source)));
    out.truncate(max_correspondences);
    out
}

fn squared_distance(a: &Descriptor, b: &Descriptor) -> f32 {
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum()
}

/// The mean and the [`SEARCH_DIM`] leading principal axes of both sets together.
struct Basis {
    mean: [f32; DIM],
    axes: [[f32; DIM]; SEARCH_DIM],
}

fn principal_axes(a: &[(u32, Descriptor)], b: &[(u32, Descriptor)]) -> Basis {
    let n = (a.len() + b.len()).max(1) as f64;
    let all = || a.iter().chain(b).map(|(_, d)| d);
    let mut mean = [0.0f64; DIM];
    for d in all() {
        for (m, &v) in mean.iter_mut().zip(d) {
            *m += v as f64 / n;
        }
    }
    let mut cov = DMatrix::<f64>::zeros(DIM, DIM);
    for d in all() {
        let c: Vec<f64> = d.iter().zip(&mean).map(|(&v, m)| v as f64 - m).collect();
        for i in 0..DIM {
            for j in i..DIM {
                cov[(i, j)] += c[i] * c[j];
            }
        }
    }
    for i in 0..DIM {
        for j in 0..i {
            cov[(i, j)] = cov[(j, i)];
        }
    }
    let eig = SymmetricEigen::new(cov);
    let mut order: Vec<usize> = (0..DIM).collect();
    order.sort_by(|&x, &y| eig.eigenvalues[y].total_cmp(&eig.eigenvalues[x]));
    let axes = std::array::from_fn(|k| std::array::from_fn(|i| eig.eigenvectors[(i, order[k])] as f32));
    Basis { mean: mean.map(|m| m as f32), axes }
}

impl Basis {
    fn project(&self, d: &Descriptor) -> [f32; SEARCH_DIM] {
        std::array::from_fn(|k| self.axes[k].iter().zip(d).zip(&self.mean).map(|((a, v), m)| a * (v - m)).sum())
    }
}

/// A kd-tree over projected descriptors.
struct Index<'b> {
    tree: ImmutableKdTree<f32, SEARCH_DIM>,
    basis: &'b Basis,
}

impl<'b> Index<'b> {
    fn new(set: &[(u32, Descriptor)], basis: &'b Basis) -> Option<Index<'b>> {
        let pts: Vec<[f32; SEARCH_DIM]> = set.iter().map(|(_, d)| basis.project(d)).collect();
        if pts.is_empty() || pts.len() > u32::MAX as usize {
            return None;
        }
        Some(Index { tree: ImmutableKdTree::new_from_slice(&pts).ok()?, basis })
    }

    /// The two nearest descriptors of `set` (the set the index was built
    /// from) to `q` in the full space, among the reduced-space candidates:
    /// `(position in set, squared distance)`, `u32::MAX` / ∞ when missing.
    fn nearest_two(&self, q: &Descriptor, set: &[(u32, Descriptor)]) -> [(u32, f32); 2] {
        let k = NonZeroUsize::new(CANDIDATES).unwrap_or(NonZeroUsize::MIN);
        let found = self.tree.query(&self.basis.project(q)).nearest_n::<SquaredEuclidean<f32>>(k).unsorted().execute();
        let mut best = [(u32::MAX, f32::INFINITY); 2];
        for r in found {
            let d = squared_distance(q, &set[r.item as usize].1);
            if d < best[0].1 || (d == best[0].1 && r.item < best[0].0) {
                best[1] = best[0];
                best[0] = (r.item, d);
            } else if d < best[1].1 {
                best[1] = (r.item, d);
            }
        }
        best
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// Descriptors like FPFH's: a few latent factors (6) mixed into 33
    /// numbers, plus a little noise.
    fn random_descriptors(n: usize, seed: u64) -> Vec<(u32, Descriptor)> {
        let mut mix = rand_chacha::ChaCha8Rng::seed_from_u64(99);
        let a: Vec<[f32; 6]> = (0..DIM).map(|_| std::array::from_fn(|_| mix.random_range(0.0f32..4.0))).collect();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        (0..n as u32)
            .map(|i| {
                let z: [f32; 6] = std::array::from_fn(|_| rng.random_range(0.0f32..10.0));
                (
                    i * 3,
                    std::array::from_fn(|k| {
                        a[k].iter().zip(&z).map(|(x, y)| x * y).sum::<f32>() + rng.random_range(0.0..1.0)
                    }),
                )
            })
            .collect()
    }

    /// The obvious O(n²) mutual nearest neighbours.
    fn brute_force(src: &[(u32, Descriptor)], tgt: &[(u32, Descriptor)]) -> Vec<(u32, u32)> {
        let d = |a: &Descriptor, b: &Descriptor| a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum::<f32>();
        let nearest = |q: &Descriptor, set: &[(u32, Descriptor)]| {
            (0..set.len()).min_by(|&a, &b| d(q, &set[a].1).total_cmp(&d(q, &set[b].1))).unwrap()
        };
        let mut out: Vec<(u32, u32)> = (0..src.len())
            .filter_map(|i| {
                let j = nearest(&src[i].1, tgt);
                (nearest(&tgt[j].1, src) == i).then_some((src[i].0, tgt[j].0))
            })
            .collect();
        out.sort_unstable();
        out
    }

    #[test]
    fn mutual_matches_agree_with_brute_force() {
        let src = random_descriptors(400, 1);
        let mut tgt = random_descriptors(500, 2);
        // Plant 50 near-copies of source descriptors in the target.
        for k in 0..50 {
            let mut d = src[k * 7].1;
            d[0] += 0.5;
            tgt[k * 9].1 = d;
        }
        let mut got: Vec<(u32, u32)> =
            mutual_matches(&src, &tgt, usize::MAX).iter().map(|c| (c.source, c.target)).collect();
        got.sort_unstable();
        assert_eq!(got, brute_force(&src, &tgt));
        // The planted copies are the most distinctive matches.
        let top = mutual_matches(&src, &tgt, 50);
        assert!(top.iter().all(|c| c.source % 21 == 0 && c.ratio < 0.1), "{top:?}");
    }
}
