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
    if json(ctx) {
        let counts: serde_json::Map<String, serde_json::Value> =
            counts.iter().map(|(k, v)| (k.clone(), (*v).into())).collect();
        return print_json(&serde_json::json!({
            "meta": meta, "tables": counts, "points": points, "size_bytes": bytes,
            "bytes_per_million_points": if points > 0 { bytes as f64 * 1e6 / points as f64 } else { 0.0 },
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
    Ok(())
}
