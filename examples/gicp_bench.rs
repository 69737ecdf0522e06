//! Times seam's GICP on one scan pair and prints one JSON object; driven by
//! `bench/gicp_vs_small_gicp.py`.
//!
//! ```text
//! cargo run --release --example gicp_bench -- TARGET SOURCE [--voxel 0.25] [--threads 2] [--runs 5]
//!     [--init r00,r01,..,r23 (12 numbers, row-major 3x4 of t_target_source)] [--serial] [--stages]
//! ```
//!
//! Preprocessing (downsampling, kd-tree, covariances) of both clouds is timed
//! apart from the registration; both numbers are medians (and minima) over
//! `--runs`. `--stages` adds the times of the source's preprocessing stages.

use seam::geometry::Pose;
use seam::registration::{GicpConfig, align, preprocess};
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

struct Args {
    target: PathBuf,
    source: PathBuf,
    voxel: f64,
    threads: usize,
    runs: usize,
    init: Pose,
    serial: bool,
    stages: bool,
}

fn parse_pose(s: &str) -> Result<Pose, String> {
    let v: Vec<f64> =
        s.split(',').map(|t| t.trim().parse::<f64>()).collect::<Result<_, _>>().map_err(|e| e.to_string())?;
    let row: [f64; 12] = v.try_into().map_err(|v: Vec<f64>| format!("--init needs 12 numbers, got {}", v.len()))?;
    seam::geometry::pose_from_kitti_row(&row).map_err(|e| format!("--init is not a rotation (error {e})"))
}

fn parse_args() -> Result<Args, String> {
    let mut it = std::env::args().skip(1);
    let mut pos = Vec::new();
    let mut a = Args {
        target: PathBuf::new(),
        source: PathBuf::new(),
        voxel: 0.25,
        threads: 2,
        runs: 5,
        init: Pose::identity(),
        serial: false,
        stages: false,
    };
    while let Some(arg) = it.next() {
        let mut val = |name: &str| it.next().ok_or(format!("{name} needs a value"));
        match arg.as_str() {
            "--voxel" => a.voxel = val("--voxel")?.parse().map_err(|e| format!("--voxel: {e}"))?,
            "--threads" => a.threads = val("--threads")?.parse().map_err(|e| format!("--threads: {e}"))?,
            "--runs" => a.runs = val("--runs")?.parse().map_err(|e| format!("--runs: {e}"))?,
            "--init" => a.init = parse_pose(&val("--init")?)?,
            "--serial" => a.serial = true,
            "--stages" => a.stages = true,
            _ => pos.push(PathBuf::from(arg)),
        }
    }
    let [target, source]: [PathBuf; 2] = pos.try_into().map_err(|_| "usage: gicp_bench TARGET SOURCE [options]")?;
    a.target = target;
    a.source = source;
    Ok(a)
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn min(v: &[f64]) -> f64 {
    v.iter().copied().fold(f64::INFINITY, f64::min)
}

fn run(a: &Args) -> Result<serde_json::Value, String> {
    let target = seam::io::read_scan(&a.target).map_err(|e| e.to_string())?;
    let source = seam::io::read_scan(&a.source).map_err(|e| e.to_string())?;
    let cfg = GicpConfig { voxel_size_m: a.voxel, parallel: !a.serial, ..GicpConfig::default() };
    let pool = rayon::ThreadPoolBuilder::new().num_threads(a.threads).build().map_err(|e| e.to_string())?;
    let (mut pre_ms, mut reg_ms) = (Vec::new(), Vec::new());
    let mut last = None;
    for _ in 0..a.runs.max(1) {
        pool.install(|| {
            let t0 = Instant::now();
            let tgt = preprocess(&target.points, &cfg);
            let src = preprocess(&source.points, &cfg);
            let t1 = Instant::now();
            let res = align(&tgt, &src, &a.init, &cfg);
            let t2 = Instant::now();
            pre_ms.push((t1 - t0).as_secs_f64() * 1e3);
            reg_ms.push((t2 - t1).as_secs_f64() * 1e3);
            last = Some((res, tgt.len(), src.len()));
        });
    }
    let (res, n_tgt, n_src) = last.ok_or("no run")?;
    let stages = if a.stages {
        pool.install(|| stage_breakdown(&source.points, &cfg, a.runs.max(1)))
    } else {
        serde_json::Value::Null
    };
    let m = res.t_target_source.to_homogeneous();
    let rows: Vec<Vec<f64>> = (0..4).map(|r| (0..4).map(|c| m[(r, c)]).collect()).collect();
    let total: Vec<f64> = pre_ms.iter().zip(&reg_ms).map(|(p, r)| p + r).collect();
    Ok(serde_json::json!({
        "t_target_source": rows,
        "converged": res.converged,
        "iterations": res.iterations,
        "num_inliers": res.num_inliers,
        "inlier_ratio": res.inlier_ratio,
        "fitness_m2": res.fitness,
        "target_points": n_tgt,
        "source_points": n_src,
        "preprocess_min_ms": min(&pre_ms),
        "registration_min_ms": min(&reg_ms),
        "total_min_ms": min(&total),
        "preprocess_ms": median(pre_ms),
        "registration_ms": median(reg_ms),
        "total_ms": median(total),
        "source_stages_ms": stages,
    }))
}

/// Median times of the preprocessing stages of one cloud.
fn stage_breakdown(points: &[[f32; 3]], cfg: &GicpConfig, runs: usize) -> serde_json::Value {
    use seam::registration::{covariance, downsample, kdtree};
    let (mut ds, mut tree, mut cov) = (Vec::new(), Vec::new(), Vec::new());
    for _ in 0..runs {
        let t0 = Instant::now();
        let down = downsample::voxel_downsample(points, cfg.voxel_size_m, cfg.parallel);
        let t1 = Instant::now();
        let kd = kdtree::KdTree::build(&down);
        let t2 = Instant::now();
        let c = covariance::estimate_covariances(&down, &kd, cfg.k_neighbors, cfg.plane_epsilon, cfg.parallel);
        let t3 = Instant::now();
        std::hint::black_box(c);
        ds.push((t1 - t0).as_secs_f64() * 1e3);
        tree.push((t2 - t1).as_secs_f64() * 1e3);
        cov.push((t3 - t2).as_secs_f64() * 1e3);
    }
    serde_json::json!({ "downsample": median(ds), "kdtree": median(tree), "covariances": median(cov) })
}

fn main() -> ExitCode {
    match parse_args().and_then(|a| run(&a)) {
        Ok(v) => {
            println!("{v}");
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("gicp_bench: {e}");
            ExitCode::FAILURE
        }
    }
}
