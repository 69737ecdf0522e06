//! Registration: scan-to-map GICP and the DOP reliability test of an
//! inter-session loop (paper III-B, MATH.md §3-4).
//!
//! What this module owns: turning two point sets and an initial guess into a
//! relative pose with its diagnostics ([`gicp`]), and judging whether the
//! matched points constrain all six degrees of freedom ([`dop`]). What it does
//! not own: choosing which keyframes to match, building the local map of the
//! target, storing edges — the pipeline does that with these results, which
//! are plain data.
//!
//! ```no_run
//! use seam::registration::{align, preprocess, reliability_test, DopConfig, GicpConfig};
//! # let (target_points, source_points): (Vec<[f32; 3]>, Vec<[f32; 3]>) = (vec![], vec![]);
//! # let fov = seam::sensor::SensorModel::Hdl64e.fov();
//! let cfg = GicpConfig::default();
//! let target = preprocess(&target_points, &cfg); // reusable for many sources
//! let source = preprocess(&source_points, &cfg);
//! let result = align(&target, &source, &seam::geometry::Pose::identity(), &cfg);
//! let verdict = reliability_test(&result, &fov, &DopConfig::default());
//! if result.converged && verdict.accepted { /* add the loop edge */ }
//! ```
//!
//! # Layout
//! - `downsample`: voxel-grid centroids.
//! - `kdtree`: kiddo `ImmutableKdTree` wrapper plus the brute-force reference.
//! - `covariance`: k-NN covariances regularised to planes.
//! - `gicp`: preprocessing and the Levenberg-Marquardt loop.
//! - `dop`: `g0`, solid angles, ρ, the ratio test, FoV estimation.
//! - `loop_check`: one loop candidate: GICP, then the acceptance rules.
//! - `global`: coarse map-to-map alignment (MATH.md §2), a module of its own.

pub mod covariance;
pub mod dop;
pub mod downsample;
pub mod gicp;
pub mod global;
pub mod kdtree;
pub mod loop_check;

pub use dop::{DopConfig, DopReason, DopVerdict, RhoReport, estimate_fov, g0, reliability_test, rho, solid_angle_sr};
pub use gicp::{GicpConfig, GicpResult, GicpTarget, PreparedCloud, align, preprocess};
pub use loop_check::{LoopConfig, LoopReason, LoopVerdict, verify_loop};
