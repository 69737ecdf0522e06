//! A session's evidence, DOR labels and cleaned maps (MATH.md §6), and the
//! reprojection of stored evidence after re-optimisation (§7).
//!
//! ```text
//!  keyframes (world poses of graph version g, scans)
//!     │ interest set: every point's voxel (+ earlier sessions' map voxels)
//!     │ surface shapes: the patch of points per voxel (evidence::surface)
//!     ▼
//!  per submap, keyframes in order:  InterestEvidence::add_keyframe   ──► SubmapEvidence (stored)
//!     │ summed over submaps (same grid: no re-binning)
//!     ▼
//!  session evidence ──► ε_l per voxel ──► PointLabels (every point), CleanedMap per submap
//!
//!  later version h:  SubmapEvidence(g) ──► ΔT_i = W_h,i · W_g,i⁻¹ of owner i ──► re-binned world rows
//! ```
//!
//! Grid choice: evidence is generated on the world grid of the graph version
//! it is generated from, not on each submap's own axes. `ΔT_i` of eq. 10 is
//! `A_now · T_rigid,i · A_gen⁻¹ = W_now,i · W_gen,i⁻¹` (W the keyframe's world
//! pose), so reprojection needs only the owner keyframe's two world poses, and
//! because ΔT is a small motion, re-binning moves whole neighbourhoods together
//! instead of aliasing a rotated grid onto the world's (a submap's own axes
//! can be turned by any yaw). The submap-frame coordinates of a row are
//! `A_gen⁻¹ · x`, with `A_gen` from the stored graph version.

use super::grid::{
    Box3, InterestEvidence, RayStats, Row, add_points_by_row, bit_set, pack, packed_key, row_of, unpack,
};
use super::ground::GroundLevel;
use super::grow::{footing_candidates, ground_rows, keyframe_dynamic, stands_on_ground};
use super::no_return::{NoReturn, NoReturnImage};
use super::raycast::voxel_key;
use super::stats::{EvidenceConfig, EvidenceModel, FreeTest};
use super::surface::{MapPatch, Moments, SurfaceShapes};
use super::tables::{CleanedMap, NO_HIT_BOX, PointLabels, SubmapEvidence};
use crate::geometry::{Pose, VoxelKey, rotate_sym, rotation_rows, transformed, transformed_into};
use crate::sensor::Fov;
use nalgebra::Point3;
use rayon::prelude::*;
use rustc_hash::{FxHashMap, FxHashSet};
use std::sync::atomic::{AtomicU32, AtomicU64, Ordering};
use std::time::Instant;

/// One keyframe going into [`generate`].
#[derive(Debug, Clone, Copy)]
pub struct KeyframeInput<'a> {
    /// Index of the keyframe in its session (the scan's index).
    pub index: u32,
    /// Ordinal of its submap within the session (0-based, non-decreasing).
    pub submap: usize,
    /// World pose of the sensor at the generating graph version.
    pub t_world_keyframe: Pose,
    /// The scan, in the sensor frame.
    pub points: &'a [[f32; 3]],
}

/// Everything [`generate`] produces for one session.
#[derive(Debug, Clone, Default)]
pub struct SessionEvidence {
    /// Per submap ordinal.
    pub submaps: Vec<SubmapEvidence>,
    /// Per submap ordinal.
    pub cleaned: Vec<CleanedMap>,
    pub labels: PointLabels,
    pub stats: GenerationStats,
}

/// Counts and times of one generation, for the step log.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct GenerationStats {
    pub keyframes: usize,
    pub points: usize,
    pub skipped_rays: usize,
    /// Map voxels freed by beams that returned nothing, summed over keyframes.
    pub no_return_voxels: usize,
    /// This session's own voxels freed that way (`own_no_return_*`).
    pub own_no_return_voxels: usize,
    /// Voxels of interest (occupied by this session's points or given).
    pub interest_voxels: usize,
    /// Voxels with stored evidence, summed over submaps.
    pub generated_voxels: usize,
    pub dynamic_voxels: usize,
    pub dynamic_points: usize,
    /// Of those, the points made dynamic by the growth and footing steps
    /// (`evidence::grow`), not by their own voxel's ε_l.
    pub grown_points: usize,
    pub cleaned_voxels: usize,
    /// Wall time before the first ray: interest keys, ground levels, the
    /// no-return candidates and the surface shapes.
    pub prepare_s: f64,
    pub raycast_s: f64,
    /// ε_l, the dynamic voxels and every point's label (growth and footing
    /// steps included).
    pub dor_s: f64,
    /// The cleaned maps.
    pub cleaned_s: f64,
    pub total_s: f64,
}

fn world_points(kf: &KeyframeInput<'_>) -> Vec<[f64; 3]> {
    transformed(kf.points, &kf.t_world_keyframe)
}

/// [`world_points`] into `out` (cleared first): one buffer for a loop over
/// keyframes, so that each keyframe's few megabytes are not fresh pages.
fn world_points_into(kf: &KeyframeInput<'_>, out: &mut Vec<[f64; 3]>) {
    transformed_into(kf.points, &kf.t_world_keyframe, out)
}

fn origin(kf: &KeyframeInput<'_>) -> [f64; 3] {
    kf.t_world_keyframe.translation.vector.into()
}

