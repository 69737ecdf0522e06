//! Global (coarse) map-to-map registration, end to end (MATH.md §2).
//!
//! Simulated sites: session 2's map (keyframes merged by its drifting
//! odometry) is registered to session 1's; the truth is
//! `inv(t_world_s1) · t_world_s2`. The promises tested:
//!
//! - it finds the transform (any yaw, tens of metres of offset) on ≥ 19 of 20
//!   sites within 0.5 m / 2°, and
//! - it never reports success with a wrong transform (> 1.5 m or > 5°), on
//!   those sites, on sparse (VLP-16) and narrow (Avia) sensors, with realistic
//!   odometry drift, and on pairs that do not overlap at all.
//!
//! Drift: the simulator's realistic drift (`drift = 1.0`, 0.4-0.9 % of the
//! distance) bends a 60 m session's map by up to ~1 m where it is far from
//! its first keyframe, and the truth is exact only at the first keyframe. No
//! rigid transform then lies within 0.5 m of the truth for every site (ICP
//! started *at* the truth ends up to 1.3 m away), so the accuracy test uses a
//! quarter of that drift; the realistic-drift test checks the verdict.

use std::path::Path;
use std::sync::{Mutex, OnceLock};

use nalgebra::{Point3, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use seam::geometry::Pose;
use seam::registration::downsample::voxel_downsample;
use seam::registration::global::{GlobalConfig, GlobalResult, Verdict, register_maps};
use seam::sensor::SensorModel;
use seam::sim::{SimConfig, simulate};

/// Keyframes per session (1 m apart) and the stride of those merged into a map.
const KEYFRAMES: usize = 60;
const EVERY: usize = 2;

/// A simulated pair of session maps and the true `t_target_source`.
#[derive(Clone)]
struct Pair {
    target: Vec<[f32; 3]>,
    source: Vec<[f32; 3]>,
    truth: Pose,
}

/// A session's keyframes merged by odometry (every `EVERY`-th), 0.2 m voxels.
fn session_map(dir: &Path) -> Vec<[f32; 3]> {
    let src = seam::io::detect_session(dir).unwrap();
    let mut pts: Vec<[f64; 3]> = Vec::new();
    for kf in src.keyframes.iter().step_by(EVERY) {
        let scan = seam::io::read_session_scan(&src, kf.index).unwrap();
        let t = kf.t_session_sensor;
        pts.extend(
            scan.points.iter().map(|p| -> [f64; 3] { (t * Point3::new(p[0] as f64, p[1] as f64, p[2] as f64)).into() }),
        );
    }
    voxel_downsample(&pts, 0.2, true).iter().map(|p| [p[0] as f32, p[1] as f32, p[2] as f32]).collect()
}

fn simulate_pair(seed: u64, sensor: SensorModel, drift: f64) -> Pair {
    let dir = tempfile::tempdir().unwrap();
    let cfg = SimConfig { sessions: 2, sensor, seed, keyframes_per_session: KEYFRAMES, keyframe_spacing_m: 1.0, drift };
    simulate(dir.path(), &cfg, &|_, _, _| {}).unwrap();
    let pose = |s: &str| seam::io::read_kitti_poses(&dir.path().join(s).join("gt/t_world_session.txt")).unwrap()[0];
    Pair {
        target: session_map(&dir.path().join("session_01")),
        source: session_map(&dir.path().join("session_02")),
        truth: pose("session_01").inverse() * pose("session_02"),
    }
}

/// OS1-64 pairs at the accuracy test's drift, simulated once per test binary
/// (the no-overlap test crops some of them).
fn os1_pair(seed: u64) -> Pair {
    static CACHE: OnceLock<Mutex<std::collections::HashMap<u64, Pair>>> = OnceLock::new();
    let cache = CACHE.get_or_init(Default::default);
    if let Some(p) = cache.lock().unwrap().get(&seed) {
        return p.clone();
    }
    let p = simulate_pair(seed, SensorModel::Os1_64, 0.25);
    cache.lock().unwrap().insert(seed, p.clone());
    p
}

/// `(translation error m, rotation error deg)` of an estimate.
fn error(truth: &Pose, est: &Pose) -> (f64, f64) {
    (
        (est.translation.vector - truth.translation.vector).norm(),
        (truth.rotation.inverse() * est.rotation).angle().to_degrees(),
    )
}

fn is_wrong(e: (f64, f64)) -> bool {
    e.0 > 1.5 || e.1 > 5.0
}

fn is_accurate(e: (f64, f64)) -> bool {
    e.0 <= 0.5 && e.1 <= 2.0
}

fn describe(label: &str, truth: &Pose, r: &GlobalResult) -> String {
    let (et, er) = error(truth, &r.t_target_source);
    let verdict = match &r.verdict {
        Verdict::Success => "success".to_string(),
        Verdict::Failure { reason } => format!("failure: {reason}"),
    };
    format!(
        "{label}: err {et:.2} m {er:.2}° | inliers {} ratio {:.2} runner-up {:.2} overlap {:.2} | {:.1} s | {verdict}",
        r.inliers, r.inlier_ratio, r.runner_up_ratio, r.overlap_fraction, r.elapsed_s
    )
}

/// Counts over a set of registrations, and one line per registration.
#[derive(Default)]
struct Tally {
    successes: usize,
    accurate: usize,
    wrong: usize,
    lines: Vec<String>,
}

impl Tally {
    fn table(&self) -> String {
        let t = self.lines.join("\n");
        eprintln!("{t}");
        t
    }
}

/// Registers every pair.
fn run(pairs: impl Iterator<Item = (String, Pair)>) -> Tally {
    let mut tally = Tally::default();
    for (label, p) in pairs {
        let r = register_maps(&p.target, &p.source, &GlobalConfig::default());
        let e = error(&p.truth, &r.t_target_source);
        if r.verdict.is_success() {
            tally.successes += 1;
            tally.accurate += is_accurate(e) as usize;
            tally.wrong += is_wrong(e) as usize;
        }
        tally.lines.push(describe(&label, &p.truth, &r));
    }
    tally
}

#[test]
fn os1_64_twenty_sites_are_aligned_and_never_wrongly() {
    let t = run((1..=20).map(|s| (format!("seed {s:2}"), os1_pair(s))));
    let table = t.table();
    assert_eq!(t.wrong, 0, "wrong transforms reported as successes:\n{table}");
    assert!(t.accurate >= 19, "only {}/20 within 0.5 m / 2°:\n{table}", t.accurate);
}

#[test]
fn sparse_and_narrow_sensors_are_aligned_and_never_wrongly() {
    let pairs =
        [(SensorModel::Vlp16, [1, 3, 4]), (SensorModel::Avia, [1, 2, 6])].into_iter().flat_map(|(sensor, seeds)| {
            seeds.map(|s| (format!("{} seed {s}", sensor.name()), simulate_pair(s, sensor, 0.25)))
        });
    let t = run(pairs);
    let table = t.table();
    assert_eq!(t.wrong, 0, "wrong transforms reported as successes:\n{table}");
    assert!(t.accurate >= 5, "only {}/6 within 0.5 m / 2°:\n{table}", t.accurate);
}

#[test]
fn realistic_drift_never_gives_a_wrong_success() {
    // Seeds with the largest drift-induced offsets at drift 1.0.
    let pairs = [1, 6, 19].map(|s| (format!("drift 1.0 seed {s}"), simulate_pair(s, SensorModel::Os1_64, 1.0)));
    let t = run(pairs.into_iter());
    let table = t.table();
    assert_eq!(t.wrong, 0, "wrong transforms reported as successes:\n{table}");
    // The sessions are still found (in GICP's basin), only not all to 0.5 m.
    assert!(t.successes >= 2, "{table}");
}

/// Splits a pair into a target half and a source half with a gap between
/// them: no surface is in both maps.
fn disjoint_halves(p: &Pair, gap_m: f64, swap: bool) -> (Vec<[f32; 3]>, Vec<[f32; 3]>) {
    let mut xs: Vec<f32> = p.target.iter().map(|q| q[0]).collect();
    xs.sort_by(f32::total_cmp);
    let split = xs[xs.len() / 2] as f64;
    let side = |x: f64| if swap { -(x - split) } else { x - split };
    let target = p.target.iter().copied().filter(|q| side(q[0] as f64) < -gap_m / 2.0).collect();
    let source = p
        .source
        .iter()
        .copied()
        .filter(|q| side((p.truth * Point3::new(q[0] as f64, q[1] as f64, q[2] as f64)).x) > gap_m / 2.0)
        .collect();
    (target, source)
}

#[test]
fn maps_that_do_not_overlap_are_left_unaligned() {
    let mut report = Vec::new();
    for seed in [1, 2] {
        let p = os1_pair(seed);
        for swap in [false, true] {
            let (target, source) = disjoint_halves(&p, 4.0, swap);
            let r = register_maps(&target, &source, &GlobalConfig::default());
            report.push((describe(&format!("seed {seed} halves (swap {swap})"), &p.truth, &r), r.verdict));
        }
    }
    // An unrelated cloud: the synthetic scene below, against a site map.
    let p = os1_pair(1);
    let r = register_maps(&p.target, &synthetic_scene(5, 0.0, 80.0), &GlobalConfig::default());
    report.push((describe("site vs unrelated scene", &p.truth, &r), r.verdict));
    let table: Vec<&str> = report.iter().map(|(l, _)| l.as_str()).collect();
    eprintln!("{}", table.join("\n"));
    for (line, verdict) in &report {
        match verdict {
            Verdict::Failure { reason } => assert!(reason.contains("unaligned"), "{line}"),
            Verdict::Success => panic!("a map pair without overlap was aligned: {line}"),
        }
    }
}

/// A synthetic scene sampled afresh (`seed`): gently undulating ground,
/// boxes of random size and heading, poles and two long walls, within
/// `x ∈ [x0, x0 + width]`, `y ∈ [-40, 40]`. The scene's geometry is fixed;
/// only the sampling depends on `seed`.
fn synthetic_scene(seed: u64, x0: f64, width: f64) -> Vec<[f32; 3]> {
    let mut layout = ChaCha8Rng::seed_from_u64(1000);
    let ground = |x: f64, y: f64| 0.3 * (x / 9.0).sin() + 0.2 * (y / 7.0).cos();
    let boxes: Vec<([f64; 2], [f64; 3], f64)> = (0..45)
        .map(|_| {
            let c = [layout.random_range(-60.0..60.0), layout.random_range(-38.0..38.0)];
            let size = [layout.random_range(1.0..7.0), layout.random_range(1.0..4.0), layout.random_range(0.8..5.0)];
            (c, size, layout.random_range(0.0..std::f64::consts::PI))
        })
        .collect();
    let poles: Vec<[f64; 2]> =
        (0..25).map(|_| [layout.random_range(-60.0..60.0), layout.random_range(-38.0..38.0)]).collect();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut pts: Vec<[f64; 3]> = Vec::new();
    let inside = |x: f64| x >= x0 && x <= x0 + width;
    for _ in 0..(width * 80.0 * 6.0) as usize {
        let (x, y) = (rng.random_range(x0..x0 + width), rng.random_range(-40.0..40.0));
        pts.push([x, y, ground(x, y)]);
    }
    for (c, s, yaw) in &boxes {
        let (sn, cs) = yaw.sin_cos();
        let z0 = ground(c[0], c[1]);
        let area = 2.0 * (s[0] + s[1]) * s[2] + s[0] * s[1];
        for _ in 0..(area * 12.0) as usize {
            // A point on the box's sides or top, in its own frame.
            let (u, v, w) = (rng.random_range(-0.5..0.5), rng.random_range(-0.5..0.5), rng.random_range(0.0..1.0));
            let local = match rng.random_range(0..5) {
                0 => [0.5 * s[0], v * s[1], w * s[2]],
                1 => [-0.5 * s[0], v * s[1], w * s[2]],
                2 => [u * s[0], 0.5 * s[1], w * s[2]],
                3 => [u * s[0], -0.5 * s[1], w * s[2]],
                _ => [u * s[0], v * s[1], s[2]],
            };
            pts.push([c[0] + cs * local[0] - sn * local[1], c[1] + sn * local[0] + cs * local[1], z0 + local[2]]);
        }
    }
    for c in &poles {
        for _ in 0..300 {
            let a = rng.random_range(0.0..std::f64::consts::TAU);
            pts.push([c[0] + 0.15 * a.cos(), c[1] + 0.15 * a.sin(), ground(c[0], c[1]) + rng.random_range(0.0..6.0)]);
        }
    }
    for _ in 0..20_000 {
        let (t, z) = (rng.random_range(-60.0..60.0), rng.random_range(0.0..3.0));
        pts.push([t, 39.0, ground(t, 39.0) + z]);
        pts.push([-61.0, t * 0.6, ground(-61.0, t * 0.6) + z]);
    }
    pts.retain(|p| inside(p[0]));
    pts.iter().map(|p| [p[0] as f32, p[1] as f32, p[2] as f32]).collect()
}

fn moved(pts: &[[f32; 3]], t: &Pose) -> Vec<[f32; 3]> {
    pts.iter()
        .map(|p| {
            let q = t * Point3::new(p[0] as f64, p[1] as f64, p[2] as f64);
            [q.x as f32, q.y as f32, q.z as f32]
        })
        .collect()
}

/// The descriptor path on its own: where two maps sample the same surfaces
/// alike, FPFH + mutual matches + max clique + GNC-TLS find the transform,
/// in 4-DoF and, without gravity, for a tilted source in 6-DoF.
#[test]
fn feature_path_aligns_a_resampled_scene_in_4_and_6_dof() {
    let target = synthetic_scene(1, -60.0, 90.0);
    let source_world = synthetic_scene(2, -30.0, 90.0);
    let cases = [
        (Pose::new(Vector3::new(25.0, -18.0, 1.5), Vector3::new(0.0, 0.0, 2.6)), true),
        (Pose::new(Vector3::new(-31.0, 12.0, -2.0), Vector3::new(0.12, -0.08, -1.9)), false),
    ];
    for (t_source_world, gravity_aligned) in cases {
        let source = moved(&source_world, &t_source_world);
        // BEV search off: the answer must come from the feature path.
        let cfg = GlobalConfig { gravity_aligned, bev_hypotheses: 0, ..GlobalConfig::default() };
        let r = register_maps(&target, &source, &cfg);
        let truth = t_source_world.inverse();
        let line = describe(&format!("synthetic, gravity {gravity_aligned}"), &truth, &r);
        eprintln!("{line}");
        let (et, er) = error(&truth, &r.t_target_source);
        assert!(r.verdict.is_success() && et < 0.2 && er < 0.5, "{line}");
        assert!(r.clique_size >= 10 && r.feature_inliers >= 10, "{line}");
    }
}
