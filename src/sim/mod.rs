//! A simulated construction site surveyed several times: seam's test bed and
//! demo data.
//!
//! This module owns generating the site, the surveys and their ground truth,
//! and reading that ground truth back ([`read_ground_truth`]). It knows
//! nothing of the store or the pipeline; its sessions are ordinary KITTI
//! folders that `seam ingest` reads like real data.
//!
//! # What is simulated
//!
//! A 110 m × 92 m site (see `site.rs` for the map): uneven ground, roads, a
//! mesh fence with gates, a building under construction (columns, slabs, a
//! stair core, walls, scaffolding and shoring of 48-60 mm tubes), a tower
//! crane, site offices, containers, material stacks, skips, stockpiles,
//! trees, light poles, parked cars, neighbouring buildings. Between sessions
//! the building grows, shoring and scaffolding come down, materials are
//! delivered and removed, containers move and cars come and go: every session
//! after the first has several objects appearing and several disappearing,
//! some in the building's apron that every route circles. Within a session
//! 4-8 people and 1-3 machines move along the roads, stopping and going.
//!
//! Each session walks a different route through the site (always once round
//! the building, so it loops), with a handheld/backpack sensor at 1.8 m or
//! (every third session) a robot at 0.6 m. Every beam of the sensor
//! ([`SensorModel`]: OS1-64, VLP-16, HDL-64E, HDL-32E bands, Livox Avia
//! rosette) is cast against the scene at the keyframe's true pose; returns
//! get range noise, reflectivity- and incidence-dependent reach, random
//! dropouts and an intensity. Odometry drifts 0.4-0.9 % of the distance
//! walked (1.2-2.7 m over 300 m, mostly yaw) and is expressed in each
//! session's own frame (random yaw, up to 30 m offset).
//!
//! # Output
//!
//! ```text
//! OUT/site.toml         seed, sensor, session names, sizes
//! OUT/objects.csv       id,class,label,dynamic,cx,cy,cz,length,width,height,yaw,first_session,last_session,sessions
//! OUT/primitives.csv    object_id,part,kind,label,cx,cy,cz,length,width,height,yaw,reflectivity,surface,surface_param
//! OUT/session_NN/velodyne/NNNNNN.bin    f32 LE x y z intensity, LiDAR frame
//! OUT/session_NN/labels/NNNNNN.label    u32 LE: class | instance << 16 (instance = object id, 0 = ground)
//! OUT/session_NN/poses.txt              KITTI 3×4 odometry t_session_lidar (no calib.txt: LiDAR poses)
//! OUT/session_NN/times.txt              seconds since the first keyframe
//! OUT/session_NN/session.toml           name = "sN", date, [sensor] model
//! OUT/session_NN/gt/poses.txt           KITTI 3×4 true t_world_lidar
//! OUT/session_NN/gt/t_world_session.txt KITTI 3×4: where the session frame sits in the world
//!                                       (exact at the first keyframe; odometry drifts after)
//! OUT/session_NN/gt/dynamic.csv         keyframe,time_s,object_id,class,label,cx,cy,cz,length,width,height,yaw
//! ```
//!
//! Boxes are centre, full size along their own axes, and yaw about +z (rad).
//! `sessions` lists the 1-based session numbers separated by `;`. A mover
//! (`dynamic` = 1) exists in one session; its objects.csv box is its pose at
//! the first keyframe and its primitives are in its body frame (origin at the
//! box centre). Shape kinds are described in `shapes.rs`.
//!
//! Session numbers are 1-based everywhere (they match `session_01` and
//! `s1`); keyframes are 0-based (they match `000000.bin`).
//!
//! ```no_run
//! use seam::sim::{SimConfig, read_ground_truth, simulate};
//!
//! let out = std::path::Path::new("site-sim");
//! let summary = simulate(out, &SimConfig { sessions: 3, ..SimConfig::default() }, &|_, _, _| {})?;
//! let truth = read_ground_truth(out)?;
//! // Which object, if any, holds this world point at session 2, keyframe 10?
//! let hit = truth.object_at(2, 10, [12.0, 3.5, 1.0], 0.05);
//! println!("{} points in session 1; {hit:?}", summary.sessions[0].points);
//! # Ok::<(), seam::sim::SimError>(())
//! ```
//!
//! # Determinism
//!
//! Every random number is derived from the seed and what it is for
//! (`seeds.rs`); keyframes are simulated in parallel but each from its own
//! seed, so the same seed writes the same bytes whatever the thread count
//! (on the same platform: `sin` and `exp` may round differently elsewhere).
//!
//! # Layout
//! - `seeds.rs`: seed derivation, per-ray hashes
//! - `shapes.rs`: primitives, ray intersection, containment
//! - `ground.rs`: the height field (also the ray-casting grid)
//! - `assets.rs`: what each kind of object is made of
//! - `site.rs`: objects, roads, placement rules; `layout.rs`: what stands where, when
//! - `trajectory.rs`: routes, true poses; `odometry.rs`: drift, session frames
//! - `dynamics.rs`: people and machines, their bodies and motion
//! - `sensor_model.rs`: beam patterns and sensor specs
//! - `raycast.rs`: the gridded scene and ray casting
//! - `scan.rs`: rays to points and labels
//! - `writer.rs`: files; `truth.rs`: reading the truth back

