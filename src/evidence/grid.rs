//! Evidence on a fixed set of voxels of interest, for speed and memory.
//!
//! DOR only ever asks for ε_l where some point fell, and change detection
//! (MATH.md §8) only where some session's map has a point. Free evidence of
//! a voxel no point ever fell into is never read. So a session's evidence
//! is kept on its **interest set** — the voxels its points (and the earlier
//! sessions' maps) occupy — as a sorted array of packed keys with one
//! fixed-size row each, instead of a hash map over every voxel a ray
//! crossed (≈1.7 M per SemanticKITTI scan at 0.2 m, ≈250 MB with f64 stats).
//!
//! Per keyframe:
//! 1. cast every ray and set 2 bits (hit, free) per voxel of interest
//!    inside the keyframe's ray box (clipped to the interest set's box), by
//!    the voxel's rank in the mask below (`RankMarks`; where the set is
//!    too wide for a mask, a dense bitmap over the box, `Marks`; one
//!    per-ray loop and one pass 2 serve both through `MarkLayout`); bits of
//!    threads meet through atomic `or`s, which commute, so the order rays are
//!    cast in does not matter (rays run in parallel); a ray that ends at the
//!    ground frees nothing within the clearance above its end, nor one
//!    that rises to a level surface within it below its end. Rays walk
//!    only the interest voxels: the keys as 4×4×4 blocks
//!    ([`BlockMask`], built once per set) let a ray jump over a block with
//!    none and pass the others' voxels without marking them (the same
//!    evidence: `bench/dor_vs_dufomap.py` scores identically, and with the
//!    surface shapes probed the same way the evidence step runs 1.4-2.1×
//!    faster; raycast's tests compare the two casts ray by ray);
//! 2. walk the interest voxels inside the box (in parallel: each row is
//!    written by one thread), drop the frees next to the keyframe's own hits
//!    (the guard; hits at the ground level beneath do not guard), and add
//!    eq. 4's `q`, `q u uᵀ` once per kind;
//! 3. with a no-return image (`evidence::no_return`), free the candidate
//!    map voxels whose direction returned nothing, once, whatever else
//!    freed them (pass 2 leaves those rows alone).
//!
//! The box bitmap's pages are zeroed lazily by the OS, so a keyframe only
//! pays for the pages its rays touch; the rank bitmap is small enough
//! (2 bits per voxel of interest) to stay in cache.

use super::ground::GroundLevel;
use super::no_return::NoReturn;
use super::raycast::{BlockMask, cast_ray, cast_ray_ranked, voxel_key};
use super::stats::{DirectionalStats, EvidenceConfig, EvidenceModel, VoxelEvidence};
use super::surface::SurfaceShapes;
use super::tables::{StatsColumns, SubmapEvidence};
use crate::geometry::VoxelKey;
use rayon::prelude::*;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

/// The free clearance (`EvidenceConfig::free_clearance_m`) applies to rays
/// that end at least this far below the sensor (and, by default, at the
/// ground level, `evidence::ground`): not walls seen level, whose rays
/// would otherwise lose every free voxel.
pub(super) const CLEARANCE_MIN_DROP_M: f64 = 0.5;

pub(super) const HIT: u64 = 1;
pub(super) const FREE: u64 = 2;

/// Bits per key axis in a packed key; keys span ±2^20 voxels (±210 km at 0.2 m).
const AXIS_BITS: u32 = 21;
const AXIS_OFFSET: i64 = 1 << (AXIS_BITS - 1);
const AXIS_MASK: u64 = (1 << AXIS_BITS) - 1;

/// Dense marks cover at most this many voxels (2 bits each: 64 MiB); larger
/// boxes are cut to the part nearest the sensor (see [`Box3::limit`]).
const DENSE_MAX_VOXELS: u64 = 1 << 28;

/// A voxel key packed into a `u64` that sorts like `(x, y, z)`; `None` when a
/// coordinate is outside ±2^20.
pub fn pack(k: VoxelKey) -> Option<u64> {
    let mut out = 0u64;
    for c in k.0 {
        let c = c as i64 + AXIS_OFFSET;
        if !(0..=AXIS_MASK as i64).contains(&c) {
            return None;
        }
        out = (out << AXIS_BITS) | c as u64;
    }
    Some(out)
}

pub fn unpack(p: u64) -> VoxelKey {
    let c = |shift: u32| (((p >> shift) & AXIS_MASK) as i64 - AXIS_OFFSET) as i32;
    VoxelKey([c(2 * AXIS_BITS), c(AXIS_BITS), c(0)])
}

/// The packed key of a point, `None` if not finite or out of range.
pub fn packed_key(p_m: &[f64; 3], voxel_m: f64) -> Option<u64> {
    voxel_key(p_m, voxel_m).and_then(pack)
}

/// An inclusive box of voxel keys.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Box3 {
    pub lo: [i32; 3],
    pub hi: [i32; 3],
}

impl Default for Box3 {
    fn default() -> Self {
        Box3::EMPTY
    }
}

impl Box3 {
    pub const EMPTY: Box3 = Box3 { lo: [i32::MAX; 3], hi: [i32::MIN; 3] };

    pub fn is_empty(&self) -> bool {
        (0..3).any(|a| self.lo[a] > self.hi[a])
    }

    pub fn add(&mut self, k: VoxelKey) {
        for a in 0..3 {
            self.lo[a] = self.lo[a].min(k.0[a]);
            self.hi[a] = self.hi[a].max(k.0[a]);
        }
    }

    /// Every voxel whose x lies in `x0..=x1`.
    pub fn x_slab(x0: i32, x1: i32) -> Box3 {
        Box3 { lo: [x0, i32::MIN, i32::MIN], hi: [x1, i32::MAX, i32::MAX] }
    }

    pub fn union(&self, o: &Box3) -> Box3 {
        Box3 { lo: [0, 1, 2].map(|a| self.lo[a].min(o.lo[a])), hi: [0, 1, 2].map(|a| self.hi[a].max(o.hi[a])) }
    }

    pub fn intersect(&self, o: &Box3) -> Box3 {
        Box3 { lo: [0, 1, 2].map(|a| self.lo[a].max(o.lo[a])), hi: [0, 1, 2].map(|a| self.hi[a].min(o.hi[a])) }
    }

    pub fn contains(&self, k: &[i32; 3]) -> bool {
        (0..3).all(|a| self.lo[a] <= k[a] && k[a] <= self.hi[a])
    }

    /// Index of `k` (inside the box) in x-fastest order, with `dims` from [`Self::dims`].
    #[inline]
    pub(super) fn index_of(&self, k: &[i32; 3], dims: &[u64; 3]) -> u64 {
        let [x, y, z] = [0, 1, 2].map(|a| (k[a] as i64 - self.lo[a] as i64) as u64);
        (z * dims[1] + y) * dims[0] + x
    }

    /// The range of sorted packed `keys` whose x lies in this box's x range.
    pub(super) fn packed_x_range(&self, keys: &[u64]) -> (usize, usize) {
        if self.is_empty() {
            return (0, 0);
        }
        let start = |x: i64| ((x + AXIS_OFFSET).clamp(0, AXIS_MASK as i64 + 1) as u64) << (2 * AXIS_BITS);
        let (x0, x1) = (start(self.lo[0] as i64), start(self.hi[0] as i64 + 1));
        let lo = keys.partition_point(|&k| k < x0);
        let hi = keys.partition_point(|&k| k < x1);
        (lo.min(hi), hi)
    }

    pub(super) fn dims(&self) -> [u64; 3] {
        [0, 1, 2].map(|a| (self.hi[a] as i64 - self.lo[a] as i64 + 1).max(0) as u64)
    }

    pub(super) fn volume(&self) -> u64 {
        let [x, y, z] = self.dims();
        x.saturating_mul(y).saturating_mul(z)
    }

    /// The box of packed keys.
    pub(super) fn of_packed(keys: &[u64]) -> Box3 {
        let mut b = Box3::EMPTY;
        for &k in keys {
            b.add(unpack(k));
        }
        b
    }

    /// The box of a keyframe's rays: its sensor and every point.
    pub fn of_rays(origin_m: &[f64; 3], points_m: &[[f64; 3]], voxel_m: f64) -> Box3 {
        let mut b = Box3::EMPTY;
        if let Some(k) = voxel_key(origin_m, voxel_m) {
            b.add(k);
        }
        for k in points_m.iter().filter_map(|p| voxel_key(p, voxel_m)) {
            b.add(k);
        }
        b
    }

    /// The keys within `range_m` (plus a voxel) of `origin_m` on every
    /// axis; empty when the origin is off the grid.
    pub fn within_range(origin_m: &[f64; 3], range_m: f64, voxel_m: f64) -> Box3 {
        let reach = (range_m / voxel_m).ceil() as i32 + 1;
        voxel_key(origin_m, voxel_m).map_or(Box3::EMPTY, |o| Box3 {
            lo: o.0.map(|c| c.saturating_sub(reach)),
            hi: o.0.map(|c| c.saturating_add(reach)),
        })
    }

    /// Shrinks the horizontal extent symmetrically around `centre` until the
    /// box holds at most `max` voxels: voxels far from the sensor then get no
    /// evidence from this keyframe, where their weight q was smallest.
    fn limit(self, centre: [i32; 3], max: u64) -> Box3 {
        let mut b = self;
        let mut half = 1i64 << 20;
        while b.volume() > max && half > 0 {
            half /= 2;
            for (a, &c) in centre.iter().enumerate().take(2) {
                b.lo[a] = self.lo[a].max((c as i64 - half) as i32);
                b.hi[a] = self.hi[a].min((c as i64 + half) as i32);
            }
        }
        b
    }
}

/// 2 bits per voxel of a box, set through atomic `or`s.
pub(super) struct Marks {
    b: Box3,
    dims: [u64; 3],
    words: Box<[AtomicU64]>,
}

/// Whether bit `i` of a row bitset is set (bits past its end are not).
pub(super) fn bit_set(bits: &[u64], i: usize) -> bool {
    bits.get(i / 64).is_some_and(|w| w & (1 << (i % 64)) != 0)
}

/// One keyframe's marks: `all` (hits, and frees above `free_clearance_m`)
/// and `band`, the frees only the lower clearance of vacated map voxels
/// allows (`EvidenceConfig::free_vacated_low`); over the keyframe's ray box
/// `b`, by voxel of interest ([`RankMarks`]) or, where the interest set has
/// no mask, by place in the box ([`Marks`]).
struct KeyframeMarks<M> {
    b: Box3,
    all: M,
    band: Option<M>,
}

