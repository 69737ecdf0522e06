//! Every bad input (issue 2 point 4, and issue 3's options): a clear error naming the file and
//! the place, the documented exit code, and a store left exactly as it was.

mod common;
use common::*;
use std::path::Path;

/// A store holding one good session, and a second good session to corrupt.
fn setup() -> (tempfile::TempDir, std::path::PathBuf, std::path::PathBuf) {
    let tmp = tempfile::tempdir().unwrap();
    let store = tmp.path().join("site.seam");
    init_store(&store);
    let good = tmp.path().join("good");
    write_kitti_session(&good, 4, 500, 1);
    let o = run(&["ingest", store.to_str().unwrap(), good.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let bad = tmp.path().join("bad");
    write_kitti_session(&bad, 5, 400, 2);
    (tmp, store, bad)
}

/// Runs ingest of `bad` and asserts exit code 4, every fragment in the
/// message, and an unchanged store.
fn assert_rejected(store: &Path, bad: &Path, fragments: &[&str]) {
    let before = store_state(store);
    let o = run(&["ingest", store.to_str().unwrap(), bad.to_str().unwrap()]);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(4), "expected exit 4 (data error), got {:?}: {err}", o.status.code());
    for f in fragments {
        assert!(err.to_lowercase().contains(&f.to_lowercase()), "message lacks {f:?}:\n{err}");
    }
    assert!(err.contains("hint:"), "message gives no hint on what to do:\n{err}");
    assert_same_state(&before, &store_state(store), "after a rejected ingest");
}

#[test]
fn bin_size_not_multiple_of_16() {
    let (_t, store, bad) = setup();
    let p = bad.join("velodyne/000002.bin");
    let mut b = std::fs::read(&p).unwrap();
    b.extend_from_slice(&[1, 2, 3]);
    std::fs::write(&p, b).unwrap();
    assert_rejected(&store, &bad, &["000002.bin", "6403 bytes", "multiple of 16"]);
}

#[test]
fn nan_coordinate() {
    let (_t, store, bad) = setup();
    let p = bad.join("velodyne/000001.bin");
    let mut b = std::fs::read(&p).unwrap();
    // point 7, y coordinate
    b[7 * 16 + 4..7 * 16 + 8].copy_from_slice(&f32::NAN.to_le_bytes());
    std::fs::write(&p, b).unwrap();
    assert_rejected(&store, &bad, &["000001.bin", "point 7"]);
}

#[test]
fn infinite_pose() {
    let (_t, store, bad) = setup();
    let p = bad.join("poses.txt");
    let text = std::fs::read_to_string(&p).unwrap().replacen("1 0 0 3 ", "1 0 0 inf ", 1);
    std::fs::write(&p, text).unwrap();
    assert_rejected(&store, &bad, &["poses.txt", "line 3"]);
}

#[test]
fn scan_count_differs_from_pose_count() {
    let (_t, store, bad) = setup();
    let p = bad.join("poses.txt");
    let text: Vec<&str> = std::fs::read_to_string(&p).map(|s| s.leak() as &str).unwrap().lines().collect();
    std::fs::write(&p, text[..4].join("\n") + "\n").unwrap();
    assert_rejected(&store, &bad, &["poses.txt", "5", "4"]);
}

#[test]
fn non_orthonormal_rotation() {
    let (_t, store, bad) = setup();
    let p = bad.join("poses.txt");
    let text = std::fs::read_to_string(&p).unwrap();
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    lines[1] = "1.2 0 0 1.5 0 1 0 0 0 0 1 0".into();
    std::fs::write(&p, lines.join("\n") + "\n").unwrap();
    assert_rejected(&store, &bad, &["poses.txt", "line 2", "rotation"]);
}

#[test]
fn empty_scan() {
    let (_t, store, bad) = setup();
    std::fs::write(bad.join("velodyne/000003.bin"), b"").unwrap();
    assert_rejected(&store, &bad, &["000003.bin", "no points"]);
}

#[test]
fn unknown_layout() {
    let (_t, store, _bad) = setup();
    let odd = store.parent().unwrap().join("odd");
    std::fs::create_dir_all(odd.join("clouds")).unwrap();
    std::fs::write(odd.join("clouds/a.xyz"), b"1 2 3\n").unwrap();
    assert_rejected(&store, &odd, &["odd", "not a session folder", "velodyne", "Scans", "pcd"]);
}

/// A ScansPcd (ELite / LT-mapper) session with ascii-free binary PCDs.
fn write_pcd_session(dir: &Path, scans: usize, points: usize) {
    std::fs::create_dir_all(dir.join("Scans")).unwrap();
    let mut poses = String::new();
    for i in 0..scans {
        let mut f = format!(
            "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z intensity\nSIZE 4 4 4 4\nTYPE F F F F\nCOUNT 1 1 1 1\nWIDTH {points}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {points}\nDATA binary\n"
        )
        .into_bytes();
        for k in 0..points {
            for v in [k as f32 * 0.1, 5.0, (k % 7) as f32, 1.0] {
                f.extend_from_slice(&v.to_le_bytes());
            }
        }
        std::fs::write(dir.join(format!("Scans/{i:06}.pcd")), f).unwrap();
        poses.push_str(&format!("1 0 0 {i} 0 1 0 0 0 0 1 0\n"));
    }
    std::fs::write(dir.join("poses.txt"), poses).unwrap();
}

#[test]
fn pcd_session_ingests() {
    let (_t, store, _bad) = setup();
    let pcd = store.parent().unwrap().join("pcd_ok");
    write_pcd_session(&pcd, 3, 100);
    let o = run(&["ingest", store.to_str().unwrap(), pcd.to_str().unwrap(), "--format", "json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert_eq!(v["layout"], "scans-pcd");
    assert_eq!(v["points"], 300);
}

#[test]
fn truncated_pcd() {
    let (_t, store, _bad) = setup();
    let pcd = store.parent().unwrap().join("pcd_trunc");
    write_pcd_session(&pcd, 3, 100);
    let p = pcd.join("Scans/000001.pcd");
    let b = std::fs::read(&p).unwrap();
    std::fs::write(&p, &b[..b.len() - 50]).unwrap();
    assert_rejected(&store, &pcd, &["000001.pcd", "byte"]);
}

#[test]
fn lying_pcd_header() {
    let (_t, store, _bad) = setup();
    let pcd = store.parent().unwrap().join("pcd_lie");
    write_pcd_session(&pcd, 3, 100);
    let p = pcd.join("Scans/000002.pcd");
    let b = std::fs::read(&p).unwrap();
    let text = String::from_utf8_lossy(&b[..300]).into_owned();
    let fixed = text.replacen("POINTS 100", "POINTS 120", 1);
    let mut out = fixed.into_bytes();
    out.extend_from_slice(&b[300..]);
    std::fs::write(&p, out).unwrap();
    assert_rejected(&store, &pcd, &["000002.pcd", "line 10", "POINTS"]);
}

#[test]
fn same_session_twice_is_a_no_op() {
    let tmp = tempfile::tempdir().unwrap();
    let store = tmp.path().join("site.seam");
    init_store(&store);
    let s = tmp.path().join("s");
    write_kitti_session(&s, 3, 300, 9);
    assert!(run(&["ingest", store.to_str().unwrap(), s.to_str().unwrap()]).status.success());
    let before = store_state(&store);
    let o = run(&["ingest", store.to_str().unwrap(), s.to_str().unwrap(), "--format", "json"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(stderr(&o).contains("already in the store as session 1"), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert_eq!(v["status"], "already_present");
    assert_eq!(before, store_state(&store));
}

#[test]
fn folder_that_is_not_a_store() {
    let tmp = tempfile::tempdir().unwrap();
    let s = tmp.path().join("s");
    write_kitti_session(&s, 2, 100, 3);
    let o = run(&["ingest", tmp.path().to_str().unwrap(), s.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(4));
    assert!(stderr(&o).contains("not a seam store"), "{}", stderr(&o));
    assert!(stderr(&o).contains("seam init"), "{}", stderr(&o));
    assert!(!tmp.path().join("seam.lock").exists(), "a lock file was left in a non-store folder");
}

#[test]
fn store_with_newer_schema() {
    let (_t, store, bad) = setup();
    write_kitti_session(&bad, 3, 100, 4);
    {
        let c = rusqlite::Connection::open(store.join("seam.db")).unwrap();
        c.pragma_update(None, "user_version", 999).unwrap();
    }
    let before = store_state(&store);
    let o = run(&["ingest", store.to_str().unwrap(), bad.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(4), "{}", stderr(&o));
    assert!(stderr(&o).contains("schema version 999 is newer"), "{}", stderr(&o));
    assert_eq!(before, store_state(&store));
}

#[test]
fn busy_store_names_the_writer_pid() {
    let (_t, store, bad) = setup();
    let _writer = seam::store::Store::open(&store).unwrap();
    let o = run(&["ingest", store.to_str().unwrap(), bad.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(5), "{}", stderr(&o));
    assert!(stderr(&o).contains(&format!("store in use by pid {}", std::process::id())), "{}", stderr(&o));
    // Readers are not blocked by the writer.
    let o = run(&["sessions", store.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
}

#[test]
fn usage_errors_exit_2() {
    let o = run(&["simulate", "/tmp/x", "--sensor", "kinect"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("os1-64"), "{}", stderr(&o));
    let o = run(&["frobnicate"]);
    assert_eq!(o.status.code(), Some(2));
}

/// The alignment options and settings of issue 3: a malformed
/// `--initial-guess`, an unknown `--anchors` mode, a config with a zero σ or
/// a misspelt key — each exit 2 with a message naming the problem, and the
/// store unchanged. A `--gt` folder that is not a simulator's output is a
/// data error (exit 4).
#[test]
fn bad_alignment_options_and_settings() {
    let (t, store, bad) = setup();
    let (st, dir) = (store.to_str().unwrap(), bad.to_str().unwrap());
    let before = store_state(&store);
    let zero_sigma = t.path().join("zero.toml");
    std::fs::write(&zero_sigma, "[graph]\nloop_sigma_trans_m = 0.0\n").unwrap();
    let typo = t.path().join("typo.toml");
    std::fs::write(&typo, "[loops.dop]\nrho_mx = 4.0\n").unwrap();
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (vec!["ingest", st, dir, "--initial-guess", "1,2,3"], "expected 4 finite numbers"),
        (vec!["ingest", st, dir, "--initial-guess", "1,2,x,4"], "\"x\" is not a number"),
        (vec!["ingest", st, dir, "--anchors", "rigid"], "is not an anchor mode"),
        (vec!["--config", zero_sigma.to_str().unwrap(), "ingest", st, dir], "graph.loop_sigma_trans_m"),
        (vec!["--config", typo.to_str().unwrap(), "ingest", st, dir], "rho_mx"),
    ];
    for (args, fragment) in cases {
        let o = run(&args);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {}", stderr(&o));
        assert!(stderr(&o).contains(fragment), "{args:?}: message lacks {fragment:?}:\n{}", stderr(&o));
        assert_same_state(&before, &store_state(&store), &format!("after {args:?}"));
    }
    let o = run(&["eval", "align", st, "--gt", dir]);
    assert_eq!(o.status.code(), Some(4), "{}", stderr(&o));
    assert!(stderr(&o).contains(dir), "the message does not name the folder:\n{}", stderr(&o));
    assert_same_state(&before, &store_state(&store), "after eval align with a bad --gt");
}

/// The evidence stage's inputs (issue 4): an unknown evidence model or free
/// test, a negative clearance or surface tolerance, an ω floor above 1 or
/// no free support in the config (among others: the single-change test's
/// angle and hits) is a usage error (exit 2) naming the key
/// (or the values it takes); `seam eval dor` with a labels folder that has no labels, or a session
/// the store does not have, is a data error (exit 4) naming the file or the
/// sessions there are. The store is unchanged every time.
#[test]
fn bad_evidence_settings_and_dor_inputs() {
    let (t, store, bad) = setup();
    let (st, dir) = (store.to_str().unwrap(), bad.to_str().unwrap());
    let before = store_state(&store);
    let model = t.path().join("model.toml");
    std::fs::write(&model, "[evidence]\nmodel = \"octomap\"\n").unwrap();
    let clearance = t.path().join("clearance.toml");
    std::fs::write(&clearance, "[evidence]\nfree_clearance_m = -1.0\n").unwrap();
    let clamp = t.path().join("clamp.toml");
    std::fs::write(&clamp, "[change]\neps_g_min = 0.9\neps_g_max = 0.1\n").unwrap();
    let reliability = t.path().join("reliability.toml");
    std::fs::write(&reliability, "[change]\ndeleted_reliability = \"support\"\n").unwrap();
    let floor = t.path().join("floor.toml");
    std::fs::write(&floor, "[evidence]\nomega_floor = 1.5\n").unwrap();
    let tolerance = t.path().join("tolerance.toml");
    std::fs::write(&tolerance, "[evidence]\nsurface_tolerance_m = -0.03\n").unwrap();
    let free_test = t.path().join("free_test.toml");
    std::fs::write(&free_test, "[evidence]\nfree_test = \"ray\"\n").unwrap();
    let support = t.path().join("support.toml");
    std::fs::write(&support, "[change]\nfree_support_keyframes = 0\n").unwrap();
    let nr_range = t.path().join("nr_range.toml");
    std::fs::write(&nr_range, "[evidence]\nno_return_range_m = -1.0\n").unwrap();
    let nr_margin = t.path().join("nr_margin.toml");
    std::fs::write(&nr_margin, "[evidence]\nno_return_margin_deg = 0.0\n").unwrap();
    let nr_elevation = t.path().join("nr_elevation.toml");
    std::fs::write(&nr_elevation, "[evidence]\nno_return_min_elevation_deg = 120.0\n").unwrap();
    let vacated = t.path().join("vacated.toml");
    std::fs::write(&vacated, "[evidence]\nvacated_clearance_m = -0.05\n").unwrap();
    let guard_deg = t.path().join("guard_deg.toml");
    std::fs::write(&guard_deg, "[evidence]\nfree_guard_deg = 5.0\n").unwrap();
    let grow_depth = t.path().join("grow_depth.toml");
    std::fs::write(&grow_depth, "[evidence]\ngrow_depth_voxels = 40\n").unwrap();
    let grow_hits = t.path().join("grow_hits.toml");
    std::fs::write(&grow_hits, "[evidence]\ngrow_max_hits = -1\n").unwrap();
    let footing = t.path().join("footing.toml");
    std::fs::write(&footing, "[evidence]\nfooting_height_m = -0.05\n").unwrap();
    let footing_kf = t.path().join("footing_kf.toml");
    std::fs::write(&footing_kf, "[evidence]\nfooting_max_keyframes = 0\n").unwrap();
    let own_range = t.path().join("own_range.toml");
    std::fs::write(&own_range, "[evidence]\nown_no_return_range_m = -60\n").unwrap();
    let own_elev = t.path().join("own_elev.toml");
    std::fs::write(&own_elev, "[evidence]\nown_no_return_min_elevation_deg = 91\n").unwrap();
    let own_kf = t.path().join("own_kf.toml");
    std::fs::write(&own_kf, "[evidence]\nown_no_return_max_keyframes = 0\n").unwrap();
    let once_deg = t.path().join("once_deg.toml");
    std::fs::write(&once_deg, "[evidence]\nchange_once_max_deg = 200.0\n").unwrap();
    let once_hits = t.path().join("once_hits.toml");
    std::fs::write(&once_hits, "[evidence]\nchange_once_min_hits = 0\n").unwrap();
    let cluster = t.path().join("cluster.toml");
    std::fs::write(&cluster, "[evidence]\ncluster_share = 60\n").unwrap();
    let reach = t.path().join("reach.toml");
    std::fs::write(&reach, "[evidence]\ncluster_reach_deg = 0.0\n").unwrap();
    let piece = t.path().join("piece.toml");
    std::fs::write(&piece, "[evidence]\ncluster_max_voxels = 0\n").unwrap();
    let object = t.path().join("object.toml");
    std::fs::write(&object, "[change]\nobject_share = 1.5\n").unwrap();
    let object_max = t.path().join("object_max.toml");
    std::fs::write(&object_max, "[change]\nobject_max_voxels = 0\n").unwrap();
    let object_new = t.path().join("object_new.toml");
    std::fs::write(&object_new, "[change]\nobject_max_new = -1.0\n").unwrap();
    let object_sure = t.path().join("object_sure.toml");
    std::fs::write(&object_sure, "[change]\nobject_sure_share = 1.2\n").unwrap();
    let piece_gone = t.path().join("piece_gone.toml");
    std::fs::write(&piece_gone, "[change]\npiece_gone_share = -0.5\n").unwrap();
    let piece_gone_w = t.path().join("piece_gone_w.toml");
    std::fs::write(&piece_gone_w, "[change]\npiece_gone_min_w = 2.0\n").unwrap();
    for (cfg, fragment) in [
        (&model, "octomap"),
        (&clearance, "free_clearance_m"),
        (&clamp, "eps_g_min"),
        (&reliability, "omega_or_half_support"),
        (&floor, "omega_floor"),
        (&tolerance, "surface_tolerance_m"),
        (&free_test, "surface"),
        (&support, "free_support_keyframes"),
        (&nr_range, "no_return_range_m"),
        (&nr_margin, "no_return_margin_deg"),
        (&nr_elevation, "no_return_min_elevation_deg"),
        (&vacated, "vacated_clearance_m"),
        (&guard_deg, "free_guard_deg"),
        (&grow_depth, "grow_depth_voxels"),
        (&grow_hits, "grow_max_hits"),
        (&footing, "footing_height_m"),
        (&footing_kf, "footing_max_keyframes"),
        (&own_range, "own_no_return_range_m"),
        (&own_elev, "own_no_return_min_elevation_deg"),
        (&own_kf, "own_no_return_max_keyframes"),
        (&once_deg, "change_once_max_deg"),
        (&once_hits, "change_once_min_hits"),
        (&cluster, "cluster_share"),
        (&reach, "cluster_reach_deg"),
        (&piece, "cluster_max_voxels"),
        (&object, "object_share"),
        (&object_max, "object_max_voxels"),
        (&object_new, "object_max_new"),
        (&object_sure, "object_sure_share"),
        (&piece_gone, "piece_gone_share"),
        (&piece_gone_w, "piece_gone_min_w"),
    ] {
        let o = run(&["--config", cfg.to_str().unwrap(), "ingest", st, dir]);
        assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
        assert!(stderr(&o).contains(fragment), "message lacks {fragment:?}:\n{}", stderr(&o));
        assert_same_state(&before, &store_state(&store), "after a bad evidence config");
    }
    let o = run(&["eval", "dor", st, "--labels", dir]);
    assert_eq!(o.status.code(), Some(4), "{}", stderr(&o));
    assert!(stderr(&o).contains("000000.label"), "the message does not name the label file:\n{}", stderr(&o));
    let o = run(&["eval", "dor", st, "--labels", dir, "--session", "nope"]);
    assert_eq!(o.status.code(), Some(4), "{}", stderr(&o));
    assert!(stderr(&o).contains("no session named \"nope\""), "{}", stderr(&o));
    assert_same_state(&before, &store_state(&store), "after eval dor with bad inputs");
}

/// `seam eval changes`: a store without a lifelong map, and a `--gt` folder
/// whose `objects.csv` is garbled or missing, are data errors (exit 4) that
/// say what to run or name the file and line. The store is unchanged.
#[test]
fn bad_change_eval_inputs() {
    let tmp = tempfile::tempdir().unwrap();
    let sim = tmp.path().join("sim");
    let o = run(&["simulate", sim.to_str().unwrap(), "--sessions", "1", "--keyframes", "2", "-q"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let store = tmp.path().join("site.seam");
    init_store(&store);
    let before = store_state(&store);
    let (st, gt) = (store.to_str().unwrap(), sim.to_str().unwrap());
    let eval = || run(&["eval", "changes", st, "--gt", gt]);

    let o = eval();
    assert_eq!(o.status.code(), Some(4), "{}", stderr(&o));
    for f in ["no lifelong map", "hint:", "seam ingest"] {
        assert!(stderr(&o).contains(f), "message lacks {f:?}:\n{}", stderr(&o));
    }

    let objects = sim.join("objects.csv");
    let text = std::fs::read_to_string(&objects).unwrap();
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    let mut cells: Vec<&str> = lines[2].split(',').collect();
    cells[4] = "east";
    lines[2] = cells.join(",");
    std::fs::write(&objects, lines.join("\n")).unwrap();
    let o = eval();
    assert_eq!(o.status.code(), Some(4), "{}", stderr(&o));
    for f in ["objects.csv", "line 3", "`east` is not a number"] {
        assert!(stderr(&o).contains(f), "message lacks {f:?}:\n{}", stderr(&o));
    }

    std::fs::remove_file(&objects).unwrap();
    let o = eval();
    assert_eq!(o.status.code(), Some(4), "{}", stderr(&o));
    for f in ["objects.csv is missing", "hint:"] {
        assert!(stderr(&o).contains(f), "message lacks {f:?}:\n{}", stderr(&o));
    }
    assert_same_state(&before, &store_state(&store), "after eval changes with bad inputs");
}

/// A reader that closes the pipe early (`seam sessions … | head -0`) ends seam
/// quietly, never with a "failed printing to stdout" panic (exit 101).
#[cfg(unix)]
#[test]
fn closed_stdout_is_not_a_panic() {
    use std::os::unix::process::ExitStatusExt;
    let tmp = tempfile::tempdir().unwrap();
    let store = tmp.path().join("site.seam");
    init_store(&store);
    let mut child = seam()
        .args(["sessions", store.to_str().unwrap(), "--format", "json"])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // Close the read end before seam writes anything: its first write meets EPIPE.
    drop(child.stdout.take());
    let o = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!err.contains("panicked"), "seam panicked on a closed stdout:\n{err}");
    assert!(
        o.status.success() || o.status.signal() == Some(13), // SIGPIPE on Linux and macOS
        "expected a quiet end (exit 0 or SIGPIPE), got {:?}: {err}",
        o.status
    );
}
