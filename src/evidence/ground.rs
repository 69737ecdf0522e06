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

/// The lowest occupied key z of every (x, y) key column.
#[derive(Debug, Clone, Default)]
pub struct GroundLevel {
    lowest_kz: FxHashMap<(i32, i32), i32>,
}

impl GroundLevel {
    /// From packed keys of occupied voxels (any order, repeats allowed).
    pub fn from_keys<'a>(keys: impl IntoIterator<Item = &'a u64>) -> GroundLevel {
        let mut lowest_kz: FxHashMap<(i32, i32), i32> = FxHashMap::default();
        for &k in keys {
            let [x, y, z] = unpack(k).0;
            lowest_kz.entry((x, y)).and_modify(|low| *low = (*low).min(z)).or_insert(z);
        }
        GroundLevel { lowest_kz }
    }

    /// Whether voxel `k` lies at its column's ground level; `None` when the
    /// column holds no occupied voxel.
    #[inline]
    pub fn at_ground(&self, k: &[i32; 3]) -> Option<bool> {
        self.lowest_kz.get(&(k[0], k[1])).map(|&low| k[2] <= low.saturating_add(GROUND_BAND_VOXELS))
    }

    /// Whether voxel `k` is its column's lowest occupied voxel (`false`
    /// when the column holds none).
    #[inline]
    pub fn is_lowest(&self, k: &[i32; 3]) -> bool {
        self.lowest_kz.get(&(k[0], k[1])).is_some_and(|&low| k[2] <= low)
    }

    pub fn columns(&self) -> usize {
        self.lowest_kz.len()
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
}
