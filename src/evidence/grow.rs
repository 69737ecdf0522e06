//! DOR's growth, cluster and footing steps: a mover's points that no ray saw
//! through, next to its points that rays did.
//!
//! ```text
//!   one keyframe's voxels (its own points only)
//!   ┌───┬───┬───┐      D  dynamic by ε_l (freed by other keyframes)
//!   │ D │ D │ c │      c  a candidate: hit by at most `grow_max_hits`
//!   ├───┼───┼───┤         keyframes, freed by none, not the lowest voxel
//!   │ D │ c │ c │         of its column
//!   ├───┼───┼───┤      g  the column's lowest voxel: never grown into
//!   │ g │ g │ g │
//!   └───┴───┴───┘      D ──26-neighbour──► c ──► c  (up to `grow_depth_voxels` steps)
//! ```
//!
//! ε_l can only call a voxel dynamic where another keyframe's ray crossed it
//! (MATH.md §6). The parts of a mover that no ray crossed — its far side,
//! the top of a person's head, the voxel a wheel shares with the road edge
//! seen once — keep ε_l = 0 and stay in the map beside the parts that were
//! removed. ELite resolves the same mixing by propagating ephemerality from
//! point to neighbouring point; DUFOMap clusters. seam grows the verdict
//! within one keyframe: from the voxels of the keyframe's points that are
//! dynamic, to 26-neighbouring voxels of the same keyframe's points that
//! at most `grow_max_hits` keyframes hit. A voxel that many keyframes hit is
//! never grown into: its own evidence decides. Neither is the lowest
//! occupied voxel of a column (the ground a mover stands on,
//! `evidence::ground`). A voxel some keyframe saw free is grown into
//! (`grow_freed`) above the ground level only: one or two hits and a free
//! ray or two leave ε_l under τ_dyn, evidence both ways that its neighbours
//! settle; in the ground level that is ground far out, which grazing rays
//! free and hit alike. Growing into freed ground-level voxels too (the
//! first version) gave the same DOR numbers to within 0.02 but cost the
//! HDL-32E change site 0.11 points of permanent structure, all ground
//! (`bench/change_sites.py`: 99.00 % without `grow_freed`, 98.89 % with
//! it into the ground level, 99.00 % now).
//!
//! The **cluster step** then judges a keyframe's points in pieces, as
//! DUFOMap clusters and ELite propagates: the keyframe's voxels above the
//! ground level (`GroundLevel::at_ground`: the ground never joins two
//! pieces, nor is taken), joined when they lie within `cluster_reach_deg`
//! (0.8°) of arc of each other seen from the sensor, one voxel near and up
//! to three far. A piece of at most `cluster_max_voxels` (1,500) whose
//! points are at least `cluster_share` (50 %) dynamic goes whole. The reach
//! is what makes it work far out: a truck standing 56 m from an OS1-64 is
//! hit a beam row (0.7 m) and a column (0.35 m) apart, each of its voxels
//! by one or two keyframes, so most of its voxels touch no other of its
//! voxels and growth, one voxel a step, cannot cross the gaps.
//!
//! Measured with `examples/dor_probe` (true poses; point-wise PR / F1,
//! before → `grow_freed` → and the cluster step at share 0.6): simulated 60-keyframe
//! sessions (seed 1) OS1-64 99.67 / 94.02 → 99.66 / 94.35 → 99.65 / 95.09,
//! HDL-64E 99.93 / 96.63 → 99.93 / 96.94 → 99.92 / 97.80, VLP-16 99.49 /
//! 91.18 → 99.48 / 91.80 → 99.47 / 91.86, HDL-32E 99.84 / 93.05 → 99.83 /
//! 93.82 → 99.83 / 93.97, Avia 99.45 / 95.37 → 99.43 / 95.76 → 99.41 /
//! 95.78; SemanticKITTI 04 99.31 / 94.94 → 99.28 / 95.17 → 99.28 / 95.42,
//! 08 99.04 / 26.52 → 99.03 / 27.01 → 99.02 / 27.10. The cluster step alone
//! (without `grow_freed`): OS1-64 94.99, 04 95.38 at PR 99.31 %, 08 26.58.
//! Share 0.5, the default (same run as 0.6 → 0.5 → 0.4): OS1-64 95.09 →
//! **95.60** → 95.80 (PR 99.65 → 99.62 → 99.61 %), HDL-64E 97.80 → 98.21 →
//! 98.25, HDL-32E 93.97 → 94.08 → 94.08, VLP-16 91.86 → 91.85 → 91.98,
//! Avia 95.78 → 95.76 → 95.84 (PR 99.41 → 99.38 → 99.36 %), 04 95.42 →
//! 95.42 → 95.50, 08 27.10 → 27.26 → 27.87 at PR 99.02 → 99.01 → 99.00 %:
//! what 0.4 adds on 08 costs the static points PR has no room left for
//! (bushes and fences with half their voxels grazed).
//! Variants tried (with `grow_freed`): at share 0.5, taking the ground band's upper layer into pieces
//! (only each column's lowest voxel kept out) cost 08 PR 98.96 % and 2,250
//! more static points on 04 (terrain), and leaving out pieces holding a
//! voxel more than 4 or 8 keyframes hit cost most of the gain on the
//! HDL-64E; reach 0.6° or 1.0° and limits of 600 or 3,000 voxels changed F1
//! by at most 0.34 (08, 0.6°: 27.44). Growth reaching as far as the cluster step (0.5° of arc)
//! instead: OS1-64 94.97 but 08 PR 98.96 %. Growth into voxels seen free only
//! where their free keyframes are at least their hit ones: half the gain.
//! It costs the DOR step 0.02-0.06 s per session here (walks from each
//! dynamic voxel, up to 342 neighbours each far out).
//!
//! The verdict is per point (a voxel can be grown into for the keyframe whose
//! mover touches it and not for another), so the labels and the cleaned map
//! use the points' flags, not the voxel's.
//!
//! The footing step then takes the mover's feet out of the ground level,
//! where neither ε_l nor growth reaches: rays to the ground behind a mover
//! end within the ground's clearance of its feet, so nothing frees the layer
//! it stands in, and growth stops at a column's lowest voxel. Ground points
//! and feet share those voxels, so this step decides point by point:
//!
//! ```text
//!   z                                     a static point of the keyframe in
//!   │   D        dynamic voxel (shin)     a ground-level voxel next to a D
//!   │  ─┼─ ·  ·  ← more than footing_height_m above the column's floor,
//!   │ ▁▁┴▁▁▁▁▁▁▁    seen that high there by at most footing_max_keyframes
//!   └──────────  floor: the lowest point any keyframe put in the column
//! ```
//!
//! A kerb's or a bush's foot beside a mover is seen at that height by many
//! keyframes and stays; a foot is there once or twice. Measured with
//! `examples/dor_probe` (point-wise PR / RR / F1; simulated sessions with the
//! store's estimated poses, `--poses`), off → 0.05 m and 2 keyframes:
//! HDL-64E 99.89 / 89.89 / 94.63 → 99.89 / 92.82 / 96.22, Avia 99.57 / 89.14
//! / 94.07 → 99.57 / 92.01 / 95.64; true poses OS1-64 91.24 → 92.08, HDL-32E
//! 89.11 → 89.69, VLP-16 86.47 → 87.34; SemanticKITTI 04 99.42 / 88.85 /
//! 93.84 → 99.38 / 90.57 / 94.77, 08 99.17 / 10.02 / 18.20 → 99.11 / 10.25 /
//! 18.58. Of the movers' points these sessions kept, half to three quarters
//! lay within 0.2 m of the ground. Also tried: 0.08 m (HDL-64E 95.79, Avia
//! 95.06, 04 94.81, 08 18.51: less gain, no PR gained); without the keyframe
//! limit, 0.03 to 0.12 m (SemanticKITTI 04 PR 99.04-99.31 %, 08 98.76-99.07
//! %: terrain, vegetation and fence feet beside movers); 1 keyframe (a
//! further −0.3 to −0.5 F1 on 04 and the HDL-64E, PR the same). Later,
//! candidates up to two voxels from a dynamic one instead of one (true
//! poses; F1, PR): OS1-64 94.02 → 94.39, 99.67 → 99.66 %; SemanticKITTI 04
//! 94.77 → 94.81, 99.38 → 99.31 %; 08 18.58 → 18.70, 99.11 → 99.02 %.
//! Not taken: 08's PR is left at the goal's edge for +0.1 F1.
//!
//! Growth, measured with `examples/dor_probe` (true poses; point-wise PR /
//! RR / F1, off → on with 2 hits and 2 steps): SemanticKITTI 04 99.51 / 86.85 / 92.75
//! → 99.36 / 88.92 / 93.85, 08 99.27 / 9.31 / 17.03 → 99.14 / 10.10 / 18.34;
//! the DOR bench's simulated 60-keyframe sessions (seed 1) OS1-64 90.49 →
//! 91.32, HDL-64E 93.87 → 95.30, VLP-16 84.53 → 86.45, HDL-32E 87.39 →
//! 89.11, Avia 92.14 → 92.64 F1, PR down by 0.02-0.15 points. Also tried:
//! 3 hits and 3 steps (F1 a further +0.1-0.3, PR a further −0.05-0.13); only
//! from seeds some keyframes saw free twice or more (less RR everywhere);
//! keeping the ground band's upper voxel too (less RR everywhere).

