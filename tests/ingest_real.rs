//! Ingest of the real SemanticKITTI sequences in ../shared/data: keyframe
//! counts, LiDAR poses `inv(Tr)·P·Tr` and point counts, checked against the
//! raw files independently of seam's readers.

mod common;
use common::*;
use nalgebra::Matrix4;
use std::path::Path;

fn parse_3x4(line: &str) -> Matrix4<f64> {
    let v: Vec<f64> = line.split_whitespace().map(|t| t.parse().unwrap()).collect();
    assert_eq!(v.len(), 12, "{line}");
    let mut m = Matrix4::identity();
    for r in 0..3 {
        for c in 0..4 {
            m[(r, c)] = v[r * 4 + c];
        }
    }
    m
}

fn check_sequence(store: &Path, seq_dir: &Path, session: i64) {
    let tr_line = std::fs::read_to_string(seq_dir.join("calib.txt"))
        .unwrap()
        .lines()
        .find_map(|l| l.strip_prefix("Tr:").map(String::from))
        .expect("calib.txt has Tr:");
    let tr = parse_3x4(&tr_line);
    let tr_inv = tr.try_inverse().unwrap();
    let poses: Vec<Matrix4<f64>> =
        std::fs::read_to_string(seq_dir.join("poses.txt")).unwrap().lines().map(parse_3x4).collect();

    let s = seam::store::Store::open_read_only(store).unwrap();
    let kfs = seam::store::keyframes(s.conn(), seam::store::SessionId(session)).unwrap();
    assert_eq!(kfs.len(), 10, "keyframes of {}", seq_dir.display());
    let files = s.conn();
    for (i, k) in kfs.iter().enumerate() {
        assert_eq!(k.keyframe_index, i as i64);
        let want = tr_inv * poses[i] * tr;
        let got = k.t_session_keyframe.to_homogeneous();
        let err = (want - got).abs().max();
        assert!(err < 1e-6, "keyframe {i} pose differs from inv(Tr)·P·Tr by {err}");
        let bin = seq_dir.join(format!("velodyne/{i:06}.bin"));
        let bytes = std::fs::read(&bin).unwrap();
        assert_eq!(k.point_count as usize, bytes.len() / 16, "{}", bin.display());
        // The stored scan is the file's points, bit for bit.
        let rel: String =
            files.query_row("SELECT rel_path FROM files WHERE file_id = ?1", [k.scan_file_id], |r| r.get(0)).unwrap();
        let scan = seam::store::read_scan_row_group(&store.join(rel), k.scan_row_group as usize).unwrap();
        assert_eq!(scan.points.len(), bytes.len() / 16);
        for j in [0, scan.points.len() / 2, scan.points.len() - 1] {
            let f = |o: usize| f32::from_le_bytes(bytes[j * 16 + o..j * 16 + o + 4].try_into().unwrap());
            assert_eq!(scan.points[j], [f(0), f(4), f(8)]);
            assert_eq!(scan.intensity[j], f(12));
        }
    }
}

#[test]
fn semantickitti_04_and_08() {
    let Some(data) = shared_data() else { return };
    let tmp = tempfile::tempdir().unwrap();
    let store = tmp.path().join("kitti.seam");
    init_store(&store);
    for seq in ["04", "08"] {
        let dir = data.join("semantickitti").join(seq);
        let o = run(&["ingest", store.to_str().unwrap(), dir.to_str().unwrap(), "--format", "json"]);
        assert!(o.status.success(), "{}", stderr(&o));
        let v: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
        assert_eq!(v["keyframes"], 10);
        assert_eq!(v["layout"], "kitti");
        eprintln!(
            "ingest {seq}: {} points in {:.3} s = {:.0} points/s, {:.1} scans/s",
            v["points"],
            v["wall_s"].as_f64().unwrap(),
            v["points_per_s"].as_f64().unwrap(),
            v["scans_per_s"].as_f64().unwrap()
        );
    }
    check_sequence(&store, &data.join("semantickitti/04"), 1);
    check_sequence(&store, &data.join("semantickitti/08"), 2);
    let o = run(&["check", store.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stdout(&o));
}
