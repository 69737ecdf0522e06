//! The paper's Table I analogue on simulated data: success rate of the loop
//! acceptance rules (`verify_loop`) on Far / Near / Near-Mismatch scan pairs
//! of Ouster, Velodyne and Avia LiDARs. The experiment is described in
//! `bench/loop_table_core.rs`.
//!
//! ```text
//! cargo run --release --example loop_table -- [--pairs 40] [--seed 7] [--keyframes 200] [--out DIR]
//!     [--reverse] [--csv FILE] [--min-inlier-ratio R] [--max-fitness M2] [--kappa K] [--rho-max R]
//! ```
//!
//! `--out` keeps the simulations (reused by later runs with the same seed and
//! keyframes); without it they go to a temporary folder. `--reverse` adds the
//! mixed groups the other way round (Ouster scans against Avia / Velodyne
//! maps). `--csv` writes every pair's numbers. The last four override
//! `LoopConfig`'s defaults, for tuning.

#[path = "../bench/loop_table_core.rs"]
mod loop_table_core;

use loop_table_core::{GROUPS, Group, REVERSED, Settings, csv, markdown, prepare_sites, run_group};
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

struct Args {
    settings: Settings,
    out: Option<PathBuf>,
    csv: Option<PathBuf>,
    reverse: bool,
}

fn parse_args() -> Result<Args, String> {
    let mut a = Args { settings: Settings::default(), out: None, csv: None, reverse: false };
    let mut it = std::env::args().skip(1);
    while let Some(arg) = it.next() {
        if arg == "--reverse" {
            a.reverse = true;
            continue;
        }
        let val = it.next().ok_or(format!("{arg} needs a value"))?;
        let num = |v: &str| v.parse::<f64>().map_err(|e| format!("{arg}: {e}"));
        let s = &mut a.settings;
        match arg.as_str() {
            "--pairs" => s.pairs = val.parse().map_err(|e| format!("--pairs: {e}"))?,
            "--seed" => s.seed = val.parse().map_err(|e| format!("--seed: {e}"))?,
            "--keyframes" => s.keyframes = val.parse().map_err(|e| format!("--keyframes: {e}"))?,
            "--out" => a.out = Some(PathBuf::from(val)),
            "--csv" => a.csv = Some(PathBuf::from(val)),
            "--min-inlier-ratio" => s.loop_cfg.min_inlier_ratio = num(&val)?,
            "--max-fitness" => s.loop_cfg.max_fitness_m2 = num(&val)?,
            "--kappa" => s.loop_cfg.dop.kappa = num(&val)?,
            "--rho-max" => s.loop_cfg.dop.rho_max = num(&val)?,
            _ => return Err(format!("unknown option {arg}")),
        }
    }
    Ok(a)
}

fn main() -> ExitCode {
    let args = match parse_args() {
        Ok(a) => a,
        Err(e) => {
            eprintln!(
                "{e}\nusage: loop_table [--pairs N] [--seed S] [--keyframes K] [--out DIR] [--reverse] [--csv FILE]"
            );
            return ExitCode::from(2);
        }
    };
    let tmp;
    let root = match &args.out {
        Some(d) => d.clone(),
        None => {
            tmp = match tempfile::tempdir() {
                Ok(t) => t,
                Err(e) => {
                    eprintln!("temporary folder: {e}");
                    return ExitCode::FAILURE;
                }
            };
            tmp.path().to_path_buf()
        }
    };
    let mut groups: Vec<Group> = GROUPS.to_vec();
    if args.reverse {
        groups.extend(REVERSED);
    }
    let s = &args.settings;
    let t0 = Instant::now();
    let sites = match prepare_sites(&root, &groups, s) {
        Ok(x) => x,
        Err(e) => {
            eprintln!("{e}");
            return ExitCode::FAILURE;
        }
    };
    let t_sim = t0.elapsed().as_secs_f64();
    let mut outcomes = Vec::new();
    for g in &groups {
        let tg = Instant::now();
        match run_group(&sites, g, s) {
            Ok(o) => {
                eprintln!("{}: {} pairs in {:.1} s", g.name, o.len(), tg.elapsed().as_secs_f64());
                outcomes.extend(o);
            }
            Err(e) => {
                eprintln!("{}: {e}", g.name);
                return ExitCode::FAILURE;
            }
        }
    }
    let c = &s.loop_cfg;
    println!(
        "# Loop reliability (Table I analogue), simulated site seed {}, 2 sessions x {} keyframes per sensor\n",
        s.seed, s.keyframes
    );
    println!(
        "Pairs per cell: {} (source: session 2 scan; target: session 1 keyframe ±{} neighbours merged by ground truth).\n\
         Near: true distance ≤ {} m{}, start = truth ⊕ (≤ {} m, ≤ {}°). Near-Mismatch: same pairs, start = truth ⊕ \
         ({}-{} m horizontal offset | {}-{}° yaw | both, in turn). Far: true distance ≥ {} m, start = identity. \
         Correct iff accepted ⇔ result within {} m / {}° of the truth.\n",
        s.pairs,
        c.neighbours,
        s.near_max_m,
        format_args!(" (with an Avia: headings within {}°)", s.avia_max_heading_deg),
        s.near_perturb_m,
        s.near_perturb_deg,
        s.mismatch_offset_m.0,
        s.mismatch_offset_m.1,
        s.mismatch_yaw_deg.0,
        s.mismatch_yaw_deg.1,
        s.far_min_m,
        s.tol_m,
        s.tol_deg
    );
    println!(
        "Rules: min_inlier_ratio {}, max_fitness_m2 {}, kappa {}, rho_max {}, DOP voxel {} m, GICP voxel {} m.\n",
        c.min_inlier_ratio, c.max_fitness_m2, c.dop.kappa, c.dop.rho_max, c.dop.voxel_size_m, c.gicp.voxel_size_m
    );
    println!("{}", markdown(&outcomes, &groups));
    println!(
        "Simulation {:.1} s (reused when --out already holds it), registration {:.1} s on {} threads.",
        t_sim,
        t0.elapsed().as_secs_f64() - t_sim,
        rayon::current_num_threads()
    );
    if let Some(path) = &args.csv
        && let Err(e) = std::fs::write(path, csv(&outcomes))
    {
        eprintln!("{}: {e}", path.display());
        return ExitCode::FAILURE;
    }
    ExitCode::SUCCESS
}