use super::grid::{InterestEvidence, bit_set, pack, unpack};
use super::ground::GroundLevel;
use super::stats::EvidenceConfig;
use crate::geometry::VoxelKey;
use nalgebra::Vector3;
use rayon::prelude::*;
use rustc_hash::{FxHashMap, FxHashSet};

/// One keyframe's DOR verdict per point: its voxel's (`dynamic`, one flag per
/// row of `session`), then grown as the module says; and how many points the
/// growth made dynamic. `rows_of` is each point's row in `session` (`None`:
/// the point has none, and is static).
pub fn keyframe_dynamic(
    origin_m: &[f64; 3],
    rows_of: &[Option<usize>],
    session: &InterestEvidence,
    dynamic: &[bool],
    ground: Option<&GroundLevel>,
    cfg: &EvidenceConfig,
) -> (Vec<bool>, usize) {
    let mut out: Vec<bool> = rows_of.iter().map(|r| r.is_some_and(|i| dynamic[i])).collect();
    let grow = cfg.grow_max_hits > 0 && cfg.grow_depth_voxels > 0;
    if !(grow || cfg.cluster_share > 0.0) || !out.iter().any(|&d| d) {
        return (out, 0);
    }
    // The keyframe's voxels: row → (grown yet or dynamic to begin with,
    // the keyframe's points in it).
    let mut voxels: FxHashMap<usize, (bool, u32)> = FxHashMap::default();
    for r in rows_of.iter().flatten() {
        voxels.entry(*r).or_insert((dynamic[*r], 0)).1 += 1;
    }
    let rows = session.rows();
    let keys = session.keys();
    // A voxel no keyframe saw free: anywhere but its column's lowest. One
    // seen free (`grow_freed`): only above the ground level, where grazing
    // rays free and hit the same patch of ground once or twice.
    let candidate = |i: usize| {
        let r = &rows[i];
        let k = unpack(keys[i]).0;
        r.hit_n <= cfg.grow_max_hits
            && if r.free_n == 0 {
                !ground.is_some_and(|g| g.is_lowest(&k))
            } else {
                cfg.grow_freed && above_ground(ground, &k)
            }
    };
    let mut frontier: Vec<usize> = voxels.iter().filter(|&(_, &(d, _))| d).map(|(&i, _)| i).collect();
    frontier.sort_unstable();
    let depth = if grow { cfg.grow_depth_voxels } else { 0 };
    for _ in 0..depth {
        let mut next = Vec::new();
        for &i in &frontier {
            for (_, n) in unpack(keys[i]).neighbours(1) {
                let Some(j) = pack(n).and_then(|n| session.find(n)) else { continue };
                match voxels.get_mut(&j) {
                    Some((done, _)) if !*done && candidate(j) => {
                        *done = true;
                        next.push(j);
                    }
                    _ => {}
                }
            }
        }
        if next.is_empty() {
            break;
        }
        frontier = next;
    }
    if cfg.cluster_share > 0.0 {
        pieces_mostly_dynamic(origin_m, session, ground, &mut voxels, cfg);
    }
    let mut added = 0;
    for (d, r) in out.iter_mut().zip(rows_of) {
        if let Some(i) = r
            && !*d
            && voxels[i].0
        {
            *d = true;
            added += 1;
        }
    }
    (out, added)
}

