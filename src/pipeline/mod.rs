//! The ingest pipeline: the paper's steps as one page of named calls.
//!
//! `ingest_session` reads and validates a session folder, then runs the steps
//! in order. Each step commits its own SQLite transaction together with its
//! row in `step_log`, so a re-run after a crash skips what was committed and
//! resumes at the first step without a row. Re-ingesting a session whose
//! content hash is already stored and complete is a no-op.
//!
//! Steps today (MATH.md section in brackets):
//! 1. `scans`         store every scan and its odometry pose (§1)
//! 2. `submaps`       cut the trajectory by travel distance (§1)
//! 3. `initial_graph` a graph version from odometry: anchors at each submap's
//!    first keyframe, local poses relative to it (§1); later steps replace it
//!    with aligned and optimised versions (§2-5)
//!
//! Alignment, evidence and change detection plug in as further [`Step`]s.

mod evidence_step;
mod ingest;
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
