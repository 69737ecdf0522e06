//! The query language end to end.
//!
//! - A synthetic store with hand-placed rows where every answer is known:
//!   box, ball and polygon boundaries, session windows by name, number and
//!   date, filters, pipeline stages, the aggregate subjects; and random
//!   boxes checked against a brute-force filter of the rows inserted.
//! - Errors: spans, carets and did-you-mean; ≥ 1,000 generated malformed
//!   queries never panic and always point inside the query.
//! - The `seam query` and `seam zones` commands: formats, Parquet, `--explain`,
//!   exit codes, a store left unchanged.
//! - Every file in `queries/` run through the binary on one simulated store
//!   and checked against SQL written here (release only).

mod common;
use common::*;
use rusqlite::types::Value;
use seam::change::{Category, ChangeEvent, LifelongMap, MapVoxel, SessionChanges};
use seam::geometry::VoxelKey;
use seam::geometry::polygon::Polygon;
use seam::query::{self, Catalog, QueryError, QueryResult};
use seam::store::{
    self, InitOptions, NewSession, SessionId, Store, StoreError, WorldBox, ZoneShape, insert_change_events,
    insert_graph_version, insert_session, insert_session_changes, insert_zone, replace_lifelong_map,
};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

// ---------------------------------------------------------------------------
// The synthetic store

const VOXEL_M: f64 = 0.2;
/// Sessions: name and date. `north` is number 4 and shares its day with s3.
const SESSIONS: [(&str, &str); 5] =
    [("s1", "2026-01-10"), ("s2", "2026-02-10"), ("s3", "2026-03-10"), ("north", "2026-03-10"), ("s5", "2026-04-02")];
const TRIANGLE: &str = "POLYGON((100 0, 110 0, 100 10))";

/// Every change event inserted, in order: event_id = index + 1.
fn truth_events() -> Vec<ChangeEvent> {
    let ev = |s: i64, xyz: [f64; 3], c: Category, before: Option<f32>, after: f32| ChangeEvent {
        session_id: s,
        voxel_id: 0,
        xyz_m: xyz,
        category: c,
        eps_g_before: before,
        eps_g_after: after,
    };
    let mut out = Vec::new();
    // Line A through Tower B (0..10 × 0..2 × 0..2): x = 0.25 .. 19.75.
    for k in 0..40usize {
        let before = (!k.is_multiple_of(4)).then_some(0.1 + (k % 5) as f32 * 0.1);
        out.push(ev(
            2 + (k % 4) as i64,
            [k as f64 * 0.5 + 0.25, 1.0, 1.0],
            Category::ALL[1 + k % 5],
            before,
            0.1 + (k % 9) as f32 * 0.1,
        ));
    }
    // Tower B's corner exactly (inside), and just past it (outside).
    out.push(ev(4, [10.0, 2.0, 2.0], Category::Coexist, Some(0.5), 0.3));
    out.push(ev(4, [10.0001, 2.0, 2.0], Category::Coexist, Some(0.5), 0.3));
    // Around (50, 50, 5) along x: 0, 0.5, 0.99, 1 (on the sphere), 1.01, 2.
    for dx in [0.0, 0.5, 0.99, 1.0, 1.01, 2.0] {
        out.push(ev(2, [50.0 + dx, 50.0, 5.0], Category::EmergedOverlap, None, 0.6));
    }
    // The triangle zone: inside, inside, in its box but not in it, above it.
    for p in [[101.0, 1.0, 1.0], [104.0, 4.0, 1.0], [106.0, 6.0, 1.0], [101.0, 1.0, 6.0]] {
        out.push(ev(3, p, Category::DeletedOverlap, Some(0.2), 0.45));
    }
    // Random events far from the above, for the brute-force comparison.
    let mut rng = Rng(0x5eed_1234);
    for _ in 0..3000 {
        let p = [200.0 + rng.f64() * 30.0, 200.0 + rng.f64() * 30.0, rng.f64() * 6.0 - 1.0];
        let before = (!rng.next().is_multiple_of(3)).then(|| 0.1 + rng.f64() as f32 * 0.8);
        out.push(ev(
            2 + (rng.next() % 4) as i64,
            p,
            Category::ALL[1 + (rng.next() % 5) as usize],
            before,
            0.1 + rng.f64() as f32 * 0.8,
        ));
    }
    for (i, e) in out.iter_mut().enumerate() {
        e.voxel_id = 10_000 + i as i64;
    }
    out
}

/// Map voxels along y = 3: ε_g cycles 0.1..0.9, first and last seen vary.
fn truth_voxels() -> Vec<MapVoxel> {
    (0..30)
        .map(|i| {
            let xyz = [i as f64 * 0.5 + 0.25, 3.0, 1.0];
            let first = 1 + (i % 4) as i64;
            MapVoxel {
                voxel_id: 1000 + i as i64,
                key: VoxelKey(xyz.map(|c| (c / VOXEL_M).floor() as i32)),
                xyz_m: xyz,
                eps_g: [0.1, 0.3, 0.5, 0.7, 0.9][i % 5],
                eps_l: 0.2,
                points: i as u32 + 1,
                first_session: first,
                last_seen_session: (first + (i % 3) as i64).min(5),
                category: Category::ALL[i % 6],
                category_session: first,
                owner_session: first,
                owner_keyframe: 0,
                spread_m2: seam::geometry::UNKNOWN_SPREAD,
            }
        })
        .collect()
}

/// A tiny deterministic generator (xorshift64*).
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }
    fn f64(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

/// Builds the synthetic store at `root` through the store's API (and raw
/// SQL for loop candidates, which need keyframes and a file row).
fn build_synthetic(root: &Path) {
    let opts = InitOptions { site_name: "synthetic".into(), crs: "local".into(), voxel_size_m: VOXEL_M };
    let mut store = Store::create(root, &opts).unwrap();
    let events = truth_events();
    store
        .transaction(|tx| -> Result<(), StoreError> {
            let mut gv = 0;
            for (i, (name, date)) in SESSIONS.iter().enumerate() {
                let sid = insert_session(
                    tx,
                    &NewSession {
                        date: Some(date),
                        sensor_model: Some("os1-64"),
                        keyframe_count: 2,
                        point_count: 100 * (i as i64 + 1),
                        ..bare_session(name)
                    },
                )?;
                store::set_session_complete(tx, sid)?;
                gv = insert_graph_version(tx, sid, "session", "{}", None, &[], &[])?;
                let n = events.iter().filter(|e| e.session_id == sid.0).count();
                insert_session_changes(tx, sid, gv, &SessionChanges { events: n, ..SessionChanges::default() })?;
            }
            insert_change_events(tx, &events)?;
            let (map, merged) = LifelongMap::from_voxels(truth_voxels(), VOXEL_M);
            assert_eq!(merged, 0);
            replace_lifelong_map(tx, &map, gv, SessionId(5))?;
            let tower = WorldBox { min_m: [0.0, 0.0, 0.0], max_m: [10.0, 2.0, 2.0] };
            insert_zone(tx, "Tower B", &ZoneShape::Box(tower))?;
            let tri = Polygon::from_wkt(TRIANGLE).unwrap();
            insert_zone(tx, "tri", &ZoneShape::Polygon { polygon: tri, min_z_m: 0.0, max_z_m: 5.0 })?;
            let pile = Polygon::from_wkt("POLYGON((199 199, 215 199, 215 215, 199 215))").unwrap();
            insert_zone(tx, "stockpile", &ZoneShape::Polygon { polygon: pile, min_z_m: -1.0, max_z_m: 3.0 })?;
            raw_loops(tx);
            Ok(())
        })
        .unwrap();
}

fn raw_loops(tx: &rusqlite::Connection) {
    tx.execute_batch(
        "INSERT INTO files(file_id, rel_path, kind, session_id, size_bytes, blake3, row_count, created_at)
             VALUES (1, 'data/none.parquet', 'scans', 1, 0, '', 0, 't');
         INSERT INTO keyframes(keyframe_id, session_id, keyframe_index, source_file, point_count, scan_file_id,
             scan_row_group, odom_x_m, odom_y_m, odom_z_m, odom_qx, odom_qy, odom_qz, odom_qw)
             VALUES (1, 1, 0, 'a', 1, 1, 0, 0, 0, 0, 0, 0, 0, 1), (2, 1, 1, 'b', 1, 1, 1, 0, 0, 0, 0, 0, 0, 1),
                    (3, 2, 0, 'a', 1, 1, 0, 0, 0, 0, 0, 0, 0, 1), (4, 3, 0, 'a', 1, 1, 0, 0, 0, 0, 0, 0, 0, 1),
                    (5, 3, 7, 'b', 1, 1, 1, 0, 0, 0, 0, 0, 0, 1);
         INSERT INTO loop_candidates(candidate_id, session_id, kind, source_keyframe, target_keyframe, distance_m,
             x_m, y_m, z_m, qx, qy, qz, qw, converged, iterations, inliers, fitness, inlier_ratio, rho_scan,
             rho_corr, accepted, reason)
             VALUES (1, 2, 'inter', 3, 1, 4.5, 0, 0, 0, 0, 0, 0, 1, 1, 12, 900, 0.02, 0.91, 2.1, 1.9, 1, 'accepted'),
                    (2, 3, 'inter', 4, 2, 12.0, 0, 0, 0, 0, 0, 0, 1, 1, 30, 300, 0.05, 0.75, 7.2, 6.1, 0,
                        'rho_scan 7.2 above rho_max 4'),
                    (3, 3, 'intra', 5, 4, 31.0, 0, 0, 0, 0, 0, 0, 1, 0, 50, 120, 0.09, 0.41, NULL, NULL, 0,
                        'inlier ratio 0.41 below 0.7');
         INSERT INTO session_alignment(session_id, method, verdict, reason, x_m, y_m, z_m, qx, qy, qz, qw)
             VALUES (1, 'reference', 'success', '', 0, 0, 0, 0, 0, 0, 1), (2, 'global', 'success', '', 0, 0, 0, 0, 0, 0, 1),
                    (3, 'global', 'failure', 'too few inliers', 0, 0, 0, 0, 0, 0, 1);",
    )
    .unwrap();
}

/// A fresh folder for a store shared by the tests of this binary, under
/// cargo's `target/tmp`: a `TempDir` in a static is never dropped, so one in
/// the system's temp folder would be left behind by every run (600 MB for
/// the simulated store). This one is replaced by the next run and goes with
/// `cargo clean`.
fn fixture_dir(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("query-{name}"));
    if dir.exists() {
        std::fs::remove_dir_all(&dir).unwrap();
    }
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// The synthetic store, built once per test binary and only read after.
fn synthetic() -> &'static Path {
    static STORE: OnceLock<PathBuf> = OnceLock::new();
    STORE.get_or_init(|| {
        let root = fixture_dir("synthetic").join("synthetic.seam");
        build_synthetic(&root);
        root
    })
}

