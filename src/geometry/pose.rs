//! SE(3) poses as `nalgebra::Isometry3<f64>` plus the text conversions the
//! pose files need (KITTI 3×4 rows, TUM quaternions) and the checks that
//! validation runs on them.

use nalgebra::{Isometry3, Matrix3, Quaternion, Rotation3, Translation3, UnitQuaternion};

/// A rigid transform `t_a_b` (rotation + translation), `f64`.
pub type Pose = Isometry3<f64>;

/// Largest `‖RᵀR − I‖_F` accepted for a rotation read from a file.
///
/// KITTI poses are printed with 6-9 significant digits, which leaves errors
/// around 1e-6; anything past 1e-3 is not a rotation (a scale, a shear, or a
/// column swapped), and orthonormalising it would silently hide a bad file.
pub const MAX_ORTHONORMALITY_ERROR: f64 = 1e-3;

/// `‖RᵀR − I‖_F` plus `|det R − 1|` of a 3×3 matrix: 0 for a rotation.
pub fn orthonormality_error(r: &Matrix3<f64>) -> f64 {
    (r.transpose() * r - Matrix3::identity()).norm() + (r.determinant() - 1.0).abs()
}

/// Builds a pose from 12 row-major numbers `r00 r01 r02 tx r10 .. tz`.
///
/// Returns `Err(error)` with the orthonormality error when the rotation part is
/// not a rotation (see [`MAX_ORTHONORMALITY_ERROR`]). The rotation is
/// re-orthonormalised (nearest rotation) so that printed round-off does not
/// accumulate through chains of poses.
pub fn pose_from_kitti_row(v: &[f64; 12]) -> Result<Pose, f64> {
    let r = Matrix3::new(v[0], v[1], v[2], v[4], v[5], v[6], v[8], v[9], v[10]);
    let err = orthonormality_error(&r);
    if !err.is_finite() || err > MAX_ORTHONORMALITY_ERROR {
        return Err(err);
    }
    Ok(Isometry3::from_parts(Translation3::new(v[3], v[7], v[11]), nearest_rotation(&r)))
}

/// The rotation nearest to `r` in the Frobenius norm (`U Vᵀ` of its SVD).
pub fn nearest_rotation(r: &Matrix3<f64>) -> UnitQuaternion<f64> {
    let svd = r.svd(true, true);
    match (svd.u, svd.v_t) {
        (Some(u), Some(v_t)) => {
            let mut d = Matrix3::identity();
            d[(2, 2)] = (u * v_t).determinant().signum();
            UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(u * d * v_t))
        }
        _ => UnitQuaternion::from_matrix(r),
    }
}

/// The 12 row-major numbers of a pose, as KITTI's `poses.txt` stores them.
pub fn pose_to_kitti_row(p: &Pose) -> [f64; 12] {
    let r = p.rotation.to_rotation_matrix();
    let m = r.matrix();
    let t = p.translation.vector;
    [m[(0, 0)], m[(0, 1)], m[(0, 2)], t.x, m[(1, 0)], m[(1, 1)], m[(1, 2)], t.y, m[(2, 0)], m[(2, 1)], m[(2, 2)], t.z]
}

/// Builds a pose from TUM's `x y z qx qy qz qw`.
///
/// Returns `Err(norm)` when the quaternion's norm is not within 1e-3 of 1.
pub fn pose_from_tum(t: [f64; 3], q_xyzw: [f64; 4]) -> Result<Pose, f64> {
    let q = Quaternion::new(q_xyzw[3], q_xyzw[0], q_xyzw[1], q_xyzw[2]);
    let n = q.norm();
    if !n.is_finite() || (n - 1.0).abs() > MAX_ORTHONORMALITY_ERROR {
        return Err(n);
    }
    Ok(Isometry3::from_parts(Translation3::new(t[0], t[1], t[2]), UnitQuaternion::from_quaternion(q)))
}

/// `[qx, qy, qz, qw]` of a pose's rotation, with `qw ≥ 0`.
pub fn pose_to_tum_quat(p: &Pose) -> [f64; 4] {
    let q = p.rotation.quaternion();
    let s = if q.w < 0.0 { -1.0 } else { 1.0 };
    [s * q.i, s * q.j, s * q.k, s * q.w]
}

/// True when every number of the pose is finite.
pub fn is_finite_pose(p: &Pose) -> bool {
    p.translation.vector.iter().all(|v| v.is_finite()) && p.rotation.coords.iter().all(|v| v.is_finite())
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    #[test]
    fn kitti_row_round_trip() {
        let p = Isometry3::new(Vector3::new(1.0, -2.0, 3.5), Vector3::new(0.1, -0.4, 2.0));
        let back = pose_from_kitti_row(&pose_to_kitti_row(&p)).unwrap();
        assert!((back.to_homogeneous() - p.to_homogeneous()).norm() < 1e-12);
    }

    #[test]
    fn scaled_rotation_is_rejected() {
        let mut row = pose_to_kitti_row(&Pose::identity());
        row[0] = 1.1;
        let err = pose_from_kitti_row(&row).unwrap_err();
        assert!(err > 0.09, "{err}");
    }

    #[test]
    fn tum_round_trip_and_bad_norm() {
        let p = Isometry3::new(Vector3::new(4.0, 5.0, 6.0), Vector3::new(-0.3, 0.2, 0.1));
        let q = pose_to_tum_quat(&p);
        let t = p.translation.vector;
        let back = pose_from_tum([t.x, t.y, t.z], q).unwrap();
        assert!((back.to_homogeneous() - p.to_homogeneous()).norm() < 1e-12);
        assert!(pose_from_tum([0.0; 3], [0.0, 0.0, 0.0, 2.0]).is_err());
    }
}
