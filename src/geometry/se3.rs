//! SE(3) and SO(3) on tangent vectors `[ω; v]` (rotation first, right
//! perturbation `X ← X · Exp(δ)`, MATH.md §0): `hat`, `Exp`/`Log` of SO(3)
//! and SE(3), the right Jacobian of SO(3) with its inverse, the adjoint and
//! the inverse right Jacobian of SE(3). GICP, global registration and the
//! pose graph all use these; nalgebra has the groups but not these maps in
//! the `[ω; v]`, right-perturbation convention.

use crate::geometry::Pose;
use nalgebra::{Matrix3, Matrix6, Translation3, UnitQuaternion, Vector3, Vector6};

/// Below this angle the series expansions replace the closed forms, whose
/// `sin θ / θ`-like ratios lose precision near 0.
const SMALL_ANGLE_RAD: f64 = 1e-6;

/// `[w]×`: the skew-symmetric matrix with `[w]× p = w × p`.
pub fn hat(w: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -w.z, w.y, w.z, 0.0, -w.x, -w.y, w.x, 0.0)
}

/// SO(3) exponential of a rotation vector.
pub fn so3_exp(w: &Vector3<f64>) -> UnitQuaternion<f64> {
    UnitQuaternion::from_scaled_axis(*w)
}

/// SO(3) logarithm: the rotation vector with angle in `[0, π]`.
pub fn so3_log(q: &UnitQuaternion<f64>) -> Vector3<f64> {
    q.scaled_axis()
}

/// `V(ω)`, the left Jacobian of SO(3): `Exp([ω; v])` has translation `V(ω) v`.
fn so3_left_jacobian(w: &Vector3<f64>) -> Matrix3<f64> {
    let theta = w.norm();
    let wx = hat(w);
    if theta < SMALL_ANGLE_RAD {
        return Matrix3::identity() + 0.5 * wx + wx * wx / 6.0;
    }
    let t2 = theta * theta;
    Matrix3::identity() + (1.0 - theta.cos()) / t2 * wx + (theta - theta.sin()) / (t2 * theta) * wx * wx
}

/// `J_r(ω)`, the right Jacobian of SO(3): `Exp(ω + δ) ≈ Exp(ω) Exp(J_r(ω) δ)`.
pub fn so3_right_jacobian(w: &Vector3<f64>) -> Matrix3<f64> {
    so3_left_jacobian(&-w)
}

/// `J_r(ω)⁻¹`, closed form: `Log(Exp(ω) Exp(δ)) ≈ ω + J_r(ω)⁻¹ δ`.
pub fn so3_right_jacobian_inv(w: &Vector3<f64>) -> Matrix3<f64> {
    let theta = w.norm();
    let wx = hat(w);
    if theta < SMALL_ANGLE_RAD {
        return Matrix3::identity() + 0.5 * wx + wx * wx / 12.0;
    }
    let coef = 1.0 / (theta * theta) - (1.0 + theta.cos()) / (2.0 * theta * theta.sin());
    Matrix3::identity() + 0.5 * wx + coef * wx * wx
}

/// SE(3) exponential of `[ω; v]`.
pub fn se3_exp(xi: &Vector6<f64>) -> Pose {
    let w = xi.fixed_rows::<3>(0).into_owned();
    let v = xi.fixed_rows::<3>(3).into_owned();
    Pose::from_parts(Translation3::from(so3_left_jacobian(&w) * v), so3_exp(&w))
}

/// SE(3) logarithm `[ω; v]` with `|ω| ≤ π`; the inverse of [`se3_exp`].
pub fn se3_log(t: &Pose) -> Vector6<f64> {
    let w = so3_log(&t.rotation);
    let v = so3_left_jacobian(&w).try_inverse().unwrap_or_else(Matrix3::identity) * t.translation.vector;
    Vector6::new(w.x, w.y, w.z, v.x, v.y, v.z)
}

/// Rotation angle of a pose, in radians (`|Log(R)|`).
pub fn rotation_angle_rad(t: &Pose) -> f64 {
    t.rotation.angle()
}

