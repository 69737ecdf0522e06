//! Helpers shared by the end-to-end tests: drive the `seam` binary in temp
//! folders, write small synthetic sessions, and compare store contents.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The `seam` binary built for these tests.
pub fn seam() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_seam"));
    c.env_remove("SEAM_FAULT");
    c
}

/// Runs `seam args...` and returns its output.
pub fn run(args: &[&str]) -> Output {
    seam().args(args).output().expect("seam binary runs")
}

pub fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}
pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// `../shared/data` if present; otherwise prints a notice and returns None.
pub fn shared_data() -> Option<PathBuf> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data");
    if p.is_dir() {
        Some(p)
    } else {
        eprintln!("notice: ../shared/data not found, skipping this test (it runs in CI)");
        None
    }
}

/// Writes a small KITTI-layout session: `scans` scans of `points` points
/// each on a few planes around the sensor, walking 1.5 m per scan along x.
pub fn write_kitti_session(dir: &Path, scans: usize, points: usize, seed: u32) {
    std::fs::create_dir_all(dir.join("velodyne")).unwrap();
    let mut poses = String::new();
    let mut state = seed.wrapping_mul(2_654_435_761).wrapping_add(1);
    let mut rnd = || {
        state ^= state << 13;
        state ^= state >> 17;
        state ^= state << 5;
        (state as f32) / (u32::MAX as f32)
    };
    for i in 0..scans {
        let mut bytes = Vec::with_capacity(points * 16);
        for k in 0..points {
            let (a, b) = (rnd() * 20.0 - 10.0, rnd() * 4.0);
            let p = match k % 3 {
                0 => [a, 8.0, b - 1.5],
                1 => [a, -8.0, b - 1.5],
                _ => [a, rnd() * 16.0 - 8.0, -1.7],
            };
            for v in [p[0], p[1], p[2], rnd()] {
                bytes.extend_from_slice(&v.to_le_bytes());
            }
        }
        std::fs::write(dir.join(format!("velodyne/{i:06}.bin")), bytes).unwrap();
        poses.push_str(&format!("1 0 0 {} 0 1 0 0 0 0 1 0\n", i as f64 * 1.5));
    }
    std::fs::write(dir.join("poses.txt"), poses).unwrap();
}

/// Every file under a folder with its bytes, for byte-for-byte comparisons.
pub fn snapshot_files(root: &Path) -> Vec<(String, Vec<u8>)> {
    let mut out = Vec::new();
    fn walk(root: &Path, dir: &Path, out: &mut Vec<(String, Vec<u8>)>) {
        let Ok(rd) = std::fs::read_dir(dir) else { return };
        for e in rd.flatten() {
            let p = e.path();
            if p.is_dir() {
                walk(root, &p, out);
            } else {
                let rel = p.strip_prefix(root).unwrap().to_string_lossy().into_owned();
                out.push((rel, std::fs::read(&p).unwrap_or_default()));
            }
        }
    }
    walk(root, root, &mut out);
    out.sort();
    out
}

/// Columns whose values are wall-clock times and differ between runs.
const TIME_COLUMNS: &[&str] =
    &["created_at", "completed_at", "started_at", "finished_at", "wall_s", "elapsed_s", "raycast_s", "total_s"];

/// A step's details without its timings (keys ending in `_s`), which differ
/// between any two runs.
fn without_timings(v: &mut serde_json::Value) {
    if let Some(m) = v.as_object_mut() {
        m.retain(|k, _| !k.ends_with("_s"));
        m.values_mut().for_each(without_timings);
    }
}

/// The content of every table of a store's database, rows sorted, time
/// columns left out (steps keep timings out of `details_json`).
pub fn dump_db(store: &Path) -> String {
    let conn = rusqlite::Connection::open_with_flags(store.join("seam.db"), rusqlite::OpenFlags::SQLITE_OPEN_READ_ONLY)
        .expect("open seam.db");
    let mut tables: Vec<String> = conn
        .prepare("SELECT name FROM sqlite_master WHERE type = 'table' AND name NOT LIKE 'sqlite_%' ORDER BY name")
        .unwrap()
        .query_map([], |r| r.get(0))
        .unwrap()
        .map(|r| r.unwrap())
        .collect();
    tables.sort();
    let mut out = String::new();
    for t in tables {
        let mut st = conn.prepare(&format!("SELECT * FROM {t}")).unwrap();
        let cols: Vec<String> = st.column_names().map(|s| s.to_string()).collect();
        let mut rows: Vec<String> = st
            .query_map([], |r| {
                let mut cells = Vec::new();
                for (i, c) in cols.iter().enumerate() {
                    if TIME_COLUMNS.contains(&c.as_str()) {
                        continue;
                    }
                    let v: rusqlite::types::Value = r.get(i)?;
                    if let (true, rusqlite::types::Value::Text(t)) = (c == "details_json", &v)
                        && let Ok(mut j) = serde_json::from_str::<serde_json::Value>(t)
                    {
                        without_timings(&mut j);
                        cells.push(format!("{c}={j}"));
                        continue;
                    }
                    cells.push(format!("{c}={v:?}"));
                }
                Ok(cells.join(" "))
            })
            .unwrap()
            .map(|r| r.unwrap())
            .collect();
        // The store's creation time differs between any two stores.
        rows.retain(|r| !r.starts_with("key=Text(\"created_at\")"));
        rows.sort();
        out.push_str(&format!("## {t} ({} rows)\n", rows.len()));
        for r in rows {
            out.push_str(&r);
            out.push('\n');
        }
    }
    out
}

