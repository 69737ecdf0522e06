//! The paper's Table I analogue, small: 12 pairs per Far / Near /
//! Near-Mismatch cell for the five sensor groups, on a simulated site, with
//! the default `LoopConfig`. The experiment lives in
//! `bench/loop_table_core.rs` (shared with `examples/loop_table.rs`, which
//! prints the full table).
//!
//! Each cell must get every verdict right for the 360° groups (100 % over
//! 3 seeds × 40 pairs when the defaults were chosen) and all but one for the
//! groups with an Avia (90-100 %: ground-dominated forward scans sometimes
//! converge to a wrong pose with a high inlier ratio, and true matches where
//! the site changed can fall under it). A rule that accepted everything
//! would fail the Far and Mismatch cells; one that rejected everything would
//! fail the Near cells. The cells themselves are checked to test something:
//! GICP finds the truth in the Near cells and mostly does not in the others.

#[path = "../bench/loop_table_core.rs"]
mod loop_table_core;

use loop_table_core::{Cell, CellStats, GROUPS, Settings, markdown, prepare_sites, run_group};
use seam::sensor::SensorModel;

#[test]
#[cfg_attr(debug_assertions, ignore = "release only: cargo test --release")]
fn loop_verdicts_are_right_for_every_sensor_group() {
    let tmp = tempfile::tempdir().unwrap();
    let s = Settings { pairs: 12, seed: 6, keyframes: 200, ..Settings::default() };
    let t0 = std::time::Instant::now();
    let sites = prepare_sites(tmp.path(), &GROUPS, &s).unwrap();
    let mut outcomes = Vec::new();
    for g in &GROUPS {
        outcomes.extend(run_group(&sites, g, &s).unwrap());
    }
    eprintln!("{}\n{:.1} s", markdown(&outcomes, &GROUPS), t0.elapsed().as_secs_f64());

    let mut problems = Vec::new();
    for g in &GROUPS {
        let avia = g.source == SensorModel::Avia || g.target == SensorModel::Avia;
        for cell in Cell::ALL {
            let c = CellStats::of(&outcomes, g.name, cell);
            let name = format!("{} {}", g.name, cell.name());
            if c.n != s.pairs {
                problems.push(format!("{name}: {} pairs, not {}", c.n, s.pairs));
                continue;
            }
            let allowed = if avia { 1 } else { 0 };
            if c.n - c.correct > allowed {
                problems.push(format!(
                    "{name}: {} of {} verdicts wrong ({} accepted wrong, {} rejected right), at most {allowed} allowed",
                    c.n - c.correct,
                    c.n,
                    c.false_accepts,
                    c.false_rejects
                ));
            }
            // The cell must test what it is meant to.
            let ok = match cell {
                Cell::Near => c.within >= c.n - 1,
                Cell::Mismatch => 2 * c.within <= c.n,
                Cell::Far => c.within == 0,
            };
            if !ok {
                problems.push(format!("{name}: GICP found the truth in {} of {} pairs", c.within, c.n));
            }
        }
    }
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}
