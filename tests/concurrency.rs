//! Readers never block: queries of the store succeed while an ingest runs.

mod common;
use common::*;

#[test]
fn read_only_queries_succeed_during_an_ingest() {
    let tmp = tempfile::tempdir().unwrap();
    let store = tmp.path().join("site.seam");
    init_store(&store);
    let a = tmp.path().join("a");
    write_kitti_session(&a, 3, 500, 1);
    assert!(run(&["ingest", store.to_str().unwrap(), a.to_str().unwrap()]).status.success());
    let b = tmp.path().join("b");
    write_kitti_session(&b, 120, 20_000, 2);

    let mut child = seam()
        .args(["ingest", store.to_str().unwrap(), b.to_str().unwrap()])
        .stdout(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let mut during = 0;
    loop {
        let running = child.try_wait().unwrap().is_none();
        for cmd in ["sessions", "info"] {
            let o = run(&[cmd, store.to_str().unwrap(), "--format", "json"]);
            assert!(o.status.success(), "{cmd} failed during an ingest: {}", stderr(&o));
            let v: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
            assert!(!v.is_null());
        }
        if running {
            during += 1;
        } else {
            break;
        }
    }
    assert!(child.wait().unwrap().success());
    assert!(during >= 1, "no query ran while the ingest was running");
    let o = run(&["sessions", store.to_str().unwrap(), "--format", "json"]);
    let v: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert_eq!(v.as_array().map(|a| a.len()), Some(2));
}
