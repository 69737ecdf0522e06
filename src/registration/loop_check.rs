//! Verifying one loop candidate (MATH.md §3-4): GICP of a keyframe's scan
//! (source, in its sensor frame) against a local map (target), then the
//! acceptance rules: converged, enough of the scan matched, a small
//! fitness, and the DOP ratio test. The pipeline chooses the candidates and
//! stores every verdict; the Table I analogue (`tests/loop_reliability.rs`,
//! `examples/loop_table.rs`) measures these rules on simulated pairs.

use super::dop::{DopConfig, DopVerdict, reliability_test};
use super::gicp::{GicpConfig, GicpResult, GicpTarget, PreparedCloud, align};
use crate::geometry::Pose;
use crate::sensor::Fov;
use serde::{Deserialize, Serialize};

/// Loop detection and acceptance settings. Every field has a default; a TOML
/// section names only what it changes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LoopConfig {
    /// A candidate pairs a keyframe with the nearest keyframe of each earlier
    /// session (or, intra-session, of its own session's past) within this
    /// distance in the current estimate (MATH.md §3: 10 m; choice: 20 m.
    /// Sessions that walk different routes through a site pass each other at
    /// 10-20 m, and a 360° scan still shares most of its structure there: on
    /// a simulated 4 × 150-keyframe site, 10 m gave 18-49 candidates per
    /// session and 86-219 mm ATE, 20 m gave 47-105 and 41-78 mm, no
    /// accepted edge wrong in either).
    pub radius_m: f64,
    /// The target's local map is its keyframe and ±this many neighbours
    /// (MATH.md §3: 5).
    pub neighbours: usize,
    /// Inter-session: at most this many earlier sessions per keyframe (the
    /// nearest ones). Choice: 2 — every earlier session still gets edges
    /// where it is among the two nearest, and the GICP work of an ingest
    /// stops growing with the number of sessions (5 × 300 keyframes: 582
    /// candidates for the fifth session without the cap).
    pub max_sessions_per_keyframe: usize,
    /// Try every n-th keyframe of the new session (choice: 2, about one
    /// candidate per 2 m at 1 m keyframe spacing: ~10 per 20 m submap and
    /// earlier session, half the GICP time of trying every keyframe).
    pub keyframe_stride: usize,
    /// Intra-session loops: the two keyframes must be at least this far apart
    /// along the trajectory (odometry travel), so a loop is a revisit and
    /// not a neighbour (choice: 30 m).
    pub intra_min_travel_m: f64,
    /// Local intra-session edges: each `keyframe_stride`-th keyframe is
    /// also registered against the keyframe about this much travel behind
    /// it (the first at least this far back; 0 turns it off), verified and
    /// stored like any intra-session loop. They are what LiDAR-odometry
    /// refinement gives a SLAM: the session's input odometry drifts (yaw
    /// bias, scale), and a scan registered to a local map a few metres back
    /// measures that drift where no revisit does.
    ///
    /// Choice: 8 m. The target's local map spans ±`neighbours` keyframes,
    /// so much shorter edges register a scan against a map that contains it,
    /// and chain more error. Measured on the simulated 60-keyframe sessions
    /// of `bench/dor_vs_dufomap.py` (drift 0.4-0.9 % of the path): ATE
    /// RMSE / max 110 / 213 mm without them; with 4 m, 88-147 mm max; with
    /// 8 m, 12-18 / 27-42 mm on every sensor; with 12-16 m, 13-15 / 37-44 mm
    /// max. DOR F1 follows the poses: with 8 m, OS1-64 90.43 → 90.69,
    /// HDL-64E 93.80 → 94.63, VLP-16 84.87 → 86.25, HDL-32E 87.16 → 88.18,
    /// Avia 93.53 → 94.07 (`seam eval dor`). Cost: one GICP per two
    /// keyframes, about 0.05-0.1 s each on 2 cores.
    pub local_travel_m: f64,
    /// Accept only if at least this fraction of the downsampled scan found a
    /// correspondence at the final distance (choice: 0.7, from the Table I
    /// analogue, `examples/loop_table.rs`, seeds 2, 6, 7, 40 pairs a cell.
    /// The rule that does the work there. Ground matches from any pose, so
    /// wrong results that converged still matched 31-66 % (OS1-64 scans),
    /// 21-60 % (VLP-16) and up to 85 % (Avia, mostly ground in front).
    /// Correct ones matched 71-96 % (OS1-64, VLP-16) and 63-100 % (Avia,
    /// lower where the site changed between sessions). With 0.5, up to 28 %
    /// of a 360° Near-Mismatch cell was accepted wrong, offset 3-5 m along a
    /// road, and up to 20 % of a Far cell. With 0.7, every 360° cell was
    /// 100 % and the Avia cells 90-100 %.)
    pub min_inlier_ratio: f64,
    /// Accept only if the mean squared distance of matched pairs is at most
    /// this (m², choice: 0.06. Correct matches in the Table I analogue
    /// reached 0.031 (OS1-64), 0.034 (Avia) and 0.051 (VLP-16, whose sparse
    /// rings leave larger gaps), so 0.05 rejected a correct VLP-16 match.
    /// This is a sanity bound. Wrong results there had 0.019-0.079, so
    /// fitness does not separate them; convergence and the inlier ratio do.)
    pub max_fitness_m2: f64,
    /// GICP for loops.
    pub gicp: GicpConfig,
    /// The DOP ratio test (MATH.md §4; see `DopConfig::rho_max` for why its
    /// default is 6.0, not MATH.md's 3.0).
    pub dop: DopConfig,
}

