//! Scoring dynamic object removal (DOR) against SemanticKITTI-style labels
//! (MATH.md section 9). Pure: no store access; callers feed points.
//!
//! Every point has a world position, a truth (`dynamic`: its label is one of
//! the moving classes 252..=259) and a prediction (`removed`: the method took
//! it out of the map). [`DorAccumulator`] streams points keyframe by keyframe
//! and [`DorAccumulator::finish`] gives two blocks of [`DorScores`]:
//!
//! - `point`: every point counts once.
//! - `voxel`: points are binned into cubes of [`DOR_VOXEL_M`] (key
//!   `floor(p / voxel_m)` per axis, as `i32`), and each voxel counts once.
//!   A voxel is truly dynamic if **at least half** of its points are (ties →
//!   dynamic), and predicted removed if **at least half** of its points are
//!   removed (ties → removed). Choice: a voxel is a majority vote of its
//!   points; ties go to "dynamic"/"removed" so that a voxel a mover shares
//!   half-and-half with the ground is scored as a mover the method had to
//!   remove. Voxels are pooled over all keyframes fed (a static voxel seen in
//!   ten scans is one voxel).
//!
//! Per block, with ERASOR's and DynamicMap_Benchmark's names:
//!
//! ```text
//! PR = SA = static kept / static            (preservation rate, static accuracy)
//! RR = DA = dynamic removed / dynamic       (rejection rate, dynamic accuracy)
//! F1 = HA = 2·PR·RR / (PR + RR)             (0 when PR = RR = 0)
//! AA      = sqrt(SA · DA)
//! precision of removal = removed-and-dynamic / removed
//! ```
//!
//! A third block, `moved`, is there when the points came with their raw
//! labels ([`DorAccumulator::add_labelled_scan`]): point-wise, without the
//! moving-labelled points that did not move during the sequence. A moving
//! point is *still* when a point of the same instance (label bits 16-31) in
//! another scan lies in its voxel or one of the 26 around it; SemanticKITTI
//! and the simulator label an object moving for the whole sequence even
//! while it waits at a crossing, and no method that removes only space some
//! ray saw empty can remove an object that never left its place. PR is the
//! point block's; RR is over the moving points that moved.
//!
//! A ratio whose denominator is zero is `None` (JSON `null`), never NaN: no
//! static points → PR, SA, F1, HA, AA are `None`; no dynamic points → RR, DA,
//! F1, HA, AA are `None`; nothing removed → precision of removal is `None`.
//!
//! Labels live at `DIR/labels/NNNNNN.label` ([`label_path`]), one u32 LE per
//! point, class in the low 16 bits; NNNNNN is the keyframe index (the scan's
//! index in its session), zero-padded to 6 digits.

use super::EvalError;
use crate::io::{ReadError, ReadErrorKind, label_instance};

/// Label-file errors become `EvalError::Mismatch` carrying the rendered
/// [`ReadError`] (path, problem, hint): the same exit code (data) a
/// `ReadError` gets, without a new `EvalError` variant.
impl From<ReadError> for EvalError {
    fn from(e: ReadError) -> Self {
        EvalError::Mismatch(e.to_string())
    }
}
use rustc_hash::FxHashMap;
use std::path::{Path, PathBuf};

/// Voxel edge of the voxel-wise block, m (MATH.md section 9).
pub const DOR_VOXEL_M: f64 = 0.2;

pub use crate::io::{MOVING_CLASSES, is_moving_label};

/// The label written for a removed point by tools that export predictions
/// (`moving-car`); any class in [`MOVING_CLASSES`] reads as removed.
pub const REMOVED_LABEL: u32 = 252;

/// `DIR/labels`, where a session folder keeps its `.label` files.
pub fn labels_dir(dir: &Path) -> PathBuf {
    dir.join("labels")
}

/// `DIR/labels/NNNNNN.label` of keyframe `index` (6 digits, zero-padded).
pub fn label_path(dir: &Path, index: u64) -> PathBuf {
    labels_dir(dir).join(format!("{index:06}.label"))
}

