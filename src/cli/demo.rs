//! `seam demo`: simulate a site, create a store, ingest every session.

use super::output::{json, log, print_json, print_table, thousands};
use super::simulate::{SiteArgs, simulate_site};
use super::{Ctx, UsageError};
use crate::change::places::{SUMMARY_MIN_EVENTS, SessionSummary};
use crate::store::{self, InitOptions, Store};
use clap::Args;
use std::path::PathBuf;

/// Marks a folder as made by `seam demo`, so a re-run may replace it.
const MARKER: &str = ".seam-demo";

#[derive(Debug, Args)]
pub struct DemoArgs {
    /// Folder for the simulated sessions and the store (replaced if an
    /// earlier demo made it).
    #[arg(long, default_value = "seam-demo")]
    pub out: PathBuf,
    #[command(flatten)]
    pub site: SiteArgs,
}

pub fn run(ctx: &Ctx, a: DemoArgs) -> anyhow::Result<()> {
    let cfg = a.site.to_config()?;
    if a.out.exists() {
        if !a.out.join(MARKER).exists() {
            return Err(UsageError(format!(
                "{} exists and was not made by `seam demo`; pass --out with a new folder",
                a.out.display()
            ))
            .into());
        }
        std::fs::remove_dir_all(&a.out)?;
    }
    std::fs::create_dir_all(&a.out)?;
    std::fs::write(a.out.join(MARKER), b"made by seam demo; safe to delete\n")?;
    let t0 = std::time::Instant::now();
    log(
        ctx,
        format!(
            "simulating {} sessions of a construction site ({}, {} keyframes each)...",
            cfg.sessions,
            cfg.sensor.name(),
            cfg.keyframes_per_session
        ),
    );
    let sim = simulate_site(ctx, &a.out.join("sessions"), &cfg)?;
    let store_path = a.out.join("site.seam");
    drop(Store::create(
        &store_path,
        &InitOptions { site_name: "demo site".into(), crs: "local".into(), voxel_size_m: 0.2 },
    )?);
    let mut receipts = Vec::new();
    for s in &sim.sessions {
        let r = super::ingest::ingest_one(ctx, &store_path, &s.dir, &crate::pipeline::IngestOptions::default())?;
        log(
            ctx,
            format!(
                "ingested {} as session {} ({} keyframes, {} points, {:.1} s)",
                s.dir.display(),
                r.session_id.unwrap_or(0),
                r.keyframes,
                thousands(r.points),
                r.wall_s
            ),
        );
        receipts.push(r);
    }
    let store = Store::open_read_only(&store_path)?;
    let sessions = store::sessions(store.conn())?;
    let voxel_m = store::map_state(store.conn())?.map_or(ctx.config.evidence.voxel_size_m, |m| m.voxel_m);
    // Session 1 starts the map; every later one is compared with it.
    let summaries = sessions
        .iter()
        .skip(1)
        .map(|s| SessionSummary::from_store(store.conn(), s.session_id, &s.name, voxel_m))
        .collect::<Result<Vec<_>, _>>()?;
    if json(ctx) {
        return print_json(&serde_json::json!({
            "store": store_path, "sessions": sessions, "receipts": receipts, "changes": summaries,
            "wall_s": t0.elapsed().as_secs_f64(),
        }));
    }
    // How close the aligned poses are to the simulator's truth.
    let eval = crate::eval::align_report(&store, &a.out.join("sessions"), false, &ctx.config.graph)?;
    let rows: Vec<Vec<String>> = sessions
        .iter()
        .zip(&sim.sessions)
        .map(|(s, g)| {
            let method = store::alignment(store.conn(), s.session_id).ok().flatten().map(|a| a.method);
            let ate = eval.sessions.iter().find(|e| e.session as i64 == s.session_id.0);
            vec![
                s.session_id.0.to_string(),
                s.name.clone(),
                s.date.clone().unwrap_or_default(),
                s.keyframe_count.to_string(),
                thousands(s.point_count as u64),
                format!("{:.0}", g.true_path_length_m),
                format!("{:.2}", g.final_drift_m),
                method.unwrap_or_default(),
                ate.map(|e| format!("{:.3}", e.ate_rmse_m)).unwrap_or_default(),
            ]
        })
        .collect();
    print_table(
        &["session", "name", "date", "keyframes", "points", "path_m", "odometry_drift_m", "alignment", "ate_m"],
        &rows,
    );
    println!("\nwhat changed, session by session (places: groups of ≥ {SUMMARY_MIN_EVENTS} changed voxels):");
    for summary in &summaries {
        println!("  {}", summary.sentence());
    }
    println!(
        "\nstore: {}  (try `seam info {0}`, `seam poses {0}`, `seam eval align {0} --gt {}`)",
        store_path.display(),
        a.out.join("sessions").display()
    );
    log(ctx, format!("demo finished in {:.1} s", t0.elapsed().as_secs_f64()));
    Ok(())
}
