//! One keyframe's rays into a hash map of every voxel they touch (MATH.md
//! §6, eq. 4). The pipeline keeps evidence on an interest set instead
//! ([`super::grid`]); this full map is the reference that version is tested
//! against, and what `examples/raycast_bench` times.
//!
//! Two passes, so that a voxel counts at most once per keyframe and kind:
//! 1. cast every ray and mark each voxel it touches as hit and/or free in a
//!    per-keyframe set: 2 bits per voxel of the keyframe's key box (16 MiB
//!    at most, shared by the threads through atomic `or`s), or a hash set
//!    when the box is larger (per thread in the parallel version, merged);
//! 2. add each marked voxel's q and `q u uᵀ` once per kind.
//!
//! Because pass 2 adds one term per voxel and kind regardless of how the rays
//! were split, the parallel and serial versions give bit-identical maps.

use super::grid::{Box3, FREE, HIT, Marks};
use super::raycast::{cast_ray, voxel_key};
use super::stats::{EvidenceConfig, VoxelEvidence};
use crate::geometry::VoxelKey;
use rayon::prelude::*;
use rustc_hash::FxHashMap;

/// Evidence per voxel, for the keyframes of one submap in the frame they
/// were given in.
pub type EvidenceMap = FxHashMap<VoxelKey, VoxelEvidence>;

/// Dense marks cover at most this many voxels (2 bits each: 16 MiB); a
/// keyframe whose key box is larger falls back to a hash set.
const DENSE_MAX_VOXELS: u64 = 1 << 26;

/// What one keyframe added, as diagnostics.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct KeyframeEvidence {
    /// Rays cast (points given).
    pub rays: usize,
    /// Rays skipped: a non-finite coordinate or a key out of `i32` range.
    pub skipped_rays: usize,
    /// Distinct voxels that got a hit from this keyframe.
    pub hit_voxels: usize,
    /// Distinct voxels that got a free from this keyframe.
    pub free_voxels: usize,
}

/// Casts one ray, calling `mark(key, HIT or FREE)`; false when skipped.
fn mark_ray(origin_m: &[f64; 3], point_m: &[f64; 3], voxel_m: f64, mut mark: impl FnMut(VoxelKey, u64)) -> bool {
    let hit = cast_ray(origin_m, point_m, voxel_m, |k| mark(k, FREE));
    if let Some(k) = hit {
        mark(k, HIT);
    }
    hit.is_some()
}

/// The per-keyframe set `{voxel → hit/free}` as [`Marks`] over the key box
/// spanned by the sensor and the points (a ray's walk never leaves the box
/// of its two end keys); `None` when the box is too large.
fn dense_marks(origin_m: &[f64; 3], points_m: &[[f64; 3]], voxel_m: f64) -> Option<Marks> {
    voxel_key(origin_m, voxel_m)?;
    let b = Box3::of_rays(origin_m, points_m, voxel_m);
    (b.volume() <= DENSE_MAX_VOXELS).then(|| Marks::new(b))
}

/// The hash-set fallback for keyframes whose key box is too large.
type SparseMarks = FxHashMap<VoxelKey, u64>;

/// Adds one keyframe's rays, sensor at `origin_world` and points
/// `points_world` (any common frame: seam uses the submap frame), to `map`.
/// Each voxel counts at most once per kind for this keyframe, so call this
/// once per keyframe.
pub fn accumulate_keyframe(
    origin_world: &[f64; 3],
    points_world: &[[f64; 3]],
    keyframe: u32,
    cfg: &EvidenceConfig,
    map: &mut EvidenceMap,
) -> KeyframeEvidence {
    let v = cfg.voxel_size_m;
    let mut cast = 0;
    if let Some(dense) = dense_marks(origin_world, points_world, v) {
        for p in points_world {
            cast += mark_ray(origin_world, p, v, |k, kind| dense.mark(k, kind)) as usize;
        }
        reserve(map, dense.count());
        apply(origin_world, dense.iter(), points_world.len(), cast, keyframe, cfg, map)
    } else {
        let mut marks = SparseMarks::default();
        for p in points_world {
            cast += mark_ray(origin_world, p, v, |k, kind| *marks.entry(k).or_default() |= kind) as usize;
        }
        reserve(map, marks.len());
        apply(origin_world, marks.into_iter(), points_world.len(), cast, keyframe, cfg, map)
    }
}

