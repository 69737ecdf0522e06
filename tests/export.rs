//! `seam export`: point labels of every session that has them, as
//! Hive-partitioned Parquet with a catalog; the static map, lifelong map and
//! change events of the lifelong map; bad table names are usage errors that
//! write nothing; an existing table is only replaced with --overwrite.

mod common;
use arrow_array::{Array, Float32Array, Float64Array, Int32Array, Int64Array, RecordBatch, StringArray};
use common::*;
use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
use seam::change::{Category, ChangeEvent, LifelongMap, MapVoxel, SessionChanges};
use seam::evidence::PointLabels;
use seam::geometry::VoxelKey;
use seam::store::evidence_files::{read_point_labels, write_point_labels};
use seam::store::map_export::z_order;
use seam::store::{
    NewSession, SessionId, Store, StoreError, insert_change_events, insert_file, insert_graph_version, insert_session,
    insert_session_changes, replace_lifelong_map,
};
use std::path::Path;

fn labels(n: usize, seed: i32) -> PointLabels {
    PointLabels {
        keyframe: (0..n as i32).map(|i| i / 100 + seed).collect(),
        point_index: (0..n as i32).map(|i| i % 100).collect(),
        dynamic: (0..n as i32).map(|i| (i + seed) % 5 == 0).collect(),
        eps_l: (0..n).map(|i| 0.1 + (i % 10) as f32 * 0.1).collect(),
    }
}

/// A store with three sessions; the first two have point labels. Returns
/// the writer that made it, still open: reopening a writer right after
/// closing one is racy in a test binary, where another thread's child
/// process may briefly inherit the lock (between its fork and exec).
fn setup(tmp: &Path) -> (std::path::PathBuf, Vec<PointLabels>, Store) {
    let root = tmp.join("site.seam");
    init_store(&root);
    let mut store = Store::open(&root).unwrap();
    let want = vec![labels(250, 1), labels(1234, 2)];
    let mut recs = Vec::new();
    for (i, l) in want.iter().enumerate() {
        recs.push(
            write_point_labels(store.root(), &format!("data/point_labels/session-{:04}.parquet", i + 1), l).unwrap(),
        );
    }
    store
        .transaction(|tx| -> Result<(), StoreError> {
            for i in 0..3 {
                let name = format!("s{}", i + 1);
                let sid = fake_session(tx, &name, 3)?;
                if let Some(rec) = recs.get(i) {
                    insert_file(tx, &root, rec, Some(sid.0))?;
                }
            }
            Ok(())
        })
        .unwrap();
    (root, want, store)
}

fn names(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> =
        std::fs::read_dir(dir).unwrap().flatten().map(|e| e.file_name().to_string_lossy().into_owned()).collect();
    v.sort();
    v
}

/// A session row with no folder behind it, named and hashed `name`.
fn fake_session(tx: &rusqlite::Transaction<'_>, name: &str, keyframes: i64) -> Result<SessionId, StoreError> {
    insert_session(tx, &NewSession { keyframe_count: keyframes, point_count: 1000, ..bare_session(name) })
}

