//! `seam report site.seam -o report.html [--width PX]`
//!
//! One self-contained HTML page about a store (see `render::report`):
//! sessions, what changed in each, and the pictures, embedded.

use super::Ctx;
use super::output::{json, log, print_json, thousands};
use crate::render::{ReportOptions, write_report};
use clap::Args;
use std::path::PathBuf;

#[derive(Debug, Args)]
pub struct ReportArgs {
    /// The store (opened read-only).
    pub store: PathBuf,
    /// The HTML file to write (its folder must exist).
    #[arg(short, long, value_name = "FILE")]
    pub out: PathBuf,
    /// Width of the main pictures in pixels.
    #[arg(long, value_name = "PX", default_value_t = 1400)]
    pub width: u32,
}

pub fn run(ctx: &Ctx, a: ReportArgs) -> anyhow::Result<()> {
    let c = &ctx.config.change;
    let opts = ReportOptions {
        width_px: a.width,
        static_threshold: c.static_threshold,
        eps_g_range: (c.eps_g_min, c.eps_g_max),
        ..ReportOptions::default()
    };
    let s = write_report(&a.store, &a.out, &opts)?;
    if json(ctx) {
        return print_json(&s);
    }
    println!(
        "{}: {} bytes, {} sessions, {} pictures",
        a.out.display(),
        thousands(s.bytes),
        s.sessions,
        s.pictures.len()
    );
    log(ctx, format!("report written in {:.1} s", s.wall_s));
    Ok(())
}
