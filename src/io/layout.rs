//! Session folders: which layout a folder is, its keyframes (scan file +
//! odometry pose in the session frame), and the files that define it.
//!
//! Detection looks for, in this order (the first that matches wins):
//!
//! | layout | scans | poses |
//! |---|---|---|
//! | `kitti` | `velodyne/*.bin` | `poses.txt` (KITTI 3×4, or TUM if it has 8 columns) or `poses_tum.txt`; optional `calib.txt` `Tr:`, `times.txt`, `labels/*.label` |
//! | `scans-pcd` | `Scans/*.pcd` | `optimized_poses.txt`, else `poses.txt`; optional `times.txt` |
//! | `dynamic-map-benchmark` | `pcd/*.pcd` (world frame) | each file's `VIEWPOINT` |
//!
//! Scans are ordered by file name, numerically when every stem is digits
//! (so `2.pcd` precedes `10.pcd` even without zero padding). Dot files are
//! ignored. Everything but the scans' points is read and validated here, so
//! a bad pose file fails before the pipeline writes anything.

use std::path::{Path, PathBuf};

use crate::geometry::{Pose, Scan};

use super::error::{ReadError, ReadErrorKind};
use super::kitti::{read_calib_tr, read_times};
use super::meta::{SessionMeta, read_session_meta};
use super::pcd::read_viewpoint;
use super::poses::{pose_file_columns, read_kitti_poses, read_tum_poses};
use super::{read_scan, validate_scan};

/// The session layouts seam recognises.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Layout {
    /// KITTI / SemanticKITTI: `velodyne/*.bin` + `poses.txt` (+ `calib.txt`, `times.txt`, `labels/`).
    Kitti,
    /// ELite / LT-mapper / SC-A-LOAM: `Scans/*.pcd` + `optimized_poses.txt` or `poses.txt`.
    ScansPcd,
    /// DynamicMap_Benchmark: `pcd/*.pcd` in the world frame, sensor pose in `VIEWPOINT`.
    DynamicMapBenchmark,
}

impl Layout {
    pub const ALL: [Layout; 3] = [Layout::Kitti, Layout::ScansPcd, Layout::DynamicMapBenchmark];

    /// The name used in messages and receipts.
    pub fn name(&self) -> &'static str {
        match self {
            Layout::Kitti => "kitti",
            Layout::ScansPcd => "scans-pcd",
            Layout::DynamicMapBenchmark => "dynamic-map-benchmark",
        }
    }

    /// The scan folder and scan extension that identify the layout.
    fn scan_dir(&self) -> (&'static str, &'static str) {
        match self {
            Layout::Kitti => ("velodyne", "bin"),
            Layout::ScansPcd => ("Scans", "pcd"),
            Layout::DynamicMapBenchmark => ("pcd", "pcd"),
        }
    }
}

/// What every layout error hint lists.
pub(crate) const ACCEPTED: &str = "seam reads: kitti (velodyne/NNNNNN.bin + poses.txt or poses_tum.txt, optional \
     calib.txt, times.txt, labels/), scans-pcd (Scans/NNNNNN.pcd + optimized_poses.txt or poses.txt), \
     dynamic-map-benchmark (pcd/NNNNNN.pcd with the sensor pose in VIEWPOINT)";

/// One scan of a session and its odometry.
#[derive(Debug, Clone, PartialEq)]
pub struct KeyframeSource {
    /// Scan index in the session, 0-based, in scan file order.
    pub index: usize,
    pub scan_path: PathBuf,
    /// Odometry pose of the LiDAR in the session frame.
    pub t_session_sensor: Pose,
    pub stamp_s: Option<f64>,
    /// SemanticKITTI labels with the scan's stem, when present.
    pub labels_path: Option<PathBuf>,
}

/// A validated session folder: everything but the scans' points.
#[derive(Debug, Clone, PartialEq)]
pub struct SessionSource {
    pub dir: PathBuf,
    pub layout: Layout,
    pub keyframes: Vec<KeyframeSource>,
    pub meta: SessionMeta,
    /// Every file whose bytes define the session, in a fixed order: pose file,
    /// calib, times, session.toml (those present), then all scans in order.
    /// Labels are not included: they are ground truth for evaluation, not input.
    pub definition_files: Vec<PathBuf>,
}

