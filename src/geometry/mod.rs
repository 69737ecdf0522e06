//! Geometry: poses, point clouds and voxel keys. No I/O lives here.
//!
//! Conventions (MATH.md §0): poses are `SE(3)` in `f64`, named by their
//! frames (`t_world_submap * t_submap_keyframe == t_world_keyframe`); a point
//! in frame b moves to frame a by `t_a_b * p_b`. Points themselves are stored
//! as `f32` in the sensor frame, because that is what sensors deliver and what
//! halves the memory of a multi-million point session.

pub mod polygon;
mod pose;
pub mod se3;
mod voxel;

pub use pose::{
    MAX_ORTHONORMALITY_ERROR, Pose, is_finite_pose, nearest_rotation, orthonormality_error, pose_from_kitti_row,
    pose_from_tum, pose_to_kitti_row, pose_to_tum_quat,
};
pub use voxel::VoxelKey;

/// `t * p` for every (f32) point, in `f64`: a scan moved into another frame.
pub fn transformed(points: &[[f32; 3]], t: &Pose) -> Vec<[f64; 3]> {
    points.iter().map(|p| (t * nalgebra::Point3::new(p[0] as f64, p[1] as f64, p[2] as f64)).into()).collect()
}

/// A single LiDAR scan in its sensor frame.
///
/// `intensity` is either empty (the format had none) or as long as `points`.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Scan {
    pub points: Vec<[f32; 3]>,
    pub intensity: Vec<f32>,
}

impl Scan {
    pub fn len(&self) -> usize {
        self.points.len()
    }
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }
}
