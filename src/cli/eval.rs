//! `seam eval align site.seam --gt SIM_DIR [--compare-anchors]`
//! `seam eval dor site.seam --labels SESSION_DIR [--session NAME] [--predicted PRED_DIR]`
//!
//! Alignment against a simulator's ground truth: per-session ATE (one
//! Umeyama SE(3) fit over all sessions) and rigid residual (each session's
//! own fit). `--compare-anchors` re-solves the store's graph after every
//! ingest step in `fixed`, `session` and `submap` mode with the same loops:
//! the paper's Table II.

use super::output::{print_json, print_table};
use super::{Ctx, Format};
use crate::eval::dor::render_table;
use crate::eval::{AlignReport, align_report, dor_report};
use crate::store::Store;
use clap::{Args, Subcommand};
use std::path::PathBuf;

#[derive(Debug, Subcommand)]
pub enum EvalCommand {
    /// Trajectory accuracy against simulated ground truth (ATE, rigid residual).
    Align(AlignArgs),
    /// Dynamic object removal against SemanticKITTI-style labels (PR, RR, F1,
    /// precision of removal; point-wise and voxel-wise at 0.2 m).
    Dor(DorArgs),
}

#[derive(Debug, Args)]
pub struct DorArgs {
    /// The store.
    pub store: PathBuf,
    /// Folder with the ground truth as `labels/NNNNNN.label` (the session
    /// folder that was ingested, for SemanticKITTI and simulated sessions).
    #[arg(long)]
    pub labels: PathBuf,
    /// The session to score (needed when the store has several).
    #[arg(long)]
    pub session: Option<String>,
    /// Score another tool's verdicts instead of the store's: label files
    /// `PRED/labels/NNNNNN.label`, moving classes (252-259) meaning removed.
    #[arg(long, value_name = "PRED")]
    pub predicted: Option<PathBuf>,
}

#[derive(Debug, Args)]
pub struct AlignArgs {
    /// The store.
    pub store: PathBuf,
    /// The simulator's output folder the sessions were ingested from.
    #[arg(long)]
    pub gt: PathBuf,
    /// Also re-solve every ingest step with fixed, session and submap anchors.
    #[arg(long)]
    pub compare_anchors: bool,
}

pub fn run(ctx: &Ctx, cmd: EvalCommand) -> anyhow::Result<()> {
    match cmd {
        EvalCommand::Dor(a) => {
            let store = Store::open_read_only(&a.store)?;
            let report = dor_report(&store, &a.labels, a.session.as_deref(), a.predicted.as_deref())?;
            match ctx.format {
                Format::Json => print_json(&report)?,
                _ => {
                    println!(
                        "session {} ({} points, verdicts from {}{})",
                        report.session,
                        report.points,
                        report.predicted,
                        report.model.as_deref().map(|m| format!(", model {m}")).unwrap_or_default()
                    );
                    if let (Some(s), Some(r)) = (report.evidence_s, report.points_per_s) {
                        println!("evidence step: {s:.2} s, {r:.0} points/s");
                    }
                    print!("{}", render_table(&report.scores));
                }
            }
            Ok(())
        }
        EvalCommand::Align(a) => {
            let store = Store::open_read_only(&a.store)?;
            let report = align_report(&store, &a.gt, a.compare_anchors, &ctx.config.graph)?;
            match ctx.format {
                Format::Json => print_json(&report)?,
                _ => print_align(&report),
            }
            Ok(())
        }
    }
}

fn mm(m: f64) -> String {
    format!("{:.0} mm", m * 1000.0)
}

fn print_align(r: &AlignReport) {
    let rows: Vec<Vec<String>> = r
        .sessions
        .iter()
        .zip(&r.names)
        .map(|(s, name)| {
            vec![
                s.session.to_string(),
                name.clone(),
                s.keyframes.to_string(),
                mm(s.ate_rmse_m),
                mm(s.ate_max_m),
                mm(s.rigid_residual_m),
                r.odometry_residual_m.get(s.session - 1).map(|&m| mm(m)).unwrap_or_default(),
            ]
        })
        .collect();
    print_table(&["session", "name", "keyframes", "ate_rmse", "ate_max", "rigid_residual", "odometry_residual"], &rows);
    let l = &r.loops;
    println!(
        "accepted loops: {} ({} wrong by > 0.3 m or 1°), error median {} / {:.2}°, max {}",
        l.accepted,
        l.wrong,
        mm(l.median_error_m),
        l.median_error_deg,
        mm(l.max_error_m)
    );
    if r.anchor_steps.is_empty() {
        return;
    }
    println!();
    println!("anchor modes re-solved after each ingest (same loops); residual = mean per-session rigid residual,");
    println!("rigid = a session moved as one rigid body (its odometry's own residual):");
    let mut rows = Vec::new();
    for k in r.anchor_steps.iter().map(|s| s.sessions).collect::<std::collections::BTreeSet<_>>() {
        let step = |mode: &str| r.anchor_steps.iter().find(|s| s.sessions == k && s.mode == mode);
        let label = if k == 2 { "01+02".to_string() } else { format!("+{k:02}") };
        let mut row = vec![label];
        row.push(step("submap").map(|s| mm(s.mean_rigid_session_residual_m)).unwrap_or_default());
        for mode in ["session", "submap"] {
            row.push(step(mode).map(|s| mm(s.mean_rigid_residual_m)).unwrap_or_default());
        }
        for mode in ["fixed", "session", "submap"] {
            row.push(step(mode).map(|s| mm(s.max_ate_rmse_m)).unwrap_or_default());
        }
        rows.push(row);
    }
    print_table(
        &["step", "residual rigid", "residual session", "residual submap", "ate fixed", "ate session", "ate submap"],
        &rows,
    );
}