#[test]
fn exports_point_labels_per_session_with_a_catalog() {
    let tmp = tempfile::tempdir().unwrap();
    // A writer holding the store does not stop a read-only export.
    let (root, want, _writer) = setup(tmp.path());
    let out = tmp.path().join("out");
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
    let args = ["export", root.to_str().unwrap(), out.to_str().unwrap(), "--tables", "point_labels", "--overwrite"];
    let o = run(&[&args[..], &["--format", "json"]].concat());
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
    let (root, _, _writer) = setup(tmp.path());
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
    // The default tables: every one, empty, the unpartitioned ones with a
    // file that carries the schema.
    let o = run(&["export", root.to_str().unwrap(), out.to_str().unwrap(), "--quiet"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(out.join("point_labels").is_dir());
    assert!(names(&out.join("point_labels")).is_empty());
    assert_eq!(
        names(&out),
        ["_catalog.json", "changes", "keyframes", "loop_edges", "map_voxels", "point_labels", "sessions"]
    );
    assert_eq!(names(&out.join("sessions")), ["part-0.parquet"]);
    let cat: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("_catalog.json")).unwrap()).unwrap();
    let order: Vec<&str> = cat["tables"].as_array().unwrap().iter().map(|t| t["name"].as_str().unwrap()).collect();
    assert_eq!(order, ["sessions", "keyframes", "loop_edges", "map_voxels", "changes", "point_labels"]);
    assert!(cat["tables"].as_array().unwrap().iter().all(|t| t["row_count"] == 0), "{cat}");
    assert_eq!(table(&cat, "sessions")["geometry"]["geometry_types"], serde_json::json!(["LineString Z"]));
    assert_eq!(table(&cat, "sessions")["geometry"]["crs"]["type"], "EngineeringCRS");
    assert_eq!(table(&cat, "point_labels")["format"], "Parquet");

    // Not a store: exit 4, nothing written.
    let o = run(&["export", tmp.path().join("nope").to_str().unwrap(), tmp.path().join("o2").to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(4), "{}", stderr(&o));
    assert!(!tmp.path().join("o2").exists());
}

// ---------------------------------------------------------------------------
// The lifelong map: static_map, lifelong_map, changes

const VOXEL_M: f64 = 0.2;
/// ε_g by `i % 9`: 0.5 itself is not static (the static map is ε_g < 0.5).
const EPS_G: [f32; 9] = [0.1, 0.2, 0.3, 0.4, 0.49, 0.5, 0.6, 0.75, 0.9];
const VOXELS: usize = 300;
/// Change events of sessions 2 and 3; session 1 (the first) has none.
const EVENTS: [usize; 2] = [40, 25];

fn map_voxel(i: usize) -> MapVoxel {
    let key = [(i % 10) as i32 - 5, ((i / 10) % 10) as i32 - 5, (i / 100) as i32];
    let s = 1 + (i % 3) as i64;
    MapVoxel {
        voxel_id: 1000 + 3 * i as i64,
        key: VoxelKey(key),
        xyz_m: key.map(|k| k as f64 * VOXEL_M + 0.05 + (i % 7) as f64 * 0.01),
        eps_g: EPS_G[i % 9],
        eps_l: (i % 10) as f32 * 0.1,
        points: i as u32 + 1,
        first_session: s,
        last_seen_session: 3,
        category: Category::ALL[i % 6],
        category_session: s,
        owner_session: s,
        owner_keyframe: (i % 7) as u32,
        spread_m2: seam::geometry::UNKNOWN_SPREAD,
    }
}

/// Event `k` of session `s`: every fourth is a voxel new to the map.
fn change_event(s: i64, k: usize) -> ChangeEvent {
    ChangeEvent {
        session_id: s,
        voxel_id: 1000 + k as i64,
        xyz_m: [k as f64 * 0.37 - 4.0, (k % 5) as f64 * -1.3, 0.1 * s as f64],
        category: Category::ALL[1 + k % 5],
        eps_g_before: (!k.is_multiple_of(4)).then_some(0.3 + (k % 3) as f32 * 0.1),
        eps_g_after: 0.2 + (k % 6) as f32 * 0.1,
    }
}

/// A store with three sessions and their graph versions, a lifelong map of
/// [`VOXELS`] voxels on session 3's version, and [`EVENTS`] change events;
/// and its writer, still open (see [`setup`]).
fn setup_lifelong(tmp: &Path) -> (std::path::PathBuf, Store) {
    setup_lifelong_in(tmp, None)
}

/// [`setup_lifelong`] in a store of CRS `crs` (`None`: local).
fn setup_lifelong_in(tmp: &Path, crs: Option<&str>) -> (std::path::PathBuf, Store) {
    let root = tmp.join("site.seam");
    match crs {
        Some(c) => assert!(run(&["init", root.to_str().unwrap(), "--crs", c]).status.success()),
        None => init_store(&root),
    }
    let mut store = Store::open(&root).unwrap();
    store
        .transaction(|tx| -> Result<(), StoreError> {
            let mut last_version = 0;
            for i in 1..=3 {
                let name = format!("s{i}");
                let sid = fake_session(tx, &name, 12)?;
                last_version = insert_graph_version(tx, sid, "session", "{}", None, &[], &[])?;
                let events: Vec<ChangeEvent> =
                    (0..if i == 1 { 0 } else { EVENTS[i as usize - 2] }).map(|k| change_event(i, k)).collect();
                insert_change_events(tx, &events)?;
                let c = SessionChanges { events: events.len(), lifelong_voxels: VOXELS, ..SessionChanges::default() };
                insert_session_changes(tx, sid, last_version, &c)?;
            }
            let (map, merged) = LifelongMap::from_voxels((0..VOXELS).map(map_voxel).collect(), VOXEL_M);
            assert_eq!(merged, 0);
            replace_lifelong_map(tx, &map, last_version, SessionId(3))
        })
        .unwrap();
    (root, store)
}

/// A Parquet file's Arrow schema and its rows as one batch (files here are
/// small: one batch holds them).
fn read_parquet(path: &Path) -> (arrow_schema::SchemaRef, Option<RecordBatch>) {
    let b = ParquetRecordBatchReaderBuilder::try_new(std::fs::File::open(path).unwrap()).unwrap();
    let schema = b.schema().clone();
    let batches: Vec<RecordBatch> = b.with_batch_size(1 << 20).build().unwrap().map(|b| b.unwrap()).collect();
    assert!(batches.len() <= 1, "{}", batches.len());
    (schema, batches.into_iter().next())
}

fn columns(schema: &arrow_schema::Schema) -> Vec<String> {
    let type_name = |t: &arrow_schema::DataType| match t {
        arrow_schema::DataType::Struct(f) => {
            format!("Struct<{}>", f.iter().map(|c| c.name().as_str()).collect::<Vec<_>>().join(","))
        }
        t => t.to_string(),
    };
    schema.fields().iter().map(|f| format!("{}:{}:{}", f.name(), type_name(f.data_type()), f.is_nullable())).collect()
}

fn col<'a, T: 'static>(b: &'a RecordBatch, name: &str) -> &'a T {
    b.column_by_name(name).unwrap_or_else(|| panic!("no column {name}")).as_any().downcast_ref::<T>().unwrap()
}

const MAP_COLUMNS: [&str; 18] = [
    "voxel_id:Int64:false",
    "kx:Int32:false",
    "ky:Int32:false",
    "kz:Int32:false",
    "x_m:Float64:false",
    "y_m:Float64:false",
    "z_m:Float64:false",
    "eps_g:Float32:false",
    "eps_l:Float32:false",
    "points:Int32:false",
    "first_session:Int32:false",
    "last_seen_session:Int32:false",
    "category:Utf8:false",
    "category_session:Int32:false",
    "owner_session:Int32:false",
    "owner_keyframe:Int32:false",
    "geometry:Binary:false",
    "bbox:Struct<xmin,ymin,xmax,ymax>:false",
];

const CHANGE_COLUMNS: [&str; 11] = [
    "event_id:Int64:false",
    "voxel_id:Int64:false",
    "x_m:Float64:false",
    "y_m:Float64:false",
    "z_m:Float64:false",
    "category:Utf8:false",
    "eps_g_before:Float32:true",
    "eps_g_after:Float32:false",
    "volume_m3:Float64:false",
    "geometry:Binary:false",
    "bbox:Struct<xmin,ymin,xmax,ymax>:false",
];

/// The voxel ids of a map file, checking the rows are in spatial order.
fn map_ids_in_spatial_order(b: &RecordBatch) -> Vec<i64> {
    let (kx, ky, kz) = (col::<Int32Array>(b, "kx"), col::<Int32Array>(b, "ky"), col::<Int32Array>(b, "kz"));
    let ids = col::<Int64Array>(b, "voxel_id");
    let codes: Vec<(u64, i64)> =
        (0..b.num_rows()).map(|r| (z_order([kx.value(r), ky.value(r), kz.value(r)]), ids.value(r))).collect();
    assert!(codes.windows(2).all(|w| w[0] < w[1]), "rows are sorted by z-order, then id");
    codes.iter().map(|c| c.1).collect()
}

fn catalog(out: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(out.join("_catalog.json")).unwrap()).unwrap()
}

fn table<'a>(cat: &'a serde_json::Value, name: &str) -> &'a serde_json::Value {
    cat["tables"].as_array().unwrap().iter().find(|t| t["name"] == name).unwrap_or_else(|| panic!("{name}: {cat}"))
}

