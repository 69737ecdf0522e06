//! The pose graph with submap anchors (SEAM eqs. 2-3, Fig. 4; MATH.md §5).
//!
//! Variables are submap anchors `A_m = t_world_submap` and keyframe poses
//! local to their submap `p_i = t_submap_keyframe`. Every between factor —
//! odometry, intra-session loop, inter-session loop — measures
//! `Z ≈ h = (A_m(i) p_i)⁻¹ (A_m(j) p_j)` with residual `r = Log(Z⁻¹ h)`; when
//! both keyframes share a submap the anchors cancel and it is an ordinary
//! between factor. Priors hold anchors near a value.
//!
//! Why a solver of seam's own: factrs and apex-solver both handle SE(3)
//! between factors, but the anchored factor touches four variables, one of
//! which may be absent (same submap) or frozen (the `fixed` mode, gauge), and
//! its Jacobians have the closed form of MATH.md §5. Writing Levenberg-Marquardt
//! on faer's sparse Cholesky is ~300 lines, keeps one nalgebra version, and
//! returns errors instead of panicking on a failed factorisation.
//!
//! Gauge (MATH.md §5): the first keyframe of each submap is its origin, so
//! `p_first = I` is held constant (the limit of the tight σ = 1e-6 prior), and
//! the first anchor of the first session is held constant; every other anchor
//! has a loose prior (σ_rot π, σ_trans 1e4 m) so that an unconnected session
//! stays where its coarse alignment put it.
//!
//! Not here: which keyframes are connected (pipeline), reading or writing
//! poses (store).

mod factors;
mod solver;

pub use crate::geometry::se3::{adjoint, se3_right_jacobian_inv};
pub use factors::{BetweenJacobians, between_residual_and_jacobians};
pub use solver::{OptimizeReport, SolveError, optimize};

use crate::geometry::Pose;
use nalgebra::Matrix6;
use serde::{Deserialize, Serialize};

/// How anchors are assigned (the comparison of the paper's Fig. 5 / Table II).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AnchorMode {
    /// Earlier sessions are frozen; only the new session moves.
    Fixed,
    /// One anchor per session.
    Session,
    /// One anchor per submap (SEAM's default).
    Submap,
}

impl AnchorMode {
    pub fn name(self) -> &'static str {
        match self {
            AnchorMode::Fixed => "fixed",
            AnchorMode::Session => "session",
            AnchorMode::Submap => "submap",
        }
    }
}

/// Noise and solver settings (MATH.md §5).
///
/// The σ defaults are not LT-SLAM's (0.01 for odometry, 0.1 m / 0.01 rad for
/// loops): measured, they weighted the loops wrongly for seam's data. On a
/// simulated 5 × 300-keyframe OS1-64 site (`seam eval align`), GICP loop
/// edges were off the truth by 4 mm / 0.02° (median; 37 mm worst, none
/// wrong), 25× better than σ_loop = 0.01 rad says, while the odometry drifts
/// up to 0.03 m / 0.003 rad per 1 m step, 3σ of σ_odom = 0.01 m. With
/// LT-SLAM's values the optimum (reached from the truth too) left 130-230 mm
/// ATE; with odometry 0.05 m / 0.005 rad and loops 0.02 m / 0.001 rad
/// (still 5× the measured loop error) it left 75-100 mm.
///
/// Tried and not taken: spreading a loop's σ over directions by the shape
/// of its GICP Hessian (each block's best direction at σ, the others
/// weaker in proportion; MATH.md §5 allows "or the GICP Hessian"). On the
/// simulated 60-keyframe sessions of `bench/dor_vs_dufomap.py` ATE RMSE went
/// from 12-14 to 14-18 mm (Avia 28 mm) and DOR F1 moved by −1.08 (Avia) to
/// +0.27; on the synthetic corridor of `tests/rebuild.rs` the position along
/// the corridor, which no loop held any more, differed by 17 cm between a
/// store and its rebuild (5 cm with these σ). GICP's Hessian counts its
/// points as independent, so its weak directions need a floor before they
/// can weigh an edge.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GraphConfig {
    pub mode: AnchorMode,
    /// Odometry between consecutive keyframes (per keyframe step, ~1 m).
    pub odom_sigma_rot_rad: f64,
    pub odom_sigma_trans_m: f64,
    /// Loop edges, scaled by `max(1, ρ_corr)` (MATH.md §5).
    pub loop_sigma_rot_rad: f64,
    pub loop_sigma_trans_m: f64,
    /// Cauchy kernel width on loop residuals (in units of σ).
    pub loop_cauchy_k: f64,
    pub anchor_prior_sigma_rot_rad: f64,
    pub anchor_prior_sigma_trans_m: f64,
    /// In `submap` and `fixed` mode, the odometry factor that crosses a
    /// submap boundary has its σ multiplied by this: the joints of the chain
    /// of rigid submaps are where drift is absorbed (paper Fig. 4, "free
    /// trajectory deformation between submaps"). 1 makes the modes
    /// equivalent at the optimum (a reparametrisation only).
    pub submap_boundary_sigma_scale: f64,
    pub max_iterations: usize,
    /// Stop when the relative cost decrease falls below this.
    pub relative_cost_tolerance: f64,
}

