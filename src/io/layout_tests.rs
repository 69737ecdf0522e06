//! Tests of layout detection and session reading on synthetic folders.

use super::*;
use crate::io::{Location, ReadErrorKind};
use nalgebra::{Point3, Vector3};
use std::fs;

const IDENTITY: &str = "1 0 0 0 0 1 0 0 0 0 1 0";
/// The KITTI velodyne → camera extrinsic (sequences 04-10), as in calib.txt.
const TR: &str = "-1.857739385241e-03 -9.999659513510e-01 -8.039975204516e-03 -4.784029760483e-03 \
                  -6.481465826011e-03 8.051860151134e-03 -9.999466081774e-01 -7.337429464231e-02 \
                  9.999773098287e-01 -1.805528627661e-03 -6.496203536139e-03 -3.339968064433e-01";

fn put(root: &Path, rel: &str, bytes: impl AsRef<[u8]>) {
    let p = root.join(rel);
    fs::create_dir_all(p.parent().unwrap()).unwrap();
    fs::write(p, bytes).unwrap();
}

fn bin(points: &[[f32; 4]]) -> Vec<u8> {
    points.iter().flatten().flat_map(|v| v.to_le_bytes()).collect()
}

fn pose_line(p: &Pose) -> String {
    crate::geometry::pose_to_kitti_row(p).map(|v| format!("{v:.17e}")).join(" ")
}

/// A KITTI folder with `n` scans of 2 points, poses moving 1 m along z.
fn kitti_dir(n: usize) -> (tempfile::TempDir, Vec<Pose>) {
    let dir = tempfile::tempdir().unwrap();
    let poses: Vec<Pose> =
        (0..n).map(|i| Pose::new(Vector3::new(0.1, 0.0, i as f64), Vector3::new(0.0, 0.02 * i as f64, 0.0))).collect();
    for i in 0..n {
        put(dir.path(), &format!("velodyne/{i:06}.bin"), bin(&[[1.0, 2.0, 3.0, 0.5], [4.0, 5.0, 6.0, 0.25]]));
    }
    let text: Vec<String> = poses.iter().map(pose_line).collect();
    put(dir.path(), "poses.txt", text.join("\n") + "\n");
    (dir, poses)
}

#[test]
fn kitti_with_calib_times_labels_and_toml() {
    let (dir, cam_poses) = kitti_dir(3);
    let d = dir.path();
    put(d, "calib.txt", format!("P0: {IDENTITY}\nTr: {TR}\n"));
    put(d, "times.txt", "0.0\n0.1\n0.2\n");
    put(d, "labels/000001.label", [0u8; 8]);
    put(d, "session.toml", "name = \"s1\"\n");
    put(d, "velodyne/.000000.bin", [1u8; 3]); // a macOS resource fork: ignored

    let src = detect_session(d).unwrap();
    assert_eq!(src.layout, Layout::Kitti);
    assert_eq!(src.layout.name(), "kitti");
    assert_eq!(src.meta.name.as_deref(), Some("s1"));
    assert_eq!(src.keyframes.len(), 3);
    let tr = crate::io::read_calib_tr(&d.join("calib.txt")).unwrap().unwrap();
    for (kf, p) in src.keyframes.iter().zip(&cam_poses) {
        let want = tr.inverse() * p * tr;
        assert!((kf.t_session_sensor.to_homogeneous() - want.to_homogeneous()).norm() < 1e-12, "{}", kf.index);
    }
    assert_eq!(src.keyframes.iter().map(|k| k.stamp_s).collect::<Vec<_>>(), vec![Some(0.0), Some(0.1), Some(0.2)]);
    assert_eq!(src.keyframes[1].labels_path, Some(d.join("labels/000001.label")));
    assert_eq!(src.keyframes[0].labels_path, None);
    let names: Vec<String> =
        src.definition_files.iter().map(|p| p.strip_prefix(d).unwrap().display().to_string()).collect();
    assert_eq!(
        names,
        [
            "poses.txt",
            "calib.txt",
            "times.txt",
            "session.toml",
            "velodyne/000000.bin",
            "velodyne/000001.bin",
            "velodyne/000002.bin"
        ]
    );
    let scan = read_session_scan(&src, 2).unwrap();
    assert_eq!(scan.points, vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]);
    assert_eq!(read_session_scan(&src, 3).unwrap_err().kind(), ReadErrorKind::CountMismatch);
}

