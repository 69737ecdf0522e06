//! Readers for the session layouts and file formats people already have.
//!
//! This module owns turning a folder on disk into a validated
//! [`SessionSource`] (which files, which poses, in which frame) and reading one
//! scan at a time as a [`Scan`] in the sensor frame. It never writes anything
//! and never touches the store. Every error is a [`ReadError`] that names the
//! file, the line or byte, what was expected, and what to do.
//!
//! Two steps, so that a bad folder fails before the pipeline writes anything:
//!
//! 1. [`detect_session`] recognises the layout, lists the scans, reads and
//!    validates every pose, the calibration, the time stamps and
//!    `session.toml`, and checks that the counts agree. It does not read scans.
//! 2. [`read_session_scan`] reads scan `i` in the sensor frame and checks it is
//!    non-empty with finite coordinates.
//!
//! Frames: a keyframe's `t_session_sensor` is the LiDAR's odometry pose. For
//! KITTI with a `calib.txt` `Tr:` line, `poses.txt` holds camera poses `P` and
//! the LiDAR pose is `inv(Tr)·P·Tr`.
//!
//! # Layout
//! - `error.rs`: [`ReadError`], [`ReadErrorKind`], [`Location`]
//! - `layout.rs`: layout detection, [`SessionSource`], [`read_session_scan`]
//! - `meta.rs`: `session.toml` → [`SessionMeta`]
//! - `poses.rs`: KITTI 3×4 and TUM pose files
//! - `kitti.rs`: KITTI `.bin` scans, SemanticKITTI `.label`, `calib.txt`, `times.txt`
//! - `pcd.rs` (+ `pcd_header.rs`): PCD v0.7 ascii / binary / binary_compressed
//!   (hand-written; why in its doc)
//! - `ply.rs`: PLY ascii and binary
//! - `las.rs`: LAS / LAZ / COPC (and the `f64` precision note)

mod error;
mod kitti;
mod las;
mod layout;
mod meta;
mod pcd;
mod ply;
mod poses;

use std::path::Path;

use crate::geometry::Scan;

pub use error::{Location, ReadError, ReadErrorKind};
pub use kitti::{read_calib_tr, read_labels, read_times};
pub use las::read_las_points_f64;
pub use layout::{KeyframeSource, Layout, SessionSource, detect_session, read_session_scan};
pub use meta::SessionMeta;
pub use pcd::pcd_viewpoint;
pub use poses::{read_kitti_poses, read_tum_poses};

/// SemanticKITTI classes of moving objects (moving car, person, cyclist, ...).
pub const MOVING_CLASSES: std::ops::RangeInclusive<u16> = 252..=259;

/// The SemanticKITTI class of a label (its low 16 bits).
pub fn label_class(label: u32) -> u16 {
    (label & 0xffff) as u16
}

/// The instance id of a label (its high 16 bits; 0 where none).
pub fn label_instance(label: u32) -> u16 {
    (label >> 16) as u16
}

/// True when a SemanticKITTI label is one of the [`MOVING_CLASSES`].
pub fn is_moving_label(label: u32) -> bool {
    MOVING_CLASSES.contains(&label_class(label))
}

/// The scan extensions [`read_scan`] accepts.
pub const SCAN_EXTENSIONS: [&str; 5] = ["bin", "pcd", "ply", "las", "laz"];

/// Reads a scan by extension (`.bin .pcd .ply .las .laz`, any case), points
/// as stored in the file: not validated, not moved to another frame.
pub fn read_scan(path: &Path) -> Result<Scan, ReadError> {
    let ext = path.extension().map(|e| e.to_string_lossy().to_ascii_lowercase()).unwrap_or_default();
    match ext.as_str() {
        "bin" => kitti::read_bin(path),
        "pcd" => pcd::read_pcd(path),
        "ply" => ply::read_ply(path),
        "las" | "laz" => las::read_las(path),
        _ => Err(ReadError::new(ReadErrorKind::Unsupported, path, format!("cannot read `.{ext}` scans"))
            .hint(format!("seam reads scans with extensions .{}", SCAN_EXTENSIONS.join(" .")))),
    }
}

/// Checks a scan the pipeline will use: at least one point, every coordinate
/// finite (intensities are not checked). `path` names the file in errors.
pub fn validate_scan(path: &Path, scan: &Scan) -> Result<(), ReadError> {
    if scan.is_empty() {
        return Err(ReadError::new(ReadErrorKind::EmptyScan, path, "scan has no points")
            .hint("remove the scan and its pose line, or re-export it"));
    }
    if let Some(k) = scan.points.iter().position(|p| p.iter().any(|c| !c.is_finite())) {
        let p = scan.points.get(k).copied().unwrap_or_default();
        return Err(ReadError::new(
            ReadErrorKind::NonFinite,
            path,
            format!("point {k} has a non-finite coordinate ({}, {}, {})", p[0], p[1], p[2]),
        )
        .at(Location::Point(k))
        .hint("drop invalid returns before saving (e.g. pcl::removeNaNFromPointCloud), or remove the scan"));
    }
    if !scan.intensity.is_empty() && scan.intensity.len() != scan.len() {
        return Err(ReadError::new(
            ReadErrorKind::CountMismatch,
            path,
            format!("{} intensities for {} points", scan.intensity.len(), scan.len()),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn moving_labels() {
        assert!(is_moving_label(252 | (3 << 16)));
        assert!(is_moving_label(259));
        assert!(!is_moving_label(251 | (252 << 16)), "the instance id is not the class");
        assert!(!is_moving_label(10));
    }

    #[test]
    fn unknown_extension_is_unsupported() {
        let e = read_scan(Path::new("scan.e57")).unwrap_err();
        assert_eq!(e.kind(), ReadErrorKind::Unsupported);
        assert!(e.to_string().starts_with("scan.e57: cannot read `.e57` scans"), "{e}");
    }

    #[test]
    fn validate_names_the_point() {
        let p = Path::new("s.pcd");
        assert_eq!(validate_scan(p, &Scan::default()).unwrap_err().kind(), ReadErrorKind::EmptyScan);
        let scan = Scan { points: vec![[0.0; 3], [1.0, f32::INFINITY, 0.0]], intensity: vec![] };
        let e = validate_scan(p, &scan).unwrap_err();
        assert_eq!((e.kind(), e.location), (ReadErrorKind::NonFinite, Some(Location::Point(1))));
        assert!(e.to_string().starts_with("s.pcd:point 1: point 1 has a non-finite coordinate (1, inf, 0)"), "{e}");
    }
}
