//! `seam eval changes`: the lifelong map and its change events after the last
//! ingested session, scored against a simulation's objects (MATH.md §9,
//! ELite-style, on the map's 0.2 m voxels).
//!
//! # What is compared
//!
//! The map's voxel centroids and the change events are brought into the
//! simulator's world frame in one of two ways (`placement`):
//!
//! - `owner` (the default): each voxel by its owner keyframe's correction
//!   `T_true · T_est⁻¹` (the map places a voxel with that keyframe, so this
//!   puts it where the sensor saw it, whatever drift is left in the graph);
//!   each event at its voxel's place when the voxel is still in the map.
//!   This scores change detection apart from alignment errors.
//! - `rigid`: one Umeyama SE(3) fit of the estimated keyframe positions onto
//!   the true ones (all sessions the map holds, on the graph version the map
//!   is on), as `seam eval align` does; alignment errors then blur the
//!   objects' edges by up to the ATE.
//!
//! Voxels whose owner has no true pose, and events whose voxel left the map
//! (merged when re-binned), fall back to the rigid fit; for an event, the fit
//! of the graph version its session recorded it on (events keep the position
//! they had then). The truth is the static objects' primitives
//! (`primitives.csv`, world frame) with their presence per session
//! (`objects.csv`, column `sessions`: the 1-based sessions the object exists
//! in), and the movers' boxes per keyframe (`gt/dynamic.csv`).
//!
//! Only the sessions the map holds count (`S`, in ingest order, `first` and
//! `last`); objects present in none of them are ignored. An object is
//! *permanent* when present in every session of `S`.
//!
//! A voxel **belongs to** an object when one of its primitives, grown by
//! `margin_m` (0.2 m), contains the centroid and the centroid is at least
//! `ground_clearance_m` (0.15 m) above the bottom of the object's box (the
//! simulator stands objects on the highest ground under them, so this leaves
//! out the ground they stand on). It is **near** an object when a primitive
//! grown by `margin_m` contains it, whatever its height. The *region* of an
//! object against session `r` is its voxels near no object present in `r`
//! (space another object fills in `r` did not change: a car replaced by
//! another at nearly the same place).
//!
//! # The metrics
//!
//! 1. **Permanent-structure preservation** (goal ≥ 98 %): of the lifelong
//!    voxels that are permanent structure, the fraction in the static map
//!    (ε_g < `static_threshold`). Permanent structure: every voxel except
//!    those within `permanent_margin_m` (0.3 m) of a primitive of a
//!    non-permanent static object or of a mover's box at any keyframe, at
//!    least `ground_clearance_m` above that object's or box's bottom. So the
//!    ground, also under movers and removed objects, is permanent.
//!    Also split: voxels near a permanent object's primitive and the rest
//!    (ground), by class, and by category after the last session.
//! 2. **Leftovers of removed objects** (goal ≤ 5 %): of the lifelong voxels
//!    that belong to a static object absent in `last` (present earlier) and
//!    are near no object present in `last`, the fraction in the static map.
//!    Also: the same among the voxels some session saw free (a
//!    `deleted_overlap` event), which leaves out what no session revisited;
//!    among the voxels some session after the object's last had *in view*
//!    (within its sensor's range and field of view from one of its true
//!    keyframe poses, [`SensorView`]; occlusion is not modelled, so this
//!    leaves out only what no sensor could have seen: a crane jib above a
//!    spinning sensor's band, the space behind a forward one); and the
//!    voxels by category and by object.
//! 3. **Presence of appeared objects** (goal ≥ 90 %): static objects absent in
//!    `first` and present in `last`. An object's voxels are its region
//!    against `first`; it is *seen* with at least `min_voxels` (10) of them
//!    and *present* when at least `present_fraction` (50 %) of them are
//!    static. Reported: present / seen objects (unseen ones listed apart),
//!    and static / all voxels over the union of those regions.
//! 4. **Dynamic leftovers** (goal ≤ 1 %): *mover voxels* are lifelong voxels
//!    inside a mover's box grown by `margin_m` at any keyframe of a session
//!    of `S`, at least `ground_clearance_m` above the box's bottom, and near
//!    no static object. Headline: static mover voxels as a fraction of the
//!    static map. Also reported: the fraction of mover voxels that are static.
//! 5. **Change events in the right session**: for each consecutive pair of
//!    sessions `(a, b)` of `S`, each static object present in `a` and absent
//!    in `b` (*removed*) is right when a `deleted_overlap` event of session
//!    `b` lies in its region against `b`; each object absent in `a` and
//!    present in `b` (*appeared*) is right when an `emerged_overlap`,
//!    `emerged_non_overlap` or `coexist` event of session `b` lies in its
//!    region against `a` (a coexist event is a voxel seen empty in the
//!    session before and occupied again, "returned" in queries: an object
//!    put where another had been taken away). Scored only when the map
//!    shows the object: a removed one with at least `min_voxels` region
//!    voxels first seen before `b`, an appeared one with at least
//!    `min_voxels` region voxels first seen in `b`; the others are counted
//!    as unscored. Each change lists the events in its region by session and
//!    category, how far its session's route passed, and how many of its
//!    region voxels that session's sensor had in view (none: no method could
//!    have placed the change there; the first session that saw the space
//!    records it).

use super::EvalError;
use super::align::{rmse_after, umeyama};
use crate::change::{Category, MapVoxel, SessionChanges};
use crate::geometry::Pose;
use crate::sensor::Fov;
use crate::sim::{GroundTruth, Shape, read_ground_truth};
use crate::store::{self, SessionId, SessionRow, Store, WorldBox};
use nalgebra::{Point3, Vector3};
use rayon::prelude::*;
use rustc_hash::FxHashMap;
use std::collections::{BTreeMap, HashMap};
use std::path::Path;

/// How voxels are matched to the truth.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ChangeEvalConfig {
    /// The static map is the voxels with ε_g below this (`[change]`).
    pub static_threshold: f64,
    /// Primitives and mover boxes are grown by this to test a voxel, m.
    pub margin_m: f64,
    /// Permanent structure keeps this far from changing objects, m.
    pub permanent_margin_m: f64,
    /// Voxels lower than this above an object's (or mover box's) bottom are
    /// the ground it stands on, m.
    pub ground_clearance_m: f64,
    /// An appeared object is present when this fraction of its voxels is static.
    pub present_fraction: f64,
    /// Voxels an object needs in the map to be scored (metrics 3 and 5).
    pub min_voxels: usize,
    /// `owner` or `rigid` (module docs).
    pub placement: Placement,
}

/// How map voxels are brought into the truth's frame (module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Placement {
    Owner,
    Rigid,
}

impl Default for ChangeEvalConfig {
    fn default() -> ChangeEvalConfig {
        ChangeEvalConfig {
            static_threshold: 0.5,
            margin_m: 0.2,
            permanent_margin_m: 0.3,
            ground_clearance_m: 0.15,
            present_fraction: 0.5,
            min_voxels: 10,
            placement: Placement::Owner,
        }
    }
}

/// A static object of the truth, world frame.
#[derive(Debug, Clone, PartialEq)]
pub struct TruthObject {
    pub id: u32,
    pub class: String,
    /// 1-based sessions it exists in, ascending.
    pub sessions: Vec<usize>,
    pub parts: Vec<Shape>,
    /// Bottom of its box, m.
    pub bottom_z: f64,
}

impl TruthObject {
    pub fn present_in(&self, session: usize) -> bool {
        self.sessions.binary_search(&session).is_ok()
    }
}

/// A mover's box at one keyframe of `session`, world frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MoverBox {
    pub session: usize,
    pub shape: Shape,
}

/// A lifelong-map voxel in the truth's frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EvalVoxel {
    pub xyz: [f64; 3],
    pub is_static: bool,
    /// Simulator session that first had it (0: unknown).
    pub first_session: usize,
    /// Some session saw it free (a `deleted_overlap` event at it).
    pub seen_free: bool,
    /// Its category after the last session.
    pub category: Category,
}

/// A change event in the truth's frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EvalEvent {
    /// Simulator session that recorded it.
    pub session: usize,
    pub xyz: [f64; 3],
    pub category: Category,
}

/// `hits` of `total`; `value` is `None` when there is nothing to count.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct Fraction {
    pub hits: u64,
    pub total: u64,
    pub value: Option<f64>,
}

impl Fraction {
    pub fn new(hits: u64, total: u64) -> Fraction {
        Fraction { hits, total, value: (total > 0).then(|| hits as f64 / total as f64) }
    }
}

/// What a session's sensor had in view: a point within the model's range
/// and field of view from one of the session's true keyframe poses (a
/// spinning sensor's elevation band; the ellipse a forward sensor's rosette
/// fills, inscribed in its rectangle). Occlusion is not modelled, so "in
/// view" is an upper bound of what the sensor saw: it separates what no
/// session could have seen (a crane jib above a spinning sensor's band,
/// the space behind a forward sensor) from what seam missed.
#[derive(Debug, Clone)]
pub struct SensorView {
    fov: Fov,
    min_range_m: f64,
    max_range_m: f64,
    /// Per simulator session, world → LiDAR of every keyframe.
    lidar_from_world: HashMap<usize, Vec<Pose>>,
}

impl SensorView {
    /// `poses`: per simulator session, its true `t_world_lidar` per keyframe.
    pub fn new(
        fov: Fov,
        min_range_m: f64,
        max_range_m: f64,
        poses: impl IntoIterator<Item = (usize, Vec<Pose>)>,
    ) -> SensorView {
        let lidar_from_world = poses.into_iter().map(|(s, p)| (s, p.iter().map(|t| t.inverse()).collect())).collect();
        SensorView { fov, min_range_m, max_range_m, lidar_from_world }
    }

