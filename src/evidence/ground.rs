//! Ground level per voxel column, for the two rules that keep rays from
//! freeing the ground without also sparing what stands on it.
//!
//! ```text
//!   column (x, y) of voxel keys        lowest occupied key z = kz_low
//!   ┌───┐
//!   │   │  kz_low + 2 …   above the ground: a ray ending here is not a
//!   │   │                 ground ray; a hit here guards its neighbours
//!   ├───┤
//!   │ g │  kz_low + 1     ground level (GROUND_BAND_VOXELS = 1: a voxel
//!   │ g │  kz_low         of slope or roughness above the lowest one)
//!   └───┘
//! ```
//!
//! The lowest key is over the points of the session being ray cast, every
//! keyframe's, so a mover's old place has its ground from the keyframes that
//! saw past it. A column with no point at all has no ground level, and the
//! rules then fall back to what they did without it (`EvidenceConfig::
//! clearance_near_ground_only`, `EvidenceConfig::ground_hits_guard`).
//!
//! Neither rule needs more than "lowest point of the column": no plane fit,
//! no classes. A column whose lowest point is a car roof (the ground beneath
//! never seen) makes the roof its ground, which only keeps the older, more
//! cautious behaviour there.

use super::grid::unpack;
use rustc_hash::FxHashMap;

/// Voxels above a column's lowest occupied one that still count as its
/// ground level.
pub const GROUND_BAND_VOXELS: i32 = 1;

/// Columns a dense [`GroundLevel`] holds at most (4 bytes each: 32 MiB);
/// keys spread wider fall back to a hash map.
const DENSE_MAX_COLUMNS: u64 = 1 << 23;

/// No point in the column (dense layout).
const NO_GROUND: i32 = i32::MAX;

/// The lowest occupied key z of every (x, y) key column.
///
/// Dense over the keys' (x, y) bounds where they fit
/// `DENSE_MAX_COLUMNS`: every downward ray looks its endpoint's column
/// up, and a scan's consecutive rays end in neighbouring columns, which a
/// grid keeps on the same cache lines where a hash map scatters them (on
/// SemanticKITTI 08 the hash probe was an eighth of the ray casting).
#[derive(Debug, Clone, Default)]
pub struct GroundLevel {
    columns: Columns,
}

#[derive(Debug, Clone)]
enum Columns {
    /// `lowest_kz[(y - lo_y) * dx + (x - lo_x)]`, [`NO_GROUND`] for none.
    Dense {
        lo: [i32; 2],
        dims: [u64; 2],
        lowest_kz: Vec<i32>,
        count: usize,
    },
    Sparse(FxHashMap<(i32, i32), i32>),
}

impl Default for Columns {
    fn default() -> Self {
        Columns::Sparse(FxHashMap::default())
    }
}