/// Whether voxel `k` lies above its column's ground level
/// (`GroundLevel::at_ground`), or no ground level is known.
fn above_ground(ground: Option<&GroundLevel>, k: &[i32; 3]) -> bool {
    ground.is_none_or(|g| g.at_ground(k) != Some(true))
}

/// The farthest reach of the cluster step between two voxels of a piece,
/// in voxels along each axis: 7³ − 1 neighbours looked up per voxel at most.
const CLUSTER_MAX_REACH_VOXELS: i32 = 3;

/// The cluster step: `voxels` (this keyframe's rows → dynamic after growth,
/// points) joined into pieces through the keyframe's voxels above the ground level,
/// each voxel reaching the others within `cfg.cluster_reach_deg` of arc seen
/// from `origin_m` (at least the 26 neighbours, at most
/// [`CLUSTER_MAX_REACH_VOXELS`] away). Pieces of at most
/// `cfg.cluster_max_voxels` voxels whose points are at least
/// `cfg.cluster_share` dynamic become dynamic whole. Only pieces holding a
/// dynamic voxel are walked: a keyframe's movers are a few hundred voxels,
/// and a walk into a building stops at the size limit.
fn pieces_mostly_dynamic(
    origin_m: &[f64; 3],
    session: &InterestEvidence,
    ground: Option<&GroundLevel>,
    voxels: &mut FxHashMap<usize, (bool, u32)>,
    cfg: &EvidenceConfig,
) {
    let keys = session.keys();
    let v = session.voxel_m;
    // The dynamic voxels above the ground level: (key, row).
    let mut seeds: Vec<([i32; 3], usize)> = voxels
        .iter()
        .filter(|(_, (d, _))| *d)
        .map(|(&r, _)| (unpack(keys[r]).0, r))
        .filter(|(k, _)| above_ground(ground, k))
        .collect();
    if seeds.is_empty() {
        return;
    }
    // The row of a keyframe voxel above the ground level at key `k`.
    let own = |k: [i32; 3]| {
        let r = pack(VoxelKey(k)).and_then(|p| session.find(p))?;
        (voxels.contains_key(&r) && above_ground(ground, &k)).then_some(r)
    };
    let origin = Vector3::from(*origin_m);
    let tan = cfg.cluster_reach_deg.to_radians().tan();
    let reach = |k: &[i32; 3]| {
        let r_m = (VoxelKey(*k).center_m(v) - origin).norm();
        ((r_m * tan / v).round() as i32).clamp(1, CLUSTER_MAX_REACH_VOXELS)
    };
    seeds.sort_unstable();
    let max = cfg.cluster_max_voxels as usize;
    let mut seen: FxHashSet<usize> = FxHashSet::default();
    let mut turned = Vec::new();
    for (seed, row) in seeds {
        if !seen.insert(row) {
            continue;
        }
        let mut piece = vec![(seed, row)];
        let mut next = 0;
        while next < piece.len() && piece.len() <= max {
            let (k, _) = piece[next];
            next += 1;
            let d = reach(&k);
            for dx in -d..=d {
                for dy in -d..=d {
                    for dz in -d..=d {
                        let n = [k[0] + dx, k[1] + dy, k[2] + dz];
                        if let Some(r) = own(n)
                            && seen.insert(r)
                        {
                            piece.push((n, r));
                        }
                    }
                }
            }
        }
        if piece.len() > max {
            continue;
        }
        let (mut all, mut moving) = (0u64, 0u64);
        for (_, r) in &piece {
            let (d, n) = voxels[r];
            all += u64::from(n);
            moving += if d { u64::from(n) } else { 0 };
        }
        if moving as f64 >= cfg.cluster_share * all as f64 {
            turned.extend(piece.iter().map(|&(_, r)| r));
        }
    }
    for r in turned {
        voxels.entry(r).and_modify(|e| e.0 = true);
    }
}

