//! Step `evidence` (MATH.md §6-7): ray cast the new session on the graph
//! version `optimize` just committed, remove its movers, store its evidence,
//! cleaned maps and point labels, and reproject every earlier session's
//! stored evidence to that version (nothing earlier is ray cast again).
//!
//! Files, all immutable and recorded in `evidence_files` with the graph
//! version they were generated from:
//! - `data/evidence/s<session>/m<submap>_v<version>.parquet`: per submap
//! - `data/cleaned/s<session>/m<submap>_v<version>.parquet`: per submap
//! - `data/labels/s<session>_v<version>.parquet`: every point's verdict

use super::IngestError;
use super::steps::{StepCtx, alignment_state};
use crate::align::maps::ScanLoader;
use crate::evidence::grid::pack;
use crate::evidence::session::{self, KeyframeInput, delta, reproject, reproject_cleaned};
use crate::evidence::surface::MapPatch;
use crate::evidence::{EvidenceModel, SubmapEvidence};
use crate::geometry::Pose;
use crate::sensor::SensorModel;
use crate::store::evidence_files::{
    read_cleaned_map, read_submap_evidence, write_cleaned_map, write_point_labels, write_submap_evidence,
};
use crate::store::{self, FileRecord, SubmapId};
use rayon::prelude::*;
use serde_json::{Value, json};
use std::collections::HashMap;
use std::time::Instant;

