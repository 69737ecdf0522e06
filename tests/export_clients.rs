//! The CI client test: a store built through the binary from two simulated
//! sessions, exported with every table and `--las`, then opened by the
//! readers analysts use — pyarrow and DuckDB for the GeoParquet tables, laspy
//! (with lazrs) for the LAZ maps — in `tests/clients/check_exports.py`. The
//! script checks schemas, row counts against what this test counts in the
//! store, a bbox query in both readers, the `geo` metadata, the Hive
//! partitions and the LAS extra bytes against the Parquet rows.
//!
//! Without python3 or the modules the test prints a notice and passes, unless
//! `CI` is set (`.ci/run` installs them: there it must really run).

mod common;
use arrow_array::{Array, BinaryArray, BooleanArray, Float64Array, Int32Array, Int64Array};
use common::*;
use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
use seam::geometry::Pose;
use seam::store::{KeyframeId, LoopRow, SessionId, Store, StoreError, insert_loops};
use std::path::Path;

/// Simulates and ingests two sessions of 30 keyframes (a few seconds in a
/// release build).
fn ingested_store(tmp: &Path) -> std::path::PathBuf {
    let summary = simulate(&tmp.join("sim"), 2, 30, 7, &[]);
    let root = tmp.join("site.seam");
    // No local loop edges: the loop candidates are the three stored below.
    let config = tmp.join("no-local-edges.toml");
    std::fs::write(&config, "[loops]\nlocal_travel_m = 0.0\n").unwrap();
    let o = run(&["--config", config.to_str().unwrap(), "init", root.to_str().unwrap(), "--crs", "EPSG:32652"]);
    assert!(o.status.success(), "{}", stderr(&o));
    ingest_all(&root, &summary);
    root
}

/// Walks this short find no revisit and, with local edges off, no loop
/// candidates at all; three stored candidates (an
/// accepted inter-session loop, a rejection with infinite ρ, an intra one)
/// give `loop_edges` rows to read.
fn add_loop_candidates(root: &Path) {
    let conn = rusqlite::Connection::open(root.join("seam.db")).unwrap();
    let id = |s: i64, k: i64| -> i64 {
        conn.query_row("SELECT keyframe_id FROM keyframes WHERE session_id = ?1 AND keyframe_index = ?2", [s, k], |r| {
            r.get(0)
        })
        .unwrap()
    };
    let edge = |source: i64, target: i64, accepted: bool, rho: Option<f64>, kind: &str| LoopRow {
        session_id: SessionId(2),
        kind: kind.into(),
        source_keyframe: KeyframeId(source),
        target_keyframe: KeyframeId(target),
        distance_m: 1.5,
        t_target_source: Pose::identity(),
        converged: true,
        iterations: 12,
        inliers: 900,
        fitness: 0.01,
        inlier_ratio: 0.8,
        rho_scan: rho,
        rho_corr: rho,
        accepted,
        reason: if accepted { "accepted".into() } else { "rho below threshold".into() },
    };
    let loops = [
        edge(id(2, 5), id(1, 3), true, Some(12.5), "inter"),
        edge(id(2, 9), id(1, 20), false, None, "inter"),
        edge(id(2, 25), id(2, 2), false, Some(0.4), "intra"),
    ];
    drop(conn);
    let mut store = Store::open(root).unwrap();
    store.transaction(|tx| -> Result<(), StoreError> { insert_loops(tx, &loops) }).unwrap();
}

/// Row counts the store holds, per table and per session partition, as the
/// script's `--expect`.
fn expected_counts(root: &Path) -> serde_json::Value {
    let conn = rusqlite::Connection::open_with_flags(root.join("seam.db"), rusqlite::OpenFlags::SQLITE_OPEN_READ_ONLY)
        .unwrap();
    let count = |q: &str| conn.query_row(q, [], |r| r.get::<_, i64>(0)).unwrap();
    let per_session = |q: &str| -> serde_json::Value {
        let mut st = conn.prepare(q).unwrap();
        let rows = st.query_map([], |r| Ok((r.get::<_, i64>(0)?, r.get::<_, i64>(1)?))).unwrap();
        rows.map(|r| r.unwrap()).map(|(s, n)| (s.to_string(), serde_json::json!(n))).collect()
    };
    let statics = count("SELECT count(*) FROM map_voxels WHERE eps_g < 0.5");
    let lifelong = count("SELECT count(*) FROM map_voxels");
    serde_json::json!({
        "tables": {
            "sessions": count("SELECT count(*) FROM sessions"),
            "keyframes": count("SELECT count(*) FROM keyframes"),
            "loop_edges": count("SELECT count(*) FROM loop_candidates"),
            "map_voxels": lifelong,
            "static_map": statics,
            "changes": count("SELECT count(*) FROM change_events"),
            "point_labels": count("SELECT coalesce(sum(row_count), 0) FROM evidence_files WHERE kind = 'point_labels'"),
        },
        "partitions": {
            "keyframes": per_session("SELECT session_id, count(*) FROM keyframes GROUP BY session_id"),
            "loop_edges": per_session("SELECT s.session_id, count(c.candidate_id) FROM sessions s LEFT JOIN loop_candidates c ON c.session_id = s.session_id GROUP BY s.session_id"),
            "changes": per_session("SELECT session_id, events FROM session_changes"),
        },
        "las": {"static_map": statics, "lifelong_map": lifelong},
    })
}

