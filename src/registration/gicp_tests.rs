//! GICP against its own maths (Jacobian, gradient by central differences) and
//! on a synthetic scene with a known transform. Real-data tests live in
//! `tests/registration_real.rs`.

use super::*;
use crate::geometry::se3::hat;
use crate::geometry::se3::se3_log;
use nalgebra::Matrix3x6;
use rand::{Rng, SeedableRng};

/// A box-shaped room with a slanted ramp and a pillar: planes in enough
/// directions to pin all six degrees of freedom. Noise 1 cm.
fn room(n: usize, seed: u64) -> Vec<[f32; 3]> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut out = Vec::with_capacity(n);
    while out.len() < n {
        let (u, v): (f64, f64) = (rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0));
        let p = match rng.random_range(0..7) {
            0 => [12.0 * u, 9.0 * v, 0.0],       // floor
            1 => [12.0, 9.0 * u, 1.5 + 1.5 * v], // walls
            2 => [-12.0, 9.0 * u, 1.5 + 1.5 * v],
            3 => [12.0 * u, 9.0, 1.5 + 1.5 * v],
            4 => [12.0 * u, -9.0, 1.5 + 1.5 * v],
            5 => [3.0 + 2.0 * u, -2.0 + 2.0 * v, 0.5 + 0.4 * (u + v)], // ramp
            _ => {
                let a = std::f64::consts::PI * u;
                [-4.0 + 0.6 * a.cos(), 3.0 + 0.6 * a.sin(), 1.5 + 1.5 * v] // pillar
            }
        };
        let noise = |rng: &mut rand_chacha::ChaCha8Rng| rng.random_range(-0.01..0.01);
        out.push([(p[0] + noise(&mut rng)) as f32, (p[1] + noise(&mut rng)) as f32, (p[2] + noise(&mut rng)) as f32]);
    }
    out
}

fn transform(t: &Pose, pts: &[[f32; 3]]) -> Vec<[f32; 3]> {
    pts.iter()
        .map(|p| {
            let q = t * nalgebra::Point3::new(p[0] as f64, p[1] as f64, p[2] as f64);
            [q.x as f32, q.y as f32, q.z as f32]
        })
        .collect()
}

fn cfg() -> GicpConfig {
    GicpConfig { voxel_size_m: 0.3, ..GicpConfig::default() }
}

/// A known `t_target_source` and the two clouds, sampled independently.
fn scene() -> (PreparedCloud, PreparedCloud, Pose) {
    let t_target_source = Pose::new(Vector3::new(0.4, -0.3, 0.05), Vector3::new(0.01, -0.02, 0.12));
    let target = preprocess(&room(30_000, 1), &cfg());
    // Source points are room points expressed in the source frame.
    let source = preprocess(&transform(&t_target_source.inverse(), &room(30_000, 2)), &cfg());
    (target, source, t_target_source)
}

#[test]
fn residual_jacobian_matches_central_differences() {
    let t = Pose::new(Vector3::new(1.0, -2.0, 0.5), Vector3::new(0.3, -0.2, 0.9));
    let a = Vector3::new(3.0, -1.0, 2.0);
    let b = Vector3::new(0.5, 0.2, -0.1);
    let r = t.rotation.to_rotation_matrix().into_inner();
    let residual = |d: &Vector6<f64>| b - (t * se3_exp(d)).transform_point(&a.into()).coords;
    let mut analytic = Matrix3x6::zeros();
    analytic.fixed_view_mut::<3, 3>(0, 0).copy_from(&(r * hat(&a)));
    analytic.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-r));
    let h = 1e-6;
    for k in 0..6 {
        let mut d = Vector6::zeros();
        d[k] = h;
        let numeric = (residual(&d) - residual(&-d)) / (2.0 * h);
        assert!((numeric - analytic.column(k)).norm() < 1e-7, "column {k}: {numeric} vs {}", analytic.column(k));
    }
}

#[test]
fn gradient_matches_central_differences_of_the_cost() {
    let (target, source, t_target_source) = scene();
    let t = t_target_source * se3_exp(&Vector6::new(0.01, -0.02, 0.015, 0.1, -0.05, 0.02));
    let mut corr = vec![Correspondence::NONE; source.len()];
    let sys = linearize(&target, &source, &mut corr, &t, 1.0, false);
    assert!(sys.inliers > 1000);
    assert!((total_error(&target, &source, &corr, &t, &t, false) - sys.error).abs() < 1e-9 * sys.error);
    let h = 1e-6;
    for k in 0..6 {
        let mut d = Vector6::zeros();
        d[k] = h;
        let plus = total_error(&target, &source, &corr, &t, &(t * se3_exp(&d)), false);
        let minus = total_error(&target, &source, &corr, &t, &(t * se3_exp(&-d)), false);
        let numeric = (plus - minus) / (2.0 * h);
        assert!((numeric - sys.b[k]).abs() < 1e-4 * sys.b.norm(), "d/dδ{k}: {numeric} vs {}", sys.b[k]);
    }
    // H is symmetric positive definite on a well-constrained scene.
    assert!((sys.h - sys.h.transpose()).norm() < 1e-9 * sys.h.norm());
    assert!(sys.h.cholesky().is_some());
}