/// The rows of `session` at their column's ground level
/// (`GroundLevel::at_ground`), a bit each (`grid::bit_set`): what the
/// footing step calls ground level, computed once per session.
pub fn ground_rows(session: &InterestEvidence, ground: &GroundLevel) -> Vec<u64> {
    let keys = session.keys();
    (0..keys.len().div_ceil(64))
        .into_par_iter()
        .map(|w| {
            let rows = w * 64..(w * 64 + 64).min(keys.len());
            rows.filter(|&i| ground.at_ground(&unpack(keys[i]).0) == Some(true)).fold(0u64, |b, i| b | 1 << (i % 64))
        })
        .collect()
}

/// The points of one keyframe that the footing step may make dynamic:
/// static points in a ground-level voxel (`ground_rows`, [`ground_rows`])
/// with a 26-neighbouring voxel (or its own) holding a dynamic point of the
/// same keyframe: `(point index, row)`, ascending.
pub fn footing_candidates(
    rows_of: &[Option<usize>],
    session: &InterestEvidence,
    verdicts: &[bool],
    ground_rows: &[u64],
) -> Vec<(u32, u32)> {
    let keys = session.keys();
    // The dynamic voxels and their 26 neighbours (a keyframe's movers are a
    // few hundred voxels: marking around them beats looking around every
    // point's voxel).
    let dynamic_rows: FxHashSet<usize> =
        rows_of.iter().zip(verdicts).filter(|&(_, &d)| d).filter_map(|(r, _)| *r).collect();
    let mut near_dynamic = dynamic_rows.clone();
    for &r in &dynamic_rows {
        near_dynamic.extend(unpack(keys[r]).neighbours(1).filter_map(|(_, n)| pack(n).and_then(|n| session.find(n))));
    }
    if near_dynamic.is_empty() {
        return Vec::new();
    }
    let mut out = Vec::new();
    for (j, (r, &d)) in rows_of.iter().zip(verdicts).enumerate() {
        let Some(r) = *r else { continue };
        if !d && near_dynamic.contains(&r) && bit_set(ground_rows, r) {
            out.push((j as u32, r as u32));
        }
    }
    out
}

