//! # seam — a lifelong LiDAR map store
//!
//! A survey script pushes each new session (a walk or drive with a LiDAR
//! through a site) into a store; seam validates it, stores every scan and its
//! odometry pose, cuts the trajectory into submaps, aligns it with every
//! earlier session (coarse map-to-map registration, intra- and inter-session
//! loops accepted by the DOP test, a joint pose graph with submap anchors),
//! and records each step as its own transaction. Then directional
//! ray-casting evidence for the new session (earlier sessions' evidence is
//! reprojected through the moved anchors, not cast again), dynamic object
//! removal, and change detection against the lifelong map, each a step of
//! the same kind.
//!
//! # Layout
//! - [`geometry`]: SE(3) poses, scans, voxel keys. No I/O.
//! - [`sensor`]: sensor models and fields of view.
//! - [`io`]: readers for KITTI `.bin`, PCD, PLY, LAS/LAZ, pose files, and the
//!   session layouts; validation with errors that name file and place.
//! - [`pipeline`]: `ingest_session`, one page of named steps.
//! - [`align`]: multi-session alignment over the store's rows: maps, coarse
//!   placement, loop candidates, the joint graph per anchor mode.
//! - [`registration`]: GICP, the DOP test, loop verification, global registration.
//! - [`graph`]: the pose graph with submap anchors (LM on sparse Cholesky).
//! - [`evidence`]: voxel ray casting and directional hit/free evidence, ε_l,
//!   dynamic object removal, reprojection.
//! - [`change`]: ELite's five categories on seam's evidence, ε_g, the
//!   lifelong and static maps and the change events.
//! - [`eval`]: metrics against ground truth (Umeyama, ATE, rigid residual).
//! - [`store`]: the only module that touches SQLite and Parquet.
//! - [`query`]: the query language: lexer, parser, planner to parameterised SQL, execution.
//! - [`render`]: top-down pictures (PNG) of a store and the HTML report.
//! - [`sim`]: a simulated multi-session construction site with ground truth.
//! - [`config`]: one `Config`, a sub-struct per stage.
//! - [`cli`]: the `seam` command line.
//!
//! ```no_run
//! use seam::{config::Config, pipeline, store};
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let opts = store::InitOptions { site_name: "site".into(), crs: "local".into(), voxel_size_m: 0.2 };
//! let mut s = store::Store::create("site.seam".as_ref(), &opts)?;
//! let receipt = pipeline::ingest_session(
//!     &mut s,
//!     "survey-2026-11-20".as_ref(),
//!     &pipeline::IngestOptions::default(),
//!     &Config::default(),
//!     &pipeline::NoProgress,
//! )?;
//! println!("session {:?}: {} keyframes", receipt.session_id, receipt.keyframes);
//! # Ok(()) }
//! ```

pub mod align;
pub mod change;
pub mod cli;
pub mod config;
pub mod eval;
pub mod evidence;
pub mod fault;
pub mod geometry;
pub mod graph;
pub mod io;
pub mod pipeline;
pub mod query;
pub mod registration;
pub mod render;
pub mod sensor;
pub mod sim;
pub mod store;
pub mod text;