    /// Whether some keyframe of `session` had `p` (world) in view.
    pub fn sees(&self, session: usize, p: [f64; 3]) -> bool {
        let Some(poses) = self.lidar_from_world.get(&session) else { return false };
        let p = Point3::from(p);
        poses.iter().any(|t| self.in_fov(&(t * p).coords))
    }

    fn in_fov(&self, q: &Vector3<f64>) -> bool {
        let r = q.norm();
        if !(self.min_range_m..=self.max_range_m).contains(&r) {
            return false;
        }
        let elevation_deg = q.z.atan2(q.x.hypot(q.y)).to_degrees();
        match self.fov {
            Fov::Band { elev_min_deg, elev_max_deg } => (elev_min_deg..=elev_max_deg).contains(&elevation_deg),
            Fov::Rect { azimuth_deg, elevation_deg: height_deg } => {
                let azimuth = q.y.atan2(q.x).to_degrees() / (azimuth_deg / 2.0);
                let elevation = elevation_deg / (height_deg / 2.0);
                azimuth * azimuth + elevation * elevation <= 1.0
            }
        }
    }
}

/// Events of one session and category in an object's region.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct EventCount {
    pub session: usize,
    pub category: String,
    pub count: u64,
}

/// Voxels of a metric's set by their category after the last session.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct CategoryCount {
    pub category: String,
    pub voxels: u64,
    pub static_voxels: u64,
}

fn by_category(counts: &[[u64; 2]; 6]) -> Vec<CategoryCount> {
    Category::ALL
        .iter()
        .zip(counts)
        .filter(|(_, n)| n[0] > 0)
        .map(|(c, n)| CategoryCount { category: c.as_str().into(), voxels: n[0], static_voxels: n[1] })
        .collect()
}

/// `[voxels, static]` summed over categories.
fn total(counts: &[[u64; 2]]) -> [u64; 2] {
    counts.iter().fold([0, 0], |t, c| [t[0] + c[0], t[1] + c[1]])
}

fn category_index(c: Category) -> usize {
    Category::ALL.iter().position(|&x| x == c).unwrap_or(0)
}

/// Voxels of a metric's set by object class.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ClassCount {
    pub class: String,
    pub voxels: u64,
    pub static_voxels: u64,
}

/// One object's change between two sessions (metric 5).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ObjectChange {
    pub object: u32,
    pub class: String,
    /// `removed` or `appeared`.
    pub change: &'static str,
    /// The session it changed in (simulator number).
    pub session: usize,
    /// Region voxels that decide whether it is scored (see the module docs).
    pub voxels: u64,
    pub scored: bool,
    pub correct: bool,
    /// Every event in its region, by session and category.
    pub events: Vec<EventCount>,
    /// Horizontal distance from the object's box centre to the nearest true
    /// keyframe position of `session`, m (filled by [`changes_report`]).
    pub nearest_keyframe_m: Option<f64>,
    /// Of `voxels`, those `session`'s sensor had in view ([`SensorView`];
    /// `None` without one).
    pub in_view_voxels: Option<u64>,
}

/// One removed object's voxels (metric 2).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct RemovedObject {
    pub object: u32,
    pub class: String,
    /// The last session of the map it was present in (simulator number).
    pub last_present: usize,
    pub voxels: u64,
    pub static_voxels: u64,
    /// Its voxels by category after the last session.
    pub categories: Vec<CategoryCount>,
}

/// One voxel of a removed object (metric 2), for diagnosis.
#[derive(Debug, Clone, PartialEq)]
pub struct RemovedVoxel {
    /// Index in the voxels scored.
    pub voxel: usize,
    pub object: u32,
    pub class: String,
    /// The last session of the map the object was present in.
    pub last_present: usize,
    /// Centroid height above the object's box bottom, m.
    pub height_m: f64,
    /// Whether a session after `last_present` had it in view ([`SensorView`]).
    pub in_view_later: Option<bool>,
}

/// One permanent-structure voxel the static map lost (metric 1), for
/// diagnosis: what a rule paid for the leftovers it took.
#[derive(Debug, Clone, PartialEq)]
pub struct LostVoxel {
    /// Index in the voxels scored.
    pub voxel: usize,
    /// The permanent object it is near (the lowest id), `None` for ground
    /// and what the simulator does not model as objects.
    pub object: Option<u32>,
    /// That object's class, `ground` without one.
    pub class: String,
}

/// One appeared object (metric 3).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct AppearedObject {
    pub object: u32,
    pub class: String,
    pub voxels: u64,
    pub static_voxels: u64,
    pub seen: bool,
    pub present: bool,
}

/// The five metrics (module docs).
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct ChangeScores {
    /// Simulator sessions of the map, in ingest order.
    pub sessions: Vec<usize>,
    pub lifelong_voxels: u64,
    pub static_voxels: u64,
    /// 1: static permanent voxels / permanent voxels.
    pub permanent_static: Fraction,
    /// 1, split: permanent voxels near a permanent object's primitive, and
    /// the rest (ground and what the simulator does not model as objects).
    pub permanent_static_objects: Fraction,
    pub permanent_static_ground: Fraction,
    /// 1: permanent voxels by category.
    pub permanent_by_category: Vec<CategoryCount>,
    /// 1: permanent voxels by the class of the permanent object they are
    /// near (the lowest id's), `ground` for the rest; most voxels first.
    pub permanent_by_class: Vec<ClassCount>,
    /// 2: static voxels of removed objects / their voxels.
    pub removed_static: Fraction,
    /// 2, among the voxels some session saw free (`deleted_overlap`): what
    /// remains when the sessions' coverage is left out.
    pub removed_static_seen_free: Fraction,
    /// 2, among the voxels some session after the object's last had in view
    /// ([`SensorView`]; `None` without one): what remains when what no
    /// sensor could see is left out.
    pub removed_static_in_view: Option<Fraction>,
    /// 2: removed objects' voxels by class, most left static first.
    pub removed_by_class: Vec<ClassCount>,
    /// 2: removed objects' voxels by category.
    pub removed_by_category: Vec<CategoryCount>,
    /// 2: each removed object's voxels, most left static first.
    pub removed_by_object: Vec<RemovedObject>,
    /// 2: every voxel counted, in `voxels` order (not in the JSON; `seam
    /// eval changes --removed-voxels FILE` writes it with the map's fields).
    #[serde(skip)]
    pub removed_voxels: Vec<RemovedVoxel>,
    /// 1: every permanent voxel not in the static map, in `voxels` order
    /// (not in the JSON; `seam eval changes --lost-voxels FILE` writes it).
    #[serde(skip)]
    pub lost_voxels: Vec<LostVoxel>,
    pub removed_objects: usize,
    /// 3: present / seen appeared objects.
    pub appeared_present: Fraction,
    /// 3: static / all voxels of the appeared objects.
    pub appeared_static_voxels: Fraction,
    pub appeared: Vec<AppearedObject>,
    /// 4: static mover voxels / static voxels.
    pub mover_static_of_static_map: Fraction,
    /// 4: static mover voxels / mover voxels.
    pub mover_voxels_static: Fraction,
    /// 5: right / scored object changes, both kinds, and each kind.
    pub events_correct: Fraction,
    pub events_removed_correct: Fraction,
    pub events_appeared_correct: Fraction,
    pub events_unscored: usize,
    /// 5: every object change between consecutive sessions.
    pub changes: Vec<ObjectChange>,
}

/// Grid cell size of the spatial index, m.
const CELL_M: f64 = 2.0;
/// A shape covering more cells than this is tested everywhere.
const MAX_CELLS: i64 = 1 << 20;

/// Items binned by the horizontal cells their grown shapes cover.
struct Grid<T> {
    cells: FxHashMap<(i32, i32), Vec<T>>,
    everywhere: Vec<T>,
}

fn cell_of(v: f64) -> i32 {
    (v / CELL_M).floor().clamp(i32::MIN as f64, i32::MAX as f64) as i32
}

impl<T: Copy> Grid<T> {
    fn build<'s>(items: impl Iterator<Item = (T, &'s Shape)>, grow: f64) -> Grid<T> {
        let mut g = Grid { cells: FxHashMap::default(), everywhere: Vec::new() };
        for (t, s) in items {
            let b = s.xy_bounds();
            let (i0, j0, i1, j1) =
                (cell_of(b[0] - grow), cell_of(b[1] - grow), cell_of(b[2] + grow), cell_of(b[3] + grow));
            let n = (i64::from(i1) - i64::from(i0) + 1) * (i64::from(j1) - i64::from(j0) + 1);
            if !(1..=MAX_CELLS).contains(&n) {
                g.everywhere.push(t);
                continue;
            }
            for j in j0..=j1 {
                for i in i0..=i1 {
                    g.cells.entry((i, j)).or_default().push(t);
                }
            }
        }
        g
    }

    fn at(&self, p: [f64; 3]) -> impl Iterator<Item = T> + '_ {
        let here = self.cells.get(&(cell_of(p[0]), cell_of(p[1]))).map(Vec::as_slice).unwrap_or_default();
        here.iter().chain(&self.everywhere).copied()
    }
}

/// Where a point is relative to the truth.
#[derive(Debug, Default)]
struct Located {
    /// Objects it is near (index into the objects), ascending, unique.
    near: Vec<u32>,
    /// Objects it belongs to (near and above the ground clearance).
    of: Vec<u32>,
    /// Within the permanent margin of a changing object or mover.
    changing: bool,
    /// Inside a mover's box (margin, above the clearance).
    mover: bool,
}