impl Marks {
    pub(super) fn new(b: Box3) -> Marks {
        let dims = b.dims();
        let n = (b.volume().div_ceil(32)) as usize;
        Marks { b, dims, words: zeroed_atomics(n) }
    }

    #[inline]
    fn index(&self, k: &[i32; 3]) -> u64 {
        self.b.index_of(k, &self.dims)
    }

    #[inline]
    pub(super) fn mark(&self, k: VoxelKey, kind: u64) {
        if !self.b.contains(&k.0) {
            return;
        }
        let i = self.index(&k.0);
        let word = &self.words[(i / 32) as usize];
        let bits = kind << (2 * (i % 32));
        // Voxels near the sensor are marked by most rays: reading first keeps
        // their cache line shared instead of bouncing between cores.
        if word.load(Ordering::Relaxed) & bits != bits {
            word.fetch_or(bits, Ordering::Relaxed);
        }
    }

    /// Whether a voxel within `r` (Chebyshev) of `k`, other than `k`, is
    /// marked hit. Voxels outside the box count as unmarked. With `ground`,
    /// hits below `k` at their column's ground level do not count.
    fn hit_near(&self, k: &[i32; 3], r: i32, ground: Option<&GroundLevel>) -> bool {
        if r <= 0 {
            return false;
        }
        for dz in -r..=r {
            for dy in -r..=r {
                for dx in -r..=r {
                    let n = [k[0] + dx, k[1] + dy, k[2] + dz];
                    if (dx, dy, dz) != (0, 0, 0)
                        && self.b.contains(&n)
                        && self.get(&n) & HIT != 0
                        && !(dz < 0 && ground.is_some_and(|g| g.at_ground(&n) == Some(true)))
                    {
                        return true;
                    }
                }
            }
        }
        false
    }

    #[inline]
    fn get(&self, k: &[i32; 3]) -> u64 {
        let i = self.index(k);
        (self.words[(i / 32) as usize].load(Ordering::Relaxed) >> (2 * (i % 32))) & 3
    }

    /// Marked voxels, for `HashMap::reserve`.
    pub(super) fn count(&self) -> usize {
        let pairs = |w: u64| ((w | (w >> 1)) & 0x5555_5555_5555_5555).count_ones() as usize;
        self.words.iter().map(|w| pairs(w.load(Ordering::Relaxed))).sum()
    }

    /// Every marked voxel with its kinds, in index order.
    pub(super) fn iter(&self) -> impl Iterator<Item = (VoxelKey, u64)> + '_ {
        let [dx, dy, _] = self.dims;
        self.words.iter().enumerate().flat_map(move |(wi, w)| {
            let w = w.load(Ordering::Relaxed);
            (0..32u64).filter_map(move |j| {
                let kinds = (w >> (2 * j)) & 3;
                (kinds != 0).then(|| {
                    let i = wi as u64 * 32 + j;
                    let (x, y, z) = (i % dx, (i / dx) % dy, i / (dx * dy));
                    let [lx, ly, lz] = self.b.lo.map(i64::from);
                    let k = [x as i64 + lx, y as i64 + ly, z as i64 + lz].map(|c| c as i32);
                    (VoxelKey(k), kinds)
                })
            })
        })
    }
}

/// `n` atomics set to 0, from zeroed memory: the OS hands out zero pages
/// lazily, so pages no ray touches cost nothing.
fn zeroed_atomics(n: usize) -> Box<[AtomicU64]> {
    let Ok(layout) = std::alloc::Layout::array::<AtomicU64>(n) else {
        panic!("evidence marks of {n} words do not fit in memory");
    };
    if layout.size() == 0 {
        return Box::new([]);
    }
    // SAFETY: the layout is non-zero-sized and for `n` AtomicU64s; all-zero
    // bytes are a valid `AtomicU64(0)`; the Box takes ownership of exactly
    // that allocation and frees it with the same layout.
    unsafe {
        let ptr = std::alloc::alloc_zeroed(layout) as *mut AtomicU64;
        if ptr.is_null() {
            std::alloc::handle_alloc_error(layout);
        }
        Box::from_raw(std::ptr::slice_from_raw_parts_mut(ptr, n))
    }
}

/// 2 bits per voxel of interest, by [`BlockMask::rank_of`]: the marks of
/// one keyframe when the interest set has a mask (the usual case).
///
/// Why not [`Marks`] over the ray box: a SemanticKITTI scan's box is
/// 10^7-10^8 voxels, megabytes of bitmap whose pages fault in as the rays
/// touch them (a tenth of the ray casting), and whose marks are scattered
/// over them; the interest set is 10^5-10^6 voxels, a bitmap of tens to
/// hundreds of kilobytes that stays in cache. The walk hands out each
/// voxel's rank ([`super::raycast::cast_ray_ranked`]), so marking costs no
/// lookup.
pub(super) struct RankMarks {
    words: Box<[AtomicU64]>,
}

impl RankMarks {
    fn new(voxels: usize) -> RankMarks {
        RankMarks { words: zeroed_atomics(voxels.div_ceil(32)) }
    }

    #[inline]
    fn mark(&self, rank: u32, kind: u64) {
        let word = &self.words[(rank / 32) as usize];
        let bits = kind << (2 * (rank % 32));
        // As in `Marks::mark`: read first, so shared lines stay shared.
        if word.load(Ordering::Relaxed) & bits != bits {
            word.fetch_or(bits, Ordering::Relaxed);
        }
    }

    #[inline]
    fn get(&self, rank: usize) -> u64 {
        (self.words[rank / 32].load(Ordering::Relaxed) >> (2 * (rank % 32))) & 3
    }

    /// [`Marks::hit_near`] for these marks: voxels outside `b` count as
    /// unmarked, and voxels not of interest were never hit.
    fn hit_near(&self, k: &[i32; 3], r: i32, b: &Box3, mask: &BlockMask, ground: Option<&GroundLevel>) -> bool {
        if r <= 0 {
            return false;
        }
        let lo = [0, 1, 2].map(|a| (k[a] - r).max(b.lo[a]));
        let hi = [0, 1, 2].map(|a| (k[a] + r).min(b.hi[a]));
        mask.any_in_box(lo, hi, |n, rank| {
            n != *k
                && self.get(rank) & HIT != 0
                && !(n[2] < k[2] && ground.is_some_and(|g| g.at_ground(&n) == Some(true)))
        })
    }
}

/// How one keyframe's marks are laid out, and how its rays and
/// [`RowsMut::apply`] reach them: by voxel of interest where the interest
/// set has a mask ([`ByRank`], the usual case), by place in the ray box
/// where it has none ([`ByBox`]). One per-ray loop ([`mark_rays`]) and one
/// pass 2 serve both; each is compiled per layout, so the trait costs the
/// hot loops nothing.
trait MarkLayout: Sync {
    /// Where a voxel is in the marks: its mask rank, or its key.
    type Slot: Copy;
    type Marks: Sync;
    /// Empty marks for a keyframe whose ray box is `b`.
    fn marks(&self, b: &Box3) -> Self::Marks;
    /// Casts the ray from `origin_m` to `end_m`: `on_free` gets each voxel
    /// it frees with its slot, and the hit voxel comes back with its slot
    /// where it has one (the rank layout has none for a hit not of
    /// interest).
    fn cast(
        &self,
        origin_m: &[f64; 3],
        end_m: &[f64; 3],
        voxel_m: f64,
        on_free: impl FnMut(VoxelKey, Self::Slot),
    ) -> Option<(VoxelKey, Option<Self::Slot>)>;
    fn mark(marks: &Self::Marks, slot: Self::Slot, kind: u64);
    /// The kinds marked at row `i`, whose key `k` is inside the ray box.
    fn get(&self, marks: &Self::Marks, i: usize, k: &[i32; 3]) -> u64;
    /// Whether a voxel within `r` (Chebyshev) of `k`, other than `k` and
    /// inside the ray box `b`, is marked hit; with `ground`, hits below `k`
    /// at their column's ground level do not count.
    fn hit_near(&self, marks: &Self::Marks, k: &[i32; 3], r: i32, b: &Box3, ground: Option<&GroundLevel>) -> bool;
}

/// Marks by the rank of the voxel in the interest set's mask
/// ([`RankMarks`]); `ranks` is each row's rank ([`KeyIndex::ranks`]).
struct ByRank<'a> {
    mask: &'a BlockMask,
    ranks: &'a [u32],
}

impl MarkLayout for ByRank<'_> {
    type Slot = u32;
    type Marks = RankMarks;

    fn marks(&self, _: &Box3) -> RankMarks {
        RankMarks::new(self.mask.count())
    }

    #[inline]
    fn cast(
        &self,
        origin_m: &[f64; 3],
        end_m: &[f64; 3],
        voxel_m: f64,
        on_free: impl FnMut(VoxelKey, u32),
    ) -> Option<(VoxelKey, Option<u32>)> {
        cast_ray_ranked(origin_m, end_m, voxel_m, self.mask, on_free)
    }

    #[inline]
    fn mark(marks: &RankMarks, rank: u32, kind: u64) {
        marks.mark(rank, kind)
    }

    #[inline]
    fn get(&self, marks: &RankMarks, i: usize, _: &[i32; 3]) -> u64 {
        marks.get(self.ranks[i] as usize)
    }

    fn hit_near(&self, marks: &RankMarks, k: &[i32; 3], r: i32, b: &Box3, ground: Option<&GroundLevel>) -> bool {
        marks.hit_near(k, r, b, self.mask, ground)
    }
}

/// Marks by place in the keyframe's ray box ([`Marks`]), for interest sets
/// too wide for a mask; rays then visit every voxel.
struct ByBox;

impl MarkLayout for ByBox {
    type Slot = VoxelKey;
    type Marks = Marks;

    fn marks(&self, b: &Box3) -> Marks {
        Marks::new(*b)
    }

    #[inline]
    fn cast(
        &self,
        origin_m: &[f64; 3],
        end_m: &[f64; 3],
        voxel_m: f64,
        mut on_free: impl FnMut(VoxelKey, VoxelKey),
    ) -> Option<(VoxelKey, Option<VoxelKey>)> {
        cast_ray(origin_m, end_m, voxel_m, |k| on_free(k, k)).map(|k| (k, Some(k)))
    }

    #[inline]
    fn mark(marks: &Marks, k: VoxelKey, kind: u64) {
        marks.mark(k, kind)
    }

    #[inline]
    fn get(&self, marks: &Marks, _: usize, k: &[i32; 3]) -> u64 {
        marks.get(k)
    }

