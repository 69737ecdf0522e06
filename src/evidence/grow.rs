//! DOR's growth step: a mover's points that no ray saw through, next to its
//! points that rays did.
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
//! have no evidence either way beyond being seen by a few keyframes. A voxel
//! any keyframe saw free, or that many keyframes hit, is never grown into:
//! its own evidence decides. Neither is the lowest occupied voxel of a
//! column (the ground a mover stands on, `evidence::ground`).
//!
//! The verdict is per point (a voxel can be grown into for the keyframe whose
//! mover touches it and not for another), so the labels and the cleaned map
//! use the points' flags, not the voxel's.
//!
//! Measured with `examples/dor_probe` (true poses; point-wise PR / RR / F1,
//! off → on with 2 hits and 2 steps): SemanticKITTI 04 99.51 / 86.85 / 92.75
//! → 99.36 / 88.92 / 93.85, 08 99.27 / 9.31 / 17.03 → 99.14 / 10.10 / 18.34;
//! the DOR bench's simulated 60-keyframe sessions (seed 1) OS1-64 90.49 →
//! 91.32, HDL-64E 93.87 → 95.30, VLP-16 84.53 → 86.45, HDL-32E 87.39 →
//! 89.11, Avia 92.14 → 92.64 F1, PR down by 0.02-0.15 points. Also tried:
//! 3 hits and 3 steps (F1 a further +0.1-0.3, PR a further −0.05-0.13); only
//! from seeds some keyframes saw free twice or more (less RR everywhere);
//! keeping the ground band's upper voxel too (less RR everywhere).

use super::grid::{InterestEvidence, pack, unpack};
use super::ground::GroundLevel;
use super::stats::EvidenceConfig;
use rustc_hash::FxHashMap;

/// One keyframe's DOR verdict per point: its voxel's (`dynamic`, one flag per
/// row of `session`), then grown as the module says; and how many points the
/// growth made dynamic. `rows_of` is each point's row in `session` (`None`:
/// the point has none, and is static).
pub fn keyframe_dynamic(
    rows_of: &[Option<usize>],
    session: &InterestEvidence,
    dynamic: &[bool],
    ground: Option<&GroundLevel>,
    cfg: &EvidenceConfig,
) -> (Vec<bool>, usize) {
    let mut out: Vec<bool> = rows_of.iter().map(|r| r.is_some_and(|i| dynamic[i])).collect();
    if cfg.grow_max_hits == 0 || cfg.grow_depth_voxels == 0 || !out.iter().any(|&d| d) {
        return (out, 0);
    }
    // The keyframe's voxels: row → grown yet (or dynamic to begin with).
    let mut voxels: FxHashMap<usize, bool> = FxHashMap::default();
    for r in rows_of.iter().flatten() {
        voxels.entry(*r).or_insert(dynamic[*r]);
    }
    let rows = session.rows();
    let keys = session.keys();
    let candidate = |i: usize| {
        let r = &rows[i];
        r.free_n == 0 && r.hit_n <= cfg.grow_max_hits && !ground.is_some_and(|g| g.is_lowest(&unpack(keys[i]).0))
    };
    let mut frontier: Vec<usize> = voxels.iter().filter(|&(_, &d)| d).map(|(&i, _)| i).collect();
    frontier.sort_unstable();
    for _ in 0..cfg.grow_depth_voxels {
        let mut next = Vec::new();
        for &i in &frontier {
            for (_, n) in unpack(keys[i]).neighbours(1) {
                let Some(j) = pack(n).and_then(|n| session.find(n)) else { continue };
                match voxels.get_mut(&j) {
                    Some(done) if !*done && candidate(j) => {
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
    let mut added = 0;
    for (d, r) in out.iter_mut().zip(rows_of) {
        if let Some(i) = r
            && !*d
            && voxels[i]
        {
            *d = true;
            added += 1;
        }
    }
    (out, added)
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
        // evidence, z = 0 the ground; beside it x = 1 a voxel seen free once
        // (static by its own evidence: never grown into) and x = -1 a voxel
        // hit by many keyframes.
        let cells = [
            ([0, 0, 0], 9, 0),
            ([0, 0, 1], 1, 4),
            ([0, 0, 2], 1, 0),
            ([0, 0, 3], 2, 0),
            ([0, 0, 4], 1, 0),
            ([1, 0, 1], 1, 1),
            ([-1, 0, 1], 5, 0),
        ];
        let session = evidence(&cells);
        let dynamic: Vec<bool> = session.keys().iter().map(|&k| unpack(k).0 == [0, 0, 1]).collect();
        let pts = rows(&session, &cells.map(|c| c.0));
        let floor: Vec<u64> = [[0, 0, 0], [1, 0, 0], [-1, 0, 0]].map(|k| pack(VoxelKey(k)).unwrap()).to_vec();
        let ground = GroundLevel::from_keys(&floor);
        let cfg = EvidenceConfig::default();
        let (d, _) = keyframe_dynamic(&pts, &session, &dynamic, Some(&ground), &cfg);
        assert_eq!(d, vec![false, true, true, true, false, false, false], "two steps up, nothing else");
        let off = EvidenceConfig { grow_max_hits: 0, ..cfg.clone() };
        let (d0, _) = keyframe_dynamic(&pts, &session, &dynamic, Some(&ground), &off);
        assert_eq!(d0, vec![false, true, false, false, false, false, false], "off: the voxel verdict");
        let one = EvidenceConfig { grow_max_hits: 1, ..cfg.clone() };
        let (d1, _) = keyframe_dynamic(&pts, &session, &dynamic, Some(&ground), &one);
        assert_eq!(d1, vec![false, true, true, false, false, false, false], "z = 3 was hit twice");
        let deep = EvidenceConfig { grow_depth_voxels: 3, ..cfg };
        let (d3, n3) = keyframe_dynamic(&pts, &session, &dynamic, Some(&ground), &deep);
        assert_eq!(d3, vec![false, true, true, true, true, false, false]);
        assert_eq!(n3, 3, "three points grown into");
    }

    #[test]
    fn grows_only_through_the_keyframes_own_voxels() {
        // z = 2 has no point of this keyframe: z = 3 is two voxels away and
        // not reached through it.
        let cells = [([0, 0, 0], 9, 0), ([0, 0, 1], 1, 3), ([0, 0, 2], 1, 0), ([0, 0, 3], 1, 0)];
        let session = evidence(&cells);
        let dynamic: Vec<bool> = session.keys().iter().map(|&k| unpack(k).0 == [0, 0, 1]).collect();
        let pts = rows(&session, &[[0, 0, 1], [0, 0, 3], [0, 0, 3]]);
        let (d, _) = keyframe_dynamic(&pts, &session, &dynamic, None, &EvidenceConfig::default());
        assert_eq!(d, vec![true, false, false]);
    }
}
