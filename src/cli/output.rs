//! Printing: aligned tables, JSON, and progress bars on stderr.

use super::{Ctx, Format};
use crate::pipeline::Progress;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::sync::Mutex;

/// Prints rows as an aligned table with a header (numbers right-aligned).
pub fn print_table(header: &[&str], rows: &[Vec<String>]) {
    let mut widths: Vec<usize> = header.iter().map(|h| h.len()).collect();
    for r in rows {
        for (w, c) in widths.iter_mut().zip(r) {
            *w = (*w).max(c.chars().count());
        }
    }
    let numeric: Vec<bool> = (0..header.len())
        .map(|i| {
            !rows.is_empty() && rows.iter().all(|r| r.get(i).is_some_and(|c| c.parse::<f64>().is_ok() || c == "-"))
        })
        .collect();
    let line = |cells: Vec<String>| {
        let parts: Vec<String> = cells
            .iter()
            .enumerate()
            .map(|(i, c)| {
                // A row longer than the header prints its extra cells unpadded.
                let w = widths.get(i).copied().unwrap_or(0);
                if numeric.get(i).copied().unwrap_or(false) { format!("{c:>w$}") } else { format!("{c:<w$}") }
            })
            .collect();
        println!("{}", parts.join("  ").trim_end());
    };
    line(header.iter().map(|s| s.to_string()).collect());
    for r in rows {
        line(r.clone());
    }
}

/// Prints a serialisable value as pretty JSON on stdout.
pub fn print_json<T: serde::Serialize>(v: &T) -> anyhow::Result<()> {
    println!("{}", serde_json::to_string_pretty(v)?);
    Ok(())
}

/// Logs a line to stderr unless `--quiet`.
pub fn log(ctx: &Ctx, msg: impl AsRef<str>) {
    if !ctx.quiet {
        eprintln!("{}", msg.as_ref());
    }
}

/// True when the command should print JSON.
pub fn json(ctx: &Ctx) -> bool {
    ctx.format == Format::Json
}

/// Progress bars on stderr; invisible when stderr is not a terminal or with `--quiet`.
pub struct Bars {
    quiet: bool,
    prefix: String,
    bar: Mutex<Option<ProgressBar>>,
}

impl Bars {
    pub fn new(ctx: &Ctx, prefix: impl Into<String>) -> Bars {
        Bars { quiet: ctx.quiet, prefix: prefix.into(), bar: Mutex::new(None) }
    }
}

impl Progress for Bars {
    fn begin(&self, phase: &str, total: u64) {
        let target = if self.quiet { ProgressDrawTarget::hidden() } else { ProgressDrawTarget::stderr() };
        let bar = ProgressBar::with_draw_target(Some(total), target);
        let style =
            ProgressStyle::with_template("{prefix:>12} {msg:<14} [{bar:30}] {pos}/{len} ({per_sec}, eta {eta})")
                .unwrap_or_else(|_| ProgressStyle::default_bar())
                .progress_chars("=> ");
        bar.set_style(style);
        bar.set_prefix(self.prefix.clone());
        bar.set_message(phase.to_string());
        if let Ok(mut b) = self.bar.lock() {
            *b = Some(bar);
        }
    }
    fn advance(&self, n: u64) {
        if let Ok(b) = self.bar.lock()
            && let Some(b) = b.as_ref()
        {
            b.inc(n);
        }
    }
    fn end(&self) {
        if let Ok(mut b) = self.bar.lock()
            && let Some(b) = b.take()
        {
            b.finish_and_clear();
        }
    }
}

pub use crate::text::thousands;