#[test]
fn hessian_equals_the_plain_jacobian_product() {
    // linearize_slice builds Jᵀ M J from cross products; rebuild it here the
    // slow way, with J = [R [a]×, −R] and M = (C_j + R C_i Rᵀ)⁻¹.
    let (target, source, t_target_source) = scene();
    let t = t_target_source * se3_exp(&Vector6::new(0.02, 0.01, -0.03, 0.2, 0.1, -0.05));
    let mut corr = vec![Correspondence::NONE; source.len()];
    let sys = linearize(&target, &source, &mut corr, &t, 1.0, false);
    let r = t.rotation.to_rotation_matrix().into_inner();
    let (mut h, mut b, mut e) = (Matrix6::zeros(), Vector6::zeros(), 0.0);
    for (i, c) in corr.iter().enumerate().filter(|(_, c)| c.target != NO_MATCH) {
        let a = Vector3::from(source.points()[i]);
        let j = c.target as usize;
        let m = (target.covariances()[j] + r * source.covariances()[i] * r.transpose()).try_inverse().unwrap();
        let res = Vector3::from(target.points()[j]) - t.transform_point(&a.into()).coords;
        let mut jac = Matrix3x6::zeros();
        jac.fixed_view_mut::<3, 3>(0, 0).copy_from(&(r * hat(&a)));
        jac.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-r));
        h += jac.transpose() * m * jac;
        b += jac.transpose() * m * res;
        e += 0.5 * res.dot(&(m * res));
    }
    assert!((sys.h - h).norm() < 1e-9 * h.norm(), "{}", (sys.h - h).norm() / h.norm());
    assert!((sys.b - b).norm() < 1e-9 * b.norm());
    assert!((sys.error - e).abs() < 1e-9 * e);
}

#[test]
fn recovers_a_known_transform_from_the_identity() {
    let (target, source, t_target_source) = scene();
    for parallel in [true, false] {
        let c = GicpConfig { parallel, ..cfg() };
        let res = align(&target, &source, &Pose::identity(), &c);
        let err = se3_log(&(t_target_source.inverse() * res.t_target_source));
        assert!(res.converged, "{res:?}");
        assert!(err.fixed_rows::<3>(3).norm() < 5e-3, "translation error {}", err.fixed_rows::<3>(3).norm());
        assert!(
            err.fixed_rows::<3>(0).norm() < 0.05f64.to_radians(),
            "rotation error {}",
            err.fixed_rows::<3>(0).norm()
        );
        // Independent samplings sit ~half a voxel apart within the planes.
        assert!(res.inlier_ratio > 0.9 && res.fitness < 0.05, "{} {}", res.inlier_ratio, res.fitness);
        assert_eq!(res.corresponded_source.len(), res.num_inliers);
        assert_eq!(res.source_points.len(), source.len());
        // The Hessian is the information of all six directions.
        let eig = res.hessian.symmetric_eigenvalues();
        assert!(eig.min() > 0.0, "{eig}");
    }
}

#[test]
fn empty_and_tiny_inputs_do_not_panic() {
    let c = cfg();
    let empty = preprocess::<[f32; 3]>(&[], &c);
    let (target, _, _) = scene();
    let res = align(&target, &empty, &Pose::identity(), &c);
    assert!(!res.converged && res.num_inliers == 0 && res.inlier_ratio == 0.0);
    let res = align(&empty, &target, &Pose::identity(), &c);
    assert!(!res.converged && res.num_inliers == 0);
    let three = preprocess(&[[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], &c);
    let res = align(&three, &three, &Pose::identity(), &c);
    assert!(!res.converged);
}

#[test]
fn config_reads_partial_toml() {
    let c: GicpConfig = toml::from_str("voxel_size_m = 0.5\nparallel = false").unwrap();
    assert_eq!(c, GicpConfig { voxel_size_m: 0.5, parallel: false, ..GicpConfig::default() });
    assert!(toml::from_str::<GicpConfig>("voxel_size = 0.5").is_err());
}
