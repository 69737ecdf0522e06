//! Voxel keys: `floor(p / voxel_size)` as three `i32` (MATH.md §0).

use nalgebra::Vector3;

/// Integer voxel coordinates of the voxel that contains a point.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct VoxelKey(pub [i32; 3]);

impl VoxelKey {
    /// The voxel containing `p_m` for a grid of `voxel_size_m`.
    pub fn of(p_m: &Vector3<f64>, voxel_size_m: f64) -> Self {
        let f = |v: f64| (v / voxel_size_m).floor() as i32;
        VoxelKey([f(p_m.x), f(p_m.y), f(p_m.z)])
    }

    /// The centre of the voxel, in metres.
    pub fn center_m(&self, voxel_size_m: f64) -> Vector3<f64> {
        Vector3::new(
            (self.0[0] as f64 + 0.5) * voxel_size_m,
            (self.0[1] as f64 + 0.5) * voxel_size_m,
            (self.0[2] as f64 + 0.5) * voxel_size_m,
        )
    }

    /// The keys within `r` voxels of this one on every axis (the 26-neighbourhood
    /// for `r = 1`), itself excluded, with their offsets, in key order (x,
    /// then y, then z).
    pub fn neighbours(self, r: i32) -> impl Iterator<Item = ([i32; 3], VoxelKey)> {
        let k = self.0;
        (-r..=r).flat_map(move |dx| {
            (-r..=r).flat_map(move |dy| {
                (-r..=r)
                    .filter(move |&dz| (dx, dy, dz) != (0, 0, 0))
                    .map(move |dz| ([dx, dy, dz], VoxelKey([k[0] + dx, k[1] + dy, k[2] + dz])))
            })
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn neighbours_exclude_the_key_and_come_in_key_order() {
        let n: Vec<VoxelKey> = VoxelKey([5, 0, -2]).neighbours(1).map(|(_, k)| k).collect();
        assert_eq!(n.len(), 26);
        assert!(!n.contains(&VoxelKey([5, 0, -2])));
        assert!(n.windows(2).all(|w| w[0] < w[1]));
        assert_eq!(n[0], VoxelKey([4, -1, -3]));
        assert_eq!(VoxelKey([0, 0, 0]).neighbours(2).count(), 124);
        assert_eq!(VoxelKey([0, 0, 0]).neighbours(0).count(), 0);
    }

    proptest! {
        #[test]
        fn centre_maps_back_to_its_key(x in -1e4f64..1e4, y in -1e4f64..1e4, z in -1e3f64..1e3, v in 0.05f64..2.0) {
            let k = VoxelKey::of(&Vector3::new(x, y, z), v);
            prop_assert_eq!(VoxelKey::of(&k.center_m(v), v), k);
            let c = k.center_m(v);
            prop_assert!((c.x - x).abs() <= v * 0.5 + 1e-9);
        }
    }

    #[test]
    fn negative_coordinates_floor_down() {
        assert_eq!(VoxelKey::of(&Vector3::new(-0.01, 0.0, 0.19), 0.2), VoxelKey([-1, 0, 0]));
    }
}
