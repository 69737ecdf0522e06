//! Crash consistency: an ingest killed at any point (by an injected abort at
//! every named fault point, and by real `kill -9` at several moments) leaves a
//! store that `seam check` passes, and a re-run finishes with the same content
//! as an uninterrupted run — the database (lifelong map, change events and
//! tile index included) and every data file.

mod common;
use common::*;
use std::path::Path;

fn ingest(store: &Path, session: &Path) {
    let o = run(&["ingest", store.to_str().unwrap(), session.to_str().unwrap()]);
    assert!(o.status.success(), "ingest failed: {}", stderr(&o));
}

fn check_ok(store: &Path) {
    let o = run(&["check", store.to_str().unwrap()]);
    assert!(o.status.success(), "seam check failed after a crash:\n{}{}", stdout(&o), stderr(&o));
}

/// A store with session `a` ingested, as a fresh copy under `dir`.
fn base_store(dir: &Path, a: &Path) -> std::path::PathBuf {
    let store = dir.join("site.seam");
    init_store(&store);
    ingest(&store, a);
    store
}

#[test]
fn abort_at_every_fault_point_then_resume() {
    let tmp = tempfile::tempdir().unwrap();
    let (a, b) = (tmp.path().join("a"), tmp.path().join("b"));
    write_kitti_session(&a, 6, 800, 1);
    write_kitti_session(&b, 30, 800, 2);

    // The uninterrupted reference, and the list of fault points it passes.
    let reference = base_store(&tmp.path().join("ref"), &a);
    let o = seam()
        .args(["ingest", reference.to_str().unwrap(), b.to_str().unwrap()])
        .env("SEAM_FAULT", "list")
        .output()
        .unwrap();
    assert!(o.status.success());
    // A point passed several times (one file per submap) is tested once: an
    // abort there stops at its first pass.
    let mut points: Vec<String> = Vec::new();
    for p in stderr(&o).lines().filter_map(|l| l.strip_prefix("seam-fault-point ")) {
        if !points.iter().any(|q| q == p) {
            points.push(p.to_string());
        }
    }
    for expected in [
        "scans:before_rename",
        "scans:before_commit",
        "submaps:before_commit",
        "coarse_align:before_commit",
        "loops:before_commit",
        "optimize:before_commit",
        "evidence:before_rename",
        "cleaned_map:before_rename",
        "point_labels:before_rename",
        "evidence:before_commit",
        "changes:before_commit",
        "complete:before_commit",
    ] {
        assert!(points.iter().any(|p| p == expected), "fault point {expected} not reached; saw {points:?}");
    }
    let want = store_state(&reference);

    for point in &points {
        let dir = tmp.path().join(format!("crash-{}", point.replace(':', "-")));
        let store = base_store(&dir, &a);
        let o = seam()
            .args(["ingest", store.to_str().unwrap(), b.to_str().unwrap()])
            .env("SEAM_FAULT", point)
            .output()
            .unwrap();
        assert!(!o.status.success(), "fault {point} did not stop the ingest");
        assert!(stderr(&o).contains(&format!("injected fault at {point}")), "{}", stderr(&o));
        check_ok(&store);
        ingest(&store, &b);
        check_ok(&store);
        assert_same_state(&want, &store_state(&store), &format!("after a crash at {point}"));
    }
}

#[test]
fn kill_9_at_several_moments_then_resume() {
    let tmp = tempfile::tempdir().unwrap();
    let (a, b) = (tmp.path().join("a"), tmp.path().join("b"));
    write_kitti_session(&a, 4, 500, 5);
    write_kitti_session(&b, 80, 20_000, 6);
    let reference = base_store(&tmp.path().join("ref"), &a);
    let t0 = std::time::Instant::now();
    ingest(&reference, &b);
    let full = t0.elapsed();
    let want = store_state(&reference);

    let mut killed_mid_run = 0;
    for (k, frac) in [0.05, 0.2, 0.4, 0.6, 0.8, 0.95].iter().enumerate() {
        let store = base_store(&tmp.path().join(format!("kill{k}")), &a);
        let mut child = seam()
            .args(["ingest", store.to_str().unwrap(), b.to_str().unwrap()])
            .stdout(std::process::Stdio::null())
            .spawn()
            .unwrap();
        std::thread::sleep(full.mul_f64(*frac));
        // SIGKILL: no destructors, no flush, like a power cut to the process.
        let _ = child.kill();
        let status = child.wait().unwrap();
        if !status.success() {
            killed_mid_run += 1;
        }
        check_ok(&store);
        ingest(&store, &b);
        check_ok(&store);
        assert_same_state(&want, &store_state(&store), &format!("after kill -9 at {frac} of the run"));
    }
    assert!(killed_mid_run >= 3, "only {killed_mid_run} kills landed mid-run; the test proved little");
}