#[test]
#[cfg_attr(debug_assertions, ignore = "release only: cargo test --release")]
fn analysts_readers_open_every_export() {
    let tmp = tempfile::tempdir().unwrap();
    let root = ingested_store(tmp.path());
    add_loop_candidates(&root);
    let before = store_state(&root);
    let out = tmp.path().join("out");
    let tables = "sessions,keyframes,loop_edges,map_voxels,changes,point_labels,static_map";
    let o = run(&["export", root.to_str().unwrap(), out.to_str().unwrap(), "--tables", tables, "--las", "--quiet"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_same_state(&before, &store_state(&root), "after an export (read-only)");

    check_loop_edges(&out);
    let expect = expected_counts(&root);
    assert_eq!(expect["tables"]["loop_edges"], 3);
    assert!(expect["tables"]["map_voxels"].as_i64().unwrap() > 100_000, "enough rows for several row groups");
    let expect_path = tmp.path().join("expect.json");
    std::fs::write(&expect_path, expect.to_string()).unwrap();
    run_client_check(&out, Some(&expect_path));
}

/// The three stored candidates, read back on the Rust side: partitioned by
/// the evaluating session, ρ null where infinite, each a LineString Z from
/// the source keyframe's exported position to the target's.
fn check_loop_edges(out: &Path) {
    let read = |p: &Path| {
        let b = ParquetRecordBatchReaderBuilder::try_new(std::fs::File::open(p).unwrap()).unwrap();
        b.build().unwrap().map(|b| b.unwrap()).collect::<Vec<_>>()
    };
    assert!(read(&out.join("loop_edges/session=1/part-0.parquet")).iter().all(|b| b.num_rows() == 0));
    let batches = read(&out.join("loop_edges/session=2/part-0.parquet"));
    assert_eq!(batches.len(), 1);
    let b = &batches[0];
    assert_eq!(b.num_rows(), 3);
    let col = |n: &str| b.column_by_name(n).unwrap_or_else(|| panic!("no column {n}")).clone();
    let ids = col("candidate_id");
    let ids = ids.as_any().downcast_ref::<Int64Array>().unwrap();
    let mut sorted = ids.values().to_vec();
    sorted.sort();
    assert_eq!(sorted, [1, 2, 3]);
    let accepted = col("accepted");
    let accepted = accepted.as_any().downcast_ref::<BooleanArray>().unwrap();
    let rho = col("rho_scan");
    let rho = rho.as_any().downcast_ref::<Float64Array>().unwrap();
    let wkb = col("geometry");
    let wkb = wkb.as_any().downcast_ref::<BinaryArray>().unwrap();
    let length = col("length_m");
    let length = length.as_any().downcast_ref::<Float64Array>().unwrap();
    let (src_kf, tgt_kf) = (col("source_keyframe"), col("target_keyframe"));
    let (src_kf, tgt_kf) =
        (src_kf.as_any().downcast_ref::<Int32Array>().unwrap(), tgt_kf.as_any().downcast_ref::<Int32Array>().unwrap());
    let (src_s, tgt_s) = (col("source_session"), col("target_session"));
    let (src_s, tgt_s) =
        (src_s.as_any().downcast_ref::<Int64Array>().unwrap(), tgt_s.as_any().downcast_ref::<Int64Array>().unwrap());
    // Keyframe positions as exported.
    let position = |s: i64, k: i32| -> [f64; 3] {
        let kb = &read(&out.join(format!("keyframes/session={s}/part-0.parquet")))[0];
        let idx = kb.column_by_name("keyframe_index").unwrap().as_any().downcast_ref::<Int32Array>().unwrap().clone();
        let r = (0..kb.num_rows()).find(|&r| idx.value(r) == k).unwrap();
        ["x_m", "y_m", "z_m"]
            .map(|c| kb.column_by_name(c).unwrap().as_any().downcast_ref::<Float64Array>().unwrap().value(r))
    };
    for r in 0..3 {
        let id = ids.value(r);
        assert_eq!(accepted.value(r), id == 1, "candidate {id}");
        assert_eq!(rho.is_null(r), id == 2, "candidate {id}: infinite rho is null");
        let w = wkb.value(r);
        assert_eq!(&w[..9], &[1, 0xea, 0x03, 0, 0, 2, 0, 0, 0], "LineString Z of two vertices");
        let a = position(src_s.value(r), src_kf.value(r));
        let b = position(tgt_s.value(r), tgt_kf.value(r));
        let got: Vec<f64> = w[9..].chunks(8).map(|c| f64::from_le_bytes(c.try_into().unwrap())).collect();
        assert_eq!(got, [a, b].concat(), "candidate {id}");
        let d = (0..3).map(|i| (a[i] - b[i]).powi(2)).sum::<f64>().sqrt();
        assert!((length.value(r) - d).abs() < 1e-9);
    }
}