#[test]
fn exports_static_map_lifelong_map_and_changes() {
    let tmp = tempfile::tempdir().unwrap();
    let (root, _writer) = setup_lifelong(tmp.path());
    let out = tmp.path().join("out");
    let o =
        run(&["export", root.to_str().unwrap(), out.to_str().unwrap(), "--tables", "static_map,lifelong_map,changes"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = stdout(&o);
    assert!(text.starts_with("table"), "{text}");
    assert!(text.contains("lifelong_map") && text.contains("static_map"), "{text}");

    assert_eq!(names(&out), ["_catalog.json", "changes", "lifelong_map", "static_map"], "only the outputs");
    let all: Vec<MapVoxel> = (0..VOXELS).map(map_voxel).collect();
    let statics: Vec<&MapVoxel> = all.iter().filter(|v| v.eps_g < 0.5).collect();
    assert_eq!(statics.len(), VOXELS / 9 * 5 + 3, "fixture: ε_g 0.5 itself is not static");

    // The lifelong map: every voxel, the documented columns, spatial order.
    assert_eq!(names(&out.join("lifelong_map")), ["part-0.parquet"]);
    let (schema, b) = read_parquet(&out.join("lifelong_map/part-0.parquet"));
    assert_eq!(columns(&schema), MAP_COLUMNS);
    let b = b.unwrap();
    assert_eq!(b.num_rows(), VOXELS);
    let mut ids = map_ids_in_spatial_order(&b);
    ids.sort();
    assert_eq!(ids, all.iter().map(|v| v.voxel_id).collect::<Vec<_>>());

    // One known voxel, every field.
    let want = map_voxel(123);
    let r = (0..b.num_rows()).find(|&r| col::<Int64Array>(&b, "voxel_id").value(r) == want.voxel_id).unwrap();
    let i32s = |c: &str| col::<Int32Array>(&b, c).value(r);
    let f64s = |c: &str| col::<Float64Array>(&b, c).value(r);
    let f32s = |c: &str| col::<Float32Array>(&b, c).value(r);
    assert_eq!([i32s("kx"), i32s("ky"), i32s("kz")], want.key.0);
    assert_eq!([f64s("x_m"), f64s("y_m"), f64s("z_m")], want.xyz_m, "centroids are float64, unrounded");
    assert_eq!((f32s("eps_g"), f32s("eps_l")), (want.eps_g, want.eps_l));
    assert_eq!(i32s("points") as u32, want.points);
    assert_eq!(
        ["first_session", "last_seen_session", "category_session", "owner_session"].map(|c| i32s(c) as i64),
        [want.first_session, want.last_seen_session, want.category_session, want.owner_session]
    );
    assert_eq!(i32s("owner_keyframe") as u32, want.owner_keyframe);
    assert_eq!(col::<StringArray>(&b, "category").value(r), want.category.as_str());

    // The static map: exactly the voxels with ε_g < 0.5.
    let (schema, b) = read_parquet(&out.join("static_map/part-0.parquet"));
    assert_eq!(columns(&schema), MAP_COLUMNS);
    let b = b.unwrap();
    let mut ids = map_ids_in_spatial_order(&b);
    ids.sort();
    assert_eq!(ids, statics.iter().map(|v| v.voxel_id).collect::<Vec<_>>());
    assert!(col::<Float32Array>(&b, "eps_g").values().iter().all(|&e| e < 0.5));

    // Changes: one partition per session change detection ran for, the
    // first session's empty but with the schema; ids follow ingest order.
    assert_eq!(names(&out.join("changes")), ["session=1", "session=2", "session=3"]);
    let mut next_id = 1;
    for (s, n) in [(1, 0), (2, EVENTS[0]), (3, EVENTS[1])] {
        let (schema, b) = read_parquet(&out.join(format!("changes/session={s}/part-0.parquet")));
        assert_eq!(columns(&schema), CHANGE_COLUMNS, "session {s}");
        let Some(b) = b else {
            assert_eq!(n, 0, "session {s}");
            continue;
        };
        assert_eq!(b.num_rows(), n, "session {s}");
        let ids = col::<Int64Array>(&b, "event_id");
        let (x, y, z) =
            (col::<Float64Array>(&b, "x_m"), col::<Float64Array>(&b, "y_m"), col::<Float64Array>(&b, "z_m"));
        let key = |r: usize| [x.value(r), y.value(r), z.value(r)].map(|c| (c / VOXEL_M).floor() as i32);
        assert!((1..n).all(|r| (z_order(key(r - 1)), ids.value(r - 1)) < (z_order(key(r)), ids.value(r))));
        let before = col::<Float32Array>(&b, "eps_g_before");
        assert_eq!(before.null_count(), n.div_ceil(4), "session {s}: every fourth event is a new voxel");
        for r in 0..n {
            let k = (ids.value(r) - next_id) as usize;
            let want = change_event(s, k);
            assert_eq!(col::<Int64Array>(&b, "voxel_id").value(r), want.voxel_id);
            assert_eq!([x.value(r), y.value(r), z.value(r)], want.xyz_m);
            assert_eq!(col::<StringArray>(&b, "category").value(r), want.category.as_str());
            assert_eq!(before.is_valid(r).then(|| before.value(r)), want.eps_g_before, "session {s} event {k}");
            assert_eq!(col::<Float32Array>(&b, "eps_g_after").value(r), want.eps_g_after);
        }
        next_id += n as i64;
    }

    // The catalog describes each table: rows, columns, frame, filter.
    let cat = catalog(&out);
    let order: Vec<&str> = cat["tables"].as_array().unwrap().iter().map(|t| t["name"].as_str().unwrap()).collect();
    assert_eq!(order, ["changes", "static_map", "lifelong_map"]);
    let st = table(&cat, "static_map");
    assert_eq!(st["row_count"], statics.len());
    assert_eq!(st["filter"], "eps_g < 0.5");
    assert_eq!(st["partition_by"].as_array().unwrap().len(), 0);
    assert_eq!(st["partitions"][0]["path"], "static_map/part-0.parquet");
    assert_eq!(st["partitions"][0]["graph_version"], 3);
    let lm = table(&cat, "lifelong_map");
    assert_eq!(lm["row_count"], VOXELS);
    assert!(lm.get("filter").is_none(), "{lm}");
    assert_eq!(lm["frame"], serde_json::json!({"name": "world", "crs": "local", "graph_version": 3, "voxel_m": 0.2}));
    let cols: Vec<String> = lm["columns"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| format!("{}:{}:{}", c["name"].as_str().unwrap(), c["type"].as_str().unwrap(), c["nullable"]))
        .collect();
    assert_eq!(cols[0], "voxel_id:int64:false");
    assert_eq!(cols[4], "x_m:float64:false");
    assert_eq!(cols[12], "category:string:false");
    assert!(lm["columns"][7]["description"].as_str().unwrap().contains("ephemerality"), "{lm}");
    let ch = table(&cat, "changes");
    assert_eq!(ch["row_count"], EVENTS[0] + EVENTS[1]);
    assert_eq!(ch["partition_by"], serde_json::json!(["session"]));
    assert_eq!(ch["frame"]["graph_version"], serde_json::Value::Null, "each partition names its own");
    let parts = ch["partitions"].as_array().unwrap();
    assert_eq!(parts.iter().map(|p| p["row_count"].as_u64().unwrap()).collect::<Vec<_>>(), [0, 40, 25]);
    assert_eq!(parts[1]["session_name"], "s2");
    assert_eq!(parts[1]["graph_version"], 2);
    assert_eq!(parts[2]["path"], "changes/session=3/part-0.parquet");
    let c = &ch["columns"][6];
    assert_eq!(
        (c["name"].as_str(), c["type"].as_str(), c["nullable"].as_bool()),
        (Some("eps_g_before"), Some("float32"), Some(true))
    );

    // Existing tables are refused without --overwrite, nothing touched.
    let before = snapshot_files(&out);
    let o = run(&["export", root.to_str().unwrap(), out.to_str().unwrap(), "--tables", "lifelong_map"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("lifelong_map") && stderr(&o).contains("--overwrite"), "{}", stderr(&o));
    assert_eq!(snapshot_files(&out), before);

    // With it and another threshold, only static_map is replaced; the catalog
    // keeps the other tables.
    let config = tmp.path().join("seam.toml");
    std::fs::write(&config, "[change]\nstatic_threshold = 0.3\n").unwrap();
    let args =
        ["export", root.to_str().unwrap(), out.to_str().unwrap(), "--tables", "static_map", "--overwrite", "--quiet"];
    let o = run(&[&args[..], &["--config", config.to_str().unwrap(), "--format", "json"]].concat());
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    let below = all.iter().filter(|v| (v.eps_g as f64) < 0.3).count();
    assert_eq!(v["partitions"].as_array().unwrap().len(), 1, "{v}");
    assert_eq!(v["partitions"][0]["rows"], below);
    assert_eq!(v["partitions"][0]["session"], serde_json::Value::Null);
    let (_, b) = read_parquet(&out.join("static_map/part-0.parquet"));
    assert_eq!(b.unwrap().num_rows(), below);
    let cat = catalog(&out);
    assert_eq!(cat["tables"].as_array().unwrap().len(), 3);
    assert_eq!(table(&cat, "static_map")["filter"], "eps_g < 0.3");
    assert_eq!(table(&cat, "changes")["row_count"], EVENTS[0] + EVENTS[1]);
    assert_eq!(names(&out), ["_catalog.json", "changes", "lifelong_map", "static_map"], "no staging folder left");
}

#[test]
fn store_without_a_lifelong_map_exports_empty_tables_with_their_schema() {
    let tmp = tempfile::tempdir().unwrap();
    let (root, _, _writer) = setup(tmp.path());
    let out = tmp.path().join("out");
    let tables = "point_labels,static_map,lifelong_map,changes";
    let o = run(&["export", root.to_str().unwrap(), out.to_str().unwrap(), "--tables", tables]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("no lifelong map yet"), "{}", stderr(&o));
    for t in ["static_map", "lifelong_map"] {
        let (schema, b) = read_parquet(&out.join(format!("{t}/part-0.parquet")));
        assert_eq!(columns(&schema), MAP_COLUMNS, "{t}");
        assert!(b.is_none_or(|b| b.num_rows() == 0), "{t}");
    }
    // No session went through change detection: no partition yet.
    assert!(names(&out.join("changes")).is_empty());
    let cat = catalog(&out);
    let order: Vec<&str> = cat["tables"].as_array().unwrap().iter().map(|t| t["name"].as_str().unwrap()).collect();
    assert_eq!(order, ["changes", "point_labels", "static_map", "lifelong_map"]);
    assert_eq!(table(&cat, "point_labels")["row_count"], 250 + 1234);
    for t in ["static_map", "lifelong_map", "changes"] {
        assert_eq!(table(&cat, t)["row_count"], 0, "{t}");
        assert_eq!(table(&cat, t)["frame"]["graph_version"], serde_json::Value::Null, "{t}");
    }
    assert_eq!(table(&cat, "changes")["columns"].as_array().unwrap().len(), CHANGE_COLUMNS.len());
}

#[test]
fn unknown_map_table_names_every_known_table() {
    let tmp = tempfile::tempdir().unwrap();
    let (root, _writer) = setup_lifelong(tmp.path());
    let out = tmp.path().join("out");
    let o = run(&["export", root.to_str().unwrap(), out.to_str().unwrap(), "--tables", "static_map,change"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    let err = stderr(&o);
    assert!(err.contains("\"change\""), "{err}");
    let known = "sessions, keyframes, loop_edges, map_voxels, changes, point_labels, static_map, lifelong_map";
    assert!(err.contains(&format!("known tables: {known}")), "{err}");
    assert!(!out.exists(), "nothing is written");
}

/// Two simulated sessions through `seam ingest`, then every table: the
/// export holds what the store holds. Before the ingest has a changes step
/// the map is empty and this checks the empty export; after, the real one.
#[test]
#[cfg_attr(debug_assertions, ignore = "release only: cargo test --release")]
fn ingested_site_exports_what_the_store_holds() {
    let tmp = tempfile::tempdir().unwrap();
    let summary = simulate(&tmp.path().join("sim"), 2, 8, 7, &[]);
    let root = tmp.path().join("site.seam");
    init_store(&root);
    ingest_all(&root, &summary);
    let out = tmp.path().join("out");
    let tables = "point_labels,static_map,lifelong_map,changes,sessions,keyframes,loop_edges";
    let o = run(&["export", root.to_str().unwrap(), out.to_str().unwrap(), "--tables", tables, "--quiet"]);
    assert!(o.status.success(), "{}", stderr(&o));

    // Keyframes hold exactly the poses `seam poses` prints, per session.
    let o = run(&["poses", root.to_str().unwrap(), "--format", "json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let poses: Vec<serde_json::Value> = serde_json::from_str(&stdout(&o)).unwrap();
    let mut seen = 0;
    for s in [1, 2] {
        let (_, b) = read_parquet(&out.join(format!("keyframes/session={s}/part-0.parquet")));
        let b = b.unwrap();
        let want: Vec<&serde_json::Value> = poses.iter().filter(|p| p["session"] == s).collect();
        assert_eq!(b.num_rows(), want.len(), "session {s}");
        for (r, p) in want.iter().enumerate() {
            assert_eq!(i64::from(col::<Int32Array>(&b, "keyframe_index").value(r)), p["keyframe"].as_i64().unwrap());
            for c in ["x_m", "y_m", "z_m", "qx", "qy", "qz", "qw"] {
                let got = col::<Float64Array>(&b, c).value(r);
                assert!((got - p[c].as_f64().unwrap()).abs() < 1e-9, "session {s} row {r} {c}: {got} vs {}", p[c]);
            }
        }
        seen += want.len();
    }
    assert_eq!(seen, poses.len());
    let (_, b) = read_parquet(&out.join("sessions/part-0.parquet"));
    let b = b.unwrap();
    assert_eq!(col::<Int64Array>(&b, "session_id").values().to_vec(), [1, 2]);
    assert_eq!(col::<StringArray>(&b, "status").value(1), "complete");
    assert_eq!(b.column_by_name("geometry").unwrap().null_count(), 0, "both sessions have trajectories");

    let conn = rusqlite::Connection::open_with_flags(root.join("seam.db"), rusqlite::OpenFlags::SQLITE_OPEN_READ_ONLY)
        .unwrap();
    let count = |q: &str| conn.query_row(q, [], |r| r.get::<_, i64>(0)).unwrap() as usize;
    let rows = |p: &Path| read_parquet(p).1.map_or(0, |b| b.num_rows());
    let lifelong = count("SELECT count(*) FROM map_voxels");
    let statics = count("SELECT count(*) FROM map_voxels WHERE eps_g < 0.5");
    assert_eq!(rows(&out.join("lifelong_map/part-0.parquet")), lifelong);
    assert_eq!(rows(&out.join("static_map/part-0.parquet")), statics);
    let mut st =
        conn.prepare("SELECT session_id, events, lifelong_voxels, static_voxels FROM session_changes").unwrap();
    let summaries: Vec<(i64, usize, usize, usize)> = st
        .query_map([], |r| {
            Ok((r.get(0)?, r.get::<_, i64>(1)? as usize, r.get::<_, i64>(2)? as usize, r.get::<_, i64>(3)? as usize))
        })
        .unwrap()
        .map(|r| r.unwrap())
        .collect();
    let cat = catalog(&out);
    assert_eq!(table(&cat, "changes")["partitions"].as_array().unwrap().len(), summaries.len());
    for &(s, events, _, _) in &summaries {
        let want = count(&format!("SELECT count(*) FROM change_events WHERE session_id = {s}"));
        assert_eq!(want, events, "session {s}: session_changes.events");
        assert_eq!(rows(&out.join(format!("changes/session={s}/part-0.parquet"))), events, "session {s}");
    }
    // The newest session's summary counted the map as exported.
    if let Some(&(_, _, lifelong_voxels, static_voxels)) = summaries.last() {
        assert_eq!((lifelong, statics), (lifelong_voxels, static_voxels));
        assert!(lifelong > 0);
    } else {
        eprintln!("notice: ingest has no changes step yet; checked the empty export only");
        assert_eq!(lifelong, 0);
    }
}

// ---------------------------------------------------------------------------
// GeoParquet metadata, LAS, bad outputs

/// The `geo` key of a Parquet file's key-value metadata, parsed.
fn geo_of(path: &Path) -> serde_json::Value {
    let b = ParquetRecordBatchReaderBuilder::try_new(std::fs::File::open(path).unwrap()).unwrap();
    let kv = b.metadata().file_metadata().key_value_metadata().cloned().unwrap_or_default();
    let geo = kv.iter().find(|k| k.key == "geo").unwrap_or_else(|| panic!("{}: no geo key", path.display()));
    serde_json::from_str(geo.value.as_deref().unwrap()).unwrap()
}

#[test]
fn map_tables_are_geoparquet_in_the_stores_crs() {
    let tmp = tempfile::tempdir().unwrap();
    let (root, _writer) = setup_lifelong_in(tmp.path(), Some("EPSG:32652"));
    let out = tmp.path().join("out");
    let o = run(&["export", root.to_str().unwrap(), out.to_str().unwrap(), "--tables", "map_voxels,changes"]);
    assert!(o.status.success(), "{}", stderr(&o));

    let path = out.join("map_voxels/part-0.parquet");
    let geo = geo_of(&path);
    assert_eq!(geo["version"], "1.1.0");
    assert_eq!(geo["primary_column"], "geometry");
    let g = &geo["columns"]["geometry"];
    assert_eq!(g["encoding"], "WKB");
    assert_eq!(g["geometry_types"], serde_json::json!(["Point Z"]));
    assert_eq!(g["crs"]["id"], serde_json::json!({"authority": "EPSG", "code": 32652}));
    assert_eq!(g["crs"]["type"], "ProjectedCRS");
    assert_eq!(g["covering"]["bbox"]["xmin"], serde_json::json!(["bbox", "xmin"]));
    let (_, b) = read_parquet(&path);
    let b = b.unwrap();
    let (x, y, z) = (col::<Float64Array>(&b, "x_m"), col::<Float64Array>(&b, "y_m"), col::<Float64Array>(&b, "z_m"));
    let wkb = col::<arrow_array::BinaryArray>(&b, "geometry");
    let bbox = col::<arrow_array::StructArray>(&b, "bbox");
    let bcol = |n: &str| bbox.column_by_name(n).unwrap().as_any().downcast_ref::<Float64Array>().unwrap().clone();
    let (xmin, ymin, xmax, ymax) = (bcol("xmin"), bcol("ymin"), bcol("xmax"), bcol("ymax"));
    for r in 0..b.num_rows() {
        let p = [x.value(r), y.value(r), z.value(r)];
        assert_eq!(wkb.value(r), seam::store::geoparquet::wkb_point_z(p), "row {r}");
        assert_eq!([xmin.value(r), ymin.value(r), xmax.value(r), ymax.value(r)], [p[0], p[1], p[0], p[1]]);
    }
    // The file bbox encloses exactly the rows.
    let fb: Vec<f64> = serde_json::from_value(g["bbox"].clone()).unwrap();
    let min = |a: &Float64Array| a.values().iter().copied().fold(f64::INFINITY, f64::min);
    let max = |a: &Float64Array| a.values().iter().copied().fold(f64::NEG_INFINITY, f64::max);
    // (serde_json's default parser may be an ulp off; the text is exact.)
    let want = [min(x), min(y), min(z), max(x), max(y), max(z)];
    assert!(fb.iter().zip(want).all(|(a, b)| (a - b).abs() < 1e-12), "{fb:?} vs {want:?}");
    // ~100k-row groups are the writer's; this file is one.
    let reader = ParquetRecordBatchReaderBuilder::try_new(std::fs::File::open(&path).unwrap()).unwrap();
    assert_eq!(reader.metadata().num_row_groups(), 1);
    let cc = reader.metadata().row_group(0).column(0).compression();
    assert!(matches!(cc, parquet::basic::Compression::ZSTD(_)), "{cc:?}");

    // Each changes partition: volume_m3 is the voxel, the catalog lists units.
    let (_, b) = read_parquet(&out.join("changes/session=2/part-0.parquet"));
    let v = col::<Float64Array>(&b.unwrap(), "volume_m3").clone();
    assert!(v.values().iter().all(|&m| (m - VOXEL_M.powi(3)).abs() < 1e-12));
    let cat = catalog(&out);
    let ch = table(&cat, "changes");
    assert_eq!(ch["format"], "GeoParquet 1.1.0");
    let unit = |n: &str| ch["columns"].as_array().unwrap().iter().find(|c| c["name"] == n).unwrap()["unit"].clone();
    assert_eq!((unit("volume_m3"), unit("x_m"), unit("eps_g_after")), ("m^3".into(), "m".into(), "1".into()));
    assert_eq!(ch["geometry"]["crs"]["name"], "WGS 84 / UTM zone 52N");
    assert_eq!(ch["geometry"]["crs_complete"], true);
    assert_eq!(ch["partitions"][1]["bbox"].as_array().unwrap().len(), 6);
    assert_eq!(cat["crs"], "EPSG:32652");
}

#[test]
fn las_export_carries_eps_g_and_change_class_as_extra_bytes() {
    let tmp = tempfile::tempdir().unwrap();
    let (root, _writer) = setup_lifelong_in(tmp.path(), Some("EPSG:32652"));
    let out = tmp.path().join("out");
    let args = ["export", root.to_str().unwrap(), out.to_str().unwrap(), "--tables", "map_voxels,static_map", "--las"];
    let o = run(&args);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(names(&out.join("las")), ["lifelong_map.laz", "static_map.laz"]);

    // LAS point i is map_voxels row i; static_map.laz is its ε_g < 0.5 rows.
    let (_, b) = read_parquet(&out.join("map_voxels/part-0.parquet"));
    let b = b.unwrap();
    let eps = col::<Float32Array>(&b, "eps_g");
    let cats = col::<StringArray>(&b, "category");
    let x = col::<Float64Array>(&b, "x_m");
    for (file, only_static) in [("lifelong_map.laz", false), ("static_map.laz", true)] {
        let mut r = las::Reader::from_path(out.join("las").join(file)).unwrap();
        let h = r.header().clone();
        assert_eq!((h.version().major, h.version().minor), (1, 4));
        assert!(h.has_wkt_crs(), "LAS 1.4 point format 6 sets the WKT bit");
        let wkt = h.all_vlrs().find(|v| v.user_id == "LASF_Projection" && v.record_id == 2112).unwrap();
        assert!(String::from_utf8_lossy(&wkt.data).contains("AUTHORITY[\"EPSG\",\"32652\"]]"));
        let eb = h.all_vlrs().find(|v| v.user_id == "LASF_Spec" && v.record_id == 4).unwrap();
        assert_eq!(eb.data.len(), 2 * 192);
        assert_eq!(&eb.data[4..9], b"eps_g");
        assert_eq!(&eb.data[192 + 4..192 + 16], b"change_class");
        let codes = h.all_vlrs().find(|v| v.user_id == "seam" && v.record_id == 1).unwrap();
        assert!(String::from_utf8_lossy(&codes.data).contains("3 = deleted_non_overlap"));
        let rows: Vec<usize> = (0..b.num_rows()).filter(|&i| !only_static || eps.value(i) < 0.5).collect();
        assert_eq!(h.number_of_points(), rows.len() as u64, "{file}");
        let points: Vec<las::Point> = r.read_all().unwrap().points().map(|p| p.unwrap()).collect();
        for (p, &i) in points.iter().zip(&rows) {
            assert_eq!(f32::from_le_bytes(p.extra_bytes[..4].try_into().unwrap()), eps.value(i), "{file} row {i}");
            let code = Category::ALL.iter().position(|c| c.as_str() == cats.value(i)).unwrap() as u8;
            assert_eq!(p.extra_bytes[4], code, "{file} row {i}");
            assert!((p.x - x.value(i)).abs() <= 0.0005 + 1e-9, "{file} row {i}: {} vs {}", p.x, x.value(i));
        }
    }
    let cat = catalog(&out);
    assert_eq!(cat["las"]["files"][0]["name"], "static_map");
    assert_eq!(cat["las"]["files"][1]["point_count"], VOXELS);
    assert_eq!(cat["las"]["extra_bytes"][1]["codes"]["5"], "emerged_non_overlap");

    // pyarrow, DuckDB and laspy agree (where python3 and the modules exist).
    run_client_check(&out, None);

    // OUT/las exists: refused without --overwrite, nothing touched.
    let before = snapshot_files(&out);
    let o = run(&["export", root.to_str().unwrap(), out.to_str().unwrap(), "--tables", "sessions", "--las"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("las") && stderr(&o).contains("--overwrite"), "{}", stderr(&o));
    assert_eq!(snapshot_files(&out), before);
}

#[test]
fn bad_outputs_are_refused_before_anything_is_written() {
    let tmp = tempfile::tempdir().unwrap();
    let (root, writer) = setup_lifelong(tmp.path());
    drop(writer);
    let before = store_state(&root);

    // OUT is a file: usage error, the file and the store untouched.
    let file = tmp.path().join("out.txt");
    std::fs::write(&file, b"not a folder").unwrap();
    let o = run(&["export", root.to_str().unwrap(), file.to_str().unwrap(), "--las"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("not a folder"), "{}", stderr(&o));
    assert_eq!(std::fs::read(&file).unwrap(), b"not a folder");

    // An unknown table: exit 2 naming every known one, OUT not created.
    let out = tmp.path().join("out");
    let o = run(&["export", root.to_str().unwrap(), out.to_str().unwrap(), "--tables", "sessions,voxels"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("\"voxels\"") && stderr(&o).contains("map_voxels, changes"), "{}", stderr(&o));
    assert!(!out.exists());

    // --las-uncompressed without --las: clap refuses it.
    let o = run(&["export", root.to_str().unwrap(), out.to_str().unwrap(), "--las-uncompressed"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(!out.exists());

    // A missing store: exit 4, OUT not created.
    let o = run(&["export", tmp.path().join("missing.seam").to_str().unwrap(), out.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(4), "{}", stderr(&o));
    assert!(!out.exists());
    assert_same_state(&before, &store_state(&root), "after refused exports");

    // And a good export leaves the store as it was too.
    let o = run(&["export", root.to_str().unwrap(), out.to_str().unwrap(), "--las", "--las-uncompressed", "--quiet"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(names(&out.join("las")), ["lifelong_map.las", "static_map.las"]);
    assert_same_state(&before, &store_state(&root), "after an export");
}
