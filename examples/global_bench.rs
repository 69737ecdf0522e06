//! Global map-to-map registration on simulated sessions: simulates a
//! two-session site per seed, merges each session's keyframes into a map by
//! its odometry, registers session 2's map to session 1's and prints one JSON
//! object per seed (truth, estimate, errors, verdict, evidence, timings).
//! Driven by `bench/global_vs_kiss_matcher.py`, which runs KISS-Matcher on
//! the maps written with `--out`.
//!
//! ```text
//! cargo run --release --example global_bench -- [--seeds 1-10] [--sensor os1-64] [--keyframes 60]
//!     [--spacing 1.0] [--every 2] [--map-voxel 0.2] [--threads 2] [--out DIR] [--drift 1.0]
//!     [--config '{"voxel_size_m": 0.7}'] [--maps-only] [--same-session]
//! ```
//!
//! `--same-session` pairs two halves of session 1 instead (even keyframes as
//! the target, odd ones moved by a random yaw and offset as the source): the
//! same viewpoints, so local descriptors repeat, unlike between sessions.
//!
//! `--config` overrides [`GlobalConfig`] fields (JSON, the names of its TOML
//! section); `--maps-only` writes the maps without registering them.
//!
//! With `--out DIR`, `DIR/seed_NN/{target,source}.bin` hold the maps (f32 x y z,
//! voxel centroids at `--map-voxel`) and `DIR/seed_NN/truth.txt` the true
//! `t_target_source` (KITTI 3×4); the simulations themselves are deleted.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use seam::geometry::Pose;
use seam::registration::downsample::voxel_downsample;
use seam::registration::global::{GlobalConfig, register_maps};
use seam::sensor::SensorModel;
use seam::sim::{SimConfig, simulate};

struct Args {
    seeds: Vec<u64>,
    sensor: SensorModel,
    keyframes: usize,
    spacing: f64,
    every: usize,
    map_voxel: f64,
    threads: usize,
    out: Option<PathBuf>,
    drift: f64,
    config: GlobalConfig,
    maps_only: bool,
    same_session: bool,
}

fn parse_seeds(s: &str) -> Result<Vec<u64>, String> {
    let mut out = Vec::new();
    for part in s.split(',') {
        let bad = |_| format!("--seeds: cannot read {part:?} (use 1-10 or 1,4,7)");
        match part.split_once('-') {
            Some((a, b)) => out.extend(a.parse::<u64>().map_err(bad)?..=b.parse::<u64>().map_err(bad)?),
            None => out.push(part.parse().map_err(bad)?),
        }
    }
    Ok(out)
}

fn parse_args() -> Result<Args, String> {
    let mut a = Args {
        seeds: (1..=10).collect(),
        sensor: SensorModel::Os1_64,
        keyframes: 60,
        spacing: 1.0,
        every: 2,
        map_voxel: 0.2,
        threads: 2,
        out: None,
        drift: 1.0,
        config: GlobalConfig::default(),
        maps_only: false,
        same_session: false,
    };
    let mut it = std::env::args().skip(1);
    while let Some(arg) = it.next() {
        if arg == "--maps-only" {
            a.maps_only = true;
            continue;
        }
        if arg == "--same-session" {
            a.same_session = true;
            continue;
        }
        let val = it.next().ok_or(format!("{arg} needs a value"))?;
        let num = |v: &str| v.parse::<f64>().map_err(|e| format!("{arg}: {e}"));
        match arg.as_str() {
            "--seeds" => a.seeds = parse_seeds(&val)?,
            "--sensor" => a.sensor = SensorModel::parse(&val).ok_or(format!("unknown sensor {val}"))?,
            "--keyframes" => a.keyframes = num(&val)? as usize,
            "--spacing" => a.spacing = num(&val)?,
            "--every" => a.every = (num(&val)? as usize).max(1),
            "--map-voxel" => a.map_voxel = num(&val)?,
            "--threads" => a.threads = num(&val)? as usize,
            "--out" => a.out = Some(PathBuf::from(val)),
            "--drift" => a.drift = num(&val)?,
            "--config" => a.config = serde_json::from_str(&val).map_err(|e| format!("--config: {e}"))?,
            _ => return Err(format!("unknown option {arg}")),
        }
    }
    Ok(a)
}

