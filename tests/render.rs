//! `seam render` and `seam report` end to end.
//!
//! Most tests draw a small synthetic store whose every voxel, change event
//! and keyframe is placed by hand (a ramp of ground, a tower, an ephemeral
//! block, a patch of events per category, three straight trajectories), so
//! pixels can be checked against the colour maps at known places. One
//! release-only test renders a simulated site ingested through the CLI.

mod common;
use base64::Engine;
use common::*;
use seam::change::{Category, ChangeEvent, LifelongMap, MapVoxel, SessionChanges};
use seam::geometry::{Pose, VoxelKey};
use seam::render::colormap::{CATEGORY_STYLES, PLASMA, Rgb, VIRIDIS, category_style, session_colour};
use seam::store::{
    NewKeyframe, NewSession, SessionId, Store, StoreError, insert_change_events, insert_graph_version,
    insert_keyframes, insert_session, insert_session_changes, insert_submaps, replace_lifelong_map,
    set_session_complete,
};
use std::path::{Path, PathBuf};

const VOXEL_M: f64 = 0.2;
/// Ground: 100 × 100 voxels over x, y ∈ [0, 20) m, z rising with x.
const GROUND: usize = 100;
fn ground_z(x: f64) -> f64 {
    0.1 + 0.05 * x
}
/// The tower: x, y ∈ [4, 6), 25 voxels high; its top is the highest voxel.
const TOWER_TOP_Z: f64 = 5.1;
/// An ephemeral block (ε_g at the clamp's top): x, y ∈ [14, 16), z = 1.5.
const EPHEMERAL_EPS_G: f32 = 0.9;

/// A 5 × 5 patch of change events: (session, category, first voxel index x, y).
const PATCHES: [(i64, Category, usize, usize); 6] = [
    (2, Category::EmergedOverlap, 40, 60),
    (2, Category::DeletedOverlap, 60, 20),
    (3, Category::Coexist, 10, 80),
    (3, Category::EmergedNonOverlap, 85, 40),
    (3, Category::DeletedNonOverlap, 85, 5),
    (3, Category::EmergedOverlap, 30, 85),
];
/// Trajectories: five keyframes each along y = this, from x = 1 to 19.
const TRACK_Y: [f64; 3] = [1.0, 10.0, 19.0];

fn centre(i: usize) -> f64 {
    i as f64 * VOXEL_M + VOXEL_M / 2.0
}

fn voxel(id: i64, key: [i32; 3], xyz_m: [f64; 3], eps_g: f32) -> MapVoxel {
    MapVoxel {
        voxel_id: id,
        key: VoxelKey(key),
        xyz_m,
        eps_g,
        eps_l: 0.1,
        points: 3,
        first_session: 1,
        last_seen_session: 3,
        category: Category::Initial,
        category_session: 1,
        owner_session: 1,
        owner_keyframe: 0,
        spread_m2: seam::geometry::UNKNOWN_SPREAD,
    }
}

/// The synthetic map: ground, tower, ephemeral block (unique keys; the
/// positions, not the keys, are what is drawn).
fn map_voxels() -> Vec<MapVoxel> {
    let mut v = Vec::new();
    for ix in 0..GROUND {
        for iy in 0..GROUND {
            let x = centre(ix);
            v.push(voxel(v.len() as i64 + 1, [ix as i32, iy as i32, 0], [x, centre(iy), ground_z(x)], 0.1));
        }
    }
    for ix in 20..30 {
        for iy in 20..30 {
            for k in 1..=25 {
                let z = 0.1 + k as f64 * 0.2;
                v.push(voxel(v.len() as i64 + 1, [ix, iy, 10 + k], [centre(ix as usize), centre(iy as usize), z], 0.1));
            }
        }
    }
    for ix in 70..80 {
        for iy in 70..80 {
            let p = [centre(ix as usize), centre(iy as usize), 1.5];
            v.push(voxel(v.len() as i64 + 1, [ix, iy, 50], p, EPHEMERAL_EPS_G));
        }
    }
    v
}

