//! `seam sessions site.seam` and `seam info site.seam`

use super::Ctx;
use super::output::{json, print_json, print_table, thousands};
use crate::store::{self, Store};
use clap::Args;
use std::path::PathBuf;

#[derive(Debug, Args)]
pub struct StoreArg {
    /// The store.
    pub store: PathBuf,
}

pub fn run_sessions(ctx: &Ctx, a: StoreArg) -> anyhow::Result<()> {
    let store = Store::open_read_only(&a.store)?;
    let sessions = store::sessions(store.conn())?;
    if json(ctx) {
        return print_json(&sessions);
    }
    let mut rows = Vec::new();
    for s in &sessions {
        let submaps = store::submaps(store.conn(), s.session_id)?.len();
        rows.push(vec![
            s.session_id.0.to_string(),
            s.name.clone(),
            s.date.clone().unwrap_or_else(|| "-".into()),
            s.sensor_model.clone().unwrap_or_else(|| "-".into()),
            s.keyframe_count.to_string(),
            submaps.to_string(),
            thousands(s.point_count as u64),
            s.status.clone(),
            s.source_dir.clone(),
        ]);
    }
    print_table(&["session", "name", "date", "sensor", "keyframes", "submaps", "points", "status", "source"], &rows);
    Ok(())
}

fn dir_size(p: &std::path::Path) -> u64 {
    let Ok(rd) = std::fs::read_dir(p) else { return 0 };
    rd.flatten()
        .map(|e| {
            let p = e.path();
            if p.is_dir() { dir_size(&p) } else { e.metadata().map(|m| m.len()).unwrap_or(0) }
        })
        .sum()
}

pub fn run_info(ctx: &Ctx, a: StoreArg) -> anyhow::Result<()> {
    let store = Store::open_read_only(&a.store)?;
    let meta = store.meta()?;
    let counts = store::table_counts(store.conn())?;
    let points: i64 = store::sessions(store.conn())?.iter().map(|s| s.point_count).sum();
    let bytes = dir_size(store.root());
    let alignment = alignment_rows(&store)?;
    // The configuration the sessions were ingested with, and how it
    // departs from seam's defaults (`None` before the first ingest).
    let config = match store.recorded_config()? {
        Some(text) => Some(crate::config::Config::from_recorded(&text, store.root())?),
        None => None,
    };
    let not_default = config.as_ref().map(|c| c.differences(&crate::config::Config::default()));
    if json(ctx) {
        let counts: serde_json::Map<String, serde_json::Value> =
            counts.iter().map(|(k, v)| (k.clone(), (*v).into())).collect();
        return print_json(&serde_json::json!({
            "meta": meta, "tables": counts, "points": points, "size_bytes": bytes, "alignment": alignment,
            "bytes_per_million_points": if points > 0 { bytes as f64 * 1e6 / points as f64 } else { 0.0 },
            "config": config, "config_not_default": not_default,
        }));
    }
    println!("store           {}", a.store.display());
    println!("site            {}", meta.site_name);
    println!("crs             {}", meta.crs);
    println!("voxel           {} m", meta.voxel_size_m);
    println!("schema          v{} (seam {})", meta.schema_version, meta.tool_version);
    println!("created         {}", meta.created_at);
    for (t, n) in counts {
        println!("{t:<15} {}", thousands(n as u64));
    }
    println!("points          {}", thousands(points as u64));
    let per_m = if points > 0 {
        format!(" ({:.1} MB per million points)", bytes as f64 / points as f64)
    } else {
        String::new()
    };
    println!("size            {:.1} MB{per_m}", bytes as f64 / 1e6);
    match &not_default {
        None => println!("config          not recorded yet (the first ingest records it)"),
        Some(d) if d.is_empty() => println!("config          seam's defaults"),
        Some(d) => {
            println!("config          seam's defaults but (value, then the default in brackets):");
            for line in d {
                println!("                  {line}");
            }
        }
    }
    if !alignment.is_empty() {
        println!();
        let rows: Vec<Vec<String>> = alignment
            .iter()
            .map(|a| {
                vec![
                    a.session.to_string(),
                    a.name.clone(),
                    a.method.clone(),
                    format!("{}/{}", a.inter_accepted, a.inter_candidates),
                    format!("{}/{}", a.intra_accepted, a.intra_candidates),
                    a.reason.clone(),
                ]
            })
            .collect();
        super::output::print_table(&["session", "name", "alignment", "inter loops", "intra loops", "note"], &rows);
    }
    Ok(())
}

/// How each session was placed and how many of its loop candidates held.
#[derive(serde::Serialize)]
struct AlignmentSummary {
    session: i64,
    name: String,
    method: String,
    reason: String,
    inter_candidates: i64,
    inter_accepted: i64,
    intra_candidates: i64,
    intra_accepted: i64,
}

fn alignment_rows(store: &Store) -> anyhow::Result<Vec<AlignmentSummary>> {
    let conn = store.conn();
    let loops = store::loops(conn, false)?;
    let mut out = Vec::new();
    for s in store::sessions(conn)? {
        let Some(a) = store::alignment(conn, s.session_id)? else { continue };
        let count = |kind: &str, accepted: bool| {
            loops.iter().filter(|l| l.session_id == s.session_id && l.kind == kind && (!accepted || l.accepted)).count()
                as i64
        };
        out.push(AlignmentSummary {
            session: s.session_id.0,
            name: s.name.clone(),
            method: a.method.clone(),
            reason: if a.method == "reference" { String::new() } else { a.reason.clone() },
            inter_candidates: count("inter", false),
            inter_accepted: count("inter", true),
            intra_candidates: count("intra", false),
            intra_accepted: count("intra", true),
        });
    }
    Ok(out)
}