/// Reads the labels of keyframe `index` from `DIR/labels/NNNNNN.label` and
/// checks there is one per point of its scan (`expected_points`).
pub fn read_keyframe_labels(dir: &Path, index: u64, expected_points: usize) -> Result<Vec<u32>, EvalError> {
    let path = label_path(dir, index);
    if !path.is_file() {
        return Err(ReadError::new(ReadErrorKind::Io, &path, format!("no label file for keyframe {index}"))
            .hint(format!(
                "labels must be at {}/NNNNNN.label, one per scan of the session; pass the folder that holds labels/",
                labels_dir(dir).display()
            ))
            .into());
    }
    Ok(crate::io::read_labels(&path, expected_points)?)
}

/// The moving-class flag of each label ([`is_moving_label`]).
pub fn moving_flags(labels: &[u32]) -> Vec<bool> {
    labels.iter().map(|&l| is_moving_label(l)).collect()
}

/// Raw counts of one block; the rates follow from them.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
struct Counts {
    static_total: u64,
    dynamic_total: u64,
    static_kept: u64,
    dynamic_removed: u64,
}

impl Counts {
    fn add(&mut self, dynamic: bool, removed: bool) {
        if dynamic {
            self.dynamic_total += 1;
            self.dynamic_removed += u64::from(removed);
        } else {
            self.static_total += 1;
            self.static_kept += u64::from(!removed);
        }
    }

    fn block(&self) -> DorBlock {
        let ratio = |num: u64, den: u64| (den > 0).then(|| num as f64 / den as f64);
        let static_removed = self.static_total - self.static_kept;
        let removed_total = static_removed + self.dynamic_removed;
        let pr = ratio(self.static_kept, self.static_total);
        let rr = ratio(self.dynamic_removed, self.dynamic_total);
        let (f1, aa) = match (pr, rr) {
            (Some(p), Some(r)) => (Some(f1_score(p, r)), Some((p * r).sqrt())),
            _ => (None, None),
        };
        DorBlock {
            static_total: self.static_total,
            dynamic_total: self.dynamic_total,
            static_kept: self.static_kept,
            dynamic_removed: self.dynamic_removed,
            removed_total,
            pr,
            rr,
            f1,
            sa: pr,
            da: rr,
            aa,
            ha: f1,
            precision_of_removal: ratio(self.dynamic_removed, removed_total),
        }
    }
}

/// F1 = 2·PR·RR / (PR + RR), 0 when both are 0.
pub fn f1_score(pr: f64, rr: f64) -> f64 {
    if pr + rr > 0.0 { 2.0 * pr * rr / (pr + rr) } else { 0.0 }
}

/// One block (point-wise or voxel-wise) of DOR scores. Rates are fractions
/// in [0, 1]; `None` where the denominator is zero (see the module docs).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DorBlock {
    /// Truly static points (voxels).
    pub static_total: u64,
    /// Truly dynamic points (voxels).
    pub dynamic_total: u64,
    /// Truly static and not removed.
    pub static_kept: u64,
    /// Truly dynamic and removed.
    pub dynamic_removed: u64,
    /// Removed, static or dynamic.
    pub removed_total: u64,
    /// Preservation rate: static kept / static (ERASOR).
    pub pr: Option<f64>,
    /// Rejection rate: dynamic removed / dynamic (ERASOR).
    pub rr: Option<f64>,
    /// 2·PR·RR / (PR + RR), 0 when both are 0.
    pub f1: Option<f64>,
    /// Static accuracy (DynamicMap_Benchmark) = PR.
    pub sa: Option<f64>,
    /// Dynamic accuracy (DynamicMap_Benchmark) = RR.
    pub da: Option<f64>,
    /// Associated accuracy sqrt(SA·DA) (DynamicMap_Benchmark).
    pub aa: Option<f64>,
    /// Harmonic accuracy (DynamicMap_Benchmark) = F1.
    pub ha: Option<f64>,
    /// Removed-and-dynamic / removed: how much of what was removed deserved it.
    pub precision_of_removal: Option<f64>,
}

