//! `rebuild`: recompute a store from the raw scans.
//!
//! A new store is created with the source store's site name, CRS and voxel,
//! and every session of the source is ingested into it again, in the
//! source's order, from the folder it recorded (`sessions.source_dir`), under
//! the same name and with the options the store records:
//!
//! - the anchor mode its optimisation ran in (the `mode` its ingest logged;
//!   that is `--anchors` or the config's `graph.mode` at the time);
//! - for a session placed by `--initial-guess` (alignment method
//!   `initial_guess`): the guess itself is not stored, so its recorded
//!   placement (the guess after ICP) is given as the guess, and a note says so.
//!
//! The configuration is the caller's: the CLI passes the one the source
//! store recorded at its first ingest unless `--config` gives another; the
//! new store records the one it was rebuilt with.
//!
//! Every source folder is checked before anything is written: it must exist
//! and hash to the recorded `content_hash`. The source store is only ever
//! opened read-only. The steps run are whatever [`super::ingest_session`]
//! runs; nothing here depends on the list of steps.

use super::{IngestError, IngestOptions, IngestReceipt, IngestStatus, NoProgress, Progress, ingest_session};
use crate::config::Config;
use crate::geometry::Pose;
use crate::graph::AnchorMode;
use crate::io::{ReadError, ReadErrorKind};
use crate::store::{self, InitOptions, SessionRow, Store, StoreError};
use std::path::{Path, PathBuf};
use std::time::Instant;