/// Compiles and runs a query on a store through the library.
fn ask(root: &Path, q: &str) -> Result<QueryResult, QueryError> {
    let store = Store::open_read_only(root).unwrap();
    let cat = Catalog::load(&store, 0.5).unwrap();
    let plan = query::compile(q, &cat)?;
    Ok(query::execute(store.conn(), &plan).unwrap_or_else(|e| panic!("{q}: {e}")))
}

fn ok(q: &str) -> QueryResult {
    ask(synthetic(), q).unwrap_or_else(|e| panic!("{}", e.render(q, false)))
}

fn err(q: &str) -> QueryError {
    match ask(synthetic(), q) {
        Ok(r) => panic!("{q}: expected an error, got {} rows", r.rows.len()),
        Err(e) => e,
    }
}

/// The values of one column.
fn col(r: &QueryResult, name: &str) -> Vec<Value> {
    let i = r.columns.iter().position(|c| c.name == name).unwrap_or_else(|| panic!("no column {name}"));
    r.rows.iter().map(|row| row[i].clone()).collect()
}

fn ints(r: &QueryResult, name: &str) -> Vec<i64> {
    col(r, name)
        .into_iter()
        .map(|v| match v {
            Value::Integer(i) => i,
            other => panic!("{name}: {other:?}"),
        })
        .collect()
}

fn reals(r: &QueryResult, name: &str) -> Vec<f64> {
    col(r, name)
        .into_iter()
        .map(|v| match v {
            Value::Integer(i) => i as f64,
            Value::Real(x) => x,
            other => panic!("{name}: {other:?}"),
        })
        .collect()
}

fn names(r: &QueryResult) -> Vec<&str> {
    r.columns.iter().map(|c| c.name.as_str()).collect()
}

/// Event ids (1-based) of the truth events that pass `f`, ascending.
fn ids_where(f: impl Fn(&ChangeEvent) -> bool) -> Vec<i64> {
    truth_events().iter().enumerate().filter(|(_, e)| f(e)).map(|(i, _)| i as i64 + 1).collect()
}

fn in_box(p: &[f64; 3], lo: [f64; 3], hi: [f64; 3]) -> bool {
    (0..3).all(|k| p[k] >= lo[k] && p[k] <= hi[k])
}

// ---------------------------------------------------------------------------
// Exact answers on the synthetic store

#[test]
fn regions_have_exact_boundaries() {
    // A box zone includes its faces.
    let r = ok("changes in zone:\"Tower B\"");
    let want = ids_where(|e| in_box(&e.xyz_m, [0.0; 3], [10.0, 2.0, 2.0]));
    assert_eq!(want.len(), 21, "fixture: 20 on line A plus the corner");
    assert_eq!(ints(&r, "event_id"), want);
    // `in` is optional, and bbox: is the same box.
    assert_eq!(ints(&ok("changes bbox:0,0,0,10,2,2"), "event_id"), want);

    // A ball includes its sphere: 0, 0.5, 0.99 and exactly 1 m.
    let r = ok("changes near:50,50,5 r:1");
    assert_eq!(reals(&r, "x_m"), [50.0, 50.5, 50.99, 51.0]);
    assert_eq!(ok("changes near:50,50,5 r:0.999").rows.len(), 3);
    assert_eq!(ok("changes r:2.5 near:50,50,5").rows.len(), 6, "r: may come first");

    // A polygon zone: inside the triangle and its heights only.
    let r = ok("changes in zone:tri");
    assert_eq!(reals(&r, "x_m"), [101.0, 104.0]);
    assert_eq!(reals(&r, "z_m"), [1.0, 1.0]);
}

#[test]
fn session_windows_by_name_number_and_date() {
    let sessions_of = |q: &str| {
        let mut s = ints(&ok(q), "session");
        s.sort();
        s.dedup();
        s
    };
    assert_eq!(sessions_of("changes since:s3"), [3, 4, 5]);
    assert_eq!(sessions_of("changes since:3"), [3, 4, 5]);
    assert_eq!(sessions_of("changes between:s2..s3"), [2, 3]);
    assert_eq!(sessions_of("changes at:north"), [4]);
    assert_eq!(sessions_of("changes at:s4"), [4], "`s4`: no session has that name, so session number 4");
    assert_eq!(sessions_of("changes session:s2,north"), [2, 4]);
    assert_eq!(sessions_of("changes since:2026-03-01"), [3, 4, 5]);
    assert_eq!(sessions_of("changes at:2026-03-10"), [3, 4], "two sessions that day");
    assert_eq!(sessions_of("changes between:2026-01-01..2026-02-28"), [2], "s1 has no events");
    assert_eq!(sessions_of("changes since:s2 between:s1..s3"), [2, 3], "qualifiers intersect");
    assert_eq!(ints(&ok("changes since:s3"), "event_id"), ids_where(|e| e.session_id >= 3));

    // A date after every session: nothing, and a note that says why.
    let r = ok("changes since:2027-01-01");
    assert!(r.rows.is_empty());
    assert!(
        r.notes[0].contains("matches no session") && r.notes[0].contains("2026-01-10 to 2026-04-02"),
        "{:?}",
        r.notes
    );

    // Sessions themselves.
    assert_eq!(ints(&ok("sessions since:2026-02-01"), "session"), [2, 3, 4, 5]);
    assert_eq!(ints(&ok("sessions date:2026-03-10"), "session"), [3, 4]);
    assert_eq!(ints(&ok("sessions verdict:failure"), "session"), [3]);
    let r = ok("sessions | fields name,alignment");
    assert_eq!(names(&r), ["name", "alignment"]);
    assert_eq!(col(&r, "alignment")[4], Value::Null, "s5 has no alignment row");
}