    fn hit_near(&self, marks: &Marks, k: &[i32; 3], r: i32, _: &Box3, ground: Option<&GroundLevel>) -> bool {
        marks.hit_near(k, r, ground)
    }
}

/// One keyframe's rays: where the sensor is, and what a ray frees (the
/// clearance above a ground end, the surface shapes).
struct KeyframeRays<'a> {
    origin_m: &'a [f64; 3],
    keyframe: u32,
    voxel_m: f64,
    cfg: &'a EvidenceConfig,
    shapes: Option<&'a SurfaceShapes>,
    /// The session's ground level, where the clearance applies near the
    /// ground only (`EvidenceConfig::clearance_near_ground_only`).
    clearance_ground: Option<&'a GroundLevel>,
}

/// How far a ray's frees may reach towards its endpoint in z, as voxel
/// keys: see [`KeyframeRays::clearances`].
#[derive(Debug, Clone, Copy)]
struct Clearances {
    /// Lowest key z freed above a ground end, under `free_clearance_m`.
    kz_min: i32,
    /// ... under `vacated_clearance_m` (the band of vacated map voxels).
    kz_band: i32,
    /// Highest key z freed below a ceiling end, under `free_clearance_m`
    /// (`EvidenceConfig::ceiling_clearance`).
    kz_max: i32,
}

impl KeyframeRays<'_> {
    /// How close to its endpoint in z the frees of a ray to `p` may come.
    ///
    /// Free voxels of a downward ray that ends at the ground stop
    /// `free_clearance_m` above its endpoint (centre z ≥ z_min ⇔ key z ≥
    /// kz_min). The ground level is looked up only for rays that drop
    /// enough to need it. With `ceiling_clearance`, the frees of an upward
    /// ray that ends on a level surface (the underside of a slab) stop as
    /// far below it (centre z ≤ z_max ⇔ key z ≤ kz_max).
    fn clearances(&self, p: &[f64; 3]) -> Clearances {
        let (v, cfg) = (self.voxel_m, self.cfg);
        let key = || voxel_key(p, v);
        let ground_ray = p[2] < self.origin_m[2] - CLEARANCE_MIN_DROP_M
            && self.clearance_ground.is_none_or(|g| key().is_none_or(|k| g.at_ground(&k.0).unwrap_or(true)));
        let to_key = |z_m: f64| z_m.clamp(i32::MIN as f64, i32::MAX as f64) as i32;
        let kz_above = |clearance_m: f64| {
            if ground_ray && clearance_m > 0.0 { to_key(((p[2] + clearance_m) / v - 0.5).ceil()) } else { i32::MIN }
        };
        let ceiling_ray = cfg.ceiling_clearance
            && cfg.free_clearance_m > 0.0
            && p[2] > self.origin_m[2] + CLEARANCE_MIN_DROP_M
            && self.shapes.zip(key()).is_some_and(|(shapes, k)| shapes.level_at(&k.0));
        let kz_max = if ceiling_ray { to_key(((p[2] - cfg.free_clearance_m) / v - 0.5).floor()) } else { i32::MAX };
        Clearances { kz_min: kz_above(cfg.free_clearance_m), kz_band: kz_above(cfg.vacated_clearance_m), kz_max }
    }

    /// Whether the ray to `p` frees voxel `k` (`Some(true)`), frees it only
    /// under the lower clearance (`Some(false)`), or not at all; `c` from
    /// [`Self::clearances`]. A voxel with a shape frees only where the ray
    /// crosses it (evidence::surface).
    #[inline]
    fn frees(&self, k: &VoxelKey, p: &[f64; 3], c: Clearances) -> Option<bool> {
        let z = k.0[2];
        match self.shapes.and_then(|shapes| shapes.at(&k.0)) {
            Some(s) => ((s.clearance_exempt || (c.kz_min..=c.kz_max).contains(&z))
                && s.passes(k.0, self.voxel_m, self.origin_m, p))
            .then_some(true),
            None if z > c.kz_max => None,
            None if z >= c.kz_min => Some(true),
            None => (z >= c.kz_band).then_some(false),
        }
    }
}

/// The points a keyframe casts rays to with
/// [`EvidenceConfig::one_ray_per_voxel`], in scan order: of each voxel of
/// interest (a row of `index` over `keys`) its points fall in, the first;
/// every point in no such voxel (the interest set is every voxel the
/// session's points occupy, so there are none in a session's own rays);
/// none without a voxel key. A bit per row instead of sorting the points by
/// voxel: sorting was a tenth of a simulated HDL-64E session's evidence step.
fn first_point_per_voxel(points_m: &[[f64; 3]], voxel_m: f64, keys: &[u64], index: &KeyIndex) -> Vec<[f64; 3]> {
    // A point's row, or one of these two.
    const NOT_OF_INTEREST: u32 = u32::MAX;
    const NO_KEY: u32 = u32::MAX - 1;
    let rows: Vec<u32> = points_m
        .par_iter()
        .with_min_len(4096)
        .map(|p| match voxel_key(p, voxel_m) {
            None => NO_KEY,
            Some(k) => index.find_voxel(keys, &k.0).map_or(NOT_OF_INTEREST, |i| i as u32),
        })
        .collect();
    let mut seen = vec![0u64; keys.len().div_ceil(64)];
    points_m
        .iter()
        .zip(rows)
        .filter(|&(_, i)| match i {
            NOT_OF_INTEREST => true,
            NO_KEY => false,
            i => {
                let (w, bit) = (i as usize / 64, 1u64 << (i % 64));
                let first = seen[w] & bit == 0;
                seen[w] |= bit;
                first
            }
        })
        .map(|(p, _)| *p)
        .collect()
}

/// Pass 1: casts every ray of a keyframe, in parallel, and marks its hit
/// and free voxels of interest inside the ray box `b` (with `banded`, the
/// frees only the lower clearance allows apart).
fn mark_rays<L: MarkLayout>(
    layout: &L,
    rays: &KeyframeRays<'_>,
    b: Box3,
    banded: bool,
    points_m: &[[f64; 3]],
) -> KeyframeMarks<L::Marks> {
    let marks = KeyframeMarks { b, all: layout.marks(&b), band: banded.then(|| layout.marks(&b)) };
    points_m.par_iter().with_min_len(2048).for_each(|p| {
        let kz = rays.clearances(p);
        let on_free = |k: VoxelKey, slot: L::Slot| {
            if !b.contains(&k.0) {
                return;
            }
            match (rays.frees(&k, p, kz), &marks.band) {
                (Some(true), _) => L::mark(&marks.all, slot, FREE),
                (Some(false), Some(band)) => L::mark(band, slot, FREE),
                _ => {}
            }
        };
        let hit = layout.cast(rays.origin_m, p, rays.voxel_m, on_free);
        if let Some((k, Some(slot))) = hit
            && b.contains(&k.0)
        {
            L::mark(&marks.all, slot, HIT);
        }
    });
    marks
}

/// The rows of an [`InterestEvidence`] pass 2 writes, borrowed apart from
/// its index (which the mark layout borrows).
struct RowsMut<'a> {
    keys: &'a [u64],
    rows: &'a mut [Row],
    log_odds: &'a mut [f32],
    when: &'a mut [Span],
    unguarded: &'a [u64],
    ground: Option<&'a GroundLevel>,
}

impl RowsMut<'_> {
    /// Pass 2: eq. 4 once per marked interest voxel and kind, on the rows
    /// inside the ray box but those in `skip` (the no-return beams' rows,
    /// which [`InterestEvidence::add_free_rows`] frees). Frees next to the
    /// keyframe's own hits are dropped (the guard), except at unguarded rows
    /// and at an earlier session's patch
    /// ([`super::surface::VoxelShape::from_map`]). Returns the hit and free
    /// voxels added.
    fn apply<L: MarkLayout>(
        &mut self,
        layout: &L,
        marks: &KeyframeMarks<L::Marks>,
        rays: &KeyframeRays<'_>,
        skip: &[u64],
    ) -> (usize, usize) {
        let KeyframeRays { origin_m, keyframe, voxel_m: v, cfg, shapes, .. } = *rays;
        let b = marks.b;
        let (lo, hi) = b.packed_x_range(self.keys);
        let (l_hit, l_miss, l_min, l_max) = cfg.log_odds.log_odds();
        // The guard's radius: `free_guard_voxels`, widened with range to the
        // lateral spread `free_guard_deg` makes there.
        let guard_rad = cfg.free_guard_deg.to_radians();
        let guard_voxels = |r_m: f64| (cfg.free_guard_voxels as i32).max((r_m * guard_rad / v).ceil() as i32);
        let ground = self.ground.filter(|_| !cfg.ground_hits_guard);
        let unguarded = self.unguarded;
        let self_unguarded = |i: usize| bit_set(unguarded, i);
        let hit_free = AtomicU64::new(0);
        self.rows[lo..hi]
            .par_iter_mut()
            .zip(self.log_odds[lo..hi].par_iter_mut())
            .zip(self.when[lo..hi].par_iter_mut())
            .zip(self.keys[lo..hi].par_iter())
            .enumerate()
            .with_min_len(4096)
            .for_each(|(j, (((row, lo_odds), when), &pk))| {
                let i = lo + j;
                if bit_set(skip, i) {
                    return;
                }
                let k = unpack(pk).0;
                if !b.contains(&k) {
                    return;
                }
                let mut kinds = layout.get(&marks.all, i, &k);
                if self_unguarded(i) {
                    kinds |= marks.band.as_ref().map_or(0, |band| layout.get(band, i, &k)) & FREE;
                }
                if kinds == 0 {
                    return;
                }
                let guarded = || {
                    layout.hit_near(&marks.all, &k, guard_voxels(ray_to_centre(VoxelKey(k), origin_m, v).1), &b, ground)
                        && !self_unguarded(i)
                        && !shapes.and_then(|s| s.at(&k)).is_some_and(|s| s.from_map)
                };
                if kinds & HIT != 0 {
                    when.hits.add(keyframe);
                } else if kinds & FREE != 0 {
                    when.frees.add(keyframe);
                }
                if kinds & FREE != 0 && (kinds & HIT != 0 || guarded()) {
                    kinds &= !FREE;
                    if kinds == 0 {
                        return;
                    }
                }
                let (u, q) = direction_and_weight(ray_to_centre(VoxelKey(k), origin_m, v), cfg);
                if kinds & HIT != 0 {
                    Row::add(&mut row.hit_n, &mut row.hit_q, &mut row.hit_m, q, u);
                    *lo_odds = (*lo_odds + l_hit).clamp(l_min, l_max);
                } else {
                    *lo_odds = (*lo_odds + l_miss).clamp(l_min, l_max);
                }
                if kinds & FREE != 0 {
                    Row::add(&mut row.free_n, &mut row.free_q, &mut row.free_m, q, u);
                }
                row.offer_owner(keyframe, q * kinds.count_ones() as f32);
                hit_free.fetch_add(((kinds & HIT) << 32) | ((kinds & FREE) >> 1), Ordering::Relaxed);
            });
        let hf = hit_free.into_inner();
        ((hf >> 32) as usize, (hf & 0xffff_ffff) as usize)
    }
}

