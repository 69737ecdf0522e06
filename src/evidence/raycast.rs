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
    walk(origin_m, end_m, voxel_m, &Unmasked, |k, _, _| f(k)).map_or(0, |(visited, _)| visited)
}

/// Which voxels a walk reports. [`Unmasked`] reports all; [`BlockMask`]
/// only its voxels of interest, and jumps over blocks that hold none.
trait Skip {
    /// Whether this kind skips at all (compiled out when not).
    const SKIPS: bool;
    /// Whether the block with block coordinates `block` holds no voxel of
    /// interest.
    fn is_empty_block(&self, block: &[i32; 3]) -> bool;
    /// The block's voxels of interest, bit [`voxel_bit`] each (0: none),
    /// and the rank of its first ([`BlockMask::rank_of`]; 0 unmasked).
    fn block_voxels(&self, block: &[i32; 3]) -> (u64, u32);
}

struct Unmasked;

impl Skip for Unmasked {
    const SKIPS: bool = false;
    #[inline(always)]
    fn is_empty_block(&self, _: &[i32; 3]) -> bool {
        false
    }
    #[inline(always)]
    fn block_voxels(&self, _: &[i32; 3]) -> (u64, u32) {
        (u64::MAX, 0)
    }
}

/// log2 of a block's edge in voxels: 4 voxels (0.8 m at 0.2 m), so that a
/// block's 64 voxels are the bits of one `u64`.
pub const BLOCK_SHIFT: u32 = 2;
const EDGE: i32 = (1 << BLOCK_SHIFT) - 1;

/// The block coordinates of voxel `key`.
#[inline]
fn block_of(key: &[i32; 3]) -> [i32; 3] {
    key.map(|c| c >> BLOCK_SHIFT)
}

/// The bit of voxel `key` in its block's `u64`.
#[inline]
fn voxel_bit(key: &[i32; 3]) -> u64 {
    1 << ((key[0] & EDGE) | ((key[1] & EDGE) << BLOCK_SHIFT) | ((key[2] & EDGE) << (2 * BLOCK_SHIFT)))
}

/// The voxels of interest of a key box, grouped in blocks of 4×4×4: a bit
/// per block over the box (with a rank per word), and for each block that
/// holds any, a `u64` of which of its 64 voxels they are.
///
/// Why: evidence is kept only on the voxels some point occupies
/// (`super::grid`), and on the sites measured 75-90 % of a ray's walk
/// crosses 0.8 m blocks that hold none of them (open air), and most of the
/// rest passes voxels that are not of interest either. [`cast_ray_ranked`]
/// jumps over an empty block in one step and reports only voxels of
/// interest. Voxels outside the box are not of interest.
#[derive(Debug, Clone)]
pub struct BlockMask {
    lo: [i32; 3],
    dims: [u64; 3],
    present: Vec<u64>,
    /// Occupied blocks before each word of `present`.
    rank: Vec<u32>,
    voxels: Vec<u64>,
    /// Voxels of interest before each occupied block (see [`Self::rank_of`]).
    voxel_rank: Vec<u32>,
}

impl BlockMask {
    /// The mask of `keys` (voxel keys; those outside the inclusive box
    /// `lo..=hi` are left out) over that box; `None` when the box has more
    /// than `max_blocks` blocks.
    pub fn new<I>(lo: [i32; 3], hi: [i32; 3], keys: I, max_blocks: u64) -> Option<BlockMask>
    where
        I: Iterator<Item = [i32; 3]> + Clone,
    {
        let blo = block_of(&lo);
        let bhi = block_of(&hi);
        let dims = [0, 1, 2].map(|a| (bhi[a] as i64 - blo[a] as i64 + 1).max(0) as u64);
        let n = dims[0].checked_mul(dims[1])?.checked_mul(dims[2])?;
        if n > max_blocks {
            return None;
        }
        let mut m = BlockMask {
            lo: blo,
            dims,
            present: vec![0; n.div_ceil(64) as usize],
            rank: Vec::new(),
            voxels: Vec::new(),
            voxel_rank: Vec::new(),
        };
        let inside = |k: &[i32; 3]| (0..3).all(|a| lo[a] <= k[a] && k[a] <= hi[a]);
        for k in keys.clone().filter(|k| inside(k)) {
            if let Some(i) = m.index_block(&block_of(&k)) {
                m.present[(i / 64) as usize] |= 1 << (i % 64);
            }
        }
        let (rank, blocks) = bits_before(&m.present);
        m.rank = rank;
        m.voxels = vec![0; blocks as usize];
        for k in keys.filter(|k| inside(k)) {
            if let Some(slot) = m.slot(&block_of(&k)) {
                m.voxels[slot] |= voxel_bit(&k);
            }
        }
        m.voxel_rank = bits_before(&m.voxels).0;
        Some(m)
    }