#[test]
fn filters_on_class_eps_and_any_field() {
    let cats = |c: &[Category]| {
        let c = c.to_vec();
        ids_where(move |e| c.contains(&e.category))
    };
    use Category::*;
    assert_eq!(ints(&ok("changes class:emerged"), "event_id"), cats(&[EmergedOverlap, EmergedNonOverlap]));
    assert_eq!(
        ints(&ok("changes class:emerged,deleted"), "event_id"),
        cats(&[EmergedOverlap, EmergedNonOverlap, DeletedOverlap, DeletedNonOverlap])
    );
    assert_eq!(ints(&ok("changes class:!=coexist"), "event_id"), ids_where(|e| e.category != Coexist));
    assert_eq!(ints(&ok("changes class:deleted_overlap"), "event_id"), cats(&[DeletedOverlap]));
    // eps is ε_g after the change; comparisons as written, NULL never matches.
    // ε is stored from an f32, and compared as one.
    assert_eq!(ints(&ok("changes eps:>0.5"), "event_id"), ids_where(|e| e.eps_g_after > 0.5));
    assert_eq!(ints(&ok("changes eps:0.3..0.5"), "event_id"), ids_where(|e| (0.3..=0.5).contains(&e.eps_g_after)));
    assert_eq!(
        ints(&ok("changes eps_g_before:<=0.2"), "event_id"),
        ids_where(|e| e.eps_g_before.is_some_and(|b| b <= 0.2))
    );
    assert_eq!(
        ints(&ok("changes z_m:>=5 x_m:<100"), "event_id"),
        ids_where(|e| e.xyz_m[2] >= 5.0 && e.xyz_m[0] < 100.0)
    );
    // The map: static is ε_g < 0.5; class includes `initial`.
    let v = truth_voxels();
    let vids = |f: &dyn Fn(&MapVoxel) -> bool| v.iter().filter(|x| f(x)).map(|x| x.voxel_id).collect::<Vec<_>>();
    assert_eq!(ints(&ok("static"), "voxel_id"), vids(&|x| x.eps_g < 0.5));
    assert_eq!(ints(&ok("lifelong class:initial"), "voxel_id"), vids(&|x| x.category == Initial));
    // ε is stored from an f32: `>= 0.7` means the stored 0.7 too.
    assert_eq!(ints(&ok("lifelong eps:>=0.7"), "voxel_id"), vids(&|x| x.eps_g >= 0.7));
    assert_eq!(ints(&ok("lifelong eps:0.7"), "voxel_id"), vids(&|x| x.eps_g == 0.7));
    // Loops: booleans and text.
    let r = ok("loops accepted:false");
    assert_eq!(ints(&r, "candidate"), [2, 3]);
    assert_eq!(col(&r, "reason")[0], Value::Text("rho_scan 7.2 above rho_max 4".into()));
    assert_eq!(ints(&ok("loops session:s3 accepted:false kind:intra"), "candidate"), [3]);
    assert_eq!(ints(&ok("loops accepted:yes"), "target_session"), [1]);
    assert_eq!(ints(&ok("loops kind:intra"), "source_keyframe"), [7]);
}

#[test]
fn map_time_is_first_seen_or_present_at() {
    let v = truth_voxels();
    let vids = |f: &dyn Fn(&MapVoxel) -> bool| v.iter().filter(|x| f(x)).map(|x| x.voxel_id).collect::<Vec<_>>();
    assert_eq!(ints(&ok("lifelong since:s3"), "voxel_id"), vids(&|x| x.first_session >= 3));
    assert_eq!(ints(&ok("lifelong at:s2"), "voxel_id"), vids(&|x| x.first_session <= 2 && x.last_seen_session >= 2));
    // A day with two sessions: the map after the last of them (north, 4).
    assert_eq!(
        ints(&ok("lifelong at:2026-03-10"), "voxel_id"),
        vids(&|x| x.first_session <= 4 && x.last_seen_session >= 4)
    );
    assert_eq!(ints(&ok("static between:s1..s2"), "voxel_id"), vids(&|x| x.first_session <= 2 && x.eps_g < 0.5));
}

#[test]
fn pipeline_stages_count_top_sort_fields_limit_sum() {
    let r = ok("changes | count");
    assert_eq!(names(&r), ["count"]);
    assert_eq!(ints(&r, "count"), [truth_events().len() as i64]);

    // count by session brings the session's name along.
    let r = ok("changes in zone:\"Tower B\" | count by session");
    assert_eq!(names(&r), ["session", "session_name", "count"]);
    let tower = truth_events().into_iter().filter(|e| in_box(&e.xyz_m, [0.0; 3], [10.0, 2.0, 2.0])).collect::<Vec<_>>();
    let want: Vec<i64> = (2..=5).map(|s| tower.iter().filter(|e| e.session_id == s).count() as i64).collect();
    assert_eq!(ints(&r, "session"), [2, 3, 4, 5]);
    assert_eq!(ints(&r, "count"), want);
    assert_eq!(col(&r, "session_name")[2], Value::Text("north".into()));
    let r = ok("changes | count by category, session | sort count desc | limit 1");
    assert_eq!(names(&r), ["category", "session", "session_name", "count"]);

    // top: the largest, ties by event id; fields keep their order.
    let r = ok("changes in zone:\"Tower B\" | top 3 by eps_g_after | fields eps_g_after,event_id");
    assert_eq!(names(&r), ["eps_g_after", "event_id"]);
    let mut want: Vec<(f32, i64)> = tower
        .iter()
        .zip(ids_where(|e| in_box(&e.xyz_m, [0.0; 3], [10.0, 2.0, 2.0])))
        .map(|(e, id)| (e.eps_g_after, id))
        .collect();
    want.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
    assert_eq!(ints(&r, "event_id"), want[..3].iter().map(|w| w.1).collect::<Vec<_>>());

    // sort then limit; limit 0; sort ascending by a text field.
    let r = ok("lifelong | sort x_m desc | limit 2 | fields voxel_id");
    assert_eq!(ints(&r, "voxel_id"), [1029, 1028]);
    assert!(ok("lifelong | limit 0").rows.is_empty());
    let r = ok("sessions | sort name | fields name");
    assert_eq!(col(&r, "name")[0], Value::Text("north".into()));

    // sum adds what adds up.
    let r = ok("sessions | sum");
    assert_eq!(names(&r), ["keyframes", "points", "change_events"]);
    assert_eq!(ints(&r, "points"), [1500]);
    assert_eq!(ints(&r, "change_events"), [truth_events().len() as i64]);
    let r = ok("changes | count by session | sum");
    assert_eq!(ints(&r, "count"), [truth_events().len() as i64]);

    // Counting counts: the new column takes another name.
    let r = ok("changes in zone:\"Tower B\" | count by session | count by count");
    assert_eq!(names(&r), ["count", "rows"]);
    assert_eq!(ints(&r, "rows").iter().sum::<i64>(), 4, "four sessions");
    // The deepest pipeline there may be runs.
    let r = ok(&format!("changes{}", " | sort x_m desc | limit 50".repeat(16)));
    assert_eq!(r.rows.len(), 50);
}

#[test]
fn volume_history_and_coverage_add_up() {
    let events = truth_events();
    let v3 = VOXEL_M.powi(3);
    // Volume: emerged (both kinds) and deleted_overlap only, × 0.008 m³.
    let r = ok("volume in zone:stockpile since:s2");
    assert_eq!(ints(&r, "session"), [2, 3, 4, 5]);
    let pile = Polygon::from_wkt("POLYGON((199 199, 215 199, 215 215, 199 215))").unwrap();
    let inside = |e: &ChangeEvent| pile.contains(e.xyz_m[0], e.xyz_m[1]) && (-1.0..=3.0).contains(&e.xyz_m[2]);
    for (row, s) in (2..=5).enumerate() {
        let em = events
            .iter()
            .filter(|e| {
                e.session_id == s
                    && inside(e)
                    && matches!(e.category, Category::EmergedOverlap | Category::EmergedNonOverlap)
            })
            .count();
        let de =
            events.iter().filter(|e| e.session_id == s && inside(e) && e.category == Category::DeletedOverlap).count();
        assert_eq!(ints(&r, "emerged_voxels")[row], em as i64, "session {s}");
        assert_eq!(ints(&r, "deleted_voxels")[row], de as i64, "session {s}");
        assert!((reals(&r, "emerged_m3")[row] - em as f64 * v3).abs() < 1e-9);
        assert!((reals(&r, "net_m3")[row] - (em as f64 - de as f64) * v3).abs() < 1e-9);
    }
    let total = ok("volume in zone:stockpile | sum");
    assert_eq!(names(&total), ["emerged_voxels", "deleted_voxels", "emerged_m3", "deleted_m3", "net_m3"]);
    assert_eq!(ints(&total, "emerged_voxels")[0], ints(&r, "emerged_voxels").iter().sum::<i64>());

    // History of the ball at (50, 50, 5), r 1: four emerged in session 2, and
    // every session listed.
    let r = ok("history near:50,50,5 r:1");
    assert_eq!(ints(&r, "session"), [1, 2, 3, 4, 5]);
    assert_eq!(ints(&r, "events"), [0, 4, 0, 0, 0]);
    assert_eq!(ints(&r, "emerged_voxels"), [0, 4, 0, 0, 0]);
    assert_eq!(ok("history near:50,50,5 r:1 events:>0").rows.len(), 1, "filters apply to what history computed");
    // Over Tower B's line (map voxels at y = 3 are outside it, so first/last seen are 0).
    let r = ok("history in bbox:0,0,0,20,4,2 | sum");
    assert_eq!(ints(&r, "events"), [ids_where(|e| in_box(&e.xyz_m, [0.0; 3], [20.0, 4.0, 2.0])).len() as i64]);
    assert_eq!(ints(&r, "first_seen_voxels"), [30]);

    // Coverage of the map line: voxels present during each session.
    let r = ok("coverage in bbox:0,2,0,20,4,2");
    let v = truth_voxels();
    for (row, s) in (1..=5).enumerate() {
        let n = v.iter().filter(|x| x.first_session <= s && x.last_seen_session >= s).count();
        assert_eq!(ints(&r, "voxels")[row], n as i64, "session {s}");
        assert!((reals(&r, "share")[row] - n as f64 / 30.0).abs() < 1e-12);
        assert!((reals(&r, "volume_m3")[row] - n as f64 * v3).abs() < 1e-9);
        // Each voxel is its own xy column here.
        assert!((reals(&r, "area_m2")[row] - n as f64 * VOXEL_M * VOXEL_M).abs() < 1e-9);
    }
}