/// Point-wise and voxel-wise DOR scores.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DorScores {
    /// Voxel edge of the voxel-wise block, m.
    pub voxel_m: f64,
    pub point: DorBlock,
    pub voxel: DorBlock,
    /// Point-wise without the still movers (module docs); `None` unless
    /// every scan came with its raw labels.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub moved: Option<DorBlock>,
}

/// A moving point kept for the `moved` block.
#[derive(Debug, Clone, Copy)]
struct MoverPoint {
    key: [i32; 3],
    instance: u16,
    keyframe: u32,
    removed: bool,
}

/// Per voxel: points truly dynamic, points removed, all points.
#[derive(Debug, Clone, Copy, Default)]
struct VoxelTally {
    dynamic: u32,
    removed: u32,
    total: u32,
}

/// Streams points (keyframe by keyframe, in any order) and scores them.
///
/// ```
/// use seam::eval::dor::DorAccumulator;
/// let mut acc = DorAccumulator::new(0.2);
/// acc.add([0.05, 0.05, 0.05], false, false); // static, kept
/// acc.add([5.05, 0.05, 0.05], true, true); // dynamic, removed
/// let s = acc.finish();
/// assert_eq!(s.point.pr, Some(1.0));
/// assert_eq!(s.point.rr, Some(1.0));
/// ```
#[derive(Debug, Clone)]
pub struct DorAccumulator {
    voxel_m: f64,
    points: Counts,
    voxels: FxHashMap<[i32; 3], VoxelTally>,
    /// Moving points of labelled scans; `None` once an unlabelled scan was
    /// added (the `moved` block then cannot be scored).
    movers: Option<Vec<MoverPoint>>,
}

impl DorAccumulator {
    /// An empty accumulator with voxels of `voxel_m` metres (use
    /// [`DOR_VOXEL_M`]). Panics unless `voxel_m` is finite and positive.
    pub fn new(voxel_m: f64) -> Self {
        assert!(voxel_m.is_finite() && voxel_m > 0.0, "DOR voxel size must be finite and > 0, got {voxel_m}");
        DorAccumulator { voxel_m, points: Counts::default(), voxels: FxHashMap::default(), movers: Some(Vec::new()) }
    }

    /// The voxel key of a world position: `floor(p / voxel_m)` per axis.
    pub fn voxel_key(&self, p: [f64; 3]) -> [i32; 3] {
        p.map(|c| (c / self.voxel_m).floor() as i32)
    }

    /// One point: its world position, whether it is truly dynamic, whether
    /// the method removed it. Without its label, the `moved` block is not
    /// scored.
    pub fn add(&mut self, p_world: [f64; 3], dynamic: bool, removed: bool) {
        if dynamic {
            self.movers = None;
        }
        self.tally(self.voxel_key(p_world), dynamic, removed);
    }

    fn tally(&mut self, key: [i32; 3], dynamic: bool, removed: bool) {
        self.points.add(dynamic, removed);
        let t = self.voxels.entry(key).or_default();
        t.dynamic += u32::from(dynamic);
        t.removed += u32::from(removed);
        t.total += 1;
    }

    /// A whole scan; the three slices must have the same length.
    pub fn add_scan(&mut self, p_world: &[[f64; 3]], dynamic: &[bool], removed: &[bool]) -> Result<(), EvalError> {
        one_per_point(p_world.len(), (dynamic.len(), "truth flags"), removed.len())?;
        self.voxels.reserve(p_world.len() / 4);
        for ((p, &d), &r) in p_world.iter().zip(dynamic).zip(removed) {
            self.add(*p, d, r);
        }
        Ok(())
    }

