//! Latency of `seam query` on a store with a million change events.
//!
//! ```text
//! cargo run --release --example query_bench -- [--events 1000000] [--sessions 10] [--site 200]
//!     [--repeats 9] [--dir DIR]
//! ```
//!
//! Fills a fresh store (in a temp folder, or `--dir`, kept) through the
//! store's own insert path (`insert_change_events`, which also indexes the
//! tiles) with `--events` change events over a `--site` × `--site` m site and
//! `--sessions` sessions (none in the first, as in a real store): 70 % on
//! 400 random "objects" (boxes of 1-12 m, up to 8 m high), 30 % on the
//! ground, on a 0.2 m voxel grid. Then times `changes in bbox:... since:sN`
//! for several box sizes and sessions, and a ball and a polygon zone, through
//! `query::compile` + `query::execute` on a read-only connection, as `seam
//! query` runs them: cold (first run on a fresh connection; the OS file cache
//! is warm) and warm (median of `--repeats`). Prints ms and rows per query,
//! SQLite's plan of the first, and the store API's `change_events_in` on the
//! same box for reference.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use seam::change::{Category, ChangeEvent};
use seam::geometry::polygon::Polygon;
use seam::query::{self, Catalog};
use seam::store::{
    InitOptions, NewSession, SessionId, Store, StoreError, WorldBox, ZoneShape, change_events_in, insert_change_events,
    insert_session, insert_zone,
};
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

struct Args {
    events: usize,
    sessions: i64,
    site_m: f64,
    repeats: usize,
    dir: Option<PathBuf>,
}

fn parse_args() -> Result<Args, String> {
    let mut a = Args { events: 1_000_000, sessions: 10, site_m: 200.0, repeats: 9, dir: None };
    let mut it = std::env::args().skip(1);
    while let Some(k) = it.next() {
        let mut v = || it.next().ok_or_else(|| format!("{k} needs a value"));
        let num = |s: String| s.parse::<f64>().map_err(|_| format!("{k}: {s:?} is not a number"));
        match k.as_str() {
            "--events" => a.events = num(v()?)? as usize,
            "--sessions" => a.sessions = num(v()?)? as i64,
            "--site" => a.site_m = num(v()?)?,
            "--repeats" => a.repeats = (num(v()?)? as usize).max(1),
            "--dir" => a.dir = Some(PathBuf::from(v()?)),
            _ => return Err(format!("unknown option {k}")),
        }
    }
    if a.sessions < 2 || a.events == 0 || a.site_m <= 0.0 {
        return Err("need --sessions ≥ 2, --events ≥ 1 and a positive --site".into());
    }
    Ok(a)
}

/// Events of one session: on objects and on the ground, voxel centres.
fn events_of(
    rng: &mut ChaCha8Rng,
    session: i64,
    n: usize,
    objects: &[([f64; 3], [f64; 3])],
    site: f64,
) -> Vec<ChangeEvent> {
    let v = 0.2;
    let snap = |x: f64| (x / v).floor() * v + v / 2.0;
    (0..n)
        .map(|k| {
            let p = if rng.random_bool(0.7) {
                let (lo, hi) = objects[rng.random_range(0..objects.len())];
                [0, 1, 2].map(|i| rng.random_range(lo[i]..hi[i]))
            } else {
                [rng.random_range(0.0..site), rng.random_range(0.0..site), rng.random_range(0.0..0.4)]
            };
            let category = Category::ALL[1 + k % 5];
            ChangeEvent {
                session_id: session,
                voxel_id: rng.random_range(0..5_000_000),
                xyz_m: p.map(snap),
                category,
                eps_g_before: (!k.is_multiple_of(3)).then(|| rng.random_range(0.1..0.9)),
                eps_g_after: rng.random_range(0.1..0.9),
            }
        })
        .collect()
}

fn fill(root: &std::path::Path, a: &Args) -> Result<(), StoreError> {
    let opts = InitOptions { site_name: "bench".into(), crs: "local".into(), voxel_size_m: 0.2 };
    let mut store = Store::create(root, &opts)?;
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let objects: Vec<([f64; 3], [f64; 3])> = (0..400)
        .map(|_| {
            let size = [rng.random_range(1.0..12.0), rng.random_range(1.0..12.0), rng.random_range(0.5..8.0)];
            let lo = [rng.random_range(0.0..a.site_m - size[0]), rng.random_range(0.0..a.site_m - size[1]), 0.0];
            (lo, [lo[0] + size[0], lo[1] + size[1], size[2]])
        })
        .collect();
    let per_session = a.events / (a.sessions as usize - 1);
    let t = Instant::now();
    for s in 1..=a.sessions {
        let name = format!("s{s}");
        let date = format!("2026-{:02}-{:02}", 1 + (s - 1) / 28, 1 + (s - 1) % 28);
        let n = if s == 1 { 0 } else { per_session };
        let events = events_of(&mut rng, s, n, &objects, a.site_m);
        store.transaction(|tx| -> Result<(), StoreError> {
            let sid = insert_session(
                tx,
                &NewSession {
                    name: &name,
                    content_hash: &name,
                    source_dir: "/bench",
                    layout: "kitti",
                    date: Some(&date),
                    sensor_model: None,
                    fov_json: None,
                    keyframe_count: 1,
                    point_count: 1,
                },
            )?;
            assert_eq!(sid, SessionId(s));
            insert_change_events(tx, &events)
        })?;
    }
    let c = a.site_m / 2.0;
    let wkt = format!(
        "POLYGON(({} {}, {} {}, {} {}, {} {}))",
        c - 10.0,
        c - 10.0,
        c + 10.0,
        c - 8.0,
        c + 6.0,
        c + 10.0,
        c - 9.0,
        c + 6.0
    );
    let polygon = Polygon::from_wkt(&wkt).map_err(|m| StoreError::Corrupt { path: root.into(), message: m })?;
    store.transaction(|tx| insert_zone(tx, "pad", &ZoneShape::Polygon { polygon, min_z_m: -1.0, max_z_m: 12.0 }))?;
    eprintln!("filled {} events in {:.1} s", per_session * (a.sessions as usize - 1), t.elapsed().as_secs_f64());
    Ok(())
}

