//! `seam rebuild site.seam --out NEW.seam [--remap OLD=NEW]... [--anchors MODE]`
//!
//! Recomputes everything from the raw scans into a new store: every session
//! of `site.seam`, in its order, from its recorded folder, with its name and
//! recorded options, with the configuration the store recorded at its first
//! ingest, or `--config`'s to recompute with other settings. Every folder is checked (exists, same content hash) before
//! anything is written; the source store is only read.

use super::output::{Bars, json, log, print_json, print_table, thousands};
use super::{Ctx, UsageError};
use crate::graph::AnchorMode;
use crate::pipeline::rebuild::{self, RebuildError, RebuildOptions, RebuildReport};
use crate::store::Store;
use clap::Args;
use std::path::{Path, PathBuf};

#[derive(Debug, Args)]
pub struct RebuildArgs {
    /// The store to rebuild (only read).
    pub store: PathBuf,
    /// The new store to create (must not exist, or be empty).
    #[arg(long, value_name = "NEW_STORE")]
    pub out: PathBuf,
    /// Read session folders recorded under OLD from under NEW instead (the
    /// data moved); repeatable, the longest OLD that matches wins.
    #[arg(long, value_name = "OLD=NEW", value_parser = parse_remap)]
    pub remap: Vec<(PathBuf, PathBuf)>,
    /// Anchor mode for every session: submap, session or fixed (default: the
    /// mode each session was optimised in).
    #[arg(long, value_parser = super::ingest::parse_mode)]
    pub anchors: Option<AnchorMode>,
}

fn parse_remap(s: &str) -> Result<(PathBuf, PathBuf), String> {
    match s.split_once('=') {
        Some((old, new)) if !old.is_empty() && !new.is_empty() => Ok((PathBuf::from(old), PathBuf::from(new))),
        _ => Err(format!("{s:?} is not OLD=NEW, e.g. /mnt/old-disk/surveys=/data/surveys")),
    }
}

/// `p` made absolute without requiring it to exist (its nearest existing
/// ancestor is canonicalised).
fn absolute(p: &Path) -> PathBuf {
    let abs = std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf());
    let mut base = abs.as_path();
    let mut rest = Vec::new();
    while !base.exists() {
        match (base.parent(), base.file_name()) {
            (Some(parent), Some(name)) => {
                rest.push(name.to_os_string());
                base = parent;
            }
            _ => return abs,
        }
    }
    let mut out = base.canonicalize().unwrap_or_else(|_| base.to_path_buf());
    out.extend(rest.iter().rev());
    out
}

/// A rebuild error as the exit-code logic reads it: the typed cause (a
/// `ReadError` for a source folder, data error 4) under a line that names
/// the session and what state the new store is in.
fn explain(err: RebuildError, out: &Path, total: usize) -> anyhow::Error {
    match err {
        RebuildError::Source { session, name, error } => anyhow::Error::new(*error)
            .context(format!("cannot rebuild session {session} {name:?} (nothing was written)")),
        RebuildError::Store(e) => e.into(),
        RebuildError::Ingest { session, name, done, error } => anyhow::Error::new(*error).context(format!(
            "rebuild stopped at session {session} {name:?}: {done} of {total} sessions are in {}; delete that \
             folder and run rebuild again",
            out.display()
        )),
    }
}

pub fn run(ctx: &Ctx, a: RebuildArgs) -> anyhow::Result<()> {
    let (src_abs, out_abs) = (absolute(&a.store), absolute(&a.out));
    if out_abs.starts_with(&src_abs) {
        return Err(UsageError(format!(
            "--out {} is inside the store being rebuilt, which rebuild never modifies\n  hint: choose a folder \
             outside {}",
            a.out.display(),
            a.store.display()
        ))
        .into());
    }
    rebuild::check_out(&a.out)?;
    let mut source = Store::open_read_only(&a.store)?;
    let opts = RebuildOptions { remap: a.remap.clone(), anchor_mode: a.anchors };
    log(ctx, format!("checking the source folders of {} ...", a.store.display()));
    let plan = rebuild::plan(&mut source, &opts, &ctx.config).map_err(|e| explain(e, &a.out, 0))?;
    drop(source);
    let n = plan.sessions.len();
    log(ctx, format!("{n} session folders unchanged ({:.1} s); rebuilding into {}", plan.verify_s, a.out.display()));
    let bars = Bars::new(ctx, "rebuild");
    let report = rebuild::execute(
        &plan,
        &a.out,
        &ctx.config,
        &bars,
        &mut |i, p| {
            log(ctx, format!("[{}/{n}] session {} {:?} from {}", i + 1, p.source_session_id, p.name, p.dir.display()))
        },
        &mut |i, r| {
            log(
                ctx,
                format!(
                    "[{}/{n}] session {:?}: {} keyframes in {:.2} s",
                    i + 1,
                    r.receipt.name,
                    r.receipt.keyframes,
                    r.receipt.wall_s
                ),
            )
        },
    )
    .map_err(|e| explain(e, &a.out, n))?;
    if json(ctx) {
        let mut v = serde_json::to_value(&report)?;
        v["config"] = serde_json::to_value(&ctx.config)?;
        return print_json(&v);
    }
    print_report(&report);
    Ok(())
}

fn print_report(r: &RebuildReport) {
    // Step columns in the order the ingests ran them (whatever the pipeline's steps are).
    let mut steps: Vec<&str> = Vec::new();
    for s in &r.sessions {
        for st in &s.receipt.steps {
            if !steps.contains(&st.step.as_str()) {
                steps.push(&st.step);
            }
        }
    }
    let keyframes: usize = r.sessions.iter().map(|s| s.receipt.keyframes).sum();
    let points: u64 = r.sessions.iter().map(|s| s.receipt.points).sum();
    println!(
        "rebuilt {} into {}: {} sessions, {} keyframes, {} points in {:.2} s (checking source folders {:.2} s, \
         ingests {:.2} s)",
        r.source.display(),
        r.out.display(),
        r.sessions.len(),
        keyframes,
        thousands(points),
        r.wall_s,
        r.verify_s,
        r.ingest_s
    );
    let mut header = vec!["session", "name", "keyframes"];
    header.extend(steps.iter().copied());
    header.push("wall_s");
    let step_s = |s: &rebuild::RebuiltSession, name: &str| {
        s.receipt.steps.iter().find(|st| st.step == name && st.ran).map(|st| st.wall_s)
    };
    let mut rows: Vec<Vec<String>> = r
        .sessions
        .iter()
        .map(|s| {
            let mut row = vec![
                s.receipt.session_id.map(|i| i.to_string()).unwrap_or_else(|| "-".into()),
                s.receipt.name.clone(),
                s.receipt.keyframes.to_string(),
            ];
            row.extend(steps.iter().map(|st| step_s(s, st).map(|t| format!("{t:.2}")).unwrap_or_else(|| "-".into())));
            row.push(format!("{:.2}", s.receipt.wall_s));
            row
        })
        .collect();
    let mut total = vec!["-".to_string(), "total".to_string(), keyframes.to_string()];
    total.extend(steps.iter().map(|st| format!("{:.2}", r.sessions.iter().filter_map(|s| step_s(s, st)).sum::<f64>())));
    total.push(format!("{:.2}", r.sessions.iter().map(|s| s.receipt.wall_s).sum::<f64>()));
    rows.push(total);
    print_table(&header, &rows);
    for s in &r.sessions {
        for note in &s.notes {
            println!("note: session {} {:?}: {note}", s.source_session_id, s.receipt.name);
        }
    }
}