/// From the sensor at `origin_m` to the centre of voxel `k`: the vector and
/// its length, m.
fn ray_to_centre(k: VoxelKey, origin_m: &[f64; 3], voxel_m: f64) -> (nalgebra::Vector3<f64>, f64) {
    let c = k.center_m(voxel_m) - nalgebra::Vector3::from(*origin_m);
    let r = c.norm();
    (c, r)
}

/// Eq. 4's unit direction `u` (zero at the sensor's own voxel centre) and
/// range weight `q` of a ray to a voxel centre.
fn direction_and_weight((c, r): (nalgebra::Vector3<f64>, f64), cfg: &EvidenceConfig) -> ([f32; 3], f32) {
    let u = if r > 0.0 { [0, 1, 2].map(|a| (c[a] / r) as f32) } else { [0.0; 3] };
    (u, cfg.range_weight(r) as f32)
}

/// When a voxel was hit and crossed within one session, for the
/// single-change test (`EvidenceConfig::change_once_min_frees`): a [`Run`]
/// of each. Crossings count whatever the own-hit guard drops (a keyframe
/// that also hit the voxel counts as a hit only). 12 bytes.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Span {
    pub hits: Run,
    pub frees: Run,
}

/// The keyframes that did one thing to a voxel: the first and last index
/// (`u16::MAX` / 0 when none) and how many. Indices saturate at `u16::MAX`
/// (sessions of more keyframes do not use the test).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Run {
    pub first: u16,
    pub last: u16,
    pub n: u16,
}

impl Default for Run {
    fn default() -> Self {
        Run { first: u16::MAX, last: 0, n: 0 }
    }
}

impl Run {
    fn add(&mut self, keyframe: u32) {
        let k = u16::try_from(keyframe).unwrap_or(u16::MAX);
        self.first = self.first.min(k);
        self.last = self.last.max(k);
        self.n = self.n.saturating_add(1);
    }

    fn merge(&mut self, o: &Run) {
        self.first = self.first.min(o.first);
        self.last = self.last.max(o.last);
        self.n = self.n.saturating_add(o.n);
    }

    /// At least `min` (and at least one) keyframes, consecutive, none
    /// saturated.
    fn consecutive(&self, min: u16) -> bool {
        self.n >= min.max(1) && self.last < u16::MAX && self.last - self.first + 1 == self.n
    }

    fn middle(&self) -> u16 {
        self.first + (self.last - self.first) / 2
    }
}

impl Span {
    fn merge(&mut self, o: &Span) {
        self.hits.merge(&o.hits);
        self.frees.merge(&o.frees);
    }

    /// The keyframes in the middle of its run of crossings and of its run of
    /// hits, when it changed once: at least `min_frees` consecutive keyframes
    /// crossed it and at least `min_hits` consecutive keyframes hit it, and
    /// one run ended before the other began (emerged: crossed, then hit;
    /// vacated: hit, then crossed). `None` otherwise.
    pub fn changed_once(&self, min_hits: u16, min_frees: u16) -> Option<(u16, u16)> {
        let (h, f) = (&self.hits, &self.frees);
        let once = h.consecutive(min_hits) && f.consecutive(min_frees) && (f.last < h.first || h.last < f.first);
        once.then(|| (f.middle(), h.middle()))
    }
}

/// One voxel's running evidence while keyframes are added (76 bytes).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Row {
    pub hit_n: u32,
    pub free_n: u32,
    pub hit_q: f32,
    pub free_q: f32,
    pub hit_m: [f32; 6],
    pub free_m: [f32; 6],
    pub owner_keyframe: u32,
    pub owner_q: f32,
    /// Keyframes whose beams that returned nothing freed it as a map voxel
    /// this session's points do not occupy (counted in `free_n` too;
    /// [`super::no_return`]); the session's own voxels freed that way are
    /// counted in `free_n` only.
    pub no_return_n: u32,
}

impl Row {
    #[inline]
    fn add(n: &mut u32, qs: &mut f32, m: &mut [f32; 6], q: f32, u: [f32; 3]) {
        *n += 1;
        *qs += q;
        let [x, y, z] = u;
        for (m, p) in m.iter_mut().zip([x * x, x * y, x * z, y * y, y * z, z * z]) {
            *m += q * p;
        }
    }

    /// Sums another row in (re-binning, merging submaps); keeps the owner
    /// with the larger contribution.
    pub fn merge(&mut self, o: &Row) {
        self.hit_n += o.hit_n;
        self.free_n += o.free_n;
        self.hit_q += o.hit_q;
        self.free_q += o.free_q;
        self.no_return_n += o.no_return_n;
        for a in 0..6 {
            self.hit_m[a] += o.hit_m[a];
            self.free_m[a] += o.free_m[a];
        }
        self.offer_owner(o.owner_keyframe, o.owner_q);
    }

    /// Keeps the keyframe with the larger contribution as the owner; ties go
    /// to the lower index, so the owner does not depend on merge order.
    #[inline]
    fn offer_owner(&mut self, keyframe: u32, q: f32) {
        if q > self.owner_q || (q == self.owner_q && keyframe < self.owner_keyframe) {
            self.owner_keyframe = keyframe;
            self.owner_q = q;
        }
    }

    pub fn is_observed(&self) -> bool {
        self.hit_n + self.free_n > 0
    }

    /// The row as [`VoxelEvidence`] (f64), for eqs. 5-8.
    pub fn evidence(&self) -> VoxelEvidence {
        let stats = |n: u32, q: f32, m: &[f32; 6]| DirectionalStats { n, q_sum: q as f64, m: m.map(|v| v as f64) };
        VoxelEvidence {
            hit: stats(self.hit_n, self.hit_q, &self.hit_m),
            free: stats(self.free_n, self.free_q, &self.free_m),
            owner_keyframe: self.owner_keyframe,
            owner_q: self.owner_q as f64,
        }
    }
}

/// Evidence on a sorted set of voxels of interest (packed keys).
#[derive(Debug, Clone, Default)]
pub struct InterestEvidence {
    pub voxel_m: f64,
    keys: Vec<u64>,
    rows: Vec<Row>,
    /// Scalar log-odds per voxel, updated keyframe by keyframe with OctoMap's
    /// clamping (the baseline; kept whatever the model, it costs 4 bytes).
    log_odds: Vec<f32>,
    /// When (keyframe indices) each row was hit and crossed ([`Span`]).
    when: Vec<Span>,
    bounds: Box3,
    /// Rows freed without the own-hit guard and with the lower clearance
    /// (bit per row; empty: none; [`Self::set_unguarded`]).
    unguarded: Vec<u64>,
    /// The ground level of the session's columns ([`Self::set_ground`]).
    ground: Option<Arc<GroundLevel>>,
    /// The keys as blocks, for the rays and for [`Self::find`]; built on
    /// first use.
    index: std::sync::OnceLock<KeyIndex>,
}

/// A point for [`add_points_by_row`]: its row and its value.
pub(super) type RowValue = (u32, [f64; 3]);

/// Adds the points of `keyframes` to per-row accumulators `acc`, keyframe
/// after keyframe and, within one, in point order, on every thread.
/// `entries(keyframe)` gives a keyframe's points as `(row, value)` (rows
/// below `acc.len()`), and `add(acc, k, value)` adds one of the `k`-th
/// keyframe.
///
/// Rows are split in ranges of 4,096, each added by one thread: a few
/// keyframes at a time (taken from `keyframes` only then, so a session's
/// points are never all held), each keyframe's points are bucketed by range
/// (a counting sort, so they keep their order), then each range takes its
/// buckets in keyframe order. So every row sees its points in the order a
/// single thread would, and the sums do not depend on threads; and a
/// range's accumulators stay in cache, where adding points to a session's
/// rows in point order missed it on nearly every point.
pub(super) fn add_points_by_row<T: Send, K: Send>(
    acc: &mut [T],
    mut keyframes: impl Iterator<Item = K>,
    entries: impl Fn(K) -> Vec<RowValue> + Sync,
    add: impl Fn(&mut T, usize, [f64; 3]) + Sync,
) {
    const RANGE_SHIFT: u32 = 12;
    // Keyframes whose points are held at once (32 bytes a point).
    let batch = rayon::current_num_threads().max(1) * 4;
    let ranges = acc.len().div_ceil(1 << RANGE_SHIFT);
    let mut first = 0;
    loop {
        let chunk: Vec<K> = keyframes.by_ref().take(batch).collect();
        if chunk.is_empty() {
            return;
        }
        // Per keyframe: its points by range, and where each range starts.
        let parts: Vec<(Vec<RowValue>, Vec<u32>)> = chunk
            .into_par_iter()
            .map(|k| {
                let e = entries(k);
                let mut starts = vec![0u32; ranges + 1];
                for (r, _) in &e {
                    starts[(*r >> RANGE_SHIFT) as usize + 1] += 1;
                }
                for i in 0..ranges {
                    starts[i + 1] += starts[i];
                }
                let mut next = starts.clone();
                let mut bucketed = vec![(0u32, [0.0; 3]); e.len()];
                for x in e {
                    let b = (x.0 >> RANGE_SHIFT) as usize;
                    bucketed[next[b] as usize] = x;
                    next[b] += 1;
                }
                (bucketed, starts)
            })
            .collect();
        acc.par_chunks_mut(1 << RANGE_SHIFT).enumerate().for_each(|(b, range)| {
            let lo = (b << RANGE_SHIFT) as u32;
            for (j, (bucketed, starts)) in parts.iter().enumerate() {
                for (r, x) in &bucketed[starts[b] as usize..starts[b + 1] as usize] {
                    add(&mut range[(r - lo) as usize], first + j, *x);
                }
            }
        });
        first += parts.len();
    }
}

