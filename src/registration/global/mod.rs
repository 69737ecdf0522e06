//! Global (coarse) map-to-map registration: where does a new session's map
//! sit in the frame of the earlier sessions' map, with no initial guess
//! (paper III-B, MATH.md §2).
//!
//! What this module owns: turning two point clouds (the target, e.g. the
//! merged or static map of earlier sessions, and the source, the new
//! session's map merged by its odometry) into `t_target_source` with a
//! conservative verdict. What it does not own: building those maps, GICP
//! refinement per keyframe, storing the result — the pipeline does that.
//!
//! # Method
//!
//! KISS-Matcher's and TEASER++'s recipe (Lim et al. 2025; Yang et al. 2020),
//! plus a dense verification that neither has:
//!
//! 1. **Preprocess**: voxel centroids at `voxel_size_m` (0.5 m), PCA normals
//!    within `normal_radius_m` (3 voxels) — [`cloud`].
//! 2. **Describe**: FPFH within `feature_radius_m` (5 voxels), in a variant
//!    invariant to the sign of the normals — [`fpfh`].
//! 3. **Match**: mutual nearest neighbours in descriptor space, the
//!    `max_correspondences` most distinctive by Lowe's ratio — [`matching`].
//!    On map pairs 95-99 % of these are wrong.
//! 4. **Prune and solve**: the pairwise-consistency graph (lengths agree
//!    within `2 noise_bound_m`; with gravity, heights too), its maximum
//!    clique, and GNC-TLS on the clique give a hypothesis; removing what it
//!    explains and repeating gives runner-ups — [`clique`], [`robust`].
//! 5. **Verify**: each hypothesis is refined by point-to-plane ICP on the
//!    maps and scored by how many source *structure* voxels (walls, poles,
//!    objects: not ground) land within `match_distance_m` of the target —
//!    [`verify`]. The best score wins.
//! 6. **Verdict** (conservative: a wrong transform must never come back as
//!    a success): enough feature inliers, a high structure fit where both
//!    maps looked, a minimum of matched structure, and no distinct
//!    runner-up that explains nearly as much. A failure keeps the best
//!    (rejected) estimate for diagnosis and says why in plain words.
//!
//! # Gravity
//!
//! With `gravity_aligned` (the default), both maps' z axes are taken to be
//! vertical to within `max_tilt_deg`, as they are for ground vehicles,
//! handheld and backpack rigs whose odometry is gravity-aligned (LIO) or
//! starts level. Then (a) the consistency graph also requires height
//! differences to agree, which removes most chance consistencies on a flat
//! site, (b) the clique's motion is fitted in 4-DoF (x, y, z, yaw), and (c)
//! ICP moves 4-DoF first, then all six. Yaw is unrestricted (±180°) and so is
//! the offset. Turn it off for maps whose frames may be arbitrarily tilted;
//! every step then works in 6-DoF (the descriptors are rotation-invariant
//! either way), but the structure test still assumes the *target's* z is up.
//!
//! ```no_run
//! use seam::registration::global::{GlobalConfig, Verdict, register_maps};
//! # let (old_map, new_map): (Vec<[f32; 3]>, Vec<[f32; 3]>) = (vec![], vec![]);
//! let result = register_maps(&old_map, &new_map, &GlobalConfig::default());
//! match &result.verdict {
//!     Verdict::Success => println!("aligned, {} inliers", result.inliers),
//!     Verdict::Failure { reason } => eprintln!("left unaligned: {reason}"),
//! }
//! ```
//!
//! # Layout
//! - `cloud`: downsampled map, kd-tree (radius + nearest), normals.
//! - `fpfh`: sign-invariant FPFH descriptors.
//! - `matching`: mutual nearest neighbours in descriptor space, Lowe ratio.
//! - `clique`: consistency graph, k-core ordering, exact max clique.
//! - `robust`: GNC-TLS, weighted 4/6-DoF fits, hypotheses.
//! - `verify`: point-to-plane ICP refinement, structure score.
//! - `register`: [`register_maps`], the steps above as one page, and the verdict.

pub mod bev;
pub mod clique;
pub mod cloud;
pub mod fpfh;
pub mod matching;
mod register;
pub mod robust;
pub mod verify;

pub use register::register_maps;

use serde::{Deserialize, Serialize};

use crate::geometry::Pose;

