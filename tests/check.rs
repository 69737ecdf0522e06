//! `seam check`: orphans are listed and repaired; damaged or missing files
//! are reported with exit code 4.

mod common;
use common::*;

#[test]
fn orphan_listed_then_repaired_and_damage_detected() {
    let tmp = tempfile::tempdir().unwrap();
    let store = tmp.path().join("site.seam");
    init_store(&store);
    let (a, b) = (tmp.path().join("a"), tmp.path().join("b"));
    write_kitti_session(&a, 3, 300, 1);
    write_kitti_session(&b, 3, 300, 2);
    assert!(run(&["ingest", store.to_str().unwrap(), a.to_str().unwrap()]).status.success());

    // A crash after the scans file is published but before its rows commit.
    let o = seam()
        .args(["ingest", store.to_str().unwrap(), b.to_str().unwrap()])
        .env("SEAM_FAULT", "scans:before_commit")
        .output()
        .unwrap();
    assert!(!o.status.success());
    let o = run(&["check", store.to_str().unwrap(), "--format", "json"]);
    assert!(o.status.success(), "{}", stdout(&o));
    let v: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    let orphans = v["report"]["orphans"].as_array().unwrap();
    assert_eq!(orphans.len(), 1, "{v}");
    let orphan = orphans[0].as_str().unwrap().to_string();
    assert!(orphan.starts_with("data/scans/session-0002-"), "{orphan}");

    let o = run(&["check", store.to_str().unwrap(), "--repair"]);
    assert!(o.status.success(), "{}", stdout(&o));
    assert!(stdout(&o).contains("removed"), "{}", stdout(&o));
    assert!(!store.join(&orphan).exists());
    let o = run(&["check", store.to_str().unwrap(), "--format", "json"]);
    let v: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert_eq!(v["report"]["orphans"].as_array().unwrap().len(), 0);
    // The session's scans, plus its evidence step's submap evidence, cleaned
    // map and point labels (one submap).
    assert_eq!(v["report"]["files_checked"], 4);

    // One flipped byte in a referenced file is found by its hash.
    let scans = std::fs::read_dir(store.join("data/scans")).unwrap().next().unwrap().unwrap().path();
    let mut bytes = std::fs::read(&scans).unwrap();
    let mid = bytes.len() / 2;
    bytes[mid] ^= 0xff;
    std::fs::write(&scans, &bytes).unwrap();
    let o = run(&["check", store.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(4), "{}", stdout(&o));
    assert!(stdout(&o).contains("content hash differs"), "{}", stdout(&o));

    // A missing one is named.
    std::fs::remove_file(&scans).unwrap();
    let o = run(&["check", store.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(4));
    assert!(stdout(&o).contains("missing"), "{}", stdout(&o));
}