/// The store's database content plus its data files' bytes.
pub fn store_state(store: &Path) -> (String, Vec<(String, Vec<u8>)>) {
    (dump_db(store), snapshot_files(&store.join("data")))
}

/// Creates a store at `path` through the binary.
pub fn init_store(path: &Path) {
    let o = run(&["init", path.to_str().unwrap()]);
    assert!(o.status.success(), "init failed: {}", stderr(&o));
}

/// Asserts two store states are equal, printing only the lines that differ.
pub fn assert_same_state(want: &(String, Vec<(String, Vec<u8>)>), got: &(String, Vec<(String, Vec<u8>)>), what: &str) {
    if want.0 != got.0 {
        let (w, g): (Vec<&str>, Vec<&str>) = (want.0.lines().collect(), got.0.lines().collect());
        let only_w: Vec<&&str> = w.iter().filter(|l| !g.contains(l)).take(8).collect();
        let only_g: Vec<&&str> = g.iter().filter(|l| !w.contains(l)).take(8).collect();
        panic!("database differs {what}\nonly in expected: {only_w:#?}\nonly in actual: {only_g:#?}");
    }
    let names = |v: &Vec<(String, Vec<u8>)>| v.iter().map(|f| f.0.clone()).collect::<Vec<_>>();
    assert_eq!(names(&want.1), names(&got.1), "data file names differ {what}");
    for (a, b) in want.1.iter().zip(&got.1) {
        assert!(a.1 == b.1, "data file {} differs {what}", a.0);
    }
}

/// Runs `tests/clients/check_exports.py OUT [--expect EXPECT]` (pyarrow,
/// DuckDB and laspy reading an export) and returns whether it ran. Without
/// python3 or its modules it prints a notice and returns false, unless `CI`
/// is set: CI must really run it, so there a missing reader is a failure.
pub fn run_client_check(out: &Path, expect: Option<&Path>) -> bool {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/clients/check_exports.py");
    let mut cmd = Command::new("python3");
    cmd.arg(&script).arg(out);
    if let Some(e) = expect {
        cmd.arg("--expect").arg(e);
    }
    let ci = std::env::var_os("CI").is_some();
    let o = match cmd.output() {
        Ok(o) => o,
        Err(e) => {
            assert!(!ci, "CI is set but python3 cannot run: {e}");
            eprintln!("notice: python3 not found ({e}); skipping the client check (CI runs it)");
            return false;
        }
    };
    let text = format!("{}{}", stdout(&o), stderr(&o));
    if o.status.code() == Some(77) {
        assert!(!ci, "CI is set but the readers are missing (.ci/run installs them):\n{text}");
        eprintln!("notice: {}; skipping the client check (CI runs it)", text.trim());
        return false;
    }
    assert!(o.status.success(), "client check failed:\n{text}");
    eprintln!("{text}");
    true
}

/// `seam simulate OUT --sessions N --keyframes K --seed S [extra…] --format
/// json`: the simulator's JSON summary (`sessions[k].dir`, `.points`, …).
pub fn simulate(out: &Path, sessions: usize, keyframes: usize, seed: u64, extra: &[&str]) -> serde_json::Value {
    let (n, k, seed) = (sessions.to_string(), keyframes.to_string(), seed.to_string());
    let mut args = vec!["simulate", out.to_str().unwrap(), "--sessions", &n, "--keyframes", &k, "--seed", &seed];
    args.extend_from_slice(extra);
    args.extend_from_slice(&["--format", "json"]);
    let o = run(&args);
    assert!(o.status.success(), "seam {args:?}: {}", stderr(&o));
    serde_json::from_str(&stdout(&o)).unwrap()
}

/// `seam ingest STORE DIR --quiet` for every session of a [`simulate`] summary, in order.
pub fn ingest_all(store: &Path, summary: &serde_json::Value) {
    for s in summary["sessions"].as_array().unwrap() {
        let o = run(&["ingest", store.to_str().unwrap(), s["dir"].as_str().unwrap(), "--quiet"]);
        assert!(o.status.success(), "{}", stderr(&o));
    }
}

/// A session row with no folder behind it, named and hashed `name`, for
/// tests that build a store by hand; set the other fields with `..`.
pub fn bare_session(name: &str) -> seam::store::NewSession<'_> {
    seam::store::NewSession {
        name,
        content_hash: name,
        source_dir: "/nowhere",
        layout: "kitti",
        date: None,
        sensor_model: None,
        fov_json: None,
        keyframe_count: 0,
        point_count: 0,
    }
}
