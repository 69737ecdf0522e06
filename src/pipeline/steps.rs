//! The steps of an ingest. Each is a function that does its work and then
//! commits, in one transaction, its rows and its `step_log` row
//! ([`StepCtx::commit`]). Add a step by writing such a function and listing
//! it in [`STEPS`]; the resume logic needs nothing else.

use super::{IngestError, Progress};
use crate::config::Config;
use crate::fault;
use crate::geometry::Pose;
use crate::io::{SessionSource, read_session_scan};
use crate::store::{self, FileRecord, KeyframeId, NewKeyframe, NewSession, ScanWriter, SessionId, Store, SubmapId};
use rayon::prelude::*;
use rusqlite::Transaction;
use serde_json::{Value, json};
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
    Step { name: "initial_graph", run: initial_graph },
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
}

impl StepCtx<'_> {
    fn session(&self) -> Result<SessionId, IngestError> {
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
    fn commit(
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

/// Step `initial_graph`: a graph version that adds this session from its
/// odometry (MATH.md §1: `A_m = t_world_session · odom_first`,
/// `p_i = odom_first⁻¹ · odom_i`, with `t_world_session = I` until alignment
/// exists) to the newest version of the earlier sessions.
fn initial_graph(ctx: &mut StepCtx<'_>, step: &'static str, seq: i64) -> Result<Value, IngestError> {
    let started_at = store::now_utc();
    let t0 = Instant::now();
    let session = ctx.session()?;
    let conn = ctx.store.conn();
    let kfs = store::keyframes(conn, session)?;
    let submaps = store::submaps(conn, session)?;
    let base = store::latest_graph_version(conn)?;
    let mut anchors: Vec<(SubmapId, Pose)> = Vec::with_capacity(submaps.len());
    let mut locals: Vec<(KeyframeId, Pose)> = Vec::with_capacity(kfs.len());
    for sm in &submaps {
        let members: Vec<_> = kfs
            .iter()
            .filter(|k| k.keyframe_index >= sm.first_keyframe && k.keyframe_index <= sm.last_keyframe)
            .collect();
        let Some(first) = members.first() else { continue };
        let t_world_submap = first.t_session_keyframe;
        anchors.push((sm.submap_id, t_world_submap));
        let inv = t_world_submap.inverse();
        locals.extend(members.iter().map(|k| (k.keyframe_id, inv * k.t_session_keyframe)));
    }
    ctx.commit(step, seq, (&started_at, t0), |tx| {
        let version = store::insert_graph_version(tx, session, "odometry", "{}", base, &anchors, &locals)?;
        Ok((session, json!({ "graph_version": version, "anchors": anchors.len() })))
    })
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
