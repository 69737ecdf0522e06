//! DOR of one session folder with its own poses, scored against its labels,
//! for tuning the evidence parameters without a store.
//!
//! ```text
//! cargo run --release --example dor_probe -- SESSION_DIR [--set key=value ...] [--submap-kf 20]
//! ```
//!
//! The field of view and beam spacing are the session's, as ingest takes
//! them (its `session.toml` sensor, else estimated from the first scan).
//!
//! Poses: `gt/poses.txt` when the folder has one (a simulated session's true
//! poses), else the layout's own (SemanticKITTI's). `--poses FILE` (KITTI
//! format, one line per keyframe, e.g. what `seam poses` writes) replaces
//! them, to see what the estimated poses cost. `--set` overrides
//! `EvidenceConfig` fields by their TOML names (e.g. `--set alpha0=0.05
//! --set model=log_odds`); several `--set` groups separated by `--vs` are run
//! one after another on the same scans.
//!
//! Diagnostics, by environment variable: `DOR_HIST=1` prints ε_l deciles of
//! static and moving points and how many kept moving points have ε_l at
//! `eps_min`, `DOR_CLASSES=1` the removed share per semantic class,
//! `DOR_INSTANCES=1` the removed moving points per instance and keyframe,
//! `DOR_MISSES=1` the moving points kept and removed by height over their
//! 0.2 m column's lowest static point and by range from the sensor (all,
//! and those over a column with no static point: far movers on ground the
//! rings do not sample), and `DOR_DUMP=FILE` writes every
//! point's ε_l (f32, little endian) followed by its verdict (one byte each),
//! in scan order, for comparing with another tool's labels point by point.

use seam::eval::dor::{DorAccumulator, render_table};
use seam::evidence::EvidenceConfig;
use seam::evidence::session::{KeyframeInput, generate};
use seam::io::{
    detect_session, is_moving_label, label_class, label_instance, read_kitti_poses, read_labels, read_session_scan,
};
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

fn main() -> ExitCode {
    seam::cli::tune_allocator();
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}

fn parse_cfg(sets: &[String]) -> Result<EvidenceConfig, String> {
    let mut toml = String::new();
    for s in sets {
        let (k, v) = s.split_once('=').ok_or(format!("--set {s}: expected key=value"))?;
        let v =
            if v.parse::<f64>().is_ok() || v == "true" || v == "false" { v.to_string() } else { format!("\"{v}\"") };
        if let Some((sec, key)) = k.split_once('.') {
            toml.push_str(&format!("[{sec}]\n{key} = {v}\n"));
        } else {
            toml.insert_str(0, &format!("{k} = {v}\n"));
        }
    }
    let cfg: EvidenceConfig = toml::from_str(&toml).map_err(|e| e.to_string())?;
    cfg.validate()?;
    Ok(cfg)
}