impl Default for LoopConfig {
    fn default() -> Self {
        LoopConfig {
            radius_m: 20.0,
            neighbours: 5,
            keyframe_stride: 2,
            max_sessions_per_keyframe: 2,
            intra_min_travel_m: 30.0,
            local_travel_m: 8.0,
            min_inlier_ratio: 0.7,
            max_fitness_m2: 0.06,
            gicp: GicpConfig::default(),
            dop: DopConfig::default(),
        }
    }
}

/// Why a candidate was accepted or rejected (the first failed rule).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LoopReason {
    Accepted,
    NotConverged,
    FewInliers,
    PoorFitness,
    Dop,
}

impl LoopReason {
    pub fn as_str(self) -> &'static str {
        match self {
            LoopReason::Accepted => "accepted",
            LoopReason::NotConverged => "gicp did not converge",
            LoopReason::FewInliers => "too few of the scan's points matched the local map",
            LoopReason::PoorFitness => "matched points are too far apart (fitness)",
            LoopReason::Dop => "DOP test failed",
        }
    }
}

/// The outcome of [`verify_loop`].
#[derive(Debug, Clone)]
pub struct LoopVerdict {
    pub gicp: GicpResult,
    pub dop: DopVerdict,
    pub accepted: bool,
    pub reason: LoopReason,
}

impl LoopVerdict {
    /// A human sentence: the rule that decided, with its numbers.
    pub fn describe(&self) -> String {
        match self.reason {
            LoopReason::Accepted => "accepted".into(),
            LoopReason::NotConverged => format!("{} after {} iterations", self.reason.as_str(), self.gicp.iterations),
            LoopReason::FewInliers => format!("{} ({:.0}%)", self.reason.as_str(), 100.0 * self.gicp.inlier_ratio),
            LoopReason::PoorFitness => format!("{} ({:.3} m²)", self.reason.as_str(), self.gicp.fitness),
            LoopReason::Dop => format!(
                "{}: {} (rho_scan {:.2}, rho_corr {:.2})",
                self.reason.as_str(),
                self.dop.reason,
                self.dop.rho_scan,
                self.dop.rho_corr
            ),
        }
    }
}

/// Registers `source` (a scan preprocessed in its sensor frame) against
/// `target` from `t_init` and applies the acceptance rules in order.
pub fn verify_loop(
    target: &GicpTarget,
    source: &PreparedCloud,
    t_init: &Pose,
    fov: &Fov,
    cfg: &LoopConfig,
) -> LoopVerdict {
    let gicp = align(target, source, t_init, &cfg.gicp);
    let dop = reliability_test(&gicp, fov, &cfg.dop);
    let reason = if !gicp.converged {
        LoopReason::NotConverged
    } else if gicp.inlier_ratio < cfg.min_inlier_ratio {
        LoopReason::FewInliers
    } else if gicp.fitness > cfg.max_fitness_m2 {
        LoopReason::PoorFitness
    } else if !dop.accepted {
        LoopReason::Dop
    } else {
        LoopReason::Accepted
    };
    LoopVerdict { gicp, dop, accepted: reason == LoopReason::Accepted, reason }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::registration::preprocess;
    use nalgebra::{Translation3, UnitQuaternion};

    /// A box room (walls, floor, ceiling) seen from inside, plus a pillar
    /// that breaks its symmetry.
    fn room(origin: [f64; 3]) -> Vec<[f32; 3]> {
        let mut pts = Vec::new();
        let step = 0.1;
        let n = (12.0 / step) as i32;
        for i in 0..=n {
            let a = -6.0 + i as f64 * step;
            for j in 0..=30 {
                let h = j as f64 * step;
                for p in [[a, -6.0, h], [a, 6.0, h], [-6.0, a, h], [6.0, a, h]] {
                    pts.push(p);
                }
            }
            for j in 0..=n {
                let b = -6.0 + j as f64 * step;
                pts.push([-6.0 + i as f64 * step, b, 0.0]);
            }
        }
        for k in 0..300 {
            let t = k as f64 * 0.3f64.to_radians() * 4.0;
            for h in 0..30 {
                pts.push([2.0 + 0.4 * t.cos(), -1.5 + 0.4 * t.sin(), h as f64 * 0.1]);
            }
        }
        pts.iter().map(|p| [(p[0] - origin[0]) as f32, (p[1] - origin[1]) as f32, (p[2] - origin[2]) as f32]).collect()
    }

    #[test]
    fn a_true_match_is_accepted_and_a_far_pair_rejected() {
        let cfg = LoopConfig::default();
        let target = preprocess(&room([0.0, 0.0, 1.0]), &cfg.gicp);
        // The source sensor sits 0.8 m away: t_target_source is that offset.
        let source = preprocess(&room([0.8, -0.3, 1.0]), &cfg.gicp);
        let fov = Fov::Band { elev_min_deg: -90.0, elev_max_deg: 90.0 };
        let truth = Pose::from_parts(Translation3::new(0.8, -0.3, 0.0), UnitQuaternion::identity());
        let guess =
            Pose::from_parts(Translation3::new(0.5, 0.0, 0.0), UnitQuaternion::from_euler_angles(0.0, 0.0, 0.05));
        let v = verify_loop(&target, &source, &guess, &fov, &cfg);
        assert!(v.accepted, "{}", v.describe());
        let err = (v.gicp.t_target_source.translation.vector - truth.translation.vector).norm();
        assert!(err < 0.05, "error {err} m");

        // The same source 40 m away from anything it could match.
        let far = Pose::from_parts(Translation3::new(40.0, 0.0, 0.0), UnitQuaternion::identity());
        let v = verify_loop(&target, &source, &far, &fov, &cfg);
        assert!(!v.accepted, "a pair with no overlap was accepted");
        assert_ne!(v.reason, LoopReason::Accepted);
        assert!(!v.describe().is_empty());
    }
}