fn events_of(session: i64) -> Vec<ChangeEvent> {
    let mut out = Vec::new();
    for &(s, category, x0, y0) in PATCHES.iter().filter(|p| p.0 == session) {
        for ix in x0..x0 + 5 {
            for iy in y0..y0 + 5 {
                out.push(ChangeEvent {
                    session_id: s,
                    voxel_id: 100_000 + out.len() as i64,
                    xyz_m: [centre(ix), centre(iy), 0.5],
                    category,
                    eps_g_before: None,
                    eps_g_after: 0.5,
                });
            }
        }
    }
    out
}

/// Session `i`'s counts as the store keeps them (made-up but distinct).
fn session_changes(i: i64) -> SessionChanges {
    let n = |k: i64| if i == 1 { 0 } else { (100 * i + k) as usize };
    SessionChanges {
        coexist: n(1),
        deleted_overlap: n(2),
        deleted_non_overlap: n(3),
        emerged_overlap: n(4),
        emerged_non_overlap: n(5),
        events: events_of(i).len(),
        merged_on_move: 0,
        lifelong_voxels: 10_000 + i as usize,
        static_voxels: 9_000 + i as usize,
    }
}

/// Builds the synthetic store at `tmp/site.seam` (three complete sessions
/// "s1", "north walk", "s3"; a graph version with their trajectories; the
/// map and events above; DOR rows for the first two).
fn synthetic_store(tmp: &Path) -> PathBuf {
    let root = tmp.join("site.seam");
    init_store(&root);
    let mut store = Store::open(&root).unwrap();
    store
        .transaction(|tx| -> Result<(), StoreError> {
            tx.execute(
                "INSERT INTO files(file_id, rel_path, kind, size_bytes, blake3, row_count, created_at)
                 VALUES (1, 'data/none.parquet', 'scans', 0, '', 0, '2026-01-01T00:00:00Z')",
                [],
            )
            .unwrap();
            let mut anchors = Vec::new();
            let mut locals = Vec::new();
            for (i, name) in ["s1", "north walk", "s3"].iter().enumerate() {
                let date = format!("2026-0{}-01", i + 1);
                let sid = insert_session(
                    tx,
                    &NewSession {
                        date: Some(&date),
                        sensor_model: Some("os1-64"),
                        keyframe_count: 5,
                        point_count: 1000 * (i as i64 + 1),
                        ..bare_session(name)
                    },
                )?;
                let kfs: Vec<NewKeyframe> = (0..5)
                    .map(|k| NewKeyframe {
                        keyframe_index: k,
                        source_file: format!("{k:06}.bin"),
                        stamp_s: None,
                        point_count: 200,
                        scan_row_group: k,
                        t_session_keyframe: Pose::identity(),
                    })
                    .collect();
                insert_keyframes(tx, sid, 1, &kfs)?;
                let sub = insert_submaps(tx, sid, &[(0, 4, 18.0)])?[0];
                tx.execute("UPDATE keyframes SET submap_id = ?1 WHERE session_id = ?2", [sub.0, sid.0]).unwrap();
                anchors.push((sub, Pose::identity()));
                let mut st = tx.prepare("SELECT keyframe_id FROM keyframes WHERE session_id = ?1 ORDER BY keyframe_index").unwrap();
                let ids: Vec<i64> = st.query_map([sid.0], |r| r.get(0)).unwrap().map(|r| r.unwrap()).collect();
                for (k, id) in ids.iter().enumerate() {
                    let p = Pose::translation(1.0 + 4.5 * k as f64, TRACK_Y[i], 0.0);
                    locals.push((seam::store::KeyframeId(*id), p));
                }
                set_session_complete(tx, sid)?;
                if i < 2 {
                    tx.execute(
                        "INSERT INTO graph_versions(graph_version, session_id, mode, created_at) VALUES (?1, ?1, 'odometry', '')",
                        [sid.0],
                    )
                    .unwrap();
                    tx.execute(
                        "INSERT INTO session_dor VALUES (?1, ?1, 'directional', ?2, ?3, 0, 0, 0, 0, 0, 0)",
                        [sid.0, 1000 * (i as i64 + 1), 37 * (i as i64 + 1)],
                    )
                    .unwrap();
                }
            }
            let version = insert_graph_version(tx, SessionId(3), "submap", "{}", None, &anchors, &locals)?;
            for s in 1..=3 {
                insert_change_events(tx, &events_of(s))?;
                insert_session_changes(tx, SessionId(s), version, &session_changes(s))?;
            }
            let (map, merged) = LifelongMap::from_voxels(map_voxels(), VOXEL_M);
            assert_eq!(merged, 0, "keys are unique");
            replace_lifelong_map(tx, &map, version, SessionId(3))
        })
        .unwrap();
    drop(store);
    root
}

