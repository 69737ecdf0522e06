//! Output files. Formats are documented in the module docs of `sim`; every
//! writer here produces the same bytes for the same input.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use super::SimError;
use super::assets::Surface;
use super::dynamics::{Mover, MoverPose};
use super::scan::KeyframeScan;
use super::shapes::Shape;
use super::site::SiteObject;
use crate::geometry::{Pose, pose_to_kitti_row};
use crate::sensor::SensorModel;

/// `fs::write` with the path in the error.
pub(crate) fn write(path: &Path, bytes: &[u8]) -> Result<(), SimError> {
    std::fs::write(path, bytes).map_err(|source| SimError::Io { path: path.to_path_buf(), source })
}

pub(crate) fn create_dir(path: &Path) -> Result<(), SimError> {
    std::fs::create_dir_all(path).map_err(|source| SimError::Io { path: path.to_path_buf(), source })
}

/// `velodyne/NNNNNN.bin` (f32 x y z intensity, LE) and `labels/NNNNNN.label` (u32 LE).
pub(crate) fn write_scan(session_dir: &Path, keyframe: usize, scan: &KeyframeScan) -> Result<(), SimError> {
    let mut bin = Vec::with_capacity(scan.points.len() * 16);
    for p in &scan.points {
        for v in p {
            bin.extend_from_slice(&v.to_le_bytes());
        }
    }
    write(&session_dir.join(format!("velodyne/{keyframe:06}.bin")), &bin)?;
    let labels: Vec<u8> = scan.labels.iter().flat_map(|l| l.to_le_bytes()).collect();
    write(&session_dir.join(format!("labels/{keyframe:06}.label")), &labels)
}

/// KITTI `poses.txt`: 12 row-major numbers of the 3×4 matrix per line.
pub(crate) fn kitti_poses(poses: &[Pose]) -> String {
    let mut s = String::with_capacity(poses.len() * 140);
    for p in poses {
        let row = pose_to_kitti_row(p);
        let cells: Vec<String> = row.iter().map(|v| format!("{:.9}", v + 0.0)).collect();
        s.push_str(&cells.join(" "));
        s.push('\n');
    }
    s
}

pub(crate) fn times_txt(times: &[f64]) -> String {
    times.iter().map(|t| format!("{t:.6}\n")).collect()
}

/// `session.toml` with exactly the keys seam's reader accepts; the rest is
/// in comments.
pub(crate) fn session_toml(session: usize, date: &str, sensor: SensorModel, platform: &str, seed: u64) -> String {
    format!(
        "# Simulated survey of a construction site (seam sim, seed {seed}).\n\
         # Platform: {platform}. Poses are odometry in the session's own frame;\n\
         # the true world poses are in gt/poses.txt.\n\
         name = \"s{session}\"\n\
         date = \"{date}\"\n\
         \n\
         [sensor]\n\
         model = \"{}\"\n",
        sensor.name()
    )
}

/// A box's `cx,cy,cz,length,width,height,yaw` columns, as every CSV here writes them.
fn box_csv(b: &Shape) -> String {
    let (c, z) = (b.center, b.size);
    format!("{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.6}", c[0], c[1], c[2], z[0], z[1], z[2], b.yaw)
}

/// `gt/dynamic.csv`: every mover's box at every keyframe.
pub(crate) fn dynamic_csv(movers: &[Mover], times: &[f64], poses: &[Vec<MoverPose>]) -> String {
    let mut s = String::from("keyframe,time_s,object_id,class,label,cx,cy,cz,length,width,height,yaw\n");
    for (k, (t, row)) in times.iter().zip(poses).enumerate() {
        for (m, p) in movers.iter().zip(row) {
            let b = m.bbox_at(p);
            let _ = writeln!(s, "{k},{t:.6},{},{},{},{}", m.object.id.0, m.object.class, m.object.label, box_csv(&b));
        }
    }
    s
}