    /// A whole scan with its raw labels (class and instance), so that the
    /// `moved` block is scored too; `keyframe` tells scans apart.
    pub fn add_labelled_scan(
        &mut self,
        keyframe: u32,
        p_world: &[[f64; 3]],
        labels: &[u32],
        removed: &[bool],
    ) -> Result<(), EvalError> {
        one_per_point(p_world.len(), (labels.len(), "labels"), removed.len())?;
        self.voxels.reserve(p_world.len() / 4);
        for ((p, &l), &r) in p_world.iter().zip(labels).zip(removed) {
            let (key, dynamic) = (self.voxel_key(*p), is_moving_label(l));
            self.tally(key, dynamic, r);
            if dynamic && let Some(m) = self.movers.as_mut() {
                m.push(MoverPoint { key, instance: label_instance(l), keyframe, removed: r });
            }
        }
        Ok(())
    }

    /// The `moved` block: the point block less the still movers.
    fn moved_block(&self) -> Option<DorBlock> {
        let movers = self.movers.as_ref()?;
        // Per (instance, voxel): the first keyframe seen there, and whether
        // another one was too.
        let mut seen: FxHashMap<(u16, [i32; 3]), (u32, bool)> = FxHashMap::default();
        for m in movers {
            seen.entry((m.instance, m.key)).and_modify(|e| e.1 |= e.0 != m.keyframe).or_insert((m.keyframe, false));
        }
        let mut counts = self.points;
        counts.dynamic_total = 0;
        counts.dynamic_removed = 0;
        for m in movers {
            let still = (-1..=1).any(|dx| {
                (-1..=1).any(|dy| {
                    (-1..=1).any(|dz| {
                        let k = [m.key[0] + dx, m.key[1] + dy, m.key[2] + dz];
                        seen.get(&(m.instance, k)).is_some_and(|&(first, other)| other || first != m.keyframe)
                    })
                })
            });
            if !still {
                counts.add(true, m.removed);
            }
        }
        Some(counts.block())
    }

    /// Adds everything `other` has seen (for per-thread accumulators).
    /// Panics if the voxel sizes differ.
    pub fn merge(&mut self, other: DorAccumulator) {
        assert_eq!(self.voxel_m, other.voxel_m, "merging DOR accumulators of different voxel sizes");
        let (a, b) = (&mut self.points, other.points);
        a.static_total += b.static_total;
        a.dynamic_total += b.dynamic_total;
        a.static_kept += b.static_kept;
        a.dynamic_removed += b.dynamic_removed;
        match (self.movers.as_mut(), other.movers) {
            (Some(a), Some(b)) => a.extend(b),
            _ => self.movers = None,
        }
        for (k, v) in other.voxels {
            let t = self.voxels.entry(k).or_default();
            t.dynamic += v.dynamic;
            t.removed += v.removed;
            t.total += v.total;
        }
    }

    /// Points added so far.
    pub fn points(&self) -> u64 {
        self.points.static_total + self.points.dynamic_total
    }

    /// The point-wise and voxel-wise scores.
    pub fn finish(&self) -> DorScores {
        let mut voxel = Counts::default();
        for t in self.voxels.values() {
            // Majority with ties to dynamic / removed (module docs).
            voxel.add(2 * t.dynamic >= t.total, 2 * t.removed >= t.total);
        }
        DorScores { voxel_m: self.voxel_m, point: self.points.block(), voxel: voxel.block(), moved: self.moved_block() }
    }
}

/// A scan's truth (`what`: flags or labels) and removal flags must be one
/// per point.
fn one_per_point(points: usize, (truth, what): (usize, &str), removed: usize) -> Result<(), EvalError> {
    if truth == points && removed == points {
        return Ok(());
    }
    Err(EvalError::Mismatch(format!(
        "DOR scoring got {points} points, {truth} {what} and {removed} removal flags; they must be one per point"
    )))
}

fn pct(x: Option<f64>) -> String {
    x.map(|v| format!("{:.2}", 100.0 * v)).unwrap_or_else(|| "-".into())
}

