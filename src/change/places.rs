//! Places: change events grouped into the things a site manager would point
//! at ("a pallet stack went here", "the stockpile grew there").
//!
//! Events are voxel centroids. Two events belong to the same place when a
//! chain of events links them with each step at most `link_m` apart (single
//! linkage, the connected components of the "within `link_m`" graph). The
//! search buckets events on a grid of `link_m` cells, so each event only
//! looks at the 27 cells around its own: O(n) for the event densities a site
//! has, with a union-find over event indices.
//!
//! A group smaller than `min_events` is not a place: one or two voxels that
//! flicker between sessions (a sensor's noise at a surface's edge) are left
//! out of the places and counted as `scattered`.

use crate::text::thousands;
use rustc_hash::FxHashMap;

/// One place: a connected group of change events.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Place {
    /// Events in the group.
    pub events: usize,
    /// Mean of the events' positions, world frame (m).
    pub centroid_m: [f64; 3],
    /// Axis-aligned bounds of the events' positions, world frame (m).
    pub min_m: [f64; 3],
    pub max_m: [f64; 3],
}

impl Place {
    /// The events' voxels' volume, m³, for voxels of `voxel_m`.
    pub fn volume_m3(&self, voxel_m: f64) -> f64 {
        self.events as f64 * voxel_m.powi(3)
    }
}

/// Places found among some events, largest first.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct Places {
    /// Groups of at least `min_events`, by event count (descending), then by
    /// position for a stable order.
    pub places: Vec<Place>,
    /// Events in groups smaller than `min_events`.
    pub scattered: usize,
}

/// Groups `points_m` (world frame, m) into places: single linkage at `link_m`,
/// groups of fewer than `min_events` counted as scattered. Non-finite points
/// are scattered too.
pub fn places(points_m: &[[f64; 3]], link_m: f64, min_events: usize) -> Places {
    assert!(link_m > 0.0 && link_m.is_finite(), "link distance must be positive, got {link_m}");
    let cell = |p: &[f64; 3]| -> [i64; 3] { [0, 1, 2].map(|i| (p[i] / link_m).floor() as i64) };
    let finite: Vec<usize> = (0..points_m.len()).filter(|&i| points_m[i].iter().all(|v| v.is_finite())).collect();
    let mut grid: FxHashMap<[i64; 3], Vec<usize>> = FxHashMap::default();
    for &i in &finite {
        grid.entry(cell(&points_m[i])).or_default().push(i);
    }
    let mut parent: Vec<usize> = (0..points_m.len()).collect();
    let link2 = link_m * link_m;
    for &i in &finite {
        let c = cell(&points_m[i]);
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let Some(members) = grid.get(&[c[0] + dx, c[1] + dy, c[2] + dz]) else { continue };
                    for &j in members {
                        if j > i && dist2(&points_m[i], &points_m[j]) <= link2 {
                            union(&mut parent, i, j);
                        }
                    }
                }
            }
        }
    }
    let mut groups: FxHashMap<usize, Vec<usize>> = FxHashMap::default();
    for &i in &finite {
        let r = find(&mut parent, i);
        groups.entry(r).or_default().push(i);
    }
    let mut out = Places { places: Vec::new(), scattered: points_m.len() - finite.len() };
    for members in groups.into_values() {
        if members.len() < min_events.max(1) {
            out.scattered += members.len();
            continue;
        }
        let mut sum = [0.0; 3];
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for &i in &members {
            for a in 0..3 {
                sum[a] += points_m[i][a];
                lo[a] = lo[a].min(points_m[i][a]);
                hi[a] = hi[a].max(points_m[i][a]);
            }
        }
        let n = members.len() as f64;
        out.places.push(Place { events: members.len(), centroid_m: sum.map(|s| s / n), min_m: lo, max_m: hi });
    }
    out.places.sort_by(|a, b| {
        b.events.cmp(&a.events).then_with(|| {
            a.centroid_m.iter().zip(&b.centroid_m).fold(std::cmp::Ordering::Equal, |o, (x, y)| o.then(x.total_cmp(y)))
        })
    });
    out
}