mod assets;
mod dynamics;
mod ground;
mod layout;
mod odometry;
mod raycast;
mod scan;
mod seeds;
mod sensor_model;
mod shapes;
mod site;
mod trajectory;
mod truth;
mod writer;

use std::path::{Path, PathBuf};

use rand::Rng;
use rayon::prelude::*;

pub use assets::{Part, Surface};
/// The simulator's beam directions of one frame, for tests of sensor-frame evidence.
#[cfg(test)]
pub(crate) use sensor_model::ray_directions;
/// The simulated sensors' ranges, for evaluation code's "in view".
pub(crate) use sensor_model::spec as sensor_spec;
pub use shapes::{Shape, ShapeKind};
pub use site::{ObjectId, SiteObject};
pub use truth::{GroundTruth, GtSession, read_ground_truth};

use crate::sensor::SensorModel;
use dynamics::MoverPose;
use raycast::{Prim, Scene};
use seeds::tag;

/// What to simulate. `Default` is five 300-keyframe OS1-64 sessions.
#[derive(Debug, Clone, PartialEq)]
pub struct SimConfig {
    /// Number of sessions (surveys), ≥ 1.
    pub sessions: usize,
    pub sensor: SensorModel,
    pub seed: u64,
    /// Keyframes per session, ≥ 1.
    pub keyframes_per_session: usize,
    /// Distance walked between keyframes, m (0.1-10).
    pub keyframe_spacing_m: f64,
    /// Scale of the odometry drift: 1.0 is realistic, 0.0 is perfect odometry.
    pub drift: f64,
}

impl Default for SimConfig {
    fn default() -> SimConfig {
        SimConfig {
            sessions: 5,
            sensor: SensorModel::Os1_64,
            seed: 1,
            keyframes_per_session: 300,
            keyframe_spacing_m: 1.0,
            drift: 1.0,
        }
    }
}

impl SimConfig {
    fn validate(&self) -> Result<(), SimError> {
        let bad = |m: String| Err(SimError::Config(m));
        if self.sessions == 0 {
            return bad("sessions must be at least 1".into());
        }
        if self.keyframes_per_session == 0 {
            return bad("keyframes_per_session must be at least 1".into());
        }
        if !(0.1..=10.0).contains(&self.keyframe_spacing_m) {
            return bad(format!("keyframe_spacing_m is {}; use 0.1 to 10 m", self.keyframe_spacing_m));
        }
        if !(0.0..=100.0).contains(&self.drift) {
            return bad(format!("drift is {}; use 0 (none) to 100 (1.0 is realistic)", self.drift));
        }
        Ok(())
    }
}

/// What a simulation wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct SimSummary {
    pub sessions: Vec<SimSessionSummary>,
    /// Objects in `objects.csv`, static and moving.
    pub objects: usize,
    pub out_dir: PathBuf,
}

