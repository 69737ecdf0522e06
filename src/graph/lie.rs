//! The SE(3) pieces the pose graph needs beyond `Exp`/`Log`: the adjoint and
//! the inverse right Jacobian, for tangent vectors `[ω; v]` (MATH.md §0).

use crate::geometry::Pose;
use crate::registration::se3::{hat, so3_right_jacobian};
use nalgebra::{Matrix3, Matrix6, Vector3, Vector6};

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
    use crate::registration::se3::{se3_exp, se3_log};
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