struct Scene<'a> {
    objects: &'a [TruthObject],
    movers: &'a [MoverBox],
    /// Present in some session of the map.
    relevant: Vec<bool>,
    permanent: Vec<bool>,
    parts: Grid<(u32, u32)>,
    mover_grid: Grid<u32>,
    cfg: &'a ChangeEvalConfig,
}

fn bottom(s: &Shape) -> f64 {
    s.center[2] - s.size[2] / 2.0
}

impl<'a> Scene<'a> {
    fn new(
        sessions: &[usize],
        objects: &'a [TruthObject],
        movers: &'a [MoverBox],
        cfg: &'a ChangeEvalConfig,
    ) -> Scene<'a> {
        let relevant: Vec<bool> = objects.iter().map(|o| sessions.iter().any(|&s| o.present_in(s))).collect();
        let permanent: Vec<bool> = objects.iter().map(|o| sessions.iter().all(|&s| o.present_in(s))).collect();
        let grow = cfg.margin_m.max(cfg.permanent_margin_m);
        let parts = Grid::build(
            objects
                .iter()
                .enumerate()
                .filter(|(i, _)| relevant[*i])
                .flat_map(|(i, o)| o.parts.iter().enumerate().map(move |(k, s)| ((i as u32, k as u32), s))),
            grow,
        );
        let in_map = |m: &&MoverBox| sessions.contains(&m.session);
        let mover_grid =
            Grid::build(movers.iter().enumerate().filter(|(_, m)| in_map(m)).map(|(i, m)| (i as u32, &m.shape)), grow);
        Scene { objects, movers, relevant, permanent, parts, mover_grid, cfg }
    }

    fn locate(&self, p: [f64; 3]) -> Located {
        let cfg = self.cfg;
        let mut l = Located::default();
        for (oi, pi) in self.parts.at(p) {
            let o = &self.objects[oi as usize];
            let shape = &o.parts[pi as usize];
            let above = p[2] >= o.bottom_z + cfg.ground_clearance_m;
            if shape.contains(p, cfg.margin_m) {
                if !l.near.contains(&oi) {
                    l.near.push(oi);
                }
                if above && !l.of.contains(&oi) {
                    l.of.push(oi);
                }
            }
            if !l.changing && above && !self.permanent[oi as usize] && shape.contains(p, cfg.permanent_margin_m) {
                l.changing = true;
            }
        }
        for mi in self.mover_grid.at(p) {
            let b = &self.movers[mi as usize].shape;
            if p[2] < bottom(b) + cfg.ground_clearance_m {
                continue;
            }
            if b.contains(p, cfg.margin_m) {
                l.mover = true;
            }
            if b.contains(p, cfg.permanent_margin_m) {
                l.changing = true;
            }
        }
        l.near.sort_unstable();
        l.of.sort_unstable();
        l
    }

    /// True when none of the objects `p` is near is present in `session`.
    fn free_of_present(&self, l: &Located, session: usize) -> bool {
        !l.near.iter().any(|&o| self.objects[o as usize].present_in(session))
    }
}

/// An object change to score (metric 5): `object` changed in `session`
/// (index `at` in the ingest order); its region is against `reference`.
struct Case {
    object: u32,
    removed: bool,
    session: usize,
    at: usize,
    reference: usize,
}

#[derive(Debug, Clone, Default)]
struct Acc {
    static_total: u64,
    total: u64,
    permanent: [u64; 2],
    permanent_objects: [u64; 2],
    removed_seen_free: [u64; 2],
    removed_in_view: [u64; 2],
    permanent_categories: [[u64; 2]; 6],
    /// By object index (`u32::MAX`: ground and the rest).
    permanent_objects_by_object: FxHashMap<u32, [u64; 2]>,
    appeared: [u64; 2],
    mover: [u64; 2],
    /// Per object: [voxels, static] of its region against `first`.
    appeared_by_object: FxHashMap<u32, [u64; 2]>,
    /// Per removed object (the lowest index a voxel is of): [voxels, static]
    /// by category after the last session; metric 2's totals and categories
    /// are their sums.
    removed_by_object: FxHashMap<u32, [[u64; 2]; 6]>,
    /// Each removed-object voxel of metric 2: its index in `voxels`, the
    /// object's index and whether a later session had it in view.
    removed_voxels: Vec<(usize, u32, Option<bool>)>,
    /// Each permanent voxel not static: its index in `voxels` and the
    /// permanent object it is near (`u32::MAX`: none).
    lost_voxels: Vec<(usize, u32)>,
    /// Per case: region voxels that decide whether it is scored.
    case_voxels: Vec<u64>,
    /// Per case: of those, the ones its session's sensor had in view.
    case_in_view: Vec<u64>,
}

impl Acc {
    fn merge(mut self, o: Acc) -> Acc {
        self.static_total += o.static_total;
        self.total += o.total;
        for (a, b) in [
            (&mut self.permanent, o.permanent),
            (&mut self.permanent_objects, o.permanent_objects),
            (&mut self.removed_seen_free, o.removed_seen_free),
            (&mut self.removed_in_view, o.removed_in_view),
            (&mut self.appeared, o.appeared),
            (&mut self.mover, o.mover),
        ] {
            a[0] += b[0];
            a[1] += b[1];
        }
        for (a, b) in self.permanent_categories.iter_mut().zip(o.permanent_categories) {
            a[0] += b[0];
            a[1] += b[1];
        }
        for (k, v) in o.permanent_objects_by_object {
            let e = self.permanent_objects_by_object.entry(k).or_default();
            e[0] += v[0];
            e[1] += v[1];
        }
        for (k, v) in o.appeared_by_object {
            let e = self.appeared_by_object.entry(k).or_default();
            e[0] += v[0];
            e[1] += v[1];
        }
        for (k, v) in o.removed_by_object {
            let e = self.removed_by_object.entry(k).or_default();
            for (a, b) in e.iter_mut().zip(v) {
                a[0] += b[0];
                a[1] += b[1];
            }
        }
        self.removed_voxels.extend(o.removed_voxels);
        self.lost_voxels.extend(o.lost_voxels);
        for (mine, theirs) in [(&mut self.case_voxels, o.case_voxels), (&mut self.case_in_view, o.case_in_view)] {
            if mine.len() < theirs.len() {
                mine.resize(theirs.len(), 0);
            }
            for (a, b) in mine.iter_mut().zip(theirs) {
                *a += b;
            }
        }
        self
    }
}

/// Per-class counts, most voxels first.
fn class_counts(classes: BTreeMap<&str, [u64; 2]>) -> Vec<ClassCount> {
    let mut out: Vec<ClassCount> =
        classes.into_iter().map(|(c, n)| ClassCount { class: c.into(), voxels: n[0], static_voxels: n[1] }).collect();
    out.sort_by(|a, b| b.voxels.cmp(&a.voxels).then_with(|| a.class.cmp(&b.class)));
    out
}

