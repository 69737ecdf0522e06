//! `seam eval align site.seam --gt SIM_DIR [--compare-anchors]`
//! `seam eval dor site.seam --labels SESSION_DIR [--session NAME] [--predicted PRED_DIR]`
//! `seam eval changes site.seam --gt SIM_DIR`
//!
//! Alignment against a simulator's ground truth: per-session ATE (one
//! Umeyama SE(3) fit over all sessions) and rigid residual (each session's
//! own fit). `--compare-anchors` re-solves the store's graph after every
//! ingest step in `fixed`, `session` and `submap` mode with the same loops:
//! the paper's Table II.
//!
//! `changes` scores the lifelong map after the last ingested session against
//! the simulator's objects (definitions in `eval::changes`).

use super::output::thousands;
use super::output::{print_json, print_table};
use super::{Ctx, Format};
use crate::eval::changes::{
    ChangeEvalConfig, ChangesReport, Fraction, Placement, changes_report, write_lost_voxels, write_removed_voxels,
};
use crate::eval::dor::render_table;
use crate::eval::{AlignReport, align_report, dor_report};
use crate::store::Store;
use anyhow::Context;
use clap::{Args, Subcommand};
use std::path::PathBuf;

#[derive(Debug, Subcommand)]
pub enum EvalCommand {
    /// Trajectory accuracy against simulated ground truth (ATE, rigid residual).
    Align(AlignArgs),
    /// Dynamic object removal against SemanticKITTI-style labels (PR, RR, F1,
    /// precision of removal; point-wise and voxel-wise at 0.2 m).
    Dor(DorArgs),
    /// Change detection against simulated ground truth: permanent structure
    /// kept, removed objects gone, appeared objects present, mover leftovers,
    /// change events in the right session (0.2 m voxels, after the last session).
    Changes(ChangesArgs),
}