/// Detects the layout of `dir` and reads and validates its poses, calibration,
/// times and `session.toml`. Scans are listed, not read.
pub fn detect_session(dir: &Path) -> Result<SessionSource, ReadError> {
    let md = std::fs::metadata(dir).map_err(|e| ReadError::io(dir, &e))?;
    if !md.is_dir() {
        return Err(ReadError::new(ReadErrorKind::Io, dir, "not a directory")
            .hint("pass the session folder (the one holding velodyne/, Scans/ or pcd/), not a file in it"));
    }
    let mut found = None;
    for layout in Layout::ALL {
        let (sub, ext) = layout.scan_dir();
        let scans = list_files(&dir.join(sub), ext)?;
        if !scans.is_empty() {
            found = Some((layout, scans));
            break;
        }
    }
    let Some((layout, scans)) = found else { return Err(unknown_layout(dir)) };

    let toml_path = dir.join("session.toml");
    let has_toml = toml_path.is_file();
    let meta = if has_toml { read_session_meta(&toml_path)? } else { SessionMeta::default() };

    let (mut definition_files, poses) = match layout {
        Layout::Kitti | Layout::ScansPcd => file_poses(dir, layout, &scans)?,
        Layout::DynamicMapBenchmark => {
            let poses: Result<Vec<_>, _> = scans.iter().map(|p| viewpoint_pose(p)).collect();
            (Vec::new(), poses?)
        }
    };
    if has_toml {
        definition_files.push(toml_path);
    }
    let labels_dir = dir.join("labels");
    let keyframes = scans
        .iter()
        .zip(poses)
        .enumerate()
        .map(|(index, (scan_path, (t_session_sensor, stamp_s)))| {
            let labels_path = (layout == Layout::Kitti)
                .then(|| {
                    let stem = scan_path.file_stem().unwrap_or_default().to_string_lossy();
                    labels_dir.join(format!("{stem}.label"))
                })
                .filter(|p| p.is_file());
            KeyframeSource { index, scan_path: scan_path.clone(), t_session_sensor, stamp_s, labels_path }
        })
        .collect();
    definition_files.extend(scans);
    Ok(SessionSource { dir: dir.to_path_buf(), layout, keyframes, meta, definition_files })
}

/// A keyframe's odometry pose and time stamp, as read.
type Odometry = (Pose, Option<f64>);

/// Poses (and stamps) from the pose file of a Kitti or ScansPcd folder, with
/// the definition files read so far.
fn file_poses(dir: &Path, layout: Layout, scans: &[PathBuf]) -> Result<(Vec<PathBuf>, Vec<Odometry>), ReadError> {
    let candidates: &[&str] = match layout {
        Layout::Kitti => &["poses.txt", "poses_tum.txt"],
        _ => &["optimized_poses.txt", "poses.txt"],
    };
    let Some(pose_path) = candidates.iter().map(|n| dir.join(n)).find(|p| p.is_file()) else {
        let (sub, ext) = layout.scan_dir();
        return Err(ReadError::new(
            ReadErrorKind::UnknownLayout,
            dir,
            format!("{sub}/ has {} .{ext} scans but there is no {}", scans.len(), candidates.join(" or ")),
        )
        .hint(format!("add the odometry poses, one line per scan. {ACCEPTED}")));
    };
    let mut files = vec![pose_path.clone()];
    let columns = pose_file_columns(&pose_path)?;
    let is_tum = columns == 8 || (columns == 0 && pose_path.ends_with("poses_tum.txt"));
    let mut poses: Vec<Odometry> = if is_tum {
        read_tum_poses(&pose_path)?.into_iter().map(|(t, p)| (p, Some(t))).collect()
    } else {
        read_kitti_poses(&pose_path)?.into_iter().map(|p| (p, None)).collect()
    };
    let (sub, ext) = layout.scan_dir();
    check_count(&pose_path, poses.len(), "poses", sub, ext, scans.len())?;

    let calib = dir.join("calib.txt");
    if layout == Layout::Kitti && calib.is_file() {
        // KITTI poses are of the left camera; the LiDAR's are inv(Tr)·P·Tr.
        // TUM files come from LiDAR odometry and are used as they are.
        if let (Some(tr), false) = (read_calib_tr(&calib)?, is_tum) {
            let tr_inv = tr.inverse();
            poses.iter_mut().for_each(|(p, _)| *p = tr_inv * *p * tr);
        }
        files.push(calib);
    }
    let times_path = dir.join("times.txt");
    if times_path.is_file() {
        let times = read_times(&times_path)?;
        check_count(&times_path, times.len(), "time stamps", sub, ext, scans.len())?;
        poses.iter_mut().zip(times).for_each(|((_, s), t)| *s = Some(t));
        files.push(times_path);
    }
    Ok((files, poses))
}