/// (cold ms, warm median ms, rows) of one query.
fn time_query(root: &std::path::Path, text: &str, repeats: usize) -> Result<(f64, f64, usize), String> {
    let store = Store::open_read_only(root).map_err(|e| e.to_string())?;
    let cat = Catalog::load(&store, 0.5).map_err(|e| e.to_string())?;
    let run = || -> Result<(f64, usize), String> {
        let t = Instant::now();
        let plan = query::compile(text, &cat).map_err(|e| e.render(text, false))?;
        let r = query::execute(store.conn(), &plan).map_err(|e| e.to_string())?;
        Ok((t.elapsed().as_secs_f64() * 1e3, r.rows.len()))
    };
    let (cold, rows) = run()?;
    let mut warm: Vec<f64> = (0..repeats).map(|_| run().map(|r| r.0)).collect::<Result<_, _>>()?;
    warm.sort_by(f64::total_cmp);
    Ok((cold, warm[warm.len() / 2], rows))
}

fn main() -> ExitCode {
    let a = match parse_args() {
        Ok(a) => a,
        Err(m) => {
            eprintln!("query_bench: {m}");
            return ExitCode::from(2);
        }
    };
    let tmp = tempfile::tempdir();
    let root = match (&a.dir, &tmp) {
        (Some(d), _) => d.clone(),
        (None, Ok(t)) => t.path().join("bench.seam"),
        (None, Err(e)) => {
            eprintln!("query_bench: temp folder: {e}");
            return ExitCode::FAILURE;
        }
    };
    if !root.join("seam.db").exists()
        && let Err(e) = fill(&root, &a)
    {
        eprintln!("query_bench: {e}");
        return ExitCode::FAILURE;
    }
    let c = a.site_m / 2.0;
    let bbox = |half: f64| format!("bbox:{},{},-1,{},{},12", c - half, c - half, c + half, c + half);
    let mid = (a.sessions + 2) / 2;
    let mut queries: Vec<String> = Vec::new();
    for half in [5.0, 10.0, 25.0] {
        for since in [2, mid, a.sessions] {
            queries.push(format!("changes in {} since:s{since}", bbox(half)));
        }
    }
    queries.push(format!("changes in {} since:s{mid}", bbox(a.site_m)));
    queries.push(format!("changes in {} since:s{mid} | count", bbox(a.site_m)));
    queries.push(format!("changes near:{c},{c},1 r:5 since:s{mid}"));
    queries.push(format!("changes in zone:pad since:s{mid}"));
    queries.push(format!("changes in {} since:s{mid} | count by session", bbox(10.0)));
    queries.push(format!("volume in {} since:s{mid}", bbox(10.0)));

    println!("{:>9} {:>9} {:>9}  query", "cold ms", "warm ms", "rows");
    for q in &queries {
        match time_query(&root, q, a.repeats) {
            Ok((cold, warm, rows)) => println!("{cold:>9.2} {warm:>9.2} {rows:>9}  {q}"),
            Err(e) => {
                eprintln!("query_bench: {q}: {e}");
                return ExitCode::FAILURE;
            }
        }
    }

    // SQLite's plan of the first query, and the store API on the same box.
    let Ok(store) = Store::open_read_only(&root) else { return ExitCode::FAILURE };
    let Ok(cat) = Catalog::load(&store, 0.5) else { return ExitCode::FAILURE };
    if let Ok(plan) = query::compile(&queries[3], &cat)
        && let Ok(lines) = query::sqlite_plan(store.conn(), &plan)
    {
        println!("\nSQLite plan of `{}`:", queries[3]);
        for l in lines {
            println!("  {l}");
        }
    }
    let b = WorldBox { min_m: [c - 10.0, c - 10.0, -1.0], max_m: [c + 10.0, c + 10.0, 12.0] };
    let mut times = Vec::new();
    let mut n = 0;
    for _ in 0..a.repeats {
        let t = Instant::now();
        n = change_events_in(store.conn(), &b, mid).map(|v| v.len()).unwrap_or(0);
        times.push(t.elapsed().as_secs_f64() * 1e3);
    }
    times.sort_by(f64::total_cmp);
    println!("\nstore::change_events_in, same 20 m box since s{mid}: {:.2} ms warm, {n} rows", times[times.len() / 2]);
    ExitCode::SUCCESS
}