    /// How many voxels of interest there are.
    pub fn count(&self) -> usize {
        self.voxel_rank.last().zip(self.voxels.last()).map_or(0, |(r, w)| *r as usize + w.count_ones() as usize)
    }

    /// The position of voxel `key` among the voxels of interest, in the
    /// mask's own order (by block, then by bit within the block), `None`
    /// when it is not one. A dense index in `0..count()` for a table of
    /// one entry per voxel of interest: a few words of the mask read
    /// instead of a hash probe.
    #[inline]
    pub fn rank_of(&self, key: &[i32; 3]) -> Option<usize> {
        let slot = self.slot(&block_of(key))?;
        let w = self.voxels[slot];
        let bit = voxel_bit(key);
        (w & bit != 0).then(|| self.voxel_rank[slot] as usize + (w & (bit - 1)).count_ones() as usize)
    }

    /// Whether `f(key, rank)` holds for some voxel of interest in the
    /// inclusive key box `lo..=hi` (stops at the first). Block by block:
    /// the box's voxels in a block are a bit pattern of its word, so a
    /// small neighbourhood costs a few block reads, not a
    /// [`Self::rank_of`] per voxel.
    pub fn any_in_box(&self, lo: [i32; 3], hi: [i32; 3], mut f: impl FnMut([i32; 3], usize) -> bool) -> bool {
        if (0..3).any(|a| lo[a] > hi[a]) {
            return false;
        }
        let (blo, bhi) = (block_of(&lo), block_of(&hi));
        // The 4 bits of an axis's local coordinates inside the box.
        let local = |a: usize, bc: i32| -> u64 {
            let base = bc << BLOCK_SHIFT;
            let from = (lo[a] - base).max(0);
            let to = (hi[a] - base).min(EDGE);
            ((1u64 << (to + 1)) - 1) & !((1u64 << from) - 1)
        };
        // A 1 at the first bit of each row (y) or plane (z) in the box: a
        // block's bit index is x + y · 2^BLOCK_SHIFT + z · 2^(2·BLOCK_SHIFT),
        // so the x pattern times both gives the box's bits.
        let spread = |m: u64, shift: u32| {
            (0..=EDGE as u32).filter(|i| (m >> i) & 1 != 0).map(|i| 1u64 << (i << shift)).sum::<u64>()
        };
        for bz in blo[2]..=bhi[2] {
            let zm = spread(local(2, bz), 2 * BLOCK_SHIFT);
            for by in blo[1]..=bhi[1] {
                let ym = spread(local(1, by), BLOCK_SHIFT);
                for bx in blo[0]..=bhi[0] {
                    let (word, base) = self.block_voxels(&[bx, by, bz]);
                    let mut m = word & (local(0, bx) * ym * zm);
                    while m != 0 {
                        let bit = m & m.wrapping_neg();
                        m ^= bit;
                        let pos = bit.trailing_zeros() as i32;
                        let key = [
                            (bx << BLOCK_SHIFT) + (pos & EDGE),
                            (by << BLOCK_SHIFT) + ((pos >> BLOCK_SHIFT) & EDGE),
                            (bz << BLOCK_SHIFT) + (pos >> (2 * BLOCK_SHIFT)),
                        ];
                        if f(key, (base + (word & (bit - 1)).count_ones()) as usize) {
                            return true;
                        }
                    }
                }
            }
        }
        false
    }