impl Default for GraphConfig {
    fn default() -> Self {
        GraphConfig {
            mode: AnchorMode::Submap,
            odom_sigma_rot_rad: 0.005,
            odom_sigma_trans_m: 0.05,
            loop_sigma_rot_rad: 0.001,
            loop_sigma_trans_m: 0.02,
            loop_cauchy_k: 1.0,
            anchor_prior_sigma_rot_rad: std::f64::consts::PI,
            anchor_prior_sigma_trans_m: 1e4,
            submap_boundary_sigma_scale: 10.0,
            max_iterations: 50,
            relative_cost_tolerance: 1e-9,
        }
    }
}

/// Information matrix `diag(1/σ_rot², ×3, 1/σ_trans², ×3)` for `[ω; v]`.
pub fn information(sigma_rot_rad: f64, sigma_trans_m: f64) -> Matrix6<f64> {
    let (r, t) = (1.0 / (sigma_rot_rad * sigma_rot_rad), 1.0 / (sigma_trans_m * sigma_trans_m));
    Matrix6::from_diagonal(&nalgebra::Vector6::new(r, r, r, t, t, t))
}

/// A robust kernel applied to the squared Mahalanobis norm `s = rᵀ Ω r`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Robust {
    None,
    /// `ρ(s) = k² ln(1 + s/k²)`.
    Cauchy {
        k: f64,
    },
}

impl Robust {
    /// `(ρ(s), ρ'(s))`.
    pub fn eval(self, s: f64) -> (f64, f64) {
        match self {
            Robust::None => (s, 1.0),
            Robust::Cauchy { k } => {
                let k2 = k * k;
                (k2 * (1.0 + s / k2).ln(), 1.0 / (1.0 + s / k2))
            }
        }
    }
}

/// A between factor on keyframes `i` and `j` (indices into `PoseGraph::locals`).
#[derive(Debug, Clone, PartialEq)]
pub struct Between {
    pub i: usize,
    pub j: usize,
    /// The measured `t_i_j`.
    pub z: Pose,
    pub information: Matrix6<f64>,
    pub robust: Robust,
}

/// A prior on an anchor.
#[derive(Debug, Clone, PartialEq)]
pub struct AnchorPrior {
    pub anchor: usize,
    pub value: Pose,
    pub information: Matrix6<f64>,
}

/// The graph: variable values, which are held constant, and the factors.
#[derive(Debug, Clone, Default)]
pub struct PoseGraph {
    /// `A_m`, one per anchor.
    pub anchors: Vec<Pose>,
    /// `p_i`, one per keyframe.
    pub locals: Vec<Pose>,
    /// The anchor of each keyframe (same length as `locals`).
    pub keyframe_anchor: Vec<usize>,
    pub anchor_fixed: Vec<bool>,
    pub local_fixed: Vec<bool>,
    pub betweens: Vec<Between>,
    pub priors: Vec<AnchorPrior>,
}

impl PoseGraph {
    /// World pose of keyframe `i`: `A_m(i) · p_i`.
    pub fn world_pose(&self, i: usize) -> Pose {
        self.anchors[self.keyframe_anchor[i]] * self.locals[i]
    }

    /// Adds an anchor and returns its index.
    pub fn add_anchor(&mut self, value: Pose, fixed: bool) -> usize {
        self.anchors.push(value);
        self.anchor_fixed.push(fixed);
        self.anchors.len() - 1
    }

    /// Adds a keyframe under `anchor` and returns its index.
    pub fn add_keyframe(&mut self, anchor: usize, local: Pose, fixed: bool) -> usize {
        self.locals.push(local);
        self.keyframe_anchor.push(anchor);
        self.local_fixed.push(fixed);
        self.locals.len() - 1
    }
}