/// `objects.csv`: one line per object with its box and the sessions it is in.
pub(crate) fn objects_csv(objects: &[SiteObject]) -> String {
    let mut s =
        String::from("id,class,label,dynamic,cx,cy,cz,length,width,height,yaw,first_session,last_session,sessions\n");
    for o in objects {
        let b = &o.bbox;
        let list: Vec<String> = o.sessions.iter().map(|x| x.to_string()).collect();
        let _ = writeln!(
            s,
            "{},{},{},{},{},{},{},{}",
            o.id.0,
            o.class,
            o.label,
            o.dynamic as u8,
            box_csv(b),
            o.sessions.first().copied().unwrap_or(0),
            o.sessions.last().copied().unwrap_or(0),
            list.join(";")
        );
    }
    s
}

/// `primitives.csv`: every part of every object (movers in their body frame).
pub(crate) fn primitives_csv(objects: &[SiteObject]) -> String {
    let mut s =
        String::from("object_id,part,kind,label,cx,cy,cz,length,width,height,yaw,reflectivity,surface,surface_param\n");
    for o in objects {
        for (k, p) in o.parts.iter().enumerate() {
            let (surface, param) = match p.surface {
                Surface::Solid => ("solid", 0.0),
                Surface::Mesh { pass } => ("mesh", pass),
                Surface::Foliage { extinction_per_m } => ("foliage", extinction_per_m),
            };
            let _ = writeln!(
                s,
                "{},{k},{},{},{},{:.3},{surface},{param:.3}",
                o.id.0,
                p.shape.kind.name(),
                p.label,
                box_csv(&p.shape),
                p.reflectivity
            );
        }
    }
    s
}

/// The marker line that says a folder was written by the simulator.
pub(crate) const GENERATOR_LINE: &str = "generator = \"seam sim\"";

pub(crate) struct SiteInfo<'a> {
    pub seed: u64,
    pub sensor: SensorModel,
    pub sessions: &'a [String],
    pub keyframes_per_session: usize,
    pub keyframe_spacing_m: f64,
    pub drift: f64,
    pub objects: usize,
}

pub(crate) fn site_toml(i: &SiteInfo) -> String {
    let names: Vec<String> = i.sessions.iter().map(|s| format!("\"{s}\"")).collect();
    format!(
        "# A simulated construction site: one KITTI-layout folder per session,\n\
         # objects.csv + primitives.csv (world frame; movers in their body frame)\n\
         # and per session gt/poses.txt (true LiDAR poses) and gt/dynamic.csv.\n\
         {GENERATOR_LINE}\n\
         seed = {}\n\
         sensor = \"{}\"\n\
         sessions = [{}]\n\
         keyframes_per_session = {}\n\
         keyframe_spacing_m = {:?}\n\
         drift = {:?}\n\
         objects = {}\n\
         site_size_m = [{:.1}, {:.1}]\n",
        i.seed,
        i.sensor.name(),
        names.join(", "),
        i.keyframes_per_session,
        i.keyframe_spacing_m,
        i.drift,
        i.objects,
        2.0 * super::site::FENCE[0],
        2.0 * super::site::FENCE[1],
    )
}

/// `session_01` … (wider when there are 100+ sessions).
pub(crate) fn session_dir_name(session: usize, sessions: usize) -> String {
    let width = sessions.to_string().len().max(2);
    format!("session_{session:0width$}")
}

/// Survey dates a few days apart from 2 March 2026, as `YYYY-MM-DD`.
pub(crate) fn session_dates(gaps_days: &[u32]) -> Vec<String> {
    let (mut y, mut m, mut d) = (2026u32, 3u32, 2u32);
    let mut out = Vec::with_capacity(gaps_days.len());
    for &gap in gaps_days {
        for _ in 0..gap {
            let leap = (y % 4 == 0 && y % 100 != 0) || y % 400 == 0;
            let len = [31, if leap { 29 } else { 28 }, 31, 30, 31, 30, 31, 31, 30, 31, 30, 31][(m - 1) as usize];
            d += 1;
            if d > len {
                d = 1;
                m += 1;
                if m > 12 {
                    m = 1;
                    y += 1;
                }
            }
        }
        out.push(format!("{y:04}-{m:02}-{d:02}"));
    }
    out
}

