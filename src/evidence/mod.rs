//! Directional ray-casting evidence (MATH.md §6, eqs. 4-8).
//!
//! ```text
//!  keyframe: sensor origin + points        (one submap's frame)
//!        │  raycast: Amanatides-Woo walk; endpoint voxel = hit,
//!        │           voxels up to two before it = free, where the ray
//!        │           crosses the voxel's patch of points (surface.rs)
//!        ▼
//!  per-keyframe marks {voxel → hit/free}   (each voxel once per keyframe and kind)
//!        │  accumulate: q = exp(-max(0, r - r0)/rs), u = sensor → voxel centre   (4)
//!        ▼
//!  EvidenceMap {voxel → (n, Q, M = Σ q u uᵀ) for hit and for free, owner keyframe}
//!        │  stats: α = λ1/λ2 of M, ω (5), h and f (6), s (7)
//!        ▼
//!  ε_l = s·f / (h + f + c), clamped to [0.1, 1]                                   (8)
//! ```
//!
//! This module owns that path, from rays to a voxel's ε_l, as plain data in
//! and out. It does not own storing evidence (that is `store`), labelling each
//! point dynamic or static for DOR, reprojecting evidence after the graph is
//! re-optimised (MATH.md §7), nor the ELite update that consumes ε_l (§8):
//! those come later in issue 4 and build on [`EvidenceMap`] and
//! [`VoxelEvidence::epsilon_l`].
//!
//! Why hand-written: no crate keeps direction-aware evidence per voxel (the
//! occupancy crates count hits and misses, not the directions they came
//! from), and the Amanatides-Woo traversal is about sixty lines that are
//! easier to test here against a dense sampling than to adapt.
//!
//! # Layout
//! - `raycast.rs`: [`traverse`] and the free/hit rule [`cast_ray`]
//! - `stats.rs`: [`EvidenceConfig`], [`DirectionalStats`], [`VoxelEvidence`],
//!   closed-form 3×3 eigenvalues [`sym3_eigenvalues`]
//! - `surface.rs`: the sub-voxel free test ([`surface::SurfaceShapes`])
//! - `ground.rs`: each voxel column's ground level, for the clearance and
//!   the guard ([`ground::GroundLevel`])
//! - `grow.rs`: DOR's growth of a keyframe's dynamic verdict into weakly
//!   seen neighbours, its cluster step (pieces mostly dynamic go whole) and
//!   its footing step ([`grow::keyframe_dynamic`])
//! - `no_return.rs`: free evidence from beams that returned nothing ([`no_return::NoReturnImage`])
//! - `accumulate.rs`: [`accumulate_keyframe`] and its parallel twin
//!   [`accumulate_keyframe_par`] into an [`EvidenceMap`]
//! - `grid.rs`: the session's evidence on its sorted voxels of interest
//!   ([`grid::InterestEvidence`]), with when each voxel was hit and crossed
//!   ([`grid::Span`], for DOR's single-change test)
//! - `session.rs`: one session from scans to evidence tables, DOR labels
//!   (ε_l over `tau_dyn`, or changed once: [`session::dynamic_voxels`]) and
//!   the cleaned map

mod accumulate;
pub mod grid;
pub mod ground;
pub mod grow;
pub mod no_return;
mod raycast;
pub mod session;
mod stats;
pub mod surface;
mod tables;

pub use accumulate::{EvidenceMap, KeyframeEvidence, accumulate_keyframe, accumulate_keyframe_par};
pub use raycast::{cast_ray, traverse, voxel_key};
pub use stats::{
    DirectionalStats, EvidenceConfig, EvidenceModel, FreeTest, LogOddsConfig, VoxelEvidence, sym3_eigenvalues,
};
pub use tables::{CleanedMap, NO_HIT_BOX, PointLabels, StatsColumns, SubmapEvidence};
