//! Amanatides-Woo voxel traversal (MATH.md §6) and the free/hit rule.
//!
//! [`traverse`] visits, in order, every voxel the segment `origin → end`
//! passes through, from the origin's voxel to the endpoint's voxel. Each step
//! changes exactly one key coordinate by ±1, so the visited voxels are
//! face-connected and none repeats. Where the segment crosses an edge or a
//! corner exactly, one of the voxels that touch it only there is visited too
//! (a face-connected walk has to pass through one).
//!
//! Robustness: the walk takes exactly `|Δi| + |Δj| + |Δk|` steps between the
//! two keys computed with [`VoxelKey`]'s own `floor(p / voxel)`, stepping only
//! along axes that have not yet reached the endpoint's key. Rounding can
//! therefore reorder two nearly simultaneous crossings but can never overshoot,
//! loop, or end anywhere but the endpoint's voxel.

use crate::geometry::VoxelKey;

/// Keys are `i32`; points whose key would not fit (or come near the limit,
/// so `key ± 1` cannot overflow) are refused.
const MAX_KEY: f64 = (i32::MAX / 2) as f64;

/// The voxel index of one coordinate, `None` when not finite or out of range.
fn key_coord(x_m: f64, voxel_m: f64) -> Option<i32> {
    let k = (x_m / voxel_m).floor();
    (k.is_finite() && k.abs() <= MAX_KEY).then_some(k as i32)
}

/// The key of `p_m`, the same as `VoxelKey::of` but `None` for a point with a
/// non-finite coordinate or one outside the `i32` key range.
pub fn voxel_key(p_m: &[f64; 3], voxel_m: f64) -> Option<VoxelKey> {
    Some(VoxelKey([key_coord(p_m[0], voxel_m)?, key_coord(p_m[1], voxel_m)?, key_coord(p_m[2], voxel_m)?]))
}

/// Calls `f` for every voxel the segment `origin_m → end_m` passes through, in
/// order from the origin's voxel to the endpoint's voxel (both included; one
/// voxel when they coincide). Returns the number of voxels visited.
///
/// Visits nothing (returns 0) when `voxel_m` is not a positive finite number
/// or a coordinate is not finite or outside the `i32` key range. A ray of
/// length L visits at most `3·L/voxel_m + 1` voxels: very long rays are slow
/// but finite.
pub fn traverse(origin_m: &[f64; 3], end_m: &[f64; 3], voxel_m: f64, mut f: impl FnMut(VoxelKey)) -> usize {
    if !(voxel_m.is_finite() && voxel_m > 0.0) {
        return 0;
    }
    let (Some(start), Some(stop)) = (voxel_key(origin_m, voxel_m), voxel_key(end_m, voxel_m)) else {
        return 0;
    };
    let mut key = start.0;
    let mut step = [0i32; 3];
    // Ray parameter t ∈ [0, 1] at the next boundary crossing along each axis,
    // and the increment of t between successive crossings.
    let mut t_max = [f64::INFINITY; 3];
    let mut t_delta = [f64::INFINITY; 3];
    let mut remaining = 0u64;
    for a in 0..3 {
        let d = end_m[a] - origin_m[a];
        let dk = stop.0[a] as i64 - start.0[a] as i64;
        remaining += dk.unsigned_abs();
        // The axis steps towards the endpoint's key; `d` can only disagree in
        // sign with `dk` through rounding, and then `dk` is 0 or the step
        // is forced by `remaining` below.
        step[a] = dk.signum() as i32;
        if step[a] != 0 && d != 0.0 {
            let boundary = if step[a] > 0 { (key[a] as f64 + 1.0) * voxel_m } else { key[a] as f64 * voxel_m };
            t_max[a] = (boundary - origin_m[a]) / d;
            t_delta[a] = voxel_m / d.abs();
        }
    }
    f(VoxelKey(key));
    let mut visited = 1;
    while remaining > 0 {
        // The earliest crossing among axes that still have to move.
        let mut axis = usize::MAX;
        for a in 0..3 {
            if key[a] != stop.0[a] && (axis == usize::MAX || t_max[a] < t_max[axis]) {
                axis = a;
            }
        }
        key[axis] += step[axis];
        t_max[axis] += t_delta[axis];
        remaining -= 1;
        f(VoxelKey(key));
        visited += 1;
    }
    visited
}

