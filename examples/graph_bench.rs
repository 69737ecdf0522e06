//! Benchmark: optimise a 5-session, 1,500-keyframe pose graph with submap
//! anchors (issue 3's "under 2 s" goal). Synthetic trajectories: five 300 m
//! walks round the same loop with drifting odometry, 20 m submaps, and an
//! inter-session loop every 5th keyframe.
//!
//! `cargo run --release --example graph_bench`

use nalgebra::{Translation3, UnitQuaternion, Vector3};
use seam::geometry::Pose;
use seam::graph::{Between, GraphConfig, PoseGraph, Robust, information, optimize};

fn truth(s: usize, k: usize) -> Pose {
    // A 300 m loop (a circle of radius ~47.7 m), each session shifted in phase.
    let a = (k as f64 + 37.0 * s as f64) / 300.0 * std::f64::consts::TAU;
    let r = 300.0 / std::f64::consts::TAU;
    Pose::from_parts(
        Translation3::new(r * a.cos(), r * a.sin(), 0.0),
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), a + std::f64::consts::FRAC_PI_2),
    )
}

#[allow(clippy::needless_range_loop)] // (session, keyframe) indices are the point here
fn main() {
    let (sessions, per) = (5, 300);
    let mut g = PoseGraph::default();
    let bias =
        Pose::from_parts(Translation3::new(0.002, 0.0, 0.0), UnitQuaternion::from_euler_angles(0.0, 0.0, 0.0015));
    let mut index = vec![vec![0usize; per]; sessions];
    for s in 0..sessions {
        let mut dr = truth(s, 0);
        let mut anchor = 0;
        let mut first = Pose::identity();
        for k in 0..per {
            if k > 0 {
                dr *= truth(s, k - 1).inverse() * truth(s, k) * bias;
            }
            if k % 20 == 0 {
                anchor = g.add_anchor(dr, s == 0 && k == 0);
                first = dr;
            }
            index[s][k] = g.add_keyframe(anchor, first.inverse() * dr, k % 20 == 0);
            if k > 0 {
                let z = truth(s, k - 1).inverse() * truth(s, k) * bias;
                g.betweens.push(Between {
                    i: index[s][k - 1],
                    j: index[s][k],
                    z,
                    information: information(0.01, 0.01),
                    robust: Robust::None,
                });
            }
        }
    }
    for s in 1..sessions {
        for k in (0..per).step_by(5) {
            // The nearest keyframe of session 0 on the same circle.
            let k0 = (k + 37 * s) % per;
            let z = truth(0, k0).inverse() * truth(s, k);
            g.betweens.push(Between {
                i: index[0][k0],
                j: index[s][k],
                z,
                information: information(0.01, 0.1),
                robust: Robust::Cauchy { k: 1.0 },
            });
        }
    }
    let t0 = std::time::Instant::now();
    let report = optimize(&mut g, &GraphConfig::default()).expect("solves");
    let dt = t0.elapsed().as_secs_f64();
    let mut worst: f64 = 0.0;
    for s in 0..sessions {
        for k in 0..per {
            worst = worst.max((g.world_pose(index[s][k]).translation.vector - truth(s, k).translation.vector).norm());
        }
    }
    println!(
        "{{\"keyframes\": {}, \"anchors\": {}, \"factors\": {}, \"iterations\": {}, \"seconds\": {dt:.3}, \"initial_cost\": {:.1}, \"final_cost\": {:.1}, \"worst_position_error_m\": {worst:.3}}}",
        g.locals.len(),
        g.anchors.len(),
        report.factors,
        report.iterations,
        report.initial_cost,
        report.final_cost
    );
}
