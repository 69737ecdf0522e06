//! `seam ingest site.seam SESSION_DIR [--name s4] [--dry-run] [--initial-guess x,y,z,yaw] [--anchors MODE]`

use super::Ctx;
use super::output::{Bars, json, log, print_json, thousands};
use crate::graph::AnchorMode;
use crate::pipeline::{IngestOptions, IngestReceipt, IngestStatus, ingest_session};
use crate::store::Store;
use clap::Args;
use std::path::PathBuf;

#[derive(Debug, Args)]
pub struct IngestArgs {
    /// The store.
    pub store: PathBuf,
    /// The session folder (KITTI, Scans/*.pcd, or DynamicMap_Benchmark layout).
    pub session: PathBuf,
    /// Session name (default: `name` in session.toml, else s<N>).
    #[arg(long)]
    pub name: Option<String>,
    /// Validate the session only; change nothing.
    #[arg(long)]
    pub dry_run: bool,
    /// Where the session's first keyframe is in the world, `x,y,z,yaw_deg`
    /// (the frame of `seam poses`), when global registration cannot find it;
    /// refined by ICP on the maps.
    #[arg(long, value_name = "X,Y,Z,YAW_DEG", allow_hyphen_values = true, value_parser = parse_guess)]
    pub initial_guess: Option<crate::geometry::Pose>,
    /// Anchors of the joint optimisation: submap (default), session, or fixed
    /// (earlier sessions frozen). For comparisons; see `seam eval align`.
    #[arg(long, value_parser = parse_mode)]
    pub anchors: Option<AnchorMode>,
}

fn parse_guess(s: &str) -> Result<crate::geometry::Pose, String> {
    crate::align::coarse::parse_initial_guess(s)
}

pub fn parse_mode(s: &str) -> Result<AnchorMode, String> {
    match s {
        "submap" => Ok(AnchorMode::Submap),
        "session" => Ok(AnchorMode::Session),
        "fixed" => Ok(AnchorMode::Fixed),
        _ => Err(format!("{s:?} is not an anchor mode: use submap, session or fixed")),
    }
}

pub fn run(ctx: &Ctx, a: IngestArgs) -> anyhow::Result<()> {
    let opts =
        IngestOptions { name: a.name, dry_run: a.dry_run, initial_guess: a.initial_guess, anchor_mode: a.anchors };
    let receipt = ingest_one(ctx, &a.store, &a.session, &opts)?;
    if json(ctx) {
        print_json(&receipt)?;
    } else {
        print_receipt(&receipt);
    }
    Ok(())
}

/// Opens the store for writing and ingests one session folder.
pub fn ingest_one(
    ctx: &Ctx,
    store: &std::path::Path,
    session: &std::path::Path,
    opts: &IngestOptions,
) -> anyhow::Result<IngestReceipt> {
    let mut store = Store::open(store)?;
    let bars = Bars::new(ctx, session.file_name().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default());
    let receipt = ingest_session(&mut store, session, opts, &ctx.config, &bars)?;
    if receipt.status == IngestStatus::AlreadyPresent {
        log(
            ctx,
            format!(
                "{}: already in the store as session {} ({:?}); nothing to do",
                session.display(),
                receipt.session_id.unwrap_or(0),
                receipt.name
            ),
        );
    }
    Ok(receipt)
}

fn print_receipt(r: &IngestReceipt) {
    let status = match r.status {
        IngestStatus::Ingested => "ingested",
        IngestStatus::Resumed => "resumed and finished",
        IngestStatus::AlreadyPresent => "already present",
        IngestStatus::Validated => "validated (dry run, nothing written)",
    };
    println!(
        "session {} {:?}: {status} — {} keyframes, {} points, layout {}, {:.2} s ({:.0} points/s, {:.1} scans/s)",
        r.session_id.map(|i| i.to_string()).unwrap_or_else(|| "-".into()),
        r.name,
        r.keyframes,
        thousands(r.points),
        r.layout,
        r.wall_s,
        r.points_per_s,
        r.scans_per_s
    );
    for s in &r.steps {
        if s.ran {
            println!("  step {:<14} {:>7.2} s  {}", s.step, s.wall_s, s.details);
        } else {
            println!("  step {:<14} (committed by an earlier run)", s.step);
        }
    }
}
