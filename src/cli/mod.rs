//! The command line: one file per subcommand, exit codes decided once.
//!
//! Data goes to stdout, logs and progress to stderr (progress bars only on a
//! terminal, never with `--quiet`). `--format json` prints machine-readable
//! results for every command a script may read.
//!
//! Exit codes (DESIGN.md): 0 ok, 1 internal or I/O failure, 2 usage (bad
//! arguments or config file), 3 query error, 4 data error (bad input file,
//! not a store, store damaged), 5 store busy (another writer).

mod check;
mod demo;
mod eval;
mod exit;
mod export;
mod ingest;
mod init;
mod output;
mod poses;
mod query;
mod rebuild;
mod render;
mod report;
mod sessions;
mod simulate;
mod zones;

use clap::{Parser, Subcommand, ValueEnum};
use std::path::PathBuf;

pub use exit::{ExitKind, exit_kind};

#[derive(Debug, Parser)]
#[command(name = "seam", version, about = "Lifelong LiDAR map store: align sessions, remove movers, detect changes, keep the history", long_about = None)]
pub struct Cli {
    /// Output format for data on stdout.
    #[arg(long, global = true, value_enum, default_value_t = Format::Table)]
    pub format: Format,
    /// No progress bars or log lines on stderr.
    #[arg(long, short, global = true)]
    pub quiet: bool,
    /// TOML file overriding the default configuration (only the keys it
    /// names). Without it, a store's commands use the configuration its
    /// first session was ingested with; later ingests must match it.
    #[arg(long, global = true, value_name = "FILE")]
    pub config: Option<PathBuf>,
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Format {
    /// Aligned columns for people.
    Table,
    Json,
    /// Comma-separated with a header line.
    Csv,
    /// KITTI pose rows (`seam poses` only).
    Kitti,
    /// TUM `t x y z qx qy qz qw` rows (`seam poses` only).
    Tum,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Create a new, empty store.
    Init(init::InitArgs),
    /// Add a session folder to a store (validated first; resumable; idempotent).
    Ingest(ingest::IngestArgs),
    /// List the sessions of a store.
    Sessions(sessions::StoreArg),
    /// Show what a store holds.
    Info(sessions::StoreArg),
    /// Print the optimised world pose of every keyframe.
    Poses(poses::PosesArgs),
    /// Verify the store's integrity; --repair removes orphan files.
    Check(check::CheckArgs),
    /// Write a simulated multi-session construction site with ground truth.
    Simulate(simulate::SimulateArgs),
    /// Simulate a site and ingest every session: the whole job on a default.
    Demo(demo::DemoArgs),
    /// Measure the store against ground truth.
    #[command(subcommand)]
    Eval(eval::EvalCommand),
    /// Write tables of a store as GeoParquet (and the maps as LAS/LAZ) for analysts.
    Export(export::ExportArgs),
    /// Recompute a store from the raw scans into a new store (same sessions, order, names).
    Rebuild(rebuild::RebuildArgs),
    /// Ask a store a question: `seam query site.seam 'changes in zone:"Tower B" since:s3'`.
    Query(query::QueryArgs),
    /// Named zones for queries: add, list, rm.
    #[command(subcommand)]
    Zones(zones::ZonesCommand),
    /// Draw a top-down picture (PNG): static map, lifelong map, changes or trajectories.
    Render(render::RenderArgs),
    /// Write a self-contained HTML report: sessions, what changed, pictures.
    Report(report::ReportArgs),
}

/// Shared settings resolved once from the global flags.
pub struct Ctx {
    pub format: Format,
    pub quiet: bool,
    pub config: crate::config::Config,
}

/// A command-line mistake found after parsing (exit code 2).
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct UsageError(pub String);

/// Lets glibc's malloc keep freed memory for reuse instead of handing it back
/// to the kernel at once: blocks up to 128 MiB come from the heap (not a
/// fresh `mmap` each), and up to 256 MiB of free heap top stays mapped.
///
/// Why: an ingest allocates and frees arrays of megabytes per keyframe and
/// per stage (world points, keys, per-voxel moments, labels). With glibc's
/// default, a freed block above its dynamic threshold is unmapped, and the
/// next one of that size takes a page fault for every 4 KiB it touches:
/// about 70,000 faults on SemanticKITTI 08 (`examples/dor_probe`, `perf
/// stat`), 48,000 with this, and the evidence generated 6-7 % faster (08:
/// 0.598 → 0.562 s, 04: 0.568 → 0.526 s, means of five alternating runs).
/// What is kept is freed memory seam reuses within the same step, so peak
/// memory grows a little: 190-194 → 197 MB there; on a 300-keyframe OS1-64
/// session (`bench/incremental.py --full`'s first) 1.07 → 1.13-1.15 GB, its
/// ingest 30.0 / 31.6 → 29.0 / 29.6 s (two runs each, in turns; evidence
/// 8.1-8.4 → 7.7-8.0 s, storing scans 0.93 → 0.66 s). Other allocators than
/// glibc's are left as they are. Call it first thing in `main`, so that
/// every allocation sees it.
pub fn tune_allocator() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: `mallopt` only sets malloc's tuning parameters, under malloc's
    // own locks; it has no preconditions on the caller.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 128 << 20);
        libc::mallopt(libc::M_TRIM_THRESHOLD, 256 << 20);
    }
}

