//! `seam export`: point labels of every session that has them, as
//! Hive-partitioned Parquet with a catalog; bad table names are usage errors
//! that write nothing; an existing table is only replaced with --overwrite.

mod common;
use common::*;
use seam::evidence::PointLabels;
use seam::store::evidence_files::{read_point_labels, write_point_labels};
use seam::store::{NewSession, Store, StoreError, insert_file, insert_session};
use std::path::Path;

fn labels(n: usize, seed: i32) -> PointLabels {
    PointLabels {
        keyframe: (0..n as i32).map(|i| i / 100 + seed).collect(),
        point_index: (0..n as i32).map(|i| i % 100).collect(),
        dynamic: (0..n as i32).map(|i| (i + seed) % 5 == 0).collect(),
        eps_l: (0..n).map(|i| 0.1 + (i % 10) as f32 * 0.1).collect(),
    }
}

/// A store with three sessions; the first two have point labels.
fn setup(tmp: &Path) -> (std::path::PathBuf, Vec<PointLabels>) {
    let root = tmp.join("site.seam");
    init_store(&root);
    let mut store = Store::open(&root).unwrap();
    let want = vec![labels(250, 1), labels(1234, 2)];
    let mut recs = Vec::new();
    for (i, l) in want.iter().enumerate() {
        recs.push(write_point_labels(&store, &format!("data/point_labels/session-{:04}.parquet", i + 1), l).unwrap());
    }
    store
        .transaction(|tx| -> Result<(), StoreError> {
            for i in 0..3 {
                let name = format!("s{}", i + 1);
                let ns = NewSession {
                    name: &name,
                    content_hash: &name,
                    source_dir: "/nowhere",
                    layout: "kitti",
                    date: None,
                    sensor_model: None,
                    fov_json: None,
                    keyframe_count: 3,
                    point_count: 1000,
                };
                let sid = insert_session(tx, &ns)?;
                if let Some(rec) = recs.get(i) {
                    insert_file(tx, &root, rec, Some(sid.0))?;
                }
            }
            Ok(())
        })
        .unwrap();
    (root, want)
}

fn names(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> =
        std::fs::read_dir(dir).unwrap().flatten().map(|e| e.file_name().to_string_lossy().into_owned()).collect();
    v.sort();
    v
}

#[test]
fn exports_point_labels_per_session_with_a_catalog() {
    let tmp = tempfile::tempdir().unwrap();
    let (root, want) = setup(tmp.path());
    let out = tmp.path().join("out");
    // A writer holding the store does not stop a read-only export.
    let _writer = Store::open(&root).unwrap();
    let o = run(&["export", root.to_str().unwrap(), out.to_str().unwrap(), "--tables", "point_labels"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = stdout(&o);
    assert!(text.starts_with("table"), "{text}");
    assert!(text.contains("1,234"), "{text}");

    assert_eq!(names(&out), ["_catalog.json", "point_labels"], "nothing but the outputs is left");
    assert_eq!(names(&out.join("point_labels")), ["session=1", "session=2"]);
    for (i, l) in want.iter().enumerate() {
        let dir = out.join(format!("point_labels/session={}", i + 1));
        assert_eq!(names(&dir), ["part-0.parquet"]);
        let part = dir.join("part-0.parquet");
        assert_eq!(&read_point_labels(&part).unwrap(), l);
        // Exactly the documented columns, nothing else.
        let reader =
            parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder::try_new(std::fs::File::open(&part).unwrap())
                .unwrap();
        let cols: Vec<(String, String)> =
            reader.schema().fields().iter().map(|f| (f.name().clone(), f.data_type().to_string())).collect();
        let expected = [("keyframe", "Int32"), ("point_index", "Int32"), ("dynamic", "Boolean"), ("eps_l", "Float32")];
        assert_eq!(cols, expected.map(|(a, b)| (a.to_string(), b.to_string())));
    }

    let cat: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("_catalog.json")).unwrap()).unwrap();
    let t = &cat["tables"][0];
    assert_eq!(cat["tables"].as_array().unwrap().len(), 1);
    assert_eq!(t["name"], "point_labels");
    assert_eq!(t["row_count"], 250 + 1234);
    let cols: Vec<String> = t["columns"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| format!("{}:{}", c["name"].as_str().unwrap(), c["type"].as_str().unwrap()))
        .collect();
    assert_eq!(cols, ["keyframe:int32", "point_index:int32", "dynamic:boolean", "eps_l:float32"]);
    let parts = t["partitions"].as_array().unwrap();
    assert_eq!(parts.len(), 2);
    assert_eq!(parts[1]["session"], 2);
    assert_eq!(parts[1]["session_name"], "s2");
    assert_eq!(parts[1]["row_count"], 1234);
    assert_eq!(parts[1]["path"], "point_labels/session=2/part-0.parquet");
    let size = std::fs::metadata(out.join("point_labels/session=2/part-0.parquet")).unwrap().len();
    assert_eq!(parts[1]["size_bytes"], size);

    // The table exists now: refused without --overwrite, nothing touched.
    let before = snapshot_files(&out);
    let o = run(&["export", root.to_str().unwrap(), out.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("--overwrite"), "{}", stderr(&o));
    assert_eq!(snapshot_files(&out), before);

    // With it, the table is replaced whole; JSON lists what was written.
    std::fs::write(out.join("point_labels/session=2/stale.parquet"), b"old").unwrap();
    let o = run(&["export", root.to_str().unwrap(), out.to_str().unwrap(), "--overwrite", "--format", "json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    let parts = v["partitions"].as_array().unwrap();
    assert_eq!(parts.len(), 2, "{v}");
    assert_eq!(parts[0]["table"], "point_labels");
    assert_eq!(parts[0]["rows"], 250);
    assert_eq!(names(&out.join("point_labels/session=2")), ["part-0.parquet"]);
    assert_eq!(names(&out), ["_catalog.json", "point_labels"]);
    assert_eq!(&read_point_labels(&out.join("point_labels/session=2/part-0.parquet")).unwrap(), &want[1]);
}

#[test]
fn unknown_table_is_a_usage_error_that_writes_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let (root, _) = setup(tmp.path());
    for tables in ["bogus", "point_labels,bogus"] {
        let out = tmp.path().join("out");
        let o = run(&["export", root.to_str().unwrap(), out.to_str().unwrap(), "--tables", tables]);
        assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
        let err = stderr(&o);
        assert!(err.contains("bogus") && err.contains("point_labels"), "{err}");
        assert!(!out.exists(), "nothing is written for --tables {tables}");
    }
}

#[test]
fn store_without_labels_exports_an_empty_table() {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path().join("site.seam");
    init_store(&root);
    let out = tmp.path().join("out");
    let o = run(&["export", root.to_str().unwrap(), out.to_str().unwrap(), "--quiet"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(out.join("point_labels").is_dir());
    assert!(names(&out.join("point_labels")).is_empty());
    let cat: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("_catalog.json")).unwrap()).unwrap();
    assert_eq!(cat["tables"][0]["row_count"], 0);

    // Not a store: exit 4, nothing written.
    let o = run(&["export", tmp.path().join("nope").to_str().unwrap(), tmp.path().join("o2").to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(4), "{}", stderr(&o));
    assert!(!tmp.path().join("o2").exists());
}