/// Ray casts one session: evidence per submap, ε_l, labels of every point and
/// the cleaned map per submap. `map` adds voxels to keep evidence for beyond
/// those the session's own points occupy — the earlier sessions' map, which
/// change detection compares against — with the patch of points each had,
/// which this session's rays must cross to free it (`evidence::surface`).
///
/// `fov` is the session's sensor field of view; with it, the beams that
/// returned nothing free the map voxels this session's points do not occupy
/// (`evidence::no_return`, up to `cfg.no_return_range_m`).
pub fn generate(
    keyframes: &[KeyframeInput<'_>],
    map: &[MapPatch],
    fov: Option<&Fov>,
    cfg: &EvidenceConfig,
    mut progress: impl FnMut(usize),
) -> SessionEvidence {
    let started = Instant::now();
    let v = cfg.voxel_size_m;
    let n_submaps = keyframes.iter().map(|k| k.submap + 1).max().unwrap_or(0);
    // Interest keys and ray boxes, per keyframe in parallel.
    let per_kf: Vec<(Vec<u64>, Box3)> = keyframes
        .par_iter()
        .map(|kf| {
            let pts = world_points(kf);
            let mut keys: Vec<u64> = pts.iter().filter_map(|p| packed_key(p, v)).collect();
            keys.sort_unstable();
            keys.dedup();
            (keys, Box3::of_rays(&origin(kf), &pts, v))
        })
        .collect();
    // Per keyframe, the cells of `own_no_return_clear_m` its points fall in.
    let own_cell = ((cfg.own_no_return_clear_m / v).round() as i32).max(1);
    let own_clear: Vec<FxHashSet<[i32; 3]>> = if fov.is_some() && cfg.own_no_return_range_m > 0.0 {
        per_kf
            .par_iter()
            .map(|(k, _)| k.iter().map(|&k| unpack(k).0.map(|c| c.div_euclid(own_cell))).collect())
            .collect()
    } else {
        Vec::new()
    };
    let no_return_fov = fov.filter(|_| cfg.no_return_range_m > 0.0 && !map.is_empty());
    // Per submap, the box of its rays (and of the map voxels its no-return
    // beams may free), and the slab of x its points span (packed keys sort
    // by x first).
    let mut submap_box = vec![Box3::EMPTY; n_submaps];
    let mut points_x = vec![Box3::EMPTY; n_submaps];
    for (kf, (k, b)) in keyframes.iter().zip(&per_kf) {
        submap_box[kf.submap] = submap_box[kf.submap].union(b);
        if let (Some(&first), Some(&last)) = (k.first(), k.last()) {
            let slab = Box3::x_slab(unpack(first).0[0], unpack(last).0[0]);
            points_x[kf.submap] = points_x[kf.submap].union(&slab);
        }
        if no_return_fov.is_some() {
            // The map voxels this keyframe's no-return beams may free.
            let around = Box3::within_range(&origin(kf), cfg.no_return_range_m, v);
            submap_box[kf.submap] = submap_box[kf.submap].union(&around);
        }
    }
    // The interest keys: the map's and every keyframe's, each run sorted.
    let mut session = {
        let mut map_keys: Vec<u64> = map.iter().map(|p| p.key).collect();
        map_keys.par_sort_unstable();
        map_keys.dedup();
        let runs: Vec<&[u64]> = std::iter::once(&map_keys[..]).chain(per_kf.iter().map(|(k, _)| &k[..])).collect();
        InterestEvidence::from_sorted_runs(&runs, v)
    };
    if cfg.clearance_near_ground_only || !cfg.ground_hits_guard || cfg.grow_max_hits > 0 || cfg.footing_height_m > 0.0 {
        session.set_ground(GroundLevel::from_keys(per_kf.iter().flat_map(|(k, _)| k)));
    }
    // Rows some point of this session occupies: what vacated map voxels and
    // (with no clearance cells) no-return candidates must not be.
    let needs_own =
        !map.is_empty() && (cfg.free_vacated_low || (no_return_fov.is_some() && cfg.no_return_clear_m <= 0.0));
    let own_rows = if needs_own { occupied_rows(&session, &per_kf) } else { Vec::new() };
    if cfg.free_vacated_low && !map.is_empty() {
        // Map voxels no point of this session occupies and that cannot be
        // ground: freed next to own hits and below the clearance.
        let vacated: Vec<usize> = map
            .par_iter()
            .filter(|p| !p.maybe_ground())
            .filter_map(|p| session.find(p.key))
            .filter(|&i| !bit_set(&own_rows, i))
            .collect();
        session.set_unguarded(vacated);
    }
    // Map voxels with none of this session's points within about
    // `no_return_clear_m`: the only ones beams that returned nothing may
    // free, each up to the range it was seen from (× the reach factor).
    let no_return_reach: Vec<f32> = if no_return_fov.is_some() {
        let cell = ((cfg.no_return_clear_m / v).round() as i32).max(1);
        let coarse = |k: u64| unpack(k).0.map(|c| c.div_euclid(cell));
        let occupied: rustc_hash::FxHashSet<[i32; 3]> =
            per_kf.iter().flat_map(|(k, _)| k.iter().map(|&k| coarse(k))).collect();
        let reach = i32::from(cfg.no_return_clear_m > 0.0);
        let clear = |k: u64| {
            let c = coarse(k);
            let r = -reach..=reach;
            !r.clone()
                .any(|dx| r.clone().any(|dy| r.clone().any(|dz| occupied.contains(&[c[0] + dx, c[1] + dy, c[2] + dz]))))
        };
        let mut in_map: Vec<(u64, f64)> = map.iter().map(|p| (p.key, p.seen_from_m)).collect();
        in_map.par_sort_unstable_by_key(|p| p.0);
        session
            .keys()
            .par_iter()
            .enumerate()
            .map(|(row, k)| match in_map.binary_search_by_key(k, |p| p.0) {
                Ok(i) if clear(*k) && (reach > 0 || !bit_set(&own_rows, row)) => {
                    (in_map[i].1 * cfg.no_return_reach_factor).min(cfg.no_return_range_m) as f32
                }
                _ => 0.0,
            })
            .collect()
    } else {
        Vec::new()
    };
    // This session's own voxels that at most `own_no_return_max_keyframes`
    // keyframes put a point in: the ones its beams that returned nothing may
    // free (`evidence::no_return`, within a session).
    let own_fov = fov.filter(|_| cfg.own_no_return_range_m > 0.0);
    let own_candidate = if own_fov.is_some() { few_keyframes_rows(&session, &per_kf, cfg) } else { Vec::new() };
    drop(per_kf);
    let level_above_m = keyframes.iter().map(|k| k.t_world_keyframe.translation.vector.z).fold(f64::INFINITY, f64::min)
        + super::grid::CLEARANCE_MIN_DROP_M;
    let shapes = (cfg.free_test == FreeTest::Surface)
        .then(|| SurfaceShapes::build(session.keys(), keyframes.iter().map(world_points), v, map, level_above_m, cfg));
    let mut stats = GenerationStats {
        keyframes: keyframes.len(),
        points: keyframes.iter().map(|k| k.points.len()).sum(),
        interest_voxels: session.len(),
        ..Default::default()
    };

    let t_ray = Instant::now();
    stats.prepare_s = (t_ray - started).as_secs_f64();
    let mut submaps = Vec::with_capacity(n_submaps);
    let mut done = 0;
    let mut pts = Vec::new();
    for (s, b) in submap_box.iter().enumerate() {
        let (mut sub, idx) = session.subset(b);
        session.continue_log_odds(&mut sub, &idx);
        let (candidates, candidate_range_m): (Vec<u32>, Vec<f32>) = if no_return_reach.is_empty() {
            Default::default()
        } else {
            (0..idx.len() as u32)
                .map(|j| (j, no_return_reach[idx[j as usize] as usize]))
                .filter(|&(_, r)| r > 0.0)
                .unzip()
        };
        let own: Vec<u32> = if own_candidate.is_empty() {
            Vec::new()
        } else {
            (0..idx.len() as u32).filter(|&j| bit_set(&own_candidate, idx[j as usize] as usize)).collect()
        };
        let mut rays = RayStats::default();
        for (kf_ordinal, kf) in keyframes.iter().enumerate().filter(|(_, k)| k.submap == s) {
            world_points_into(kf, &mut pts);
            let image = no_return_fov.or(own_fov.filter(|_| !own.is_empty())).and_then(|f| {
                NoReturnImage::build_above(kf.points, f, cfg.no_return_margin_deg, image_floor_deg(kf, cfg))
            });
            let mut no_return = Vec::with_capacity(2);
            if let Some(image) = &image {
                let r_world_sensor = kf.t_world_keyframe.rotation;
                if no_return_fov.is_some() {
                    no_return.push(NoReturn {
                        image,
                        r_world_sensor,
                        candidates: &candidates,
                        candidate_range_m: &candidate_range_m,
                        range_m: cfg.no_return_range_m,
                        min_elevation_deg: cfg.no_return_min_elevation_deg,
                        clear_cells: None,
                    });
                }
                if own_fov.is_some() {
                    no_return.push(NoReturn {
                        image,
                        r_world_sensor,
                        candidates: &own,
                        candidate_range_m: &[],
                        range_m: cfg.own_no_return_range_m,
                        min_elevation_deg: cfg.own_no_return_min_elevation_deg,
                        clear_cells: Some((&own_clear[kf_ordinal], own_cell)),
                    });
                }
            }
            rays += sub.add_keyframe_seeing(&origin(kf), &pts, kf.index, cfg, shapes.as_ref(), &no_return);
            done += 1;
            progress(done);
        }
        stats.skipped_rays += rays.skipped_rays;
        stats.no_return_voxels += rays.no_return_voxels;
        stats.own_no_return_voxels += rays.own_no_return_voxels;
        let mut boxes = hit_boxes(&sub, keyframes.iter().filter(|k| k.submap == s));
        for b in &mut boxes {
            if b[0] > b[3] {
                *b = NO_HIT_BOX;
            }
        }
        let table = sub.to_table(&boxes);
        stats.generated_voxels += table.len();
        session.merge_subset(&sub, &idx);
        submaps.push(table);
    }
    stats.raycast_s = t_ray.elapsed().as_secs_f64();

    let t_dor = Instant::now();
    let eps = session.eps_l(cfg);
    let mut origins_m = vec![None; keyframes.iter().map(|k| k.index as usize + 1).max().unwrap_or(0)];
    for kf in keyframes {
        origins_m[kf.index as usize] = Some(origin(kf));
    }
    let dynamic = dynamic_voxels(&session, &eps, &origins_m, cfg);
    stats.dynamic_voxels = dynamic.iter().filter(|&&d| d).count();
    let (labels, grown) = label_points(keyframes, &session, &eps, &dynamic, cfg);
    stats.dynamic_points = labels.dynamic.iter().filter(|&&d| d).count();
    stats.grown_points = grown;
    // Each keyframe's verdicts: its slice of the labels (in keyframe order).
    let mut verdicts: Vec<&[bool]> = Vec::with_capacity(keyframes.len());
    let mut rest = &labels.dynamic[..];
    for kf in keyframes {
        let (this, more) = rest.split_at(kf.points.len());
        verdicts.push(this);
        rest = more;
    }
    let t_cleaned = Instant::now();
    stats.dor_s = (t_cleaned - t_dor).as_secs_f64();
    // One submap at a time, each on every thread.
    let cleaned: Vec<CleanedMap> = (0..n_submaps)
        .map(|s| {
            let of_submap: Vec<(&KeyframeInput<'_>, &[bool])> =
                keyframes.iter().zip(verdicts.iter().copied()).filter(|(k, _)| k.submap == s).collect();
            cleaned_map(&of_submap, &points_x[s], &session, &eps)
        })
        .collect();
    stats.cleaned_voxels = cleaned.iter().map(CleanedMap::len).sum();
    stats.cleaned_s = t_cleaned.elapsed().as_secs_f64();
    stats.total_s = started.elapsed().as_secs_f64();
    SessionEvidence { submaps, cleaned, labels, stats }
}

/// The sensor-frame elevation below which a keyframe's no-return image
/// needs no returns: the lowest world elevation either test looks at, less
/// the sensor's tilt, twice the widest margin and a degree.
fn image_floor_deg(kf: &KeyframeInput<'_>, cfg: &EvidenceConfig) -> f64 {
    let up = kf.t_world_keyframe.rotation * nalgebra::Vector3::z();
    let tilt_deg = up.z.clamp(-1.0, 1.0).acos().to_degrees();
    let lowest = if cfg.own_no_return_range_m > 0.0 {
        cfg.no_return_min_elevation_deg.min(cfg.own_no_return_min_elevation_deg)
    } else {
        cfg.no_return_min_elevation_deg
    };
    lowest - tilt_deg - 2.0 * super::no_return::FORWARD_MARGIN_FACTOR * cfg.no_return_margin_deg - 1.0
}

/// One bit per row of `session`: set where at least one and at most
/// `cfg.own_no_return_max_keyframes` keyframes' point keys (`per_kf`) hold it.
fn few_keyframes_rows(session: &InterestEvidence, per_kf: &[(Vec<u64>, Box3)], cfg: &EvidenceConfig) -> Vec<u64> {
    let counts: Vec<AtomicU32> = (0..session.len()).map(|_| AtomicU32::new(0)).collect();
    per_kf.par_iter().flat_map_iter(|(k, _)| k.iter()).for_each(|&k| {
        if let Some(i) = session.find(k) {
            counts[i].fetch_add(1, Ordering::Relaxed);
        }
    });
    let max = cfg.own_no_return_max_keyframes;
    let mut bits = vec![0u64; session.len().div_ceil(64)];
    for (i, c) in counts.into_iter().enumerate() {
        if (1..=max).contains(&c.into_inner()) {
            bits[i / 64] |= 1 << (i % 64);
        }
    }
    bits
}

/// One bit per row of `session`: set where some keyframe's point keys
/// (`per_kf`, each keyframe's a subset of the session's keys) hold it.
fn occupied_rows(session: &InterestEvidence, per_kf: &[(Vec<u64>, Box3)]) -> Vec<u64> {
    let bits: Vec<AtomicU64> = (0..session.len().div_ceil(64)).map(|_| AtomicU64::new(0)).collect();
    per_kf.par_iter().flat_map_iter(|(k, _)| k.iter()).for_each(|&k| {
        if let Some(i) = session.find(k) {
            bits[i / 64].fetch_or(1 << (i % 64), Ordering::Relaxed);
        }
    });
    bits.into_iter().map(AtomicU64::into_inner).collect()
}

/// An empty box for [`hit_boxes`]: every `lo` above every `hi`.
const EMPTY_BOX: [f32; 6] =
    [f32::INFINITY, f32::INFINITY, f32::INFINITY, f32::NEG_INFINITY, f32::NEG_INFINITY, f32::NEG_INFINITY];

/// Each row's box of the points of `keyframes` (offsets from the voxel's
/// lower corner, see [`SubmapEvidence::hit_box_m`]); [`EMPTY_BOX`] for a
/// row none of them falls in.
fn hit_boxes<'a>(sub: &InterestEvidence, keyframes: impl Iterator<Item = &'a KeyframeInput<'a>>) -> Vec<[f32; 6]> {
    let v = sub.voxel_m;
    let mut boxes = vec![EMPTY_BOX; sub.len()];
    add_points_by_row(
        &mut boxes,
        keyframes,
        |kf| {
            world_points(kf)
                .iter()
                .filter_map(|p| {
                    let k = packed_key(p, v)?;
                    let i = sub.find(k)?;
                    let c = unpack(k).0;
                    Some((i as u32, [0, 1, 2].map(|a| p[a] - c[a] as f64 * v)))
                })
                .collect()
        },
        |b, _, o| {
            for a in 0..3 {
                let o = o[a] as f32;
                b[a] = b[a].min(o);
                b[a + 3] = b[a + 3].max(o);
            }
        },
    );
    boxes
}

/// DOR's verdict per voxel: ε_l > τ_dyn or the single-change test
/// (`EvidenceConfig::change_once_min_frees`; `origins_m[k]` is the sensor of
/// keyframe index k, `None` where the session has none), and with
/// `static_neighbour_veto` no static occupied voxel among its 26 neighbours.
pub fn dynamic_voxels(
    session: &InterestEvidence,
    eps: &[f32],
    origins_m: &[Option<[f64; 3]>],
    cfg: &EvidenceConfig,
) -> Vec<bool> {
    let tau = cfg.tau_dyn;
    let rows = session.rows();
    let keys = session.keys();
    let when = session.when();
    let v = session.voxel_m;
    let min_cos = cfg.change_once_max_deg.to_radians().cos();
    let single_change = cfg.change_once_min_frees > 0 && cfg.model == EvidenceModel::Directional;
    let [min_hits, min_frees] =
        [cfg.change_once_min_hits, cfg.change_once_min_frees].map(|n| u16::try_from(n).unwrap_or(u16::MAX));
    // Changed once, as seen from about the same direction.
    let changed_once = |i: usize| {
        let Some((crossed, hit)) = when[i].changed_once(min_hits, min_frees) else {
            return false;
        };
        let origin = |k: u16| origins_m.get(k as usize).copied().flatten().map(nalgebra::Vector3::from);
        let (Some(a), Some(b)) = (origin(crossed), origin(hit)) else {
            return false;
        };
        let c = unpack(keys[i]).center_m(v);
        let (u, w) = (c - a, c - b);
        let n = u.norm() * w.norm();
        n > 0.0 && u.dot(&w) >= min_cos * n
    };
    (0..keys.len())
        .into_par_iter()
        .map(|i| {
            if eps[i] as f64 <= tau && !(single_change && changed_once(i)) {
                return false;
            }
            if !cfg.static_neighbour_veto {
                return true;
            }
            // Vetoed when a static occupied voxel is among its 26 neighbours.
            !unpack(keys[i]).neighbours(1).any(|(_, n)| {
                pack(n).and_then(|n| session.find(n)).is_some_and(|j| rows[j].hit_n > 0 && eps[j] as f64 <= tau)
            })
        })
        .collect()
}

/// The row index of a world point's voxel, `None` when it has none.
fn row_at(session: &InterestEvidence, p: &[f64; 3]) -> Option<usize> {
    packed_key(p, session.voxel_m).and_then(|k| session.find(k))
}

/// Every point's label, keyframe after keyframe: its voxel's verdict
/// (`dynamic`, per row) grown within its keyframe ([`keyframe_dynamic`]);
/// and how many points the growth made dynamic.
fn label_points(
    keyframes: &[KeyframeInput<'_>],
    session: &InterestEvidence,
    eps: &[f32],
    dynamic: &[bool],
    cfg: &EvidenceConfig,
) -> (PointLabels, usize) {
    // The footing step's ground level, a bit per row; `None`: the step is off.
    let at_ground = session.ground().filter(|_| cfg.footing_height_m > 0.0).map(|g| ground_rows(session, g));
    let mut parts: Vec<KeyframeLabels> = keyframes
        .par_iter()
        .map(|kf| {
            // A point without a row (non-finite, out of range) is kept:
            // there is no evidence that it moved.
            let rows: Vec<Option<usize>> = world_points(kf).iter().map(|p| row_at(session, p)).collect();
            let (verdicts, grown) = keyframe_dynamic(&origin(kf), &rows, session, dynamic, session.ground(), cfg);
            let (mut feet, mut band) = (Vec::new(), Vec::new());
            if let Some(at_ground) = &at_ground {
                feet = footing_candidates(&rows, session, &verdicts, at_ground);
                band = (rows.iter().enumerate())
                    .filter_map(|(j, r)| r.filter(|&r| bit_set(at_ground, r)).map(|r| (j as u32, r as u32)))
                    .collect();
            }
            let labels = PointLabels {
                keyframe: vec![kf.index as i32; rows.len()],
                point_index: (0..rows.len() as i32).collect(),
                dynamic: verdicts,
                eps_l: rows.iter().map(|i| i.map_or(cfg.eps_min as f32, |i| eps[i])).collect(),
            };
            KeyframeLabels { labels, grown, feet, band }
        })
        .collect();
    let grown_feet = at_ground.map_or(0, |at_ground| footing(keyframes, session, &at_ground, &mut parts, cfg));
    let mut out = PointLabels::default();
    let mut grown = grown_feet;
    for KeyframeLabels { labels: p, grown: g, .. } in parts {
        out.keyframe.extend(p.keyframe);
        out.point_index.extend(p.point_index);
        out.dynamic.extend(p.dynamic);
        out.eps_l.extend(p.eps_l);
        grown += g;
    }
    (out, grown)
}

/// One keyframe's labels in [`label_points`], before the footing step.
struct KeyframeLabels {
    labels: PointLabels,
    /// Points the growth step made dynamic.
    grown: usize,
    /// The footing step's candidates ([`footing_candidates`]) and every
    /// point at ground level: `(point index, row)`.
    feet: Vec<(u32, u32)>,
    band: Vec<(u32, u32)>,
}

/// The footing step (`evidence::grow`'s docs): each keyframe's candidates
/// that stand on the ground of their column ([`stands_on_ground`]) become
/// dynamic; how many did. Only the ground-level voxels of the candidates'
/// columns are looked at again, so the step costs a pass over the keyframes'
/// ground-level rows, not another transform of every point.
fn footing(
    keyframes: &[KeyframeInput<'_>],
    session: &InterestEvidence,
    at_ground: &[u64],
    parts: &mut [KeyframeLabels],
    cfg: &EvidenceConfig,
) -> usize {
    let keys = session.keys();
    let column = |row: u32| {
        let k = unpack(keys[row as usize]).0;
        (k[0], k[1])
    };
    // The ground-level rows of the candidates' columns (the band is two
    // voxels high, so each is the candidate's row or one above or below).
    let mut in_band = vec![0u64; session.len().div_ceil(64)];
    let mut any = false;
    for &(_, r) in parts.iter().flat_map(|p| &p.feet) {
        let k = unpack(keys[r as usize]).0;
        for dz in -1..=1 {
            let n = VoxelKey([k[0], k[1], k[2] + dz]);
            if let Some(i) = pack(n).and_then(|n| session.find(n))
                && bit_set(at_ground, i)
            {
                in_band[i / 64] |= 1 << (i % 64);
                any = true;
            }
        }
    }
    if !any {
        return 0;
    }
    // Their points' heights, every keyframe's: (keyframe, z) per column.
    let z_of = |kf: &KeyframeInput<'_>, j: u32| {
        let p = kf.points[j as usize];
        (kf.t_world_keyframe * Point3::new(p[0] as f64, p[1] as f64, p[2] as f64)).z
    };
    let band: FxHashMap<(i32, i32), Vec<(u32, f32)>> = keyframes
        .par_iter()
        .zip(parts.par_iter())
        .enumerate()
        .fold(FxHashMap::default, |mut acc: FxHashMap<(i32, i32), Vec<(u32, f32)>>, (i, (kf, p))| {
            for &(j, r) in &p.band {
                if bit_set(&in_band, r as usize) {
                    acc.entry(column(r)).or_default().push((i as u32, z_of(kf, j) as f32));
                }
            }
            acc
        })
        .reduce(FxHashMap::default, |mut a, b| {
            for (c, mut v) in b {
                a.entry(c).or_default().append(&mut v);
            }
            a
        });
    let max_others = (cfg.footing_max_keyframes as usize).saturating_sub(1);
    let mut added = 0;
    for (i, (kf, p)) in keyframes.iter().zip(parts.iter_mut()).enumerate() {
        for &(j, r) in &p.feet {
            let stands = band
                .get(&column(r))
                .is_some_and(|b| stands_on_ground(i as u32, z_of(kf, j), b, cfg.footing_height_m, max_others));
            if stands {
                p.labels.dynamic[j as usize] = true;
                added += 1;
            }
        }
    }
    added
}

/// The static points of a submap's keyframes (each with its points'
/// verdicts), one centroid per voxel. `b` holds the keyframes' points, so
/// their rows lie in its x range of `session`'s keys, and accumulators are
/// kept for that range only.
fn cleaned_map(
    keyframes: &[(&KeyframeInput<'_>, &[bool])],
    b: &Box3,
    session: &InterestEvidence,
    eps: &[f32],
) -> CleanedMap {
    #[derive(Clone, Default)]
    struct Acc {
        /// The points, as offsets from the voxel centre.
        moments: Moments,
        /// The keyframe adding points now and how many it added, and the
        /// keyframe that added the most (the first of equals).
        cur: (u32, u32),
        best: (u32, u32),
    }
    let v = session.voxel_m;
    let (lo, hi) = session.x_range(b);
    let keys = &session.keys()[lo..hi];
    let mut acc = vec![Acc::default(); keys.len()];
    add_points_by_row(
        &mut acc,
        keyframes.iter(),
        |(kf, dynamic)| {
            world_points(kf)
                .iter()
                .zip(dynamic.iter())
                .filter(|(_, d)| !**d)
                .filter_map(|(p, _)| {
                    let k = packed_key(p, v)?;
                    let i = session.find(k).filter(|i| (lo..hi).contains(i))?;
                    let c = unpack(k).center_m(v);
                    Some(((i - lo) as u32, [p[0] - c[0], p[1] - c[1], p[2] - c[2]]))
                })
                .collect()
        },
        |a, k, d| {
            // Points come keyframe by keyframe: count the current run.
            let index = keyframes[k].0.index;
            if a.moments.count() == 0 || a.cur.0 != index {
                a.cur = (index, 0);
            }
            a.moments.add(d);
            a.cur.1 += 1;
            if a.cur.1 > a.best.1 {
                a.best = a.cur;
            }
        },
    );
    let mut m = CleanedMap::default();
    for ((j, a), &k) in acc.iter().enumerate().zip(keys).filter(|((_, a), _)| a.moments.count() > 0) {
        let (mean, spread) = a.moments.mean_and_spread();
        let c = unpack(k).center_m(v);
        m.xyz_m.push([0, 1, 2].map(|i| (c[i] + mean[i]) as f32));
        m.spread_m2.push(spread.map(|x| x as f32));
        m.eps_l.push(eps[lo + j]);
        m.points.push(a.moments.count());
        m.owner_keyframe.push(a.best.0);
    }
    m
}

/// A rigid motion per keyframe: `ΔT_i = W_now,i · W_gen,i⁻¹` (eq. 10).
pub fn delta(t_world_keyframe_gen: &Pose, t_world_keyframe_now: &Pose) -> Pose {
    t_world_keyframe_now * t_world_keyframe_gen.inverse()
}

/// A keyframe's ΔT and its rotation matrix.
type Motion = (Pose, [[f64; 3]; 3]);

/// Re-bins stored evidence rows into the world grid after their owners moved
/// by `delta_of(owner_keyframe)` (eqs. 9-11), with `M' = R M Rᵀ` for both
/// kinds. A row with a box of points ([`SubmapEvidence::hit_box_m`]) lands in
/// every voxel its moved box overlaps — the voxels its moved points fall in
/// (at most [`MAX_SPLAT`]; a larger box keeps only its centre's voxel) —
/// and a row without one where its moved voxel centre falls. Rows landing on
/// one voxel are summed. Owners `delta_of` does not know keep their place.
///
/// Only the directional statistics move: the result's ε_l is the
/// directional model's whatever `EvidenceConfig::model` says.
pub fn reproject(
    tables: &[&SubmapEvidence],
    voxel_m: f64,
    delta_of: impl Fn(u32) -> Option<Pose> + Sync,
) -> InterestEvidence {
    // Chunks of rows, so that one large table uses every thread too.
    const CHUNK: usize = 1 << 14;
    let chunks: Vec<(&SubmapEvidence, std::ops::Range<usize>)> = tables
        .iter()
        .flat_map(|t| (0..t.len()).step_by(CHUNK).map(move |a| (*t, a..(a + CHUNK).min(t.len()))))
        .collect();
    let parts: Vec<Vec<(u64, Row)>> = chunks
        .into_par_iter()
        .map(|(t, range)| {
            let mut cache: FxHashMap<u32, Option<Motion>> = FxHashMap::default();
            let mut out = Vec::with_capacity(range.len() * 2);
            for i in range {
                let mut row = row_of(t, i);
                let moved = cache
                    .entry(row.owner_keyframe)
                    .or_insert_with(|| delta_of(row.owner_keyframe).map(|d| (d, rotation_rows(&d))))
                    .as_ref();
                let Some((d, r)) = moved else {
                    out.extend(pack(t.keys[i]).map(|k| (k, row)));
                    continue;
                };
                row.hit_m = rotate_sym(r, &row.hit_m);
                row.free_m = rotate_sym(r, &row.free_m);
                moved_voxels(t.keys[i], &t.hit_box_m[i], d, voxel_m, |k| out.push((k, row)));
            }
            out
        })
        .collect();
    InterestEvidence::from_parts(&parts, voxel_m)
}

/// The most voxels one moved row is spread over: a box of points moved by a
/// small motion overlaps at most 2 voxels per axis.
pub const MAX_SPLAT: usize = 8;

/// The packed keys a stored voxel lands on after moving by `d`: those its
/// moved box of points overlaps, or its moved centre's.
fn moved_voxels(key: VoxelKey, hit_box_m: &[f32; 6], d: &Pose, voxel_m: f64, mut emit: impl FnMut(u64)) {
    let corner = key.0.map(|c| c as f64 * voxel_m);
    let centre = d * Point3::from(key.center_m(voxel_m));
    let mut by_centre = || packed_key(&[centre.x, centre.y, centre.z], voxel_m).into_iter().for_each(&mut emit);
    if hit_box_m.iter().any(|v| !v.is_finite()) {
        return by_centre();
    }
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for c in 0..8 {
        let p = Point3::from([0, 1, 2].map(|a| corner[a] + hit_box_m[a + 3 * ((c >> a) & 1)] as f64));
        let q = d * p;
        for a in 0..3 {
            lo[a] = lo[a].min(q[a]);
            hi[a] = hi[a].max(q[a]);
        }
    }
    let (Some(klo), Some(khi)) = (voxel_key(&lo, voxel_m), voxel_key(&hi, voxel_m)) else { return by_centre() };
    let span = (0..3).map(|a| (khi.0[a] as i64 - klo.0[a] as i64 + 1) as usize).product::<usize>();
    if span > MAX_SPLAT {
        return by_centre();
    }
    for x in klo.0[0]..=khi.0[0] {
        for y in klo.0[1]..=khi.0[1] {
            for z in klo.0[2]..=khi.0[2] {
                pack(VoxelKey([x, y, z])).into_iter().for_each(&mut emit);
            }
        }
    }
}

/// Moves a cleaned map's centroids with their owners' ΔT (eq. 11), and turns
/// their spread with it.
pub fn reproject_cleaned(map: &CleanedMap, delta_of: impl Fn(u32) -> Option<Pose>) -> CleanedMap {
    let mut cache: FxHashMap<u32, Option<Pose>> = FxHashMap::default();
    let mut out = map.clone();
    for (i, (p, spread)) in out.xyz_m.iter_mut().zip(out.spread_m2.iter_mut()).enumerate() {
        if let Some(d) = cache.entry(map.owner_keyframe[i]).or_insert_with(|| delta_of(map.owner_keyframe[i])) {
            let q = *d * Point3::new(p[0] as f64, p[1] as f64, p[2] as f64);
            *p = [q.x as f32, q.y as f32, q.z as f32];
            *spread = rotate_sym(&rotation_rows(d), spread);
        }
    }
    out
}

/// Reprojected evidence against evidence recomputed on the new poses (the
/// paper's Fig. 6 claim, measured).
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct ReprojectionCheck {
    /// Occupied (hit) voxels of the evidence recomputed from scratch.
    pub occupied_recomputed: usize,
    /// Occupied voxels after reprojecting the old evidence.
    pub occupied_reprojected: usize,
    /// Of those, the ones occupied in the recomputed evidence too: a moved
    /// box of points spread over voxels the moved points do not reach shows
    /// here as a fraction below 1.
    pub reprojected_also_recomputed: usize,
    /// Recomputed occupied voxels that are occupied after reprojection too.
    pub same_voxel: usize,
    /// ... and get the same dynamic verdict (ε_l > τ_dyn).
    pub same_voxel_and_verdict: usize,
    /// Of the recomputed occupied voxels found occupied after reprojection
    /// but with the other verdict: those one keyframe alone hit on
    /// recomputation (a point at a surface's fringe that other keyframes'
    /// rays pass by; re-binning hands it the hits of the voxels whose
    /// points' box it now overlaps), ...
    pub disagree_single_hit: usize,
    /// ... and those dynamic on recomputation, static after reprojection.
    pub disagree_dynamic_recomputed: usize,
    /// `same_voxel_and_verdict / occupied_recomputed`.
    pub match_fraction: f64,
    /// Recomputed occupied voxels with a reprojected occupied voxel of the
    /// same verdict at most one voxel away (26-neighbourhood), as a fraction.
    pub neighbour_match_fraction: f64,
    pub generate_s: f64,
    pub reproject_s: f64,
    pub recompute_s: f64,
}

/// Generates evidence on `inputs`' poses, moves every keyframe to
/// `poses_now` (by index into `inputs`), and compares reprojecting the stored
/// evidence with ray casting again on the new poses.
pub fn check_reprojection(inputs: &[KeyframeInput<'_>], poses_now: &[Pose], cfg: &EvidenceConfig) -> ReprojectionCheck {
    let t = Instant::now();
    let before = generate(inputs, &[], None, cfg, |_| {});
    let generate_s = t.elapsed().as_secs_f64();
    let by_index: FxHashMap<u32, Pose> =
        inputs.iter().zip(poses_now).map(|(k, now)| (k.index, delta(&k.t_world_keyframe, now))).collect();
    let t = Instant::now();
    let tables: Vec<&SubmapEvidence> = before.submaps.iter().collect();
    let moved = reproject(&tables, cfg.voxel_size_m, |kf| by_index.get(&kf).copied());
    let moved_eps = moved.eps_l(cfg);
    let reproject_s = t.elapsed().as_secs_f64();

    let now_inputs: Vec<KeyframeInput<'_>> =
        inputs.iter().zip(poses_now).map(|(k, p)| KeyframeInput { t_world_keyframe: *p, ..*k }).collect();
    let t = Instant::now();
    let after = generate(&now_inputs, &[], None, cfg, |_| {});
    let recompute_s = t.elapsed().as_secs_f64();
    let tables: Vec<&SubmapEvidence> = after.submaps.iter().collect();
    let fresh = reproject(&tables, cfg.voxel_size_m, |_| None);
    let fresh_eps = fresh.eps_l(cfg);

    let dynamic = |e: f32| e as f64 > cfg.tau_dyn;
    // The row index of an occupied voxel.
    let occupied = |e: &InterestEvidence, k: u64| e.find(k).filter(|&i| e.rows()[i].hit_n > 0);
    let mut out = ReprojectionCheck { generate_s, reproject_s, recompute_s, ..Default::default() };
    for (&k, r) in moved.keys().iter().zip(moved.rows()) {
        if r.hit_n > 0 {
            out.occupied_reprojected += 1;
            out.reprojected_also_recomputed += occupied(&fresh, k).is_some() as usize;
        }
    }
    let mut near = 0usize;
    for (i, (&k, r)) in fresh.keys().iter().zip(fresh.rows()).enumerate() {
        if r.hit_n == 0 {
            continue;
        }
        out.occupied_recomputed += 1;
        let verdict = dynamic(fresh_eps[i]);
        if let Some(j) = occupied(&moved, k) {
            out.same_voxel += 1;
            if dynamic(moved_eps[j]) == verdict {
                out.same_voxel_and_verdict += 1;
            } else {
                out.disagree_single_hit += (r.hit_n == 1) as usize;
                out.disagree_dynamic_recomputed += verdict as usize;
            }
        }
        let same = |j: usize| dynamic(moved_eps[j]) == verdict;
        let found = occupied(&moved, k).is_some_and(same)
            || unpack(k).neighbours(1).any(|(_, n)| pack(n).and_then(|n| occupied(&moved, n)).is_some_and(same));
        near += found as usize;
    }
    let total = out.occupied_recomputed.max(1) as f64;
    out.match_fraction = out.same_voxel_and_verdict as f64 / total;
    out.neighbour_match_fraction = near as f64 / total;
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Rotation3, Translation3, UnitQuaternion, Vector3};

    #[test]
    fn rotate_sym_matches_matrix_product() {
        let r = Rotation3::from_euler_angles(0.3, -0.2, 1.1).into_inner();
        let rr = [0, 1, 2].map(|a| [0, 1, 2].map(|b| r[(a, b)]));
        let m = [2.0f32, 0.5, -0.3, 1.0, 0.2, 0.7];
        let full = nalgebra::Matrix3::new(2.0, 0.5, -0.3, 0.5, 1.0, 0.2, -0.3, 0.2, 0.7);
        let want = r * full * r.transpose();
        let got = rotate_sym(&rr, &m);
        let idx = [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)];
        for (g, (a, b)) in got.iter().zip(idx) {
            assert!((*g as f64 - want[(a, b)]).abs() < 1e-5);
        }
    }

    /// A walled corridor with a person standing in it for the first half:
    /// the person's points come out dynamic, the walls static, labels cover
    /// every point, and the cleaned map holds no person.
    #[test]
    fn person_is_removed_and_walls_kept() {
        let wall = |y: f64| -> Vec<[f64; 3]> {
            let mut v = Vec::new();
            for i in 0..400 {
                for h in 0..10 {
                    v.push([i as f64 * 0.1 - 10.0, y, h as f64 * 0.2 + 0.05]);
                }
            }
            v
        };
        let mut static_pts = wall(4.0);
        static_pts.extend(wall(-4.0));
        let person: Vec<[f64; 3]> = (0..40)
            .flat_map(|i| (0..3).map(move |j| [6.0 + j as f64 * 0.05, 1.9 + 0.005 * i as f64, 0.5 + 0.03 * i as f64]))
            .collect();
        let mut scans = Vec::new();
        let mut poses = Vec::new();
        for f in 0..12 {
            let t = Pose::from_parts(Translation3::new(f as f64 * 0.5 - 3.0, 0.0, 1.0), UnitQuaternion::identity());
            let mut pts: Vec<[f64; 3]> = static_pts.clone();
            // A far wall ahead so rays beyond the person hit something.
            pts.extend((0..80).flat_map(|i| (0..10).map(move |h| [25.0, i as f64 * 0.1 - 4.0, h as f64 * 0.2 + 0.05])));
            if f < 3 {
                pts.extend(person.iter().copied());
            }
            let inv = t.inverse();
            let local: Vec<[f32; 3]> = pts
                .iter()
                .map(|p| {
                    let q = inv * Point3::new(p[0], p[1], p[2]);
                    [q.x as f32, q.y as f32, q.z as f32]
                })
                .collect();
            scans.push((local, f < 3));
            poses.push(t);
        }
        let inputs: Vec<KeyframeInput<'_>> = scans
            .iter()
            .zip(&poses)
            .enumerate()
            .map(|(i, ((pts, _), t))| KeyframeInput {
                index: i as u32,
                submap: i / 4,
                t_world_keyframe: *t,
                points: pts,
            })
            .collect();
        let cfg = EvidenceConfig::default();
        let out = generate(&inputs, &[], None, &cfg, |_| {});
        assert_eq!(out.submaps.len(), 3);
        assert_eq!(out.labels.len(), scans.iter().map(|s| s.0.len()).sum::<usize>());
        let n_static = static_pts.len() + 800;
        let (mut person_removed, mut person_total, mut static_removed) = (0, 0, 0);
        let mut row = 0;
        for (pts, has_person) in &scans {
            for j in 0..pts.len() {
                let d = out.labels.dynamic[row];
                if *has_person && j >= n_static {
                    person_total += 1;
                    person_removed += d as usize;
                } else {
                    static_removed += d as usize;
                }
                row += 1;
            }
        }
        // Voxels the person's points touch only at sensor height are seen
        // along one direction; three quarters is what eqs. 4-8 give here.
        assert!(person_removed * 4 >= person_total * 3, "{person_removed}/{person_total}");
        assert!(static_removed * 1000 <= row, "{static_removed} of {row} static points removed");
        // The cleaned map keeps less than a quarter of where the person stood.
        let left: u32 = out
            .cleaned
            .iter()
            .flat_map(|m| m.xyz_m.iter().zip(&m.points))
            .filter(|(p, _)| p[0] > 5.9 && p[0] < 6.3 && (p[1] - 2.0).abs() < 0.3)
            .map(|(_, n)| *n)
            .sum();
        assert!(left as usize * 4 <= person_total, "{left} person points left in the cleaned map");
        assert!(out.stats.dynamic_points >= person_removed);
        // The wall at y = 4 is a plane: its voxels' spread has no variance
        // across it (yy, xy, yz), and along x the variance of points 0.1 m
        // apart (every other one on a voxel boundary): never above 0.1².
        let (mut walls, mut spread_x) = (0, 0);
        for m in &out.cleaned {
            for ((p, c), n) in m.xyz_m.iter().zip(&m.spread_m2).zip(&m.points) {
                if (p[1] - 4.0).abs() < 1e-4 && p[2] > 0.5 && p[0] > -9.0 && p[0] < 20.0 {
                    walls += 1;
                    assert!(c[3].abs() < 1e-8 && c[1].abs() < 1e-8 && c[4].abs() < 1e-8, "{p:?} {c:?}");
                    assert!((0.0..=0.01).contains(&c[0]), "{p:?} {c:?}");
                    spread_x += (c[0] > 1e-4) as usize;
                    assert!(*n > 0);
                }
            }
        }
        assert!(walls > 100 && spread_x * 4 > walls, "{spread_x} of {walls} wall voxels spread along x");
    }

    /// Keyframe `i` has scan `i` at pose `i`, in submap `i / per_submap`.
    fn inputs_of<'a>(scans: &'a [Vec<[f32; 3]>], poses: &[Pose], per_submap: usize) -> Vec<KeyframeInput<'a>> {
        scans
            .iter()
            .zip(poses)
            .enumerate()
            .map(|(i, (pts, t))| KeyframeInput {
                index: i as u32,
                submap: i / per_submap,
                t_world_keyframe: *t,
                points: pts,
            })
            .collect()
    }

    /// A spinning sensor (64 beams over ±22.5°, 512 columns) at 1.8 m on a
    /// road past a wall along y = 15 m (x in ±50 m, 40 m tall): returns from
    /// the ground and the wall, nothing from the open sky to the south.
    fn road_and_wall_scan(origin: [f64; 3]) -> Vec<[f32; 3]> {
        spin_scan(origin, 512, 100.0, &[([-50.0, 15.0, 0.0], [50.0, 16.0, 40.0])])
    }

    #[test]
    fn beams_that_returned_nothing_free_a_removed_jib_but_not_the_wall_ground_or_far() {
        let poses: Vec<Pose> = (0..6)
            .map(|i| Pose::from_parts(Translation3::new(i as f64 * 2.0 - 5.0, 0.0, 1.8), UnitQuaternion::identity()))
            .collect();
        let scans: Vec<Vec<[f32; 3]>> = poses.iter().map(|p| road_and_wall_scan(p.translation.vector.into())).collect();
        let inputs = inputs_of(&scans, &poses, 3);
        let v = 0.2;
        let patch = |p: [f64; 3]| MapPatch {
            key: packed_key(&p, v).unwrap(),
            xyz_m: p,
            points: 5,
            spread_m2: [1e-3, 0.0, 0.0, 1e-3, 0.0, 1e-4],
            seen_from_m: 38.0,
        };
        // An earlier session's jib in the open sky, the wall's far face, a
        // kerb to the south (below the horizon), a jib beyond reach.
        let (jib, behind_wall, kerb, far) =
            ([3.0, -40.0, 12.0], [0.0, 15.3, 5.0], [0.0, -30.0, 0.1], [0.0, -150.0, 30.0]);
        let map: Vec<MapPatch> = [jib, behind_wall, kerb, far].into_iter().map(patch).collect();
        let band = Fov::Band { elev_min_deg: -22.5, elev_max_deg: 22.5 };
        let cfg = EvidenceConfig::default();
        let out = generate(&inputs, &map, Some(&band), &cfg, |_| {});
        let row_in = |out: &SessionEvidence, p: [f64; 3]| {
            let k = voxel_key(&p, v).unwrap();
            let mut r = Row::default();
            for t in &out.submaps {
                if let Some(i) = t.keys.iter().position(|x| *x == k) {
                    r.merge(&row_of(t, i));
                }
            }
            r
        };
        let row = |p| row_in(&out, p);
        let r = row(jib);
        assert_eq!((r.no_return_n, r.free_n), (6, 6), "every keyframe saw the sky where the jib was");
        assert!(r.free_q > 0.0 && r.owner_q > 0.0);
        for p in [behind_wall, kerb, far] {
            assert_eq!(row(p).no_return_n, 0, "{p:?}");
        }
        assert_eq!(out.stats.no_return_voxels, 6);
        // A forward-looking sensor that did not look that way (the jib is to
        // the side), or an unknown field of view, frees nothing this way.
        let rect = Fov::Rect { azimuth_deg: 70.0, elevation_deg: 77.0 };
        for fov in [None, Some(&rect)] {
            let out = generate(&inputs, &map, fov, &cfg, |_| {});
            assert_eq!(out.stats.no_return_voxels, 0);
        }
        // One that looked at it (a jib ahead, along +x) does.
        let ahead = [40.0, 3.0, 12.0];
        let with_ahead: Vec<MapPatch> = map.iter().copied().chain([patch(ahead)]).collect();
        let out = generate(&inputs, &with_ahead, Some(&rect), &cfg, |_| {});
        assert_eq!(row_in(&out, ahead).no_return_n, 6);
        assert_eq!(row_in(&out, jib).no_return_n, 0);
        assert_eq!(out.stats.no_return_voxels, 6);
        // Nor when the map saw it from much closer than this session's beams
        // pass: a surface seen from 20 m may return nothing from 41 m.
        let close: Vec<MapPatch> = map.iter().map(|p| MapPatch { seen_from_m: 20.0, ..*p }).collect();
        assert_eq!(generate(&inputs, &close, Some(&band), &cfg, |_| {}).stats.no_return_voxels, 0);
        // Nor with the range set to 0.
        let off = EvidenceConfig { no_return_range_m: 0.0, ..cfg.clone() };
        assert_eq!(generate(&inputs, &map, Some(&band), &off, |_| {}).stats.no_return_voxels, 0);
        // A point of this session 0.6 m above the jib (1° away from it at
        // 40 m: outside a 0.01° window) keeps it: something is still there.
        let tip: Vec<Vec<[f32; 3]>> = scans
            .iter()
            .zip(&poses)
            .map(|(s, p)| {
                let mut s = s.clone();
                let q = p.inverse() * Point3::new(jib[0], jib[1], jib[2] + 0.6);
                s.push([q.x as f32, q.y as f32, q.z as f32]);
                s
            })
            .collect();
        let tip_inputs: Vec<KeyframeInput<'_>> =
            inputs.iter().zip(&tip).map(|(k, s)| KeyframeInput { points: s, ..*k }).collect();
        let narrow = EvidenceConfig { no_return_margin_deg: 0.01, ..cfg.clone() };
        assert_eq!(row_in(&generate(&tip_inputs, &map, Some(&band), &narrow, |_| {}), jib).no_return_n, 0);
        let anywhere = EvidenceConfig { no_return_clear_m: 0.0, ..narrow };
        assert_eq!(row_in(&generate(&tip_inputs, &map, Some(&band), &anywhere, |_| {}), jib).no_return_n, 6);
    }

    /// A 64-beam spinning sensor (±22.5°, `columns` per turn) at `origin`
    /// over flat ground (z = 0) with axis-aligned boxes `[lo, hi]`: the first
    /// return of each beam within `max_range_m`, in the sensor frame (no
    /// rotation).
    fn spin_scan(origin: [f64; 3], columns: usize, max_range_m: f64, boxes: &[([f64; 3], [f64; 3])]) -> Vec<[f32; 3]> {
        let mut out = Vec::new();
        for b in 0..64 {
            let el = (-22.5 + 45.0 * b as f64 / 63.0f64).to_radians();
            for c in 0..columns {
                let az = std::f64::consts::TAU * c as f64 / columns as f64;
                let d = [el.cos() * az.cos(), el.cos() * az.sin(), el.sin()];
                let mut t = if d[2] < 0.0 { -origin[2] / d[2] } else { f64::INFINITY };
                for (lo, hi) in boxes {
                    // Slab test.
                    let (mut t0, mut t1) = (0.0f64, f64::INFINITY);
                    for a in 0..3 {
                        let (p, q) = ((lo[a] - origin[a]) / d[a], (hi[a] - origin[a]) / d[a]);
                        t0 = t0.max(p.min(q));
                        t1 = t1.min(p.max(q));
                    }
                    if t0 <= t1 {
                        t = t.min(t0);
                    }
                }
                if t <= max_range_m {
                    out.push(d.map(|x| (x * t) as f32));
                }
            }
        }
        out
    }

    /// `n` poses 1.8 m up, 0.5 m apart along x, level.
    fn stepping_along_x(n: usize) -> Vec<Pose> {
        (0..n)
            .map(|i| Pose::from_parts(Translation3::new(0.5 * i as f64, 0.0, 1.8), UnitQuaternion::identity()))
            .collect()
    }

    /// A truck crossing the view 44 m out, seen against the sky, on ground
    /// between two of the sensor's rings (41 and 58 m): once it has driven
    /// on, the beams where it was return nothing, and no ray with an
    /// endpoint crosses its upper half. (Where a ring lies within the
    /// clearance below it, the ground's points keep it, as they do a
    /// structure.) Beams that returned nothing free it within the session;
    /// with them off it stays. A sign post a few
    /// beams catch in one keyframe only, 1.5 m beside a billboard, stays
    /// with the default clearance (the other keyframes see the billboard
    /// beside it) and goes without it; the billboard (seen by every
    /// keyframe) and the ground stay.
    #[test]
    fn a_truck_seen_against_the_sky_is_freed_by_beams_that_returned_nothing() {
        let n = 4;
        let poses = stepping_along_x(n);
        let truck_at = |i: usize| {
            let y = -10.0 + 8.0 * i as f64;
            ([44.0, y, 0.5], [46.5, y + 5.0, 3.5])
        };
        let billboard = ([30.0, 20.0, 3.0], [30.4, 24.0, 5.0]);
        let post = ([30.0, 25.5, 3.0], [30.4, 25.9, 5.0]);
        let scans: Vec<Vec<[f32; 3]>> = (0..n)
            .map(|i| {
                let o: [f64; 3] = poses[i].translation.vector.into();
                let mut boxes = vec![truck_at(i), billboard];
                if i == 0 {
                    boxes.push(post);
                }
                spin_scan(o, 720, 60.0, &boxes)
            })
            .collect();
        let inputs = inputs_of(&scans, &poses, usize::MAX);
        let band = Fov::Band { elev_min_deg: -22.5, elev_max_deg: 22.5 };
        let inside =
            |b: ([f64; 3], [f64; 3]), p: [f64; 3]| (0..3).all(|a| p[a] >= b.0[a] - 1e-3 && p[a] <= b.1[a] + 1e-3);
        // Removed / total of the first keyframe's points on the truck above
        // the sensor, on the post; and every keyframe's removed static points.
        let run = |cfg: &EvidenceConfig| {
            let out = generate(&inputs, &[], Some(&band), cfg, |_| {});
            let (mut upper, mut on_post, mut static_gone) = ((0, 0), (0, 0), (0, 0));
            let mut row = 0;
            for (i, scan) in scans.iter().enumerate() {
                let o: [f64; 3] = poses[i].translation.vector.into();
                for p in scan {
                    let w = [p[0] as f64 + o[0], p[1] as f64 + o[1], p[2] as f64 + o[2]];
                    let gone = out.labels.dynamic[row] as usize;
                    row += 1;
                    if inside(truck_at(i), w) {
                        if i == 0 && w[2] > 1.8 {
                            upper = (upper.0 + gone, upper.1 + 1);
                        }
                    } else if inside(post, w) {
                        on_post = (on_post.0 + gone, on_post.1 + 1);
                    } else {
                        static_gone = (static_gone.0 + gone, static_gone.1 + 1);
                    }
                }
            }
            assert!(upper.1 >= 20 && on_post.1 >= 5, "the truck and the post have points: {upper:?} {on_post:?}");
            let share = |c: (usize, usize)| c.0 as f64 / c.1 as f64;
            (share(upper), share(on_post), static_gone, out.stats.own_no_return_voxels)
        };
        let cfg = EvidenceConfig::default();
        let (upper, post_gone, static_gone, freed) = run(&cfg);
        assert!(upper > 0.8, "defaults: {upper:.2} of the truck's upper half removed");
        assert!(freed > 0);
        assert_eq!(post_gone, 0.0, "the post beside the billboard stays");
        assert_eq!(static_gone.0, 0, "{static_gone:?} static points removed");
        let off = EvidenceConfig { own_no_return_range_m: 0.0, ..cfg.clone() };
        let (upper_off, _, _, freed_off) = run(&off);
        assert!(upper_off < 0.2, "no ray frees the truck's upper half: {upper_off:.2} removed");
        assert_eq!(freed_off, 0);
        let near = EvidenceConfig { own_no_return_range_m: 35.0, ..cfg.clone() };
        assert!(run(&near).0 < 0.2, "the truck lies beyond 35 m");
        let unguarded = EvidenceConfig { own_no_return_clear_m: 0.0, ..cfg.clone() };
        let (_, post_unguarded, billboard, _) = run(&unguarded);
        assert!(post_unguarded > 0.5, "without the clearance the post goes: {post_unguarded:.2}");
        assert_eq!(billboard.0, 0, "the billboard, seen by every keyframe, stays");
    }

    /// A car driving ahead along the sensor's beams, a little faster than
    /// the sensor: the middle of its back is crossed only by rays that end
    /// on its back again, a little lower, and its lowest layer mostly by
    /// rays to the ground beside it. The ground-aware clearance and guard
    /// free both; with the rules off both are kept.
    #[test]
    fn a_car_driving_ahead_is_removed_down_to_its_lowest_layer() {
        // Sensor at 1.8 m moving 1 m per keyframe along x; the car (4 × 1.8 ×
        // 1.5 m, its floor 0.25 m up, wheels left out) 1.3 m per keyframe,
        // its back 16 m ahead at first; a wall 40 m ahead closes the view. A
        // ray to where the car's back was, 1 m up, ends on its back again
        // 0.07 m (next keyframe) and 0.15 m (the one after) lower: under the
        // 0.2 m clearance.
        let n = 3;
        let poses: Vec<Pose> = (0..n)
            .map(|i| Pose::from_parts(Translation3::new(i as f64, 0.0, 1.8), UnitQuaternion::identity()))
            .collect();
        let car_at = |i: usize| {
            let x = 16.0 + 1.3 * i as f64;
            ([x, -0.9, 0.25], [x + 4.0, 0.9, 1.5])
        };
        let wall = ([40.0, -30.0, 0.0], [41.0, 30.0, 6.0]);
        let scans: Vec<Vec<[f32; 3]>> =
            (0..n).map(|i| spin_scan(poses[i].translation.vector.into(), 720, 60.0, &[car_at(i), wall])).collect();
        let inputs = inputs_of(&scans, &poses, usize::MAX);
        // The first keyframe's points on the car's back: its lowest voxel
        // layer (below 0.4 m, next to the ground) and its middle (0.7-1.2 m).
        let back_x = car_at(0).0[0];
        let removed = |cfg: &EvidenceConfig| {
            let out = generate(&inputs, &[], None, cfg, |_| {});
            let (mut low, mut middle) = ((0, 0), (0, 0));
            for (j, p) in scans[0].iter().enumerate() {
                let (x, z) = (p[0] as f64, p[2] as f64 + 1.8);
                if (x - back_x).abs() > 1e-3 {
                    continue;
                }
                let c = match z {
                    z if z < 0.4 => &mut low,
                    z if (0.7..1.2).contains(&z) => &mut middle,
                    _ => continue,
                };
                c.0 += out.labels.dynamic[j] as usize;
                c.1 += 1;
            }
            assert!(low.1 >= 5 && middle.1 >= 10, "the car's back has points: {low:?} {middle:?}");
            (low.0 as f64 / low.1 as f64, middle.0 as f64 / middle.1 as f64)
        };
        let cfg = EvidenceConfig::default();
        let (low, middle) = removed(&cfg);
        assert!(low > 0.8 && middle > 0.8, "defaults: lowest layer {low:.2}, middle {middle:.2} removed");
        // Each rule on its own, without the footing step (which takes the
        // lowest layer's points beside a removed middle), the cluster step
        // (what is left of a piece mostly removed) and growth into voxels
        // some keyframe saw free.
        let no_footing = EvidenceConfig { footing_height_m: 0.0, cluster_share: 0.0, grow_freed: false, ..cfg.clone() };
        let clearance = EvidenceConfig { clearance_near_ground_only: false, ..no_footing.clone() };
        let (_, middle_old) = removed(&clearance);
        assert!(middle_old < 0.2, "the clearance on every downward ray keeps the middle: {middle_old:.2}");
        let guard = EvidenceConfig { ground_hits_guard: true, ..no_footing };
        let (low_old, _) = removed(&guard);
        assert!(low_old < 0.2, "ground hits guarding keep the lowest layer: {low_old:.2}");
        // No ground point is removed.
        let out = generate(&inputs, &[], None, &cfg, |_| {});
        let ground = scans.iter().flatten().zip(&out.labels.dynamic).filter(|(p, _)| (p[2] as f64 + 1.8).abs() < 1e-3);
        let (total, gone) = ground.fold((0, 0), |(t, g), (_, &d)| (t + 1, g + d as usize));
        assert!(total > 10_000 && gone == 0, "{gone} of {total} ground points removed");
    }

    /// A car creeping 0.05 m a keyframe towards the road (a quarter voxel) while
    /// the sensor drives past: its front fills, keyframe by keyframe, space
    /// the rays of the keyframes before crossed just before they hit it, so
    /// the own-hit guard drops every such crossing and ε_l stays at its
    /// floor. The single-change test removes the front's points once it
    /// has moved a voxel (crossed by three keyframes or more, then hit by
    /// two); with the test off they stay. The same car parked on the other
    /// side of the road, the ground and the far wall lose no more points
    /// than without the test.
    #[test]
    fn a_creeping_cars_front_goes_with_the_single_change_test() {
        let n = 12;
        let poses: Vec<Pose> = (0..n)
            .map(|i| Pose::from_parts(Translation3::new(0.6 * i as f64, 0.0, 1.8), UnitQuaternion::identity()))
            .collect();
        let front_y = |i: usize| 6.05 - 0.05 * i as f64;
        let car_at = |i: usize| ([16.0, front_y(i), 0.3], [20.0, front_y(i) + 1.8, 1.5]);
        let parked = ([16.0, -7.85, 0.3], [20.0, -6.05, 1.5]);
        let wall = ([-50.0, 30.0, 0.0], [50.0, 31.0, 6.0]);
        let scans: Vec<Vec<[f32; 3]>> = (0..n)
            .map(|i| spin_scan(poses[i].translation.vector.into(), 1440, 60.0, &[car_at(i), parked, wall]))
            .collect();
        let inputs = inputs_of(&scans, &poses, 4);
        // Per keyframe, removed / total points of the moving car's front face
        // and of everything static.
        let removed = |cfg: &EvidenceConfig| {
            let out = generate(&inputs, &[], None, cfg, |_| {});
            let (mut front, mut fixed) = (vec![(0, 0); n], (0, 0));
            let mut row = 0;
            for (i, (pts, t)) in scans.iter().zip(&poses).enumerate() {
                let (lo, hi) = car_at(i);
                for p in pts {
                    let w = t * Point3::new(p[0] as f64, p[1] as f64, p[2] as f64);
                    let d = out.labels.dynamic[row] as usize;
                    row += 1;
                    let on_car =
                        (lo[0] - 1e-3..=hi[0] + 1e-3).contains(&w.x) && (lo[1] - 1e-3..=hi[1] + 1e-3).contains(&w.y);
                    if on_car && (w.y - lo[1]).abs() < 1e-3 {
                        front[i].0 += d;
                        front[i].1 += 1;
                    } else if !on_car {
                        fixed.0 += d;
                        fixed.1 += 1;
                    }
                }
            }
            (front, fixed)
        };
        let (front, fixed) = removed(&EvidenceConfig::default());
        let share = |f: &[(usize, usize)]| {
            let (d, t) = f.iter().fold((0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
            assert!(t > 100, "the front has points: {f:?}");
            d as f64 / t as f64
        };
        let off = EvidenceConfig { change_once_min_frees: 0, ..Default::default() };
        let (front_off, fixed_off) = removed(&off);
        // Keyframes 6-8: the front has entered the voxel layer the first six
        // crossed (guarded from the third on). Later, the sensor abreast of
        // the car, rays cross that space from aside and ε_l takes them too.
        assert!(share(&front[6..9]) > 0.4, "front of keyframes 6-8: {:?}", &front[6..9]);
        assert!(share(&front_off[6..9]) < 0.1, "without the test: {:?}", &front_off[6..9]);
        // Keyframes 2-4: the front has not left the voxels it filled first.
        assert!(share(&front[2..5]) < 0.05, "front of keyframes 2-4: {:?}", &front[2..5]);
        // Static points: the ground, the wall and the parked car (a few of
        // whose roof points, grazed 0.3 m below the sensor, go either way).
        assert!(fixed_off.1 > 100_000 && fixed_off.0 * 1000 < fixed_off.1, "{fixed_off:?}");
        assert!(fixed.0 <= fixed_off.0 + 20, "{} static points removed, {} without the test", fixed.0, fixed_off.0);
    }

    /// A person walking across the view, each keyframe somewhere else: the
    /// rays to the ground behind where they stood end within the ground's
    /// clearance of their feet, so no ray frees the layer they stand in, and
    /// growth never enters a column's lowest voxel. The footing step takes
    /// their feet out of it; with it off they stay. No ground point goes,
    /// nor any of a kerb beside their path.
    #[test]
    fn a_walking_persons_feet_go_with_the_footing_step() {
        let n = 8;
        let poses = stepping_along_x(n);
        let person_at = |i: usize| {
            let y = -3.0 + 0.8 * i as f64;
            ([8.0, y, 0.0], [8.4, y + 0.4, 1.7])
        };
        let wall = ([30.0, -30.0, 0.0], [31.0, 30.0, 6.0]);
        // A kerb just behind the person's path, 0.15 m high.
        let kerb = ([8.5, -4.0, 0.0], [9.0, 4.0, 0.15]);
        let scans: Vec<Vec<[f32; 3]>> = (0..n)
            .map(|i| spin_scan(poses[i].translation.vector.into(), 1024, 60.0, &[person_at(i), wall, kerb]))
            .collect();
        let inputs = inputs_of(&scans, &poses, usize::MAX);
        // (removed, all) of the person's points 0.06-0.2 m up (above the
        // footing height) and above 0.4 m; the ground and kerb points removed.
        let count = |cfg: &EvidenceConfig| {
            let out = generate(&inputs, &[], None, cfg, |_| {});
            let (mut feet, mut body, mut ground, mut on_kerb) = ((0, 0), (0, 0), 0, 0);
            let mut row = 0;
            for (i, scan) in scans.iter().enumerate() {
                let (lo, hi) = person_at(i);
                let o = poses[i].translation.vector;
                for p in scan {
                    let w = [p[0] as f64 + o.x, p[1] as f64 + o.y, p[2] as f64 + o.z];
                    let d = out.labels.dynamic[row] as usize;
                    row += 1;
                    let inside = (0..2).all(|a| w[a] > lo[a] - 1e-3 && w[a] < hi[a] + 1e-3);
                    let c = match w[2] {
                        z if z.abs() < 1e-3 => {
                            ground += d;
                            continue;
                        }
                        z if inside && z > 0.06 && z < 0.2 => &mut feet,
                        z if inside && z > 0.4 => &mut body,
                        _ if w[0] > kerb.0[0] - 1e-3 => {
                            on_kerb += d;
                            continue;
                        }
                        _ => continue,
                    };
                    c.0 += d;
                    c.1 += 1;
                }
            }
            (feet, body, ground, on_kerb)
        };
        let cfg = EvidenceConfig::default();
        let (feet, body, ground, on_kerb) = count(&cfg);
        let off = EvidenceConfig { footing_height_m: 0.0, ..cfg.clone() };
        let (feet_off, body_off, ground_off, _) = count(&off);
        let any = EvidenceConfig { footing_max_keyframes: 100, ..cfg.clone() };
        let (feet_any, _, _, on_kerb_any) = count(&any);
        assert!(feet.1 >= 10 && body.1 >= 100, "the person has points: {feet:?} {body:?}");
        assert!(body.0 * 10 >= body.1 * 9, "the body is removed: {body:?}");
        assert!(feet.0 * 10 >= feet.1 * 9, "footing on: the feet are removed: {feet:?}");
        assert!(feet_off.0 * 2 <= feet_off.1, "footing off: most of the feet stay: {feet_off:?}");
        assert_eq!(body_off, body, "the footing step leaves the body alone");
        assert_eq!((ground, ground_off), (0, 0), "no ground point is removed");
        // The kerb's top beside the person's feet is seen there by many
        // keyframes: kept. Without that limit the step takes some of it.
        assert_eq!(on_kerb, 0, "no kerb point is removed");
        assert_eq!(feet_any, feet);
        assert!(on_kerb_any > 0, "any number of keyframes: the kerb beside the feet goes too");
    }

    /// The layer of a removed object just above the ground this session
    /// hits: rays crossing it end on that ground a little behind, so the
    /// clearance and the own-hit guard drop them, unless the voxel is a
    /// vacated one that cannot be ground (`free_vacated_low`).
    #[test]
    fn vacated_layer_above_the_ground_is_freed_unless_it_may_be_ground() {
        // Ground at z = 0.15 (the sensor 1.8 m above it): the ground's
        // voxels are the layer [0, 0.2), the object's lowest one [0.2, 0.4),
        // its centre 0.15 m above the ground, under the 0.2 m clearance.
        let poses: Vec<Pose> = (0..6)
            .map(|i| Pose::from_parts(Translation3::new(i as f64 * 2.0 - 5.0, 0.0, 1.95), UnitQuaternion::identity()))
            .collect();
        let scans: Vec<Vec<[f32; 3]>> = (0..6).map(|_| road_and_wall_scan([0.0, 0.0, 1.8])).collect();
        let inputs = inputs_of(&scans, &poses, usize::MAX);
        let v = 0.2;
        let at = [0.1, -6.1, 0.3];
        // A container's side (a plane across y), and a piece of ground.
        let side = MapPatch {
            key: packed_key(&at, v).unwrap(),
            xyz_m: at,
            points: 12,
            spread_m2: [3e-3, 0.0, 0.0, 1e-6, 0.0, 3e-3],
            seen_from_m: 10.0,
        };
        let ground = MapPatch { spread_m2: [3e-3, 0.0, 0.0, 3e-3, 0.0, 1e-6], ..side };
        assert!(!side.maybe_ground() && ground.maybe_ground());
        let freed = |patch: &MapPatch, cfg: &EvidenceConfig| {
            let out = generate(&inputs, std::slice::from_ref(patch), None, cfg, |_| {});
            let t = &out.submaps[0];
            t.keys.iter().position(|k| *k == unpack(patch.key)).map_or(0, |i| row_of(t, i).free_n)
        };
        let cfg = EvidenceConfig::default();
        assert!(freed(&side, &cfg) >= 3, "rays to the ground behind cross where the side was");
        assert_eq!(freed(&ground, &cfg), 0, "ground keeps the clearance and the guard");
        let off = EvidenceConfig { free_vacated_low: false, ..cfg.clone() };
        assert_eq!(freed(&side, &off), 0, "without the rule the clearance drops every ray");
        let high = EvidenceConfig { vacated_clearance_m: 0.2, ..cfg.clone() };
        assert_eq!(freed(&side, &high), 0, "the rule's own clearance applies");
    }

    /// Reprojection by ΔT of the poses that generated the evidence is the
    /// identity; by a pure translation of whole voxels it shifts every key.
    #[test]
    fn reproject_identity_and_translation() {
        let mut t = SubmapEvidence::default();
        for i in 0..5 {
            t.keys.push(VoxelKey([i, 2, -3]));
            t.hit.n.push(1);
            t.hit.q.push(1.0);
            t.hit.m.push([1.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
            t.free.n.push(0);
            t.free.q.push(0.0);
            t.free.m.push([0.0; 6]);
            t.owner_keyframe.push(7);
            t.owner_q.push(1.0);
            t.hit_box_m.push(NO_HIT_BOX);
        }
        let same = reproject(&[&t], 0.2, |_| Some(Pose::identity()));
        assert_eq!(same.len(), 5);
        assert!(t.keys.iter().all(|k| same.get(pack(*k).unwrap()).is_some()));
        let moved = reproject(&[&t], 0.2, |kf| {
            (kf == 7).then(|| Pose::from_parts(Translation3::new(0.4, 0.0, 0.2), UnitQuaternion::identity()))
        });
        assert!(t.keys.iter().all(|k| moved.get(pack(VoxelKey([k.0[0] + 2, 2, -2])).unwrap()).is_some()));
        // A half-turn about z maps M's xx to xx and the key's x to -x.
        let turn = Pose::from_parts(
            Translation3::identity(),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::PI),
        );
        let turned = reproject(&[&t], 0.2, |_| Some(turn));
        let r = turned.get(pack(VoxelKey([-1, -3, -3])).unwrap()).unwrap();
        assert!((r.hit_m[0] - 1.0).abs() < 1e-6 && r.hit_m[1].abs() < 1e-6);
    }

    /// A row with a box of points lands in every voxel the moved box
    /// overlaps and nowhere else; a box too large to be a small motion's
    /// keeps only its centre's voxel.
    #[test]
    fn moved_box_lands_where_its_points_do() {
        let keys = |b: [f32; 6], d: Pose| {
            let mut v = Vec::new();
            moved_voxels(VoxelKey([3, 0, 0]), &b, &d, 0.2, |k| v.push(unpack(k).0));
            v.sort();
            v
        };
        let shift = |x: f64, y: f64| Pose::from_parts(Translation3::new(x, y, 0.0), UnitQuaternion::identity());
        // Points in x ∈ [0.6, 0.7] (offsets 0..0.1), y ∈ [0.05, 0.06], z ∈ [0.1, 0.1].
        let b = [0.0, 0.05, 0.1, 0.1, 0.06, 0.1];
        assert_eq!(keys(b, shift(0.0, 0.0)), vec![[3, 0, 0]]);
        // +0.15 m in x: the points span x ∈ [0.75, 0.85], across the face at 0.8.
        assert_eq!(keys(b, shift(0.15, 0.0)), vec![[3, 0, 0], [4, 0, 0]]);
        // The voxel centre (0.7 → 0.85) alone would have said [4, 0, 0] only.
        // -0.08 m in y: y ∈ [-0.03, -0.02], one voxel down, x unchanged.
        assert_eq!(keys(b, shift(0.0, -0.08)), vec![[3, -1, 0]]);
        // No box: the centre decides.
        assert_eq!(keys(NO_HIT_BOX, shift(0.15, 0.0)), vec![[4, 0, 0]]);
        // A box spread over a 3×3×3 block is not a small motion's: centre only.
        let turn = Pose::from_parts(
            Translation3::new(0.1, 0.1, 0.1),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.9),
        );
        assert!(keys([0.0, 0.0, 0.0, 0.2, 0.2, 0.2], turn).len() == 1);
    }

    /// The veto keeps a dynamic voxel with a static occupied neighbour; a
    /// static neighbour that was only freed does not veto.
    #[test]
    fn static_neighbour_veto_needs_an_occupied_static_neighbour() {
        let hit = Row { hit_n: 1, ..Row::default() };
        let key = |k: [i32; 3]| pack(VoxelKey(k)).unwrap();
        let cells = [
            ([0, 0, 0], hit, 0.9f32),
            ([1, 0, 1], hit, 0.1),
            ([5, 5, 5], hit, 0.9),
            ([6, 5, 5], Row::default(), 0.1),
            ([10, 0, 0], hit, 0.9),
        ];
        let parts = vec![cells.iter().map(|(k, r, _)| (key(*k), *r)).collect::<Vec<_>>()];
        let ev = InterestEvidence::from_parts(&parts, 0.2);
        let eps: Vec<f32> = cells.iter().map(|c| c.2).collect();
        let veto = EvidenceConfig { static_neighbour_veto: true, ..EvidenceConfig::default() };
        assert_eq!(dynamic_voxels(&ev, &eps, &[], &veto), vec![false, false, true, false, true]);
        assert_eq!(dynamic_voxels(&ev, &eps, &[], &EvidenceConfig::default()), vec![true, false, true, false, true]);
    }

    /// Two walls 10 m apart seen by 6 keyframes driving between them, in
    /// two submaps.
    fn corridor() -> (Vec<[f32; 3]>, Vec<Pose>) {
        let mut pts: Vec<[f32; 3]> = Vec::new();
        for i in 0..300 {
            for h in 0..12 {
                let (x, z) = (i as f32 * 0.07 - 10.0, h as f32 * 0.15 - 0.9);
                pts.push([x, 5.03, z]);
                pts.push([x, -4.97, z]);
            }
        }
        let poses = (0..6)
            .map(|f| {
                Pose::from_parts(Translation3::new(f as f64 * 0.7 + 0.013, 0.021, 1.017), UnitQuaternion::identity())
            })
            .collect();
        (pts, poses)
    }

    fn corridor_inputs<'a>(pts: &'a [[f32; 3]], poses: &[Pose]) -> Vec<KeyframeInput<'a>> {
        poses
            .iter()
            .enumerate()
            .map(|(i, t)| KeyframeInput { index: i as u32, submap: i / 3, t_world_keyframe: *t, points: pts })
            .collect()
    }

    /// A session moved rigidly by a sub-voxel shift and a small turn:
    /// reprojection agrees with recomputation on ≥ 95 % of the occupied
    /// voxels, which moving voxel centres alone does not reach.
    #[test]
    fn reprojection_matches_recomputation_for_sub_voxel_motion() {
        let (pts, poses) = corridor();
        let inputs = corridor_inputs(&pts, &poses);
        let motion = Pose::from_parts(
            Translation3::new(0.13, -0.07, 0.05),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 1.5f64.to_radians()),
        );
        let now: Vec<Pose> = poses.iter().map(|p| motion * p).collect();
        let c = check_reprojection(&inputs, &now, &EvidenceConfig::default());
        assert!(c.occupied_recomputed > 1000);
        assert_eq!(c.same_voxel, c.occupied_recomputed, "{c:?}");
        assert!(c.match_fraction > 0.95, "{c:?}");
        assert!(c.reprojected_also_recomputed as f64 > 0.8 * c.occupied_reprojected as f64, "{c:?}");
    }

    /// Moving every keyframe by whole voxels moves the ray-cast evidence by
    /// the same whole voxels, so reprojection must agree with recomputation
    /// almost everywhere (rounding at voxel faces aside). (That ΔT points the
    /// right way is `reproject_identity_and_translation`'s job.)
    #[test]
    fn reprojection_matches_recomputation_for_whole_voxel_shifts() {
        let (pts, poses) = corridor();
        let inputs = corridor_inputs(&pts, &poses);
        let shift = Pose::from_parts(Translation3::new(0.4, -0.2, 0.0), UnitQuaternion::identity());
        let now: Vec<Pose> = poses.iter().map(|p| shift * p).collect();
        let c = check_reprojection(&inputs, &now, &EvidenceConfig::default());
        assert!(c.occupied_recomputed > 1000);
        assert!(c.match_fraction > 0.99, "{c:?}");
    }
}