#[derive(Debug, Clone, PartialEq)]
pub struct SimSessionSummary {
    pub dir: PathBuf,
    pub keyframes: usize,
    pub points: u64,
    /// Points labelled with a moving class (252-259).
    pub moving_points: u64,
    pub true_path_length_m: f64,
    /// Odometry's error at the last keyframe when aligned at the first, m.
    pub final_drift_m: f64,
}

#[derive(Debug, thiserror::Error)]
pub enum SimError {
    #[error("{}: {source}", path.display())]
    Io { path: PathBuf, source: std::io::Error },
    #[error("simulation settings: {0}")]
    Config(String),
    /// A ground-truth file that does not read back.
    #[error("{}:line {line}: {message}", path.display())]
    Format { path: PathBuf, line: usize, message: String },
}

/// Simulates `cfg.sessions` surveys of the site into `out_dir` (created if
/// missing; an earlier simulation there is replaced, any other content is
/// refused). `progress(session, keyframes_done, keyframes_total)` is called
/// from this thread after every keyframe.
pub fn simulate(
    out_dir: &Path,
    cfg: &SimConfig,
    progress: &dyn Fn(usize, usize, usize),
) -> Result<SimSummary, SimError> {
    cfg.validate()?;
    let site = site::Site::generate(cfg.seed, cfg.sessions);
    // Object ids are the labels' 16-bit instance ids.
    let most = site.objects.len() + cfg.sessions * dynamics::MAX_MOVERS;
    if most > usize::from(u16::MAX) {
        return Err(SimError::Config(format!(
            "{} sessions may need {most} object ids, more than 16-bit instance ids hold; simulate fewer sessions",
            cfg.sessions
        )));
    }
    writer::prepare_out_dir(out_dir)?;
    let mut objects = site.objects.clone();
    let mut date_rng = seeds::rng(cfg.seed, &[tag::SESSION, 0]);
    let gaps: Vec<u32> = (0..cfg.sessions).map(|s| if s == 0 { 0 } else { date_rng.random_range(3..=9) }).collect();
    let dates = writer::session_dates(&gaps);
    let names: Vec<String> = (1..=cfg.sessions).map(|s| format!("s{s}")).collect();
    let mut sessions = Vec::with_capacity(cfg.sessions);
    for s in 1..=cfg.sessions {
        let first_id = objects.len() as u32 + 1;
        let (summary, movers) = simulate_session(out_dir, cfg, &site, s, &dates[s - 1], first_id, progress)?;
        objects.extend(movers);
        sessions.push(summary);
    }
    if objects.len() > usize::from(u16::MAX) {
        return Err(SimError::Config(format!(
            "{} objects do not fit 16-bit instance ids; simulate fewer sessions",
            objects.len()
        )));
    }
    writer::write(&out_dir.join("objects.csv"), writer::objects_csv(&objects).as_bytes())?;
    writer::write(&out_dir.join("primitives.csv"), writer::primitives_csv(&objects).as_bytes())?;
    let info = writer::SiteInfo {
        seed: cfg.seed,
        sensor: cfg.sensor,
        sessions: &names,
        keyframes_per_session: cfg.keyframes_per_session,
        keyframe_spacing_m: cfg.keyframe_spacing_m,
        drift: cfg.drift,
        objects: objects.len(),
    };
    // site.toml last: its presence marks a complete simulation.
    writer::write(&out_dir.join("site.toml"), writer::site_toml(&info).as_bytes())?;
    Ok(SimSummary { sessions, objects: objects.len(), out_dir: out_dir.to_path_buf() })
}

