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
    let mut out = Vec::with_capacity(points.len());
    transformed_into(points, t, &mut out);
    out
}

/// [`transformed`] into `out` (cleared first), so that a loop over scans can
/// reuse one buffer.
pub fn transformed_into(points: &[[f32; 3]], t: &Pose, out: &mut Vec<[f64; 3]>) {
    out.clear();
    // The rotation as a matrix once, not the quaternion's product per point
    // (a third of the instructions).
    let r = t.rotation.to_rotation_matrix().into_inner();
    let [r0, r1, r2] = [0, 1, 2].map(|i| [r[(i, 0)], r[(i, 1)], r[(i, 2)], t.translation.vector[i]]);
    let row = |r: &[f64; 4], x: f64, y: f64, z: f64| r[0] * x + r[1] * y + r[2] * z + r[3];
    out.extend(points.iter().map(|p| {
        let (x, y, z) = (f64::from(p[0]), f64::from(p[1]), f64::from(p[2]));
        [row(&r0, x, y, z), row(&r1, x, y, z), row(&r2, x, y, z)]
    }));
}

/// A symmetric 3×3 matrix kept as its upper triangle `[xx, xy, xz, yy, yz,
/// zz]`: direction matrices `M` and the spread (covariance) of a voxel's
/// points.
pub type Sym3 = [f32; 6];

/// The (row, column) of each entry of a [`Sym3`].
pub const SYM3_PAIRS: [(usize, usize); 6] = [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)];

/// The full matrix of an upper triangle `[xx, xy, xz, yy, yz, zz]` (a
/// [`Sym3`] in `f64`).
pub fn sym3_matrix(m: &[f64; 6]) -> nalgebra::Matrix3<f64> {
    let [xx, xy, xz, yy, yz, zz] = *m;
    nalgebra::Matrix3::new(xx, xy, xz, xy, yy, yz, xz, yz, zz)
}

/// The spread of a voxel's points where it is not known (cleaned maps and
/// lifelong maps written before seam kept it).
pub const UNKNOWN_SPREAD: Sym3 = [f32::NAN; 6];

/// The rotation of `t` as rows of a matrix.
pub fn rotation_rows(t: &Pose) -> [[f64; 3]; 3] {
    let r = t.rotation.to_rotation_matrix().into_inner();
    [0, 1, 2].map(|a| [0, 1, 2].map(|b| r[(a, b)]))
}

/// `R M Rᵀ` of a symmetric matrix.
pub fn rotate_sym(r: &[[f64; 3]; 3], m: &Sym3) -> Sym3 {
    let [xx, xy, xz, yy, yz, zz] = m.map(|v| v as f64);
    let full = [[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]];
    let mut rm = [[0.0; 3]; 3];
    for a in 0..3 {
        for b in 0..3 {
            rm[a][b] = (0..3).map(|k| r[a][k] * full[k][b]).sum();
        }
    }
    let e = |a: usize, b: usize| -> f32 { (0..3).map(|k| rm[a][k] * r[b][k]).sum::<f64>() as f32 };
    [e(0, 0), e(0, 1), e(0, 2), e(1, 1), e(1, 2), e(2, 2)]
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
