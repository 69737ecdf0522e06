//! The steps of an ingest. Each is a function that does its work and then
//! commits, in one transaction, its rows and its `step_log` row
//! ([`StepCtx::commit`]). Add a step by writing such a function and listing
//! it in [`STEPS`]; the resume logic needs nothing else.

use super::{IngestError, Progress};
use crate::align::{self, SessionState, maps::ScanLoader};
use crate::config::Config;
use crate::fault;
use crate::geometry::Pose;
use crate::graph::AnchorMode;
use crate::io::{SessionSource, read_session_scan};
use crate::store::{self, FileRecord, KeyframeRow, NewKeyframe, NewSession, ScanWriter, SessionId, Store};
use rayon::prelude::*;
use rusqlite::Transaction;
use serde_json::{Value, json};
use std::collections::HashSet;
use std::time::Instant;

/// A named step of the ingest pipeline.
pub(super) struct Step {
    pub name: &'static str,
    pub run: fn(&mut StepCtx<'_>, &'static str, i64) -> Result<Value, IngestError>,
}

/// The pipeline, in order.
pub(super) const STEPS: &[Step] = &[
    Step { name: "scans", run: store_scans },
    Step { name: "submaps", run: make_submaps },
    Step { name: "coarse_align", run: coarse_align },
    Step { name: "loops", run: find_loops },
    Step { name: "optimize", run: optimize_graph },
    Step { name: "evidence", run: super::evidence_step::evidence },
    Step { name: "changes", run: super::changes_step::changes },
    Step { name: "complete", run: complete },
];

/// What every step can see.
pub(super) struct StepCtx<'a> {
    pub store: &'a mut Store,
    pub src: &'a SessionSource,
    pub config: &'a Config,
    pub progress: &'a dyn Progress,
    /// Set once the `scans` step has created the session row.
    pub session: Option<SessionId>,
    pub name: String,
    pub content_hash: String,
    /// `--initial-guess`: `t_world_session` for the coarse alignment.
    pub initial_guess: Option<Pose>,
    /// Overrides `config.graph.mode`.
    pub anchor_mode: Option<AnchorMode>,
}

impl StepCtx<'_> {
    pub(super) fn session(&self) -> Result<SessionId, IngestError> {
        self.session.ok_or_else(|| {
            store::StoreError::Corrupt {
                path: self.store.root().to_path_buf(),
                message: "a step ran before the session row existed".into(),
            }
            .into()
        })
    }

    /// Commits a step: `write` adds the step's rows, then the step's log row
    /// is added, then (after the `<step>:before_commit` fault point) the
    /// transaction commits. `write` returns the session id (for the step that
    /// creates it) and the details to log.
    pub(super) fn commit(
        &mut self,
        step: &'static str,
        seq: i64,
        started: (&str, Instant),
        write: impl FnOnce(&Transaction<'_>) -> Result<(SessionId, Value), IngestError>,
    ) -> Result<Value, IngestError> {
        let (started_at, t0) = started;
        let (session, details) = self.store.transaction(|tx| {
            let (session, details) = write(tx)?;
            store::log_step(tx, session, step, seq, started_at, t0.elapsed().as_secs_f64(), &details.to_string())?;
            fault::point(&format!("{step}:before_commit"));
            Ok::<_, IngestError>((session, details))
        })?;
        self.session = Some(session);
        Ok(details)
    }
}

