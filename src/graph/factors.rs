//! Residuals and analytic Jacobians of the anchored between factor (eq. 2-3)
//! and of the anchor prior (MATH.md §5).

use crate::geometry::Pose;
use crate::geometry::se3::se3_log;
use crate::geometry::se3::{adjoint, se3_right_jacobian_inv};
use nalgebra::{Matrix6, Vector6};

/// `∂r/∂` each of the four variables of an anchored between factor.
#[derive(Debug, Clone, PartialEq)]
pub struct BetweenJacobians {
    pub d_anchor_i: Matrix6<f64>,
    pub d_local_i: Matrix6<f64>,
    pub d_anchor_j: Matrix6<f64>,
    pub d_local_j: Matrix6<f64>,
}

/// `r = Log(Z⁻¹ h)` with `h = (A_a p_i)⁻¹ (A_b p_j)`, and its Jacobians for
/// right perturbations of `A_a, p_i, A_b, p_j`:
/// `∂r/∂p_i = −J·Ad(h⁻¹)`, `∂r/∂A_a = −J·Ad(h⁻¹)·Ad(p_i⁻¹)`,
/// `∂r/∂p_j = J`, `∂r/∂A_b = J·Ad(p_j⁻¹)`, with `J = J_r⁻¹(r)`.
/// When `a == b` the two anchor blocks cancel; callers may skip them.
pub fn between_residual_and_jacobians(
    z: &Pose,
    anchor_i: &Pose,
    local_i: &Pose,
    anchor_j: &Pose,
    local_j: &Pose,
) -> (Vector6<f64>, BetweenJacobians) {
    let h = (anchor_i * local_i).inverse() * (anchor_j * local_j);
    let r = se3_log(&(z.inverse() * h));
    let j = se3_right_jacobian_inv(&r);
    let j_ad_h_inv = j * adjoint(&h.inverse());
    let jac = BetweenJacobians {
        d_anchor_i: -j_ad_h_inv * adjoint(&local_i.inverse()),
        d_local_i: -j_ad_h_inv,
        d_anchor_j: j * adjoint(&local_j.inverse()),
        d_local_j: j,
    };
    (r, jac)
}

/// `r = Log(Z⁻¹ X)` and `∂r/∂X = J_r⁻¹(r)`.
pub fn prior_residual_and_jacobian(z: &Pose, x: &Pose) -> (Vector6<f64>, Matrix6<f64>) {
    let r = se3_log(&(z.inverse() * x));
    (r, se3_right_jacobian_inv(&r))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::se3::se3_exp;
    use proptest::prelude::*;

    fn pose(a: [f64; 6]) -> Pose {
        se3_exp(&Vector6::from_row_slice(&a))
    }

    fn numeric(f: impl Fn(&Vector6<f64>) -> Vector6<f64>) -> Matrix6<f64> {
        let h = 1e-6;
        let mut m = Matrix6::zeros();
        for k in 0..6 {
            let mut d = Vector6::zeros();
            d[k] = h;
            m.set_column(k, &((f(&d) - f(&-d)) / (2.0 * h)));
        }
        m
    }

    proptest! {
        #[test]
        fn jacobians_match_central_differences(
            a in proptest::array::uniform6(-1.0f64..1.0), pi in proptest::array::uniform6(-1.0f64..1.0),
            b in proptest::array::uniform6(-1.0f64..1.0), pj in proptest::array::uniform6(-1.0f64..1.0),
            noise in proptest::array::uniform6(-0.3f64..0.3),
        ) {
            let (ai, li, aj, lj) = (pose(a), pose(pi), pose(b), pose(pj));
            let h = (ai * li).inverse() * (aj * lj);
            let z = h * pose(noise);
            let (_, jac) = between_residual_and_jacobians(&z, &ai, &li, &aj, &lj);
            let r = |ai: &Pose, li: &Pose, aj: &Pose, lj: &Pose| between_residual_and_jacobians(&z, ai, li, aj, lj).0;
            let e = |d: &Vector6<f64>| se3_exp(d);
            let checks = [
                (jac.d_anchor_i, numeric(|d| r(&(ai * e(d)), &li, &aj, &lj))),
                (jac.d_local_i, numeric(|d| r(&ai, &(li * e(d)), &aj, &lj))),
                (jac.d_anchor_j, numeric(|d| r(&ai, &li, &(aj * e(d)), &lj))),
                (jac.d_local_j, numeric(|d| r(&ai, &li, &aj, &(lj * e(d))))),
            ];
            for (k, (analytic, num)) in checks.iter().enumerate() {
                prop_assert!((analytic - num).norm() < 1e-5, "block {k}: {analytic} vs {num}");
            }
        }

        #[test]
        fn same_anchor_blocks_cancel(a in proptest::array::uniform6(-1.0f64..1.0), pi in proptest::array::uniform6(-1.0f64..1.0), pj in proptest::array::uniform6(-1.0f64..1.0)) {
            let (am, li, lj) = (pose(a), pose(pi), pose(pj));
            let (_, jac) = between_residual_and_jacobians(&Pose::identity(), &am, &li, &am, &lj);
            prop_assert!((jac.d_anchor_i + jac.d_anchor_j).norm() < 1e-9);
        }
    }

    #[test]
    fn prior_jacobian_matches_central_differences() {
        let z = pose([0.1, -0.2, 0.3, 1.0, 2.0, 3.0]);
        let x = pose([0.4, 0.1, -0.3, -1.0, 0.5, 2.0]);
        let (_, j) = prior_residual_and_jacobian(&z, &x);
        let n = numeric(|d| prior_residual_and_jacobian(&z, &(x * se3_exp(d))).0);
        assert!((j - n).norm() < 1e-5);
    }
}