/// Written first into an output folder, so that even an interrupted
/// simulation is recognised (and replaced) by the next run.
const MARKER: &str = ".seam-sim";

/// Makes `out_dir` ready: created if missing; if it holds an earlier
/// simulation (its marker or `site.toml` says so), that simulation's files
/// are removed; any other non-empty folder is refused rather than mixed with.
pub(crate) fn prepare_out_dir(out_dir: &Path) -> Result<(), SimError> {
    let io = |path: &Path| {
        let path: PathBuf = path.to_path_buf();
        move |source| SimError::Io { path, source }
    };
    let mark = || write(&out_dir.join(MARKER), b"written by seam's simulator; safe to delete\n");
    if !out_dir.exists() {
        create_dir(out_dir)?;
        return mark();
    }
    let entries: Vec<PathBuf> = std::fs::read_dir(out_dir)
        .map_err(io(out_dir))?
        .map(|e| e.map(|e| e.path()))
        .collect::<Result<_, _>>()
        .map_err(io(out_dir))?;
    if entries.is_empty() {
        return mark();
    }
    let site = out_dir.join("site.toml");
    let ours = out_dir.join(MARKER).is_file()
        || std::fs::read_to_string(&site).is_ok_and(|t| t.lines().any(|l| l.trim() == GENERATOR_LINE));
    if !ours {
        return Err(SimError::Config(format!(
            "{} is not empty and does not hold an earlier simulation: choose a new or empty folder",
            out_dir.display()
        )));
    }
    for p in entries {
        let name = p.file_name().and_then(|n| n.to_str()).unwrap_or_default().to_string();
        let session_dir =
            name.strip_prefix("session_").is_some_and(|n| !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit()));
        if session_dir && p.is_dir() {
            std::fs::remove_dir_all(&p).map_err(io(&p))?;
        } else if ["objects.csv", "primitives.csv", "site.toml"].contains(&name.as_str()) {
            std::fs::remove_file(&p).map_err(io(&p))?;
        }
    }
    mark()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dates_roll_over_months_and_years() {
        assert_eq!(session_dates(&[0, 5, 30]), ["2026-03-02", "2026-03-07", "2026-04-06"]);
        let far = session_dates(&[365]);
        assert_eq!(far, ["2027-03-02"]);
        assert_eq!(session_dir_name(3, 5), "session_03");
        assert_eq!(session_dir_name(7, 120), "session_007");
    }

    #[test]
    fn site_toml_is_toml_with_typed_values() {
        let names = ["s1".to_string(), "s2".to_string()];
        let info = SiteInfo {
            seed: 3,
            sensor: SensorModel::Avia,
            sessions: &names,
            keyframes_per_session: 10,
            keyframe_spacing_m: 1.0,
            drift: 0.0,
            objects: 42,
        };
        let t: toml::Table = site_toml(&info).parse().unwrap();
        assert_eq!(t["generator"].as_str(), Some("seam sim"));
        assert_eq!(t["sensor"].as_str(), Some("avia"));
        assert_eq!(t["sessions"].as_array().map(Vec::len), Some(2));
        assert_eq!(t["keyframe_spacing_m"].as_float(), Some(1.0));
        assert_eq!(t["drift"].as_float(), Some(0.0));
        assert_eq!(t["objects"].as_integer(), Some(42));
    }

    #[test]
    fn kitti_rows_parse_back() {
        let p = Pose::new(nalgebra::Vector3::new(1.5, -2.25, 0.125), nalgebra::Vector3::new(0.1, -0.2, 2.5));
        let text = kitti_poses(&[p]);
        let v: Vec<f64> = text.split_whitespace().map(|x| x.parse().unwrap()).collect();
        let back = crate::geometry::pose_from_kitti_row(&v.try_into().unwrap()).unwrap();
        assert!((back.to_homogeneous() - p.to_homogeneous()).norm() < 1e-8);
    }
}