/// A session's keyframes merged by odometry (every `every`-th), voxel centroids.
fn session_map(dir: &Path, first: usize, every: usize, voxel: f64) -> Result<Vec<[f32; 3]>, String> {
    let src = seam::io::detect_session(dir).map_err(|e| e.to_string())?;
    let mut pts: Vec<[f64; 3]> = Vec::new();
    for kf in src.keyframes.iter().skip(first).step_by(every) {
        let scan = seam::io::read_session_scan(&src, kf.index).map_err(|e| e.to_string())?;
        let t = kf.t_session_sensor;
        pts.extend(scan.points.iter().map(|p| {
            let q = t * nalgebra::Point3::new(p[0] as f64, p[1] as f64, p[2] as f64);
            [q.x, q.y, q.z]
        }));
    }
    Ok(voxel_downsample(&pts, voxel, true).iter().map(|p| [p[0] as f32, p[1] as f32, p[2] as f32]).collect())
}

/// Yaw in ±180°, up to 30 m horizontal and 2 m vertical offset, from the seed.
fn random_motion(seed: u64) -> Pose {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed ^ 0x5eed);
    let t = nalgebra::Vector3::new(
        rng.random_range(-21.0..21.0),
        rng.random_range(-21.0..21.0),
        rng.random_range(-2.0..2.0),
    );
    Pose::new(t, nalgebra::Vector3::new(0.0, 0.0, rng.random_range(-std::f64::consts::PI..std::f64::consts::PI)))
}

fn read_single_pose(path: &Path) -> Result<Pose, String> {
    let poses = seam::io::read_kitti_poses(path).map_err(|e| e.to_string())?;
    poses.first().copied().ok_or(format!("{}: no pose", path.display()))
}

fn kitti_row(p: &Pose) -> String {
    seam::geometry::pose_to_kitti_row(p).iter().map(|v| format!("{v:.9}")).collect::<Vec<_>>().join(" ")
}

/// Translation (m) and rotation (deg) error of `estimate` against `truth`:
/// `|t_est − t_true|` and the angle of `R_trueᵀ R_est`.
fn pose_error(truth: &Pose, estimate: &Pose) -> (f64, f64) {
    let dt = (estimate.translation.vector - truth.translation.vector).norm();
    (dt, (truth.rotation.inverse() * estimate.rotation).angle().to_degrees())
}

fn write_bin(path: &Path, pts: &[[f32; 3]]) -> Result<(), String> {
    let bytes: Vec<u8> = pts.iter().flat_map(|p| p.iter().flat_map(|c| c.to_le_bytes())).collect();
    std::fs::write(path, bytes).map_err(|e| format!("{}: {e}", path.display()))
}