/// Fast code against a slow reference: random boxes, balls, windows and
/// classes against a filter over the rows inserted.
#[test]
fn random_queries_match_a_brute_force_filter() {
    let events = truth_events();
    let mut rng = Rng(99);
    let classes = ["emerged", "deleted", "coexist", "emerged_overlap", "deleted_non_overlap"];
    for i in 0..300 {
        let lo = [195.0 + rng.f64() * 30.0, 195.0 + rng.f64() * 30.0, rng.f64() * 6.0 - 2.0];
        let size = [rng.f64() * 15.0, rng.f64() * 15.0, rng.f64() * 4.0];
        let hi = [lo[0] + size[0], lo[1] + size[1], lo[2] + size[2]];
        let since = 1 + rng.below(5) as i64;
        let class = classes[rng.below(classes.len())];
        let in_class = |c: Category| match class {
            "emerged" => matches!(c, Category::EmergedOverlap | Category::EmergedNonOverlap),
            "deleted" => matches!(c, Category::DeletedOverlap | Category::DeletedNonOverlap),
            other => c.as_str() == other,
        };
        let q = if i % 2 == 0 {
            format!(
                "changes in bbox:{},{},{},{},{},{} since:{since} class:{class}",
                lo[0], lo[1], lo[2], hi[0], hi[1], hi[2]
            )
        } else {
            format!("changes near:{},{},{} r:{} since:{since} class:{class}", lo[0], lo[1], lo[2], size[0] + 0.01)
        };
        let want: Vec<i64> = events
            .iter()
            .enumerate()
            .filter(|(_, e)| e.session_id >= since && in_class(e.category))
            .filter(|(_, e)| {
                if i % 2 == 0 {
                    in_box(&e.xyz_m, lo, hi)
                } else {
                    let r = size[0] + 0.01;
                    (0..3).map(|k| (e.xyz_m[k] - lo[k]).powi(2)).sum::<f64>() <= r * r
                }
            })
            .map(|(i, _)| i as i64 + 1)
            .collect();
        assert_eq!(ints(&ok(&q), "event_id"), want, "{q}");
    }
}

/// DESIGN.md's examples, verbatim, on the synthetic store.
#[test]
fn design_examples_run_verbatim() {
    for q in [
        "changes in zone:\"Tower B\" since:s3",
        "changes in bbox:10,20,0,40,60,5 between:s3..s5 class:emerged,deleted",
        "changes near:12.5,3,1 r:2 | count by session",
        "static in bbox:0,0,-2,50,50,10 | count",
        "history near:12.5,3,1 r:0.5          # one spot through every session",
        "sessions since:2026-01-01",
        "loops session:s4 accepted:false      # why did s4 not merge?",
        "volume in zone:stockpile since:s2    # m³ emerged / deleted",
    ] {
        ok(q);
    }
    assert_eq!(
        ints(&ok("changes in zone:\"Tower B\" since:s3"), "event_id"),
        ids_where(|e| e.session_id >= 3 && in_box(&e.xyz_m, [0.0; 3], [10.0, 2.0, 2.0]))
    );
    assert_eq!(ints(&ok("sessions since:2026-01-01"), "session"), [1, 2, 3, 4, 5]);
}

// ---------------------------------------------------------------------------
// Errors

fn at<'a>(q: &'a str, e: &QueryError) -> &'a str {
    &q[e.span.start..e.span.end]
}

fn help(e: &QueryError) -> &str {
    e.help.as_deref().unwrap_or("")
}

#[test]
fn unknown_names_get_did_you_mean_at_their_span() {
    let q = "chnages in zone:\"Tower B\" since:s3";
    let e = err(q);
    assert_eq!(at(q, &e), "chnages");
    assert!(help(&e).starts_with("did you mean `changes`?"), "{e:?}");
    let r = e.render(q, false);
    assert!(r.contains("1 | chnages in zone") && r.contains("  | ^^^^^^^ "), "{r}");

    let q = "changes in zone:\"Towr B\" since:s3";
    let e = err(q);
    assert_eq!(at(q, &e), "\"Towr B\"");
    assert!(help(&e).contains("did you mean `Tower B`?") && help(&e).contains("`stockpile`"), "{e:?}");

    let q = "changes since:s9";
    let e = err(q);
    assert_eq!(at(q, &e), "s9");
    assert!(e.message.contains("no session s9"), "{e:?}");
    let list = "sessions in this store: 1 `s1` (2026-01-10), 2 `s2` (2026-02-10), 3 `s3` (2026-03-10), 4 `north` (2026-03-10), 5 `s5` (2026-04-02)";
    assert_eq!(help(&e), list);
    let q = "changes between:s2..7";
    assert_eq!(at(q, &err(q)), "7");
    let q = "changes at:nrth";
    let e = err(q);
    assert!(help(&e).starts_with("did you mean `north`?") && help(&e).contains(list), "{e:?}");

    for (q, span, want) in [
        ("changes | count by sesion", "sesion", "did you mean `session`?"),
        ("changes clas:emerged", "clas", "did you mean `class:`?"),
        ("changes class:emergd", "emergd", "did you mean `emerged`?"),
        ("changes sinse:s2", "sinse", "did you mean `since:`?"),
        ("lifelong | top 3 by eps", "eps", "did you mean `eps_g`?"),
        ("changes | fields x_m | count by session", "session", "fields left here: x_m"),
        ("changes | cuont", "cuont", "did you mean `count`?"),
        ("changes class:initial", "initial", "categories"),
        ("sessions in bbox:0,0,0,1,1,1", "bbox:0,0,0,1,1,1", "regions apply to changes"),
        ("changes near:1,2,3", "near:1,2,3", "add `r:`"),
        ("changes r:3", "r:3", "near:12.5,3,1 r:2"),
        ("changes between:s3..s2", "s3..s2", "between:s2..s3"),
        ("changes bbox:5,0,0,1,1,1", "bbox:5,0,0,1,1,1", "x0 ≤ x1"),
        ("static | sum", "sum", "`sum` adds"),
        ("changes eps:high", "high", "is a number"),
        ("loops accepted:maybe", "maybe", "e.g. `accepted:false`"),
        ("changes eps:0.9..0.1", "0.9..0.1", "LOW..HIGH"),
        ("changes class:>emerged", "class:>emerged", ""),
        ("changes zone:nowhere", "nowhere", "zones: `Tower B`, `stockpile`, `tri`"),
    ] {
        let e = err(q);
        assert_eq!(at(q, &e), span, "{q}: {e:?}");
        assert!(e.message.contains(want) || help(&e).contains(want), "{q}: {e:?}");
    }
}