/// `Ad(T)` for `[ω; v]`: `T · Exp(δ) = Exp(Ad(T) δ) · T`.
pub fn adjoint(t: &Pose) -> Matrix6<f64> {
    let r = t.rotation.to_rotation_matrix().into_inner();
    let tx = hat(&t.translation.vector);
    let mut ad = Matrix6::zeros();
    ad.fixed_view_mut::<3, 3>(0, 0).copy_from(&r);
    ad.fixed_view_mut::<3, 3>(3, 0).copy_from(&(tx * r));
    ad.fixed_view_mut::<3, 3>(3, 3).copy_from(&r);
    ad
}

/// Barfoot's `Q(ρ, φ)`: the off-diagonal block of the SE(3) left Jacobian.
fn q_block(rho: &Vector3<f64>, phi: &Vector3<f64>) -> Matrix3<f64> {
    let th = phi.norm();
    let (px, rx) = (hat(phi), hat(rho));
    let (pr, rp, prp) = (px * rx, rx * px, px * rx * px);
    if th < 1e-5 {
        // Series limits of the coefficients below as θ → 0.
        return 0.5 * rx + (pr + rp + prp) / 6.0 - (px * px * rx + rx * px * px - 3.0 * prp) / 24.0;
    }
    let (s, c) = (th.sin(), th.cos());
    let (t2, t3) = (th * th, th * th * th);
    0.5 * rx
        + (th - s) / t3 * (pr + rp + prp)
        + (t2 + 2.0 * c - 2.0) / (2.0 * t2 * t2) * (px * px * rx + rx * px * px - 3.0 * prp)
        + (2.0 * th - 3.0 * s + th * c) / (2.0 * t2 * t3) * (prp * px + px * prp)
}

/// `J_r(ξ)⁻¹` of SE(3): `Log(Exp(ξ) Exp(δ)) ≈ ξ + J_r(ξ)⁻¹ δ`.
pub fn se3_right_jacobian_inv(xi: &Vector6<f64>) -> Matrix6<f64> {
    // J_r(ξ) = J_l(−ξ) = [[J, 0], [Q, J]] with J = J_l,SO3(−ω) = J_r,SO3(ω).
    let w = Vector3::new(xi[0], xi[1], xi[2]);
    let v = Vector3::new(xi[3], xi[4], xi[5]);
    let j = so3_right_jacobian(&w);
    let j_inv = j.try_inverse().unwrap_or_else(Matrix3::identity);
    let q = q_block(&-v, &-w);
    let mut out = Matrix6::zeros();
    out.fixed_view_mut::<3, 3>(0, 0).copy_from(&j_inv);
    out.fixed_view_mut::<3, 3>(3, 3).copy_from(&j_inv);
    out.fixed_view_mut::<3, 3>(3, 0).copy_from(&(-j_inv * q * j_inv));
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn vec6(a: [f64; 6]) -> Vector6<f64> {
        Vector6::from_row_slice(&a)
    }

    proptest! {
        #[test]
        fn se3_exp_log_round_trip(w in prop::array::uniform3(-1.8f64..1.8), v in prop::array::uniform3(-50f64..50.0)) {
            let xi = vec6([w[0], w[1], w[2], v[0], v[1], v[2]]);
            let back = se3_log(&se3_exp(&xi));
            prop_assert!((back - xi).norm() < 1e-9, "{xi} -> {back}");
        }

        #[test]
        fn se3_log_exp_round_trip(w in prop::array::uniform3(-1.8f64..1.8), t in prop::array::uniform3(-50f64..50.0)) {
            let pose = Pose::from_parts(Translation3::new(t[0], t[1], t[2]), so3_exp(&Vector3::from(w)));
            let back = se3_exp(&se3_log(&pose));
            prop_assert!((back.to_homogeneous() - pose.to_homogeneous()).norm() < 1e-9);
        }

        #[test]
        fn tiny_angles_round_trip(w in prop::array::uniform3(-1e-7f64..1e-7), v in prop::array::uniform3(-5f64..5.0)) {
            let xi = vec6([w[0], w[1], w[2], v[0], v[1], v[2]]);
            prop_assert!((se3_log(&se3_exp(&xi)) - xi).norm() < 1e-12);
        }

        #[test]
        fn right_jacobian_matches_central_differences(w in prop::array::uniform3(-2.0f64..2.0)) {
            let w = Vector3::from(w);
            let jr = so3_right_jacobian(&w);
            let h = 1e-6;
            // Column k of J_r: Log(Exp(ω)⁻¹ Exp(ω + h e_k)) / h, by central differences.
            let mut num = Matrix3::zeros();
            for k in 0..3 {
                let mut e = Vector3::zeros();
                e[k] = h;
                let plus = so3_log(&(so3_exp(&w).inverse() * so3_exp(&(w + e))));
                let minus = so3_log(&(so3_exp(&w).inverse() * so3_exp(&(w - e))));
                num.set_column(k, &((plus - minus) / (2.0 * h)));
            }
            prop_assert!((num - jr).norm() < 1e-6, "{num} vs {jr}");
            prop_assert!((so3_right_jacobian_inv(&w) * jr - Matrix3::identity()).norm() < 1e-9);
        }
    }

    #[test]
    fn hat_is_cross_product() {
        let w = Vector3::new(0.3, -1.2, 2.0);
        let p = Vector3::new(-4.0, 0.5, 1.5);
        assert!((hat(&w) * p - w.cross(&p)).norm() < 1e-15);
    }

    #[test]
    fn exp_is_rotation_first() {
        let t = se3_exp(&vec6([0.0, 0.0, std::f64::consts::FRAC_PI_2, 0.0, 0.0, 0.0]));
        let p = t * nalgebra::Point3::new(1.0, 0.0, 0.0);
        assert!((p.coords - Vector3::new(0.0, 1.0, 0.0)).norm() < 1e-12);
        let t = se3_exp(&vec6([0.0, 0.0, 0.0, 1.0, 2.0, 3.0]));
        assert!((t.translation.vector - Vector3::new(1.0, 2.0, 3.0)).norm() < 1e-15);
    }
}

