//! Step `changes` (MATH.md §8): fold the new session into the lifelong map.
//!
//! Reads the new session's cleaned maps and evidence back from the files the
//! `evidence` step stored (no ray casting), moves the lifelong map to the
//! graph version `optimize` committed, sorts every voxel into ELite's
//! categories, updates ε_g, and writes the map, the session's change events
//! and its summary in one transaction.

use super::IngestError;
use super::steps::StepCtx;
use crate::change::{LifelongMap, detect};
use crate::evidence::SubmapEvidence;
use crate::evidence::session::{delta, reproject};
use crate::geometry::Pose;
use crate::store::evidence_files::{read_cleaned_map, read_submap_evidence};
use crate::store::{self, SessionId};
use rayon::prelude::*;
use rusqlite::Connection;
use serde_json::{Value, json};
use std::collections::HashMap;
use std::time::Instant;

/// The lifelong map as stored, moved to `version` (each voxel by its owner
/// keyframe's ΔT between the map's version and `version`), and how many
/// voxels merged on the way. Before the first session's `changes` it is an
/// empty map of `voxel_m` voxels.
pub(super) fn placed_map(conn: &Connection, version: i64, voxel_m: f64) -> Result<(LifelongMap, usize), IngestError> {
    let Some(state) = store::map_state(conn)? else {
        return Ok((LifelongMap { voxel_m, voxels: Vec::new() }, 0));
    };
    let map = store::read_lifelong_map(conn)?;
    if state.graph_version == version {
        return Ok((map, 0));
    }
    let mut owners: Vec<i64> = map.voxels.iter().map(|v| v.owner_session).collect();
    owners.sort_unstable();
    owners.dedup();
    let mut deltas: HashMap<(i64, u32), Pose> = HashMap::new();
    for s in owners {
        let then: HashMap<i64, Pose> =
            store::world_poses(conn, state.graph_version, SessionId(s))?.into_iter().collect();
        for (i, now) in store::world_poses(conn, version, SessionId(s))? {
            if let Some(t) = then.get(&i) {
                deltas.insert((s, i as u32), delta(t, &now));
            }
        }
    }
    Ok(map.moved(|s, k| deltas.get(&(s, k)).copied()))
}

pub(super) fn changes(ctx: &mut StepCtx<'_>, step: &'static str, seq: i64) -> Result<Value, IngestError> {
    let started_at = store::now_utc();
    let t0 = Instant::now();
    let session = ctx.session()?;
    let conn = ctx.store.conn();
    let version = store::latest_graph_version(conn)?.ok_or_else(|| store::StoreError::Corrupt {
        path: ctx.store.root().to_path_buf(),
        message: "the changes step found no graph version; optimize must run first".into(),
    })?;
    let ecfg = &ctx.config.evidence;
    let v = ecfg.voxel_size_m;

    let t_move = Instant::now();
    let (map, merged_on_move) = placed_map(conn, version, v)?;
    let move_s = t_move.elapsed().as_secs_f64();

    // The new session's cleaned maps and evidence, on this version's grid.
    let t_read = Instant::now();
    let of_version = |kind: &str| -> Result<Vec<std::path::PathBuf>, IngestError> {
        Ok(store::evidence_files(conn, session, kind)?
            .into_iter()
            .filter(|f| f.graph_version == version)
            .map(|f| ctx.store.path_of(&f.rel_path))
            .collect())
    };
    let cleaned = of_version("cleaned_map")?.par_iter().map(|p| read_cleaned_map(p)).collect::<Result<Vec<_>, _>>()?;
    let tables: Vec<SubmapEvidence> =
        of_version("evidence")?.par_iter().map(|p| read_submap_evidence(p)).collect::<Result<_, _>>()?;
    let refs: Vec<&SubmapEvidence> = tables.iter().collect();
    let evidence = reproject(&refs, v, |_| None);
    drop(tables);
    let read_s = t_read.elapsed().as_secs_f64();

    let t_update = Instant::now();
    let rows = cleaned.iter().flat_map(|m| {
        (0..m.len()).map(move |i| detect::CleanedRow {
            xyz_m: m.xyz_m[i].map(|c| c as f64),
            eps_l: m.eps_l[i],
            points: m.points[i],
            owner_keyframe: m.owner_keyframe[i],
            spread_m2: m.spread_m2[i],
        })
    });
    let new = detect::new_voxels(rows, v, |k| evidence.get(k).map_or(0.0, |r| r.evidence().hit.omega(ecfg) as f32));
    let free_at = |k: u64| {
        evidence.get(k).map(|r| {
            let w = ctx.config.change.deleted_weight(r.evidence().free.omega(ecfg), r.free_n, r.no_return_n);
            (r.free_n, w as f32)
        })
    };
    let next_id = map.max_id() + 1;
    let (map, events, mut stats) = detect::update_map(map, &new, &free_at, session.0, next_id, &ctx.config.change);
    stats.merged_on_move = merged_on_move;
    let update_s = t_update.elapsed().as_secs_f64();

    let details = json!({
        "graph_version": version,
        "new_voxels": new.len(),
        "coexist": stats.coexist,
        "deleted_overlap": stats.deleted_overlap,
        "deleted_non_overlap": stats.deleted_non_overlap,
        "emerged_overlap": stats.emerged_overlap,
        "emerged_non_overlap": stats.emerged_non_overlap,
        "events": stats.events,
        "merged_on_move": stats.merged_on_move,
        "lifelong_voxels": stats.lifelong_voxels,
        "static_voxels": stats.static_voxels,
        "move_s": move_s,
        "read_s": read_s,
        "update_s": update_s,
    });
    ctx.commit(step, seq, (&started_at, t0), |tx| {
        let t_write = Instant::now();
        store::replace_lifelong_map(tx, &map, version, session)?;
        let map_write_s = t_write.elapsed().as_secs_f64();
        store::insert_change_events(tx, &events)?;
        store::insert_session_changes(tx, session, version, &stats)?;
        let mut details = details;
        details["map_write_s"] = json!(map_write_s);
        details["events_write_s"] = json!(t_write.elapsed().as_secs_f64() - map_write_s);
        Ok((session, details))
    })
}
