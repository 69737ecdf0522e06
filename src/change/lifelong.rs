//! The lifelong map in memory: every voxel any session's cleaned map had,
//! with its ε_g and history, on the world grid of one graph version.
//!
//! Moving it to a later version is MATH.md §7 applied to map voxels: each
//! voxel's centroid moves with its owner keyframe's `ΔT = W_now · W_then⁻¹`
//! and is re-binned. Two voxels landing on one key merge; the older one (by
//! first session, then id) keeps its row, as the voxel that was there first.

use crate::evidence::grid::{pack, packed_key, unpack};
use crate::geometry::{Pose, Sym3, VoxelKey, rotate_sym, rotation_rows};
use nalgebra::Point3;
use rayon::prelude::*;
use rustc_hash::FxHashMap;

/// ELite's five categories (MATH.md §8), plus `Initial` for the voxels of
/// the first session, which nothing was compared against.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Category {
    Initial,
    Coexist,
    DeletedOverlap,
    DeletedNonOverlap,
    EmergedOverlap,
    EmergedNonOverlap,
}

impl Category {
    pub const ALL: [Category; 6] = [
        Category::Initial,
        Category::Coexist,
        Category::DeletedOverlap,
        Category::DeletedNonOverlap,
        Category::EmergedOverlap,
        Category::EmergedNonOverlap,
    ];

    /// The name stored in SQLite and exported.
    pub fn as_str(self) -> &'static str {
        match self {
            Category::Initial => "initial",
            Category::Coexist => "coexist",
            Category::DeletedOverlap => "deleted_overlap",
            Category::DeletedNonOverlap => "deleted_non_overlap",
            Category::EmergedOverlap => "emerged_overlap",
            Category::EmergedNonOverlap => "emerged_non_overlap",
        }
    }

    pub fn parse(s: &str) -> Option<Category> {
        Category::ALL.into_iter().find(|c| c.as_str() == s)
    }
}

impl std::fmt::Display for Category {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// One voxel of the lifelong map.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MapVoxel {
    /// Stable while the voxel lives (SQLite's `map_voxels.voxel_id`).
    pub voxel_id: i64,
    /// Key on the world grid of the map's graph version.
    pub key: VoxelKey,
    /// Centroid of its points, world frame, metres.
    pub xyz_m: [f64; 3],
    /// Global ephemerality, clamped to `[eps_g_min, eps_g_max]`.
    pub eps_g: f32,
    /// ε_l in the last session that saw it.
    pub eps_l: f32,
    /// Points behind the centroid in the last session that saw it.
    pub points: u32,
    pub first_session: i64,
    pub last_seen_session: i64,
    pub category: Category,
    /// The session that set `category`.
    pub category_session: i64,
    /// The voxel moves with this keyframe (index in `owner_session`).
    pub owner_session: i64,
    pub owner_keyframe: u32,
    /// Covariance of its points about the centroid, m², from the session
    /// that placed it (`CleanedMap::spread_m2`); `UNKNOWN_SPREAD` for voxels
    /// stored before seam kept it.
    pub spread_m2: Sym3,
}

/// A change a session saw at one voxel (SQLite's `change_events`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ChangeEvent {
    pub session_id: i64,
    pub voxel_id: i64,
    pub xyz_m: [f64; 3],
    pub category: Category,
    /// `None`: the voxel was new to the map.
    pub eps_g_before: Option<f32>,
    pub eps_g_after: f32,
}

/// The lifelong map: voxels sorted by packed key, keys unique.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LifelongMap {
    pub voxel_m: f64,
    pub voxels: Vec<MapVoxel>,
}

impl LifelongMap {
    /// A map from voxels in any order; on duplicate keys the older voxel
    /// (first session, then id) stays. Returns the map and how many merged.
    pub fn from_voxels(mut voxels: Vec<MapVoxel>, voxel_m: f64) -> (LifelongMap, usize) {
        voxels.par_sort_unstable_by_key(|v| (pack(v.key).unwrap_or(u64::MAX), v.first_session, v.voxel_id));
        let before = voxels.len();
        voxels.dedup_by_key(|v| v.key);
        let merged = before - voxels.len();
        (LifelongMap { voxel_m, voxels }, merged)
    }

    pub fn len(&self) -> usize {
        self.voxels.len()
    }

    pub fn is_empty(&self) -> bool {
        self.voxels.is_empty()
    }

    /// Packed keys, sorted.
    pub fn packed_keys(&self) -> Vec<u64> {
        self.voxels.iter().filter_map(|v| pack(v.key)).collect()
    }

