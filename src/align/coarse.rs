//! Coarse alignment of a new session (MATH.md §2): where its odometry frame
//! sits in the world, from its map and the earlier sessions' map.
//!
//! Three outcomes, all stored: `global` (the map-to-map registration
//! succeeded), `initial_guess` (the user gave `--initial-guess`; it is
//! refined by point-to-plane ICP on the two maps and kept as given if that
//! cannot improve it), `unaligned` (registration failed and there is no
//! guess: the session keeps its own frame, no inter-session loops are
//! tried, and the reason is stored for `seam info`).

use crate::geometry::Pose;
use crate::registration::global::cloud::MapCloud;
use crate::registration::global::robust::Dof;
use crate::registration::global::verify::{RefineParams, refine};
use crate::registration::global::{GlobalConfig, register_maps};
use crate::store::{AlignmentRow, SessionId};
use nalgebra::{Translation3, UnitQuaternion, Vector3};
use std::time::Instant;

/// `x, y, z` (m) and yaw (deg) about the world's z axis, as `--initial-guess` takes them.
pub fn pose_from_xyz_yaw(x_m: f64, y_m: f64, z_m: f64, yaw_deg: f64) -> Pose {
    Pose::from_parts(
        Translation3::new(x_m, y_m, z_m),
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw_deg.to_radians()),
    )
}

/// Parses `x,y,z,yaw_deg`.
pub fn parse_initial_guess(text: &str) -> Result<Pose, String> {
    let v: Vec<f64> = text
        .split(',')
        .map(|s| s.trim().parse::<f64>().map_err(|_| format!("{s:?} is not a number")))
        .collect::<Result<_, _>>()?;
    if v.len() != 4 || v.iter().any(|x| !x.is_finite()) {
        return Err(format!("expected 4 finite numbers x,y,z,yaw_deg, got {:?}", text));
    }
    Ok(pose_from_xyz_yaw(v[0], v[1], v[2], v[3]))
}

/// The first session defines the world.
pub fn reference(session: SessionId) -> AlignmentRow {
    AlignmentRow {
        session_id: session,
        method: "reference".into(),
        success: true,
        reason: "the first session defines the world frame".into(),
        t_world_session: Pose::identity(),
        correspondences: 0,
        inliers: 0,
        inlier_ratio: 0.0,
        overlap_fraction: 0.0,
        elapsed_s: 0.0,
    }
}

/// `t_world_session` from a guess of where the session's first keyframe is
/// (`x, y, z`, yaw about the world's z): the keyframe keeps its odometry
/// tilt (roll, pitch), its yaw and position become the guess's.
pub fn placement_from_first_keyframe(guess: &Pose, t_session_first: &Pose) -> Pose {
    let (_, _, yaw0) = t_session_first.rotation.euler_angles();
    let tilt = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), -yaw0) * t_session_first.rotation;
    let t_world_first = Pose::from_parts(guess.translation, guess.rotation * tilt);
    t_world_first * t_session_first.inverse()
}

/// Aligns `session_map` (the new session's keyframes merged by odometry, in
/// its session frame) to `world_map` (the earlier sessions, world frame).
/// `initial_guess` is the world pose of the session's first keyframe
/// (`t_session_first` is its odometry pose).
pub fn coarse_align(
    session: SessionId,
    world_map: &[[f32; 3]],
    session_map: &[[f32; 3]],
    initial_guess: Option<(Pose, Pose)>,
    cfg: &GlobalConfig,
) -> AlignmentRow {
    let t0 = Instant::now();
    if let Some((guess, t_session_first)) = initial_guess {
        let guess = placement_from_first_keyframe(&guess, &t_session_first);
        let refined = refine_guess(world_map, session_map, &guess, cfg);
        return AlignmentRow {
            session_id: session,
            method: "initial_guess".into(),
            success: true,
            reason: "placed by --initial-guess, refined by ICP on the maps".into(),
            t_world_session: refined,
            correspondences: 0,
            inliers: 0,
            inlier_ratio: 0.0,
            overlap_fraction: 0.0,
            elapsed_s: t0.elapsed().as_secs_f64(),
        };
    }
    let r = register_maps(world_map, session_map, cfg);
    let (method, success, reason, t) = match &r.verdict {
        crate::registration::global::Verdict::Success => ("global", true, String::new(), r.t_target_source),
        crate::registration::global::Verdict::Failure { reason } => (
            "unaligned",
            false,
            format!(
                "global registration failed: {reason}; the session keeps its own frame and has no inter-session \
                 loops. Re-ingest it into a store without it, with --initial-guess x,y,z,yaw_deg (where its first \
                 keyframe is in the world)"
            ),
            Pose::identity(),
        ),
    };
    AlignmentRow {
        session_id: session,
        method: method.into(),
        success,
        reason,
        t_world_session: t,
        correspondences: r.correspondences as i64,
        inliers: r.inliers as i64,
        inlier_ratio: r.inlier_ratio,
        overlap_fraction: r.overlap_fraction,
        elapsed_s: t0.elapsed().as_secs_f64(),
    }
}

/// Point-to-plane ICP from a user's guess (which may be metres and degrees off).
fn refine_guess(world_map: &[[f32; 3]], session_map: &[[f32; 3]], guess: &Pose, cfg: &GlobalConfig) -> Pose {
    if world_map.is_empty() || session_map.is_empty() {
        return *guess;
    }
    let target = MapCloud::new(world_map, cfg.voxel_size_m, cfg.normal_radius_m);
    let source: Vec<[f64; 3]> = crate::registration::downsample::voxel_downsample(session_map, cfg.voxel_size_m, true);
    let params = RefineParams {
        max_dist_start_m: 4.0 * cfg.match_distance_m.max(0.5),
        max_dist_end_m: cfg.match_distance_m.max(0.25),
        iterations: 30,
        dof: if cfg.gravity_aligned { Dof::Four } else { Dof::Six },
    };
    let t = refine(&target, &source, guess, &params);
    if crate::geometry::is_finite_pose(&t) { t } else { *guess }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_guess_places_the_first_keyframe_and_keeps_its_tilt() {
        let first =
            Pose::from_parts(Translation3::new(5.0, -3.0, 0.4), UnitQuaternion::from_euler_angles(0.02, -0.03, 1.2));
        let guess = pose_from_xyz_yaw(10.0, 20.0, 1.0, -60.0);
        let t_world_session = placement_from_first_keyframe(&guess, &first);
        let placed = t_world_session * first;
        assert!((placed.translation.vector - Vector3::new(10.0, 20.0, 1.0)).norm() < 1e-9);
        let (r, p, y) = placed.rotation.euler_angles();
        assert!((r - 0.02).abs() < 1e-9 && (p + 0.03).abs() < 1e-9, "tilt lost: {r} {p}");
        assert!((y - (-60f64).to_radians()).abs() < 1e-9);
    }

    #[test]
    fn initial_guess_parses_and_rejects_garbage() {
        let p = parse_initial_guess("1.5, -2, 0.25, 90").unwrap();
        assert!((p.translation.vector - Vector3::new(1.5, -2.0, 0.25)).norm() < 1e-12);
        assert!((p.rotation.angle() - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        assert!((p * nalgebra::Point3::new(1.0, 0.0, 0.0) - nalgebra::Point3::new(1.5, -1.0, 0.25)).norm() < 1e-12);
        for bad in ["", "1,2,3", "1,2,3,4,5", "a,2,3,4", "1,2,nan,4"] {
            assert!(parse_initial_guess(bad).is_err(), "{bad:?} was accepted");
        }
    }
}