/// Mutations of the example queries: deletions, insertions of characters
/// and tokens, truncations, swaps, huge numbers, unicode, unterminated
/// strings. None panics; every error points inside the query on char
/// boundaries and renders; every query that plans also runs.
#[test]
fn malformed_queries_never_panic_and_point_inside() {
    let root = synthetic();
    let store = Store::open_read_only(root).unwrap();
    let cat = Catalog::load(&store, 0.5).unwrap();
    let mut seeds: Vec<String> = vec![
        "changes in zone:\"Tower B\" since:s3".into(),
        "changes in bbox:10,20,0,40,60,5 between:s3..s5 class:emerged,deleted".into(),
        "changes near:12.5,3,1 r:2 | count by session".into(),
        "static in bbox:0,0,-2,50,50,10 | count".into(),
        "history near:12.5,3,1 r:0.5 # one spot".into(),
        "sessions since:2026-01-01".into(),
        "loops session:s4 accepted:false".into(),
        "volume in zone:stockpile since:s2 | sum".into(),
        "lifelong eps:0.2..0.6 at:2026-03-10 | top 3 by eps_g | fields voxel_id,eps_g | limit 2".into(),
        "coverage in zone:tri | sort share desc".into(),
    ];
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("queries");
    for f in std::fs::read_dir(&dir).unwrap().flatten() {
        if f.path().extension().is_some_and(|e| e == "seamql") {
            seeds.push(std::fs::read_to_string(f.path()).unwrap());
        }
    }
    let chars = [
        '"', '\'', ':', ',', '|', '.', '#', '\n', '\t', '<', '>', '=', '!', '(', '\\', '-', 'é', '塔', '\u{200b}',
        '🦀', 'x', '9', ' ',
    ];
    let nines: &'static str = "9".repeat(400).leak();
    let tokens = [
        ":",
        "|",
        "..",
        ",",
        "bbox:",
        "near:",
        "r:",
        "zone:",
        "since:",
        "between:",
        "at:",
        "session:",
        "class:",
        "eps:>",
        "\"",
        "'unterminated",
        "1e309",
        "99999999999999999999",
        "-0",
        "NaN",
        "inf",
        "s99",
        "2026-13-01",
        "2026-02-29",
        "| top",
        "by",
        "count",
        "| sum",
        "| fields",
        "| limit -1",
        "| limit 1e20",
        "desc",
        "in",
        "#",
        "\"\"",
        "..s3",
        "Tower B",
        "zone:\"\"",
        nines,
        "📍",
        "\u{feff}",
    ];
    let mut rng = Rng(2026);
    let (mut errors, mut planned) = (0, 0);
    for n in 0..3000 {
        let mut q = seeds[n % seeds.len()].clone();
        for _ in 0..1 + rng.below(3) {
            q = mutate(&q, &mut rng, &chars, &tokens);
        }
        let outcome = std::panic::catch_unwind(|| query::compile(&q, &cat));
        let Ok(outcome) = outcome else { panic!("compile panicked on {q:?}") };
        match outcome {
            Err(e) => {
                errors += 1;
                let s = e.span;
                assert!(s.start <= s.end && s.end <= q.len(), "{q:?}: span {s:?} outside");
                assert!(q.is_char_boundary(s.start) && q.is_char_boundary(s.end), "{q:?}: span {s:?} splits a char");
                let r = e.render(&q, false);
                assert!(r.starts_with("error: ") && r.contains("--> query:") && r.contains('^'), "{q:?}: {r}");
                assert!(!e.message.is_empty());
            }
            Ok(plan) => {
                planned += 1;
                if let Err(e) = query::execute(store.conn(), &plan) {
                    panic!("{q:?} planned but failed to run: {e}\n{}", plan.sql.text);
                }
            }
        }
    }
    eprintln!("{errors} of 3000 mutations were errors, {planned} planned and ran");
    assert!(errors >= 1000, "only {errors} of 3000 mutations were malformed ({planned} planned)");
}

/// One mutation at a char boundary.
fn mutate(q: &str, rng: &mut Rng, chars: &[char], tokens: &[&str]) -> String {
    let bounds: Vec<usize> = q.char_indices().map(|(i, _)| i).chain([q.len()]).collect();
    let pick = |rng: &mut Rng| bounds[rng.below(bounds.len())];
    let (a, b) = {
        let (x, y) = (pick(rng), pick(rng));
        (x.min(y), x.max(y))
    };
    match rng.below(7) {
        0 => {
            // Delete 1-6 characters.
            let i = rng.below(bounds.len());
            let j = (i + 1 + rng.below(6)).min(bounds.len() - 1);
            format!("{}{}", &q[..bounds[i]], &q[bounds[j]..])
        }
        1 => format!("{}{}{}", &q[..a], chars[rng.below(chars.len())], &q[a..]),
        2 => format!("{}{}{}", &q[..a], tokens[rng.below(tokens.len())], &q[a..]),
        3 => q[..a].to_string(),
        4 => {
            let mut w: Vec<&str> = q.split(' ').collect();
            if w.len() > 1 {
                let (i, j) = (rng.below(w.len()), rng.below(w.len()));
                w.swap(i, j);
            }
            w.join(" ")
        }
        5 => {
            // A number made huge, negative or fractional.
            let repl = ["1e308", "-1e308", "0.000000001", "18446744073709551616", "-5", "2.5"][rng.below(6)];
            match q.find(|c: char| c.is_ascii_digit()) {
                Some(i) => format!("{}{}{}", &q[..i], repl, &q[i + 1..]),
                None => format!("{q} {repl}"),
            }
        }
        _ => format!("{}{}", &q[..a], &q[b..]),
    }
}

mod props {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]
        /// Any text at all: an answer or an error inside the text.
        #[test]
        fn any_text_parses_or_errs_inside(q in "\\PC{0,60}") {
            let store = Store::open_read_only(synthetic()).unwrap();
            let cat = Catalog::load(&store, 0.5).unwrap();
            if let Err(e) = query::compile(&q, &cat) {
                prop_assert!(e.span.end <= q.len() && q.is_char_boundary(e.span.start) && q.is_char_boundary(e.span.end));
                prop_assert!(e.render(&q, false).contains("--> query:"));
            }
        }

        /// Sentences of the language's own words in random order.
        #[test]
        fn shuffled_keywords_parse_or_err_inside(words in proptest::collection::vec(
            prop::sample::select(vec!["changes", "static", "in", "bbox:1,2,3,4,5,6", "near:1,2,3", "r:2", "since:s2",
                "between:s1..s3", "zone:tri", "class:emerged", "|", "count", "by", "session", "top", "3", "sum",
                "fields", "x_m", ",", "limit", "\"", ":", "eps:>0.5", "..", "at:2026-03-10"]), 0..12)) {
            let q = words.join(" ");
            let store = Store::open_read_only(synthetic()).unwrap();
            let cat = Catalog::load(&store, 0.5).unwrap();
            match query::compile(&q, &cat) {
                Err(e) => prop_assert!(e.span.end <= q.len()),
                Ok(plan) => prop_assert!(query::execute(store.conn(), &plan).is_ok(), "{}", plan.sql.text),
            }
        }
    }
}

// ---------------------------------------------------------------------------
// The command line

fn seam_query(root: &Path, args: &[&str]) -> std::process::Output {
    let mut all = vec!["query", root.to_str().unwrap()];
    all.extend_from_slice(args);
    seam().args(&all).env("NO_COLOR", "1").output().unwrap()
}

