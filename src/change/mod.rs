//! Change detection across sessions (MATH.md §8): the lifelong map, ELite's
//! five categories decided with seam's own evidence, the ε_g update, and the
//! change events that make "what changed here since session 3" a lookup.
//!
//! ```text
//!  lifelong map (SQLite, on graph version g) ──► moved to version h by each
//!     voxel's owner keyframe ΔT = W_h · W_g⁻¹, re-binned         (lifelong.rs)
//!                                      │
//!  new session: cleaned maps (ε_l) ────┤   its evidence at the map's voxels
//!                                      ▼   (n_free, ω_free, ω_hit)
//!            categories + ε_g update + events                      (detect.rs)
//!                                      │
//!                                      ▼
//!  lifelong map on h, change_events, session_changes (one transaction)
//! ```
//!
//! Nothing here ray casts: the new session's evidence is read back from the
//! files the `evidence` step stored, and the lifelong map carries what every
//! earlier session contributed (its ε_g), so an ingest costs one session's
//! work, not all of them.

pub mod detect;
pub mod lifelong;
pub mod places;

pub use detect::{ChangeConfig, DeletedReliability, SessionChanges, update_map};
pub use lifelong::{Category, ChangeEvent, LifelongMap, MapVoxel};