/// Step `scans`: every scan into one Parquet file (one row group per scan),
/// then the session, file and keyframe rows.
fn store_scans(ctx: &mut StepCtx<'_>, step: &'static str, seq: i64) -> Result<Value, IngestError> {
    let started_at = store::now_utc();
    let t0 = Instant::now();
    let id_guess = store::next_session_id(ctx.store.conn())?;
    let rel = format!("{}/scans/session-{id_guess:04}-{}.parquet", store::DATA_DIR, &ctx.content_hash[..16]);
    let mut writer = ScanWriter::create(ctx.store, &rel)?;
    let n = ctx.src.keyframes.len();
    let batch = ctx.config.ingest.read_batch_scans.max(1);
    let mut kfs = Vec::with_capacity(n);
    let mut points = 0u64;
    ctx.progress.begin("store scans", n as u64);
    for start in (0..n).step_by(batch) {
        let end = (start + batch).min(n);
        let scans =
            (start..end).into_par_iter().map(|i| read_session_scan(ctx.src, i)).collect::<Result<Vec<_>, _>>()?;
        for (i, scan) in (start..end).zip(scans) {
            let row_group = writer.write_scan(&scan)?;
            let k = &ctx.src.keyframes[i];
            points += scan.len() as u64;
            kfs.push(NewKeyframe {
                keyframe_index: k.index as i64,
                source_file: k.scan_path.file_name().map(|f| f.to_string_lossy().into_owned()).unwrap_or_default(),
                stamp_s: k.stamp_s,
                point_count: scan.len() as i64,
                scan_row_group: row_group as i64,
                t_session_keyframe: k.t_session_sensor,
            });
            ctx.progress.advance(1);
        }
    }
    ctx.progress.end();
    let record: FileRecord = writer.finish()?;
    let meta = &ctx.src.meta;
    let fov_json = meta.fov.map(|f| serde_json::to_string(&f).unwrap_or_default());
    let source_dir = ctx.src.dir.display().to_string();
    let root = ctx.store.root().to_path_buf();
    let (name, hash) = (ctx.name.clone(), ctx.content_hash.clone());
    let config_json = ctx.config.to_recorded();
    let new = NewSession {
        name: &name,
        content_hash: &hash,
        source_dir: &source_dir,
        layout: ctx.src.layout.name(),
        date: meta.date.as_deref(),
        sensor_model: meta.sensor_model.map(|m| m.name()),
        fov_json: fov_json.as_deref(),
        keyframe_count: n as i64,
        point_count: points as i64,
    };
    ctx.commit(step, seq, (&started_at, t0), |tx| {
        let session = store::insert_session(tx, &new)?;
        // The first session binds the store to its configuration (a store
        // from before seam recorded one is bound by its next session).
        if session.0 == 1 || store::recorded_config(tx, &root)?.is_none() {
            store::record_config(tx, &root, &config_json)?;
        }
        let file_id = store::insert_file(tx, &root, &record, Some(session.0))?;
        store::insert_keyframes(tx, session, file_id, &kfs)?;
        Ok((session, json!({ "file": record.rel_path, "bytes": record.size_bytes, "points": points, "scans": n })))
    })
}

/// Step `submaps`: cut by travel distance (MATH.md §1).
fn make_submaps(ctx: &mut StepCtx<'_>, step: &'static str, seq: i64) -> Result<Value, IngestError> {
    let started_at = store::now_utc();
    let t0 = Instant::now();
    let session = ctx.session()?;
    let kfs = store::keyframes(ctx.store.conn(), session)?;
    let poses: Vec<Pose> = kfs.iter().map(|k| k.t_session_keyframe).collect();
    let spans: Vec<(i64, i64, f64)> = super::cut_submaps(&poses, &ctx.config.submap)
        .into_iter()
        .map(|(a, b, len)| (kfs[a].keyframe_index, kfs[b].keyframe_index, len))
        .collect();
    let submap_length_m = ctx.config.submap.submap_length_m;
    ctx.commit(step, seq, (&started_at, t0), |tx| {
        store::insert_submaps(tx, session, &spans)?;
        Ok((session, json!({ "submaps": spans.len(), "submap_length_m": submap_length_m })))
    })
}

