//! The readers on real sensor data in `../shared/data` (see its README.md).
//!
//! Every expected number here was computed independently of seam, from file
//! sizes and raw header bytes, and is asserted as a literal. The tests skip
//! (with a notice) when the data folder is absent.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use nalgebra::Matrix4;
use seam::io::{
    Layout, MOVING_CLASSES, detect_session, pcd_viewpoint, read_labels, read_las_points_f64, read_scan,
    read_session_scan, read_times,
};

fn data_dir() -> Option<PathBuf> {
    let d = Path::new("../shared/data");
    if d.is_dir() {
        Some(d.to_path_buf())
    } else {
        eprintln!("notice: ../shared/data not found, skipping");
        None
    }
}

/// The 12 numbers of a text line as a 4×4 matrix, exactly as printed.
fn matrix_from_text(line: &str) -> Matrix4<f64> {
    let v: Vec<f64> = line.split_whitespace().map(|t| t.parse().unwrap()).collect();
    assert_eq!(v.len(), 12, "{line}");
    Matrix4::new(v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7], v[8], v[9], v[10], v[11], 0.0, 0.0, 0.0, 1.0)
}

/// Checks one SemanticKITTI sequence; returns (moving points, moving (class, instance) pairs).
fn check_sequence(seq: &Path) -> (usize, usize) {
    let src = detect_session(seq).unwrap();
    assert_eq!(src.layout, Layout::Kitti);
    assert_eq!(src.keyframes.len(), 10);
    // poses.txt, calib.txt, times.txt, then the 10 scans.
    assert_eq!(src.definition_files.len(), 13);

    // Every keyframe's pose, computed here from the raw text: inv(Tr)·P·Tr.
    // Keyframe 0 to 1e-9. The later rows are printed with 6 significant
    // digits, so their rotations are off by ~1e-6 and seam re-orthonormalises
    // them (geometry::pose_from_kitti_row): those agree to 1e-5. P0 is nearly
    // the identity, so keyframe 0 alone would not notice a missing Tr; the
    // later poses differ from P by decimetres to metres.
    let calib = std::fs::read_to_string(seq.join("calib.txt")).unwrap();
    let tr = matrix_from_text(calib.lines().find_map(|l| l.strip_prefix("Tr:")).unwrap());
    let poses = std::fs::read_to_string(seq.join("poses.txt")).unwrap();
    for (kf, line) in src.keyframes.iter().zip(poses.lines()) {
        let p = matrix_from_text(line);
        let want = tr.try_inverse().unwrap() * p * tr;
        let got = kf.t_session_sensor.to_homogeneous();
        let err = (got - want).abs().max();
        let tol = if kf.index == 0 { 1e-9 } else { 1e-5 };
        assert!(err < tol, "keyframe {}: {got} vs {want}", kf.index);
    }
    let p9 = matrix_from_text(poses.lines().nth(9).unwrap());
    assert!((src.keyframes[9].t_session_sensor.to_homogeneous() - p9).abs().max() > 0.1, "Tr was not applied");

    let times = read_times(&seq.join("times.txt")).unwrap();
    let mut moving = 0;
    let mut instances = BTreeSet::new();
    for (i, kf) in src.keyframes.iter().enumerate() {
        assert_eq!(kf.index, i);
        assert_eq!(kf.scan_path, seq.join(format!("velodyne/{i:06}.bin")));
        assert_eq!(kf.stamp_s, Some(times[i]));
        let n = std::fs::metadata(&kf.scan_path).unwrap().len() as usize / 16;
        let scan = read_session_scan(&src, i).unwrap();
        assert_eq!(scan.len(), n, "{}", kf.scan_path.display());
        assert_eq!(scan.intensity.len(), n);
        let labels_path = kf.labels_path.clone().expect("labels/ is present");
        assert_eq!(std::fs::metadata(&labels_path).unwrap().len() as usize, 4 * n);
        let labels = read_labels(&labels_path, n).unwrap();
        assert_eq!(labels.len(), n);
        for l in labels.into_iter().filter(|l| MOVING_CLASSES.contains(&((l & 0xffff) as u16))) {
            moving += 1;
            instances.insert(l);
        }
        // A label file for another scan is a count mismatch.
        assert!(read_labels(&labels_path, n + 1).is_err());
    }
    (moving, instances.len())
}