/// Link distance for a session's summary: voxels up to four empty 0.2 m
/// voxels apart still belong to one place, so one object seen in patches
/// (its faces from different spots) is one place. On a simulated 3-session
/// site, 0.5 m split 18 appeared objects into 113 places, 1.0 m into 60.
pub const SUMMARY_LINK_M: f64 = 1.0;
/// Smallest place in a session's summary and the report: 25 voxels (0.2 m³
/// of 0.2 m voxels, a 1 m × 1 m face). Smaller groups are mostly a surface's
/// edge flickering between sessions; with 1.0 m links a simulated 3-session
/// site gave 60 appeared places for 18 objects at 10 voxels, 34 at 50.
pub const SUMMARY_MIN_EVENTS: usize = 25;

/// What one session changed, in a site manager's terms.
#[derive(Debug, Clone, serde::Serialize)]
pub struct SessionSummary {
    pub session_id: i64,
    pub name: String,
    pub voxel_m: f64,
    /// `emerged_overlap` events: built or brought in where an earlier session
    /// had looked.
    pub appeared: Places,
    /// `deleted_overlap` events: gone from space this session saw empty.
    pub removed: Places,
    /// `emerged_non_overlap` events: area no earlier session had mapped.
    pub newly_mapped_voxels: usize,
    /// `coexist` events: voxels back after an earlier session saw them gone.
    pub back_voxels: usize,
}

impl SessionSummary {
    /// Reads session `session`'s change events and groups them into places.
    pub fn from_store(
        conn: &rusqlite::Connection,
        session: crate::store::SessionId,
        name: &str,
        voxel_m: f64,
    ) -> Result<SessionSummary, crate::store::StoreError> {
        use super::Category as C;
        use crate::store::{session_event_count as count, session_event_positions as positions};
        let appeared = positions(conn, session, &[C::EmergedOverlap])?;
        let removed = positions(conn, session, &[C::DeletedOverlap])?;
        Ok(SessionSummary {
            session_id: session.0,
            name: name.to_string(),
            voxel_m,
            appeared: places(&appeared, SUMMARY_LINK_M, SUMMARY_MIN_EVENTS),
            removed: places(&removed, SUMMARY_LINK_M, SUMMARY_MIN_EVENTS),
            newly_mapped_voxels: count(conn, session, C::EmergedNonOverlap)?,
            back_voxels: count(conn, session, C::Coexist)?,
        })
    }

    /// One line: "s3: 1,204 voxels appeared (9.6 m³) in 4 places, largest
    /// 3.1 m³ at (12.3, 40.1); 310 removed (2.5 m³) in 2 places, …".
    pub fn sentence(&self) -> String {
        let part = |verb: &str, p: &Places| -> String {
            let in_places: usize = p.places.iter().map(|x| x.events).sum();
            if p.places.is_empty() {
                return format!("nothing {verb} ({} scattered voxels)", p.scattered);
            }
            let big = &p.places[0];
            format!(
                "{} voxels {verb} ({:.1} m³) in {} place{}, largest {:.1} m³ at ({:.1}, {:.1})",
                thousands(in_places as u64),
                in_places as f64 * self.voxel_m.powi(3),
                p.places.len(),
                if p.places.len() == 1 { "" } else { "s" },
                big.volume_m3(self.voxel_m),
                big.centroid_m[0],
                big.centroid_m[1],
            )
        };
        format!(
            "{}: {}; {}; {} voxels of newly mapped area",
            self.name,
            part("appeared", &self.appeared),
            part("removed", &self.removed),
            thousands(self.newly_mapped_voxels as u64)
        )
    }
}

fn dist2(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    (0..3).map(|i| (a[i] - b[i]) * (a[i] - b[i])).sum()
}

/// The root of `i` in a union-find forest (`parent[i] == i` at a root),
/// halving the path on the way.
pub(super) fn find(parent: &mut [usize], mut i: usize) -> usize {
    while parent[i] != i {
        parent[i] = parent[parent[i]];
        i = parent[i];
    }
    i
}