    /// Voxels with `eps_g` below the threshold: the static map.
    pub fn static_count(&self, threshold: f64) -> usize {
        self.voxels.iter().filter(|v| (v.eps_g as f64) < threshold).count()
    }

    /// The largest voxel id, 0 for an empty map.
    pub fn max_id(&self) -> i64 {
        self.voxels.iter().map(|v| v.voxel_id).max().unwrap_or(0)
    }

    /// The map moved to a later graph version: each voxel's centroid by its
    /// owner's `delta_of(owner_session, owner_keyframe)` (owners it does not
    /// know stay), re-binned. Returns the map and how many voxels merged.
    pub fn moved(self, delta_of: impl Fn(i64, u32) -> Option<Pose> + Sync) -> (LifelongMap, usize) {
        let v = self.voxel_m;
        let mut cache: FxHashMap<(i64, u32), Option<Pose>> = FxHashMap::default();
        for x in &self.voxels {
            cache
                .entry((x.owner_session, x.owner_keyframe))
                .or_insert_with(|| delta_of(x.owner_session, x.owner_keyframe));
        }
        let moved: Vec<MapVoxel> = self
            .voxels
            .into_par_iter()
            .map(|mut x| {
                if let Some(d) = cache[&(x.owner_session, x.owner_keyframe)] {
                    let p = d * Point3::from(x.xyz_m);
                    x.xyz_m = [p.x, p.y, p.z];
                    x.spread_m2 = rotate_sym(&rotation_rows(&d), &x.spread_m2);
                    if let Some(k) = packed_key(&x.xyz_m, v) {
                        x.key = unpack(k);
                    }
                }
                x
            })
            .collect();
        LifelongMap::from_voxels(moved, v)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion};
    use std::f64::consts::FRAC_PI_2;

    fn voxel(id: i64, xyz: [f64; 3], first: i64, owner: (i64, u32)) -> MapVoxel {
        MapVoxel {
            voxel_id: id,
            key: unpack(packed_key(&xyz, 0.2).unwrap()),
            xyz_m: xyz,
            eps_g: 0.2,
            eps_l: 0.1,
            points: 3,
            first_session: first,
            last_seen_session: first,
            category: Category::Initial,
            category_session: first,
            owner_session: owner.0,
            owner_keyframe: owner.1,
            spread_m2: [1e-4, 0.0, 0.0, 1e-4, 0.0, 0.0],
        }
    }

    #[test]
    fn categories_round_trip_their_names() {
        for c in Category::ALL {
            assert_eq!(Category::parse(c.as_str()), Some(c));
        }
        assert_eq!(Category::parse("deleted"), None);
    }

    /// Voxels move with their own owner; two landing on one key merge and
    /// the older stays.
    #[test]
    fn moved_follows_owners_and_merges_collisions() {
        let m = vec![
            voxel(1, [1.05, 0.05, 0.05], 1, (1, 0)),
            voxel(2, [1.25, 0.05, 0.05], 2, (2, 4)),
            voxel(3, [5.05, 5.05, 0.05], 1, (1, 7)),
        ];
        let (map, merged) = LifelongMap::from_voxels(m, 0.2);
        assert_eq!((map.len(), merged), (3, 0));
        let shift = Pose::from_parts(Translation3::new(-0.2, 0.0, 0.0), UnitQuaternion::identity());
        // Session 2's keyframe 4 moves 0.2 m back onto voxel 1's key.
        let (moved, merged) = map.moved(|s, k| ((s, k) == (2, 4)).then_some(shift));
        assert_eq!((moved.len(), merged), (2, 1));
        let kept = moved.voxels.iter().find(|v| v.key == VoxelKey([5, 0, 0])).unwrap();
        assert_eq!(kept.voxel_id, 1);
        assert!(moved.voxels.iter().any(|v| v.voxel_id == 3 && v.xyz_m == [5.05, 5.05, 0.05]));
        // The spread turns with its owner: a quarter turn about z swaps x and y.
        let turn = Pose::from_parts(Translation3::identity(), UnitQuaternion::from_euler_angles(0.0, 0.0, FRAC_PI_2));
        let wide_x =
            MapVoxel { spread_m2: [4e-4, 0.0, 0.0, 1e-4, 0.0, 1e-6], ..voxel(9, [9.05, 0.05, 0.05], 1, (1, 9)) };
        let (turned, _) = LifelongMap::from_voxels(vec![wide_x], 0.2).0.moved(|_, _| Some(turn));
        let s = turned.voxels[0].spread_m2;
        assert!((s[0] - 1e-4).abs() < 1e-9 && (s[3] - 4e-4).abs() < 1e-9 && (s[5] - 1e-6).abs() < 1e-9, "{s:?}");
    }
}
