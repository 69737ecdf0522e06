//! Alignment metrics (MATH.md §9): Umeyama SE(3) fits, ATE, and the
//! per-session rigid-alignment residual of the paper's Table II.
//!
//! - **ATE** of a session: one Umeyama SE(3) fit of the estimated keyframe
//!   positions of *all* sessions onto the true ones (the world frames differ
//!   by a rigid motion only), then the RMSE of that session's position errors.
//! - **Rigid residual** of a session: the RMSE after fitting that session's
//!   estimate onto its truth with its own SE(3). It is what no single rigid
//!   motion of the session can remove — the drift left inside it. Session
//!   anchors cannot remove drift, submap anchors can (paper Table II).

use crate::geometry::Pose;
use nalgebra::{Matrix3, Translation3, UnitQuaternion, Vector3};

/// The rigid motion `T` minimising `Σ |T·src_i − dst_i|²` (Umeyama 1991,
/// no scale). Fewer than 3 points, or all coincident, give what the points
/// determine (identity rotation when nothing does).
pub fn umeyama(src: &[Vector3<f64>], dst: &[Vector3<f64>]) -> Pose {
    let n = src.len().min(dst.len());
    if n == 0 {
        return Pose::identity();
    }
    let mean = |v: &[Vector3<f64>]| v[..n].iter().sum::<Vector3<f64>>() / n as f64;
    let (ms, md) = (mean(src), mean(dst));
    let mut cov = Matrix3::zeros();
    for i in 0..n {
        cov += (dst[i] - md) * (src[i] - ms).transpose();
    }
    cov /= n as f64;
    let svd = cov.svd(true, true);
    let (Some(u), Some(vt)) = (svd.u, svd.v_t) else {
        return Pose::from_parts(Translation3::from(md - ms), UnitQuaternion::identity());
    };
    // A reflection is turned into a rotation by flipping the direction of
    // the smallest singular value (nalgebra does not sort them).
    let mut s = Matrix3::identity();
    if (u * vt).determinant() < 0.0 {
        let smallest = svd.singular_values.imin();
        s[(smallest, smallest)] = -1.0;
    }
    let r = u * s * vt;
    let rot = UnitQuaternion::from_matrix(&r);
    let t = md - rot * ms;
    Pose::from_parts(Translation3::from(t), rot)
}

/// Root mean square of `|T·src_i − dst_i|` and the largest of them.
pub fn rmse_after(t: &Pose, src: &[Vector3<f64>], dst: &[Vector3<f64>]) -> (f64, f64) {
    let n = src.len().min(dst.len());
    if n == 0 {
        return (0.0, 0.0);
    }
    let mut sum = 0.0;
    let mut max: f64 = 0.0;
    for i in 0..n {
        let e = (t.transform_vector(&src[i]) + t.translation.vector - dst[i]).norm();
        sum += e * e;
        max = max.max(e);
    }
    ((sum / n as f64).sqrt(), max)
}

/// RMSE left after the best rigid fit of `estimated` onto `truth`: what no
/// single rigid motion of the trajectory can remove.
pub fn rigid_residual(estimated: &[Vector3<f64>], truth: &[Vector3<f64>]) -> f64 {
    rmse_after(&umeyama(estimated, truth), estimated, truth).0
}

/// One session's numbers.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct SessionAlignment {
    pub session: usize,
    pub keyframes: usize,
    pub ate_rmse_m: f64,
    pub ate_max_m: f64,
    pub rigid_residual_m: f64,
}

/// ATE and rigid residual per session, from estimated and true positions
/// (same sessions, same keyframes, in order). Sessions numbered from 1.
pub fn evaluate(estimated: &[Vec<Vector3<f64>>], truth: &[Vec<Vector3<f64>>]) -> Vec<SessionAlignment> {
    let all_est: Vec<Vector3<f64>> = estimated.iter().flatten().copied().collect();
    let all_true: Vec<Vector3<f64>> = truth.iter().flatten().copied().collect();
    let joint = umeyama(&all_est, &all_true);
    estimated
        .iter()
        .zip(truth)
        .enumerate()
        .map(|(i, (e, t))| {
            let (ate, ate_max) = rmse_after(&joint, e, t);
            SessionAlignment {
                session: i + 1,
                keyframes: e.len(),
                ate_rmse_m: ate,
                ate_max_m: ate_max,
                rigid_residual_m: rigid_residual(e, t),
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    #[test]
    fn umeyama_recovers_a_rigid_motion() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(4);
        let src: Vec<Vector3<f64>> = (0..50)
            .map(|_| {
                Vector3::new(rng.random_range(-20.0..20.0), rng.random_range(-20.0..20.0), rng.random_range(-2.0..2.0))
            })
            .collect();
        let t = Pose::from_parts(Translation3::new(3.0, -7.0, 0.5), UnitQuaternion::from_euler_angles(0.1, -0.05, 2.5));
        let dst: Vec<Vector3<f64>> = src.iter().map(|p| t.transform_vector(p) + t.translation.vector).collect();
        let est = umeyama(&src, &dst);
        assert!((est.translation.vector - t.translation.vector).norm() < 1e-9);
        assert!(est.rotation.angle_to(&t.rotation) < 1e-9);
        assert!(rmse_after(&est, &src, &dst).0 < 1e-9);
    }

    #[test]
    fn a_reflection_is_never_returned() {
        // Points on a line admit a reflection as the best orthogonal fit.
        let src: Vec<Vector3<f64>> = (0..10).map(|i| Vector3::new(i as f64, 0.0, 0.0)).collect();
        let dst: Vec<Vector3<f64>> = (0..10).map(|i| Vector3::new(-(i as f64), 0.0, 0.0)).collect();
        let est = umeyama(&src, &dst);
        assert!((est.rotation.to_rotation_matrix().matrix().determinant() - 1.0).abs() < 1e-9);
        assert!(rmse_after(&est, &src, &dst).0 < 1e-9);
    }

    /// A rigidly moved session has zero residual; a bent one keeps its bend
    /// in the residual whatever rigid motion it is given.
    #[test]
    fn ate_sees_placement_and_residual_sees_only_bending() {
        let line: Vec<Vector3<f64>> =
            (0..40).map(|i| Vector3::new(i as f64, (i as f64 * 0.3).sin() * 5.0, 0.0)).collect();
        let shifted: Vec<Vector3<f64>> = line.iter().map(|p| p + Vector3::new(1.0, 0.0, 0.0)).collect();
        let bent: Vec<Vector3<f64>> = line.iter().map(|p| p + Vector3::new(0.0, 0.0, 0.002 * p.x * p.x)).collect();
        let r = evaluate(&[line.clone(), shifted, bent], &[line.clone(), line.clone(), line.clone()]);
        assert!(r[1].rigid_residual_m < 1e-9);
        assert!(r[1].ate_rmse_m > 0.5, "a session 1 m off the others has ATE {}", r[1].ate_rmse_m);
        assert!(r[2].rigid_residual_m > 0.2, "bending hidden: {}", r[2].rigid_residual_m);
        assert!(r[0].ate_rmse_m < r[1].ate_rmse_m);
    }
}