/// Joins the trees of `a` and `b` under the lower root.
pub(super) fn union(parent: &mut [usize], a: usize, b: usize) {
    let (ra, rb) = (find(parent, a), find(parent, b));
    if ra != rb {
        parent[ra.max(rb)] = ra.min(rb);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 3×3×3 block of 0.2 m voxels centred on `c`.
    fn block(c: [f64; 3]) -> Vec<[f64; 3]> {
        let mut v = Vec::new();
        for i in -1..=1 {
            for j in -1..=1 {
                for k in -1..=1 {
                    v.push([c[0] + 0.2 * i as f64, c[1] + 0.2 * j as f64, c[2] + 0.2 * k as f64]);
                }
            }
        }
        v
    }

    #[test]
    fn separate_blocks_are_separate_places_and_specks_are_scattered() {
        let mut pts = block([0.0, 0.0, 0.0]);
        pts.extend(block([10.0, 0.0, 0.0]));
        pts.push([5.0, 5.0, 5.0]);
        pts.push([5.0, 5.0, 5.1]); // a two-voxel speck
        let p = places(&pts, 0.35, 5);
        assert_eq!(p.places.len(), 2);
        assert_eq!(p.scattered, 2);
        assert!(p.places.iter().all(|pl| pl.events == 27));
        // Centroids and bounds of the two blocks, ordered by position on ties.
        assert!((p.places[0].centroid_m[0] - 0.0).abs() < 1e-9);
        assert!((p.places[1].centroid_m[0] - 10.0).abs() < 1e-9);
        assert!((p.places[1].min_m[0] - 9.8).abs() < 1e-9 && (p.places[1].max_m[0] - 10.2).abs() < 1e-9);
        assert!((p.places[0].volume_m3(0.2) - 27.0 * 0.008).abs() < 1e-12);
    }

    #[test]
    fn a_chain_links_across_cells_but_a_gap_splits_it() {
        // Steps of 0.3 m along x link at 0.35 m however the cells fall.
        let line: Vec<[f64; 3]> = (0..20).map(|i| [-1.0 + 0.3 * i as f64, 0.05, 0.0]).collect();
        assert_eq!(places(&line, 0.35, 1).places.len(), 1);
        // A 0.5 m gap in the middle splits it in two.
        let mut gap = line.clone();
        for p in gap.iter_mut().skip(10) {
            p[0] += 0.2;
        }
        let p = places(&gap, 0.35, 1);
        assert_eq!(p.places.iter().map(|pl| pl.events).collect::<Vec<_>>(), vec![10, 10]);
    }

    #[test]
    fn brute_force_agrees_on_random_points() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let pts: Vec<[f64; 3]> = (0..400)
            .map(|_| [rng.random_range(-5.0..5.0), rng.random_range(-5.0..5.0), rng.random_range(0.0..1.0)])
            .collect();
        let link = 0.6;
        // Reference: union over every pair.
        let mut parent: Vec<usize> = (0..pts.len()).collect();
        for i in 0..pts.len() {
            for j in i + 1..pts.len() {
                if dist2(&pts[i], &pts[j]) <= link * link {
                    union(&mut parent, i, j);
                }
            }
        }
        let mut sizes: FxHashMap<usize, usize> = FxHashMap::default();
        for i in 0..pts.len() {
            *sizes.entry(find(&mut parent, i)).or_default() += 1;
        }
        let mut want: Vec<usize> = sizes.into_values().collect();
        want.sort_unstable_by(|a, b| b.cmp(a));
        let got: Vec<usize> = places(&pts, link, 1).places.iter().map(|p| p.events).collect();
        assert_eq!(got, want);
    }

    #[test]
    fn non_finite_points_are_scattered_not_a_panic() {
        let pts = vec![[f64::NAN, 0.0, 0.0], [0.0, 0.0, 0.0], [0.1, 0.0, 0.0]];
        let p = places(&pts, 0.35, 2);
        assert_eq!(p.places.len(), 1);
        assert_eq!(p.scattered, 1);
    }
}
