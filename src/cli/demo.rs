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
    let cfg = a.site.to_config(super::simulate::DEMO_KEYFRAMES)?;
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
    drop(store);
    ask_questions(ctx, &store_path, &summaries)?;
    let report = crate::render::report::write_report(
        &store_path,
        &a.out.join("report.html"),
        &crate::render::report::ReportOptions::default(),
    )?;
    println!(
        "\nreport: {} ({} pictures, {:.1} MB; open it in a browser)",
        report.path,
        report.pictures.len(),
        report.bytes as f64 / 1e6
    );
    println!(
        "store: {}  (try `seam info {0}`, `seam poses {0}`, `seam eval align {0} --gt {}`)",
        store_path.display(),
        a.out.join("sessions").display()
    );
    log(ctx, format!("demo finished in {:.1} s", t0.elapsed().as_secs_f64()));
    Ok(())
}

/// The zone the demo's questions name: the largest place that appeared in the
/// last session, grown by 2 m (a site manager would draw it around the new
/// work).
pub const DEMO_ZONE: &str = "new work";

/// Adds [`DEMO_ZONE`] and asks the store a few of the questions in `queries/`,
/// printing each as the command a user would type and its answer.
fn ask_questions(ctx: &Ctx, store_path: &std::path::Path, summaries: &[SessionSummary]) -> anyhow::Result<()> {
    let last = summaries.last();
    let biggest = last.and_then(|s| s.appeared.places.first().or(s.removed.places.first()));
    let mut questions: Vec<String> = vec!["changes | count by session,category".into(), "volume since:s2".into()];
    if let Some(place) = biggest {
        let grow = 2.0;
        let shape = store::ZoneShape::Box(store::WorldBox {
            min_m: place.min_m.map(|v| v - grow),
            max_m: place.max_m.map(|v| v + grow),
        });
        let mut s = Store::open(store_path)?;
        s.transaction(|tx| store::insert_zone(tx, DEMO_ZONE, &shape))?;
        let c = place.centroid_m;
        questions.push(format!("changes in zone:\"{DEMO_ZONE}\" | count by session,category"));
        questions.push(format!("history near:{:.1},{:.1},{:.1} r:1", c[0], c[1], c[2]));
    }
    questions.push("loops | count by session,kind,accepted".into());
    let store = Store::open_read_only(store_path)?;
    let catalog = crate::query::Catalog::load(&store, ctx.config.change.static_threshold)?;
    if biggest.is_some() {
        let b = &catalog.zones.iter().find(|z| z.name == DEMO_ZONE).map(|z| z.shape.bounds());
        if let Some(b) = b {
            println!(
                "\n$ seam zones add {} \"{DEMO_ZONE}\" bbox:{:.1},{:.1},{:.1},{:.1},{:.1},{:.1}",
                store_path.display(),
                b.min_m[0],
                b.min_m[1],
                b.min_m[2],
                b.max_m[0],
                b.max_m[1],
                b.max_m[2]
            );
        }
    }
    for q in &questions {
        println!("\n$ seam query {} '{q}'", store_path.display());
        let plan = crate::query::compile(q, &catalog).map_err(|error| crate::query::Report {
            error,
            query: q.clone(),
            color: false,
        })?;
        let result = crate::query::execute(store.conn(), &plan)?;
        super::query::print_result_table(ctx, &result)?;
    }
    Ok(())
}