/// A plain-text table of the scores: one row per block, rates in percent
/// with 2 decimals (`-` where undefined), then the counts.
pub fn render_table(s: &DorScores) -> String {
    let head = [
        "block",
        "PR %",
        "RR %",
        "F1 %",
        "precision %",
        "AA %",
        "static",
        "dynamic",
        "static kept",
        "dyn removed",
        "removed",
    ];
    let row = |name: String, b: &DorBlock| -> Vec<String> {
        vec![
            name,
            pct(b.pr),
            pct(b.rr),
            pct(b.f1),
            pct(b.precision_of_removal),
            pct(b.aa),
            b.static_total.to_string(),
            b.dynamic_total.to_string(),
            b.static_kept.to_string(),
            b.dynamic_removed.to_string(),
            b.removed_total.to_string(),
        ]
    };
    let mut rows = vec![row("point".into(), &s.point), row(format!("voxel {} m", s.voxel_m), &s.voxel)];
    if let Some(m) = &s.moved {
        rows.push(row("moved".into(), m));
    }
    let widths: Vec<usize> =
        (0..head.len()).map(|i| rows.iter().map(|r| r[i].len()).chain([head[i].len()]).max().unwrap_or(0)).collect();
    let line = |cells: &[String]| -> String {
        let mut l = String::new();
        for (i, c) in cells.iter().enumerate() {
            if i == 0 {
                l.push_str(&format!("{c:<w$}", w = widths[i]));
            } else {
                l.push_str(&format!("  {c:>w$}", w = widths[i]));
            }
        }
        l.push('\n');
        l
    };
    let mut out = line(&head.map(String::from));
    for r in &rows {
        out.push_str(&line(r));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: Option<f64>, b: f64) {
        let a = a.expect("defined");
        assert!((a - b).abs() < 1e-12, "{a} != {b}");
    }

    #[test]
    fn moving_classes_are_252_to_259_in_the_low_16_bits() {
        for c in 252..=259 {
            assert!(is_moving_label(c));
            assert!(is_moving_label(c | (17 << 16)));
        }
        for c in [0, 1, 10, 40, 251, 260, 0xFFFF] {
            assert!(!is_moving_label(c));
            assert!(!is_moving_label(c | (252 << 16)), "instance bits must not count");
        }
    }

    #[test]
    fn point_block_by_hand() {
        // 10 static points: 8 kept, 2 removed. 4 dynamic: 3 removed, 1 kept.
        // All far apart so the voxel block is the same as the point block.
        let mut acc = DorAccumulator::new(0.2);
        let mut i = 0.0;
        let mut put = |acc: &mut DorAccumulator, d, r| {
            acc.add([i, 0.0, 0.0], d, r);
            i += 1.0;
        };
        for k in 0..10 {
            put(&mut acc, false, k >= 8);
        }
        for k in 0..4 {
            put(&mut acc, true, k < 3);
        }
        let s = acc.finish();
        for b in [&s.point, &s.voxel] {
            assert_eq!((b.static_total, b.dynamic_total, b.static_kept, b.dynamic_removed), (10, 4, 8, 3));
            assert_eq!(b.removed_total, 5);
            close(b.pr, 0.8);
            close(b.rr, 0.75);
            // 2·0.8·0.75 / 1.55 = 1.2 / 1.55
            close(b.f1, 1.2 / 1.55);
            close(b.aa, 0.6_f64.sqrt());
            close(b.precision_of_removal, 3.0 / 5.0);
            assert_eq!((b.sa, b.da, b.ha), (b.pr, b.rr, b.f1));
        }
        assert_eq!(acc.points(), 14);
    }

    #[test]
    fn f1_formula() {
        assert_eq!(f1_score(0.0, 0.0), 0.0);
        assert_eq!(f1_score(1.0, 0.0), 0.0);
        assert!((f1_score(0.9, 0.6) - 2.0 * 0.54 / 1.5).abs() < 1e-15);
        assert!((f1_score(0.5, 0.5) - 0.5).abs() < 1e-15);
        // Harmonic, not arithmetic, mean.
        assert!((f1_score(1.0, 0.5) - 2.0 / 3.0).abs() < 1e-15);
    }

    #[test]
    fn nothing_removed_gives_no_precision_and_zero_rr() {
        let mut acc = DorAccumulator::new(0.2);
        acc.add([0.0, 0.0, 0.0], false, false);
        acc.add([1.0, 0.0, 0.0], true, false);
        let s = acc.finish();
        assert_eq!(s.point.precision_of_removal, None);
        assert_eq!(s.point.removed_total, 0);
        close(s.point.pr, 1.0);
        close(s.point.rr, 0.0);
        close(s.point.f1, 0.0);
        close(s.point.aa, 0.0);
        let json = serde_json::to_value(&s).unwrap();
        assert!(json["point"]["precision_of_removal"].is_null());
        assert_eq!(json["voxel"]["pr"], 1.0);
    }

    #[test]
    fn empty_dynamic_set_leaves_rr_f1_aa_undefined() {
        let mut acc = DorAccumulator::new(0.2);
        acc.add([0.0, 0.0, 0.0], false, false);
        acc.add([1.0, 0.0, 0.0], false, true);
        let s = acc.finish();
        let b = &s.point;
        assert_eq!(b.dynamic_total, 0);
        close(b.pr, 0.5);
        assert_eq!((b.rr, b.da, b.f1, b.ha, b.aa), (None, None, None, None, None));
        // One static point removed and nothing dynamic: precision 0, not None.
        close(b.precision_of_removal, 0.0);
        assert_eq!(s.voxel, s.point);
    }

    #[test]
    fn empty_accumulator_is_all_undefined() {
        let s = DorAccumulator::new(0.2).finish();
        assert_eq!(s.point.pr, None);
        assert_eq!(s.point.rr, None);
        assert_eq!(s.point.precision_of_removal, None);
        assert_eq!(s.voxel.static_total + s.voxel.dynamic_total, 0);
    }

    #[test]
    fn voxel_majority_and_ties() {
        let mut acc = DorAccumulator::new(0.2);
        // Voxel A [0,0,0]: 3 points, 2 dynamic (majority dynamic), 1 removed
        // (minority: kept). A dynamic voxel not removed.
        acc.add([0.01, 0.01, 0.01], true, false);
        acc.add([0.19, 0.01, 0.01], true, true);
        acc.add([0.01, 0.19, 0.19], false, false);
        // Voxel B [5,0,0]: 2 points, 1 dynamic (tie → dynamic), 1 removed
        // (tie → removed): a dynamic voxel removed.
        acc.add([1.01, 0.0, 0.0], true, false);
        acc.add([1.1, 0.1, 0.1], false, true);
        // Voxel C [-1,-1,-1]: 4 points, 1 dynamic (static), 2 removed
        // (tie → removed): a static voxel removed.
        for (d, r) in [(true, true), (false, true), (false, false), (false, false)] {
            acc.add([-0.1, -0.1, -0.1], d, r);
        }
        // Voxel D [10,0,0]: 1 static point kept.
        acc.add([2.05, 0.0, 0.0], false, false);
        let s = acc.finish();
        let v = &s.voxel;
        assert_eq!((v.static_total, v.dynamic_total, v.static_kept, v.dynamic_removed), (2, 2, 1, 1));
        assert_eq!(v.removed_total, 2);
        close(v.pr, 0.5);
        close(v.rr, 0.5);
        close(v.f1, 0.5);
        close(v.aa, 0.5);
        close(v.precision_of_removal, 0.5);
        // The point block of the same points: static 6 (kept 4: A1, C2, D1...),
        // dynamic 4 (removed 2).
        let p = &s.point;
        assert_eq!((p.static_total, p.dynamic_total), (6, 4));
        assert_eq!((p.static_kept, p.dynamic_removed, p.removed_total), (4, 2, 4));
        close(p.pr, 4.0 / 6.0);
        close(p.rr, 0.5);
        close(p.f1, 2.0 * (4.0 / 6.0) * 0.5 / (4.0 / 6.0 + 0.5));
        close(p.aa, (4.0 / 6.0 * 0.5_f64).sqrt());
        close(p.precision_of_removal, 0.5);
    }

    #[test]
    fn voxel_keys_floor_negative_coordinates() {
        let acc = DorAccumulator::new(0.2);
        assert_eq!(acc.voxel_key([0.0, 0.199, -0.001]), [0, 0, -1]);
        assert_eq!(acc.voxel_key([-0.2, 0.2, -0.4]), [-1, 1, -2]);
        assert_eq!(acc.voxel_key([1.0, -1.0, 0.39]), [5, -5, 1]);
    }

    #[test]
    fn voxels_pool_points_of_all_scans() {
        // The same static voxel seen in 3 scans is one voxel; a mover passes
        // through two voxels and is removed in one.
        let mut acc = DorAccumulator::new(0.2);
        for _ in 0..3 {
            acc.add_scan(&[[0.1, 0.1, 0.1]], &[false], &[false]).unwrap();
        }
        acc.add_scan(&[[4.1, 0.1, 0.1], [6.1, 0.1, 0.1]], &[true, true], &[true, false]).unwrap();
        let s = acc.finish();
        assert_eq!((s.voxel.static_total, s.voxel.dynamic_total, s.voxel.dynamic_removed), (1, 2, 1));
        assert_eq!((s.point.static_total, s.point.dynamic_total), (3, 2));
        assert!(acc.add_scan(&[[0.0; 3]], &[true], &[]).is_err());
    }

    #[test]
    fn merge_equals_one_accumulator() {
        let pts: Vec<([f64; 3], bool, bool)> =
            (0..200).map(|i| ([(i % 7) as f64 * 0.13, (i % 5) as f64 * 0.11, 0.0], i % 3 == 0, i % 4 == 0)).collect();
        let mut one = DorAccumulator::new(0.2);
        let (mut a, mut b) = (DorAccumulator::new(0.2), DorAccumulator::new(0.2));
        for (k, &(p, d, r)) in pts.iter().enumerate() {
            one.add(p, d, r);
            if k % 2 == 0 { a.add(p, d, r) } else { b.add(p, d, r) }
        }
        a.merge(b);
        assert_eq!(a.finish(), one.finish());
    }

    /// One labelled scan: keyframe, world points, raw labels, removed flags.
    type Scan = (u32, Vec<[f64; 3]>, Vec<u32>, Vec<bool>);

    /// Instance 1 stands (its points in both scans share a voxel or touch
    /// one), instance 2 drives 2 m between the scans; a static point too.
    fn two_scans() -> Vec<Scan> {
        let standing = 252 | (1 << 16);
        let driving = 252 | (2 << 16);
        vec![
            (
                0,
                vec![[0.05, 0.05, 0.05], [5.05, 0.05, 0.05], [9.0, 9.0, 0.0]],
                vec![standing, driving, 40],
                vec![false, true, false],
            ),
            // The standing object's point is one voxel over (a neighbour):
            // still. The driving one is 2 m on: moved.
            (
                1,
                vec![[0.25, 0.05, 0.05], [7.05, 0.05, 0.05], [9.0, 9.0, 0.0]],
                vec![standing, driving, 40],
                vec![true, false, true],
            ),
        ]
    }

    #[test]
    fn moved_block_leaves_out_movers_that_stayed_in_place() {
        let mut acc = DorAccumulator::new(0.2);
        for (kf, p, l, r) in two_scans() {
            acc.add_labelled_scan(kf, &p, &l, &r).unwrap();
        }
        let s = acc.finish();
        assert_eq!(s.point.dynamic_total, 4);
        assert_eq!(s.point.dynamic_removed, 2);
        let m = s.moved.clone().expect("labelled scans give the moved block");
        // Only the driving object's two points count, one of them removed.
        assert_eq!(m.dynamic_total, 2);
        assert_eq!(m.dynamic_removed, 1);
        assert_eq!((m.static_total, m.static_kept), (s.point.static_total, s.point.static_kept));
        close(m.rr, 0.5);
        assert_eq!(m.pr, s.point.pr);
        assert!(render_table(&s).lines().any(|l| l.starts_with("moved")));
    }

    #[test]
    fn same_instance_in_one_scan_only_is_not_still() {
        // Two points of one object in the same voxel of one scan: nothing
        // of it was seen anywhere else, so both count as moved.
        let mut acc = DorAccumulator::new(0.2);
        let l = 254 | (7 << 16);
        acc.add_labelled_scan(3, &[[1.01, 1.01, 1.01], [1.02, 1.02, 1.02]], &[l, l], &[true, false]).unwrap();
        // Another instance at the same place in another scan does not make it still.
        acc.add_labelled_scan(4, &[[1.03, 1.03, 1.03]], &[254 | (8 << 16)], &[true]).unwrap();
        let m = acc.finish().moved.unwrap();
        assert_eq!((m.dynamic_total, m.dynamic_removed), (3, 2));
    }

    #[test]
    fn moved_block_needs_labels_and_survives_merging() {
        let scans = two_scans();
        let mut a = DorAccumulator::new(0.2);
        let mut b = DorAccumulator::new(0.2);
        a.add_labelled_scan(scans[0].0, &scans[0].1, &scans[0].2, &scans[0].3).unwrap();
        b.add_labelled_scan(scans[1].0, &scans[1].1, &scans[1].2, &scans[1].3).unwrap();
        a.merge(b);
        assert_eq!(a.finish().moved.unwrap().dynamic_total, 2);
        // A moving point added without its label: the block cannot be scored.
        a.add([3.0, 3.0, 3.0], true, true);
        assert_eq!(a.finish().moved, None);
        let mut c = DorAccumulator::new(0.2);
        c.add_scan(&[[0.0; 3]], &[true], &[false]).unwrap();
        assert_eq!(c.finish().moved, None);
        assert!(!render_table(&c.finish()).lines().any(|l| l.starts_with("moved")));
        assert!(c.add_labelled_scan(0, &[[0.0; 3]], &[252], &[]).is_err());
    }

    #[test]
    fn label_files_read_and_bad_sizes_name_the_file() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::create_dir_all(labels_dir(dir.path())).unwrap();
        let p = label_path(dir.path(), 7);
        assert!(p.ends_with("labels/000007.label"));
        let labels: Vec<u32> = vec![252 | (3 << 16), 40, 259];
        std::fs::write(&p, labels.iter().flat_map(|v| v.to_le_bytes()).collect::<Vec<u8>>()).unwrap();
        assert_eq!(read_keyframe_labels(dir.path(), 7, 3).unwrap(), labels);
        assert_eq!(moving_flags(&labels), vec![true, false, true]);
        let e = read_keyframe_labels(dir.path(), 7, 4).unwrap_err().to_string();
        assert!(e.contains("000007.label") && e.contains("3 labels") && e.contains("4 points"), "{e}");
        let e = read_keyframe_labels(dir.path(), 8, 3).unwrap_err().to_string();
        assert!(e.contains("000008.label") && e.contains("hint"), "{e}");
        std::fs::write(&p, [0u8; 6]).unwrap();
        let e = read_keyframe_labels(dir.path(), 7, 1).unwrap_err().to_string();
        assert!(e.contains("000007.label") && e.contains("6 bytes") && e.contains("multiple of 4"), "{e}");
    }

    #[test]
    fn table_has_both_rows_in_percent() {
        let mut acc = DorAccumulator::new(0.2);
        acc.add([0.0; 3], false, false);
        acc.add([0.0, 0.0, 1.0], false, true);
        acc.add([1.0, 0.0, 0.0], true, true);
        let t = render_table(&acc.finish());
        let lines: Vec<&str> = t.lines().collect();
        assert_eq!(lines.len(), 3, "{t}");
        assert!(lines[0].starts_with("block") && lines[0].contains("PR %") && lines[0].contains("precision %"));
        // PR 50.00, RR 100.00, F1 66.67, precision 50.00, AA 70.71.
        for cell in ["50.00", "100.00", "66.67", "70.71"] {
            assert!(lines[1].contains(cell), "{t}");
        }
        assert!(lines[1].starts_with("point") && lines[2].starts_with("voxel 0.2 m"), "{t}");
    }
}