fn run_seed(a: &Args, seed: u64, work: &Path) -> Result<serde_json::Value, String> {
    let sim_dir = work.join(format!("sim_{seed:02}"));
    let cfg = SimConfig {
        sessions: 2,
        sensor: a.sensor,
        seed,
        keyframes_per_session: a.keyframes,
        keyframe_spacing_m: a.spacing,
        drift: a.drift,
    };
    let t0 = Instant::now();
    simulate(&sim_dir, &cfg, &|_, _, _| {}).map_err(|e| e.to_string())?;
    let sim_s = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    let target = session_map(&sim_dir.join("session_01"), 0, a.every, a.map_voxel)?;
    let source = if a.same_session {
        // The other keyframes of session 1, moved by a random yaw and offset.
        let odd = session_map(&sim_dir.join("session_01"), a.every.div_ceil(2), a.every, a.map_voxel)?;
        let motion = random_motion(seed);
        odd.iter()
            .map(|p| {
                let q = motion.inverse() * nalgebra::Point3::new(p[0] as f64, p[1] as f64, p[2] as f64);
                [q.x as f32, q.y as f32, q.z as f32]
            })
            .collect()
    } else {
        session_map(&sim_dir.join("session_02"), 0, a.every, a.map_voxel)?
    };
    let map_s = t1.elapsed().as_secs_f64();
    let t_w_1 = read_single_pose(&sim_dir.join("session_01/gt/t_world_session.txt"))?;
    let t_w_2 = read_single_pose(&sim_dir.join("session_02/gt/t_world_session.txt"))?;
    let truth = if a.same_session { random_motion(seed) } else { t_w_1.inverse() * t_w_2 };
    if let Some(out) = &a.out {
        let d = out.join(format!("seed_{seed:02}"));
        std::fs::create_dir_all(&d).map_err(|e| format!("{}: {e}", d.display()))?;
        write_bin(&d.join("target.bin"), &target)?;
        write_bin(&d.join("source.bin"), &source)?;
        std::fs::write(d.join("truth.txt"), kitti_row(&truth) + "\n").map_err(|e| e.to_string())?;
    }
    std::fs::remove_dir_all(&sim_dir).map_err(|e| e.to_string())?;
    if a.maps_only {
        return Ok(
            serde_json::json!({ "seed": seed, "target_points_in": target.len(), "source_points_in": source.len() }),
        );
    }
    let res = register_maps(&target, &source, &a.config);
    let (err_t, err_r) = pose_error(&truth, &res.t_target_source);
    let (reason, success) = match &res.verdict {
        seam::registration::global::Verdict::Success => (String::new(), true),
        seam::registration::global::Verdict::Failure { reason } => (reason.clone(), false),
    };
    Ok(serde_json::json!({
        "seed": seed,
        "sensor": a.sensor.name(),
        "truth_yaw_deg": truth.rotation.euler_angles().2.to_degrees(),
        "truth_offset_m": truth.translation.vector.norm(),
        "success": success,
        "reason": reason,
        "err_t_m": err_t,
        "err_r_deg": err_r,
        "t_target_source": kitti_row(&res.t_target_source),
        "correspondences": res.correspondences,
        "feature_inliers": res.feature_inliers,
        "inliers": res.inliers,
        "inlier_ratio": res.inlier_ratio,
        "clique": res.clique_size,
        "hypotheses": res.hypotheses,
        "refined": res.refined,
        "overlap_fraction": res.overlap_fraction,
        "runner_up_ratio": res.runner_up_ratio,
        "target_points_in": target.len(),
        "source_points_in": source.len(),
        "target_voxels": res.target_points,
        "source_voxels": res.source_points,
        "elapsed_s": res.elapsed_s,
        "timings": serde_json::to_value(res.timings).unwrap_or_default(),
        "sim_s": sim_s,
        "map_s": map_s,
    }))
}

fn main() -> ExitCode {
    let a = match parse_args() {
        Ok(a) => a,
        Err(e) => {
            eprintln!("global_bench: {e}");
            return ExitCode::from(2);
        }
    };
    let pool = match rayon::ThreadPoolBuilder::new().num_threads(a.threads).build() {
        Ok(p) => p,
        Err(e) => {
            eprintln!("global_bench: {e}");
            return ExitCode::FAILURE;
        }
    };
    let work = match &a.out {
        Some(out) => out.clone(),
        None => std::env::temp_dir().join(format!("seam_global_bench_{}", std::process::id())),
    };
    let mut failed = false;
    for &seed in &a.seeds {
        match pool.install(|| run_seed(&a, seed, &work)) {
            Ok(v) => println!("{v}"),
            Err(e) => {
                eprintln!("seed {seed}: {e}");
                failed = true;
            }
        }
    }
    if a.out.is_none() {
        let _ = std::fs::remove_dir_all(&work);
    }
    if failed { ExitCode::FAILURE } else { ExitCode::SUCCESS }
}
