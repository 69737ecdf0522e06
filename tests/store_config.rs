//! A store records the configuration its first session was ingested with:
//! later commands without `--config` run with it, an ingest with other
//! settings is refused (exit 2, naming each key, the store untouched), and
//! `seam rebuild` without `--config` reproduces the store; `seam info` shows it.

mod common;
use common::*;
use std::path::Path;

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// `submap_length_m` each session's `submaps` step ran with, by session id.
fn submap_lengths(store: &Path) -> Vec<(i64, f64)> {
    let conn = rusqlite::Connection::open_with_flags(store.join("seam.db"), rusqlite::OpenFlags::SQLITE_OPEN_READ_ONLY)
        .unwrap();
    let mut st = conn
        .prepare("SELECT session_id, details_json FROM step_log WHERE step = 'submaps' ORDER BY session_id")
        .unwrap();
    st.query_map([], |r| Ok((r.get::<_, i64>(0)?, r.get::<_, String>(1)?)))
        .unwrap()
        .map(|r| {
            let (id, json) = r.unwrap();
            let v: serde_json::Value = serde_json::from_str(&json).unwrap();
            (id, v["submap_length_m"].as_f64().unwrap())
        })
        .collect()
}

#[test]
fn the_first_ingest_binds_the_store_to_its_configuration() {
    let tmp = tempfile::tempdir().unwrap();
    let t = tmp.path();
    let (x, y, z) = (t.join("x"), t.join("y"), t.join("z"));
    write_kitti_session(&x, 6, 600, 1);
    write_kitti_session(&y, 6, 600, 2);
    write_kitti_session(&z, 6, 600, 3);
    let a_toml = t.join("a.toml");
    std::fs::write(&a_toml, "[submap]\nsubmap_length_m = 4.0\n").unwrap();
    let b_toml = t.join("b.toml");
    std::fs::write(&b_toml, "[submap]\nsubmap_length_m = 8.0\n[loops.dop]\nrho_max = 4.0\n").unwrap();
    let a_batch = t.join("a_batch.toml");
    std::fs::write(&a_batch, "[submap]\nsubmap_length_m = 4.0\n[ingest]\nread_batch_scans = 2\n").unwrap();

    let store = t.join("site.seam");
    // `init --config B` records B, but the first ingest may still choose A.
    let o = run(&["--config", s(&b_toml), "init", s(&store)]);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = run(&["--config", s(&a_toml), "ingest", s(&store), s(&x)]);
    assert!(o.status.success(), "{}", stderr(&o));

    // Another configuration is refused, naming every key that differs; nothing is written.
    let before = store_state(&store);
    let o = run(&["--config", s(&b_toml), "ingest", s(&store), s(&y)]);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{err}");
    for f in ["submap.submap_length_m = 8.0 (4.0)", "loops.dop.rho_max = 4.0 (6.0)", "hint:", "seam rebuild"] {
        assert!(err.contains(f), "stderr lacks {f:?}:\n{err}");
    }
    assert_same_state(&before, &store_state(&store), "after a refused ingest");

    // Without --config the store's own settings apply; [ingest] may differ.
    let o = run(&["ingest", s(&store), s(&y)]);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = run(&["--config", s(&a_batch), "ingest", s(&store), s(&z)]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(submap_lengths(&store), vec![(1, 4.0), (2, 4.0), (3, 4.0)]);
    // `seam info` says how the recorded configuration departs from the defaults.
    let o = run(&["info", s(&store), "--format", "json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let info: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert_eq!(info["config_not_default"], serde_json::json!(["submap.submap_length_m = 4.0 (20.0)"]));
    assert_eq!(info["config"]["submap"]["submap_length_m"], 4.0);
    let o = run(&["info", s(&store)]);
    assert!(stdout(&o).contains("submap.submap_length_m = 4.0 (20.0)"), "{}", stdout(&o));

    // A rebuild without --config recomputes with the recorded settings: the same store.
    let copy = t.join("copy.seam");
    let o = run(&["rebuild", s(&store), "--out", s(&copy), "--quiet"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_same_state(&store_state(&store), &store_state(&copy), "between the store and its rebuild");
    // With --config it recomputes with other settings, and the new store records them.
    let other = t.join("other.seam");
    let o = run(&["--config", s(&b_toml), "rebuild", s(&store), "--out", s(&other), "--quiet"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(submap_lengths(&other), vec![(1, 8.0), (2, 8.0), (3, 8.0)]);
    let w = t.join("w");
    write_kitti_session(&w, 6, 600, 4);
    let o = run(&["--config", s(&a_toml), "ingest", s(&other), s(&w)]);
    assert_eq!(o.status.code(), Some(2), "the rebuilt store is bound to B: {}", stderr(&o));
    assert!(stderr(&o).contains("submap.submap_length_m = 4.0 (8.0)"), "{}", stderr(&o));
}