#[cfg(test)]
mod adjoint_tests {
    use super::*;
    use crate::geometry::se3::{se3_exp, se3_log};
    use proptest::prelude::*;

    fn xi(a: [f64; 6]) -> Vector6<f64> {
        Vector6::from_row_slice(&a)
    }

    proptest! {
        #[test]
        fn right_jacobian_inverse_matches_finite_differences(
            a in proptest::array::uniform6(-1.2f64..1.2), k in 0usize..6
        ) {
            let x = xi(a);
            let jinv = se3_right_jacobian_inv(&x);
            let h = 1e-6;
            let mut d = Vector6::zeros();
            d[k] = h;
            let plus = se3_log(&(se3_exp(&x) * se3_exp(&d)));
            let minus = se3_log(&(se3_exp(&x) * se3_exp(&-d)));
            let numeric = (plus - minus) / (2.0 * h);
            let analytic = jinv.column(k).into_owned();
            prop_assert!((numeric - analytic).norm() < 1e-5, "{numeric} vs {analytic}");
        }

        #[test]
        fn adjoint_moves_perturbations_across(a in proptest::array::uniform6(-2.0f64..2.0), b in proptest::array::uniform6(-0.5f64..0.5)) {
            let t = se3_exp(&xi(a));
            let d = xi(b);
            let lhs = t * se3_exp(&d);
            let rhs = se3_exp(&(adjoint(&t) * d)) * t;
            prop_assert!((lhs.to_homogeneous() - rhs.to_homogeneous()).norm() < 1e-9);
        }
    }

    #[test]
    fn small_angle_branch_is_continuous() {
        let just_above = xi([1.2e-5, 0.0, 0.0, 0.5, -1.0, 2.0]);
        let just_below = xi([0.9e-5, 0.0, 0.0, 0.5, -1.0, 2.0]);
        assert!((se3_right_jacobian_inv(&just_above) - se3_right_jacobian_inv(&just_below)).norm() < 1e-4);
    }
}