/// Casts one ray and applies MATH.md §6's rule, returning the hit voxel.
///
/// With the traversal `k0, k1, …, kN` (`kN` the endpoint's voxel):
/// - `kN` is the **hit** (returned);
/// - `k0 … k(N-2)` are **free** (`on_free` is called for each, in order);
/// - `k(N-1)`, the voxel just before the endpoint's, is neither: stopping one
///   voxel short spares thin surfaces whose points fall just past a voxel
///   boundary (choice, MATH.md §6).
///
/// So a ray within one voxel is a hit only, a ray across two voxels frees
/// nothing, and the sensor's own voxel is free once the ray spans three or
/// more voxels. `None` (and no free voxel) when [`traverse`] visits nothing.
pub fn cast_ray(
    origin_m: &[f64; 3],
    end_m: &[f64; 3],
    voxel_m: f64,
    mut on_free: impl FnMut(VoxelKey),
) -> Option<VoxelKey> {
    // A two-deep delay line: a voxel is known to be free once two more follow.
    let mut last: Option<VoxelKey> = None;
    let mut before_last: Option<VoxelKey> = None;
    traverse(origin_m, end_m, voxel_m, |k| {
        if let Some(free) = before_last {
            on_free(free);
        }
        before_last = last;
        last = Some(k);
    });
    last
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::collections::BTreeSet;

    fn collect(o: [f64; 3], e: [f64; 3], v: f64) -> Vec<VoxelKey> {
        let mut out = Vec::new();
        let n = traverse(&o, &e, v, |k| out.push(k));
        assert_eq!(n, out.len());
        out
    }

    /// The slow reference: the voxels of points sampled every `v / 200`
    /// along the segment (and both ends). A sample within 1e-9 of a voxel
    /// boundary along an axis the segment moves in is left out: there `floor`
    /// may name a voxel the segment only touches at an edge or corner, where
    /// the walk is free to pick another one (its neighbours along the segment
    /// still find the voxels on both sides).
    fn sampled(o: [f64; 3], e: [f64; 3], v: f64) -> BTreeSet<VoxelKey> {
        let len = (0..3).map(|a| (e[a] - o[a]).powi(2)).sum::<f64>().sqrt();
        let n = ((len / (v / 200.0)).ceil() as usize).max(1);
        let on_boundary = |p: &[f64; 3]| (0..3).any(|a| e[a] != o[a] && ((p[a] / v).round() * v - p[a]).abs() <= 1e-9);
        (0..=n)
            .map(|i| {
                let t = i as f64 / n as f64;
                [o[0] + t * (e[0] - o[0]), o[1] + t * (e[1] - o[1]), o[2] + t * (e[2] - o[2])]
            })
            .filter(|p| !on_boundary(p))
            .map(|p| voxel_key(&p, v).unwrap())
            .collect()
    }

    /// Whether the segment comes within `tol` of the voxel's box (slab test on
    /// the box grown by `tol`).
    fn touches(o: [f64; 3], e: [f64; 3], v: f64, k: VoxelKey, tol: f64) -> bool {
        let (mut t0, mut t1) = (0.0f64, 1.0f64);
        for a in 0..3 {
            let lo = k.0[a] as f64 * v - tol;
            let hi = (k.0[a] as f64 + 1.0) * v + tol;
            let d = e[a] - o[a];
            if d == 0.0 {
                if o[a] < lo || o[a] > hi {
                    return false;
                }
            } else {
                let (ta, tb) = ((lo - o[a]) / d, (hi - o[a]) / d);
                t0 = t0.max(ta.min(tb));
                t1 = t1.min(ta.max(tb));
            }
        }
        t0 <= t1
    }

    fn check_against_reference(o: [f64; 3], e: [f64; 3], v: f64) {
        let fast = collect(o, e, v);
        assert_eq!(fast.first(), voxel_key(&o, v).as_ref());
        assert_eq!(fast.last(), voxel_key(&e, v).as_ref());
        for w in fast.windows(2) {
            let diff: i32 = (0..3).map(|a| (w[1].0[a] - w[0].0[a]).abs()).sum();
            assert_eq!(diff, 1, "not face-connected: {:?} → {:?}", w[0], w[1]);
        }
        let set: BTreeSet<VoxelKey> = fast.iter().copied().collect();
        assert_eq!(set.len(), fast.len(), "a voxel repeats");
        for k in sampled(o, e, v) {
            assert!(set.contains(&k), "reference voxel {k:?} not visited for {o:?} → {e:?} at {v}");
        }
        for &k in &fast {
            assert!(touches(o, e, v, k, 1e-9), "visited {k:?} that the segment {o:?} → {e:?} misses");
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(300))]
        #[test]
        fn visits_what_a_dense_sampling_finds(
            o in prop::array::uniform3(-20.0f64..20.0),
            e in prop::array::uniform3(-20.0f64..20.0),
            v in 0.1f64..2.0,
        ) {
            check_against_reference(o, e, v);
        }

        #[test]
        fn short_rays_and_grid_aligned_ends(
            o in prop::array::uniform3(-10i32..10),
            e in prop::array::uniform3(-10i32..10),
            jitter in prop::array::uniform3(prop::sample::select(vec![0.0, 0.25, 0.5, 1.0])),
        ) {
            // Ends on voxel boundaries, edges and corners at voxel 0.5.
            let v = 0.5;
            let o = [o[0] as f64 * 0.5 * jitter[0], o[1] as f64 * 0.5, o[2] as f64 * 0.5 * jitter[2]];
            let e = [e[0] as f64 * 0.5, e[1] as f64 * 0.5 * jitter[1], e[2] as f64 * 0.5];
            check_against_reference(o, e, v);
        }
    }

    #[test]
    fn axis_parallel_rays_walk_one_axis() {
        for a in 0..3 {
            let o = [0.1, 0.1, 0.1];
            let mut e = o;
            e[a] = -1.05;
            let keys = collect(o, e, 0.2);
            assert_eq!(keys.len(), 7, "0.1 → -1.05 crosses voxels 0, -1, …, -6");
            for (i, k) in keys.iter().enumerate() {
                let mut want = [0; 3];
                want[a] = -(i as i32);
                assert_eq!(k.0, want);
            }
        }
        // A ray lying in a voxel face stays on the side `floor` picks.
        check_against_reference([0.0, 0.2, 0.0], [3.0, 0.2, 0.0], 0.2);
    }

    #[test]
    fn a_diagonal_through_corners_stays_connected() {
        check_against_reference([0.0; 3], [2.0, 2.0, 2.0], 0.2);
        check_against_reference([0.0; 3], [-2.0, 2.0, -2.0], 0.2);
        let keys = collect([0.0; 3], [2.0, 2.0, 2.0], 0.2);
        assert_eq!(keys.len(), 3 * 10 + 1);
    }

    #[test]
    fn degenerate_rays_do_not_panic() {
        assert_eq!(collect([0.3; 3], [0.3; 3], 0.2), vec![VoxelKey([1, 1, 1])]);
        assert!(collect([f64::NAN, 0.0, 0.0], [1.0; 3], 0.2).is_empty());
        assert!(collect([0.0; 3], [f64::INFINITY, 0.0, 0.0], 0.2).is_empty());
        assert!(collect([0.0; 3], [1e12, 0.0, 0.0], 0.2).is_empty(), "key outside i32");
        assert!(collect([0.0; 3], [1.0; 3], 0.0).is_empty());
        assert!(collect([0.0; 3], [1.0; 3], -0.2).is_empty());
        assert!(collect([0.0; 3], [1.0; 3], f64::NAN).is_empty());
        // Long: 100 km at 0.2 m, 500,001 voxels along x.
        let n = traverse(&[0.1, 0.1, 0.1], &[1e5, 0.1, 0.1], 0.2, |_| {});
        assert_eq!(n, 500_001);
        // Tiny segments across a boundary.
        assert_eq!(collect([0.2 - 1e-13, 0.1, 0.1], [0.2 + 1e-13, 0.1, 0.1], 0.2).len(), 2);
    }

    #[test]
    fn cast_ray_frees_all_but_the_last_two_voxels() {
        let (o, e) = ([0.1, 0.1, 0.1], [10.1, 0.1, 0.1]);
        let all = collect(o, e, 0.2);
        let mut free = Vec::new();
        let hit = cast_ray(&o, &e, 0.2, |k| free.push(k));
        assert_eq!(hit, Some(VoxelKey([50, 0, 0])));
        assert_eq!(all.len(), 51);
        assert_eq!(free, all[..all.len() - 2].to_vec());
        assert_eq!(free.last(), Some(&VoxelKey([48, 0, 0])));

        let mut free = Vec::new();
        assert_eq!(cast_ray(&[0.1; 3], &[0.15; 3], 0.2, |k| free.push(k)), Some(VoxelKey([0; 3])));
        assert_eq!(cast_ray(&[0.1; 3], &[0.3, 0.1, 0.1], 0.2, |k| free.push(k)), Some(VoxelKey([1, 0, 0])));
        assert!(free.is_empty(), "one- and two-voxel rays free nothing");
        assert_eq!(cast_ray(&[0.1; 3], &[f64::NAN; 3], 0.2, |k| free.push(k)), None);
        assert!(free.is_empty());
    }
}