/// The five metrics for a map holding simulator sessions `sessions` (in
/// ingest order, at least one), from its voxels and change events in the
/// truth's frame. See the module docs for the definitions.
pub fn score(
    sessions: &[usize],
    objects: &[TruthObject],
    movers: &[MoverBox],
    voxels: &[EvalVoxel],
    events: &[EvalEvent],
    view: Option<&SensorView>,
    cfg: &ChangeEvalConfig,
) -> ChangeScores {
    let (Some(&first), Some(&last)) = (sessions.first(), sessions.last()) else {
        return ChangeScores::default();
    };
    let scene = Scene::new(sessions, objects, movers, cfg);
    let position: HashMap<usize, usize> = sessions.iter().enumerate().map(|(i, &s)| (s, i)).collect();
    let pos_of = |s: usize| position.get(&s).copied().unwrap_or(usize::MAX);
    let static_objects = || (0..objects.len()).filter(|&i| scene.relevant[i]);
    let removed_final: Vec<bool> =
        (0..objects.len()).map(|i| scene.relevant[i] && !objects[i].present_in(last)).collect();
    let appeared_final: Vec<bool> = (0..objects.len())
        .map(|i| scene.relevant[i] && !objects[i].present_in(first) && objects[i].present_in(last))
        .collect();
    // Per object, the position in `sessions` of the last one it was present
    // in, and the sessions of the map after it.
    let last_present: Vec<Option<usize>> =
        objects.iter().map(|o| sessions.iter().rposition(|&s| o.present_in(s))).collect();
    let after_last: Vec<&[usize]> = last_present.iter().map(|k| &sessions[k.map_or(0, |k| k + 1)..]).collect();
    let seen_later = |o: u32, p: [f64; 3]| view.map(|v| after_last[o as usize].iter().any(|&s| v.sees(s, p)));
    let mut cases: Vec<Case> = Vec::new();
    for (at, w) in sessions.windows(2).enumerate() {
        let (a, b) = (w[0], w[1]);
        for i in static_objects() {
            let o = &objects[i];
            if o.present_in(a) && !o.present_in(b) {
                cases.push(Case { object: i as u32, removed: true, session: b, at: at + 1, reference: b });
            } else if !o.present_in(a) && o.present_in(b) {
                cases.push(Case { object: i as u32, removed: false, session: b, at: at + 1, reference: a });
            }
        }
    }
    let mut cases_of: FxHashMap<u32, Vec<usize>> = FxHashMap::default();
    for (c, case) in cases.iter().enumerate() {
        cases_of.entry(case.object).or_default().push(c);
    }

    let empty = || Acc { case_voxels: vec![0; cases.len()], case_in_view: vec![0; cases.len()], ..Acc::default() };
    let mut acc = voxels
        .par_iter()
        .enumerate()
        .fold(empty, |mut acc, (i, v)| {
            let s = u64::from(v.is_static);
            acc.total += 1;
            acc.static_total += s;
            let l = scene.locate(v.xyz);
            if !l.changing {
                acc.permanent[0] += 1;
                acc.permanent[1] += s;
                let c = &mut acc.permanent_categories[category_index(v.category)];
                c[0] += 1;
                c[1] += s;
                let on = l.near.iter().copied().find(|&o| scene.permanent[o as usize]);
                if on.is_some() {
                    acc.permanent_objects[0] += 1;
                    acc.permanent_objects[1] += s;
                }
                let e = acc.permanent_objects_by_object.entry(on.unwrap_or(u32::MAX)).or_default();
                e[0] += 1;
                e[1] += s;
                if !v.is_static {
                    acc.lost_voxels.push((i, on.unwrap_or(u32::MAX)));
                }
            }
            if let Some(&o) = l.of.iter().find(|&&o| removed_final[o as usize])
                && scene.free_of_present(&l, last)
            {
                let e = &mut acc.removed_by_object.entry(o).or_default()[category_index(v.category)];
                e[0] += 1;
                e[1] += s;
                if v.seen_free {
                    acc.removed_seen_free[0] += 1;
                    acc.removed_seen_free[1] += s;
                }
                let later = seen_later(o, v.xyz);
                if later == Some(true) {
                    acc.removed_in_view[0] += 1;
                    acc.removed_in_view[1] += s;
                }
                acc.removed_voxels.push((i, o, later));
            }
            if l.of.iter().any(|&o| appeared_final[o as usize]) && scene.free_of_present(&l, first) {
                acc.appeared[0] += 1;
                acc.appeared[1] += s;
                for &o in l.of.iter().filter(|&&o| appeared_final[o as usize]) {
                    let e = acc.appeared_by_object.entry(o).or_default();
                    e[0] += 1;
                    e[1] += s;
                }
            }
            if l.mover && l.near.is_empty() {
                acc.mover[0] += 1;
                acc.mover[1] += s;
            }
            for &o in &l.of {
                for &c in cases_of.get(&o).map(Vec::as_slice).unwrap_or_default() {
                    let case = &cases[c];
                    let seen =
                        if case.removed { pos_of(v.first_session) < case.at } else { v.first_session == case.session };
                    if seen && scene.free_of_present(&l, case.reference) {
                        acc.case_voxels[c] += 1;
                        if view.is_some_and(|w| w.sees(case.session, v.xyz)) {
                            acc.case_in_view[c] += 1;
                        }
                    }
                }
            }
            acc
        })
        .reduce(empty, Acc::merge);

    // Events in each case's region, by (session, category).
    let case_events: Vec<BTreeMap<(usize, Category), u64>> = events
        .par_iter()
        .fold(
            || vec![BTreeMap::new(); cases.len()],
            |mut acc, e| {
                let l = scene.locate(e.xyz);
                for &o in &l.of {
                    for &c in cases_of.get(&o).map(Vec::as_slice).unwrap_or_default() {
                        if scene.free_of_present(&l, cases[c].reference) {
                            *acc[c].entry((e.session, e.category)).or_insert(0) += 1;
                        }
                    }
                }
                acc
            },
        )
        .reduce(
            || vec![BTreeMap::new(); cases.len()],
            |mut a, b| {
                for (x, y) in a.iter_mut().zip(b) {
                    for (k, n) in y {
                        *x.entry(k).or_insert(0) += n;
                    }
                }
                a
            },
        );

    let changes: Vec<ObjectChange> = cases
        .iter()
        .zip(&case_events)
        .zip(acc.case_voxels.iter().zip(&acc.case_in_view))
        .map(|((case, ev), (&voxels, &in_view))| {
            let o = &objects[case.object as usize];
            let scored = voxels as usize >= cfg.min_voxels;
            let right = |c: Category| {
                if case.removed {
                    c == Category::DeletedOverlap
                } else {
                    // A voxel seen empty the session before and occupied
                    // now comes back as a coexist event ("returned").
                    matches!(c, Category::EmergedOverlap | Category::EmergedNonOverlap | Category::Coexist)
                }
            };
            let correct = scored && ev.iter().any(|(&(s, c), &n)| s == case.session && right(c) && n > 0);
            ObjectChange {
                object: o.id,
                class: o.class.clone(),
                change: if case.removed { "removed" } else { "appeared" },
                session: case.session,
                voxels,
                scored,
                correct,
                events: ev
                    .iter()
                    .map(|(&(session, c), &count)| EventCount { session, category: c.as_str().into(), count })
                    .collect(),
                nearest_keyframe_m: None,
                in_view_voxels: view.is_some().then_some(in_view),
            }
        })
        .collect();
    let right_of = |removed: Option<bool>| {
        let pick: Vec<&ObjectChange> =
            changes.iter().filter(|c| c.scored && removed.is_none_or(|r| (c.change == "removed") == r)).collect();
        Fraction::new(pick.iter().filter(|c| c.correct).count() as u64, pick.len() as u64)
    };

    let mut appeared: Vec<AppearedObject> = (0..objects.len())
        .filter(|&i| appeared_final[i])
        .map(|i| {
            let [n, s] = acc.appeared_by_object.get(&(i as u32)).copied().unwrap_or_default();
            let seen = n as usize >= cfg.min_voxels;
            AppearedObject {
                object: objects[i].id,
                class: objects[i].class.clone(),
                voxels: n,
                static_voxels: s,
                seen,
                present: seen && s as f64 >= cfg.present_fraction * n as f64,
            }
        })
        .collect();
    appeared.sort_by_key(|a| a.object);
    let seen = appeared.iter().filter(|a| a.seen).count() as u64;
    let mut classes: BTreeMap<&str, [u64; 2]> = BTreeMap::new();
    for (&o, n) in &acc.permanent_objects_by_object {
        let e = classes.entry(objects.get(o as usize).map_or("ground", |o| o.class.as_str())).or_default();
        e[0] += n[0];
        e[1] += n[1];
    }
    let permanent_by_class = class_counts(classes);
    let mut classes: BTreeMap<&str, [u64; 2]> = BTreeMap::new();
    let mut removed_categories = [[0u64; 2]; 6];
    let mut removed_by_object: Vec<RemovedObject> = Vec::with_capacity(acc.removed_by_object.len());
    for (&o, counts) in &acc.removed_by_object {
        for (all, c) in removed_categories.iter_mut().zip(counts) {
            all[0] += c[0];
            all[1] += c[1];
        }
        let n = total(counts);
        let object = &objects[o as usize];
        let e = classes.entry(object.class.as_str()).or_default();
        e[0] += n[0];
        e[1] += n[1];
        removed_by_object.push(RemovedObject {
            object: object.id,
            class: object.class.clone(),
            last_present: last_present[o as usize].map_or(0, |k| sessions[k]),
            voxels: n[0],
            static_voxels: n[1],
            categories: by_category(counts),
        });
    }
    removed_by_object.sort_by(|a, b| b.static_voxels.cmp(&a.static_voxels).then_with(|| a.object.cmp(&b.object)));
    acc.removed_voxels.sort_unstable_by_key(|r| r.0);
    let removed_voxels = acc
        .removed_voxels
        .iter()
        .map(|&(i, o, in_view_later)| RemovedVoxel {
            voxel: i,
            object: objects[o as usize].id,
            class: objects[o as usize].class.clone(),
            last_present: last_present[o as usize].map_or(0, |k| sessions[k]),
            height_m: voxels[i].xyz[2] - objects[o as usize].bottom_z,
            in_view_later,
        })
        .collect();
    acc.lost_voxels.sort_unstable_by_key(|r| r.0);
    let lost_voxels = acc
        .lost_voxels
        .iter()
        .map(|&(i, o)| {
            let object = objects.get(o as usize);
            LostVoxel {
                voxel: i,
                object: object.map(|o| o.id),
                class: object.map_or_else(|| "ground".to_string(), |o| o.class.clone()),
            }
        })
        .collect();
    let mut removed_by_class = class_counts(classes);
    removed_by_class.sort_by(|a, b| b.static_voxels.cmp(&a.static_voxels).then_with(|| a.class.cmp(&b.class)));
    ChangeScores {
        sessions: sessions.to_vec(),
        lifelong_voxels: acc.total,
        static_voxels: acc.static_total,
        permanent_static: Fraction::new(acc.permanent[1], acc.permanent[0]),
        permanent_static_objects: Fraction::new(acc.permanent_objects[1], acc.permanent_objects[0]),
        permanent_static_ground: Fraction::new(
            acc.permanent[1] - acc.permanent_objects[1],
            acc.permanent[0] - acc.permanent_objects[0],
        ),
        removed_static: {
            let [n, s] = total(&removed_categories);
            Fraction::new(s, n)
        },
        removed_static_seen_free: Fraction::new(acc.removed_seen_free[1], acc.removed_seen_free[0]),
        removed_static_in_view: view.is_some().then(|| Fraction::new(acc.removed_in_view[1], acc.removed_in_view[0])),
        permanent_by_category: by_category(&acc.permanent_categories),
        permanent_by_class,
        removed_by_class,
        removed_by_category: by_category(&removed_categories),
        removed_by_object,
        removed_voxels,
        lost_voxels,
        removed_objects: removed_final.iter().filter(|&&r| r).count(),
        appeared_present: Fraction::new(appeared.iter().filter(|a| a.present).count() as u64, seen),
        appeared_static_voxels: Fraction::new(acc.appeared[1], acc.appeared[0]),
        appeared,
        mover_static_of_static_map: Fraction::new(acc.mover[1], acc.static_total),
        mover_voxels_static: Fraction::new(acc.mover[1], acc.mover[0]),
        events_correct: right_of(None),
        events_removed_correct: right_of(Some(true)),
        events_appeared_correct: right_of(Some(false)),
        events_unscored: changes.iter().filter(|c| !c.scored).count(),
        changes,
    }
}