/// Sorted, unique packed keys → their index. Where the keys' bounds fit a
/// [`BlockMask`] (up to 2^28 blocks: a 32 MiB bitmap, 13 km × 13 km ×
/// 200 m at 0.2 m) a key's index is read through the mask's
/// [`BlockMask::rank_of`] (a few words of a compact bitmap and one entry
/// of a table); elsewhere by binary search.
///
/// Why: every point of a session is looked up several times (its voxel's
/// box, label and cleaned map; the surface shapes), and change detection
/// looks up every voxel's neighbours. A binary search over a quarter of a
/// million keys takes 18 probes, the last of them cache misses; on a
/// simulated HDL-64E session the lookups were a third of the evidence
/// step.
#[derive(Debug, Clone, Default)]
pub struct KeyIndex {
    mask: Option<BlockMask>,
    /// The index of each key, in the mask's rank order.
    index_of_rank: Vec<u32>,
    /// The rank of each key, in key order (the inverse of `index_of_rank`),
    /// built on first use: only the rays' marks read it.
    ranks: std::sync::OnceLock<Vec<u32>>,
}

impl KeyIndex {
    /// The index of `keys` (sorted and unique) within their bounds `bounds`.
    pub fn new(keys: &[u64], bounds: &Box3) -> KeyIndex {
        let mask = if bounds.is_empty() {
            None
        } else {
            BlockMask::new(bounds.lo, bounds.hi, keys.iter().map(|&k| unpack(k).0), 1 << 28)
        };
        let index_of_rank = match &mask {
            Some(mask) => {
                let mut out = vec![u32::MAX; keys.len()];
                for (i, &k) in keys.iter().enumerate() {
                    if let Some(r) = mask.rank_of(&unpack(k).0) {
                        out[r] = i as u32;
                    }
                }
                out
            }
            None => Vec::new(),
        };
        KeyIndex { mask, index_of_rank, ranks: Default::default() }
    }

    /// The [`BlockMask::rank_of`] of each key, in key order (empty without
    /// a mask).
    fn ranks(&self) -> &[u32] {
        self.ranks.get_or_init(|| {
            let mut ranks = vec![u32::MAX; self.index_of_rank.len()];
            for (r, &i) in self.index_of_rank.iter().enumerate() {
                if let Some(slot) = ranks.get_mut(i as usize) {
                    *slot = r as u32;
                }
            }
            ranks
        })
    }

    /// The keys as a mask, `None` where their bounds are too large for one.
    pub fn mask(&self) -> Option<&BlockMask> {
        self.mask.as_ref()
    }

    /// The index of packed key `key` in `keys` (the keys this index was
    /// built on).
    #[inline]
    pub fn find(&self, keys: &[u64], key: u64) -> Option<usize> {
        match &self.mask {
            Some(mask) => mask.rank_of(&unpack(key).0).map(|r| self.index_of_rank[r] as usize),
            None => keys.binary_search(&key).ok(),
        }
    }

    /// [`Self::find`] by voxel key (no packing on the mask's path).
    #[inline]
    pub fn find_voxel(&self, keys: &[u64], k: &[i32; 3]) -> Option<usize> {
        match &self.mask {
            Some(mask) => mask.rank_of(k).map(|r| self.index_of_rank[r] as usize),
            None => pack(VoxelKey(*k)).and_then(|key| keys.binary_search(&key).ok()),
        }
    }
}

/// What one keyframe added.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RayStats {
    pub rays: usize,
    /// Rays skipped: a non-finite coordinate or a key out of range.
    pub skipped_rays: usize,
    pub hit_voxels: usize,
    pub free_voxels: usize,
    /// Map voxels freed by beams that returned nothing ([`super::no_return`]).
    pub no_return_voxels: usize,
    /// The session's own voxels freed that way (the tests with clear cells).
    pub own_no_return_voxels: usize,
}

impl std::ops::AddAssign for RayStats {
    fn add_assign(&mut self, o: RayStats) {
        self.rays += o.rays;
        self.skipped_rays += o.skipped_rays;
        self.hit_voxels += o.hit_voxels;
        self.free_voxels += o.free_voxels;
        self.no_return_voxels += o.no_return_voxels;
        self.own_no_return_voxels += o.own_no_return_voxels;
    }
}

/// The sorted union of sorted, deduplicated runs (two-way merges, halves in
/// parallel).
fn merge_sorted_runs(runs: &[&[u64]]) -> Vec<u64> {
    match runs {
        [] => Vec::new(),
        [one] => one.to_vec(),
        _ => {
            let (a, b) = runs.split_at(runs.len() / 2);
            let (a, b) = rayon::join(|| merge_sorted_runs(a), || merge_sorted_runs(b));
            let mut out = Vec::with_capacity(a.len() + b.len());
            let (mut i, mut j) = (0, 0);
            while i < a.len() && j < b.len() {
                let (x, y) = (a[i], b[j]);
                out.push(x.min(y));
                i += usize::from(x <= y);
                j += usize::from(y <= x);
            }
            out.extend_from_slice(&a[i..]);
            out.extend_from_slice(&b[j..]);
            out
        }
    }
}

impl InterestEvidence {
    /// Empty evidence on `keys` (packed; sorted and deduplicated here).
    pub fn new(mut keys: Vec<u64>, voxel_m: f64) -> InterestEvidence {
        keys.par_sort_unstable();
        keys.dedup();
        Self::on_sorted(keys, voxel_m)
    }

    /// Empty evidence on the union of `runs`, each sorted and deduplicated
    /// (a keyframe's keys): merged pairwise in parallel, in about a tenth of
    /// what sorting their concatenation costs.
    pub fn from_sorted_runs(runs: &[&[u64]], voxel_m: f64) -> InterestEvidence {
        debug_assert!(runs.iter().all(|r| r.windows(2).all(|w| w[0] < w[1])), "runs sorted and deduplicated");
        Self::on_sorted(merge_sorted_runs(runs), voxel_m)
    }

    /// Evidence summed from parts of `(key, row)` pairs in any key order.
    /// Equal keys merge in the order of the parts and then of the pairs, so
    /// the sums do not depend on threads. The scalar log-odds are not
    /// carried: only the directional statistics can be moved (see
    /// [`super::session::reproject`]).
    pub fn from_parts(parts: &[Vec<(u64, Row)>], voxel_m: f64) -> InterestEvidence {
        // Sort 16-byte (key, where) pairs rather than the 80-byte rows.
        let mut order: Vec<(u64, u32, u32)> = parts
            .iter()
            .enumerate()
            .flat_map(|(p, part)| part.iter().enumerate().map(move |(i, (k, _))| (*k, p as u32, i as u32)))
            .collect();
        order.par_sort_unstable();
        let mut keys: Vec<u64> = Vec::with_capacity(order.len());
        let mut rows: Vec<Row> = Vec::with_capacity(order.len());
        for (k, p, i) in order {
            let r = &parts[p as usize][i as usize].1;
            match (keys.last(), rows.last_mut()) {
                (Some(&last), Some(w)) if last == k => w.merge(r),
                _ => {
                    keys.push(k);
                    rows.push(*r);
                }
            }
        }
        let mut out = Self::on_sorted(keys, voxel_m);
        out.rows = rows;
        out
    }

    /// Empty evidence on keys already sorted and unique.
    fn on_sorted(keys: Vec<u64>, voxel_m: f64) -> InterestEvidence {
        let bounds = Box3::of_packed(&keys);
        let n = keys.len();
        InterestEvidence {
            voxel_m,
            keys,
            rows: vec![Row::default(); n],
            log_odds: vec![0.0; n],
            when: vec![Span::default(); n],
            bounds,
            unguarded: Vec::new(),
            ground: None,
            index: std::sync::OnceLock::new(),
        }
    }

    pub fn len(&self) -> usize {
        self.keys.len()
    }

    pub fn is_empty(&self) -> bool {
        self.keys.is_empty()
    }

    pub fn keys(&self) -> &[u64] {
        &self.keys
    }

    pub fn rows(&self) -> &[Row] {
        &self.rows
    }

    pub fn bounds(&self) -> Box3 {
        self.bounds
    }

    /// The row index of a packed key.
    #[inline]
    pub fn find(&self, key: u64) -> Option<usize> {
        self.index().find(&self.keys, key)
    }

    /// The keys' [`KeyIndex`], built once.
    fn index(&self) -> &KeyIndex {
        self.index.get_or_init(|| KeyIndex::new(&self.keys, &self.bounds))
    }

    /// The row of a packed key.
    pub fn get(&self, key: u64) -> Option<&Row> {
        self.find(key).map(|i| &self.rows[i])
    }

    /// The sub-set of these keys inside `b`, as a new empty evidence, with
    /// each key's index here.
    pub fn subset(&self, b: &Box3) -> (InterestEvidence, Vec<u32>) {
        let (lo, hi) = self.x_range(b);
        let (keys, idx): (Vec<u64>, Vec<u32>) =
            (lo..hi).filter(|&i| b.contains(&unpack(self.keys[i]).0)).map(|i| (self.keys[i], i as u32)).unzip();
        let mut sub = Self::on_sorted(keys, self.voxel_m);
        sub.ground = self.ground.clone();
        if !self.unguarded.is_empty() {
            sub.set_unguarded(
                idx.iter().enumerate().filter(|(_, i)| bit_set(&self.unguarded, **i as usize)).map(|(j, _)| j),
            );
        }
        (sub, idx)
    }

    /// The rows (indices; those past the end are ignored) a keyframe frees
    /// next to its own hits and down to
    /// `EvidenceConfig::vacated_clearance_m` (see
    /// `EvidenceConfig::free_vacated_low`).
    pub fn set_unguarded(&mut self, rows: impl IntoIterator<Item = usize>) {
        let mut bits = vec![0u64; self.len().div_ceil(64)];
        for i in rows.into_iter().filter(|&i| i < self.len()) {
            bits[i / 64] |= 1 << (i % 64);
        }
        self.unguarded = bits;
    }

    /// The ground level of the columns the session's points occupy: rays
    /// get the free clearance only where they end at it
    /// (`EvidenceConfig::clearance_near_ground_only`), and hits at it below a
    /// voxel do not guard that voxel (`EvidenceConfig::ground_hits_guard`).
    /// Without it (or with both rules off) every downward ray gets the
    /// clearance and every hit guards.
    pub fn set_ground(&mut self, ground: GroundLevel) {
        self.ground = Some(Arc::new(ground));
    }

    /// The ground level given by [`Self::set_ground`], if any.
    pub fn ground(&self) -> Option<&GroundLevel> {
        self.ground.as_deref()
    }

    /// Indices of the keys whose x lies in the box's x range.
    pub(super) fn x_range(&self, b: &Box3) -> (usize, usize) {
        b.packed_x_range(&self.keys)
    }