    #[inline]
    fn index_block(&self, block: &[i32; 3]) -> Option<u64> {
        // Below `lo` wraps to a huge offset: one unsigned test per axis, and
        // no branch between the axes.
        let c = [0, 1, 2].map(|a| (block[a] as i64 - self.lo[a] as i64) as u64);
        if (c[0] >= self.dims[0]) | (c[1] >= self.dims[1]) | (c[2] >= self.dims[2]) {
            return None;
        }
        Some((c[2] * self.dims[1] + c[1]) * self.dims[0] + c[0])
    }

    /// Where an occupied block's voxels are in `voxels`.
    #[inline]
    fn slot(&self, block: &[i32; 3]) -> Option<usize> {
        let i = self.index_block(block)?;
        let w = self.present[(i / 64) as usize];
        let bit = 1u64 << (i % 64);
        (w & bit != 0).then(|| (self.rank[(i / 64) as usize] + (w & (bit - 1)).count_ones()) as usize)
    }

    /// Whether voxel `key` is of interest.
    #[inline]
    pub fn holds(&self, key: &[i32; 3]) -> bool {
        self.block_voxels(&block_of(key)).0 & voxel_bit(key) != 0
    }
}

/// Per word, the set bits of the words before it; and the set bits of all.
fn bits_before(words: &[u64]) -> (Vec<u32>, u32) {
    let mut total = 0u32;
    let before = words
        .iter()
        .map(|w| {
            let r = total;
            total += w.count_ones();
            r
        })
        .collect();
    (before, total)
}

impl Skip for BlockMask {
    const SKIPS: bool = true;
    #[inline]
    fn is_empty_block(&self, block: &[i32; 3]) -> bool {
        self.index_block(block).is_none_or(|i| self.present[(i / 64) as usize] & (1 << (i % 64)) == 0)
    }
    #[inline]
    fn block_voxels(&self, block: &[i32; 3]) -> (u64, u32) {
        self.slot(block).map_or((0, 0), |s| (self.voxels[s], self.voxel_rank[s]))
    }
}