/// A decoded RGB picture.
struct Png {
    w: u32,
    h: u32,
    rgb: Vec<u8>,
}

impl Png {
    fn decode(bytes: &[u8]) -> Png {
        let mut r = png::Decoder::new(std::io::Cursor::new(bytes)).read_info().expect("a PNG");
        let mut buf = vec![0; r.output_buffer_size().unwrap()];
        let info = r.next_frame(&mut buf).unwrap();
        assert_eq!(info.color_type, png::ColorType::Rgb);
        buf.truncate(info.buffer_size());
        Png { w: info.width, h: info.height, rgb: buf }
    }
    fn read(path: &Path) -> Png {
        Png::decode(&std::fs::read(path).unwrap())
    }
    fn at(&self, x: u32, y: u32) -> Rgb {
        let i = (y * self.w + x) as usize * 3;
        Rgb([self.rgb[i], self.rgb[i + 1], self.rgb[i + 2]])
    }
    /// Pixels in a rectangle darker than mid-grey (text, lines, bars).
    fn ink(&self, x0: u32, y0: u32, x1: u32, y1: u32) -> usize {
        let mut n = 0;
        for y in y0..y1.min(self.h) {
            for x in x0..x1.min(self.w) {
                let c = self.at(x, y).0;
                if (c[0] as u32 + c[1] as u32 + c[2] as u32) < 3 * 110 {
                    n += 1;
                }
            }
        }
        n
    }
}

