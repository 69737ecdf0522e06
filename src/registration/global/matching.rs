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

use std::num::NonZeroUsize;

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use rayon::prelude::*;

use super::fpfh::{DIM, Descriptor};

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
    let (Some(src_tree), Some(tgt_tree)) = (build(source), build(target)) else { return Vec::new() };
    let two = NonZeroUsize::new(2).unwrap_or(NonZeroUsize::MIN);
    // Source → target: nearest and second nearest.
    let forward: Vec<(u32, f32, f32)> = source
        .par_iter()
        .map(|(_, d)| {
            let nn = tgt_tree.query(d).nearest_n::<SquaredEuclidean<f32>>(two).execute();
            let d1 = nn.first().map_or(f32::INFINITY, |r| r.distance);
            let d2 = nn.get(1).map_or(f32::INFINITY, |r| r.distance);
            (nn.first().map_or(u32::MAX, |r| r.item), d1, d2)
        })
        .collect();
    // Target → source: nearest only.
    let backward: Vec<u32> = target
        .par_iter()
        .map(|(_, d)| src_tree.query(d).nearest_one::<SquaredEuclidean<f32>>().execute().item)
        .collect();
    let mut out: Vec<Correspondence> = forward
        .iter()
        .enumerate()
        .filter(|&(i, &(j, _, _))| j != u32::MAX && backward[j as usize] as usize == i)
        .map(|(i, &(j, d1, d2))| {
            let ratio = if d2 > 0.0 && d2.is_finite() { (d1 / d2).sqrt() } else { 1.0 };
            Correspondence { source: source[i].0, target: target[j as usize].0, ratio }
        })
        .collect();
    out.sort_by(|a, b| a.ratio.total_cmp(&b.ratio).then(a.source.cmp(&b.source)));
    out.truncate(max_correspondences);
    out
}

fn build(set: &[(u32, Descriptor)]) -> Option<ImmutableKdTree<f32, DIM>> {
    let pts: Vec<Descriptor> = set.iter().map(|(_, d)| *d).collect();
    if pts.len() > u32::MAX as usize {
        return None;
    }
    ImmutableKdTree::<f32, DIM>::new_from_slice(&pts).ok()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    fn random_descriptors(n: usize, seed: u64) -> Vec<(u32, Descriptor)> {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        (0..n as u32).map(|i| (i * 3, std::array::from_fn(|_| rng.random_range(0.0f32..10.0)))).collect()
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
            d[0] += 0.01;
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
