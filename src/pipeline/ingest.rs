//! `ingest_session`: read, validate, then run the steps that are not yet
//! committed for this session.

use super::Progress;
use super::steps::{STEPS, StepCtx};
use crate::config::Config;
use crate::io::{ReadError, SessionSource, detect_session, read_session_scan};
use crate::store::{self, SessionId, Store, StoreError};
use rayon::prelude::*;
use std::io::Read;
use std::path::Path;
use std::time::Instant;

#[derive(Debug, thiserror::Error)]
pub enum IngestError {
    #[error(transparent)]
    Read(#[from] ReadError),
    #[error(transparent)]
    Store(#[from] StoreError),
    #[error(
        "session name {name:?} is already used by session {existing} in this store\n  hint: pass --name with another name"
    )]
    NameTaken { name: String, existing: i64 },
    #[error(
        "{store}: this store's sessions were ingested with another configuration; these settings differ (given, then the store's in brackets):\n    {}\n  hint: run without --config to ingest with the store's configuration, or `seam rebuild {store} --out NEW --config FILE` to recompute every session with another",
        differences.join("\n    ")
    )]
    ConfigChanged { store: String, differences: Vec<String> },
}

#[derive(Debug, Clone, Default)]
pub struct IngestOptions {
    /// Overrides the name from `session.toml`; default `s<N>`.
    pub name: Option<String>,
    /// Validate only; write nothing.
    pub dry_run: bool,
    /// Where the session's frame sits in the world (`--initial-guess`),
    /// used instead of global registration.
    pub initial_guess: Option<crate::geometry::Pose>,
    /// Anchor mode of this ingest's optimisation (default: `config.graph.mode`).
    pub anchor_mode: Option<crate::graph::AnchorMode>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum IngestStatus {
    /// Every step ran now.
    Ingested,
    /// Some steps were committed by an earlier, interrupted run.
    Resumed,
    /// The same content is already stored and complete: nothing was done.
    AlreadyPresent,
    /// `--dry-run`: validated, nothing written.
    Validated,
}

#[derive(Debug, Clone, serde::Serialize)]
pub struct StepReceipt {
    pub step: String,
    /// False when an earlier run had already committed the step.
    pub ran: bool,
    pub wall_s: f64,
    pub details: serde_json::Value,
}

/// What an ingest did, for humans and for `--format json`.
#[derive(Debug, Clone, serde::Serialize)]
pub struct IngestReceipt {
    pub status: IngestStatus,
    pub session_id: Option<i64>,
    pub name: String,
    pub source_dir: String,
    pub layout: String,
    pub content_hash: String,
    pub keyframes: usize,
    pub points: u64,
    pub steps: Vec<StepReceipt>,
    pub wall_s: f64,
    pub points_per_s: f64,
    pub scans_per_s: f64,
}

/// blake3 over the name and bytes of every file that defines the session.
fn content_hash(src: &SessionSource) -> Result<String, ReadError> {
    let mut h = blake3::Hasher::new();
    let mut buf = vec![0u8; 1 << 20];
    for path in &src.definition_files {
        let name = path.strip_prefix(&src.dir).unwrap_or(path).to_string_lossy().replace('\\', "/");
        h.update(name.as_bytes());
        h.update(&[0]);
        let mut f = std::fs::File::open(path).map_err(|e| ReadError::io(path, &e))?;
        loop {
            let n = f.read(&mut buf).map_err(|e| ReadError::io(path, &e))?;
            if n == 0 {
                break;
            }
            h.update(&buf[..n]);
        }
    }
    Ok(h.finalize().to_hex().to_string())
}

/// Reads every scan once, in parallel, to prove the session is whole before
/// anything is written. Returns the point count of each scan.
fn validate_scans(src: &SessionSource, progress: &dyn Progress) -> Result<Vec<usize>, ReadError> {
    progress.begin("validate", src.keyframes.len() as u64);
    let counts = (0..src.keyframes.len())
        .into_par_iter()
        .map(|i| {
            let n = read_session_scan(src, i)?.len();
            progress.advance(1);
            Ok(n)
        })
        .collect::<Result<Vec<_>, ReadError>>();
    progress.end();
    counts
}

/// Checks `config` against the one the store recorded once it holds a
/// session: every session of a store is ingested with one configuration,
/// or its lifelong map would mix settings (and `seam rebuild` could not
/// reproduce it). The first session's `scans` step records the
/// configuration in the transaction that creates the session; before that
/// (or in a store from before seam recorded one) any configuration goes.
fn check_config(store: &Store, config: &Config) -> Result<(), IngestError> {
    if store::next_session_id(store.conn())? == 1 {
        return Ok(());
    }
    let Some(json) = store.recorded_config()? else { return Ok(()) };
    let recorded = Config::from_recorded(&json, store.root())
        .map_err(|e| store::StoreError::Corrupt { path: store.root().to_path_buf(), message: e.to_string() })?;
    let differences = config.differences(&recorded);
    if differences.is_empty() {
        return Ok(());
    }
    Err(IngestError::ConfigChanged { store: store.root().display().to_string(), differences })
}

/// Ingests the session in `dir` into `store`.
pub fn ingest_session(
    store: &mut Store,
    dir: &Path,
    opts: &IngestOptions,
    config: &Config,
    progress: &dyn Progress,
) -> Result<IngestReceipt, IngestError> {
    let t0 = Instant::now();
    let src = detect_session(dir)?;
    let hash = content_hash(&src)?;
    let existing = store::session_by_hash(store.conn(), &hash)?;

    let mut receipt = IngestReceipt {
        status: IngestStatus::Ingested,
        session_id: existing.as_ref().map(|s| s.session_id.0),
        name: String::new(),
        source_dir: dir.display().to_string(),
        layout: src.layout.name().to_string(),
        content_hash: hash.clone(),
        keyframes: src.keyframes.len(),
        points: 0,
        steps: Vec::new(),
        wall_s: 0.0,
        points_per_s: 0.0,
        scans_per_s: 0.0,
    };
    if let Some(s) = &existing {
        receipt.name = s.name.clone();
        receipt.points = s.point_count as u64;
        if s.status == "complete" {
            receipt.status = IngestStatus::AlreadyPresent;
            receipt.wall_s = t0.elapsed().as_secs_f64();
            return Ok(receipt);
        }
        receipt.status = IngestStatus::Resumed;
    }

    let done: Vec<String> = match &existing {
        Some(s) => store::steps(store.conn(), s.session_id)?.into_iter().map(|r| r.step).collect(),
        None => Vec::new(),
    };
    // Scans are re-validated unless an earlier run already stored them.
    if !done.iter().any(|s| s == "scans") {
        receipt.points = validate_scans(&src, progress)?.iter().map(|&n| n as u64).sum();
    }
    if existing.is_none() {
        let next = store::next_session_id(store.conn())?;
        receipt.name = opts.name.clone().or_else(|| src.meta.name.clone()).unwrap_or_else(|| format!("s{next}"));
        if store::session_name_taken(store.conn(), &receipt.name)? {
            let other = store::sessions(store.conn())?.into_iter().find(|s| s.name == receipt.name);
            return Err(IngestError::NameTaken {
                name: receipt.name.clone(),
                existing: other.map(|s| s.session_id.0).unwrap_or(0),
            });
        }
    }
    if opts.dry_run {
        receipt.status = IngestStatus::Validated;
        receipt.wall_s = t0.elapsed().as_secs_f64();
        return Ok(receipt);
    }
    check_config(store, config)?;

    let mut ctx = StepCtx {
        store,
        src: &src,
        config,
        progress,
        session: existing.as_ref().map(|s| s.session_id),
        name: receipt.name.clone(),
        content_hash: hash,
        initial_guess: opts.initial_guess,
        anchor_mode: opts.anchor_mode,
    };
    for (seq, step) in STEPS.iter().enumerate() {
        if done.iter().any(|d| d == step.name) {
            receipt.steps.push(StepReceipt {
                step: step.name.into(),
                ran: false,
                wall_s: 0.0,
                details: serde_json::Value::Null,
            });
            continue;
        }
        let ts = Instant::now();
        let details = (step.run)(&mut ctx, step.name, seq as i64)?;
        receipt.steps.push(StepReceipt {
            step: step.name.into(),
            ran: true,
            wall_s: ts.elapsed().as_secs_f64(),
            details,
        });
    }
    let session: SessionId = ctx.session.ok_or_else(|| StoreError::Corrupt {
        path: ctx.store.root().to_path_buf(),
        message: "ingest finished without a session row".into(),
    })?;
    receipt.session_id = Some(session.0);
    receipt.wall_s = t0.elapsed().as_secs_f64();
    if receipt.wall_s > 0.0 {
        receipt.points_per_s = receipt.points as f64 / receipt.wall_s;
        receipt.scans_per_s = receipt.keyframes as f64 / receipt.wall_s;
    }
    Ok(receipt)
}