fn run() -> Result<(), String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let dir = PathBuf::from(args.first().ok_or("usage: dor_probe SESSION_DIR [--set k=v ...] [--vs ...]")?);
    let mut groups: Vec<Vec<String>> = vec![Vec::new()];
    let mut submap_kf = 20usize;
    let mut poses_file: Option<PathBuf> = None;
    let mut it = args[1..].iter();
    while let Some(a) = it.next() {
        match a.as_str() {
            "--set" => groups.last_mut().unwrap().push(it.next().ok_or("--set needs key=value")?.clone()),
            "--vs" => groups.push(Vec::new()),
            "--submap-kf" => submap_kf = it.next().and_then(|v| v.parse().ok()).ok_or("--submap-kf N")?,
            "--poses" => poses_file = Some(PathBuf::from(it.next().ok_or("--poses FILE")?)),
            other => return Err(format!("unknown argument {other}")),
        }
    }
    let src = detect_session(&dir).map_err(|e| e.to_string())?;
    let gt = dir.join("gt/poses.txt");
    let poses: Vec<_> = if let Some(f) = &poses_file {
        read_kitti_poses(f).map_err(|e| e.to_string())?
    } else if gt.exists() {
        read_kitti_poses(&gt).map_err(|e| e.to_string())?
    } else {
        src.keyframes.iter().map(|k| k.t_session_sensor).collect()
    };
    let mut scans = Vec::new();
    // Each keyframe's raw labels (class | instance << 16), in scan order.
    let mut labels: Vec<Vec<u32>> = Vec::new();
    for (i, kf) in src.keyframes.iter().enumerate() {
        let scan = read_session_scan(&src, i).map_err(|e| e.to_string())?;
        labels.push(match &kf.labels_path {
            Some(p) => read_labels(p, scan.len()).map_err(|e| e.to_string())?,
            None => return Err(format!("{}: keyframe {i} has no labels", dir.display())),
        });
        scans.push(scan.points);
    }
    // (keyframe, label) of every point, in the order of the verdicts.
    let every_label = || labels.iter().enumerate().flat_map(|(i, l)| l.iter().map(move |&l| (i, l)));
    let points: usize = scans.iter().map(Vec::len).sum();
    let dynamic = every_label().filter(|&(_, l)| is_moving_label(l)).count();
    println!("{}: {} keyframes, {points} points, {dynamic} moving", dir.display(), scans.len());
    for sets in groups {
        let cfg = parse_cfg(&sets)?;
        let inputs: Vec<KeyframeInput<'_>> = scans
            .iter()
            .enumerate()
            .map(|(i, p)| KeyframeInput {
                index: i as u32,
                submap: i / submap_kf,
                t_world_keyframe: poses[i],
                points: p,
            })
            .collect();
        let t = Instant::now();
        // The session's field of view and beam spacing, as ingest takes them.
        let fov = src
            .meta
            .fov
            .unwrap_or_else(|| seam::registration::dop::estimate_fov(scans.first().map_or(&[][..], |s| &s[..])));
        let spacing = src.meta.sensor_model.and_then(seam::sensor::SensorModel::beam_spacing_deg);
        let cfg = cfg.for_beam_spacing(spacing).into_owned();
        let out = generate(&inputs, &[], Some(&fov), &cfg, |_| {});
        let secs = t.elapsed().as_secs_f64();
        let mut acc = DorAccumulator::new(0.2);
        let mut row = 0;
        for (i, p) in scans.iter().enumerate() {
            let world = seam::geometry::transformed(p, &poses[i]);
            acc.add_labelled_scan(i as u32, &world, &labels[i], &out.labels.dynamic[row..row + p.len()])
                .map_err(|e| e.to_string())?;
            row += p.len();
        }
        let s = acc.finish();
        println!(
            "\n[{}] {secs:.2} s ({:.0} points/s; prepare {:.3} s, ray casting {:.3} s, DOR {:.3} s, cleaned map {:.3} s), {} interest voxels, {} stored",
            sets.join(" "),
            points as f64 / secs,
            out.stats.prepare_s,
            out.stats.raycast_s,
            out.stats.dor_s,
            out.stats.cleaned_s,
            out.stats.interest_voxels,
            out.stats.generated_voxels
        );
        println!("{}", render_table(&s));
        // Every point's (keyframe, label, removed, eps_l).
        let verdicts =
            || every_label().zip(&out.labels.dynamic).zip(&out.labels.eps_l).map(|(((i, l), &d), &e)| (i, l, d, e));
        if std::env::var_os("DOR_HIST").is_some() {
            let mut h = [[0usize; 10]; 2];
            for (_, l, _, e) in verdicts() {
                h[is_moving_label(l) as usize][((e * 10.0) as usize).min(9)] += 1;
            }
            println!("  eps_l deciles, static : {:?}\n  eps_l deciles, dynamic: {:?}", h[0], h[1]);
            // Moving points kept: at ε_min (no evidence of free space), or above it but too weak.
            let kept = || verdicts().filter(|&(_, l, d, _)| is_moving_label(l) && !d);
            let unfreed = kept().filter(|&(_, _, _, e)| f64::from(e) <= cfg.eps_min + 1e-6).count();
            println!("  moving points kept: {} at eps_min, {} above it", unfreed, kept().count() - unfreed);
        }
        if let Some(path) = std::env::var_os("DOR_DUMP") {
            // Every point's eps_l (f32) then dynamic (u8), in scan order.
            let mut bytes: Vec<u8> = out.labels.eps_l.iter().flat_map(|e| e.to_le_bytes()).collect();
            bytes.extend(out.labels.dynamic.iter().map(|&d| d as u8));
            std::fs::write(&path, bytes).map_err(|e| e.to_string())?;
        }
        if std::env::var_os("DOR_INSTANCES").is_some() {
            // Moving points by (instance, keyframe): removed of all.
            let mut by_inst: BTreeMap<(u16, usize), (usize, usize)> = BTreeMap::new();
            for (i, l, d, _) in verdicts().filter(|&(_, l, _, _)| is_moving_label(l)) {
                let e = by_inst.entry((label_instance(l), i)).or_default();
                e.0 += 1;
                e.1 += d as usize;
            }
            let mut last = None;
            for ((inst, kf), (n, r)) in &by_inst {
                if last != Some(*inst) {
                    print!("\n  moving instance {inst:>3}:");
                    last = Some(*inst);
                }
                print!(" kf{kf} {r}/{n}");
            }
            println!();
        }
        if std::env::var_os("DOR_MISSES").is_some() {
            // Moving points by height over their 0.2 m column's floor: the
            // lowest static point any keyframe put in it (≈ the ground).
            // 0.1 m bins, then 2 m and more, then no floor at all.
            let cell = |q: &[f64; 3]| ((q[0] / 0.2).floor() as i64, (q[1] / 0.2).floor() as i64);
            let world: Vec<Vec<[f64; 3]>> =
                scans.iter().zip(&poses).map(|(p, t)| seam::geometry::transformed(p, t)).collect();
            let mut floor: std::collections::HashMap<(i64, i64), f64> = Default::default();
            for (i, w) in world.iter().enumerate() {
                for (_, q) in w.iter().enumerate().filter(|&(j, _)| !is_moving_label(labels[i][j])) {
                    let e = floor.entry(cell(q)).or_insert(f64::MAX);
                    *e = e.min(q[2]);
                }
            }
            let mut hist = [[0usize; 22]; 2];
            // Range from the sensor in 5 m bins (the last: 50 m and more),
            // for every moving point and for those over no floor.
            let mut by_range = [[[0usize; 11]; 2]; 2];
            let mut row = 0;
            for (i, w) in world.iter().enumerate() {
                for (j, q) in w.iter().enumerate() {
                    if is_moving_label(labels[i][j]) {
                        let b = floor.get(&cell(q)).map_or(21, |f| (((q[2] - f).max(0.0) / 0.1) as usize).min(20));
                        let d = out.labels.dynamic[row + j] as usize;
                        hist[d][b] += 1;
                        let p = scans[i][j];
                        let r = ((p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt() / 5.0) as usize;
                        by_range[usize::from(b == 21)][d][r.min(10)] += 1;
                    }
                }
                row += w.len();
            }
            println!("  moving points by range (5 m bins, then 50 m and more): kept / removed");
            println!("    all       : {:?} / {:?}", by_range[0][0], by_range[0][1]);
            println!("    over none : {:?} / {:?}", by_range[1][0], by_range[1][1]);
            println!("  moving points by height over their 0.2 m column's lowest static point");
            println!("  (0.1 m bins, then 2 m and more, then no static point in the column)");
            println!("    kept   : {:?}\n    removed: {:?}", hist[0], hist[1]);
        }
        if std::env::var_os("DOR_CLASSES").is_some() {
            let mut by_class: BTreeMap<u16, (usize, usize)> = BTreeMap::new();
            for (_, l, d, _) in verdicts() {
                let e = by_class.entry(label_class(l)).or_default();
                e.0 += 1;
                e.1 += d as usize;
            }
            for (c, (n, r)) in &by_class {
                println!("  class {c:>3}: {r:>7} of {n:>8} removed ({:.1} %)", 100.0 * *r as f64 / *n as f64);
            }
        }
    }
    Ok(())
}