/// [`accumulate_keyframe`] with the rays cast in parallel (rayon); the
/// resulting map is identical.
pub fn accumulate_keyframe_par(
    origin_world: &[f64; 3],
    points_world: &[[f64; 3]],
    keyframe: u32,
    cfg: &EvidenceConfig,
    map: &mut EvidenceMap,
) -> KeyframeEvidence {
    let v = cfg.voxel_size_m;
    let rays = points_world.par_iter().with_min_len(1024);
    if let Some(dense) = dense_marks(origin_world, points_world, v) {
        let cast = rays.map(|p| mark_ray(origin_world, p, v, |k, kind| dense.mark(k, kind)) as usize).sum();
        reserve(map, dense.count());
        apply(origin_world, dense.iter(), points_world.len(), cast, keyframe, cfg, map)
    } else {
        // Per-thread sets, merged.
        let (marks, cast) = rays
            .fold(
                || (SparseMarks::default(), 0usize),
                |(mut marks, cast), p| {
                    let ok = mark_ray(origin_world, p, v, |k, kind| *marks.entry(k).or_default() |= kind);
                    (marks, cast + ok as usize)
                },
            )
            .reduce(|| (SparseMarks::default(), 0), merge_marks);
        reserve(map, marks.len());
        apply(origin_world, marks.into_iter(), points_world.len(), cast, keyframe, cfg, map)
    }
}

/// Room for a keyframe's `marked` voxels, assuming those already in `map`
/// are among them: keyframes of a submap overlap, and reserving `marked` on a
/// full map would double (and rehash) it for nothing.
fn reserve(map: &mut EvidenceMap, marked: usize) {
    map.reserve(marked.saturating_sub(map.len()));
}

fn merge_marks((a, ca): (SparseMarks, usize), (b, cb): (SparseMarks, usize)) -> (SparseMarks, usize) {
    let (mut big, small) = if a.len() >= b.len() { (a, b) } else { (b, a) };
    for (k, m) in small {
        *big.entry(k).or_default() |= m;
    }
    (big, ca + cb)
}

