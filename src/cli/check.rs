//! `seam check site.seam [--repair]`

use super::Ctx;
use super::output::{json, print_json};
use crate::store::{Store, StoreError};
use clap::Args;
use std::path::PathBuf;

#[derive(Debug, Args)]
pub struct CheckArgs {
    /// The store.
    pub store: PathBuf,
    /// Remove orphan files (left by a crash before their rows were committed).
    #[arg(long)]
    pub repair: bool,
}

pub fn run(ctx: &Ctx, a: CheckArgs) -> anyhow::Result<()> {
    // Repair deletes files, so it takes the writer lock; a plain check only reads.
    let store = if a.repair { Store::open(&a.store)? } else { Store::open_read_only(&a.store)? };
    let report = store.check(a.repair)?;
    if json(ctx) {
        print_json(&serde_json::json!({ "ok": report.is_ok(), "report": report }))?;
    } else {
        println!("sqlite      {}", report.sqlite.join("; "));
        println!("files       {} checked, {} bad", report.files_checked, report.bad_files.len());
        for b in &report.bad_files {
            println!("  bad       {}: {}", b.rel_path, b.problem);
        }
        for o in &report.orphans {
            let what =
                if report.removed.contains(o) { "removed" } else { "orphan (run `seam check --repair` to remove)" };
            println!("  {what:<9} {o}");
        }
        for s in &report.incomplete_sessions {
            println!("  note      session {s:?} has an unfinished ingest; `seam ingest` of the same folder resumes it");
        }
        println!("{}", if report.is_ok() { "ok" } else { "PROBLEMS FOUND" });
    }
    if !report.is_ok() {
        return Err(StoreError::Corrupt {
            path: a.store.clone(),
            message: format!("{} bad files; sqlite: {}", report.bad_files.len(), report.sqlite.join("; ")),
        }
        .into());
    }
    Ok(())
}