#[test]
fn semantickitti_sequences() {
    let Some(data) = data_dir() else { return };
    // Moving points and (class, instance) pairs as the data README states.
    assert_eq!(check_sequence(&data.join("semantickitti/04")), (17_431, 8));
    assert_eq!(check_sequence(&data.join("semantickitti/08")), (14_927, 9));
}

#[test]
fn semantickitti_scan_sizes() {
    let Some(data) = data_dir() else { return };
    // Point counts of the first and last scans, from file_size / 16.
    for (rel, n) in [
        ("semantickitti/04/velodyne/000000.bin", 124_231),
        ("semantickitti/04/velodyne/000009.bin", 122_909),
        ("semantickitti/08/velodyne/000000.bin", 123_389),
        ("semantickitti/08/velodyne/000009.bin", 123_445),
    ] {
        assert_eq!(read_scan(&data.join(rel)).unwrap().len(), n, "{rel}");
    }
}

#[test]
fn registration_pcd_and_ply_are_the_same_scans() {
    let Some(data) = data_dir() else { return };
    let reg = data.join("registration");
    // (PCD, PLY, POINTS in both headers): the data sections are byte-identical.
    for (pcd, ply, n) in [("251370668.pcd", "target.ply", 69_088), ("251371071.pcd", "source.ply", 69_792)] {
        let a = read_scan(&reg.join(pcd)).unwrap();
        let b = read_scan(&reg.join(ply)).unwrap();
        assert_eq!(a.len(), n, "{pcd}");
        assert_eq!(b.len(), n, "{ply}");
        assert_eq!(a.intensity.len(), n, "{pcd}");
        assert_eq!(b.intensity.len(), n, "{ply} (scalar_intensity)");
        assert_eq!(a, b, "{pcd} and {ply} hold the same points and intensities");
        assert!(a.points.iter().flatten().all(|c| c.is_finite()));
        assert_eq!(pcd_viewpoint(&reg.join(pcd)).unwrap(), seam::geometry::Pose::identity());
    }
}

/// Bounds from a LAS public header, read from raw bytes: (min, max) per axis.
fn las_header_bounds(path: &Path) -> [(f64, f64); 3] {
    let b = std::fs::read(path).unwrap();
    let f = |at: usize| f64::from_le_bytes(b[at..at + 8].try_into().unwrap());
    // max_x, min_x, max_y, min_y, max_z, min_z from byte 179.
    [(f(187), f(179)), (f(203), f(195)), (f(219), f(211))]
}

#[test]
fn every_las_file_reads_its_header_point_count() {
    let Some(data) = data_dir() else { return };
    // Point counts from each file's public header (legacy count at byte 107,
    // LAS 1.4's 64-bit count at byte 247 where present).
    let expected = [
        ("autzen_trim.laz", 110_000),
        ("extrabytes.las", 1_065),
        ("simple.copc.laz", 1_065),
        ("simple.las", 1_065),
        ("simple.laz", 1_065),
        ("simple1_4.las", 22_600),
        ("test1_4.las", 1_000),
    ];
    let mut names: Vec<String> = std::fs::read_dir(data.join("las"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(names, expected.map(|(n, _)| n.to_string()), "a new file in las/ needs its count here");
    for (name, n) in expected {
        let path = data.join("las").join(name);
        let scan = read_scan(&path).unwrap();
        assert_eq!(scan.len(), n, "{name}");
        assert_eq!(scan.intensity.len(), n, "{name}");
        let xyz = read_las_points_f64(&path).unwrap();
        assert_eq!(xyz.len(), n, "{name}");
        // Scale and offset applied: every point within the header's bounds.
        let bounds = las_header_bounds(&path);
        for (axis, (lo, hi)) in bounds.iter().enumerate() {
            let tol = 1e-6 * hi.abs().max(lo.abs()).max(1.0);
            assert!(xyz.iter().all(|p| p[axis] >= lo - tol && p[axis] <= hi + tol), "{name} axis {axis}");
        }
    }
}