#[derive(Debug, Args)]
pub struct ChangesArgs {
    /// The store.
    pub store: PathBuf,
    /// The simulator's output folder the sessions were ingested from.
    #[arg(long)]
    pub gt: PathBuf,
    /// How map voxels reach the truth's frame: `owner` moves each by its owner
    /// keyframe's true pose (scores change detection alone), `rigid` by one
    /// Umeyama fit of all keyframes (alignment errors included).
    #[arg(long, default_value = "owner", value_parser = ["owner", "rigid"])]
    pub placement: String,
    /// Also write every voxel of a removed object (metric 2) as CSV: its
    /// object, ε_g, category, sessions, whether some session saw it free or
    /// had it in view, its height above the object's bottom, and its place
    /// in the truth's and the store's frame. For finding out what stayed.
    #[arg(long, value_name = "FILE.csv")]
    pub removed_voxels: Option<PathBuf>,
    /// Also write every permanent-structure voxel missing from the static
    /// map (metric 1) as CSV: the permanent object it is near (empty for
    /// ground), ε_g, category, sessions and its place in both frames. For
    /// finding out what a rule paid.
    #[arg(long, value_name = "FILE.csv")]
    pub lost_voxels: Option<PathBuf>,
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

/// Writes a CSV to `path` when one is given; the error names the file.
fn write_csv(
    path: Option<&std::path::Path>,
    rows: impl FnOnce(&mut std::io::BufWriter<std::fs::File>) -> std::io::Result<()>,
) -> anyhow::Result<()> {
    let Some(path) = path else { return Ok(()) };
    let write = || -> std::io::Result<()> {
        let mut out = std::io::BufWriter::new(std::fs::File::create(path)?);
        rows(&mut out)?;
        std::io::Write::flush(&mut out)
    };
    write().with_context(|| format!("cannot write {}", path.display()))
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
                    if let (Some(s), Some(r)) = (report.in_memory_s, report.in_memory_points_per_s) {
                        println!("  of which in memory (ray casting, DOR, cleaned map): {s:.2} s, {r:.0} points/s");
                    }
                    print!("{}", render_table(&report.scores));
                }
            }
            Ok(())
        }
        EvalCommand::Changes(a) => {
            let store = Store::open_read_only(&a.store)?;
            let cfg = ChangeEvalConfig {
                static_threshold: ctx.config.change.static_threshold,
                placement: if a.placement == "rigid" { Placement::Rigid } else { Placement::Owner },
                ..ChangeEvalConfig::default()
            };
            let report = changes_report(&store, &a.gt, &cfg)?;
            write_csv(a.removed_voxels.as_deref(), |out| write_removed_voxels(&report.removed_voxels, out))?;
            write_csv(a.lost_voxels.as_deref(), |out| write_lost_voxels(&report.lost_voxels, out))?;
            match ctx.format {
                Format::Json => print_json(&report)?,
                _ => print_changes(&report),
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

fn percent(v: Option<f64>) -> String {
    v.map_or("-".into(), |v| format!("{:.2} %", v * 100.0))
}

fn count(f: &Fraction) -> String {
    format!("{} / {}", thousands(f.hits), thousands(f.total))
}

fn print_changes(r: &ChangesReport) {
    let s = &r.scores;
    println!(
        "lifelong map after session {} (graph version {}): {} voxels of {} m, {} static (eps_g < {})",
        r.last_session,
        r.graph_version,
        thousands(s.lifelong_voxels),
        r.voxel_m,
        thousands(s.static_voxels),
        r.settings.static_threshold
    );
    let a = &r.alignment;
    println!(
        "rigid fit to the truth on {} keyframes: RMSE {:.0} mm, max {:.0} mm; voxels placed {} ({} voxels, {} events \
         by the rigid fit)",
        a.keyframes,
        a.rmse_m * 1000.0,
        a.max_m * 1000.0,
        match r.settings.placement {
            Placement::Owner => "by their owner keyframes' true poses",
            Placement::Rigid => "by the rigid fit",
        },
        thousands(r.voxels_placed_rigidly as u64),
        thousands(r.events_placed_rigidly as u64)
    );
    println!();
    let rows: Vec<Vec<String>> = r
        .sessions
        .iter()
        .map(|x| {
            let c = &x.counts;
            vec![
                x.session_id.to_string(),
                x.name.clone(),
                x.sim_session.to_string(),
                c.coexist.to_string(),
                c.deleted_overlap.to_string(),
                c.deleted_non_overlap.to_string(),
                c.emerged_overlap.to_string(),
                c.emerged_non_overlap.to_string(),
                c.events.to_string(),
                c.merged_on_move.to_string(),
                c.lifelong_voxels.to_string(),
                c.static_voxels.to_string(),
            ]
        })
        .collect();
    print_table(
        &[
            "session",
            "name",
            "sim",
            "coexist",
            "deleted_overlap",
            "deleted_non_overlap",
            "emerged_overlap",
            "emerged_non_overlap",
            "events",
            "merged_on_move",
            "lifelong",
            "static",
        ],
        &rows,
    );
    println!();
    let counts = [
        count(&s.permanent_static),
        count(&s.removed_static),
        count(&s.appeared_present),
        count(&s.mover_static_of_static_map),
        count(&s.events_correct),
    ];
    let mut rows: Vec<Vec<String>> = r
        .goals
        .iter()
        .zip(counts)
        .enumerate()
        .map(|(i, (g, c))| {
            let rel = if g.relation == ">=" { "≥" } else { "≤" };
            vec![
                format!("{} {}", i + 1, g.metric),
                percent(g.value),
                c,
                format!("{rel} {:.0} %", g.goal * 100.0),
                g.met.map_or("-", |m| if m { "yes" } else { "NO" }).into(),
            ]
        })
        .collect();
    let extra = |metric: &str, f: &Fraction| vec![format!("  {metric}"), percent(f.value), count(f), String::new()];
    rows.insert(1, extra("on permanent objects", &s.permanent_static_objects));
    rows.insert(2, extra("ground and the rest", &s.permanent_static_ground));
    rows.insert(4, extra("of the voxels some session saw free", &s.removed_static_seen_free));
    rows.insert(6, extra("appeared objects' voxels static", &s.appeared_static_voxels));
    rows.insert(8, extra("mover voxels static (of mover voxels)", &s.mover_voxels_static));
    if let Some(f) = &s.removed_static_in_view {
        rows.insert(5, extra("of the voxels a later session had in view", f));
    }
    rows.push(extra("removed objects", &s.events_removed_correct));
    rows.push(extra("appeared objects", &s.events_appeared_correct));
    print_table(&["metric", "value", "count", "goal", "met"], &rows);
    let cats = |c: &[crate::eval::changes::CategoryCount]| {
        c.iter()
            .map(|c| format!("{} {} ({} static)", c.category, thousands(c.voxels), thousands(c.static_voxels)))
            .collect::<Vec<_>>()
            .join(", ")
    };
    println!("permanent voxels by category: {}", cats(&s.permanent_by_category));
    println!("removed-object voxels by category: {}", cats(&s.removed_by_category));
    let classes: Vec<String> = s
        .permanent_by_class
        .iter()
        .take(8)
        .map(|c| format!("{} {} ({} static)", c.class, thousands(c.voxels), thousands(c.static_voxels)))
        .collect();
    println!("permanent voxels by class (largest): {}", classes.join(", "));
    let left: Vec<String> = s
        .removed_by_class
        .iter()
        .filter(|c| c.static_voxels > 0)
        .take(8)
        .map(|c| format!("{} {} of {}", c.class, thousands(c.static_voxels), thousands(c.voxels)))
        .collect();
    println!("removed-object voxels left static by class (most): {}", left.join(", "));
    let objects: Vec<String> = s
        .removed_by_object
        .iter()
        .filter(|o| o.static_voxels > 0)
        .take(8)
        .map(|o| {
            format!(
                "{} {} (last in s{}) {} of {} [{}]",
                o.class,
                o.object,
                o.last_present,
                thousands(o.static_voxels),
                thousands(o.voxels),
                o.categories
                    .iter()
                    .filter(|c| c.static_voxels > 0)
                    .map(|c| format!("{} {}", c.category, thousands(c.static_voxels)))
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        })
        .collect();
    println!("removed objects with the most voxels left static: {}", objects.join("; "));
    let unseen = s.appeared.iter().filter(|a| !a.seen).count();
    println!(
        "{} removed, {} appeared objects ({unseen} not seen in the map); {} object changes unscored (fewer than {} \
         voxels in the map)",
        s.removed_objects,
        s.appeared.len(),
        s.events_unscored,
        r.settings.min_voxels
    );
    let wrong: Vec<Vec<String>> = s
        .changes
        .iter()
        .filter(|c| c.scored && !c.correct)
        .map(|c| {
            let events: Vec<String> =
                c.events.iter().map(|e| format!("s{}:{}={}", e.session, e.category, e.count)).collect();
            vec![
                c.session.to_string(),
                c.object.to_string(),
                c.class.clone(),
                c.change.into(),
                c.voxels.to_string(),
                c.in_view_voxels.map_or("-".into(), |n| n.to_string()),
                c.nearest_keyframe_m.map_or("-".into(), |m| format!("{m:.1}")),
                if events.is_empty() { "none".into() } else { events.join(" ") },
            ]
        })
        .collect();
    if !wrong.is_empty() {
        println!();
        println!("object changes without the right events in their session:");
        print_table(
            &["session", "object", "class", "change", "voxels", "in_view", "nearest_kf_m", "events in its region"],
            &wrong,
        );
    }
}