/// One metric against its goal, for the summary.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Goal {
    pub metric: String,
    pub value: Option<f64>,
    /// `>=` or `<=`.
    pub relation: &'static str,
    pub goal: f64,
    /// `None` when there was nothing to measure.
    pub met: Option<bool>,
}

fn goal(metric: &str, f: &Fraction, relation: &'static str, goal: f64) -> Goal {
    let met = f.value.map(|v| if relation == ">=" { v >= goal } else { v <= goal });
    Goal { metric: metric.into(), value: f.value, relation, goal, met }
}

/// The goals of the issue, in metric order.
pub fn goals(s: &ChangeScores) -> Vec<Goal> {
    vec![
        goal("permanent structure in the static map", &s.permanent_static, ">=", 0.98),
        goal("removed-object voxels left in the static map", &s.removed_static, "<=", 0.05),
        goal("appeared objects present in the static map", &s.appeared_present, ">=", 0.90),
        goal("mover voxels in the static map (share of it)", &s.mover_static_of_static_map, "<=", 0.01),
        goal("object changes with events in the right session", &s.events_correct, ">=", 0.90),
    ]
}

/// A session's change summary as stored, with its simulator session.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct SessionChangesRow {
    pub session_id: i64,
    pub name: String,
    pub sim_session: usize,
    pub graph_version: i64,
    #[serde(flatten)]
    pub counts: SessionChanges,
}

/// How well the map's keyframes fit the truth.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct FitQuality {
    pub graph_version: i64,
    pub keyframes: usize,
    pub rmse_m: f64,
    pub max_m: f64,
}

/// What `seam eval changes` prints.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ChangesReport {
    pub voxel_m: f64,
    /// The graph version the map is on and the last session folded in.
    pub graph_version: i64,
    pub last_session: String,
    pub sessions: Vec<SessionChangesRow>,
    /// The rigid fit of the map's version to the truth.
    pub alignment: FitQuality,
    /// Voxels and events placed by the rigid fit (all of them with
    /// `rigid`; with `owner`, those without an owner or voxel to follow).
    pub voxels_placed_rigidly: usize,
    pub events_placed_rigidly: usize,
    pub settings: ChangeEvalConfig,
    pub goals: Vec<Goal>,
    pub scores: ChangeScores,
    /// Metric 2's voxels with their map fields (not in the JSON; see
    /// [`write_removed_voxels`]).
    #[serde(skip)]
    pub removed_voxels: Vec<RemovedVoxelRow>,
    /// Metric 1's lost voxels with their map fields (see [`write_lost_voxels`]).
    #[serde(skip)]
    pub lost_voxels: Vec<LostVoxelRow>,
}

/// A voxel the metrics single out (`of`: why), as the map holds it and as
/// the truth places it.
#[derive(Debug, Clone, PartialEq)]
pub struct VoxelRow<T> {
    pub of: T,
    /// As scored: in the truth's frame, static or not, first session.
    pub scored: EvalVoxel,
    pub voxel: MapVoxel,
    /// Simulator numbers of its last session and of the session that set
    /// its category (0: not a session of the truth).
    pub last_seen_session: usize,
    pub category_session: usize,
}

/// A removed object's voxel (metric 2's leftovers and the rest).
pub type RemovedVoxelRow = VoxelRow<RemovedVoxel>;
/// A permanent-structure voxel missing from the static map (metric 1).
pub type LostVoxelRow = VoxelRow<LostVoxel>;

/// The columns every voxel row ends with, after its own.
const VOXEL_COLUMNS: &str = "static,eps_g,eps_l,category,category_session,first_session,last_seen_session,seen_free";
const PLACE_COLUMNS: &str = "truth_x_m,truth_y_m,truth_z_m,x_m,y_m,z_m,points";

impl<T> VoxelRow<T> {
    /// From the scored voxel, the map's, and the simulator numbers of its
    /// last session and of its category's.
    fn new(of: T, (scored, voxel, last_seen_session, category_session): (EvalVoxel, MapVoxel, usize, usize)) -> Self {
        VoxelRow { of, scored, voxel, last_seen_session, category_session }
    }

    fn write_map_fields(&self, out: &mut impl std::io::Write) -> std::io::Result<()> {
        let v = &self.voxel;
        write!(
            out,
            "{},{:.4},{:.4},{},{},{},{},{}",
            self.scored.is_static,
            v.eps_g,
            v.eps_l,
            v.category.as_str(),
            self.category_session,
            self.scored.first_session,
            self.last_seen_session,
            self.scored.seen_free,
        )
    }

    fn write_place(&self, out: &mut impl std::io::Write) -> std::io::Result<()> {
        let [tx, ty, tz] = self.scored.xyz;
        let [x, y, z] = self.voxel.xyz_m;
        writeln!(out, "{tx:.3},{ty:.3},{tz:.3},{x:.3},{y:.3},{z:.3},{}", self.voxel.points)
    }
}

/// Writes `rows` as CSV, one voxel per line, to find out why a removed
/// object's voxels stayed in the static map.
pub fn write_removed_voxels(rows: &[RemovedVoxelRow], out: &mut impl std::io::Write) -> std::io::Result<()> {
    writeln!(out, "voxel_id,object,class,last_present,{VOXEL_COLUMNS},in_view_later,height_m,{PLACE_COLUMNS}")?;
    for r in rows {
        write!(
            out,
            "{},{},{},{},",
            r.voxel.voxel_id,
            r.of.object,
            crate::text::csv_field(&r.of.class),
            r.of.last_present
        )?;
        r.write_map_fields(out)?;
        write!(out, ",{},{:.3},", r.of.in_view_later.map_or(String::new(), |b| b.to_string()), r.of.height_m)?;
        r.write_place(out)?;
    }
    Ok(())
}

/// Writes `rows` as CSV, one voxel per line, to find out what permanent
/// structure a rule took out of the static map (`object` empty: ground).
pub fn write_lost_voxels(rows: &[LostVoxelRow], out: &mut impl std::io::Write) -> std::io::Result<()> {
    writeln!(out, "voxel_id,object,class,{VOXEL_COLUMNS},{PLACE_COLUMNS}")?;
    for r in rows {
        write!(
            out,
            "{},{},{},",
            r.voxel.voxel_id,
            r.of.object.map_or(String::new(), |o| o.to_string()),
            crate::text::csv_field(&r.of.class)
        )?;
        r.write_map_fields(out)?;
        out.write_all(b",")?;
        r.write_place(out)?;
    }
    Ok(())
}

/// The simulator session of each stored session (in store order): the one
/// whose folder the session was ingested from (`session_NN`), else the one
/// its name gives (`sN`), else the same position.
pub fn sim_sessions(rows: &[SessionRow], truth_dirs: &[std::path::PathBuf]) -> Vec<Option<usize>> {
    rows.iter()
        .enumerate()
        .map(|(i, r)| {
            let name = Path::new(&r.source_dir).file_name();
            let by_dir = name.and_then(|n| truth_dirs.iter().position(|d| d.file_name() == Some(n))).map(|p| p + 1);
            let by_name = r
                .name
                .strip_prefix('s')
                .and_then(|n| n.parse::<usize>().ok())
                .filter(|&n| (1..=truth_dirs.len()).contains(&n));
            by_dir.or(by_name).or((i < truth_dirs.len()).then_some(i + 1))
        })
        .collect()
}

fn no_map(store: &Store) -> EvalError {
    EvalError::Mismatch(format!(
        "{} has no lifelong map yet (no session went through the `changes` step)\n  hint: ingest the simulator's \
         sessions with `seam ingest {} SESSION_DIR`, one after the other, then run `seam eval changes` again",
        store.root().display(),
        store.root().display()
    ))
}

/// The Umeyama fit of the keyframe positions of `sessions` on graph
/// version `version` onto the truth.
fn fit(
    store: &Store,
    version: i64,
    sessions: &[(SessionId, usize)],
    truth: &GroundTruth,
) -> Result<(Pose, FitQuality), EvalError> {
    let conn = store.conn();
    let (mut est, mut tru) = (Vec::new(), Vec::new());
    for &(id, number) in sessions {
        let Some(g) = truth.session(number) else { continue };
        for (k, pose) in store::world_poses(conn, version, id)? {
            if let Some(p) = usize::try_from(k).ok().and_then(|k| g.poses.get(k)) {
                est.push(pose.translation.vector);
                tru.push(p.translation.vector);
            }
        }
    }
    if est.len() < 3 {
        return Err(EvalError::Mismatch(format!(
            "only {} keyframes of graph version {version} match the truth's poses; the store's sessions do not come \
             from this simulation\n  hint: pass the --gt folder the sessions were ingested from",
            est.len()
        )));
    }
    let t = umeyama(&est, &tru);
    let (rmse_m, max_m) = rmse_after(&t, &est, &tru);
    Ok((t, FitQuality { graph_version: version, keyframes: est.len(), rmse_m, max_m }))
}

/// Per keyframe `(session id, index)` of `sessions` on graph version
/// `version`, the motion from its estimated world pose to its true pose.
fn corrections(
    store: &Store,
    version: i64,
    sessions: &[(SessionId, usize)],
    truth: &GroundTruth,
) -> Result<FxHashMap<(i64, u32), Pose>, EvalError> {
    let mut out = FxHashMap::default();
    for &(id, number) in sessions {
        let Some(g) = truth.session(number) else { continue };
        for (k, pose) in store::world_poses(store.conn(), version, id)? {
            if let (Ok(k), Some(t)) = (u32::try_from(k), usize::try_from(k).ok().and_then(|k| g.poses.get(k))) {
                out.insert((id.0, k), t * pose.inverse());
            }
        }
    }
    Ok(out)
}