    /// Adds one keyframe's rays (sensor at `origin_m`, points `points_m`, both
    /// in this evidence's frame). Each voxel counts at most once per kind.
    ///
    /// With `shapes`, a ray frees a voxel that has a shape only if it passes
    /// through that shape ([`super::surface::VoxelShape::passes`]); voxels
    /// without one follow the voxel rule.
    pub fn add_keyframe(
        &mut self,
        origin_m: &[f64; 3],
        points_m: &[[f64; 3]],
        keyframe: u32,
        cfg: &EvidenceConfig,
        shapes: Option<&SurfaceShapes>,
    ) -> RayStats {
        self.add_keyframe_seeing(origin_m, points_m, keyframe, cfg, shapes, &[])
    }

    /// [`Self::add_keyframe`], and with `no_return` the candidate voxels the
    /// keyframe's beams that returned nothing pass through are freed too
    /// (once per keyframe, whatever else freed them). The tests' candidate
    /// sets must be disjoint.
    pub fn add_keyframe_seeing(
        &mut self,
        origin_m: &[f64; 3],
        points_m: &[[f64; 3]],
        keyframe: u32,
        cfg: &EvidenceConfig,
        shapes: Option<&SurfaceShapes>,
        no_return: &[NoReturn<'_>],
    ) -> RayStats {
        let v = self.voxel_m;
        let mut out = RayStats { rays: points_m.len(), ..Default::default() };
        let Some(o_key) = voxel_key(origin_m, v) else {
            out.skipped_rays = points_m.len();
            return out;
        };
        // Map voxels freed this way count in `no_return_n` (change
        // detection's full-weight support); the session's own do not.
        let (mut sky, mut own_sky) = (Vec::new(), Vec::new());
        for nr in no_return {
            let rows = self.no_return_rows(origin_m, nr);
            if nr.clear_cells.is_some() {
                own_sky.extend(rows);
            } else {
                sky.extend(rows);
            }
        }
        out.own_no_return_voxels = own_sky.len();
        sky.sort_unstable();
        own_sky.sort_unstable();
        let none = sky.is_empty() && own_sky.is_empty();
        let mut sky_bits = vec![0u64; if none { 0 } else { self.rows.len().div_ceil(64) }];
        for &i in sky.iter().chain(&own_sky) {
            sky_bits[i as usize / 64] |= 1 << (i % 64);
        }
        let b = Box3::of_rays(origin_m, points_m, v).intersect(&self.bounds).limit(o_key.0, DENSE_MAX_VOXELS);
        let cast = points_m.iter().filter(|p| voxel_key(p, v).is_some()).count();
        if !b.is_empty() {
            let InterestEvidence { keys, rows, log_odds, when, bounds, unguarded, ground, index, .. } = self;
            let ground = ground.as_deref();
            let rays = KeyframeRays {
                origin_m,
                keyframe,
                voxel_m: v,
                cfg,
                shapes,
                clearance_ground: ground.filter(|_| cfg.clearance_near_ground_only),
            };
            // Voxels freed only under the lower clearance of the unguarded
            // (vacated map) voxels.
            let banded = !unguarded.is_empty() && cfg.vacated_clearance_m < cfg.free_clearance_m;
            let mut rows = RowsMut { keys, rows, log_odds, when, unguarded, ground };
            // Only interest voxels get evidence: with a mask, rays report
            // only those and jump over the blocks that hold none.
            let index = index.get_or_init(|| KeyIndex::new(keys, bounds));
            let firsts;
            let rays_m = if cfg.one_ray_per_voxel {
                firsts = first_point_per_voxel(points_m, v, keys, index);
                &firsts[..]
            } else {
                points_m
            };
            let (h, f) = match index.mask() {
                Some(mask) => {
                    let layout = ByRank { mask, ranks: index.ranks() };
                    let marks = mark_rays(&layout, &rays, b, banded, rays_m);
                    rows.apply(&layout, &marks, &rays, &sky_bits)
                }
                None => {
                    let marks = mark_rays(&ByBox, &rays, b, banded, rays_m);
                    rows.apply(&ByBox, &marks, &rays, &sky_bits)
                }
            };
            out.hit_voxels = h;
            out.free_voxels = f;
        }
        out.skipped_rays = points_m.len() - cast;
        self.add_free_rows(&sky, origin_m, keyframe, cfg, true);
        self.add_free_rows(&own_sky, origin_m, keyframe, cfg, false);
        out.no_return_voxels = sky.len();
        out
    }

    /// Rows of `nr.candidates` within reach whose direction from the sensor
    /// returned nothing, ascending, without those near the keyframe's points
    /// when `nr.clear_cells` asks for it.
    fn no_return_rows(&self, origin_m: &[f64; 3], nr: &NoReturn<'_>) -> Vec<u32> {
        let v = self.voxel_m;
        let b = Box3::within_range(origin_m, nr.range_m, v);
        if b.is_empty() {
            return Vec::new();
        }
        let (lo, hi) = self.x_range(&b);
        let from = nr.candidates.partition_point(|&i| (i as usize) < lo);
        let to = nr.candidates.partition_point(|&i| (i as usize) < hi);
        let r_sensor_world = nr.r_world_sensor.inverse();
        let min_sin = nr.min_elevation_deg.to_radians().sin();
        let mut sky: Vec<u32> = (from..to)
            .into_par_iter()
            .with_min_len(1024)
            .filter(|&j| {
                let (c, r) = ray_to_centre(unpack(self.keys[nr.candidates[j] as usize]), origin_m, v);
                let reach = nr.candidate_range_m.get(j).map_or(nr.range_m, |&m| nr.range_m.min(m as f64));
                if !(r > v && r <= reach) || c.z < min_sin * r {
                    return false;
                }
                nr.image.is_empty_around(&(r_sensor_world * c).into())
            })
            .map(|j| nr.candidates[j])
            .collect();
        if let Some((cells, cell)) = nr.clear_cells {
            sky.retain(|&i| {
                let c = unpack(self.keys[i as usize]).0.map(|c| c.div_euclid(cell));
                !(-1..=1)
                    .any(|dx| (-1..=1).any(|dy| (-1..=1).any(|dz| cells.contains(&[c[0] + dx, c[1] + dy, c[2] + dz]))))
            });
        }
        sky
    }

    /// Eq. 4's free evidence of one keyframe on the given rows.
    fn add_free_rows(&mut self, rows: &[u32], origin_m: &[f64; 3], keyframe: u32, cfg: &EvidenceConfig, map: bool) {
        let v = self.voxel_m;
        let (_, l_miss, l_min, l_max) = cfg.log_odds.log_odds();
        for &i in rows {
            let (u, q) = direction_and_weight(ray_to_centre(unpack(self.keys[i as usize]), origin_m, v), cfg);
            let row = &mut self.rows[i as usize];
            Row::add(&mut row.free_n, &mut row.free_q, &mut row.free_m, q, u);
            row.no_return_n += u32::from(map);
            row.offer_owner(keyframe, q);
            self.when[i as usize].frees.add(keyframe);
            let l = &mut self.log_odds[i as usize];
            *l = (*l + l_miss).clamp(l_min, l_max);
        }
    }

    /// Adds `other` (a [`subset`](Self::subset) of this set, `idx` from it)
    /// into these rows. The scalar log-odds are carried over, not summed: a
    /// session's submaps are added in keyframe order, so the subset's value
    /// continues where the session's left off (see [`Self::continue_log_odds`]).
    pub fn merge_subset(&mut self, other: &InterestEvidence, idx: &[u32]) {
        for (j, &i) in idx.iter().enumerate() {
            self.rows[i as usize].merge(&other.rows[j]);
            self.log_odds[i as usize] = other.log_odds[j];
            self.when[i as usize].merge(&other.when[j]);
        }
    }

    /// Starts a subset's scalar log-odds where the session's stand, so that
    /// OctoMap's clamped update runs in keyframe order across submaps.
    pub fn continue_log_odds(&self, sub: &mut InterestEvidence, idx: &[u32]) {
        for (j, &i) in idx.iter().enumerate() {
            sub.log_odds[j] = self.log_odds[i as usize];
        }
    }

    /// When each row was hit and crossed ([`Span`]).
    pub fn when(&self) -> &[Span] {
        &self.when
    }

    /// Clamped ε_l of every row under the configured model.
    pub fn eps_l(&self, cfg: &EvidenceConfig) -> Vec<f32> {
        self.rows.par_iter().zip(self.log_odds.par_iter()).map(|(r, &l)| eps_of(r, l, cfg) as f32).collect()
    }

    /// The observed rows as a stored table (keys unpacked, sorted), with the
    /// points' box per row (`hit_box_m[i]` for row `i`, see
    /// [`SubmapEvidence::hit_box_m`]).
    pub fn to_table(&self, hit_box_m: &[[f32; 6]]) -> SubmapEvidence {
        assert_eq!(hit_box_m.len(), self.len(), "one hit box per row");
        let mut t = SubmapEvidence::default();
        let mut hit = StatsColumns::default();
        let mut free = StatsColumns::default();
        for ((k, r), b) in self.keys.iter().zip(&self.rows).zip(hit_box_m).filter(|((_, r), _)| r.is_observed()) {
            t.hit_box_m.push(*b);
            t.keys.push(unpack(*k));
            hit.n.push(r.hit_n);
            hit.q.push(r.hit_q);
            hit.m.push(r.hit_m);
            free.n.push(r.free_n);
            free.q.push(r.free_q);
            free.m.push(r.free_m);
            t.owner_keyframe.push(r.owner_keyframe);
            t.owner_q.push(r.owner_q);
            t.no_return_n.push(r.no_return_n);
        }
        t.hit = hit;
        t.free = free;
        t
    }
}

/// One stored row back as a [`Row`].
pub fn row_of(t: &SubmapEvidence, i: usize) -> Row {
    Row {
        hit_n: t.hit.n[i],
        free_n: t.free.n[i],
        hit_q: t.hit.q[i],
        free_q: t.free.q[i],
        hit_m: t.hit.m[i],
        free_m: t.free.m[i],
        owner_keyframe: t.owner_keyframe[i],
        owner_q: t.owner_q[i],
        no_return_n: t.no_return_n.get(i).copied().unwrap_or(0),
    }
}

/// Clamped ε_l of one row: eqs. 5-8 for the directional model, `1 − P(occ)`
/// of the log-odds `l` for the scalar baseline.
pub fn eps_of(r: &Row, log_odds: f32, cfg: &EvidenceConfig) -> f64 {
    let raw = match cfg.model {
        EvidenceModel::Directional => r.evidence().epsilon_l_raw(cfg),
        // Never observed: no evidence either way, like ε_l's h + f = 0.
        EvidenceModel::LogOdds if !r.is_observed() => 0.0,
        EvidenceModel::LogOdds => 1.0 / (1.0 + (log_odds as f64).exp()),
    };
    raw.clamp(cfg.eps_min, cfg.eps_max)
}

#[cfg(test)]
mod tests {
    use super::super::{EvidenceMap, accumulate_keyframe};
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// The single-change test's record: one run of crossings wholly before
    /// or after one run of hits, each of consecutive keyframes and long
    /// enough; its middles; merging submaps' records.
    #[test]
    fn span_changes_once_only_in_consecutive_runs() {
        let span = |hits: &[u32], frees: &[u32]| {
            let mut s = Span::default();
            hits.iter().for_each(|&k| s.hits.add(k));
            frees.iter().for_each(|&k| s.frees.add(k));
            s
        };
        // Emerged: crossed by 0-3, hit by 4-6; vacated: hit by 2-3, crossed by 5-7.
        assert_eq!(span(&[4, 5, 6], &[0, 1, 2, 3]).changed_once(2, 3), Some((1, 5)));
        assert_eq!(span(&[2, 3], &[5, 6, 7]).changed_once(2, 3), Some((6, 2)));
        // Too few of either.
        assert_eq!(span(&[4], &[0, 1, 2, 3]).changed_once(2, 3), None);
        assert_eq!(span(&[4, 5], &[2, 3]).changed_once(2, 3), None);
        // Interleaved, or a run with a gap.
        assert_eq!(span(&[3, 5], &[0, 1, 2, 4]).changed_once(2, 3), None);
        assert_eq!(span(&[5, 6], &[0, 1, 3]).changed_once(2, 3), None);
        assert_eq!(span(&[5, 7], &[0, 1, 2]).changed_once(2, 3), None);
        // Never crossed or never hit.
        assert_eq!(span(&[0, 1, 2], &[]).changed_once(2, 3), None);
        assert_eq!(span(&[], &[0, 1, 2]).changed_once(2, 3), None);
        // Two submaps' records merge into the session's.
        let mut a = span(&[], &[0, 1]);
        a.merge(&span(&[4, 5], &[2, 3]));
        assert_eq!(a, span(&[4, 5], &[0, 1, 2, 3]));
        // Indices past u16 saturate, and such runs never count.
        assert_eq!(span(&[70_000, 70_001], &[0, 1, 2]).changed_once(2, 3), None);
    }

