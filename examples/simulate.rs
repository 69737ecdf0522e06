//! Simulates a construction site and prints what it wrote and how long it took.
//!
//! ```text
//! cargo run --release --example simulate -- OUT_DIR [--sessions 5] [--sensor os1-64] [--seed 1] [--keyframes 300] [--drift 1.0]
//! ```

use std::process::ExitCode;
use std::time::Instant;

use seam::sensor::SensorModel;
use seam::sim::{SimConfig, simulate};

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(out) = args.first().filter(|a| !a.starts_with("--")) else {
        eprintln!(
            "usage: simulate OUT_DIR [--sessions N] [--sensor os1-64|vlp16|avia|hdl-64e|hdl-32e] [--seed S] [--keyframes K] [--drift D]"
        );
        return ExitCode::from(2);
    };
    let mut cfg = SimConfig::default();
    for pair in args[1..].chunks(2) {
        let (Some(key), Some(value)) = (pair.first(), pair.get(1)) else {
            eprintln!("{} needs a value", pair[0]);
            return ExitCode::from(2);
        };
        let ok = match key.as_str() {
            "--sessions" => value.parse().map(|v| cfg.sessions = v).is_ok(),
            "--seed" => value.parse().map(|v| cfg.seed = v).is_ok(),
            "--keyframes" => value.parse().map(|v| cfg.keyframes_per_session = v).is_ok(),
            "--drift" => value.parse().map(|v| cfg.drift = v).is_ok(),
            "--sensor" => SensorModel::parse(value).map(|m| cfg.sensor = m).is_some(),
            _ => false,
        };
        if !ok {
            eprintln!("bad option {key} {value}");
            return ExitCode::from(2);
        }
    }
    let t0 = Instant::now();
    let last = std::cell::Cell::new((0usize, Instant::now()));
    let progress = |session: usize, done: usize, total: usize| {
        if done == total {
            let (_, start) = last.get();
            eprintln!("session {session}: {total} keyframes in {:.1} s", start.elapsed().as_secs_f64());
            last.set((session, Instant::now()));
        }
    };
    match simulate(std::path::Path::new(out), &cfg, &progress) {
        Ok(summary) => {
            for s in &summary.sessions {
                println!(
                    "{}: {} keyframes, {} points ({:.0}/scan), {} moving ({:.2} %), path {:.1} m, drift {:.2} m",
                    s.dir.display(),
                    s.keyframes,
                    s.points,
                    s.points as f64 / s.keyframes as f64,
                    s.moving_points,
                    100.0 * s.moving_points as f64 / s.points.max(1) as f64,
                    s.true_path_length_m,
                    s.final_drift_m
                );
            }
            println!("{} objects, {:.1} s total", summary.objects, t0.elapsed().as_secs_f64());
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}
