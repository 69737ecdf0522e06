//! `seam query site.seam 'QUERY' [--explain] [--out FILE.parquet] [--format table|json|csv]`
//!
//! Opens the store read-only (a query may run beside an ingest and never
//! changes the store), compiles the query against it and prints the rows.
//! A mistake in the query exits 3 with the query shown and `^^^` under the
//! part that is wrong, plus what exists instead; colours only on a terminal
//! and never with `NO_COLOR`. `QUERY` may be `@FILE` to read it from a file
//! (such as `queries/*.seamql`).

use super::output::{json, log, print_json};
use super::{Ctx, Format, UsageError};
use crate::query::{self, Catalog, QueryResult, Report};
use crate::store::{Store, StoreError, evidence_files::write_batch};
use clap::Args;
use std::io::{IsTerminal, Write};
use std::path::PathBuf;

#[derive(Debug, Args)]
pub struct QueryArgs {
    /// The store (opened read-only).
    pub store: PathBuf,
    /// The query, e.g. 'changes in zone:"Tower B" since:s3', or @FILE to read it from a file.
    pub query: String,
    /// Print the plan, the SQL with its `?` placeholders, the parameters and SQLite's plan; run nothing.
    #[arg(long)]
    pub explain: bool,
    /// Write the rows to this Parquet file instead of printing them.
    #[arg(long, value_name = "FILE.parquet")]
    pub out: Option<PathBuf>,
}

/// Colours on stderr: only on a terminal, and never with `NO_COLOR` set.
pub fn stderr_color() -> bool {
    std::io::stderr().is_terminal() && std::env::var_os("NO_COLOR").is_none_or(|v| v.is_empty())
}

pub fn run(ctx: &Ctx, a: QueryArgs) -> anyhow::Result<()> {
    if matches!(ctx.format, Format::Kitti | Format::Tum) {
        return Err(UsageError("seam query prints --format table, json or csv".into()).into());
    }
    let text = match a.query.strip_prefix('@') {
        Some(path) => {
            std::fs::read_to_string(path).map_err(|e| UsageError(format!("cannot read the query file {path}: {e}")))?
        }
        None => a.query.clone(),
    };
    let store = Store::open_read_only(&a.store)?;
    let catalog = Catalog::load(&store, ctx.config.change.static_threshold)?;
    let plan = query::compile(&text, &catalog).map_err(|error| Report {
        error,
        query: text.clone(),
        color: stderr_color(),
    })?;
    if a.explain {
        let lines = query::sqlite_plan(store.conn(), &plan)?;
        print!("{}", query::explain(&plan, Some(&lines)));
        return Ok(());
    }
    let result = query::execute(store.conn(), &plan)?;
    for n in &result.notes {
        log(ctx, format!("note: {n}"));
    }
    if let Some(out) = &a.out {
        let batch =
            result.to_record_batch().map_err(|e| StoreError::Parquet { path: out.clone(), message: e.to_string() })?;
        let written = write_batch(out, "query", &batch)?;
        if json(ctx) {
            let cols: Vec<&str> = result.columns.iter().map(|c| c.name.as_str()).collect();
            return print_json(&serde_json::json!({
                "out": out.display().to_string(), "rows": written.row_count, "bytes": written.size_bytes, "columns": cols,
            }));
        }
        println!("{} rows written to {}", written.row_count, out.display());
        return Ok(());
    }
    if result.rows.is_empty() {
        log(ctx, "(no rows)");
    }
    let text = match ctx.format {
        Format::Json => serde_json::to_string_pretty(&query::exec::JsonRows(&result))? + "\n",
        Format::Csv => csv(&result),
        _ => table(&result),
    };
    emit(&text)
}

/// Writes to stdout; a reader that stopped reading (`seam query ... | head`)
/// is not an error.
fn emit(text: &str) -> anyhow::Result<()> {
    let mut out = std::io::stdout().lock();
    match out.write_all(text.as_bytes()).and_then(|_| out.flush()) {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => Err(e.into()),
        _ => Ok(()),
    }
}

/// Aligned columns with a header, numbers right-aligned, reals to 3
/// decimals, NULL as `-` (the layout of every seam table).
fn table(r: &QueryResult) -> String {
    let header: Vec<String> = r.columns.iter().map(|c| c.name.clone()).collect();
    let rows: Vec<Vec<String>> =
        (0..r.rows.len()).map(|i| (0..header.len()).map(|c| r.cell(i, c, Some(3), "-")).collect()).collect();
    let width = |c: usize| rows.iter().map(|row| row[c].chars().count()).chain([header[c].len()]).max().unwrap_or(0);
    let widths: Vec<usize> = (0..header.len()).map(width).collect();
    let numeric: Vec<bool> = (0..header.len())
        .map(|c| !rows.is_empty() && rows.iter().all(|row| row[c].parse::<f64>().is_ok() || row[c] == "-"))
        .collect();
    let line = |cells: &[String]| {
        let parts: Vec<String> = cells
            .iter()
            .enumerate()
            .map(|(c, s)| {
                let w = widths[c];
                if numeric[c] { format!("{s:>w$}") } else { format!("{s:<w$}") }
            })
            .collect();
        parts.join("  ").trim_end().to_string() + "\n"
    };
    let mut out = line(&header);
    for row in &rows {
        out.push_str(&line(row));
    }
    out
}

/// The rows as aligned columns on stdout (for `seam demo`'s questions).
pub(super) fn print_result_table(ctx: &Ctx, result: &QueryResult) -> anyhow::Result<()> {
    if result.rows.is_empty() {
        log(ctx, "(no rows)");
    }
    emit(&table(result))
}

/// Comma-separated with a header; reals exact; fields with `,`, `"` or a
/// line break quoted.
fn csv(r: &QueryResult) -> String {
    let quote = |s: &str| crate::text::csv_field(s).into_owned();
    let mut out = r.columns.iter().map(|c| quote(&c.name)).collect::<Vec<_>>().join(",");
    out.push('\n');
    for i in 0..r.rows.len() {
        let cells: Vec<String> = (0..r.columns.len()).map(|c| quote(&r.cell(i, c, None, ""))).collect();
        out.push_str(&cells.join(","));
        out.push('\n');
    }
    out
}