#[derive(Debug, thiserror::Error)]
pub enum RebuildError {
    /// A session's source folder is missing, changed or unreadable, or the
    /// session is unfinished in the source store. Found before anything was
    /// written.
    #[error("session {session} {name:?}: {error}")]
    Source { session: i64, name: String, error: Box<ReadError> },
    /// The source store could not be read, or the new store not created.
    #[error(transparent)]
    Store(#[from] StoreError),
    /// Ingesting a session into the new store failed; `done` sessions were
    /// rebuilt before it.
    #[error("session {session} {name:?}: {error}")]
    Ingest { session: i64, name: String, done: usize, error: Box<IngestError> },
}

/// What the caller may change about a rebuild.
#[derive(Debug, Clone, Default)]
pub struct RebuildOptions {
    /// `(old, new)` path prefixes: a recorded source folder under `old` is
    /// read from under `new` instead (the data moved). The longest match wins.
    pub remap: Vec<(PathBuf, PathBuf)>,
    /// Every session's anchor mode (default: each session's recorded mode).
    pub anchor_mode: Option<AnchorMode>,
}

/// One session to ingest again.
#[derive(Debug, Clone, serde::Serialize)]
pub struct PlannedSession {
    /// Its id in the source store.
    pub source_session_id: i64,
    pub name: String,
    /// `source_dir` as the source store recorded it.
    pub recorded_dir: String,
    /// Where it is read from (after `--remap`).
    pub dir: PathBuf,
    pub content_hash: String,
    pub keyframes: i64,
    /// The anchor mode it is optimised in (None: the config's).
    pub anchor_mode: Option<&'static str>,
    /// The `--initial-guess` (`x, y, z, yaw_deg`) its ingest gets, if any.
    pub initial_guess: Option<[f64; 4]>,
    /// What the rebuild could not reproduce exactly, or did differently.
    pub notes: Vec<String>,
    #[serde(skip)]
    pub options: IngestOptions,
}

/// The checked list of sessions, and the new store's settings.
#[derive(Debug, Clone)]
pub struct RebuildPlan {
    pub source: PathBuf,
    pub init: InitOptions,
    pub sessions: Vec<PlannedSession>,
    /// The source's named zones (`seam zones`), copied into the new store
    /// before its first ingest: they are the user's, not computed.
    pub zones: Vec<crate::store::Zone>,
    /// Time spent checking the source folders, s.
    pub verify_s: f64,
}

/// One rebuilt session: the plan and its ingest receipt.
#[derive(Debug, Clone, serde::Serialize)]
pub struct RebuiltSession {
    pub source_session_id: i64,
    pub recorded_dir: String,
    pub anchor_mode: Option<&'static str>,
    pub initial_guess: Option<[f64; 4]>,
    pub notes: Vec<String>,
    #[serde(flatten)]
    pub receipt: IngestReceipt,
}

/// What a rebuild did.
#[derive(Debug, Clone, serde::Serialize)]
pub struct RebuildReport {
    pub source: PathBuf,
    pub out: PathBuf,
    pub sessions: Vec<RebuiltSession>,
    /// Checking every source folder's hash, s.
    pub verify_s: f64,
    /// The ingests, s (the sum of the sessions' `wall_s` and store creation).
    pub ingest_s: f64,
    /// All of it, s.
    pub wall_s: f64,
}

/// Fails like `Store::create` would if `out` exists and is not empty, before
/// any long work.
pub fn check_out(out: &Path) -> Result<(), StoreError> {
    if out.exists() {
        let mut entries = std::fs::read_dir(out).map_err(|e| StoreError::Io { path: out.to_path_buf(), source: e })?;
        if entries.next().is_some() {
            return Err(StoreError::AlreadyExists { path: out.to_path_buf() });
        }
    }
    Ok(())
}

/// `recorded` with the longest matching `old` prefix replaced by its `new`.
pub fn remap_dir(recorded: &str, remap: &[(PathBuf, PathBuf)]) -> PathBuf {
    let path = Path::new(recorded);
    remap
        .iter()
        .filter_map(|(old, new)| {
            let rest = path.strip_prefix(old).ok()?;
            let to = if rest.as_os_str().is_empty() { new.clone() } else { new.join(rest) };
            Some((old.components().count(), to))
        })
        .max_by_key(|(n, _)| *n)
        .map(|(_, p)| p)
        .unwrap_or_else(|| path.to_path_buf())
}

fn source_error(s: &SessionRow, error: ReadError) -> RebuildError {
    RebuildError::Source { session: s.session_id.0, name: s.name.clone(), error: Box::new(error) }
}

/// The anchor mode a session's optimisation logged: `"mode"` in the details
/// of the step that made its last graph version.
fn recorded_anchor_mode(source: &Store, s: &SessionRow) -> Result<Option<AnchorMode>, StoreError> {
    let steps = store::steps(source.conn(), s.session_id)?;
    Ok(steps.iter().rev().find_map(|st| {
        let details: serde_json::Value = serde_json::from_str(&st.details_json).ok()?;
        details.get("graph_version")?;
        match details.get("mode")?.as_str()? {
            "fixed" => Some(AnchorMode::Fixed),
            "session" => Some(AnchorMode::Session),
            "submap" => Some(AnchorMode::Submap),
            _ => None,
        }
    }))
}

/// For a session placed by `--initial-guess`: its recorded placement as a
/// guess `x, y, z, yaw_deg` of its first keyframe (the guess itself is not
/// stored).
fn recorded_guess(source: &Store, s: &SessionRow) -> Result<Option<[f64; 4]>, StoreError> {
    let Some(a) = store::alignment(source.conn(), s.session_id)? else { return Ok(None) };
    if a.method != "initial_guess" {
        return Ok(None);
    }
    let first = store::keyframes(source.conn(), s.session_id)?
        .first()
        .map(|k| k.t_session_keyframe)
        .unwrap_or_else(Pose::identity);
    let world_first = a.t_world_session * first;
    let t = world_first.translation.vector;
    let (_, _, yaw) = world_first.rotation.euler_angles();
    Ok(Some([t.x, t.y, t.z, yaw.to_degrees()]))
}

/// Reads the source store's sessions and checks every source folder: it
/// exists and its content hashes to the recorded hash. Writes nothing.
pub fn plan(source: &mut Store, opts: &RebuildOptions, config: &Config) -> Result<RebuildPlan, RebuildError> {
    let t0 = Instant::now();
    let meta = source.meta()?;
    let init = InitOptions { site_name: meta.site_name, crs: meta.crs, voxel_size_m: meta.voxel_size_m };
    let root = source.root().to_path_buf();
    let mut sessions = Vec::new();
    for s in store::sessions(source.conn())? {
        if s.status != "complete" {
            let error = ReadError::new(
                ReadErrorKind::Unsupported,
                &root,
                format!(
                    "this session is not complete in the store (status {:?}: its ingest was interrupted or is \
                     still running)",
                    s.status
                ),
            )
            .hint(format!(
                "finish it first with `seam ingest {} {}` (it resumes), then run rebuild again",
                root.display(),
                s.source_dir
            ));
            return Err(source_error(&s, error));
        }
        let dir = remap_dir(&s.source_dir, &opts.remap);
        let moved = dir != Path::new(&s.source_dir);
        if !dir.is_dir() {
            let recorded = if moved { format!(" (recorded as {})", s.source_dir) } else { String::new() };
            let relative = if dir.is_relative() {
                "the recorded path is relative to the folder `seam ingest` ran in: run rebuild from there, "
            } else {
                ""
            };
            let error = ReadError::new(ReadErrorKind::Io, &dir, format!("source folder{recorded} no longer exists"))
                .hint(format!(
                    "rebuild reads every session from its original scans: {relative}restore the folder, or, if the \
                     data moved, pass --remap OLD=NEW (OLD a leading part of the recorded path, NEW where that part \
                     is now; repeatable)"
                ));
            return Err(source_error(&s, error));
        }
        // A dry run against the source store (read-only) hashes the folder;
        // it finds the session by hash and stops there when the hash matches.
        // A name no session has, so that a folder whose hash differs is not
        // refused for its name first.
        let dry = IngestOptions {
            name: Some(format!("{}\u{1}rebuild-check", s.name)),
            dry_run: true,
            ..IngestOptions::default()
        };
        let receipt = ingest_session(source, &dir, &dry, config, &NoProgress).map_err(|e| match e {
            IngestError::Read(r) => source_error(&s, r),
            IngestError::Store(st) => RebuildError::Store(st),
            other => source_error(&s, ReadError::new(ReadErrorKind::Unsupported, &dir, other.to_string())),
        })?;
        if receipt.content_hash != s.content_hash {
            let error = ReadError::new(
                ReadErrorKind::Unsupported,
                &dir,
                format!(
                    "content differs from what was ingested (content hash {}…, recorded {}…)",
                    &receipt.content_hash[..receipt.content_hash.len().min(16)],
                    &s.content_hash[..s.content_hash.len().min(16)]
                ),
            )
            .hint(
                "a scan, pose or session.toml file changed, was added or removed since the ingest; restore the \
                 original files (a rebuild must read the same data), or point --remap at a copy of them",
            );
            return Err(source_error(&s, error));
        }
        let recorded_mode = recorded_anchor_mode(source, &s)?;
        let anchor_mode = opts.anchor_mode.or(recorded_mode);
        let initial_guess = recorded_guess(source, &s)?;
        let mut notes = Vec::new();
        if let Some(g) = initial_guess {
            notes.push(format!(
                "placed by --initial-guess, which the store does not record; its recorded placement is the guess \
                 ({:.3},{:.3},{:.3},{:.2})",
                g[0], g[1], g[2], g[3]
            ));
        }
        if let (Some(r), Some(o)) = (recorded_mode, opts.anchor_mode)
            && r != o
        {
            notes.push(format!("anchors {} (--anchors), was {}", o.name(), r.name()));
        } else if recorded_mode.is_none() && opts.anchor_mode.is_none() {
            notes.push("no anchor mode recorded; the config's graph.mode is used".into());
        }
        if moved {
            notes.push(format!("read from {} (recorded {})", dir.display(), s.source_dir));
        }
        let options = IngestOptions {
            name: Some(s.name.clone()),
            dry_run: false,
            initial_guess: initial_guess.map(|g| crate::align::coarse::pose_from_xyz_yaw(g[0], g[1], g[2], g[3])),
            anchor_mode,
        };
        sessions.push(PlannedSession {
            source_session_id: s.session_id.0,
            name: s.name.clone(),
            recorded_dir: s.source_dir.clone(),
            dir,
            content_hash: s.content_hash.clone(),
            keyframes: s.keyframe_count,
            anchor_mode: anchor_mode.map(|m| m.name()),
            initial_guess,
            notes,
            options,
        });
    }
    let zones = crate::store::zones(source.conn())?;
    Ok(RebuildPlan { source: root, init, sessions, zones, verify_s: t0.elapsed().as_secs_f64() })
}

/// Creates `out` and ingests every planned session into it, in order.
/// `on_session(i, planned)` is called before each ingest and
/// `on_done(i, rebuilt)` after it.
pub fn execute(
    plan: &RebuildPlan,
    out: &Path,
    config: &Config,
    progress: &dyn Progress,
    on_session: &mut dyn FnMut(usize, &PlannedSession),
    on_done: &mut dyn FnMut(usize, &RebuiltSession),
) -> Result<RebuildReport, RebuildError> {
    let t0 = Instant::now();
    let mut store = Store::create(out, &plan.init)?;
    store.transaction(|tx| plan.zones.iter().try_for_each(|z| crate::store::insert_zone(tx, &z.name, &z.shape)))?;
    let mut sessions = Vec::with_capacity(plan.sessions.len());
    for (i, p) in plan.sessions.iter().enumerate() {
        on_session(i, p);
        let receipt = ingest_session(&mut store, &p.dir, &p.options, config, progress).map_err(|error| {
            RebuildError::Ingest { session: p.source_session_id, name: p.name.clone(), done: i, error: Box::new(error) }
        })?;
        let mut notes = p.notes.clone();
        if receipt.status != IngestStatus::Ingested {
            notes.push(format!("ingest status {:?}", receipt.status));
        }
        if receipt.session_id != Some(p.source_session_id) {
            notes.push(format!("session {} in the new store", receipt.session_id.unwrap_or(0)));
        }
        let done = RebuiltSession {
            source_session_id: p.source_session_id,
            recorded_dir: p.recorded_dir.clone(),
            anchor_mode: p.anchor_mode,
            initial_guess: p.initial_guess,
            notes,
            receipt,
        };
        on_done(i, &done);
        sessions.push(done);
    }
    drop(store);
    let ingest_s = t0.elapsed().as_secs_f64();
    Ok(RebuildReport {
        source: plan.source.clone(),
        out: out.to_path_buf(),
        sessions,
        verify_s: plan.verify_s,
        ingest_s,
        wall_s: plan.verify_s + ingest_s,
    })
}

/// The whole rebuild: check `out`, plan (check every source folder), then
/// execute. The source store is opened read-only.
pub fn rebuild(
    source: &Path,
    out: &Path,
    opts: &RebuildOptions,
    config: &Config,
    progress: &dyn Progress,
) -> Result<RebuildReport, RebuildError> {
    check_out(out)?;
    let mut src = Store::open_read_only(source)?;
    let plan = plan(&mut src, opts, config)?;
    drop(src);
    execute(&plan, out, config, progress, &mut |_, _| {}, &mut |_, _| {})
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn remap_replaces_the_longest_matching_prefix() {
        let remap = vec![
            (PathBuf::from("/data"), PathBuf::from("/mnt/a")),
            (PathBuf::from("/data/2026"), PathBuf::from("/mnt/b")),
        ];
        assert_eq!(remap_dir("/data/2026/s1", &remap), PathBuf::from("/mnt/b/s1"));
        assert_eq!(remap_dir("/data/2025/s1", &remap), PathBuf::from("/mnt/a/2025/s1"));
        // Whole components only: /database is not under /data.
        assert_eq!(remap_dir("/database/s1", &remap), PathBuf::from("/database/s1"));
        assert_eq!(remap_dir("rel/s1", &[]), PathBuf::from("rel/s1"));
        assert_eq!(remap_dir("/data/2026", &remap).as_os_str(), "/mnt/b");
    }

    #[test]
    fn out_must_be_missing_or_empty() {
        let dir = tempfile::tempdir().unwrap();
        assert!(check_out(&dir.path().join("new")).is_ok());
        assert!(check_out(dir.path()).is_ok());
        std::fs::write(dir.path().join("x"), b"1").unwrap();
        assert!(matches!(check_out(dir.path()), Err(StoreError::AlreadyExists { .. })));
    }
}