fn check_count(path: &Path, n: usize, what: &str, sub: &str, ext: &str, scans: usize) -> Result<(), ReadError> {
    if n == scans {
        return Ok(());
    }
    let file = path.file_name().map(|f| f.to_string_lossy().into_owned()).unwrap_or_default();
    Err(ReadError::new(
        ReadErrorKind::CountMismatch,
        path,
        format!("{file} has {n} {what} but {sub}/ has {scans} .{ext} scans"),
    )
    .hint(format!(
        "{file} needs exactly one line per scan in {sub}/, in file-name order; remove the extra scans or lines"
    )))
}

fn viewpoint_pose(path: &Path) -> Result<Odometry, ReadError> {
    match read_viewpoint(path)? {
        Some(p) => Ok((p, None)),
        None => Err(ReadError::new(ReadErrorKind::BadHeader, path, "PCD header has no VIEWPOINT line")
            .hint("dynamic-map-benchmark scans carry the sensor pose in VIEWPOINT tx ty tz qw qx qy qz")),
    }
}

/// Regular, non-hidden files in `dir` with extension `ext` (any case), in
/// scan order; empty when `dir` does not exist.
fn list_files(dir: &Path, ext: &str) -> Result<Vec<PathBuf>, ReadError> {
    if !dir.is_dir() {
        return Ok(Vec::new());
    }
    let entries = std::fs::read_dir(dir).map_err(|e| ReadError::io(dir, &e))?;
    let mut files = Vec::new();
    for entry in entries {
        let path = entry.map_err(|e| ReadError::io(dir, &e))?.path();
        let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        let ext_ok = path.extension().is_some_and(|e| e.eq_ignore_ascii_case(ext));
        if ext_ok && !name.starts_with('.') && path.is_file() {
            files.push(path);
        }
    }
    let stem = |p: &PathBuf| p.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    let numeric = files.iter().all(|p| {
        let s = stem(p);
        !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit())
    });
    if numeric {
        // Digit strings compare as numbers by (length without leading zeros, text).
        files.sort_by_cached_key(|p| {
            let s = stem(p);
            let t = s.trim_start_matches('0').to_string();
            (t.len(), t, s)
        });
    } else {
        files.sort_by_cached_key(|p| p.file_name().map(|n| n.to_os_string()));
    }
    Ok(files)
}

fn unknown_layout(dir: &Path) -> ReadError {
    let mut found: Vec<String> = std::fs::read_dir(dir)
        .map(|rd| {
            rd.filter_map(Result::ok)
                .map(|e| {
                    let name = e.file_name().to_string_lossy().into_owned();
                    if e.path().is_dir() { format!("{name}/") } else { name }
                })
                .collect()
        })
        .unwrap_or_default();
    found.sort();
    let listing = match found.len() {
        0 => "an empty folder".to_string(),
        n if n > 12 => format!("{}, … ({n} entries)", found.iter().take(12).cloned().collect::<Vec<_>>().join(", ")),
        _ => found.join(", "),
    };
    ReadError::new(ReadErrorKind::UnknownLayout, dir, format!("not a session folder seam recognises; found: {listing}"))
        .hint(ACCEPTED)
}

/// Scan `i` of a session in the sensor frame, validated (non-empty, finite).
///
/// Dynamic-map-benchmark scans are stored in the world frame; their points are
/// moved by the inverse of the `VIEWPOINT` pose. The other layouts store
/// sensor-frame points and are returned as read.
pub fn read_session_scan(src: &SessionSource, i: usize) -> Result<Scan, ReadError> {
    let Some(kf) = src.keyframes.get(i) else {
        return Err(ReadError::new(
            ReadErrorKind::CountMismatch,
            &src.dir,
            format!("scan index {i} out of range: the session has {} keyframes", src.keyframes.len()),
        )
        .hint("scan indices are 0-based and below the keyframe count"));
    };
    let mut scan = read_scan(&kf.scan_path)?;
    validate_scan(&kf.scan_path, &scan)?;
    if src.layout == Layout::DynamicMapBenchmark {
        let t_sensor_world = kf.t_session_sensor.inverse();
        for p in &mut scan.points {
            let q = t_sensor_world * nalgebra::Point3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]));
            *p = [q.x as f32, q.y as f32, q.z as f32];
        }
    }
    Ok(scan)
}

#[cfg(test)]
#[path = "layout_tests.rs"]
mod tests;