/// The sessions alignment works on: every complete session and this one,
/// with poses from the newest graph version.
pub(super) fn alignment_state(ctx: &StepCtx<'_>) -> Result<(Vec<SessionState>, usize), IngestError> {
    let session = ctx.session()?;
    let version = store::latest_graph_version(ctx.store.conn())?;
    let mut sessions = align::load_sessions(ctx.store, version)?;
    sessions.retain(|s| s.row.status == "complete" || s.id() == session);
    let new = sessions.iter().position(|s| s.id() == session).ok_or_else(|| store::StoreError::Corrupt {
        path: ctx.store.root().to_path_buf(),
        message: format!("session {} has no rows to align", session.0),
    })?;
    Ok((sessions, new))
}

/// Step `coarse_align` (MATH.md §2): where the new session's frame sits in
/// the world. The first session is the reference; later ones are registered
/// map-to-map against the earlier sessions' merged map (or placed by
/// `--initial-guess`). Commits the alignment row and a graph version that
/// adds the session at `t_world_session · odometry`.
fn coarse_align(ctx: &mut StepCtx<'_>, step: &'static str, seq: i64) -> Result<Value, IngestError> {
    let started_at = store::now_utc();
    let t0 = Instant::now();
    let session = ctx.session()?;
    let (sessions, new) = alignment_state(ctx)?;
    let loader = ScanLoader::new(ctx.store)?;
    let cc = &ctx.config.coarse;
    let stride = cc.map_keyframe_stride.max(1);
    let row = if !sessions.iter().enumerate().any(|(i, s)| i != new && s.aligned) {
        align::coarse::reference(session)
    } else {
        ctx.progress.begin("coarse alignment", 3);
        let earlier: Vec<(&KeyframeRow, Pose)> = sessions
            .iter()
            .enumerate()
            .filter(|(i, s)| *i != new && s.aligned)
            .flat_map(|(_, s)| s.keyframes.iter().step_by(stride).map(|k| (&k.row, k.t_world_keyframe)))
            .collect();
        let world_map = align::maps::merged_map(&loader, &earlier, cc.map_voxel_m)?;
        ctx.progress.advance(1);
        let mine: Vec<(&KeyframeRow, Pose)> =
            sessions[new].keyframes.iter().step_by(stride).map(|k| (&k.row, k.row.t_session_keyframe)).collect();
        let session_map = align::maps::merged_map(&loader, &mine, cc.map_voxel_m)?;
        ctx.progress.advance(1);
        let first = sessions[new].keyframes.first().map(|k| k.row.t_session_keyframe).unwrap_or_else(Pose::identity);
        let guess = ctx.initial_guess.map(|g| (g, first));
        let row = align::coarse::coarse_align(session, &world_map, &session_map, guess, &ctx.config.global);
        ctx.progress.advance(1);
        ctx.progress.end();
        row
    };
    let t_world_session = row.t_world_session;
    let placed = vec![sessions[new].keyframes.iter().map(|k| t_world_session * k.row.t_session_keyframe).collect()];
    let (anchors, locals) = align::graph::to_version_rows(std::slice::from_ref(&sessions[new]), &placed);
    let base = store::latest_graph_version(ctx.store.conn())?;
    let details = json!({
        "method": row.method,
        "success": row.success,
        "reason": row.reason,
        "inliers": row.inliers,
        "inlier_ratio": row.inlier_ratio,
        "overlap_fraction": row.overlap_fraction,
    });
    ctx.commit(step, seq, (&started_at, t0), |tx| {
        store::insert_alignment(tx, &row)?;
        let version =
            store::insert_graph_version(tx, session, "coarse", &details.to_string(), base, &anchors, &locals)?;
        let mut details = details;
        details["graph_version"] = json!(version);
        Ok((session, details))
    })
}

