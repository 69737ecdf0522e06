//! `seam eval dor`: a stored session's DOR verdicts (or another tool's, as
//! SemanticKITTI label files) scored against ground-truth labels, with the
//! points placed by the store's current poses.

use super::EvalError;
use super::dor::{DOR_VOXEL_M, DorAccumulator, DorScores, moving_flags, read_keyframe_labels};
use crate::align::maps::ScanLoader;
use crate::geometry::transformed;
use crate::store::evidence_files::read_point_labels;
use crate::store::{self, Store};
use std::collections::HashMap;
use std::path::Path;

/// What `seam eval dor` prints.
#[derive(Debug, Clone, serde::Serialize)]
pub struct DorReport {
    pub session: String,
    /// `store` (the session's own labels) or the `--predicted` folder.
    pub predicted: String,
    pub model: Option<String>,
    pub points: u64,
    /// Wall time of the session's evidence step (reading its scans, ray
    /// casting, DOR, writing its files).
    pub evidence_s: Option<f64>,
    pub points_per_s: Option<f64>,
    /// The same step without its reading of the scans, moving of the
    /// lifelong map and writing of files: ray casting, evidence, DOR and the
    /// cleaned map with everything in memory (the step log's `generate_s`),
    /// which is what a tool timed on preloaded scans is compared with.
    pub in_memory_s: Option<f64>,
    pub in_memory_points_per_s: Option<f64>,
    pub scores: DorScores,
}

/// Scores the DOR of `session` (by name; the only session when `None`).
pub fn dor_report(
    store: &Store,
    labels: &Path,
    session: Option<&str>,
    predicted: Option<&Path>,
) -> Result<DorReport, EvalError> {
    let conn = store.conn();
    let sessions = store::sessions(conn)?;
    let names = || sessions.iter().map(|s| s.name.as_str()).collect::<Vec<_>>().join(", ");
    let row = match session {
        Some(n) => sessions
            .iter()
            .find(|s| s.name == n)
            .ok_or_else(|| EvalError::Mismatch(format!("no session named {n:?}; the store has: {}", names())))?,
        None if sessions.len() == 1 => &sessions[0],
        None => {
            return Err(EvalError::Mismatch(format!(
                "the store has {} sessions ({}); name one with --session",
                sessions.len(),
                names()
            )));
        }
    };
    let id = row.session_id;
    let version = store::latest_graph_version(conn)?
        .ok_or_else(|| EvalError::Mismatch(format!("session {} has no poses yet; finish its ingest", row.name)))?;
    let poses: HashMap<i64, _> = store::world_poses(conn, version, id)?.into_iter().collect();
    let keyframes = store::keyframes(conn, id)?;
    let dor = store::session_dor(conn, id)?;
    // The store's own verdicts by keyframe (empty when scoring `--predicted`).
    let mut own: HashMap<i32, Vec<bool>> = match predicted {
        Some(_) => HashMap::new(),
        None => {
            let files = store::evidence_files(conn, id, "point_labels")?;
            let f = files.last().ok_or_else(|| {
                EvalError::Mismatch(format!(
                    "session {} has no DOR labels; it was ingested before the evidence step existed or its ingest \
                     did not finish (re-run `seam ingest`)",
                    row.name
                ))
            })?;
            let l = read_point_labels(&store.path_of(&f.rel_path))?;
            let mut by_kf: HashMap<i32, Vec<bool>> = HashMap::new();
            for i in 0..l.len() {
                let v = by_kf.entry(l.keyframe[i]).or_default();
                let j = l.point_index[i] as usize;
                if v.len() <= j {
                    v.resize(j + 1, false);
                }
                v[j] = l.dynamic[i];
            }
            by_kf
        }
    };
    let loader = ScanLoader::new(store)?;
    let mut acc = DorAccumulator::new(DOR_VOXEL_M);
    for kf in &keyframes {
        let scan = loader.load(kf)?;
        let n = scan.points.len();
        let truth = read_keyframe_labels(labels, kf.keyframe_index as u64, n)?;
        let removed = match predicted {
            Some(dir) => moving_flags(&read_keyframe_labels(dir, kf.keyframe_index as u64, n)?),
            None => {
                let v = own.remove(&(kf.keyframe_index as i32)).unwrap_or_default();
                if v.len() != n {
                    return Err(EvalError::Mismatch(format!(
                        "keyframe {} of session {} has {n} points but {} stored labels; the store is damaged (run \
                         `seam check`)",
                        kf.keyframe_index,
                        row.name,
                        v.len()
                    )));
                }
                v
            }
        };
        let pose = poses.get(&kf.keyframe_index).ok_or_else(|| {
            EvalError::Mismatch(format!(
                "keyframe {} of {} has no pose in version {version}",
                kf.keyframe_index, row.name
            ))
        })?;
        acc.add_labelled_scan(kf.keyframe_index as u32, &transformed(&scan.points, pose), &truth, &removed)?;
    }
    let points = acc.points();
    let step = store::steps(conn, id)?.into_iter().find(|s| s.step == "evidence");
    let step_s = step.as_ref().map(|s| s.wall_s);
    let in_memory_s =
        step.and_then(|s| serde_json::from_str::<serde_json::Value>(&s.details_json).ok()?.get("generate_s")?.as_f64());
    let per_s = |t: Option<f64>| t.filter(|s| *s > 0.0).map(|s| points as f64 / s);
    Ok(DorReport {
        session: row.name.clone(),
        predicted: predicted.map_or("store".into(), |p| p.display().to_string()),
        model: dor.map(|d| d.model),
        points,
        evidence_s: step_s,
        points_per_s: per_s(step_s),
        in_memory_s,
        in_memory_points_per_s: per_s(in_memory_s),
        scores: acc.finish(),
    })
}