/// One session: trajectory, odometry, movers, files, then every scan.
/// Returns its summary and its movers as objects.
fn simulate_session(
    out_dir: &Path,
    cfg: &SimConfig,
    site: &site::Site,
    s: usize,
    date: &str,
    first_id: u32,
    progress: &dyn Fn(usize, usize, usize),
) -> Result<(SimSessionSummary, Vec<SiteObject>), SimError> {
    let n = cfg.keyframes_per_session;
    let truth = trajectory::true_path(&site.roads, &site.ground, cfg.seed, s, n, cfg.keyframe_spacing_m);
    let odom = odometry::odometry(&truth.poses, truth.length_m, cfg.seed, s, cfg.drift);
    let duration = truth.times.last().copied().unwrap_or(0.0);
    let movers = dynamics::session_movers(&site.roads, &site.ground, cfg.seed, s, duration, first_id);
    let mover_poses: Vec<Vec<MoverPose>> =
        truth.times.iter().map(|&t| movers.iter().map(|m| m.pose_at(t, &site.ground)).collect()).collect();

    let dir = out_dir.join(writer::session_dir_name(s, cfg.sessions));
    for sub in ["velodyne", "labels", "gt"] {
        writer::create_dir(&dir.join(sub))?;
    }
    let platform = match truth.platform {
        trajectory::Platform::Backpack => "backpack, LiDAR 1.8 m above ground",
        trajectory::Platform::Robot => "legged robot, LiDAR 0.6 m above ground",
    };
    writer::write(&dir.join("session.toml"), writer::session_toml(s, date, cfg.sensor, platform, cfg.seed).as_bytes())?;
    writer::write(&dir.join("poses.txt"), writer::kitti_poses(&odom.poses).as_bytes())?;
    writer::write(&dir.join("times.txt"), writer::times_txt(&truth.times).as_bytes())?;
    writer::write(&dir.join("gt/poses.txt"), writer::kitti_poses(&truth.poses).as_bytes())?;
    let t_world_session = odom.t_session_world.inverse();
    writer::write(&dir.join("gt/t_world_session.txt"), writer::kitti_poses(&[t_world_session]).as_bytes())?;
    writer::write(&dir.join("gt/dynamic.csv"), writer::dynamic_csv(&movers, &truth.times, &mover_poses).as_bytes())?;

    let statics: Vec<Prim> = (site.objects.iter().filter(|o| o.present_in(s)))
        .flat_map(|o| {
            o.parts
                .iter()
                .enumerate()
                .map(move |(k, p)| Prim::new(p, o.id.0 as u16, (u64::from(o.id.0) << 16) | k as u64))
        })
        .collect();
    let scene = Scene::new(&site.ground, statics);
    let reach = sensor_model::spec(cfg.sensor).max_range_m + 10.0;
    let scan_one = |k: usize| -> Result<(u64, u64), SimError> {
        let pose = &truth.poses[k];
        let near = |p: &&MoverPose| (p.center[0] - pose.translation.x).hypot(p.center[1] - pose.translation.y) < reach;
        let prims: Vec<Prim> =
            movers.iter().zip(&mover_poses[k]).filter(|(_, p)| near(p)).flat_map(|(m, p)| m.prims_at(p)).collect();
        let seed = seeds::derive(cfg.seed, &[tag::KEYFRAME, s as u64, k as u64]);
        let scan = scan::scan_keyframe(&scene, &prims, cfg.sensor, pose, truth.times[k], seed);
        writer::write_scan(&dir, k, &scan)?;
        Ok((scan.points.len() as u64, scan.moving))
    };
    // Chunks keep progress reports on this thread; results do not depend on them.
    let chunk = (4 * rayon::current_num_threads()).max(8);
    let (mut points, mut moving_points) = (0, 0);
    for start in (0..n).step_by(chunk) {
        let results: Vec<Result<(u64, u64), SimError>> =
            (start..(start + chunk).min(n)).into_par_iter().map(scan_one).collect();
        for (i, r) in results.into_iter().enumerate() {
            let (p, m) = r?;
            points += p;
            moving_points += m;
            progress(s, start + i + 1, n);
        }
    }
    let summary = SimSessionSummary {
        dir,
        keyframes: n,
        points,
        moving_points,
        true_path_length_m: truth.length_m,
        final_drift_m: odom.final_drift_m,
    };
    Ok((summary, movers.into_iter().map(|m| m.object).collect()))
}
