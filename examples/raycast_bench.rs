//! Rays per second of the evidence accumulation on one real scan, serial
//! against parallel (MATH.md §6).
//!
//! ```text
//! cargo run --release --example raycast_bench -- [SCAN] [--voxel 0.2] [--runs 5]
//! ```
//!
//! SCAN defaults to `../shared/data/semantickitti/04/velodyne/000000.bin`; the
//! sensor sits at the origin of the scan's frame. Prints the median time of
//! `--runs` runs of each version, as points per second, into a fresh map and
//! into one that already holds the scan, and checks that both versions give
//! the same map.

use seam::evidence::{EvidenceConfig, EvidenceMap, KeyframeEvidence, accumulate_keyframe, accumulate_keyframe_par};
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

const DEFAULT_SCAN: &str = "../shared/data/semantickitti/04/velodyne/000000.bin";

type Accumulate = fn(&[f64; 3], &[[f64; 3]], u32, &EvidenceConfig, &mut EvidenceMap) -> KeyframeEvidence;

/// Median seconds of `f` on the scan as keyframe 1, into a fresh map (cold:
/// every voxel is inserted) and into a map that already holds the scan as
/// keyframe 0 (warm: the usual case inside a submap, where most voxels exist).
fn median_secs(runs: usize, points: &[[f64; 3]], cfg: &EvidenceConfig, f: Accumulate) -> (f64, f64, EvidenceMap) {
    let (mut cold, mut warm) = (Vec::with_capacity(runs), Vec::with_capacity(runs));
    let mut map = EvidenceMap::default();
    for _ in 0..runs {
        map = EvidenceMap::default();
        let t = Instant::now();
        f(&[0.0; 3], points, 0, cfg, &mut map);
        cold.push(t.elapsed().as_secs_f64());
        let t = Instant::now();
        f(&[0.0; 3], points, 1, cfg, &mut map);
        warm.push(t.elapsed().as_secs_f64());
    }
    cold.sort_by(f64::total_cmp);
    warm.sort_by(f64::total_cmp);
    (cold[runs / 2], warm[runs / 2], map)
}

fn main() -> ExitCode {
    let mut scan = PathBuf::from(DEFAULT_SCAN);
    let mut cfg = EvidenceConfig::default();
    let mut runs = 5usize;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let value = |args: &mut dyn Iterator<Item = String>| args.next().and_then(|v| v.parse::<f64>().ok());
        match a.as_str() {
            "--voxel" => match value(&mut args) {
                Some(v) if v > 0.0 => cfg.voxel_size_m = v,
                _ => return usage("--voxel needs a positive number of metres"),
            },
            "--runs" => match value(&mut args) {
                Some(v) if v >= 1.0 => runs = v as usize,
                _ => return usage("--runs needs a count of at least 1"),
            },
            _ if a.starts_with("--") => return usage(&format!("unknown option {a}")),
            _ => scan = PathBuf::from(a),
        }
    }
    if !scan.exists() {
        println!("skipped: scan {} is absent (pass another scan as the first argument)", scan.display());
        return ExitCode::SUCCESS;
    }
    let points: Vec<[f64; 3]> = match seam::io::read_scan(&scan) {
        Ok(s) => s.points.iter().map(|p| [p[0] as f64, p[1] as f64, p[2] as f64]).collect(),
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::FAILURE;
        }
    };
    let (serial_cold, serial_warm, serial_map) = median_secs(runs, &points, &cfg, accumulate_keyframe);
    let (par_cold, par_warm, par_map) = median_secs(runs, &points, &cfg, accumulate_keyframe_par);
    let n = points.len() as f64;
    println!(
        "{}: {} points, voxel {} m, {} voxels, {} threads, median of {runs}",
        scan.display(),
        points.len(),
        cfg.voxel_size_m,
        serial_map.len(),
        rayon::current_num_threads()
    );
    for (name, s, p) in [("fresh map", serial_cold, par_cold), ("warm map ", serial_warm, par_warm)] {
        println!(
            "{name}: serial {:7.1} ms {:9.0} points/s | parallel {:7.1} ms {:9.0} points/s ({:.2}x)",
            s * 1e3,
            n / s,
            p * 1e3,
            n / p,
            s / p
        );
    }
    if serial_map != par_map {
        eprintln!("error: the parallel map differs from the serial one");
        return ExitCode::FAILURE;
    }
    ExitCode::SUCCESS
}

fn usage(msg: &str) -> ExitCode {
    eprintln!("error: {msg}\nusage: raycast_bench [SCAN] [--voxel 0.2] [--runs 5]");
    ExitCode::FAILURE
}