#[test]
fn scan_and_pose_count_mismatch_names_both() {
    let (dir, _) = kitti_dir(3);
    put(dir.path(), "velodyne/000003.bin", bin(&[[1.0; 4]]));
    let e = detect_session(dir.path()).unwrap_err();
    assert_eq!(e.kind(), ReadErrorKind::CountMismatch);
    let s = e.to_string();
    assert!(s.contains("poses.txt: poses.txt has 3 poses but velodyne/ has 4 .bin scans"), "{s}");

    fs::remove_file(dir.path().join("velodyne/000003.bin")).unwrap();
    put(dir.path(), "times.txt", "0.0\n0.1\n");
    let e = detect_session(dir.path()).unwrap_err();
    assert_eq!(e.kind(), ReadErrorKind::CountMismatch);
    assert!(e.to_string().contains("times.txt: times.txt has 2 time stamps but velodyne/ has 3 .bin scans"), "{e}");
}

#[test]
fn bad_pose_fails_detection_with_line() {
    let (dir, _) = kitti_dir(2);
    put(dir.path(), "poses.txt", format!("{IDENTITY}\n1 0 0 0 0 1 0 0 0 0 -1 0\n"));
    let e = detect_session(dir.path()).unwrap_err();
    assert_eq!((e.kind(), e.location), (ReadErrorKind::NotRotation, Some(Location::Line(2))), "{e}");
    put(dir.path(), "poses.txt", format!("{IDENTITY}\n1 0 0 0 0 1 0 inf 0 0 1 0\n"));
    let e = detect_session(dir.path()).unwrap_err();
    assert_eq!((e.kind(), e.location), (ReadErrorKind::NonFinite, Some(Location::Line(2))), "{e}");
    assert!(e.to_string().contains("poses.txt:line 2:"), "{e}");
}

#[test]
fn tum_poses_by_column_count_or_name_skip_tr() {
    let (dir, _) = kitti_dir(2);
    let d = dir.path();
    put(d, "calib.txt", format!("Tr: {TR}\n"));
    put(d, "poses.txt", "5.0 1 2 3 0 0 0 1\n5.1 1 2 4 0 0 0 1\n");
    let src = detect_session(d).unwrap();
    assert_eq!(src.keyframes[1].stamp_s, Some(5.1));
    assert_eq!(src.keyframes[1].t_session_sensor.translation.vector, Vector3::new(1.0, 2.0, 4.0));
    fs::remove_file(d.join("poses.txt")).unwrap();
    put(d, "poses_tum.txt", "5.0 1 2 3 0 0 0 1\n5.1 1 2 4 0 0 0 1\n");
    let src = detect_session(d).unwrap();
    assert_eq!(src.definition_files[0], d.join("poses_tum.txt"));
    assert_eq!(src.keyframes[0].stamp_s, Some(5.0));
}

#[test]
fn scans_pcd_prefers_optimized_poses_and_orders_numerically() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let pcd = |x: f32| format!("FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 1\nDATA ascii\n{x} 0 0\n");
    for i in [1, 2, 10] {
        put(d, &format!("Scans/{i}.pcd"), pcd(i as f32));
    }
    put(d, "poses.txt", format!("{IDENTITY}\n"));
    put(d, "optimized_poses.txt", format!("{IDENTITY}\n{IDENTITY}\n1 0 0 7 0 1 0 0 0 0 1 0\n"));
    let src = detect_session(d).unwrap();
    assert_eq!(src.layout, Layout::ScansPcd);
    assert_eq!(src.definition_files[0], d.join("optimized_poses.txt"));
    let order: Vec<f32> = (0..3).map(|i| read_session_scan(&src, i).unwrap().points[0][0]).collect();
    assert_eq!(order, vec![1.0, 2.0, 10.0]);
    assert_eq!(src.keyframes[2].t_session_sensor.translation.x, 7.0);
}

