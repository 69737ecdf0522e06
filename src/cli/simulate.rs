//! `seam simulate OUT_DIR [--sessions 5] [--sensor os1-64] [--seed 1] [--keyframes 300]`

use super::output::{json, log, print_json, thousands};
use super::{Ctx, UsageError};
use crate::sensor::SensorModel;
use crate::sim::{SimConfig, SimSummary, simulate};
use clap::Args;
use std::path::{Path, PathBuf};

#[derive(Debug, Args)]
pub struct SimulateArgs {
    /// Output folder: one KITTI-layout folder per session plus ground truth.
    pub out: PathBuf,
    #[command(flatten)]
    pub site: SiteArgs,
}

/// The simulated site's knobs, shared with `seam demo`.
#[derive(Debug, Args, Clone)]
pub struct SiteArgs {
    /// Number of sessions (surveys of the site).
    #[arg(long, default_value_t = 5)]
    pub sessions: usize,
    /// Sensor model: os1-64, vlp16, avia (also hdl-64e, hdl-32e).
    #[arg(long, default_value = "os1-64")]
    pub sensor: String,
    /// Random seed; the same seed gives the same files.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Keyframes per session, about one per metre walked [default: 300 for
    /// `seam simulate`, 150 for `seam demo`].
    #[arg(long)]
    pub keyframes: Option<usize>,
}

/// `seam simulate`'s sessions: 300 keyframes, the size of the paper's
/// construction-site runs.
pub const SIMULATE_KEYFRAMES: usize = 300;
/// `seam demo`'s sessions: 150 keyframes, so that the whole demo (five
/// sessions aligned, cleaned and compared, queries, report) takes a few
/// minutes on two cores.
pub const DEMO_KEYFRAMES: usize = 150;

impl SiteArgs {
    /// The simulator's settings; `default_keyframes` when `--keyframes` is not given.
    pub fn to_config(&self, default_keyframes: usize) -> anyhow::Result<SimConfig> {
        let keyframes = self.keyframes.unwrap_or(default_keyframes);
        let sensor = SensorModel::parse(&self.sensor).ok_or_else(|| {
            let names: Vec<&str> = SensorModel::ALL.iter().map(|m| m.name()).collect();
            UsageError(format!(
                "--sensor {:?} is not a sensor seam knows; use one of {}",
                self.sensor,
                names.join(", ")
            ))
        })?;
        if self.sessions == 0 || keyframes < 2 {
            return Err(UsageError("--sessions must be ≥ 1 and --keyframes ≥ 2".into()).into());
        }
        Ok(SimConfig {
            sessions: self.sessions,
            sensor,
            seed: self.seed,
            keyframes_per_session: keyframes,
            ..SimConfig::default()
        })
    }
}

/// Runs the simulator with a progress line per session on stderr.
pub fn simulate_site(ctx: &Ctx, out: &Path, cfg: &SimConfig) -> anyhow::Result<SimSummary> {
    let bars = super::output::Bars::new(ctx, "simulate");
    let last = std::sync::Mutex::new(usize::MAX);
    let progress = |session: usize, _done: usize, total: usize| {
        use crate::pipeline::Progress;
        if let Ok(mut l) = last.lock()
            && *l != session
        {
            if *l != usize::MAX {
                bars.end();
            }
            bars.begin(&format!("session {session}"), total as u64);
            *l = session;
        }
        bars.advance(1);
    };
    let summary = simulate(out, cfg, &progress)?;
    crate::pipeline::Progress::end(&bars);
    Ok(summary)
}

pub fn run(ctx: &Ctx, a: SimulateArgs) -> anyhow::Result<()> {
    let cfg = a.site.to_config(SIMULATE_KEYFRAMES)?;
    let t0 = std::time::Instant::now();
    let summary = simulate_site(ctx, &a.out, &cfg)?;
    if json(ctx) {
        return print_json(&serde_json::json!({
            "out_dir": summary.out_dir,
            "objects": summary.objects,
            "sessions": summary.sessions.iter().map(|s| serde_json::json!({
                "dir": s.dir, "keyframes": s.keyframes, "points": s.points, "moving_points": s.moving_points,
                "true_path_length_m": s.true_path_length_m, "final_drift_m": s.final_drift_m,
            })).collect::<Vec<_>>(),
            "wall_s": t0.elapsed().as_secs_f64(),
        }));
    }
    for s in &summary.sessions {
        println!(
            "{}: {} keyframes, {} points ({} moving), path {:.0} m, odometry drift {:.2} m",
            s.dir.display(),
            s.keyframes,
            thousands(s.points),
            thousands(s.moving_points),
            s.true_path_length_m,
            s.final_drift_m
        );
    }
    log(
        ctx,
        format!(
            "simulated {} sessions, {} objects in {:.1} s",
            summary.sessions.len(),
            summary.objects,
            t0.elapsed().as_secs_f64()
        ),
    );
    Ok(())
}