    #[test]
    fn merged_runs_are_the_sorted_union() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        for n_runs in [0usize, 1, 2, 3, 10] {
            let runs: Vec<Vec<u64>> = (0..n_runs)
                .map(|r| {
                    // Runs of different lengths, overlapping in part.
                    let mut k: Vec<u64> = (0..rng.random_range(0..2_000)).map(|_| rng.random_range(0..5_000)).collect();
                    k.push(r as u64 * 1_000);
                    k.sort_unstable();
                    k.dedup();
                    k
                })
                .collect();
            let refs: Vec<&[u64]> = runs.iter().map(|r| &r[..]).collect();
            let mut want: Vec<u64> = runs.concat();
            want.sort_unstable();
            want.dedup();
            assert_eq!(merge_sorted_runs(&refs), want, "{n_runs} runs");
            assert_eq!(InterestEvidence::from_sorted_runs(&refs, 0.2).keys(), &want[..]);
        }
    }

    /// Every row gets its points in keyframe order and, within a keyframe,
    /// in point order, with the keyframe's ordinal: what one thread adding
    /// them in turn would do, over several batches of keyframes and ranges.
    #[test]
    fn points_reach_their_rows_in_order() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let rows = 10_000usize;
        let keyframes: Vec<Vec<RowValue>> = (0..37)
            .map(|k| {
                (0..rng.random_range(0..3000))
                    .map(|i| (rng.random_range(0..rows as u32), [k as f64, i as f64, rng.random::<f64>()]))
                    .collect()
            })
            .collect();
        let mut want: Vec<Vec<(usize, [f64; 3])>> = vec![Vec::new(); rows];
        for (k, pts) in keyframes.iter().enumerate() {
            for &(r, x) in pts {
                want[r as usize].push((k, x));
            }
        }
        let mut got: Vec<Vec<(usize, [f64; 3])>> = vec![Vec::new(); rows];
        add_points_by_row(&mut got, keyframes.iter(), |pts| pts.clone(), |row, k, x| row.push((k, x)));
        assert_eq!(got, want);
    }

    /// The index finds every key at its place and nothing else, through
    /// the mask and through the binary search it falls back to; the mask's
    /// ranks number the keys 0..n once each.
    #[test]
    fn key_index_finds_what_binary_search_finds() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        // Clustered keys (several to a block) and a few far apart.
        let mut keys: Vec<u64> = (0..3000)
            .map(|i| {
                let spread = if i % 100 == 0 { 400 } else { 12 };
                VoxelKey(std::array::from_fn(|_| rng.random_range(-spread..spread)))
            })
            .filter_map(pack)
            .collect();
        keys.sort_unstable();
        keys.dedup();
        let bounds = Box3::of_packed(&keys);
        let index = KeyIndex::new(&keys, &bounds);
        let mask = index.mask().expect("small bounds fit a mask");
        assert_eq!(mask.count(), keys.len());
        let mut ranks: Vec<usize> = keys.iter().map(|&k| mask.rank_of(&unpack(k).0).unwrap()).collect();
        ranks.sort_unstable();
        assert_eq!(ranks, (0..keys.len()).collect::<Vec<_>>());
        // A bitmap of more than 2^28 blocks is not built: binary search.
        let far = [pack(VoxelKey([-(1 << 19), 0, 0])).unwrap(), pack(VoxelKey([1 << 19, 1 << 18, 500])).unwrap()];
        let mut wide = keys.clone();
        wide.extend(far);
        wide.sort_unstable();
        let wide_index = KeyIndex::new(&wide, &Box3::of_packed(&wide));
        assert!(wide_index.mask().is_none());
        for (set, index) in [(&keys, &index), (&wide, &wide_index)] {
            for (i, &k) in set.iter().enumerate() {
                assert_eq!(index.find(set, k), Some(i));
            }
            for _ in 0..3000 {
                let v = VoxelKey(std::array::from_fn(|_| rng.random_range(-20..20)));
                let k = pack(v).unwrap();
                assert_eq!(index.find(set, k), set.binary_search(&k).ok(), "{v:?}");
                assert_eq!(index.find_voxel(set, &v.0), index.find(set, k), "{v:?}");
            }
        }
        assert!(KeyIndex::new(&[], &Box3::EMPTY).find(&[], keys[0]).is_none());
    }

    #[test]
    fn pack_round_trips_and_sorts_like_keys() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let mut keys: Vec<VoxelKey> =
            (0..2000).map(|_| VoxelKey(std::array::from_fn(|_| rng.random_range(-(1 << 20)..(1 << 20))))).collect();
        keys.push(VoxelKey([-(1 << 20), (1 << 20) - 1, 0]));
        for k in &keys {
            assert_eq!(unpack(pack(*k).unwrap()), *k);
        }
        let mut by_key = keys.clone();
        by_key.sort();
        let mut by_packed = keys.clone();
        by_packed.sort_by_key(|k| pack(*k).unwrap());
        assert_eq!(by_key, by_packed);
        assert_eq!(pack(VoxelKey([1 << 20, 0, 0])), None);
        assert_eq!(pack(VoxelKey([0, 0, -(1 << 20) - 1])), None);
    }

    fn scan(rng: &mut ChaCha8Rng, origin: [f64; 3], n: usize) -> Vec<[f64; 3]> {
        (0..n)
            .map(|_| {
                let (a, b) = (rng.random::<f64>() * std::f64::consts::TAU, rng.random::<f64>() - 0.5);
                let r = 2.0 + rng.random::<f64>() * 35.0;
                [origin[0] + r * a.cos(), origin[1] + r * a.sin(), origin[2] + r * b * 0.3]
            })
            .collect()
    }

    /// On the interest voxels, the rows equal the full hash-map evidence of
    /// `accumulate_keyframe` (to f32 rounding), and ε_l agrees: for rays to
    /// every point, and with `one_ray_per_voxel` for the reference's rays
    /// to the first point of each voxel. (A small pseudo-count keeps eq. 8
    /// away from its 0/0 edge, where ω of nearly parallel rays sits at the α
    /// floor and f32 rounding decides.)
    #[test]
    fn interest_rows_equal_full_map_on_their_voxels() {
        for one_ray_per_voxel in [false, true] {
            rows_equal_full_map(one_ray_per_voxel);
        }
    }

    fn rows_equal_full_map(one_ray_per_voxel: bool) {
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let cfg = EvidenceConfig {
            pseudo_count: 0.05,
            free_guard_voxels: 0,
            free_guard_deg: 0.0,
            free_clearance_m: 0.0,
            one_ray_per_voxel,
            ..Default::default()
        };
        let v = cfg.voxel_size_m;
        // Each point with a second one 4 cm aside, often in its voxel.
        let frames: Vec<([f64; 3], Vec<[f64; 3]>)> = (0..5)
            .map(|i| {
                let o = [i as f64 * 2.5, 0.3 * i as f64, 1.5];
                (o, scan(&mut rng, o, 4000).into_iter().flat_map(|p| [p, [p[0] + 0.04, p[1], p[2]]]).collect())
            })
            .collect();
        let keys: Vec<u64> = frames.iter().flat_map(|(_, p)| p.iter().filter_map(|p| packed_key(p, v))).collect();
        let mut ev = InterestEvidence::new(keys, v);
        let mut full = EvidenceMap::default();
        for (i, (o, p)) in frames.iter().enumerate() {
            let a = ev.add_keyframe(o, p, i as u32, &cfg, None);
            let firsts = first_point_per_voxel(p, v, ev.keys(), ev.index());
            assert_eq!(firsts, first_point_per_voxel_by_sorting(p, v));
            assert!(firsts.len() < p.len() * 9 / 10, "{} of {}", firsts.len(), p.len());
            accumulate_keyframe(o, if one_ray_per_voxel { &firsts } else { p }, i as u32, &cfg, &mut full);
            assert_eq!(a.skipped_rays, 0);
            assert!(a.hit_voxels > 0 && a.free_voxels > 0);
        }
        let eps = ev.eps_l(&cfg);
        let mut dynamic = 0;
        for (j, (&k, r)) in ev.keys().iter().zip(ev.rows()).enumerate() {
            let want = full.get(&unpack(k)).copied().unwrap_or_default();
            let got = r.evidence();
            assert_eq!((got.hit.n, got.free.n), (want.hit.n, want.free.n), "{:?}", unpack(k));
            assert!((got.hit.q_sum - want.hit.q_sum).abs() < 1e-4 && (got.free.q_sum - want.free.q_sum).abs() < 1e-4);
            for a in 0..6 {
                assert!((got.free.m[a] - want.free.m[a]).abs() < 1e-4);
            }
            assert_eq!(got.owner_keyframe, want.owner_keyframe);
            assert!(
                (eps[j] as f64 - want.epsilon_l(&cfg)).abs() < 1e-3,
                "{:?} {} {} {:?} {:?} {} {}",
                unpack(k),
                eps[j],
                want.epsilon_l(&cfg),
                got.hit_free_scores(&cfg),
                want.hit_free_scores(&cfg),
                got.free.alpha(),
                want.free.alpha()
            );
            dynamic += (eps[j] as f64 > cfg.tau_dyn) as usize;
        }
        // Random points in free space: later keyframes' rays pass through
        // earlier endpoints, so some voxels must come out dynamic.
        assert!(dynamic > 0);
    }

    /// The reference for [`first_point_per_voxel`] where every point's voxel
    /// is of interest: the points sorted by voxel, each voxel's first kept.
    fn first_point_per_voxel_by_sorting(points_m: &[[f64; 3]], v: f64) -> Vec<[f64; 3]> {
        let mut by_voxel: Vec<([i32; 3], usize)> =
            points_m.iter().enumerate().filter_map(|(i, p)| Some((voxel_key(p, v)?.0, i))).collect();
        by_voxel.sort_unstable();
        let mut firsts: Vec<usize> = by_voxel.chunk_by(|a, b| a.0 == b.0).map(|run| run[0].1).collect();
        firsts.sort_unstable();
        firsts.into_iter().map(|i| points_m[i]).collect()
    }

    /// One point per voxel of interest, the first in scan order, kept in
    /// scan order; every point outside the voxels of interest kept, and
    /// points without a voxel key left out. With a mask and without.
    #[test]
    fn first_point_per_voxel_keeps_each_voxels_first_in_scan_order() {
        let pts = [
            [0.15, 0.05, 0.05],
            [0.05, 0.05, 0.05],
            [f64::NAN, 0.0, 0.0],
            [0.11, 0.01, 0.09],
            [0.01, 0.19, 0.02],
            [-0.01, 0.0, 0.0],
            [0.02, 0.03, 0.04],
        ];
        let v = 0.1;
        // Voxels of interest: those of points 0, 1 and 4 (not 5's), and, for
        // the index without a mask, one 30 km off.
        let keys = |far: bool| {
            let mut k: Vec<u64> = [0, 1, 4].iter().map(|&i| packed_key(&pts[i], v).unwrap()).collect();
            k.extend(far.then(|| pack(VoxelKey([150_000, 150_000, 0])).unwrap()));
            k.sort_unstable();
            k
        };
        for far in [false, true] {
            let keys = keys(far);
            let index = KeyIndex::new(&keys, &Box3::of_packed(&keys));
            assert_eq!(index.mask().is_none(), far);
            let got = first_point_per_voxel(&pts, v, &keys, &index);
            assert_eq!(got, vec![pts[0], pts[1], pts[4], pts[5]]);
        }
        assert_eq!(first_point_per_voxel_by_sorting(&pts, v), vec![pts[0], pts[1], pts[4], pts[5]]);
    }

    /// An interest set too wide for a mask is marked by place in the ray box
    /// (`ByBox`: rays visit every voxel); on the same voxels it gives the
    /// rows marking by rank gives (`ByRank`), with the own-hit guard, the
    /// ground level, the clearances and the unguarded rows' band all at work.
    #[test]
    fn box_marks_give_the_rows_rank_marks_give() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let cfg = EvidenceConfig::default();
        assert!(cfg.vacated_clearance_m < cfg.free_clearance_m, "the band must be in play");
        let frames: Vec<([f64; 3], Vec<[f64; 3]>)> = (0..4)
            .map(|i| {
                let o = [i as f64 * 3.0, -0.4 * i as f64, 1.8];
                let mut p = scan(&mut rng, o, 6000);
                p.extend((0..3000).map(|_| {
                    let (a, r) = (rng.random::<f64>() * std::f64::consts::TAU, 1.0 + rng.random::<f64>() * 25.0);
                    [o[0] + r * a.cos(), o[1] + r * a.sin(), 0.03 * rng.random::<f64>()]
                }));
                (o, p)
            })
            .collect();
        let v = cfg.voxel_size_m;
        let keys: Vec<u64> = frames.iter().flat_map(|(_, p)| p.iter().filter_map(|p| packed_key(p, v))).collect();
        // 30 km off in x and y: it sorts last, and its bounds need far more
        // blocks than a mask may have.
        let far = pack(VoxelKey([150_000, 150_000, 0])).unwrap();
        let run = |extra: Option<u64>| {
            let mut ev = InterestEvidence::new(keys.iter().copied().chain(extra).collect(), v);
            assert_eq!(ev.index().mask().is_some(), extra.is_none());
            ev.set_ground(GroundLevel::from_keys(keys.iter()));
            ev.set_unguarded((0..ev.len()).step_by(3));
            let stats: Vec<RayStats> =
                frames.iter().enumerate().map(|(i, (o, p))| ev.add_keyframe(o, p, i as u32, &cfg, None)).collect();
            let n = ev.len() - extra.is_some() as usize;
            (stats, ev.rows()[..n].to_vec(), ev.log_odds[..n].to_vec())
        };
        let (by_rank, by_box) = (run(None), run(Some(far)));
        assert!(by_rank.0.iter().all(|s| s.hit_voxels > 0 && s.free_voxels > 0), "{:?}", by_rank.0);
        assert_eq!(by_rank.0, by_box.0);
        assert_eq!(by_rank.1, by_box.1);
        assert_eq!(by_rank.2, by_box.2);
    }

    /// Parallel rays give the same rows whatever the thread count.
    #[test]
    fn result_does_not_depend_on_threads() {
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        let cfg = EvidenceConfig::default();
        let o = [0.5, -0.2, 1.0];
        let pts = scan(&mut rng, o, 20_000);
        let keys: Vec<u64> = pts.iter().filter_map(|p| packed_key(p, 0.2)).collect();
        let run = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            pool.install(|| {
                let mut ev = InterestEvidence::new(keys.clone(), 0.2);
                ev.add_keyframe(&o, &pts, 0, &cfg, None);
                ev.add_keyframe(&[1.0, 1.0, 1.0], &pts, 1, &cfg, None);
                ev.rows().to_vec()
            })
        };
        assert_eq!(run(1), run(3));
    }

    /// A box too large for the dense marks is cut around the sensor.
    #[test]
    fn limit_keeps_the_sensor_and_bounds_the_volume() {
        let b = Box3 { lo: [-100_000, -100_000, -10], hi: [100_000, 100_000, 10] };
        let l = b.limit([5, -7, 0], 1 << 20);
        assert!(l.volume() <= 1 << 20);
        assert!(l.contains(&[5, -7, 0]));
        assert_eq!((l.lo[2], l.hi[2]), (-10, 10));
    }

    /// The own-hit guard widens with range (`free_guard_deg`): a ray through
    /// a voxel two voxels beside the keyframe's own hit frees it at 10 m
    /// (guard 1) but not at 50 m (guard ⌈50 m · 0.4° / 0.2 m⌉ = 2), unless
    /// the angle is 0.
    #[test]
    fn own_hit_guard_widens_with_range() {
        let o = [0.1, 0.1, 1.1];
        let freed = |x: f64, cfg: &EvidenceConfig| {
            let target = [x, 0.1, 1.1];
            let beside = [x, 0.1 + 0.4, 1.1];
            let behind = [x + 3.0, 0.1, 1.1];
            let keys: Vec<u64> = [target, beside, behind].iter().filter_map(|p| packed_key(p, 0.2)).collect();
            let mut ev = InterestEvidence::new(keys, 0.2);
            ev.add_keyframe(&o, &[beside, behind], 0, cfg, None);
            let i = ev.find(packed_key(&target, 0.2).unwrap()).unwrap();
            ev.rows()[i].free_n
        };
        let cfg = EvidenceConfig::default();
        assert_eq!((cfg.free_guard_voxels, cfg.free_guard_deg), (1, 0.4));
        assert_eq!(freed(10.1, &cfg), 1);
        assert_eq!(freed(50.1, &cfg), 0);
        assert_eq!(freed(50.1, &EvidenceConfig { free_guard_deg: 0.0, ..cfg.clone() }), 1);
        assert_eq!(freed(10.1, &EvidenceConfig { free_guard_voxels: 2, ..cfg }), 0);
    }

    /// The scalar baseline: a voxel hit then freed more often flips to free
    /// (ε > 0.5); one only hit stays occupied.
    #[test]
    fn log_odds_baseline_follows_octomap_updates() {
        let cfg = EvidenceConfig { model: EvidenceModel::LogOdds, ..Default::default() };
        let (l_hit, l_miss, l_min, l_max) = cfg.log_odds.log_odds();
        // Voxel [50,0,5] (x = 10 m): hit by keyframe 0 from the origin, then
        // freed by 5 keyframes whose rays pass through it to x = 20 m.
        let target = [10.1, 0.1, 1.1];
        let keys = vec![packed_key(&target, 0.2).unwrap()];
        let mut ev = InterestEvidence::new(keys, 0.2);
        ev.add_keyframe(&[0.1, 0.1, 1.1], &[target], 0, &cfg, None);
        let after_hit = ev.eps_l(&cfg)[0] as f64;
        let mut want = 0.0f32;
        want = (want + l_hit).clamp(l_min, l_max);
        assert!((after_hit - (1.0 / (1.0 + (want as f64).exp())).clamp(0.1, 1.0)).abs() < 1e-6);
        assert!(after_hit < 0.5);
        for k in 1..=5 {
            ev.add_keyframe(&[0.1, 0.1, 1.1], &[[20.1, 0.1, 1.1]], k, &cfg, None);
            want = (want + l_miss).clamp(l_min, l_max);
        }
        let eps = ev.eps_l(&cfg)[0] as f64;
        assert!((eps - 1.0 / (1.0 + (want as f64).exp())).abs() < 1e-6, "{eps}");
        assert!(eps > 0.5);
        assert_eq!((ev.rows()[0].hit_n, ev.rows()[0].free_n), (1, 5));
    }
}