/// The walk behind [`traverse`] and the casts: calls `f(key, remaining,
/// rank)` for every voxel visited, `remaining` the steps still to go (0 at
/// the endpoint's voxel) and `rank` the voxel's [`BlockMask::rank_of`]
/// (0 unmasked), and returns the number of steps walked one voxel at
/// a time and the endpoint's voxel (`None`, visiting nothing, for the rays
/// [`traverse`] refuses). With a skipping `mask`, only its voxels of interest
/// are reported, and empty blocks the endpoint is not in are left by
/// [`Dda::jump_empty`] instead of walked. A jump moves each axis at most to the
/// block entered and never past the endpoint's key, so the walk still ends
/// at the endpoint's voxel after `|Δi| + |Δj| + |Δk|` steps in all.
///
/// Tried and dropped: setting `t_max = ∞` on the axes that reached the
/// endpoint's key, so that the axis choice is a plain minimum without the
/// `key != stop` tests. Same results, no faster (SemanticKITTI 04's evidence
/// step 1.17-1.23 s before, 1.21-1.29 s after, alternating runs). Also
/// dropped, on `examples/dor_probe` (medians of alternating runs, ray
/// casting): a bit per 4×4×4 blocks read before a block's own bit in
/// [`Dda::jump_empty`] (SemanticKITTI 08 0.555 → 0.530 s, a simulated
/// HDL-64E session 2.06 → 2.27 s: noise, not a gain); leaving such an
/// empty super-block in one step (SemanticKITTI 04 0.49 → 0.53 s, 08
/// 0.47 → 0.555 s: slower); and `present` laid out in 4×4×4-block tiles
/// of one word each (08: 0.49 → 0.53 s).
fn walk<S: Skip>(
    origin_m: &[f64; 3],
    end_m: &[f64; 3],
    voxel_m: f64,
    mask: &S,
    mut f: impl FnMut(VoxelKey, u64, u32),
) -> Option<(usize, VoxelKey)> {
    if !(voxel_m.is_finite() && voxel_m > 0.0) {
        return None;
    }
    let (Some(start), Some(stop)) = (voxel_key(origin_m, voxel_m), voxel_key(end_m, voxel_m)) else {
        return None;
    };
    let key = start.0;
    let stop = stop.0;
    let mut step = [0i32; 3];
    // Ray parameter t ∈ [0, 1] at the next boundary crossing along each axis,
    // and the increment of t between successive crossings.
    let mut t_max = [f64::INFINITY; 3];
    let mut t_delta = [f64::INFINITY; 3];
    let mut remaining = 0u64;
    for a in 0..3 {
        let d = end_m[a] - origin_m[a];
        let dk = stop[a] as i64 - start.0[a] as i64;
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
    // The walk's state stays in locals updated at constant indices (the
    // `match` below), so that it lives in registers: indexing the arrays by
    // the chosen axis put them in memory, each step a store and reloads.
    // Only a block change hands it to [`Dda::enter_block`].
    let (mut key, mut t_max) = (key, t_max);
    let mut visited = 1;
    // The current block's voxels of interest (all, unmasked).
    let (mut here, mut base) = (u64::MAX, 0u32);
    // The rank of the current voxel, of interest in the current block.
    let rank = |here: u64, base: u32, key: &[i32; 3]| {
        if S::SKIPS { base + (here & (voxel_bit(key) - 1)).count_ones() } else { 0 }
    };
    let enter = |key: &mut [i32; 3], t_max: &mut [f64; 3], remaining: &mut u64| {
        let mut ray = Dda { key: *key, stop, step, t_max: *t_max, t_delta, remaining: *remaining };
        let here = ray.enter_block(mask);
        (*key, *t_max, *remaining) = (ray.key, ray.t_max, ray.remaining);
        here
    };
    if S::SKIPS {
        (here, base) = enter(&mut key, &mut t_max, &mut remaining);
    }
    if !S::SKIPS || here & voxel_bit(&key) != 0 {
        f(VoxelKey(key), remaining, rank(here, base, &key));
    }
    while remaining > 0 {
        // The earliest crossing among axes that still have to move; ties
        // to the lower axis.
        let mut axis = 3;
        let mut t = f64::INFINITY;
        if key[0] != stop[0] {
            (axis, t) = (0, t_max[0]);
        }
        if key[1] != stop[1] && (axis == 3 || t_max[1] < t) {
            (axis, t) = (1, t_max[1]);
        }
        if key[2] != stop[2] && (axis == 3 || t_max[2] < t) {
            axis = 2;
        }
        let crossed_block = match axis {
            0 => step_axis::<0>(&mut key, &mut t_max, &step, &t_delta),
            1 => step_axis::<1>(&mut key, &mut t_max, &step, &t_delta),
            _ => step_axis::<2>(&mut key, &mut t_max, &step, &t_delta),
        };
        remaining -= 1;
        visited += 1;
        if S::SKIPS {
            if crossed_block {
                (here, base) = enter(&mut key, &mut t_max, &mut remaining);
            }
            if here & voxel_bit(&key) == 0 {
                continue;
            }
        }
        f(VoxelKey(key), remaining, rank(here, base, &key));
    }
    Some((visited, VoxelKey(stop)))
}

/// One step of the walk along axis `A`; whether it entered another block.
#[inline(always)]
fn step_axis<const A: usize>(key: &mut [i32; 3], t_max: &mut [f64; 3], step: &[i32; 3], t_delta: &[f64; 3]) -> bool {
    let before = key[A];
    key[A] += step[A];
    t_max[A] += t_delta[A];
    (key[A] >> BLOCK_SHIFT) != (before >> BLOCK_SHIFT)
}

/// The state of [`walk`]'s Amanatides-Woo traversal: the current and the
/// endpoint's voxel, the step per axis, the ray parameter `t ∈ [0, 1]` of
/// the next boundary crossing per axis and its increment between
/// crossings, and the steps still to go.
struct Dda {
    key: [i32; 3],
    stop: [i32; 3],
    step: [i32; 3],
    t_max: [f64; 3],
    t_delta: [f64; 3],
    remaining: u64,
}

impl Dda {
    /// On entering the block of `key`: the voxels of interest of the block
    /// the walk goes on in. An empty block is left by jumping over the
    /// empty blocks ahead ([`Dda::jump_empty`]); the block returned is
    /// then 0 only if it is the endpoint's own, walked but not reported.
    fn enter_block<S: Skip>(&mut self, mask: &S) -> (u64, u32) {
        let here = mask.block_voxels(&block_of(&self.key));
        if here.0 != 0 {
            return here;
        }
        self.jump_empty(mask);
        mask.block_voxels(&block_of(&self.key))
    }

    /// Leaves the empty blocks (of `mask`) ahead until an occupied block or
    /// the endpoint's block. See [`walk`].
    ///
    /// Between blocks it is the walk one level up: per axis the parameter
    /// of the next block crossing (`t_max` plus the crossings to the
    /// block's edge), advanced by four `t_delta` a block. Where it stops,
    /// each other axis takes the crossings before the entry (counted from
    /// `t_max`, clamped to the block entered and to the endpoint's key).
    fn jump_empty<S: Skip>(&mut self, mask: &S) {
        let Dda { key, stop, step, t_max, t_delta, remaining } = self;
        let stop_block = block_of(stop);
        let block = block_of(key);
        if *remaining == 0 || block == stop_block {
            return;
        }
        // Parameter of the crossing out of the current block along each axis.
        let mut t_block = [f64::INFINITY; 3];
        for a in 0..3 {
            if step[a] != 0 {
                let within = key[a] & EDGE;
                let n = if step[a] > 0 { EDGE - within } else { within };
                t_block[a] = t_max[a] + n as f64 * t_delta[a];
            }
        }
        let block_delta = t_delta.map(|d| d * (1 << BLOCK_SHIFT) as f64);
        // Per-axis scalars, not arrays indexed by the axis: an element
        // store followed by the whole array's load (the comparison with
        // the endpoint's block) defeats store-to-load forwarding, and the
        // stall was a third of this loop's time.
        let [mut b0, mut b1, mut b2] = block;
        let [mut t0, mut t1, mut t2] = t_block;
        let [s0, s1, s2] = stop_block;
        let mut t_enter;
        let mut entered;
        loop {
            // Ties to the lower axis, as in the walk.
            let (mut e, mut t) = (3usize, f64::INFINITY);
            if b0 != s0 {
                (e, t) = (0, t0);
            }
            if b1 != s1 && (e == 3 || t1 < t) {
                (e, t) = (1, t1);
            }
            if b2 != s2 && (e == 3 || t2 < t) {
                (e, t) = (2, t2);
            }
            match e {
                0 => {
                    b0 += step[0];
                    t0 += block_delta[0];
                }
                1 => {
                    b1 += step[1];
                    t1 += block_delta[1];
                }
                2 => {
                    b2 += step[2];
                    t2 += block_delta[2];
                }
                _ => return,
            }
            t_enter = t;
            entered = e;
            if (b0 == s0 && b1 == s1 && b2 == s2) || !mask.is_empty_block(&[b0, b1, b2]) {
                break;
            }
        }
        let block = [b0, b1, b2];
        for a in 0..3 {
            if step[a] == 0 {
                continue;
            }
            let base = block[a] << BLOCK_SHIFT;
            let target = if a == entered {
                if step[a] > 0 { base } else { base + EDGE }
            } else {
                let c = if t_max[a] < t_enter { ((t_enter - t_max[a]) / t_delta[a]) as i64 + 1 } else { 0 };
                let k = (key[a] as i64 + step[a] as i64 * c).clamp(base as i64, (base + EDGE) as i64) as i32;
                // Never past the endpoint's key.
                if step[a] > 0 { k.min(stop[a]) } else { k.max(stop[a]) }
            };
            let n = (target - key[a]).abs();
            key[a] = target;
            t_max[a] += n as f64 * t_delta[a];
        }
        *remaining = (0..3).map(|a| (stop[a] as i64 - key[a] as i64).unsigned_abs()).sum();
    }
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

/// [`cast_ray`] over the voxels of interest only: the same hit, and of the
/// same free voxels those `mask` holds; its empty blocks are jumped over
/// (see [`BlockMask`]). The tests' view of [`cast_ray_ranked`].
#[cfg(test)]
pub fn cast_ray_masked(
    origin_m: &[f64; 3],
    end_m: &[f64; 3],
    voxel_m: f64,
    mask: &BlockMask,
    mut on_free: impl FnMut(VoxelKey),
) -> Option<VoxelKey> {
    cast_ray_ranked(origin_m, end_m, voxel_m, mask, |k, _| on_free(k)).map(|(hit, _)| hit)
}

/// [`cast_ray_masked`] with each voxel's [`BlockMask::rank_of`]: `on_free`
/// gets the rank of each free voxel, and the hit comes with its rank when
/// it is of interest. The walk knows the rank from the block it is in, so
/// tables with one entry per voxel of interest need no lookup.
pub fn cast_ray_ranked(
    origin_m: &[f64; 3],
    end_m: &[f64; 3],
    voxel_m: f64,
    mask: &BlockMask,
    mut on_free: impl FnMut(VoxelKey, u32),
) -> Option<(VoxelKey, Option<u32>)> {
    let mut hit_rank = None;
    walk(origin_m, end_m, voxel_m, mask, |k, remaining, rank| {
        if remaining >= 2 {
            on_free(k, rank)
        } else if remaining == 0 {
            hit_rank = Some(rank)
        }
    })
    .map(|(_, hit)| (hit, hit_rank))
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

    /// `any_in_box` visits exactly the voxels of interest in the box, each
    /// with its rank.
    #[test]
    fn any_in_box_visits_the_box_voxels_of_interest_with_their_ranks() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let keys: Vec<[i32; 3]> = (0..4000).map(|_| std::array::from_fn(|_| rng.random_range(-20..20))).collect();
        let mask = BlockMask::new([-20; 3], [19; 3], keys.iter().copied(), u64::MAX).unwrap();
        let set: BTreeSet<[i32; 3]> = keys.iter().copied().collect();
        for _ in 0..300 {
            let c: [i32; 3] = std::array::from_fn(|_| rng.random_range(-22..22));
            let r = rng.random_range(0..4);
            let (lo, hi) = (c.map(|x| x - r), c.map(|x| x + r + rng.random_range(0..2)));
            let mut got = Vec::new();
            assert!(!mask.any_in_box(lo, hi, |k, rank| {
                got.push((k, rank));
                false
            }));
            got.sort_unstable();
            let mut want = Vec::new();
            for z in lo[2]..=hi[2] {
                for y in lo[1]..=hi[1] {
                    for x in lo[0]..=hi[0] {
                        if set.contains(&[x, y, z]) {
                            want.push(([x, y, z], mask.rank_of(&[x, y, z]).unwrap()));
                        }
                    }
                }
            }
            want.sort_unstable();
            assert_eq!(got, want, "box {lo:?}..={hi:?}");
        }
    }

    /// The masked cast against the full one with its free voxels filtered
    /// to the voxels of interest: same hit, same frees, same order.
    fn check_masked(o: [f64; 3], e: [f64; 3], v: f64, occupied: &[[i32; 3]]) {
        let (lo, hi) = ([-200; 3], [200; 3]);
        let mask = BlockMask::new(lo, hi, occupied.iter().copied(), u64::MAX).unwrap();
        let set: BTreeSet<[i32; 3]> = occupied.iter().copied().collect();
        for k in occupied {
            assert!(mask.holds(k));
        }
        let mut full = Vec::new();
        let hit = cast_ray(&o, &e, v, |k| full.push(k));
        let want: Vec<VoxelKey> = full.into_iter().filter(|k| set.contains(&k.0)).collect();
        let mut got = Vec::new();
        let hit_masked = cast_ray_masked(&o, &e, v, &mask, |k| got.push(k));
        assert_eq!(hit_masked, hit, "{o:?} → {e:?} at {v}");
        assert_eq!(got, want, "{o:?} → {e:?} at {v}");
        // The ranks the walk hands out are the mask's own.
        let mut ranked = Vec::new();
        let hit_ranked = cast_ray_ranked(&o, &e, v, &mask, |k, r| ranked.push((k, r as usize)));
        let want_ranked: Vec<(VoxelKey, usize)> = want.iter().map(|k| (*k, mask.rank_of(&k.0).unwrap())).collect();
        assert_eq!(ranked, want_ranked, "{o:?} → {e:?} at {v}");
        assert_eq!(hit_ranked.map(|(k, _)| k), hit);
        assert_eq!(
            hit_ranked.and_then(|(_, r)| r.map(|r| r as usize)),
            hit.and_then(|k| mask.rank_of(&k.0)),
            "the hit's rank exactly when it is of interest"
        );
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(500))]
        #[test]
        fn masked_cast_frees_what_the_full_cast_frees_among_the_voxels_of_interest(
            o in prop::array::uniform3(-15.0f64..15.0),
            e in prop::array::uniform3(-15.0f64..15.0),
            v in 0.15f64..1.0,
            // Voxels of interest: a few near the segment, by its parameter.
            near in prop::collection::vec((0.0f64..1.0, prop::array::uniform3(-3i32..4)), 0..12),
        ) {
            let occupied: Vec<[i32; 3]> = near
                .iter()
                .filter_map(|&(t, d)| {
                    let p = [0, 1, 2].map(|a| o[a] + t * (e[a] - o[a]));
                    voxel_key(&p, v).map(|k| [0, 1, 2].map(|a| k.0[a] + d[a]))
                })
                .collect();
            check_masked(o, e, v, &occupied);
        }
    }

    #[test]
    fn masked_cast_edge_cases() {
        // Nothing occupied: the hit only, no free voxel, even for long rays.
        check_masked([0.1, 0.1, 0.1], [30.3, -12.7, 4.1], 0.2, &[]);
        // Everything along the ray occupied: the full cast.
        let (o, e, v) = ([0.05, -0.3, 1.7], [-14.2, 9.9, -1.3], 0.2);
        let mut all = Vec::new();
        traverse(&o, &e, v, |k| all.push(k.0));
        check_masked(o, e, v, &all);
        // Axis-parallel and grid-aligned rays, endpoint's block empty.
        check_masked([0.0, 0.0, 0.0], [8.0, 0.0, 0.0], 0.5, &[[4, 0, 0], [9, 0, 0]]);
        check_masked([0.0, 0.0, 0.0], [-8.0, -8.0, -8.0], 0.5, &[[-5, -5, -5], [-1, -1, -1]]);
        // Voxels outside the mask's box are not of interest; inside, exactly
        // the keys given, whatever their block.
        let keys = [[100, 0, 0], [-1, 0, 0], [3, 3, 3], [0, 1, 2], [-5, -6, -7]];
        let mask = BlockMask::new([-8; 3], [3; 3], keys.iter().copied(), u64::MAX).unwrap();
        assert!(!mask.holds(&[100, 0, 0]));
        assert!(
            mask.holds(&[-1, 0, 0]) && mask.holds(&[3, 3, 3]) && mask.holds(&[0, 1, 2]) && mask.holds(&[-5, -6, -7])
        );
        assert!(
            !mask.holds(&[0, 0, 0]) && !mask.holds(&[2, 1, 3]) && !mask.holds(&[-5, -6, -6]) && !mask.holds(&[4, 0, 0])
        );
        assert!(BlockMask::new([-8; 3], [3; 3], keys.iter().copied(), 26).is_none(), "27 blocks");
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