pub(super) fn evidence(ctx: &mut StepCtx<'_>, step: &'static str, seq: i64) -> Result<Value, IngestError> {
    let started_at = store::now_utc();
    let t0 = Instant::now();
    let session = ctx.session()?;
    let cfg = &ctx.config.evidence;
    let version = store::latest_graph_version(ctx.store.conn())?.ok_or_else(|| store::StoreError::Corrupt {
        path: ctx.store.root().to_path_buf(),
        message: "the evidence step found no graph version; optimize must run first".into(),
    })?;
    let (sessions, new) = alignment_state(ctx)?;
    let state = &sessions[new];

    // The new session's scans, read in parallel, and its submap ordinals.
    let submaps = store::submaps(ctx.store.conn(), session)?;
    let ordinal: HashMap<SubmapId, usize> = submaps.iter().map(|s| (s.submap_id, s.submap_index as usize)).collect();
    let loader = ScanLoader::new(ctx.store)?;
    let t_read = Instant::now();
    ctx.progress.begin("read scans", state.keyframes.len() as u64);
    let scans = state
        .keyframes
        .par_iter()
        .map(|k| {
            let s = loader.load(&k.row).map(|s| s.points);
            ctx.progress.advance(1);
            s
        })
        .collect::<Result<Vec<_>, _>>()?;
    ctx.progress.end();
    let read_s = t_read.elapsed().as_secs_f64();
    let inputs: Vec<KeyframeInput<'_>> = state
        .keyframes
        .iter()
        .zip(&scans)
        .map(|(k, pts)| KeyframeInput {
            index: k.row.keyframe_index as u32,
            submap: k.row.submap_id.and_then(|id| ordinal.get(&id).copied()).unwrap_or(0),
            t_world_keyframe: k.t_world_keyframe,
            points: pts,
        })
        .collect();
    // The lifelong map's voxels, moved to this version, are kept as interest
    // too: change detection asks whether this session saw them free, which
    // takes a ray through the patch of points each had.
    let (map, _) = super::changes_step::placed_map(ctx.store.conn(), version, cfg.voxel_size_m)?;
    let sensor_at: HashMap<(i64, u32), [f64; 3]> = sessions
        .iter()
        .flat_map(|s| {
            s.keyframes
                .iter()
                .map(move |k| ((s.id().0, k.row.keyframe_index as u32), k.t_world_keyframe.translation.vector.into()))
        })
        .collect();
    let map_patches: Vec<MapPatch> = map
        .voxels
        .iter()
        .filter_map(|v| {
            let seen_from_m = sensor_at
                .get(&(v.owner_session, v.owner_keyframe))
                .map_or(f64::INFINITY, |o: &[f64; 3]| (0..3).map(|a| (v.xyz_m[a] - o[a]).powi(2)).sum::<f64>().sqrt());
            Some(MapPatch { key: pack(v.key)?, xyz_m: v.xyz_m, points: v.points, spread_m2: v.spread_m2, seen_from_m })
        })
        .collect();
    drop(map);
    ctx.progress.begin("ray cast", inputs.len() as u64);
    let fov = crate::align::session_fov(&state.row, || scans.first().cloned());
    // The no-return window follows the sensor's beam spacing where seam
    // knows its beams.
    let spacing =
        state.row.sensor_model.as_deref().and_then(SensorModel::parse).and_then(SensorModel::beam_spacing_deg);
    let out = session::generate(&inputs, &map_patches, Some(&fov), &cfg.for_beam_spacing(spacing), |_| {
        ctx.progress.advance(1)
    });
    ctx.progress.end();
    drop(inputs);
    drop(scans);

    // Earlier sessions: reproject their stored evidence and cleaned maps.
    let t_re = Instant::now();
    let mut reprojected_voxels = 0usize;
    let mut reprojected_rows = 0usize;
    let mut reprojected_cleaned = 0usize;
    for earlier in sessions.iter().filter(|s| s.id() != session) {
        let conn = ctx.store.conn();
        let files = store::evidence_files(conn, earlier.id(), "evidence")?;
        let cleaned = store::evidence_files(conn, earlier.id(), "cleaned_map")?;
        let now: HashMap<u32, Pose> =
            earlier.keyframes.iter().map(|k| (k.row.keyframe_index as u32, k.t_world_keyframe)).collect();
        // ΔT_i = W_now,i · W_gen,i⁻¹ of every keyframe, for each graph version
        // some file of this session was generated from (eq. 10).
        let mut deltas: HashMap<i64, HashMap<u32, Pose>> = HashMap::new();
        for g in files.iter().chain(&cleaned).map(|f| f.graph_version) {
            if let std::collections::hash_map::Entry::Vacant(v) = deltas.entry(g) {
                let at_gen = store::world_poses(conn, g, earlier.id())?;
                v.insert(
                    at_gen
                        .into_iter()
                        .filter_map(|(i, p)| Some((i as u32, delta(&p, now.get(&(i as u32))?))))
                        .collect(),
                );
            }
        }
        for (g, d) in &deltas {
            let paths: Vec<std::path::PathBuf> =
                files.iter().filter(|f| f.graph_version == *g).map(|f| ctx.store.path_of(&f.rel_path)).collect();
            let tables: Vec<SubmapEvidence> =
                paths.par_iter().map(|p| read_submap_evidence(p)).collect::<Result<_, _>>()?;
            let refs: Vec<&SubmapEvidence> = tables.iter().collect();
            reprojected_rows += refs.iter().map(|t| t.len()).sum::<usize>();
            reprojected_voxels += reproject(&refs, cfg.voxel_size_m, |kf| d.get(&kf).copied()).len();
        }
        for f in &cleaned {
            let m = read_cleaned_map(&ctx.store.path_of(&f.rel_path))?;
            let d = &deltas[&f.graph_version];
            reprojected_cleaned += reproject_cleaned(&m, |kf| d.get(&kf).copied()).len();
        }
    }
    let reproject_s = t_re.elapsed().as_secs_f64();

    // Publish the files, then record them with the step in one transaction.
    // Each file is compressed and synced on one thread, so they are written
    // side by side.
    let t_write = Instant::now();
    let by_ordinal: HashMap<usize, SubmapId> = ordinal.iter().map(|(id, o)| (*o, *id)).collect();
    let root = ctx.store.root();
    let s = session.0;
    type Published = (FileRecord, Option<SubmapId>, usize);
    let write_submaps = || -> Result<Vec<Published>, IngestError> {
        let evidence = out.submaps.par_iter().enumerate().map(|(o, table)| {
            let rel = format!("data/evidence/s{s:04}/m{o:04}_v{version}.parquet");
            Ok((write_submap_evidence(root, &rel, table)?, by_ordinal.get(&o).copied(), table.len()))
        });
        let cleaned = out.cleaned.par_iter().enumerate().map(|(o, map)| {
            let rel = format!("data/cleaned/s{s:04}/m{o:04}_v{version}.parquet");
            Ok((write_cleaned_map(root, &rel, map)?, by_ordinal.get(&o).copied(), map.len()))
        });
        evidence.chain(cleaned).collect()
    };
    let write_labels = || -> Result<Published, IngestError> {
        let rel = format!("data/labels/s{s:04}_v{version}.parquet");
        Ok((write_point_labels(root, &rel, &out.labels)?, None, out.labels.len()))
    };
    let (submap_files, labels_file) = rayon::join(write_submaps, write_labels);
    let mut published = submap_files?;
    published.push(labels_file?);
    let write_s = t_write.elapsed().as_secs_f64();

    let model = match cfg.model {
        EvidenceModel::Directional => "directional",
        EvidenceModel::LogOdds => "log_odds",
    };
    let st = &out.stats;
    let details = json!({
        "graph_version": version,
        "model": model,
        "points": st.points,
        "dynamic_points": st.dynamic_points,
        "grown_points": st.grown_points,
        "interest_voxels": st.interest_voxels,
        "map_interest_voxels": map_patches.len(),
        "generated_voxels": st.generated_voxels,
        "dynamic_voxels": st.dynamic_voxels,
        "cleaned_voxels": st.cleaned_voxels,
        "skipped_rays": st.skipped_rays,
        "no_return_voxels": st.no_return_voxels,
        "own_no_return_voxels": st.own_no_return_voxels,
        "prepare_s": st.prepare_s,
        "raycast_s": st.raycast_s,
        "dor_s": st.dor_s,
        "cleaned_s": st.cleaned_s,
        "generate_s": st.total_s,
        "reprojected_rows": reprojected_rows,
        "reprojected_voxels": reprojected_voxels,
        "reprojected_cleaned_points": reprojected_cleaned,
        "reproject_s": reproject_s,
        "read_s": read_s,
        "write_s": write_s,
    });
    let root = ctx.store.root().to_path_buf();
    ctx.commit(step, seq, (&started_at, t0), |tx| {
        for (rec, submap, rows) in &published {
            let id = store::insert_file(tx, &root, rec, Some(session.0))?;
            store::insert_evidence_file(tx, id, session, *submap, &rec.kind, version, *rows)?;
        }
        store::insert_session_dor(tx, session, version, model, st)?;
        Ok((session, details))
    })
}