#[test]
fn cli_prints_tables_json_csv_and_parquet() {
    let root = synthetic();
    let tmp = tempfile::tempdir().unwrap();
    let q = "changes in zone:\"Tower B\" | fields event_id,session,category,x_m,eps_g_before";
    let want = ok(q);

    let o = seam_query(root, &[q]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = stdout(&o);
    let lines: Vec<&str> = text.lines().collect();
    assert!(lines[0].starts_with("event_id  session  category"), "{text}");
    assert_eq!(lines.len(), want.rows.len() + 1);
    assert!(text.lines().any(|l| l.ends_with(" -")), "NULL eps_g_before prints as -: {text}");

    let o = seam_query(root, &[q, "--format", "json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    let rows = v.as_array().unwrap();
    assert_eq!(rows.len(), want.rows.len());
    let ids: Vec<i64> = rows.iter().map(|r| r["event_id"].as_i64().unwrap()).collect();
    assert_eq!(ids, ints(&want, "event_id"));
    assert!(rows.iter().any(|r| r["eps_g_before"].is_null()));
    assert!(stdout(&o).find("\"event_id\"").unwrap() < stdout(&o).find("\"session\"").unwrap(), "keys in column order");

    let o = seam_query(root, &[q, "--format", "csv"]);
    let csv = stdout(&o);
    let mut lines = csv.lines();
    assert_eq!(lines.next(), Some("event_id,session,category,x_m,eps_g_before"));
    let first: Vec<&str> = lines.next().unwrap().split(',').collect();
    assert_eq!(first[0].parse::<i64>().unwrap(), ids[0]);
    assert_eq!(first[3].parse::<f64>().unwrap(), reals(&want, "x_m")[0]);

    // Parquet: typed columns with the result's names, the same rows.
    let out = tmp.path().join("sub/tower.parquet");
    let o = seam_query(root, &[q, "--out", out.to_str().unwrap(), "--format", "json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let receipt: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert_eq!(receipt["rows"], want.rows.len());
    let reader =
        parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder::try_new(std::fs::File::open(&out).unwrap())
            .unwrap();
    let cols: Vec<String> =
        reader.schema().fields().iter().map(|f| format!("{}:{}", f.name(), f.data_type())).collect();
    assert_eq!(cols, ["event_id:Int64", "session:Int64", "category:Utf8", "x_m:Float64", "eps_g_before:Float64"]);
    let batch = reader.build().unwrap().next().unwrap().unwrap();
    assert_eq!(batch.num_rows(), want.rows.len());
    let got = batch.column(0).as_any().downcast_ref::<arrow_array::Int64Array>().unwrap();
    assert_eq!(got.values().to_vec(), ids);
    let xs = batch.column(3).as_any().downcast_ref::<arrow_array::Float64Array>().unwrap();
    assert_eq!(xs.values().to_vec(), reals(&want, "x_m"), "Parquet keeps the exact f64");
    assert!(std::fs::read_dir(out.parent().unwrap()).unwrap().count() == 1, "no temporary file left");

    // Booleans print as true/false everywhere.
    let o = seam_query(root, &["loops | fields candidate,accepted", "--format", "csv"]);
    assert_eq!(stdout(&o), "candidate,accepted\n1,true\n2,false\n3,false\n");
}

#[test]
fn cli_explain_shows_placeholders_not_values() {
    let root = synthetic();
    let o = seam_query(
        root,
        &["changes in zone:tri since:north class:emerged eps:>0.123 | top 7 by eps_g_after", "--explain"],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let text = stdout(&o);
    let sql = text.split("\nsql:\n").nth(1).unwrap().split("\nparameters:\n").next().unwrap();
    assert!(sql.contains('?'), "{sql}");
    for value in ["tri", "north", "emerged", "0.123", "100", "110", "POLYGON", " 7", "'4'"] {
        assert!(!sql.contains(value), "the SQL holds the user's value {value:?}: {sql}");
    }
    assert!(sql.contains("seam_in_polygon(?") && sql.contains("map_tiles"), "{sql}");
    let params = text.split("\nparameters:\n").nth(1).unwrap();
    assert!(
        params.contains("\"POLYGON((100 0, 110 0, 100 10, 100 0))\"") && params.contains("= 0.12300000"),
        "{params}"
    );
    assert!(text.contains("tested in Rust (seam_in_polygon)") && text.contains("R*Tree"), "{text}");
    assert!(
        text.contains("sqlite plan:") && text.contains("USING COVERING INDEX change_events_by_tile_cover"),
        "{text}"
    );
    assert!(text.contains("time: since:north → sessions 4 (north), 5 (s5)"), "{text}");
}

#[test]
fn cli_query_errors_exit_3_with_a_caret_and_leave_the_store_alone() {
    let root = synthetic();
    let before = store_state(root);
    for (q, want) in [
        (
            "chnages in zone:\"Tower B\" since:s3",
            vec!["unknown subject `chnages`", "^^^^^^^", "did you mean `changes`?"],
        ),
        ("changes in zone:\"Towr B\" since:s3", vec!["no zone named `Towr B`", "^^^^^^^^", "did you mean `Tower B`?"]),
        ("changes since:s9", vec!["there is no session s9", "1 `s1` (2026-01-10)", "5 `s5` (2026-04-02)"]),
        ("changes in bbox:1,2,3", vec!["expected 6 numbers, found 3", "^^^^^"]),
    ] {
        let o = seam_query(root, &[q]);
        assert_eq!(o.status.code(), Some(3), "{q}: {}", stderr(&o));
        let err = stderr(&o);
        assert!(err.starts_with("error: "), "{err}");
        assert!(err.contains("--> query:1:"), "{err}");
        for w in want {
            assert!(err.contains(w), "{q}: {w:?} not in\n{err}");
        }
        assert!(!err.contains('\x1b'), "no colours with NO_COLOR or off a terminal: {err}");
        assert!(stdout(&o).is_empty());
    }
    // Queries, explains and exports to a file never change the store.
    let tmp = tempfile::tempdir().unwrap();
    for args in [
        vec!["changes | count by session"],
        vec!["volume in zone:stockpile", "--explain"],
        vec!["lifelong", "--out", tmp.path().join("l.parquet").to_str().unwrap()],
    ] {
        assert!(seam_query(root, &args).status.success());
    }
    assert_same_state(&before, &store_state(root), "after queries");
    // Not a store: exit 4; an unreadable query file: exit 2.
    let o = seam_query(tmp.path(), &["changes"]);
    assert_eq!(o.status.code(), Some(4), "{}", stderr(&o));
    let o = seam_query(root, &["@/nonexistent.seamql"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
}

#[test]
fn cli_zones_add_list_rm() {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path().join("z.seam");
    init_store(&root);
    let st = root.to_str().unwrap();
    let zones = |args: &[&str]| {
        let mut all = vec!["zones"];
        all.extend_from_slice(args);
        run(&all)
    };
    let o = zones(&["add", st, "Tower B", "bbox:0,0,0,10,2,2"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stdout(&o).contains("zone:\"Tower B\""), "{}", stdout(&o));
    let o = zones(&["add", st, "pad", "--wkt", "POLYGON((0 0, 4 0, 4 4, 0 4))", "--z", "-1..3"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = zones(&["list", st, "--format", "json"]);
    let v: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert_eq!(v[0]["name"], "Tower B");
    assert_eq!(v[1]["kind"], "polygon");
    assert_eq!(v[1]["min_m"], serde_json::json!([0.0, 0.0, -1.0]));
    assert_eq!(v[1]["polygon_wkt"], "POLYGON((0 0, 4 0, 4 4, 0 4, 0 0))");

    // Mistakes: usage errors that change nothing.
    let before = store_state(&root);
    for (args, want) in [
        (vec!["add", st, "pad", "bbox:0,0,0,1,1,1"], "already exists"),
        (vec!["add", st, "x", "bbox:0,0,0,1,1"], "expected 6 numbers"),
        (vec!["add", st, "x", "bbox:2,0,0,1,1,1"], "x0 = 2 is above"),
        (vec!["add", st, "x", "--wkt", "POLYGON((0 0, 1 1))"], "at least 3"),
        (vec!["add", st, "x", "--wkt", "POLYGON((0 0, 1 0, 1 1))"], "needs --z"),
        (vec!["add", st, "x"], "give the zone's shape"),
        (vec!["rm", st, "Towr B"], "did you mean \"Tower B\"?"),
    ] {
        let o = zones(&args);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {}", stderr(&o));
        assert!(stderr(&o).contains(want), "{args:?}: {}", stderr(&o));
    }
    assert_same_state(&before, &store_state(&root), "after refused zone commands");

    // The zones answer queries (an empty store has no rows, but they plan).
    let o = run(&["query", st, "changes in zone:pad | count"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = zones(&["rm", st, "pad"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = run(&["query", st, "changes in zone:pad"]);
    assert_eq!(o.status.code(), Some(3));
    assert!(stderr(&o).contains("no zone named `pad`") && stderr(&o).contains("zones: `Tower B`"), "{}", stderr(&o));
}

// ---------------------------------------------------------------------------
// Every file in queries/, on a simulated store

/// A simulated 3-session site, ingested through the binary, with the zones
/// the example queries name.
fn simulated() -> &'static Path {
    static STORE: OnceLock<PathBuf> = OnceLock::new();
    STORE.get_or_init(|| {
        let dir = fixture_dir("simulated");
        let sim = dir.join("sim");
        let o =
            run(&["simulate", sim.to_str().unwrap(), "--sessions", "3", "--keyframes", "80", "--seed", "3", "--quiet"]);
        assert!(o.status.success(), "{}", stderr(&o));
        let root = dir.join("site.seam");
        init_store(&root);
        let st = root.to_str().unwrap();
        for s in 1..=3 {
            let o = run(&["ingest", st, sim.join(format!("session_0{s}")).to_str().unwrap(), "--quiet"]);
            assert!(o.status.success(), "{}", stderr(&o));
        }
        for args in [
            vec!["zones", "add", st, "Tower B", "bbox:-25,-35,0,-5,-15,20"],
            vec!["zones", "add", st, "stockpile", "--wkt", STOCKPILE, "--z", "0..10"],
        ] {
            let o = run(&args);
            assert!(o.status.success(), "{}", stderr(&o));
        }
        // The queries read only the store; the scans are 180 MB.
        std::fs::remove_dir_all(&sim).unwrap();
        root
    })
}

const STOCKPILE: &str = "POLYGON((-22 12, -10 11, -9 21, -16 24, -23 19))";
const TOWER_B: ([f64; 3], [f64; 3]) = ([-25.0, -35.0, 0.0], [-5.0, -15.0, 20.0]);

/// Point in polygon by winding number: independent of the even-odd test
/// the store uses.
fn winding_inside(poly: &[[f64; 2]], x: f64, y: f64) -> bool {
    let mut wn = 0i32;
    for i in 0..poly.len() {
        let (a, b) = (poly[i], poly[(i + 1) % poly.len()]);
        let cross = (b[0] - a[0]) * (y - a[1]) - (x - a[0]) * (b[1] - a[1]);
        if a[1] <= y && b[1] > y && cross > 0.0 {
            wn += 1;
        } else if a[1] > y && b[1] <= y && cross < 0.0 {
            wn -= 1;
        }
    }
    wn != 0
}

fn stockpile_inside(x: f64, y: f64, z: f64) -> bool {
    let poly = [[-22.0, 12.0], [-10.0, 11.0], [-9.0, 21.0], [-16.0, 24.0], [-23.0, 19.0]];
    winding_inside(&poly, x, y) && (0.0..=10.0).contains(&z)
}

/// Runs one example file through the binary as JSON.
fn run_example(root: &Path, file: &Path) -> Vec<serde_json::Value> {
    let arg = format!("@{}", file.display());
    let o = seam().args(["query", root.to_str().unwrap(), &arg, "--format", "json", "--quiet"]).output().unwrap();
    assert!(o.status.success(), "{}: {}", file.display(), stderr(&o));
    serde_json::from_str::<serde_json::Value>(&stdout(&o)).unwrap().as_array().unwrap().clone()
}

fn sql_ints(conn: &rusqlite::Connection, sql: &str) -> Vec<Vec<i64>> {
    let mut st = conn.prepare(sql).unwrap();
    let n = st.column_count();
    st.query_map([], |r| (0..n).map(|i| r.get::<_, i64>(i)).collect::<Result<Vec<_>, _>>())
        .unwrap()
        .map(|r| r.unwrap())
        .collect()
}

fn json_ints(rows: &[serde_json::Value], keys: &[&str]) -> Vec<Vec<i64>> {
    rows.iter().map(|r| keys.iter().map(|k| r[*k].as_i64().unwrap_or_else(|| panic!("{k}: {r}"))).collect()).collect()
}

fn json_f(r: &serde_json::Value, k: &str) -> f64 {
    r[k].as_f64().unwrap_or_else(|| panic!("{k}: {r}"))
}

/// Change events inside the stockpile by session: (session, emerged, deleted_overlap, above 3 m).
fn stockpile_events(conn: &rusqlite::Connection) -> Vec<(i64, String, f64)> {
    let mut st = conn.prepare("SELECT session_id, category, x_m, y_m, z_m FROM change_events").unwrap();
    st.query_map([], |r| {
        Ok((r.get::<_, i64>(0)?, r.get::<_, String>(1)?, r.get::<_, f64>(2)?, r.get::<_, f64>(3)?, r.get::<_, f64>(4)?))
    })
    .unwrap()
    .map(|r| r.unwrap())
    .filter(|e| stockpile_inside(e.2, e.3, e.4))
    .map(|e| (e.0, e.1, e.4))
    .collect()
}

/// The independent answer to each example, compared with what it returned.
fn check_example(name: &str, rows: &[serde_json::Value], conn: &rusqlite::Connection) {
    let (lo, hi) = TOWER_B;
    let tower = format!(
        "x_m BETWEEN {} AND {} AND y_m BETWEEN {} AND {} AND z_m BETWEEN {} AND {}",
        lo[0], hi[0], lo[1], hi[1], lo[2], hi[2]
    );
    let ids = |rows: &[serde_json::Value], k: &str| json_ints(rows, &[k]).into_iter().map(|v| v[0]).collect::<Vec<_>>();
    let col0 = |sql: &str| sql_ints(conn, sql).into_iter().map(|v| v[0]).collect::<Vec<_>>();
    let v3 = 0.2f64.powi(3);
    match name {
        "tower_b_changes_since_s2" => {
            let want = col0(&format!(
                "SELECT event_id FROM change_events WHERE {tower} AND session_id >= 2 ORDER BY event_id"
            ));
            assert!(!want.is_empty());
            assert_eq!(ids(rows, "event_id"), want);
            for r in rows {
                let p = [json_f(r, "x_m"), json_f(r, "y_m"), json_f(r, "z_m")];
                assert!((0..3).all(|k| p[k] >= lo[k] - 1e-4 && p[k] <= hi[k] + 1e-4), "{r}");
                assert!(r["session"].as_i64().unwrap() >= 2);
            }
        }
        "built_or_removed_in_yard" => {
            let want = col0(&format!(
                "SELECT event_id FROM change_events WHERE {tower} AND session_id BETWEEN 2 AND 3 AND category <> 'coexist' ORDER BY event_id"
            ));
            assert!(!want.is_empty());
            assert_eq!(ids(rows, "event_id"), want);
            assert!(rows.iter().all(|r| r["category"] != "coexist"));
        }
        "changes_near_crane_per_survey" => {
            let want = sql_ints(
                conn,
                "SELECT session_id, count(*) FROM change_events WHERE (x_m + 17) * (x_m + 17) + (y_m + 29) * (y_m + 29) + (z_m - 3) * (z_m - 3) <= 4 GROUP BY session_id ORDER BY session_id",
            );
            assert!(!want.is_empty());
            assert_eq!(json_ints(rows, &["session", "count"]), want);
            assert!(rows.iter().all(|r| r["session_name"] == format!("s{}", r["session"])));
        }
        "static_structure_in_block" => {
            let want = sql_ints(
                conn,
                &format!("SELECT count(*) FROM map_voxels WHERE {} AND eps_g < 0.5", tower.replace("AND 20", "AND 40")),
            );
            assert!(want[0][0] > 0);
            assert_eq!(json_ints(rows, &["count"]), want);
        }
        "history_of_one_spot" => {
            let ball = "(x_m + 17) * (x_m + 17) + (y_m + 31) * (y_m + 31) + (z_m - 3) * (z_m - 3) <= 1";
            assert_eq!(ids(rows, "session"), [1, 2, 3], "every session, even without events");
            for r in rows {
                let s = r["session"].as_i64().unwrap();
                let n = |cond: &str| {
                    sql_ints(
                        conn,
                        &format!("SELECT count(*) FROM change_events WHERE {ball} AND session_id = {s} AND {cond}"),
                    )[0][0]
                };
                assert_eq!(r["events"].as_i64().unwrap(), n("1"), "{r}");
                assert_eq!(r["emerged_voxels"].as_i64().unwrap(), n("category LIKE 'emerged%'"), "{r}");
                assert_eq!(r["deleted_voxels"].as_i64().unwrap(), n("category = 'deleted_overlap'"), "{r}");
                assert_eq!(r["out_of_view_voxels"].as_i64().unwrap(), n("category = 'deleted_non_overlap'"), "{r}");
                assert_eq!(r["returned_voxels"].as_i64().unwrap(), n("category = 'coexist'"), "{r}");
                let m = |c: &str| {
                    sql_ints(conn, &format!("SELECT count(*) FROM map_voxels WHERE {ball} AND {c} = {s}"))[0][0]
                };
                assert_eq!(r["first_seen_voxels"].as_i64().unwrap(), m("first_session"), "{r}");
                assert_eq!(r["last_seen_voxels"].as_i64().unwrap(), m("last_seen_session"), "{r}");
            }
            assert!(rows.iter().map(|r| r["events"].as_i64().unwrap()).sum::<i64>() > 0);
        }
        "surveys_since_march" => {
            let want = col0(
                "SELECT session_id FROM sessions WHERE coalesce(date, created_at) >= '2026-03-05' ORDER BY session_id",
            );
            assert!(!want.is_empty());
            assert_eq!(ids(rows, "session"), want);
        }
        "why_s3_did_not_merge" => {
            let want = col0(
                "SELECT candidate_id FROM loop_candidates WHERE session_id = 3 AND accepted = 0 ORDER BY candidate_id",
            );
            assert_eq!(ids(rows, "candidate"), want);
            assert!(rows.iter().all(|r| r["accepted"] == false
                && r["session"] == 3
                && r["reason"].as_str().is_some_and(|s| !s.is_empty())));
        }
        "loop_closures_per_survey" => {
            let mut st = conn.prepare("SELECT session_id, kind, count(*) FROM loop_candidates WHERE accepted = 1 GROUP BY 1, 2 ORDER BY 1, 2").unwrap();
            let want: Vec<(i64, String, i64)> =
                st.query_map([], |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?))).unwrap().map(|r| r.unwrap()).collect();
            assert!(!want.is_empty(), "the fixture has accepted loops");
            let got: Vec<(i64, String, i64)> = rows
                .iter()
                .map(|r| {
                    (
                        r["session"].as_i64().unwrap(),
                        r["kind"].as_str().unwrap().to_string(),
                        r["count"].as_i64().unwrap(),
                    )
                })
                .collect();
            assert_eq!(got, want);
        }
        "stockpile_volume_since_s2" | "stockpile_net_volume" => {
            let ev = stockpile_events(conn);
            let per = |s: i64| {
                let em = ev.iter().filter(|e| e.0 == s && e.1.starts_with("emerged")).count() as i64;
                let de = ev.iter().filter(|e| e.0 == s && e.1 == "deleted_overlap").count() as i64;
                (em, de)
            };
            let sessions: Vec<i64> = if name == "stockpile_net_volume" { vec![1, 2, 3] } else { vec![2, 3] };
            if name == "stockpile_net_volume" {
                assert_eq!(rows.len(), 1);
                let (em, de) = sessions.iter().map(|s| per(*s)).fold((0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
                assert_eq!(json_ints(rows, &["emerged_voxels", "deleted_voxels"]), [[em, de]]);
                assert!((json_f(&rows[0], "net_m3") - (em - de) as f64 * v3).abs() < 1e-6);
                assert!(em + de > 0);
            } else {
                assert_eq!(ids(rows, "session"), sessions);
                for r in rows {
                    let (em, de) = per(r["session"].as_i64().unwrap());
                    assert_eq!(
                        json_ints(std::slice::from_ref(r), &["emerged_voxels", "deleted_voxels"]),
                        [[em, de]],
                        "{r}"
                    );
                    assert!((json_f(r, "emerged_m3") - em as f64 * v3).abs() < 1e-6, "{r}");
                    assert!((json_f(r, "deleted_m3") - de as f64 * v3).abs() < 1e-6, "{r}");
                    assert!(
                        (json_f(r, "net_m3") - (json_f(r, "emerged_m3") - json_f(r, "deleted_m3"))).abs() < 1e-6,
                        "{r}"
                    );
                }
            }
        }
        "tower_b_coverage" => {
            let total = sql_ints(conn, &format!("SELECT count(*) FROM map_voxels WHERE {tower}"))[0][0];
            assert!(total > 0);
            assert_eq!(ids(rows, "session"), [1, 2, 3]);
            for r in rows {
                let s = r["session"].as_i64().unwrap();
                let want = sql_ints(conn, &format!(
                    "SELECT count(*), count(DISTINCT kx * 4194304 + ky) FROM map_voxels WHERE {tower} AND first_session <= {s} AND last_seen_session >= {s}"
                ))[0].clone();
                assert_eq!(r["voxels"].as_i64().unwrap(), want[0], "{r}");
                assert!((json_f(r, "area_m2") - want[1] as f64 * 0.04).abs() < 1e-6, "{r}");
                assert!((json_f(r, "share") - want[0] as f64 / total as f64).abs() < 1e-6, "{r}");
            }
        }
        "most_doubtful_in_tower_b" => {
            let want =
                col0(&format!("SELECT voxel_id FROM map_voxels WHERE {tower} ORDER BY eps_g DESC, voxel_id LIMIT 10"));
            assert_eq!(ids(rows, "voxel_id"), want);
            let keys: Vec<&String> = rows[0].as_object().unwrap().keys().collect();
            assert_eq!(keys.len(), 7, "only the fields asked for");
        }
        "new_permanent_structure" => {
            let mut st = conn.prepare("SELECT category, count(*) FROM map_voxels WHERE eps_g < 0.5 AND first_session >= 2 GROUP BY category ORDER BY category").unwrap();
            let want: Vec<(String, i64)> =
                st.query_map([], |r| Ok((r.get(0)?, r.get(1)?))).unwrap().map(|r| r.unwrap()).collect();
            let got: Vec<(String, i64)> =
                rows.iter().map(|r| (r["category"].as_str().unwrap().into(), r["count"].as_i64().unwrap())).collect();
            assert!(!want.is_empty());
            assert_eq!(got, want);
        }
        "removed_in_last_survey" => {
            let want = sql_ints(
                conn,
                "SELECT count(*) FROM change_events WHERE session_id = 3 AND category = 'deleted_overlap'",
            );
            assert!(want[0][0] > 0);
            assert_eq!(json_ints(rows, &["count"]), want);
        }
        "change_kinds_per_survey" => {
            let mut st = conn
                .prepare("SELECT session_id, category, count(*) FROM change_events GROUP BY 1, 2 ORDER BY 1, 2")
                .unwrap();
            let want: Vec<(i64, String, i64)> =
                st.query_map([], |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?))).unwrap().map(|r| r.unwrap()).collect();
            let got: Vec<(i64, String, i64)> = rows
                .iter()
                .map(|r| {
                    (
                        r["session"].as_i64().unwrap(),
                        r["category"].as_str().unwrap().into(),
                        r["count"].as_i64().unwrap(),
                    )
                })
                .collect();
            assert_eq!(got, want);
            let total = sql_ints(conn, "SELECT count(*) FROM change_events")[0][0];
            assert_eq!(got.iter().map(|g| g.2).sum::<i64>(), total, "counts add up to every event");
        }
        "tower_b_as_of_s2" => {
            let want = sql_ints(
                conn,
                &format!(
                    "SELECT count(*) FROM map_voxels WHERE {tower} AND first_session <= 2 AND last_seen_session >= 2"
                ),
            );
            assert!(want[0][0] > 0);
            assert_eq!(json_ints(rows, &["count"]), want);
        }
        "unsure_changes_in_tower_b" => {
            let want = col0(&format!(
                "SELECT event_id FROM change_events WHERE {tower} AND eps_g_after BETWEEN 0.3 AND 0.7 ORDER BY event_id DESC LIMIT 20"
            ));
            assert_eq!(want.len(), 20);
            assert_eq!(ids(rows, "event_id"), want);
        }
        "stockpile_changes_by_height" => {
            let ev = stockpile_events(conn);
            let want: Vec<Vec<i64>> = (1..=3)
                .map(|s| vec![s, ev.iter().filter(|e| e.0 == s && e.2 > 3.0).count() as i64])
                .filter(|v| v[1] > 0)
                .collect();
            assert!(!want.is_empty());
            assert_eq!(json_ints(rows, &["session", "count"]), want);
        }
        other => panic!("queries/{other}.seamql has no check in tests/query.rs: add one"),
    }
}

#[test]
#[cfg_attr(debug_assertions, ignore = "release only: cargo test --release")]
fn every_example_query_answers_what_sql_says() {
    let root = simulated();
    let conn = rusqlite::Connection::open_with_flags(root.join("seam.db"), rusqlite::OpenFlags::SQLITE_OPEN_READ_ONLY)
        .unwrap();
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("queries");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e == "seamql"))
        .collect();
    files.sort();
    assert!(files.len() >= 12, "{} example queries", files.len());
    // The database file and the data files' names and sizes (the store is
    // hundreds of MB: not read whole twice).
    let state = || {
        let db = blake3::hash(&std::fs::read(root.join("seam.db")).unwrap()).to_hex().to_string();
        let mut files: Vec<(String, u64)> = Vec::new();
        fn walk(dir: &Path, out: &mut Vec<(String, u64)>) {
            for e in std::fs::read_dir(dir).unwrap().flatten() {
                if e.path().is_dir() {
                    walk(&e.path(), out);
                } else {
                    out.push((e.path().display().to_string(), e.metadata().unwrap().len()));
                }
            }
        }
        walk(&root.join("data"), &mut files);
        files.sort();
        (db, files)
    };
    let before = state();
    for f in &files {
        let text = std::fs::read_to_string(f).unwrap();
        assert!(
            text.lines().next().is_some_and(|l| l.starts_with("# ") && l.len() > 10),
            "{}: a first line `# what it answers`",
            f.display()
        );
        let name = f.file_stem().unwrap().to_str().unwrap();
        let rows = run_example(root, f);
        check_example(name, &rows, &conn);
    }
    assert!(before == state(), "the store changed while answering the example queries");
}