fn apply(t: &Pose, p: [f64; 3]) -> [f64; 3] {
    let q = t * Point3::from(p);
    [q.x, q.y, q.z]
}

/// `seam eval changes`: the store's lifelong map and change events after its
/// last session against the simulation in `gt_dir`.
pub fn changes_report(store: &Store, gt_dir: &Path, cfg: &ChangeEvalConfig) -> Result<ChangesReport, EvalError> {
    for file in ["site.toml", "objects.csv", "primitives.csv"] {
        let path = gt_dir.join(file);
        if !path.is_file() {
            return Err(EvalError::Mismatch(format!(
                "{} is missing\n  hint: --gt takes the folder `seam simulate` wrote (site.toml, objects.csv, \
                 primitives.csv, session_NN/gt/)",
                path.display()
            )));
        }
    }
    let truth = read_ground_truth(gt_dir)?;
    let conn = store.conn();
    let state = store::map_state(conn)?.ok_or_else(|| no_map(store))?;
    let rows = store::sessions(conn)?;
    let dirs: Vec<std::path::PathBuf> = truth.sessions.iter().map(|s| s.dir.clone()).collect();
    let numbers = sim_sessions(&rows, &dirs);
    let number_of: HashMap<i64, usize> =
        rows.iter().zip(&numbers).filter_map(|(r, n)| Some((r.session_id.0, (*n)?))).collect();
    let name_of: HashMap<i64, &str> = rows.iter().map(|r| (r.session_id.0, r.name.as_str())).collect();
    // The graph version each session's changes were recorded on.
    let sql = |source| store::StoreError::Sql { path: conn.path().unwrap_or("seam.db").into(), source };
    let versions: HashMap<i64, i64> = conn
        .prepare("SELECT session_id, graph_version FROM session_changes")
        .and_then(|mut st| st.query_map([], |r| Ok((r.get(0)?, r.get(1)?)))?.collect())
        .map_err(sql)?;
    let mut sessions = Vec::new();
    for (id, counts) in store::session_changes(conn)? {
        let sim_session = number_of.get(&id.0).copied().ok_or_else(|| {
            EvalError::Mismatch(format!(
                "no ground truth for session {} ({:?}); {} has {} sessions\n  hint: pass the --gt folder the \
                 sessions were ingested from",
                id.0,
                name_of.get(&id.0).copied().unwrap_or("?"),
                gt_dir.display(),
                truth.sessions.len()
            ))
        })?;
        sessions.push(SessionChangesRow {
            session_id: id.0,
            name: name_of.get(&id.0).copied().unwrap_or_default().to_string(),
            sim_session,
            graph_version: versions.get(&id.0).copied().unwrap_or(state.graph_version),
            counts,
        });
    }
    sessions.retain(|s| s.session_id <= state.session_id.0);
    if sessions.is_empty() {
        return Err(no_map(store));
    }
    let in_map: Vec<(SessionId, usize)> = sessions.iter().map(|s| (SessionId(s.session_id), s.sim_session)).collect();
    let order: Vec<usize> = in_map.iter().map(|s| s.1).collect();
    let (t_map, alignment) = fit(store, state.graph_version, &in_map, &truth)?;

    let map = store::read_lifelong_map(conn)?;
    let all_events = store::change_events_in(conn, &WorldBox::ALL, 0)?;
    let freed: rustc_hash::FxHashSet<i64> =
        all_events.iter().filter(|r| r.event.category == Category::DeletedOverlap).map(|r| r.event.voxel_id).collect();
    let owners = match cfg.placement {
        Placement::Owner => corrections(store, state.graph_version, &in_map, &truth)?,
        Placement::Rigid => FxHashMap::default(),
    };
    let voxels: Vec<EvalVoxel> = map
        .voxels
        .par_iter()
        .map(|v| EvalVoxel {
            xyz: apply(owners.get(&(v.owner_session, v.owner_keyframe)).unwrap_or(&t_map), v.xyz_m),
            is_static: (v.eps_g as f64) < cfg.static_threshold,
            first_session: number_of.get(&v.first_session).copied().unwrap_or(0),
            seen_free: freed.contains(&v.voxel_id),
            category: v.category,
        })
        .collect();
    let voxels_placed_rigidly =
        map.voxels.iter().filter(|v| !owners.contains_key(&(v.owner_session, v.owner_keyframe))).count();
    let placed: FxHashMap<i64, [f64; 3]> = match cfg.placement {
        Placement::Owner => map.voxels.iter().zip(&voxels).map(|(m, v)| (m.voxel_id, v.xyz)).collect(),
        Placement::Rigid => FxHashMap::default(),
    };
    // Each session's events on the version its ingest recorded them on.
    let mut fits: HashMap<i64, Pose> = HashMap::from([(state.graph_version, t_map)]);
    for (i, s) in sessions.iter().enumerate() {
        if let std::collections::hash_map::Entry::Vacant(e) = fits.entry(s.graph_version) {
            // A version fits the sessions that existed when it was solved.
            e.insert(fit(store, s.graph_version, &in_map[..=i], &truth).map(|f| f.0).unwrap_or(t_map));
        }
    }
    let version_of: HashMap<i64, i64> = sessions.iter().map(|s| (s.session_id, s.graph_version)).collect();
    let mut events_placed_rigidly = 0;
    let events: Vec<EvalEvent> = all_events
        .into_iter()
        .filter_map(|r| {
            let e = r.event;
            let session = *number_of.get(&e.session_id)?;
            let xyz = placed.get(&e.voxel_id).copied().unwrap_or_else(|| {
                events_placed_rigidly += 1;
                apply(version_of.get(&e.session_id).and_then(|v| fits.get(v)).unwrap_or(&t_map), e.xyz_m)
            });
            Some(EvalEvent { session, xyz, category: e.category })
        })
        .collect();

    let objects: Vec<TruthObject> = truth
        .objects
        .iter()
        .filter(|o| !o.dynamic)
        .map(|o| TruthObject {
            id: o.id.0,
            class: o.class.clone(),
            sessions: o.sessions.clone(),
            parts: o.parts.iter().map(|p| p.shape).collect(),
            bottom_z: bottom(&o.bbox),
        })
        .collect();
    let movers: Vec<MoverBox> = truth
        .sessions
        .iter()
        .filter(|g| order.contains(&g.number))
        .flat_map(|g| g.movers.iter().flatten().map(|(_, shape)| MoverBox { session: g.number, shape: *shape }))
        .collect();
    let view = truth.sensor.map(|model| {
        let spec = crate::sim::sensor_spec(model);
        SensorView::new(
            model.fov(),
            spec.min_range_m,
            spec.max_range_m,
            truth.sessions.iter().filter(|g| order.contains(&g.number)).map(|g| (g.number, g.poses.clone())),
        )
    });
    let mut scores = score(&order, &objects, &movers, &voxels, &events, view.as_ref(), cfg);
    for c in &mut scores.changes {
        let (Some(o), Some(g)) = (truth.object(crate::sim::ObjectId(c.object)), truth.session(c.session)) else {
            continue;
        };
        let centre = Vector3::new(o.bbox.center[0], o.bbox.center[1], 0.0);
        c.nearest_keyframe_m = g
            .poses
            .iter()
            .map(|p| (Vector3::new(p.translation.x, p.translation.y, 0.0) - centre).norm())
            .min_by(f64::total_cmp);
    }
    let last_session = name_of.get(&state.session_id.0).copied().unwrap_or_default().to_string();
    let row = |i: usize| {
        let m = &map.voxels[i];
        let session = |id: &i64| number_of.get(id).copied().unwrap_or(0);
        (voxels[i], *m, session(&m.last_seen_session), session(&m.category_session))
    };
    let removed_voxels = scores.removed_voxels.iter().map(|r| VoxelRow::new(r.clone(), row(r.voxel))).collect();
    let lost_voxels = scores.lost_voxels.iter().map(|r| VoxelRow::new(r.clone(), row(r.voxel))).collect();
    Ok(ChangesReport {
        voxel_m: state.voxel_m,
        graph_version: state.graph_version,
        last_session,
        sessions,
        alignment,
        voxels_placed_rigidly,
        events_placed_rigidly,
        settings: cfg.clone(),
        goals: goals(&scores),
        scores,
        removed_voxels,
        lost_voxels,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::FRAC_PI_4;

    fn cfg() -> ChangeEvalConfig {
        ChangeEvalConfig::default()
    }

    fn object(id: u32, sessions: &[usize], parts: Vec<Shape>) -> TruthObject {
        let bottom_z = parts.iter().map(bottom).fold(f64::INFINITY, f64::min);
        TruthObject { id, class: "container".into(), sessions: sessions.to_vec(), parts, bottom_z }
    }

    fn voxel(xyz: [f64; 3], is_static: bool, first_session: usize) -> EvalVoxel {
        EvalVoxel { xyz, is_static, first_session, seen_free: false, category: Category::Coexist }
    }

    /// Voxel centres on a 0.2 m grid filling `[lo, hi)`.
    fn fill(lo: [f64; 3], hi: [f64; 3], is_static: bool, first: usize) -> Vec<EvalVoxel> {
        let mut out = Vec::new();
        let n = |a: f64, b: f64| ((b - a) / 0.2).round() as usize;
        for i in 0..n(lo[0], hi[0]) {
            for j in 0..n(lo[1], hi[1]) {
                for k in 0..n(lo[2], hi[2]).max(1) {
                    let p = [lo[0] + 0.1 + 0.2 * i as f64, lo[1] + 0.1 + 0.2 * j as f64, lo[2] + 0.1 + 0.2 * k as f64];
                    out.push(voxel(p, is_static, first));
                }
            }
        }
        out
    }

    /// A 4 m × 1 m box turned 45° covers points an unturned one does not,
    /// and misses points an unturned one covers; the index finds it in
    /// every cell it reaches.
    #[test]
    fn an_oriented_box_is_tested_in_its_own_frame() {
        let b = Shape::cuboid([10.0, 10.0, 1.0], [4.0, 1.0, 2.0], FRAC_PI_4);
        let along = [10.0 + 1.5 * FRAC_PI_4.cos(), 10.0 + 1.5 * FRAC_PI_4.sin(), 1.0];
        let off_axis = [11.5, 10.0, 1.0];
        assert!(b.contains(along, 0.0) && !b.contains(off_axis, 0.0));
        let unturned = Shape::cuboid([10.0, 10.0, 1.0], [4.0, 1.0, 2.0], 0.0);
        assert!(!unturned.contains(along, 0.0) && unturned.contains(off_axis, 0.0));
        // Removed after session 1: the voxel along its axis belongs to it,
        // the one beside it is permanent ground-level structure.
        let objects = vec![object(1, &[1], vec![b])];
        let voxels = vec![voxel(along, true, 1), voxel(off_axis, true, 1)];
        let s = score(&[1, 2], &objects, &[], &voxels, &[], None, &cfg());
        assert_eq!(s.removed_static, Fraction::new(1, 1));
        assert_eq!(s.permanent_static, Fraction::new(1, 1));
        // Far from the grid's origin cell and across cell borders too.
        let g = Grid::build([(7u32, &b)].into_iter(), 0.3);
        for p in [along, [8.8, 8.8, 0.0], [11.2, 11.2, 0.0]] {
            assert!(g.at(p).any(|t| t == 7), "{p:?}");
        }
        assert_eq!(g.at([20.0, 20.0, 0.0]).count(), 0);
    }

    /// Permanent structure is everything away from changing objects and
    /// movers, the ground under them included; only static voxels of it count.
    #[test]
    fn permanent_structure_excludes_changing_objects_but_not_their_ground() {
        let wall = Shape::cuboid([0.0, 5.0, 1.5], [10.0, 0.2, 3.0], 0.0);
        let container = Shape::cuboid([0.0, 0.0, 1.3], [6.0, 2.4, 2.6], 0.0);
        let mut objects = vec![object(1, &[1, 2, 3], vec![wall]), object(2, &[2, 3], vec![container])];
        objects[0].class = "wall".into();
        let mut voxels = fill([-1.0, 4.8, 0.4], [1.0, 5.2, 2.0], true, 1); // the wall: permanent
        let wall_n = voxels.len() as u64;
        voxels.extend(fill([-1.0, -0.8, 0.4], [1.0, 0.8, 2.0], true, 2)); // the container
        voxels.extend(fill([-1.0, -0.8, -0.2], [1.0, 0.8, 0.0], true, 1)); // ground under it
        let ground_n = 10 * 8;
        voxels.push(voxel([0.0, 5.0, 2.9], false, 1)); // a wall voxel out of the static map
        let s = score(&[1, 2, 3], &objects, &[], &voxels, &[], None, &cfg());
        assert_eq!(s.permanent_static, Fraction::new(wall_n + ground_n, wall_n + ground_n + 1));
        assert_eq!(s.permanent_static_objects, Fraction::new(wall_n, wall_n + 1));
        assert_eq!(s.permanent_static_ground, Fraction::new(ground_n, ground_n));
        let classes: Vec<(&str, u64, u64)> =
            s.permanent_by_class.iter().map(|c| (c.class.as_str(), c.voxels, c.static_voxels)).collect();
        assert_eq!(classes, [("wall", wall_n + 1, wall_n), ("ground", ground_n, ground_n)]);
        // The lost list holds that one wall voxel, named by its object.
        let lost: Vec<(usize, Option<u32>, &str)> =
            s.lost_voxels.iter().map(|l| (l.voxel, l.object, l.class.as_str())).collect();
        assert_eq!(lost, [(voxels.len() - 1, Some(1), "wall")]);
        // The container appeared in session 2 and is all static: present.
        assert_eq!(s.appeared_present, Fraction::new(1, 1));
        assert_eq!(s.appeared[0].voxels, 10 * 8 * 8);
    }

    /// Voxels of a removed object that another object fills in the last
    /// session (a car replaced by another at nearly the same place) are not
    /// leftovers; the rest are, and the ground under it is not.
    #[test]
    fn removed_leftovers_skip_space_a_present_object_fills() {
        let old = Shape::cuboid([0.0, 0.0, 0.8], [4.5, 1.8, 1.6], 0.0);
        let new = Shape::cuboid([1.0, 0.0, 0.8], [4.5, 1.8, 1.6], 0.0);
        let objects = vec![object(1, &[1], vec![old]), object(2, &[2], vec![new])];
        // Old car's voxels from x -2.2 to 2.2; x >= -1.45 is within the new
        // car grown by 0.2 m.
        let mut voxels = fill([-2.2, -0.8, 0.4], [-1.6, 0.8, 1.4], false, 1);
        let gone = voxels.len() as u64;
        voxels.extend(fill([-1.4, -0.8, 0.4], [2.2, 0.8, 1.4], true, 1));
        voxels.extend(fill([-2.2, -0.8, -0.2], [2.2, 0.8, 0.0], true, 1)); // ground
        voxels[0].is_static = true; // one leftover, never seen free
        for v in &mut voxels[1..4] {
            v.seen_free = true;
        }
        let s = score(&[1, 2], &objects, &[], &voxels, &[], None, &cfg());
        assert_eq!(s.removed_objects, 1);
        assert_eq!(s.removed_static, Fraction::new(1, gone));
        assert_eq!(s.removed_static_seen_free, Fraction::new(0, 3));
        let c = &s.removed_by_category;
        assert_eq!((c.len(), c[0].category.as_str(), c[0].voxels, c[0].static_voxels), (1, "coexist", gone, 1));
        let k = &s.removed_by_class;
        assert_eq!((k.len(), k[0].class.as_str(), k[0].voxels, k[0].static_voxels), (1, "container", gone, 1));
        let o = &s.removed_by_object;
        assert_eq!((o.len(), o[0].object, o[0].last_present, o[0].voxels, o[0].static_voxels), (1, 1, 1, gone, 1));
        assert_eq!(o[0].categories, *c);
        // The per-voxel list holds exactly those voxels, in order, with the
        // height above the car's bottom (0 m): the leftover's centre is 0.5 m up.
        let listed: Vec<usize> = s.removed_voxels.iter().map(|r| r.voxel).collect();
        assert_eq!(listed, (0..gone as usize).collect::<Vec<_>>());
        let r = &s.removed_voxels[0];
        assert_eq!((r.object, r.class.as_str(), r.last_present, r.in_view_later), (1, "container", 1, None));
        assert!((r.height_m - 0.5).abs() < 1e-9, "{}", r.height_m);
    }

    /// A spinning sensor sees its elevation band within range; a forward
    /// one the ellipse inside its rectangle, ahead only.
    #[test]
    fn sensor_view_is_the_band_or_the_ellipse_within_range() {
        let at_origin = || [(1, vec![Pose::identity()])];
        let band = SensorView::new(Fov::Band { elev_min_deg: -22.5, elev_max_deg: 22.5 }, 0.5, 120.0, at_origin());
        assert!(band.sees(1, [-10.0, 0.0, 1.0])); // behind is fine for a 360° sensor
        assert!(!band.sees(1, [10.0, 0.0, 5.0])); // 26.6° up
        assert!(!band.sees(1, [130.0, 0.0, 0.0])); // beyond its range
        assert!(!band.sees(1, [0.2, 0.0, 0.0])); // blanked
        assert!(!band.sees(2, [10.0, 0.0, 0.0])); // no such session
        let ahead = SensorView::new(Fov::Rect { azimuth_deg: 70.4, elevation_deg: 77.2 }, 1.0, 190.0, at_origin());
        assert!(ahead.sees(1, [10.0, 0.0, 0.0]));
        assert!(!ahead.sees(1, [-10.0, 0.0, 0.0]));
        let corner = [10.0, 30f64.to_radians().tan() * 10.0, 0.0];
        assert!(ahead.sees(1, corner)); // 30° left, level
        // 30° left and 30° up: inside the rectangle, outside the ellipse.
        let up = 30f64.to_radians().tan() * corner[0].hypot(corner[1]);
        assert!(!ahead.sees(1, [corner[0], corner[1], up]));
        // A keyframe turned around sees behind the first.
        let turned = Pose::from_parts(
            nalgebra::Translation3::new(0.0, 0.0, 0.0),
            nalgebra::UnitQuaternion::from_euler_angles(0.0, 0.0, std::f64::consts::PI),
        );
        let both = SensorView::new(
            Fov::Rect { azimuth_deg: 70.4, elevation_deg: 77.2 },
            1.0,
            190.0,
            [(1, vec![Pose::identity(), turned])],
        );
        assert!(both.sees(1, [-10.0, 0.0, 0.0]));
    }

    /// Removed-object leftovers among what a later session had in view, and
    /// each change's voxels its session had in view.
    #[test]
    fn in_view_leftovers_count_only_what_a_later_session_could_see() {
        let crate_box = Shape::cuboid([20.0, 0.0, 0.8], [2.0, 2.0, 1.6], 0.0);
        let objects = vec![object(1, &[1], vec![crate_box])];
        let voxels = fill([19.2, -0.8, 0.4], [20.8, 0.8, 1.4], true, 1);
        // Session 2 looks down the +x axis from x = 0 (the crate is ahead)
        // with a band that ends at 2° up: the crate's top layers, about
        // 0.7 m above the sensor's height and more, are out of view.
        let view = SensorView::new(
            Fov::Band { elev_min_deg: -20.0, elev_max_deg: 2.0 },
            0.5,
            100.0,
            [(1, vec![Pose::identity()]), (2, vec![Pose::identity()])],
        );
        let s = score(&[1, 2], &objects, &[], &voxels, &[], Some(&view), &cfg());
        let elevation_deg = |p: [f64; 3]| p[2].atan2(p[0].hypot(p[1])).to_degrees();
        let low = voxels.iter().filter(|v| elevation_deg(v.xyz) <= 2.0).count() as u64;
        assert!(low > 0 && low < voxels.len() as u64);
        assert_eq!(s.removed_static, Fraction::new(voxels.len() as u64, voxels.len() as u64));
        assert_eq!(s.removed_static_in_view, Some(Fraction::new(low, low)));
        let change = &s.changes[0];
        assert_eq!((change.change, change.voxels, change.in_view_voxels), ("removed", voxels.len() as u64, Some(low)));
        let without = score(&[1, 2], &objects, &[], &voxels, &[], None, &cfg());
        assert_eq!((without.removed_static_in_view, without.changes[0].in_view_voxels), (None, None));
    }

    /// An appeared object is present with half its voxels static and seen
    /// with `min_voxels` (3 here); the voxel fraction pools every appeared object.
    #[test]
    fn appeared_presence_rule() {
        let a = Shape::cuboid([0.0, 0.0, 1.0], [1.0, 1.0, 2.0], 0.0);
        let b = Shape::cuboid([10.0, 0.0, 1.0], [1.0, 1.0, 2.0], 0.3);
        let c = Shape::cuboid([20.0, 0.0, 1.0], [1.0, 1.0, 2.0], 0.0);
        let objects = vec![object(1, &[2, 3], vec![a]), object(2, &[3], vec![b]), object(3, &[3], vec![c])];
        let mut voxels = Vec::new();
        for (i, x) in [0.0, 0.1, 0.2, 0.3].iter().enumerate() {
            voxels.push(voxel([*x, 0.0, 1.0], i < 2, 2)); // 2 of 4: present
            voxels.push(voxel([10.0 + x, 0.0, 1.0], i < 1, 3)); // 1 of 4: absent
        }
        voxels.push(voxel([20.0, 0.0, 1.0], true, 3)); // 1 voxel: unseen
        let s = score(&[1, 2, 3], &objects, &[], &voxels, &[], None, &ChangeEvalConfig { min_voxels: 3, ..cfg() });
        assert_eq!(s.appeared_present, Fraction::new(1, 2));
        assert_eq!(s.appeared_static_voxels, Fraction::new(4, 9));
        let seen: Vec<(u32, bool, bool)> = s.appeared.iter().map(|a| (a.object, a.seen, a.present)).collect();
        assert_eq!(seen, [(1, true, true), (2, true, false), (3, false, false)]);
    }

    /// Mover leftovers: static voxels inside a mover's box at some keyframe,
    /// above its feet; the road under it is permanent.
    #[test]
    fn mover_leftovers_ignore_the_ground_under_feet() {
        let person = |x: f64| MoverBox { session: 1, shape: Shape::cuboid([x, 0.0, 0.85], [0.5, 0.5, 1.7], 1.0) };
        let movers = vec![person(0.0), person(0.5), person(1.0), MoverBox { session: 4, ..person(30.0) }];
        let mut voxels = fill([-0.2, -0.2, 0.0], [1.2, 0.2, 0.2], true, 1); // road
        let road = voxels.len() as u64;
        voxels.push(voxel([0.5, 0.0, 1.0], true, 1)); // a leftover
        voxels.push(voxel([1.0, 0.1, 1.5], false, 1)); // removed
        voxels.push(voxel([30.0, 0.0, 1.0], true, 1)); // a session not in the map: ignored
        let s = score(&[1, 2], &[], &movers, &voxels, &[], None, &cfg());
        assert_eq!(s.mover_voxels_static, Fraction::new(1, 2));
        assert_eq!(s.mover_static_of_static_map, Fraction::new(1, road + 2));
        assert_eq!(s.permanent_static, Fraction::new(road + 1, road + 1));
    }

    /// Events count for the session an object changed in, in its region,
    /// with the right category; objects the map never showed are unscored.
    #[test]
    fn change_events_must_be_in_the_right_session() {
        let gone = Shape::cuboid([0.0, 0.0, 1.0], [2.0, 2.0, 2.0], 0.5);
        let came = Shape::cuboid([10.0, 0.0, 1.0], [2.0, 2.0, 2.0], 0.0);
        let late = Shape::cuboid([20.0, 0.0, 1.0], [2.0, 2.0, 2.0], 0.0);
        let unseen = Shape::cuboid([30.0, 0.0, 1.0], [2.0, 2.0, 2.0], 0.0);
        let back = Shape::cuboid([40.0, 0.0, 1.0], [2.0, 2.0, 2.0], 0.0);
        let objects = vec![
            object(1, &[1], vec![gone]),
            object(2, &[2, 3], vec![came]),
            object(3, &[1, 2], vec![late]),
            object(4, &[3], vec![unseen]),
            object(5, &[3], vec![back]),
        ];
        let mut voxels = fill([-0.6, -0.6, 0.6], [0.6, 0.6, 1.2], false, 1);
        voxels.extend(fill([9.4, -0.6, 0.6], [10.6, 0.6, 1.2], true, 2));
        voxels.extend(fill([19.4, -0.6, 0.6], [20.6, 0.6, 1.2], true, 1));
        voxels.extend(fill([39.4, -0.6, 0.6], [40.6, 0.6, 1.2], true, 3));
        let ev = |session, x: f64, category| EvalEvent { session, xyz: [x, 0.1, 1.0], category };
        let events = vec![
            ev(2, 0.1, Category::DeletedOverlap),       // right
            ev(2, 10.1, Category::EmergedNonOverlap),   // right
            ev(2, 20.1, Category::DeletedOverlap),      // object 3 is removed in 3, not 2
            ev(3, 20.1, Category::DeletedNonOverlap),   // not seen free: wrong
            ev(2, 10.1, Category::DeletedOverlap),      // noise, ignored
            ev(3, 30.1, Category::EmergedNonOverlap),   // object 4 has no voxels
            ev(2, 0.1 + 5.0, Category::DeletedOverlap), // outside every object
            ev(3, 20.1, Category::Coexist),             // came back: no removal
            ev(3, 40.1, Category::Coexist),             // came back where object 5 appeared: right
        ];
        let s = score(&[1, 2, 3], &objects, &[], &voxels, &events, None, &cfg());
        let got: Vec<(u32, &str, usize, bool, bool)> =
            s.changes.iter().map(|c| (c.object, c.change, c.session, c.scored, c.correct)).collect();
        assert_eq!(
            got,
            [
                (1, "removed", 2, true, true),
                (2, "appeared", 2, true, true),
                (3, "removed", 3, true, false),
                (4, "appeared", 3, false, false),
                (5, "appeared", 3, true, true),
            ]
        );
        assert_eq!(s.events_correct, Fraction::new(3, 4));
        assert_eq!(s.events_removed_correct, Fraction::new(1, 2));
        assert_eq!(s.events_appeared_correct, Fraction::new(2, 2));
        assert_eq!(s.events_unscored, 1);
        let three = &s.changes[2].events;
        assert_eq!(three.len(), 3);
        assert_eq!((three[1].session, three[1].category.as_str()), (3, "coexist"));
        assert_eq!((three[2].session, three[2].category.as_str(), three[2].count), (3, "deleted_non_overlap", 1));
    }

    /// The goals read the fractions; nothing measured is neither met nor missed.
    #[test]
    fn goals_compare_in_the_right_direction() {
        let s = ChangeScores {
            permanent_static: Fraction::new(99, 100),
            removed_static: Fraction::new(6, 100),
            ..ChangeScores::default()
        };
        let g = goals(&s);
        assert_eq!(g[0].met, Some(true));
        assert_eq!(g[1].met, Some(false));
        assert_eq!(g[2].met, None);
    }

    fn row(id: i64, name: &str, dir: &str) -> SessionRow {
        SessionRow {
            session_id: SessionId(id),
            name: name.into(),
            content_hash: String::new(),
            source_dir: dir.into(),
            layout: "kitti".into(),
            date: None,
            sensor_model: None,
            fov_json: None,
            keyframe_count: 0,
            point_count: 0,
            status: "complete".into(),
            created_at: String::new(),
            completed_at: None,
        }
    }

    /// Stored sessions find their simulator session by folder, then name,
    /// then position.
    #[test]
    fn stored_sessions_map_to_simulator_sessions() {
        let dirs: Vec<std::path::PathBuf> =
            (1..=3).map(|n| std::path::PathBuf::from(format!("/sim/session_{n:02}"))).collect();
        let rows = [
            row(1, "a", "/data/copy/session_02"),
            row(2, "s3", "/elsewhere/x"),
            row(3, "b", "/elsewhere/y"),
            row(4, "c", "/elsewhere/z"),
        ];
        assert_eq!(sim_sessions(&rows, &dirs), [Some(2), Some(3), Some(3), None]);
    }
}