/// Global registration settings. Every field has a default; a TOML section
/// names only what it changes. Radii and distances are in metres and should
/// scale with `voxel_size_m` (the defaults are 3, 5, 1 and 2 voxels).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GlobalConfig {
    /// Voxel size of both maps before anything else (MATH.md: 0.5-1.0 m).
    pub voxel_size_m: f64,
    /// Neighbourhood of the PCA normals (choice: 3 voxels, KISS-Matcher's).
    pub normal_radius_m: f64,
    /// Neighbourhood of the FPFH descriptors (choice: 5 voxels, KISS-Matcher's).
    pub feature_radius_m: f64,
    /// Most distinctive mutual matches kept for the robust estimator.
    pub max_correspondences: usize,
    /// Bound on the position error of a true correspondence, m (choice: 1
    /// voxel, KISS-Matcher's graph bound). Pairs are consistent within twice this.
    pub noise_bound_m: f64,
    /// Treat both maps' z as vertical (see the module doc).
    pub gravity_aligned: bool,
    /// Largest tilt of either map's z from vertical when `gravity_aligned`, deg.
    pub max_tilt_deg: f64,
    /// Hypotheses (cliques) refined and compared.
    pub max_hypotheses: usize,
    /// Branch-and-bound nodes per max-clique search before settling for the
    /// best clique found (the result then says so).
    pub clique_node_budget: usize,
    /// Hypotheses from the exhaustive bird's-eye-view search (gravity only; 0: off).
    pub bev_hypotheses: usize,
    /// Cell of that search, m.
    pub bev_cell_m: f64,
    /// Yaw step of that search, deg.
    pub bev_yaw_step_deg: f64,
    /// Point-to-plane ICP iterations per hypothesis.
    pub refine_iterations: usize,
    /// ICP's correspondence distance at the first iteration, m (it shrinks to one voxel).
    pub refine_start_m: f64,
    // --- verdict ---
    /// Fewest feature correspondences that agree with the final transform
    /// (within `noise_bound_m`).
    pub min_inliers: usize,
    /// A source voxel is matched when a target point lies this close after
    /// alignment (choice: 2 voxels).
    pub match_distance_m: f64,
    /// Horizontal cell of the target's surveyed-area map, m.
    pub coverage_cell_m: f64,
    /// Smallest structure fit: matched / covered source structure voxels.
    pub min_structure_fit: f64,
    /// Fewest matched source structure voxels.
    pub min_matched_structure: usize,
    /// Largest score of a distinct runner-up relative to the winner.
    pub max_runner_up_ratio: f64,
    /// Hypotheses closer than this to the winner are the same answer, m…
    pub same_answer_m: f64,
    /// …and degrees.
    pub same_answer_deg: f64,
}

impl Default for GlobalConfig {
    fn default() -> Self {
        GlobalConfig {
            voxel_size_m: 0.5,
            normal_radius_m: 1.5,
            feature_radius_m: 2.5,
            max_correspondences: 3000,
            noise_bound_m: 0.5,
            gravity_aligned: true,
            max_tilt_deg: 2.0,
            max_hypotheses: 4,
            clique_node_budget: 200_000,
            bev_hypotheses: 3,
            bev_cell_m: 2.0,
            bev_yaw_step_deg: 1.5,
            refine_iterations: 30,
            refine_start_m: 3.0,
            min_inliers: 12,
            match_distance_m: 1.0,
            coverage_cell_m: 2.0,
            min_structure_fit: 0.5,
            min_matched_structure: 300,
            max_runner_up_ratio: 0.6,
            same_answer_m: 1.5,
            same_answer_deg: 3.0,
        }
    }
}

/// Whether the estimate can initialise the new session's anchors.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Verdict {
    Success,
    /// Keep the session unaligned; `reason` says why, for the user.
    Failure {
        reason: String,
    },
}

impl Verdict {
    pub fn is_success(&self) -> bool {
        matches!(self, Verdict::Success)
    }
}

/// Wall-clock seconds of each step.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct GlobalTimings {
    pub preprocess_s: f64,
    pub features_s: f64,
    pub matching_s: f64,
    pub solver_s: f64,
    pub verify_s: f64,
}

/// The outcome of [`register_maps`], with the evidence behind the verdict.
#[derive(Debug, Clone, PartialEq)]
pub struct GlobalResult {
    /// Moves source points into the target frame. On failure: the best
    /// rejected estimate (identity if there was none) — do not use it.
    pub t_target_source: Pose,
    pub verdict: Verdict,
    /// Mutual-nearest-neighbour feature matches given to the robust estimator.
    pub correspondences: usize,
    /// Of those, the ones within `noise_bound_m` under the final transform.
    pub inliers: usize,
    /// `inliers / correspondences` (a few per cent is normal for map pairs).
    pub inlier_ratio: f64,
    /// Fraction of all source voxels within `match_distance_m` of a target
    /// point after alignment.
    pub overlap_fraction: f64,
    /// Fraction of the source structure voxels over the target's surveyed
    /// area that are within `match_distance_m` of a target point.
    pub structure_fit: f64,
    /// Matched source structure voxels.
    pub matched_structure: usize,
    /// Size of the winning hypothesis' clique.
    pub clique_size: usize,
    /// Best distinct runner-up's score over the winner's (0 if none).
    pub runner_up_ratio: f64,
    /// Hypotheses generated.
    pub hypotheses: usize,
    /// Voxels of the downsampled maps.
    pub target_points: usize,
    pub source_points: usize,
    pub elapsed_s: f64,
    pub timings: GlobalTimings,
}