/// Runs the command line and returns the process exit code.
pub fn main() -> std::process::ExitCode {
    let cli = match Cli::try_parse() {
        Ok(c) => c,
        Err(e) => {
            let _ = e.print();
            return std::process::ExitCode::from(if e.use_stderr() { ExitKind::Usage as u8 } else { 0 });
        }
    };
    match run(cli) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(err) => {
            let kind = exit_kind(&err);
            eprintln!("error: {err:#}");
            std::process::ExitCode::from(kind as u8)
        }
    }
}

/// The store a command works on, when it has one (not `init`'s: that one
/// does not exist yet).
fn store_of(command: &Command) -> Option<&std::path::Path> {
    use eval::EvalCommand as E;
    use zones::ZonesCommand as Z;
    Some(match command {
        Command::Init(_) | Command::Simulate(_) | Command::Demo(_) => return None,
        Command::Ingest(a) => &a.store,
        Command::Sessions(a) | Command::Info(a) => &a.store,
        Command::Poses(a) => &a.store,
        Command::Check(a) => &a.store,
        Command::Eval(E::Changes(a)) => &a.store,
        Command::Eval(E::Dor(a)) => &a.store,
        Command::Eval(E::Align(a)) => &a.store,
        Command::Export(a) => &a.store,
        Command::Rebuild(a) => &a.store,
        Command::Query(a) => &a.store,
        Command::Zones(Z::Add(a)) => &a.store,
        Command::Zones(Z::List(a)) => &a.store,
        Command::Zones(Z::Rm(a)) => &a.store,
        Command::Render(a) => &a.store,
        Command::Report(a) => &a.store,
    })
}

/// The configuration a command runs with: `--config`'s file over the
/// defaults; without `--config`, the one the command's store recorded at
/// its first ingest (or `init --config`), so a store keeps its settings
/// from one command to the next. A store that cannot be read here is left
/// to the command, which reports it.
fn resolve_config(cli: &Cli) -> anyhow::Result<crate::config::Config> {
    use crate::config::Config;
    if let Some(path) = &cli.config {
        return Ok(Config::from_file(path)?);
    }
    let recorded = store_of(&cli.command)
        .and_then(|root| crate::store::Store::open_read_only(root).ok())
        .and_then(|store| Some((store.recorded_config().ok()??, store.root().to_path_buf())));
    Ok(match recorded {
        Some((json, root)) => Config::from_recorded(&json, &root)?,
        None => Config::default(),
    })
}

fn run(cli: Cli) -> anyhow::Result<()> {
    let config = resolve_config(&cli)?;
    let ctx = Ctx { format: cli.format, quiet: cli.quiet, config };
    match cli.command {
        Command::Init(a) => init::run(&ctx, a, cli.config.is_some()),
        Command::Ingest(a) => ingest::run(&ctx, a),
        Command::Sessions(a) => sessions::run_sessions(&ctx, a),
        Command::Info(a) => sessions::run_info(&ctx, a),
        Command::Check(a) => check::run(&ctx, a),
        Command::Poses(a) => poses::run(&ctx, a),
        Command::Simulate(a) => simulate::run(&ctx, a),
        Command::Demo(a) => demo::run(&ctx, a),
        Command::Eval(c) => eval::run(&ctx, c),
        Command::Export(a) => export::run(&ctx, a),
        Command::Rebuild(a) => rebuild::run(&ctx, a),
        Command::Query(a) => query::run(&ctx, a),
        Command::Zones(c) => zones::run(&ctx, c),
        Command::Render(a) => render::run(&ctx, a),
        Command::Report(a) => report::run(&ctx, a),
    }
}