#[test]
fn dynamic_map_benchmark_moves_world_points_to_the_sensor_frame() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let t_world_sensor = Pose::new(Vector3::new(10.0, -5.0, 2.0), Vector3::new(0.1, -0.2, 1.3));
    let p_sensor = Point3::new(3.0, 1.0, -0.5);
    let p_world = t_world_sensor * p_sensor;
    let q = t_world_sensor.rotation.quaternion();
    let t = t_world_sensor.translation.vector;
    put(
        d,
        "pcd/000000.pcd",
        format!(
            "FIELDS x y z\nSIZE 8 8 8\nTYPE F F F\nWIDTH 1\nVIEWPOINT {} {} {} {} {} {} {}\nDATA ascii\n{} {} {}\n",
            t.x, t.y, t.z, q.w, q.i, q.j, q.k, p_world.x, p_world.y, p_world.z
        ),
    );
    let src = detect_session(d).unwrap();
    assert_eq!(src.layout.name(), "dynamic-map-benchmark");
    let got = src.keyframes[0].t_session_sensor;
    assert!((got.to_homogeneous() - t_world_sensor.to_homogeneous()).norm() < 1e-12);
    let scan = read_session_scan(&src, 0).unwrap();
    let back = Vector3::new(scan.points[0][0], scan.points[0][1], scan.points[0][2]).cast::<f64>();
    assert!((back - p_sensor.coords).norm() < 1e-5, "{back:?}");

    put(d, "pcd/000001.pcd", "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 1\nDATA ascii\n0 0 0\n");
    let e = detect_session(d).unwrap_err();
    assert_eq!(e.kind(), ReadErrorKind::BadHeader);
    assert!(e.to_string().contains("000001.pcd: PCD header has no VIEWPOINT line"), "{e}");
}

#[test]
fn unknown_layout_lists_what_was_found_and_what_is_accepted() {
    let dir = tempfile::tempdir().unwrap();
    put(dir.path(), "notes.txt", "hi");
    put(dir.path(), "lidar/0.bin", [0u8; 16]);
    fs::create_dir(dir.path().join("velodyne")).unwrap();
    let e = detect_session(dir.path()).unwrap_err();
    assert_eq!(e.kind(), ReadErrorKind::UnknownLayout);
    let s = e.to_string();
    assert!(s.contains("found: lidar/, notes.txt, velodyne/"), "{s}");
    for name in ["kitti (", "scans-pcd (", "dynamic-map-benchmark ("] {
        assert!(e.hint.contains(name), "{s}");
    }

    let e = detect_session(&dir.path().join("notes.txt")).unwrap_err();
    assert_eq!(e.kind(), ReadErrorKind::Io);
    let e = detect_session(&dir.path().join("missing")).unwrap_err();
    assert_eq!(e.kind(), ReadErrorKind::Io);

    put(dir.path(), "velodyne/000000.bin", [0u8; 16]);
    let e = detect_session(dir.path()).unwrap_err();
    assert_eq!(e.kind(), ReadErrorKind::UnknownLayout);
    assert!(e.message.contains("velodyne/ has 1 .bin scans but there is no poses.txt or poses_tum.txt"), "{e}");
}

#[test]
fn session_scans_are_validated() {
    let (dir, _) = kitti_dir(3);
    let d = dir.path();
    put(d, "velodyne/000000.bin", bin(&[]));
    put(d, "velodyne/000001.bin", bin(&[[1.0, 2.0, 3.0, 0.0], [f32::NAN, 0.0, 0.0, 0.0]]));
    put(d, "velodyne/000002.bin", [0u8; 20]);
    let src = detect_session(d).unwrap();
    let e = read_session_scan(&src, 0).unwrap_err();
    assert_eq!(e.kind(), ReadErrorKind::EmptyScan);
    assert!(e.to_string().contains("000000.bin: scan has no points"), "{e}");
    let e = read_session_scan(&src, 1).unwrap_err();
    assert_eq!((e.kind(), e.location), (ReadErrorKind::NonFinite, Some(Location::Point(1))), "{e}");
    assert!(e.to_string().contains("000001.bin:point 1: "), "{e}");
    let e = read_session_scan(&src, 2).unwrap_err();
    assert_eq!(e.kind(), ReadErrorKind::NotMultipleOf16);
    assert!(e.to_string().contains("000002.bin: file has 20 bytes"), "{e}");
}

#[test]
fn session_toml_errors_surface_from_detection() {
    let (dir, _) = kitti_dir(1);
    put(dir.path(), "session.toml", "name = \"s1\"\nsensr = 1\n");
    let e = detect_session(dir.path()).unwrap_err();
    assert_eq!((e.kind(), e.location), (ReadErrorKind::Parse, Some(Location::Line(2))), "{e}");
    assert!(e.to_string().contains("session.toml:line 2:") && e.message.contains("sensr"), "{e}");
}
