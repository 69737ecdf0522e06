//! The ingest pipeline: the paper's steps as one page of named calls.
//!
//! `ingest_session` reads and validates a session folder, then runs the steps
//! in order. Each step commits its own SQLite transaction together with its
//! row in `step_log`, so a re-run after a crash skips what was committed and
//! resumes at the first step without a row. Re-ingesting a session whose
//! content hash is already stored and complete is a no-op.
//!
//! Steps (MATH.md section in brackets; [`steps::STEPS`] is the list):
//! 1. `scans`         store every scan and its odometry pose (§1)
//! 2. `submaps`       cut the trajectory by travel distance (§1)
//! 3. `coarse_align`  place the session against the earlier ones (§2)
//! 4. `loops`         inter-session loop closures, DOP-tested (§3-4)
//! 5. `optimize`      the pose graph with submap anchors: a new graph version (§5)
//! 6. `evidence`      ray cast the new session only, DOR, store evidence and
//!    cleaned maps; reproject earlier sessions' evidence (§6-7)
//! 7. `changes`       fold the session into the lifelong map: categories,
//!    ε_g, change events (§8)
//! 8. `complete`      mark the session complete

mod changes_step;
mod evidence_step;
mod ingest;
pub mod rebuild;
mod steps;
mod submaps;

pub use ingest::{IngestError, IngestOptions, IngestReceipt, IngestStatus, StepReceipt, ingest_session};
pub use submaps::cut_submaps;

/// Receives progress of long work; the CLI draws it, tests ignore it.
pub trait Progress: Sync {
    /// A phase with `total` units of work begins.
    fn begin(&self, _phase: &str, _total: u64) {}
    /// `n` more units are done.
    fn advance(&self, _n: u64) {}
    /// The phase is over.
    fn end(&self) {}
}

/// Progress that goes nowhere.
pub struct NoProgress;
impl Progress for NoProgress {}