/// Where a world point lands, from `--format json`'s map area and world box.
fn pixel_of(j: &serde_json::Value, x: f64, y: f64) -> (u32, u32) {
    let a: Vec<f64> = j["map_area_px"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
    let b: Vec<f64> = j["world_bbox_m"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
    let m = j["m_per_px"].as_f64().unwrap();
    ((a[0] + (x - b[0]) / m).floor() as u32, (a[1] + (b[3] - y) / m).floor() as u32)
}

/// Renders through the CLI with `--format json`; returns the summary and picture.
fn render(root: &Path, out: &Path, extra: &[&str]) -> (serde_json::Value, Png) {
    let mut args = vec!["render", root.to_str().unwrap(), "-o", out.to_str().unwrap(), "--format", "json", "-q"];
    args.extend_from_slice(extra);
    let o = run(&args);
    assert!(o.status.success(), "{extra:?}: {}", stderr(&o));
    let j: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    let png = Png::read(out);
    assert_eq!((png.w as u64, png.h as u64), (j["width_px"].as_u64().unwrap(), j["height_px"].as_u64().unwrap()));
    (j, png)
}

fn close(a: Rgb, b: Rgb, tol: i32) -> bool {
    (0..3).all(|c| (a.0[c] as i32 - b.0[c] as i32).abs() <= tol)
}

/// The folder holds exactly these file names (no temporary leftovers).
fn assert_files(dir: &Path, want: &[&str]) {
    let mut got: Vec<String> =
        std::fs::read_dir(dir).unwrap().flatten().map(|e| e.file_name().to_string_lossy().into_owned()).collect();
    got.sort();
    let mut want: Vec<String> = want.iter().map(|s| s.to_string()).collect();
    want.sort();
    assert_eq!(got, want);
}

#[test]
fn static_map_is_coloured_by_height_with_legend_and_scale_bar() {
    let tmp = tempfile::tempdir().unwrap();
    let root = synthetic_store(tmp.path());
    let out = tmp.path().join("pics");
    std::fs::create_dir(&out).unwrap();
    let (j, png) = render(&root, &out.join("static.png"), &["--what", "static", "--width", "1000"]);
    assert_eq!(png.w, 1000);
    assert_eq!(j["what"], "static");
    assert_eq!(j["drawn"], (GROUND * GROUND + 100 * 25) as u64, "the ephemeral block is not static");
    assert_eq!(j["colormap"], "viridis");
    // The tower's top is above the colour range's top: the LUT's top colour.
    let range: Vec<f32> = j["colour_range"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap() as f32).collect();
    assert!((range[1] as f64) < TOWER_TOP_Z && range[0] < range[1], "{range:?}");
    let (tx, ty) = pixel_of(&j, 5.0, 5.0);
    assert_eq!(png.at(tx, ty), VIRIDIS.high(), "tower top");
    // The lowest ground (x ≈ 0) is at or below the range's bottom.
    let (gx, gy) = pixel_of(&j, 0.1, 10.0);
    assert_eq!(png.at(gx, gy), VIRIDIS.low(), "lowest ground");
    // Mid-ramp ground has the colour of its height on the range.
    let (mx, my) = pixel_of(&j, 10.1, 10.1);
    assert!(close(png.at(mx, my), VIRIDIS.of(ground_z(10.1) as f32, range[0], range[1]), 3), "mid ground");
    // Under the ephemeral block the static map shows the ground, not the block.
    let (ex, ey) = pixel_of(&j, 15.1, 15.1);
    assert!(close(png.at(ex, ey), VIRIDIS.of(ground_z(15.1) as f32, range[0], range[1]), 3));
    // Outside the map: background.
    let (ox, oy) = pixel_of(&j, -1.0, -1.0);
    assert_eq!(png.at(ox, oy), Rgb::WHITE);
    // 0.2 m voxels fill the ground without holes: every pixel of a 2 m box is drawn.
    let (ax, ay) = pixel_of(&j, 8.0, 12.0);
    let (bx, by) = pixel_of(&j, 10.0, 10.0);
    for y in ay..by {
        for x in ax..bx {
            assert_ne!(png.at(x, y), Rgb::WHITE, "hole at ({x}, {y})");
        }
    }
    // The legend panel (right of the map) has ink: text, colour bar, scale bar.
    let a = j["map_area_px"].as_array().unwrap();
    let right = (a[0].as_u64().unwrap() + a[2].as_u64().unwrap()) as u32;
    assert!(png.ink(right + 5, 0, png.w, png.h) > 1500, "legend ink: {}", png.ink(right + 5, 0, png.w, png.h));
    // The title band has text.
    assert!(png.ink(0, 0, png.w, a[1].as_u64().unwrap() as u32) > 500);
    // The scale bar is a round length no longer than the legend is wide.
    let bar = j["scale_bar_m"].as_f64().unwrap();
    let mant = bar / 10f64.powf(bar.log10().floor());
    assert!([1.0, 2.0, 5.0].iter().any(|m| (mant - m).abs() < 1e-9), "{bar}");
    assert!(bar / j["m_per_px"].as_f64().unwrap() <= (png.w - right) as f64);
    assert_files(&out, &["static.png"]);
}

#[test]
fn lifelong_map_is_coloured_by_the_largest_eps_g() {
    let tmp = tempfile::tempdir().unwrap();
    let root = synthetic_store(tmp.path());
    let path = tmp.path().join("lifelong.png");
    let (j, png) = render(&root, &path, &["--what", "lifelong", "--width", "900"]);
    assert_eq!(j["drawn"], (GROUND * GROUND + 100 * 25 + 100) as u64);
    assert_eq!(j["colormap"], "plasma");
    assert_eq!(j["colour_range"], serde_json::json!([0.1f32 as f64, 0.9f32 as f64]));
    // The ephemeral block over static ground: its ε_g (the LUT's top) wins.
    let (ex, ey) = pixel_of(&j, 15.0, 15.0);
    assert_eq!(png.at(ex, ey), PLASMA.high());
    assert_eq!(png.at(ex, ey), PLASMA.of(EPHEMERAL_EPS_G, 0.1, 0.9));
    // Static ground and the tower: the bottom.
    for (x, y) in [(5.0, 5.0), (10.0, 2.0)] {
        let (px, py) = pixel_of(&j, x, y);
        assert_eq!(png.at(px, py), PLASMA.low(), "({x}, {y})");
    }
}

#[test]
fn changes_carry_category_colours_over_a_grey_static_map() {
    let tmp = tempfile::tempdir().unwrap();
    let root = synthetic_store(tmp.path());
    let path = tmp.path().join("changes.png");
    let patch_centre = |x0: usize, y0: usize| (centre(x0 + 2), centre(y0 + 2));

    // Default: every session from the second on.
    let (j, png) = render(&root, &path, &["--what", "changes", "--width", "1000"]);
    assert_eq!(j["sessions"], "north walk–s3");
    assert_eq!(j["drawn"], (PATCHES.len() * 25) as u64);
    for &(_, category, x0, y0) in &PATCHES {
        let (x, y) = patch_centre(x0, y0);
        let (px, py) = pixel_of(&j, x, y);
        assert_eq!(png.at(px, py), category_style(category).unwrap().colour, "{category} at ({x}, {y})");
    }
    let counts: Vec<(String, u64)> = j["categories"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| (c["category"].as_str().unwrap().to_string(), c["events"].as_u64().unwrap()))
        .collect();
    assert_eq!(counts.len(), CATEGORY_STYLES.len());
    for (cat, n) in &counts {
        let want = PATCHES.iter().filter(|p| p.1.as_str() == cat).count() as u64 * 25;
        assert_eq!(*n, want, "{cat}");
    }
    // Elsewhere on the map: the grey context (r = g = b), not a category.
    let (gx, gy) = pixel_of(&j, 12.0, 12.0);
    let g = png.at(gx, gy);
    assert!(g.0[0] == g.0[1] && g.0[1] == g.0[2] && g.0[0] > 150 && g.0[0] < 250, "{g:?}");

    // One session, by name: only its patches.
    let (j, png) = render(&root, &path, &["--what", "changes", "--session", "north walk"]);
    assert_eq!(j["sessions"], "north walk");
    assert_eq!(j["drawn"], 50);
    for &(s, category, x0, y0) in &PATCHES {
        let (x, y) = patch_centre(x0, y0);
        let (px, py) = pixel_of(&j, x, y);
        let c = png.at(px, py);
        assert_eq!(c == category_style(category).unwrap().colour, s == 2, "{category} of session {s}: {c:?}");
    }
    // From the third on, by number.
    let (j, _) = render(&root, &path, &["--what", "changes", "--since", "s3"]);
    assert_eq!(j["drawn"], 100);
    // The first session has no changes: an empty picture that says why.
    let (j, png) = render(&root, &path, &["--what", "changes", "--session", "1"]);
    assert_eq!(j["drawn"], 0);
    let a: Vec<u32> = j["map_area_px"].as_array().unwrap().iter().map(|v| v.as_u64().unwrap() as u32).collect();
    assert!(png.ink(a[0], a[1] + a[3] / 3, a[0] + a[2], a[1] + 2 * a[3] / 3) > 100, "the note is written on the map");
}

#[test]
fn trajectories_are_drawn_per_session_with_start_markers() {
    let tmp = tempfile::tempdir().unwrap();
    let root = synthetic_store(tmp.path());
    let path = tmp.path().join("t.png");
    let (j, png) = render(&root, &path, &["--what", "trajectories"]);
    assert_eq!(png.w, 1600, "the default width");
    assert_eq!(j["drawn"], 15);
    let t = j["trajectories"].as_array().unwrap();
    let names: Vec<&str> = t.iter().map(|t| t["name"].as_str().unwrap()).collect();
    assert_eq!(names, ["s1", "north walk", "s3"]);
    for (i, tr) in t.iter().enumerate() {
        assert_eq!(tr["length_m"], 18.0);
        assert_eq!(tr["colour"], session_colour(i).hex());
        // The start disc and a point half way between two keyframes.
        for x in [1.0, 3.25] {
            let (px, py) = pixel_of(&j, x, TRACK_Y[i]);
            assert_eq!(png.at(px, py), session_colour(i), "session {} at x = {x}", i + 1);
        }
    }
    // One session only.
    let (j, png) = render(&root, &path, &["--what", "trajectories", "--session", "3"]);
    assert_eq!(j["trajectories"].as_array().unwrap().len(), 1);
    let (px, py) = pixel_of(&j, 3.25, TRACK_Y[0]);
    assert_ne!(png.at(px, py), session_colour(0), "s1 is not drawn");
    let (px, py) = pixel_of(&j, 3.25, TRACK_Y[2]);
    assert_eq!(png.at(px, py), session_colour(2), "s3 keeps its colour");
}

#[test]
fn bbox_crops_and_zooms() {
    let tmp = tempfile::tempdir().unwrap();
    let root = synthetic_store(tmp.path());
    let path = tmp.path().join("zoom.png");
    // Negative coordinates are values, not flags.
    let (j, _) = render(&root, &path, &["--what", "static", "--bbox", "-5,-5.5,7,7"]);
    assert!(j["world_bbox_m"][1].as_f64().unwrap() <= -5.5);
    let (j, png) = render(&root, &path, &["--what", "static", "--bbox", "3,3,7,7", "--width", "800"]);
    let b: Vec<f64> = j["world_bbox_m"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
    assert!(b[0] <= 3.0 && b[1] <= 3.0 && b[2] >= 7.0 && b[3] >= 7.0, "{b:?}");
    assert!(b[2] - b[0] < 12.0, "zoomed in: {b:?}");
    let m = j["m_per_px"].as_f64().unwrap();
    assert!(m < 0.02, "{m}");
    // Only voxels inside the box are read.
    assert!(j["drawn"].as_u64().unwrap() < 5000);
    // The tower fills the middle with the top colour, big enough to see.
    let (px, py) = pixel_of(&j, 5.0, 5.0);
    assert_eq!(png.at(px, py), VIRIDIS.high());
    let (qx, qy) = pixel_of(&j, 5.9, 5.9);
    assert_eq!(png.at(qx, qy), VIRIDIS.high());
    // Voxels are squares of their size: 0.2 m is many pixels here.
    assert!(VOXEL_M / m > 10.0);
}

#[test]
fn bad_inputs_write_nothing_and_say_what_exists() {
    let tmp = tempfile::tempdir().unwrap();
    let root = synthetic_store(tmp.path());
    let r = root.to_str().unwrap();
    let out = tmp.path().join("out");
    std::fs::create_dir(&out).unwrap();
    // An earlier picture must survive every failed run untouched.
    std::fs::write(out.join("map.png"), b"earlier").unwrap();
    let o = out.join("map.png");
    let o = o.to_str().unwrap();
    let cases: &[(&[&str], i32, &[&str])] = &[
        (&["render", r, "--what", "heights", "-o", o], 2, &["heights", "static", "trajectories"]),
        (
            &["render", r, "--what", "changes", "--session", "s9", "-o", o],
            4,
            &["\"s9\"", "1 (s1)", "2 (north walk)", "3 (s3)"],
        ),
        (&["render", r, "--what", "trajectories", "--since", "south", "-o", o], 4, &["south", "north walk"]),
        (&["render", r, "--what", "changes", "--session", "2", "--since", "3", "-o", o], 2, &["not both"]),
        (&["render", r, "--what", "static", "--session", "2", "-o", o], 2, &["--session"]),
        (&["render", r, "--what", "static", "--bbox", "1,2,3", "-o", o], 2, &["x0,y0,x1,y1"]),
        (&["render", r, "--what", "static", "--bbox", "5,0,1,4", "-o", o], 2, &["x0 < x1"]),
        (&["render", r, "--what", "static", "--width", "10", "-o", o], 2, &["--width"]),
        (&["render", "/nowhere/site.seam", "--what", "static", "-o", o], 4, &["not a seam store"]),
        (&["report", r, "-o", "/nowhere/at/all/r.html"], 2, &["does not exist"]),
        (&["report", "/nowhere/site.seam", "-o", o], 4, &["not a seam store"]),
    ];
    for (args, code, needles) in cases {
        let res = run(args);
        let err = stderr(&res);
        assert_eq!(res.status.code(), Some(*code), "{args:?}: {err}");
        for n in *needles {
            assert!(err.contains(n), "{args:?}: {err:?} lacks {n:?}");
        }
        assert_files(&out, &["map.png"]);
        assert_eq!(std::fs::read(out.join("map.png")).unwrap(), b"earlier");
    }
    // A missing output folder: exit 2, and the folder is not created.
    let missing = tmp.path().join("no/such/dir/map.png");
    let res = run(&["render", r, "--what", "static", "-o", missing.to_str().unwrap()]);
    assert_eq!(res.status.code(), Some(2), "{}", stderr(&res));
    assert!(stderr(&res).contains("does not exist"), "{}", stderr(&res));
    assert!(!tmp.path().join("no").exists());
    // The same command with a good session replaces the file whole.
    let res = run(&["render", r, "--what", "changes", "--session", "north walk", "-o", o, "-q"]);
    assert!(res.status.success(), "{}", stderr(&res));
    assert_eq!(Png::read(&out.join("map.png")).w, 1600);
    assert_files(&out, &["map.png"]);
}

/// The `<span data-col="KEY">` values of a report row, as numbers.
fn row_values(html: &str, session: i64) -> std::collections::HashMap<String, String> {
    let start = html.find(&format!("<tr data-session=\"{session}\">")).expect("a row per session");
    let row = &html[start..start + html[start..].find("</tr>").unwrap()];
    let mut out = std::collections::HashMap::new();
    for part in row.split("data-col=\"").skip(1) {
        let key = &part[..part.find('"').unwrap()];
        let rest = &part[part.find('>').unwrap() + 1..];
        let value = &rest[..rest.find('<').unwrap()];
        out.insert(key.to_string(), value.replace(',', "").trim_end_matches(" m³").to_string());
    }
    out
}

#[test]
fn report_is_one_self_contained_page_with_the_stores_numbers() {
    let tmp = tempfile::tempdir().unwrap();
    let root = synthetic_store(tmp.path());
    let out = tmp.path().join("rep");
    std::fs::create_dir(&out).unwrap();
    let path = out.join("report.html");
    // Through the library, as `seam demo` calls it.
    let opts = seam::render::ReportOptions { width_px: 900, ..Default::default() };
    let s = seam::render::write_report(&root, &path, &opts).unwrap();
    assert_eq!(s.sessions, 3);
    let html = std::fs::read_to_string(&path).unwrap();
    assert_eq!(s.bytes, html.len() as u64);
    assert_files(&out, &["report.html"]);

    assert!(html.starts_with("<!doctype html>") && html.trim_end().ends_with("</html>"));
    for bad in ["http://", "https://", "<link", "<script", "@import", "url("] {
        assert!(!html.contains(bad), "loads nothing from elsewhere: found {bad}");
    }
    assert!(html.contains("<h1>site</h1>"), "site name as title");
    for name in ["s1", "north walk", "s3"] {
        assert!(html.contains(&format!("data-col=\"name\">{name}<")), "{name}");
    }
    // Trajectories, static, lifelong, changes since the second session, and
    // one per later session; every image is a PNG of the size it claims.
    let imgs: Vec<&str> = html.split("src=\"data:image/png;base64,").skip(1).collect();
    assert_eq!(imgs.len(), 6);
    assert_eq!(s.pictures.len(), 6);
    assert_eq!(html.matches("<img ").count(), 6, "no image that is not embedded");
    for (b64, p) in imgs.iter().zip(&s.pictures) {
        let bytes = base64::engine::general_purpose::STANDARD.decode(&b64[..b64.find('"').unwrap()]).unwrap();
        let png = Png::decode(&bytes);
        assert_eq!((png.w, png.h), (p.width_px, p.height_px));
        assert_eq!(png.w, 900);
    }
    let whats: Vec<&str> = s.pictures.iter().map(|p| p.what.as_str()).collect();
    assert_eq!(whats, ["trajectories", "static", "lifelong", "changes", "changes", "changes"]);
    assert_eq!(s.pictures[3].sessions, "north walk–s3");

    // The sessions table holds the store's numbers.
    for i in 1..=3 {
        let v = row_values(&html, i);
        let c = session_changes(i);
        assert_eq!(v["keyframes"], "5");
        assert_eq!(v["points"], (1000 * i).to_string());
        assert_eq!(v["emerged_overlap"], c.emerged_overlap.to_string(), "s{i}");
        assert_eq!(v["deleted_overlap"], c.deleted_overlap.to_string());
        assert_eq!(v["emerged_non_overlap"], c.emerged_non_overlap.to_string());
        assert_eq!(v["lifelong_voxels"], c.lifelong_voxels.to_string());
        assert_eq!(v["static_voxels"], c.static_voxels.to_string());
        let vol = |n: usize| format!("{:.1}", n as f64 * 0.008);
        assert_eq!(v["emerged_overlap_m3"], vol(c.emerged_overlap));
        assert_eq!(v["deleted_overlap_m3"], vol(c.deleted_overlap));
    }
    assert!(row_values(&html, 1)["dynamic"].starts_with("3.7 %"), "37 of 1000 points");
    assert_eq!(row_values(&html, 3)["dynamic"], "—", "no DOR row");
    // A sentence per session, with places: each 5 × 5 patch is one.
    assert!(html.contains("s1 (2026-01-01) is the first session"));
    assert!(
        html.contains(
            "north walk (2026-02-01): 204 voxels appeared (1.6 m³) and 202 were removed (1.6 m³), in 2 places"
        )
    );
    assert!(html.contains("25 back again"));
    // How to redraw every picture.
    assert!(
        html.contains("seam render ")
            && html.contains("--what changes --session &#39;north walk&#39; -o changes-2.png")
    );

    // The CLI writes the same page; a second run replaces it whole.
    let o =
        run(&["report", root.to_str().unwrap(), "-o", path.to_str().unwrap(), "--format", "json", "--width", "600"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let j: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert_eq!(j["pictures"].as_array().unwrap().len(), 6);
    assert_eq!(j["bytes"].as_u64().unwrap(), std::fs::metadata(&path).unwrap().len());
    assert_files(&out, &["report.html"]);
}

/// A simulated site through the whole pipeline: pictures of a real map.
#[test]
#[cfg_attr(debug_assertions, ignore = "ingests a simulated site; run with --release")]
fn simulated_site_renders_and_reports() {
    let tmp = tempfile::tempdir().unwrap();
    let demo = tmp.path().join("demo");
    let o = run(&["demo", "--out", demo.to_str().unwrap(), "--keyframes", "20", "--sessions", "3", "-q"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let root = demo.join("site.seam");
    let conn = rusqlite::Connection::open_with_flags(root.join("seam.db"), rusqlite::OpenFlags::SQLITE_OPEN_READ_ONLY)
        .unwrap();
    let q = |sql: &str| conn.query_row(sql, [], |r| r.get::<_, i64>(0)).unwrap() as u64;
    for what in ["static", "lifelong", "changes", "trajectories"] {
        let (j, png) = render(&root, &tmp.path().join(format!("{what}.png")), &["--what", what]);
        let want = match what {
            "static" => q("SELECT count(*) FROM map_voxels WHERE eps_g < 0.5"),
            "lifelong" => q("SELECT count(*) FROM map_voxels"),
            "changes" => q("SELECT count(*) FROM change_events WHERE session_id >= 2"),
            _ => q("SELECT count(*) FROM keyframes"),
        };
        assert_eq!(j["drawn"].as_u64().unwrap(), want, "{what}");
        assert!(want > 0, "{what}: the simulated site has something to draw");
        // Where voxels are, pixels are drawn: sample voxels of the static
        // map, at the centre of their grid cell (what a voxel's square is
        // drawn around; the cell holds the centroid).
        if what != "trajectories" {
            let v = conn.query_row("SELECT voxel_m FROM map_state", [], |r| r.get::<_, f64>(0)).unwrap();
            let mut st = conn
                .prepare("SELECT kx, ky, x_m, y_m FROM map_voxels WHERE eps_g < 0.5 AND voxel_id % 997 = 0")
                .unwrap();
            let pts: Vec<(f64, f64)> = st
                .query_map([], |r| {
                    let (kx, ky, x, y): (i64, i64, f64, f64) = (r.get(0)?, r.get(1)?, r.get(2)?, r.get(3)?);
                    assert_eq!(
                        (kx, ky),
                        ((x / v).floor() as i64, (y / v).floor() as i64),
                        "the cell holds the centroid"
                    );
                    Ok(((kx as f64 + 0.5) * v, (ky as f64 + 0.5) * v))
                })
                .unwrap()
                .map(|r| r.unwrap())
                .collect();
            assert!(pts.len() > 20);
            for (x, y) in pts {
                let (px, py) = pixel_of(&j, x, y);
                assert_ne!(png.at(px, py), Rgb::WHITE, "{what}: nothing at voxel ({x}, {y})");
            }
        }
    }
    let out = tmp.path().join("report.html");
    let o = run(&["report", root.to_str().unwrap(), "-o", out.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let html = std::fs::read_to_string(&out).unwrap();
    for i in 1..=3 {
        let v = row_values(&html, i);
        let kf = q(&format!("SELECT keyframe_count FROM sessions WHERE session_id = {i}"));
        assert_eq!(v["keyframes"], kf.to_string());
        let em = q(&format!("SELECT emerged_overlap FROM session_changes WHERE session_id = {i}"));
        assert_eq!(v["emerged_overlap"], em.to_string());
    }
}