/// Step `loops` (MATH.md §3-4): intra- and inter-session candidates of the
/// new session, each registered with GICP and judged; every candidate is
/// stored with its verdict and reason.
fn find_loops(ctx: &mut StepCtx<'_>, step: &'static str, seq: i64) -> Result<Value, IngestError> {
    let started_at = store::now_utc();
    let t0 = Instant::now();
    let session = ctx.session()?;
    let (sessions, new) = alignment_state(ctx)?;
    let loader = ScanLoader::new(ctx.store)?;
    let aligned = sessions[new].aligned;
    let cfg = &ctx.config.loops;
    let mut candidates = align::loops::intra_candidates(&sessions, new, cfg);
    let intra = candidates.len();
    if aligned {
        candidates.extend(align::loops::inter_candidates(&sessions, new, cfg));
    }
    let first = sessions[new].keyframes.first().map(|k| &k.row);
    let fov = align::session_fov(&sessions[new].row, || first.and_then(|k| loader.load(k).ok()).map(|s| s.points));
    let rows = align::loops::evaluate(&loader, &sessions, &candidates, session, &fov, cfg, ctx.progress)?;
    let accepted = |kind: &str| rows.iter().filter(|r| r.accepted && r.kind == kind).count();
    let details = json!({
        "intra_candidates": intra,
        "inter_candidates": candidates.len() - intra,
        "intra_accepted": accepted("intra"),
        "inter_accepted": accepted("inter"),
        "inter_skipped_unaligned": !aligned,
    });
    ctx.commit(step, seq, (&started_at, t0), |tx| {
        store::insert_loops(tx, &rows)?;
        Ok((session, details))
    })
}

/// Step `optimize` (MATH.md §5): all sessions jointly, odometry plus every
/// accepted loop, in the configured anchor mode; a new graph version.
fn optimize_graph(ctx: &mut StepCtx<'_>, step: &'static str, seq: i64) -> Result<Value, IngestError> {
    let started_at = store::now_utc();
    let t0 = Instant::now();
    let session = ctx.session()?;
    let (sessions, _) = alignment_state(ctx)?;
    let loops = store::loops(ctx.store.conn(), true)?;
    let mode = ctx.anchor_mode.unwrap_or(ctx.config.graph.mode);
    let frozen: HashSet<SessionId> = sessions.iter().map(|s| s.id()).filter(|&id| id != session).collect();
    let initial = align::graph::current(&sessions);
    ctx.progress.begin("optimize", 1);
    let solved = align::graph::solve(&sessions, &initial, &loops, mode, &frozen, &ctx.config.graph);
    ctx.progress.end();
    let (world, details) = match solved {
        Ok((world, report, used)) => {
            let moved = max_move(&initial, &world);
            (world, json!({ "mode": mode.name(), "loops": used, "report": report, "max_keyframe_move_m": moved }))
        }
        // A graph the solver cannot handle keeps the current estimate; the
        // step's details (in the step log and the ingest receipt) say so.
        Err(e) => (initial, json!({ "mode": mode.name(), "error": e.to_string() })),
    };
    let (anchors, locals) = align::graph::to_version_rows(&sessions, &world);
    let base = store::latest_graph_version(ctx.store.conn())?;
    ctx.commit(step, seq, (&started_at, t0), |tx| {
        let version =
            store::insert_graph_version(tx, session, mode.name(), &details.to_string(), base, &anchors, &locals)?;
        let mut details = details;
        details["graph_version"] = json!(version);
        Ok((session, details))
    })
}

/// The largest distance any keyframe moved between two estimates, m.
fn max_move(a: &align::graph::WorldPoses, b: &align::graph::WorldPoses) -> f64 {
    a.iter()
        .zip(b)
        .flat_map(|(x, y)| x.iter().zip(y).map(|(p, q)| (p.translation.vector - q.translation.vector).norm()))
        .fold(0.0, f64::max)
}

/// Step `complete`: marks the session complete.
fn complete(ctx: &mut StepCtx<'_>, step: &'static str, seq: i64) -> Result<Value, IngestError> {
    let started_at = store::now_utc();
    let t0 = Instant::now();
    let session = ctx.session()?;
    ctx.commit(step, seq, (&started_at, t0), |tx| {
        store::set_session_complete(tx, session)?;
        Ok((session, json!({})))
    })
}