impl GroundLevel {
    /// From packed keys of occupied voxels (any order, repeats allowed).
    pub fn from_keys<'a>(keys: impl IntoIterator<Item = &'a u64> + Clone) -> GroundLevel {
        let (mut lo, mut hi) = ([i32::MAX; 2], [i32::MIN; 2]);
        for &k in keys.clone() {
            let [x, y, _] = unpack(k).0;
            (lo, hi) = ([lo[0].min(x), lo[1].min(y)], [hi[0].max(x), hi[1].max(y)]);
        }
        let dims = [0, 1].map(|a| (hi[a] as i64 - lo[a] as i64 + 1).max(0) as u64);
        let n = dims[0].saturating_mul(dims[1]);
        if n == 0 || n > DENSE_MAX_COLUMNS {
            let mut lowest_kz: FxHashMap<(i32, i32), i32> = FxHashMap::default();
            for &k in keys {
                let [x, y, z] = unpack(k).0;
                lowest_kz.entry((x, y)).and_modify(|low| *low = (*low).min(z)).or_insert(z);
            }
            return GroundLevel { columns: Columns::Sparse(lowest_kz) };
        }
        let mut lowest_kz = vec![NO_GROUND; n as usize];
        for &k in keys {
            let [x, y, z] = unpack(k).0;
            let i = ((y as i64 - lo[1] as i64) as u64 * dims[0] + (x as i64 - lo[0] as i64) as u64) as usize;
            lowest_kz[i] = lowest_kz[i].min(z);
        }
        let count = lowest_kz.iter().filter(|&&z| z != NO_GROUND).count();
        GroundLevel { columns: Columns::Dense { lo, dims, lowest_kz, count } }
    }

    /// The lowest occupied key z of column (x, y) of `k`, if any.
    #[inline]
    fn lowest(&self, k: &[i32; 3]) -> Option<i32> {
        match &self.columns {
            Columns::Dense { lo, dims, lowest_kz, .. } => {
                let (dx, dy) = (k[0] as i64 - lo[0] as i64, k[1] as i64 - lo[1] as i64);
                if dx < 0 || dy < 0 || dx as u64 >= dims[0] || dy as u64 >= dims[1] {
                    return None;
                }
                let z = lowest_kz[(dy as u64 * dims[0] + dx as u64) as usize];
                (z != NO_GROUND).then_some(z)
            }
            Columns::Sparse(m) => m.get(&(k[0], k[1])).copied(),
        }
    }

    /// Whether voxel `k` lies at its column's ground level; `None` when the
    /// column holds no occupied voxel.
    #[inline]
    pub fn at_ground(&self, k: &[i32; 3]) -> Option<bool> {
        self.lowest(k).map(|low| k[2] <= low.saturating_add(GROUND_BAND_VOXELS))
    }

    /// Whether voxel `k` is its column's lowest occupied voxel (`false`
    /// when the column holds none).
    #[inline]
    pub fn is_lowest(&self, k: &[i32; 3]) -> bool {
        self.lowest(k).is_some_and(|low| k[2] <= low)
    }

    /// Whether voxel `k` lies above the ground level of the columns within
    /// `r` of its own: above the lowest occupied key z among them plus
    /// [`GROUND_BAND_VOXELS`]; `true` when none of them holds a voxel.
    ///
    /// For what stands on ground no session saw beneath it (a pipe stack, a
    /// pallet), whose own column's lowest voxel is the object's bottom: the
    /// ground seen beside it sets the level.
    pub fn above_nearby(&self, k: &[i32; 3], r: i32) -> bool {
        let low = (-r..=r)
            .flat_map(|dy| (-r..=r).map(move |dx| (dx, dy)))
            .filter_map(|(dx, dy)| self.lowest(&[k[0].saturating_add(dx), k[1].saturating_add(dy), k[2]]))
            .min();
        low.is_none_or(|low| k[2] > low.saturating_add(GROUND_BAND_VOXELS))
    }

    pub fn columns(&self) -> usize {
        match &self.columns {
            Columns::Dense { count, .. } => *count,
            Columns::Sparse(m) => m.len(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::evidence::grid::pack;
    use crate::geometry::VoxelKey;

    #[test]
    fn ground_level_is_the_lowest_voxel_of_the_column_and_the_one_above() {
        let keys: Vec<u64> =
            [[0, 0, 5], [0, 0, -2], [0, 0, 9], [1, 0, 3]].iter().map(|&k| pack(VoxelKey(k)).unwrap()).collect();
        let g = GroundLevel::from_keys(&keys);
        assert_eq!(g.columns(), 2);
        assert_eq!(g.at_ground(&[0, 0, -2]), Some(true));
        assert_eq!(g.at_ground(&[0, 0, -1]), Some(true), "one voxel of slope above the lowest");
        assert_eq!(g.at_ground(&[0, 0, 0]), Some(false));
        assert_eq!(g.at_ground(&[0, 0, 9]), Some(false));
        assert_eq!(g.at_ground(&[1, 0, 4]), Some(true));
        assert_eq!(g.at_ground(&[1, 0, 5]), Some(false));
        assert_eq!(g.at_ground(&[2, 0, 0]), None, "a column without points has no ground level");
    }

    #[test]
    fn keys_spread_too_wide_for_a_grid_give_the_same_levels_from_a_hash_map() {
        // 5,001 × 4,001 columns: past DENSE_MAX_COLUMNS, so the sparse layout.
        let far = [[0, 0, 5], [0, 0, -2], [5000, 4000, 3], [5000, 4000, 1], [-1, 2, 0]];
        let keys: Vec<u64> = far.iter().map(|&k| pack(VoxelKey(k)).unwrap()).collect();
        let g = GroundLevel::from_keys(&keys);
        assert!(matches!(g.columns, Columns::Sparse(_)));
        let near: Vec<u64> = keys.iter().take(2).chain(keys.iter().skip(4)).copied().collect();
        let d = GroundLevel::from_keys(&near);
        assert!(matches!(d.columns, Columns::Dense { .. }));
        assert_eq!((g.columns(), d.columns()), (3, 2));
        for k in [[0, 0, -2], [0, 0, -1], [0, 0, 0], [-1, 2, 1], [-1, 2, 2], [7, 7, 0], [-9, 2, 0]] {
            assert_eq!(g.at_ground(&k), d.at_ground(&k), "{k:?}");
            assert_eq!(g.is_lowest(&k), d.is_lowest(&k), "{k:?}");
        }
        assert_eq!(g.at_ground(&[5000, 4000, 2]), Some(true));
        assert_eq!(g.at_ground(&[5000, 4000, 3]), Some(false));
        assert!(g.is_lowest(&[5000, 4000, 1]) && !g.is_lowest(&[5000, 4000, 2]));
        assert_eq!(d.at_ground(&[-1, 2, 1]), Some(true));
        assert_eq!(d.at_ground(&[1, 0, 0]), None, "inside the grid, no point in the column");
        for k in [[1, 1, -2], [1, 1, 0], [1, 2, 0], [1, 2, 1], [2, 0, -1], [3, 0, 0], [6, 6, 0]] {
            assert_eq!(g.above_nearby(&k, 2), d.above_nearby(&k, 2), "{k:?}");
        }
        assert!(!g.above_nearby(&[1, 1, -1], 2) && g.above_nearby(&[1, 1, 0], 2), "(0, 0) has -2 within 2");
        assert!(!g.above_nearby(&[5003, 4000, 2], 3) && g.above_nearby(&[5003, 4000, 3], 3));
    }

    #[test]
    fn the_ground_nearby_is_the_lowest_column_within_reach() {
        // A 3 x 3 box standing from z = 4 on ground seen at z = 0 two
        // columns off; its own columns' lowest voxel is its bottom.
        let mut keys: Vec<[i32; 3]> = vec![[-2, 0, 0], [9, 9, -7]];
        for x in 0..3 {
            for y in 0..3 {
                keys.extend((4..7).map(|z| [x, y, z]));
            }
        }
        let packed: Vec<u64> = keys.iter().map(|&k| pack(VoxelKey(k)).unwrap()).collect();
        let g = GroundLevel::from_keys(&packed);
        assert_eq!(g.at_ground(&[1, 1, 4]), Some(true), "its own column: the bottom is its ground");
        assert!(g.above_nearby(&[1, 1, 4], 3), "ground seen 3 columns off");
        assert!(!g.above_nearby(&[1, 1, 4], 1), "no lower column within 1: its own bottom");
        assert!(!g.above_nearby(&[-2, 0, 1], 3), "the band above the ground");
        assert!(g.above_nearby(&[-2, 0, 2], 3));
        assert!(g.above_nearby(&[30, 30, -100], 5), "no column within reach");
        assert!(!g.above_nearby(&[8, 8, -6], 1), "reach is per axis: (9, 9) is within 1 of (8, 8)");
    }
}