/// Whether a point of keyframe `kf` at height `z_m`, in a column with the
/// ground-level points `band` (`(keyframe, z_m)` of every keyframe's points
/// at ground level there), stands on the
/// ground rather than being it: more than `height_m` above the column's
/// lowest point, in a column where at most `max_others` other keyframes put
/// a point that high.
pub fn stands_on_ground(kf: u32, z_m: f64, band: &[(u32, f32)], height_m: f64, max_others: usize) -> bool {
    let Some(floor) = band.iter().map(|&(_, z)| f64::from(z)).reduce(f64::min) else { return false };
    if z_m - floor <= height_m {
        return false;
    }
    let mut others: Vec<u32> =
        band.iter().filter(|&&(k, z)| k != kf && f64::from(z) - floor > height_m).map(|&(k, _)| k).collect();
    others.sort_unstable();
    others.dedup();
    others.len() <= max_others
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::evidence::grid::Row;
    use crate::geometry::VoxelKey;

    /// Evidence on voxels `[x, 0, z]` with the given (hit_n, free_n).
    fn evidence(cells: &[([i32; 3], u32, u32)]) -> InterestEvidence {
        let parts: Vec<Vec<(u64, Row)>> = vec![
            cells
                .iter()
                .map(|&(k, h, f)| (pack(VoxelKey(k)).unwrap(), Row { hit_n: h, free_n: f, ..Default::default() }))
                .collect(),
        ];
        InterestEvidence::from_parts(&parts, 0.2)
    }

    /// The rows of points in the voxels `keys`, one point per entry.
    fn rows(session: &InterestEvidence, keys: &[[i32; 3]]) -> Vec<Option<usize>> {
        keys.iter().map(|&k| session.find(pack(VoxelKey(k)).unwrap())).collect()
    }

    #[test]
    fn grows_into_unseen_neighbours_but_not_into_evidence_or_the_ground() {
        // A column of a mover: z = 1 dynamic, z = 2, 3, 4 above it with no
        // evidence, z = 0 the ground; beside it x = 1 voxels seen free once
        // (static by their own evidence: grown into only with `grow_freed`,
        // and then only the one above the ground level, z = 2, not z = 1,
        // where grazing rays free and hit the ground) and x = -1 a voxel
        // hit by many keyframes. The cluster step is off.
        let cells = [
            ([0, 0, 0], 9, 0),
            ([0, 0, 1], 1, 4),
            ([0, 0, 2], 1, 0),
            ([0, 0, 3], 2, 0),
            ([0, 0, 4], 1, 0),
            ([1, 0, 1], 1, 1),
            ([-1, 0, 1], 5, 0),
            ([1, 0, 2], 1, 1),
        ];
        let session = evidence(&cells);
        let dynamic: Vec<bool> = session.keys().iter().map(|&k| unpack(k).0 == [0, 0, 1]).collect();
        let pts = rows(&session, &cells.map(|c| c.0));
        let floor: Vec<u64> = [[0, 0, 0], [1, 0, 0], [-1, 0, 0]].map(|k| pack(VoxelKey(k)).unwrap()).to_vec();
        let ground = GroundLevel::from_keys(&floor);
        let cfg = EvidenceConfig { grow_freed: false, cluster_share: 0.0, ..Default::default() };
        let o = [0.0; 3];
        let (d, _) = keyframe_dynamic(&o, &pts, &session, &dynamic, Some(&ground), &cfg);
        assert_eq!(d, vec![false, true, true, true, false, false, false, false], "two steps up, nothing else");
        let freed = EvidenceConfig { grow_freed: true, ..cfg.clone() };
        let (df, _) = keyframe_dynamic(&o, &pts, &session, &dynamic, Some(&ground), &freed);
        assert_eq!(
            df,
            vec![false, true, true, true, false, false, false, true],
            "and the voxel seen free above the ground level"
        );
        let off = EvidenceConfig { grow_max_hits: 0, ..cfg.clone() };
        let (d0, _) = keyframe_dynamic(&o, &pts, &session, &dynamic, Some(&ground), &off);
        assert_eq!(d0, vec![false, true, false, false, false, false, false, false], "off: the voxel verdict");
        let one = EvidenceConfig { grow_max_hits: 1, ..cfg.clone() };
        let (d1, _) = keyframe_dynamic(&o, &pts, &session, &dynamic, Some(&ground), &one);
        assert_eq!(d1, vec![false, true, true, false, false, false, false, false], "z = 3 was hit twice");
        let deep = EvidenceConfig { grow_depth_voxels: 3, ..cfg };
        let (d3, n3) = keyframe_dynamic(&o, &pts, &session, &dynamic, Some(&ground), &deep);
        assert_eq!(d3, vec![false, true, true, true, true, false, false, false]);
        assert_eq!(n3, 3, "three points grown into");
    }

    #[test]
    fn footing_candidates_are_static_ground_level_points_beside_a_dynamic_one() {
        // Ground at z = 0 in columns x = 0..=3, so the ground band is z <= 1;
        // a dynamic voxel at x = 1, z = 1 (a mover's ankle), a static one
        // beside it in the band, one above the band.
        let cells = [
            ([0, 0, 0], 9, 0),
            ([1, 0, 0], 9, 0),
            ([2, 0, 0], 9, 0),
            ([3, 0, 0], 9, 0),
            ([1, 0, 1], 1, 4),
            ([2, 0, 1], 1, 0),
            ([0, 0, 2], 1, 0),
        ];
        let session = evidence(&cells);
        let floor: Vec<u64> = [[0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0]].map(|k| pack(VoxelKey(k)).unwrap()).to_vec();
        let ground = GroundLevel::from_keys(&floor);
        // One point per voxel, plus a second in the dynamic one.
        let mut keys: Vec<[i32; 3]> = cells.iter().map(|c| c.0).collect();
        keys.push([1, 0, 1]);
        let pts = rows(&session, &keys);
        let verdicts: Vec<bool> = keys.iter().map(|k| *k == [1, 0, 1]).collect();
        let at_ground = ground_rows(&session, &ground);
        let got = footing_candidates(&pts, &session, &verdicts, &at_ground);
        // The ground at x = 0..=2 and [2,0,1] touch [1,0,1]; x = 3 is two
        // columns off; [0,0,2] touches it but lies above the band; the
        // dynamic points are no candidates.
        let row = |k: [i32; 3]| session.find(pack(VoxelKey(k)).unwrap()).unwrap() as u32;
        assert_eq!(got, vec![(0, row([0, 0, 0])), (1, row([1, 0, 0])), (2, row([2, 0, 0])), (5, row([2, 0, 1]))]);
        assert!(footing_candidates(&pts, &session, &vec![false; keys.len()], &at_ground).is_empty());
    }

    #[test]
    fn stands_on_ground_needs_height_over_the_floor_and_few_keyframes_there() {
        // The column's floor is 0.00 (keyframe 0's ground); keyframe 3's
        // foot is at 0.10.
        let band = [(0, 0.0), (0, 0.01), (1, 0.02), (3, 0.10), (3, 0.15)];
        assert!(stands_on_ground(3, 0.10, &band, 0.05, 1));
        assert!(!stands_on_ground(3, 0.04, &band, 0.05, 1), "within the footing height of the floor");
        assert!(!stands_on_ground(3, 0.10, &band, 0.12, 1));
        // Two other keyframes saw something that high there: a kerb.
        let kerb = [(0, 0.0), (1, 0.11), (2, 0.12), (3, 0.10)];
        assert!(!stands_on_ground(3, 0.10, &kerb, 0.05, 1));
        assert!(stands_on_ground(3, 0.10, &kerb, 0.05, 2));
        // A point of another keyframe just on the floor does not count.
        assert!(stands_on_ground(3, 0.10, &[(0, 0.0), (1, 0.03), (2, 0.04), (3, 0.10)], 0.05, 0));
        assert!(!stands_on_ground(3, 0.10, &[], 0.05, 1), "no floor known");
    }

    #[test]
    fn grows_only_through_the_keyframes_own_voxels() {
        // z = 2 has no point of this keyframe: z = 3 is two voxels away and
        // not reached through it.
        let cells = [([0, 0, 0], 9, 0), ([0, 0, 1], 1, 3), ([0, 0, 2], 1, 0), ([0, 0, 3], 1, 0)];
        let session = evidence(&cells);
        let dynamic: Vec<bool> = session.keys().iter().map(|&k| unpack(k).0 == [0, 0, 1]).collect();
        let pts = rows(&session, &[[0, 0, 1], [0, 0, 3], [0, 0, 3]]);
        let cfg = EvidenceConfig { cluster_share: 0.0, ..Default::default() };
        let (d, _) = keyframe_dynamic(&[0.0; 3], &pts, &session, &dynamic, None, &cfg);
        assert_eq!(d, vec![true, false, false]);
    }

    #[test]
    fn a_piece_mostly_dynamic_goes_whole_reaching_farther_with_range() {
        // Four voxels of a truck 50 m out, a beam row or column apart (two or
        // three voxels), three of them dynamic; then the same shape 5 m out.
        // Each voxel was hit by many keyframes, so growth never enters one.
        let shape = |x: i32| [[x, 0, 10], [x, 0, 13], [x, 2, 10], [x, 2, 13]];
        let (far, near) = (shape(250), shape(25));
        let cells: Vec<([i32; 3], u32, u32)> = far.iter().chain(&near).map(|&k| (k, 5, 0)).collect();
        let session = evidence(&cells);
        let is_seed = |k: [i32; 3]| k[1] == 0 || k[2] == 10;
        let dynamic: Vec<bool> = session.keys().iter().map(|&k| is_seed(unpack(k).0)).collect();
        let keys: Vec<[i32; 3]> = far.iter().chain(&near).copied().collect();
        let pts = rows(&session, &keys);
        let cfg = EvidenceConfig::default();
        let (d, n) = keyframe_dynamic(&[0.0; 3], &pts, &session, &dynamic, None, &cfg);
        // 50 m: 0.8° of arc is 3.5 voxels, so the four are one piece, 75 %
        // dynamic. 5 m: one voxel, and the static one stands alone.
        assert_eq!(d, vec![true, true, true, true, true, true, true, false]);
        assert_eq!(n, 1);
        // Below the share, or larger than allowed: left as they are.
        let share = EvidenceConfig { cluster_share: 0.8, ..cfg.clone() };
        let small = EvidenceConfig { cluster_max_voxels: 3, ..cfg.clone() };
        let off = EvidenceConfig { cluster_share: 0.0, ..cfg.clone() };
        let seeds: Vec<bool> = keys.iter().map(|&k| is_seed(k)).collect();
        for c in [share, small, off] {
            assert_eq!(keyframe_dynamic(&[0.0; 3], &pts, &session, &dynamic, None, &c).0, seeds);
        }
    }

    #[test]
    fn the_cluster_step_never_joins_or_takes_the_ground_level() {
        // A person's legs at z = 2, 3 (dynamic), hip at z = 4 (static, hit
        // often: no growth), the ground at z = 0 and the band above it at
        // z = 1 (static, beside the legs).
        let cells = [([0, 0, 0], 9, 0), ([0, 0, 1], 9, 0), ([0, 0, 2], 9, 3), ([0, 0, 3], 9, 3), ([0, 0, 4], 9, 0)];
        let session = evidence(&cells);
        let dynamic: Vec<bool> = session.keys().iter().map(|&k| matches!(unpack(k).0[2], 2 | 3)).collect();
        let pts = rows(&session, &cells.map(|c| c.0));
        let ground = GroundLevel::from_keys(&[pack(VoxelKey([0, 0, 0])).unwrap()]);
        let (d, _) = keyframe_dynamic(&[0.0; 3], &pts, &session, &dynamic, Some(&ground), &EvidenceConfig::default());
        assert_eq!(d, vec![false, false, true, true, true]);
    }
}