/// Pass 2: eq. 4 once per marked voxel and kind.
fn apply(
    origin_m: &[f64; 3],
    marks: impl Iterator<Item = (VoxelKey, u64)>,
    rays: usize,
    cast: usize,
    keyframe: u32,
    cfg: &EvidenceConfig,
    map: &mut EvidenceMap,
) -> KeyframeEvidence {
    let mut out = KeyframeEvidence { rays, skipped_rays: rays - cast, ..Default::default() };
    for (key, mut kinds) in marks {
        // A keyframe does not free a voxel it hit (as in `grid`).
        if kinds & HIT != 0 {
            kinds &= !FREE;
        }
        let c = key.center_m(cfg.voxel_size_m);
        let d = [c.x - origin_m[0], c.y - origin_m[1], c.z - origin_m[2]];
        let r = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        // The sensor exactly at a voxel centre has no direction to it.
        let u = if r > 0.0 { [d[0] / r, d[1] / r, d[2] / r] } else { [0.0; 3] };
        let q = cfg.range_weight(r);
        let v = map.entry(key).or_default();
        if kinds & HIT != 0 {
            v.hit.add(q, &u);
            out.hit_voxels += 1;
        }
        if kinds & FREE != 0 {
            v.free.add(q, &u);
            out.free_voxels += 1;
        }
        v.offer_owner(keyframe, q * kinds.count_ones() as f64);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn cfg() -> EvidenceConfig {
        EvidenceConfig::default()
    }

    fn sorted(map: &EvidenceMap) -> Vec<(VoxelKey, VoxelEvidence)> {
        let mut v: Vec<_> = map.iter().map(|(k, e)| (*k, *e)).collect();
        v.sort_by_key(|(k, _)| *k);
        v
    }

    fn close(a: &VoxelEvidence, b: &VoxelEvidence) -> bool {
        let kind = |x: &super::super::stats::DirectionalStats, y: &super::super::stats::DirectionalStats| {
            x.n == y.n && (x.q_sum - y.q_sum).abs() <= 1e-9 && x.m.iter().zip(y.m).all(|(p, q)| (p - q).abs() <= 1e-9)
        };
        kind(&a.hit, &b.hit) && kind(&a.free, &b.free) && a.owner_keyframe == b.owner_keyframe
    }

    #[test]
    fn parallel_equals_serial() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let (mut serial, mut parallel) = (EvidenceMap::default(), EvidenceMap::default());
        for kf in 0..4u32 {
            let origin = [kf as f64 * 1.3, 0.2 * kf as f64, 1.7];
            let mut points: Vec<[f64; 3]> = (0..20_000)
                .map(|_| {
                    let (a, b) = (rng.random::<f64>() * std::f64::consts::TAU, rng.random::<f64>() - 0.5);
                    let r = 2.0 + rng.random::<f64>() * 40.0;
                    [origin[0] + r * a.cos(), origin[1] + r * a.sin(), origin[2] + r * b * 0.3]
                })
                .collect();
            points.push([f64::NAN, 0.0, 0.0]);
            let s = accumulate_keyframe(&origin, &points, kf, &cfg(), &mut serial);
            let p = accumulate_keyframe_par(&origin, &points, kf, &cfg(), &mut parallel);
            assert_eq!(s, p);
            assert_eq!(s.skipped_rays, 1);
        }
        let (s, p) = (sorted(&serial), sorted(&parallel));
        assert_eq!(s.len(), p.len());
        for ((ks, es), (kp, ep)) in s.iter().zip(&p) {
            assert_eq!(ks, kp);
            assert!(close(es, ep), "{ks:?}: {es:?} vs {ep:?}");
        }
        // Stronger than asked: pass 2 makes them bit-identical.
        assert_eq!(serial, parallel);
    }

    #[test]
    fn the_hash_set_fallback_agrees() {
        // Key boxes far beyond the dense limit force the hash-set path.
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let points: Vec<[f64; 3]> =
            (0..300).map(|_| std::array::from_fn(|_| (rng.random::<f64>() - 0.5) * 400.0)).collect();
        let (mut serial, mut parallel) = (EvidenceMap::default(), EvidenceMap::default());
        let s = accumulate_keyframe(&[0.3; 3], &points, 0, &cfg(), &mut serial);
        let p = accumulate_keyframe_par(&[0.3; 3], &points, 0, &cfg(), &mut parallel);
        assert_eq!(s, p);
        assert_eq!(serial, parallel);
        // One diagonal ray: hit at its end, every voxel but the last two free.
        let mut map = EvidenceMap::default();
        let end = [1000.1, 1000.1, 1000.1];
        let visited = super::super::raycast::traverse(&[0.1; 3], &end, 0.2, |_| {});
        let d = accumulate_keyframe(&[0.1; 3], &[end], 0, &cfg(), &mut map);
        assert_eq!((d.hit_voxels, d.free_voxels), (1, visited - 2));
        assert_eq!(map[&VoxelKey([5000; 3])].hit.n, 1);
    }

    #[test]
    fn a_ray_along_x_hits_its_end_and_frees_the_way() {
        let mut map = EvidenceMap::default();
        let origin = [0.1, 0.1, 0.1];
        let d = accumulate_keyframe(&origin, &[[10.1, 0.1, 0.1]], 7, &cfg(), &mut map);
        assert_eq!(d, KeyframeEvidence { rays: 1, skipped_rays: 0, hit_voxels: 1, free_voxels: 49 });
        let end = map[&VoxelKey([50, 0, 0])];
        assert_eq!((end.hit.n, end.free.n), (1, 0));
        assert_eq!(end.hit.q_sum, 1.0, "within r0 the weight is 1");
        assert!((end.hit.m[0] - 1.0).abs() < 1e-12 && end.hit.m[1..].iter().all(|m| m.abs() < 1e-12), "u = +x");
        assert_eq!((end.owner_keyframe, end.owner_q), (7, 1.0));
        assert!(!map.contains_key(&VoxelKey([49, 0, 0])), "one voxel short of the endpoint");
        for i in 0..49 {
            let v = map[&VoxelKey([i, 0, 0])];
            assert_eq!((v.hit.n, v.free.n), (0, 1), "voxel {i}");
        }
        assert_eq!(map.len(), 50);
    }

    #[test]
    fn counts_are_per_keyframe() {
        let mut map = EvidenceMap::default();
        // Three points in one voxel, twice in the same keyframe: one hit.
        let pts = [[5.05, 0.1, 0.1], [5.15, 0.15, 0.1], [5.1, 0.1, 0.19], [5.05, 0.1, 0.1]];
        let d = accumulate_keyframe(&[0.1, 0.1, 0.1], &pts, 0, &cfg(), &mut map);
        assert_eq!(d.hit_voxels, 1);
        let key = VoxelKey([25, 0, 0]);
        assert_eq!(map[&key].hit.n, 1);
        // The same point from a second keyframe: n = 2, Q adds up.
        accumulate_keyframe(&[0.1, 3.1, 0.1], &pts[..1], 1, &cfg(), &mut map);
        assert_eq!(map[&key].hit.n, 2);
        assert_eq!(map[&key].hit.q_sum, 2.0);
        // Free voxels shared by many rays of one keyframe count once too.
        assert_eq!(map[&VoxelKey([3, 0, 0])].free.n, 1);
    }

    #[test]
    fn owner_is_the_keyframe_with_the_largest_weight() {
        let mut map = EvidenceMap::default();
        let p = [[30.1, 0.1, 0.1]];
        accumulate_keyframe(&[0.1, 0.1, 0.1], &p, 0, &cfg(), &mut map); // r = 30 m
        accumulate_keyframe(&[20.1, 0.1, 0.1], &p, 1, &cfg(), &mut map); // r = 10 m
        accumulate_keyframe(&[-20.1, 0.1, 0.1], &p, 2, &cfg(), &mut map); // r = 50 m
        let v = map[&VoxelKey([150, 0, 0])];
        assert_eq!((v.hit.n, v.owner_keyframe, v.owner_q), (3, 1, 1.0));
        // A voxel one keyframe both hit and passed through counts as a hit
        // only (the hit wins), with weight q.
        let mut map = EvidenceMap::default();
        let origin = [0.1, 0.1, 0.1];
        accumulate_keyframe(&origin, &[[1.1, 0.1, 0.1], [3.1, 0.1, 0.1]], 4, &cfg(), &mut map);
        let v = map[&VoxelKey([5, 0, 0])];
        assert_eq!((v.hit.n, v.free.n, v.owner_q), (1, 0, 1.0));
    }
}
