//! The construction site: its roads, its objects and when each exists.
//!
//! Layout (world frame, metres, x east, y north; the site is 110 m × 92 m):
//!
//! ```text
//!  fence ┌──────────────────────────────────────────────┐ y = 46
//!        │  perimeter road (10 m wide, centre |x|=47, |y|=38)
//!        │   ┌─────────── ring road (|x|=26, |y|=19) ──┐ │
//!  west  │ offices  ┌──── building 30 × 16 ────┐  crane │
//!  gate ═╡ ═spoke═  │ columns, slabs, stair core│ ═spoke═│
//!        │ parking  └──── scaffolding ─────────┘  laydown
//!        │   └──────────────────┬──────────────────┘ │
//!        └──────────────── south gate ────────────────┘ y = -46
//! ```
//!
//! Roads are kept clear of static objects (1 m margin): that is where the
//! surveyor walks and where people and machines move, which keeps the ground
//! truth clean (a mover never overlaps a static object). Materials, containers
//! and stockpiles sit in the laydown strips between the roads and in the apron
//! around the building, which every session's route circles. Objects change
//! between sessions on a schedule drawn from the seed; see [`Site::generate`].

use rand::Rng;
use rand_chacha::ChaCha8Rng;

use super::assets::{Asset, Part};
use super::ground::Ground;
use super::layout;
use super::seeds::{self, tag};
use super::shapes::Shape;

/// An object's id: unique over the whole simulation, also its instance id in
/// the `.label` files (high 16 bits), so it is below 65,536.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct ObjectId(pub u32);

/// An object of the site, static or moving.
#[derive(Debug, Clone, PartialEq)]
pub struct SiteObject {
    pub id: ObjectId,
    /// What it is: `container`, `pallet_stack`, `person`, `excavator`, ...
    pub class: String,
    /// Its main SemanticKITTI class (its parts may differ: a tree's trunk is 71).
    pub label: u16,
    /// True for movers (people, machines): they exist in one session and
    /// their pose per keyframe is in that session's `gt/dynamic.csv`.
    pub dynamic: bool,
    /// Oriented bounding box in the world frame (for a mover: at its
    /// session's first keyframe).
    pub bbox: Shape,
    /// The primitives: world frame for static objects; for movers, the body
    /// frame (origin at the box centre, x forward).
    pub parts: Vec<Part>,
    /// 1-based numbers of the sessions in which the object exists, ascending.
    pub sessions: Vec<usize>,
}

impl SiteObject {
    /// True when the object exists in `session` (1-based).
    pub fn present_in(&self, session: usize) -> bool {
        self.sessions.binary_search(&session).is_ok()
    }
}

pub(crate) const FENCE: [f64; 2] = [55.0, 46.0];
const PERIMETER: [f64; 2] = [47.0, 38.0];
const RING: [f64; 2] = [26.0, 19.0];
pub(crate) const ROAD_HALF_WIDTH_M: f64 = 5.0;
/// Static objects keep this far from a road's edge (people walk within
/// 0.15 m of it)...
const ROAD_CLEARANCE_M: f64 = 0.6;
/// ...plus this, which is also the gap left between objects.
pub(crate) const OBJECT_CLEARANCE_M: f64 = 0.4;

/// The road graph: 8 ring nodes (0..8, anticlockwise from east), 8 perimeter
/// nodes (8..16, same order) and four spokes joining the even ones.
pub(crate) struct Roads {
    pub nodes: Vec<[f64; 2]>,
    pub edges: Vec<[usize; 2]>,
}

impl Roads {
    pub(crate) fn site() -> Roads {
        let around = |r: [f64; 2]| {
            [[1.0, 0.0], [1.0, 1.0], [0.0, 1.0], [-1.0, 1.0], [-1.0, 0.0], [-1.0, -1.0], [0.0, -1.0], [1.0, -1.0]]
                .map(|[u, v]| [u * r[0], v * r[1]])
        };
        let nodes: Vec<[f64; 2]> = around(RING).into_iter().chain(around(PERIMETER)).collect();
        let mut edges = Vec::new();
        for i in 0..8 {
            edges.push([i, (i + 1) % 8]);
            edges.push([8 + i, 8 + (i + 1) % 8]);
        }
        for i in [0, 2, 4, 6] {
            edges.push([i, 8 + i]);
        }
        Roads { nodes, edges }
    }

    /// (edge, other node) pairs at node `n`.
    pub(crate) fn neighbours(&self, n: usize) -> Vec<(usize, usize)> {
        (self.edges.iter().enumerate())
            .filter_map(|(e, &[a, b])| {
                if a == n {
                    Some((e, b))
                } else if b == n {
                    Some((e, a))
                } else {
                    None
                }
            })
            .collect()
    }

    /// Axis-aligned rectangles `[x0, y0, x1, y1]` of every road surface, plus
    /// the gate accesses and the streets outside the fence.
    pub(crate) fn surfaces(&self) -> Vec<[f64; 4]> {
        let w = ROAD_HALF_WIDTH_M;
        let mut rects: Vec<[f64; 4]> = (self.edges.iter())
            .map(|&[a, b]| {
                let (p, q) = (self.nodes[a], self.nodes[b]);
                [p[0].min(q[0]) - w, p[1].min(q[1]) - w, p[0].max(q[0]) + w, p[1].max(q[1]) + w]
            })
            .collect();
        rects.push([-4.0, -60.0, 4.0, -PERIMETER[1]]); // south gate access
        rects.push([-100.0, -60.0, 100.0, -52.0]); // street south of the site
        rects.push([-66.0, -4.0, -PERIMETER[0], 4.0]); // west gate access
        rects.push([-74.0, -90.0, -66.0, 90.0]); // street west of the site
        rects
    }
}

/// A footprint for overlap tests: centre, half extents, yaw.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Footprint {
    c: [f64; 2],
    half: [f64; 2],
    yaw: f64,
}

impl Footprint {
    pub(crate) fn rect(r: [f64; 4]) -> Footprint {
        Footprint {
            c: [(r[0] + r[2]) / 2.0, (r[1] + r[3]) / 2.0],
            half: [(r[2] - r[0]) / 2.0, (r[3] - r[1]) / 2.0],
            yaw: 0.0,
        }
    }

    pub(crate) fn of(size: [f64; 3], x: f64, y: f64, yaw: f64, grow: f64) -> Footprint {
        Footprint { c: [x, y], half: [size[0] / 2.0 + grow, size[1] / 2.0 + grow], yaw }
    }

    /// Half extents of the axis-aligned bounds.
    fn extents(&self) -> [f64; 2] {
        let (s, c) = self.yaw.sin_cos();
        [self.half[0] * c.abs() + self.half[1] * s.abs(), self.half[0] * s.abs() + self.half[1] * c.abs()]
    }

    /// Separating-axis test of two oriented rectangles.
    fn overlaps(&self, o: &Footprint) -> bool {
        let axes = |f: &Footprint| {
            let (s, c) = f.yaw.sin_cos();
            [[c, s], [-s, c]]
        };
        let radius = |f: &Footprint, ax: [f64; 2]| {
            let [u, v] = axes(f);
            f.half[0] * (u[0] * ax[0] + u[1] * ax[1]).abs() + f.half[1] * (v[0] * ax[0] + v[1] * ax[1]).abs()
        };
        let d = [o.c[0] - self.c[0], o.c[1] - self.c[1]];
        axes(self)
            .into_iter()
            .chain(axes(o))
            .all(|ax| (d[0] * ax[0] + d[1] * ax[1]).abs() <= radius(self, ax) + radius(o, ax))
    }
}

/// The whole site over all sessions: ground, roads and static objects.
pub(crate) struct Site {
    pub ground: Ground,
    pub roads: Roads,
    pub objects: Vec<SiteObject>,
}

/// Axis-aligned bounds of parts: (centre, size).
pub(crate) fn bounds_of(parts: &[Part]) -> ([f64; 3], [f64; 3]) {
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for p in parts {
        let b = p.shape.xy_bounds();
        let (z0, z1) = p.shape.z_range();
        for (k, (l, h)) in [(b[0], b[2]), (b[1], b[3]), (z0, z1)].into_iter().enumerate() {
            lo[k] = lo[k].min(l);
            hi[k] = hi[k].max(h);
        }
    }
    ([0, 1, 2].map(|k| (lo[k] + hi[k]) / 2.0), [0, 1, 2].map(|k| hi[k] - lo[k]))
}

/// Collects objects and answers "is this footprint free in these sessions".
pub(crate) struct Builder {
    pub ground: Ground,
    forbidden: Vec<Footprint>,
    taken: Vec<(Footprint, Vec<usize>)>,
    pub objects: Vec<SiteObject>,
    pub sessions: usize,
    pub rng: ChaCha8Rng,
}

impl Builder {
    fn push(&mut self, class: &str, label: u16, bbox: Shape, parts: Vec<Part>, sessions: Vec<usize>) {
        if sessions.is_empty() {
            return; // an event after the last session never happens
        }
        let id = ObjectId(self.objects.len() as u32 + 1);
        let o = SiteObject { id, class: class.into(), label, dynamic: false, bbox, parts, sessions };
        self.objects.push(o);
    }

    /// An object built directly in world coordinates (box = its bounds).
    pub(crate) fn add_world(&mut self, class: &str, label: u16, parts: Vec<Part>, sessions: Vec<usize>) {
        let (c, size) = bounds_of(&parts);
        self.push(class, label, Shape::cuboid(c, size, 0.0), parts, sessions);
    }

    /// [`Builder::add_world`], reserving the bounds' footprint in `sessions`.
    pub(crate) fn add_world_reserved(&mut self, class: &str, label: u16, parts: Vec<Part>, sessions: Vec<usize>) {
        let (c, size) = bounds_of(&parts);
        self.taken.push((Footprint::of(size, c[0], c[1], 0.0, 0.0), sessions.clone()));
        self.push(class, label, Shape::cuboid(c, size, 0.0), parts, sessions);
    }

    /// An asset standing on the ground at (x, y) with heading `yaw`.
    pub(crate) fn add(&mut self, a: &Asset, x: f64, y: f64, yaw: f64, sessions: Vec<usize>) {
        let z = self.ground.max_under(&a.footprint(x, y, yaw)) + a.size[2] / 2.0;
        self.add_at(a, x, y, z, yaw, sessions);
    }

    /// An asset with its box centre at (x, y, z); its footprint is reserved.
    pub(crate) fn add_at(&mut self, a: &Asset, x: f64, y: f64, z: f64, yaw: f64, sessions: Vec<usize>) {
        self.taken.push((Footprint::of(a.size, x, y, yaw, 0.0), sessions.clone()));
        let (bbox, parts) = a.placed(x, y, z, yaw);
        self.push(a.class, a.label, bbox, parts, sessions);
    }

    pub(crate) fn free(&self, f: &Footprint, sessions: &[usize]) -> bool {
        let ext = f.extents();
        let inside_fence = (0..2).all(|k| f.c[k].abs() + ext[k] < FENCE[k] - 1.0);
        inside_fence
            && !self.forbidden.iter().any(|r| r.overlaps(f))
            && !(self.taken.iter()).any(|(t, ss)| ss.iter().any(|s| sessions.contains(s)) && t.overlaps(f))
    }

    /// Places `a` at a random free spot in one of `regions`, mostly with its
    /// long side along the region's (± a few degrees); None after many tries.
    pub(crate) fn place(&mut self, a: &Asset, regions: &[[f64; 4]], sessions: &[usize]) -> Option<[f64; 2]> {
        let area: f64 = regions.iter().map(|r| (r[2] - r[0]) * (r[3] - r[1])).sum();
        for _ in 0..300 {
            let mut pick = self.rng.random_range(0.0..area);
            let r = *regions.iter().find(|r| {
                pick -= (r[2] - r[0]) * (r[3] - r[1]);
                pick < 0.0
            })?;
            let along_x = (r[2] - r[0] >= r[3] - r[1]) == (a.size[0] >= a.size[1]);
            let quarter = if along_x != self.rng.random_bool(0.2) { 0.0 } else { std::f64::consts::FRAC_PI_2 };
            let yaw = quarter + self.rng.random_range(-0.06..0.06);
            let f = Footprint::of(a.size, 0.0, 0.0, yaw, OBJECT_CLEARANCE_M);
            let ext = f.extents();
            if r[2] - r[0] < 2.0 * ext[0] || r[3] - r[1] < 2.0 * ext[1] {
                continue;
            }
            let x = self.rng.random_range(r[0] + ext[0]..=r[2] - ext[0]);
            let y = self.rng.random_range(r[1] + ext[1]..=r[3] - ext[1]);
            if self.free(&Footprint { c: [x, y], ..f }, sessions) {
                self.add(a, x, y, yaw, sessions.to_vec());
                return Some([x, y]);
            }
        }
        None
    }

    pub(crate) fn all(&self) -> Vec<usize> {
        (1..=self.sessions).collect()
    }

    /// The session of the k-th of four building events (k = 1..4), spread
    /// over the sessions; `sessions + 1` (never) when there is one session.
    pub(crate) fn event(&self, k: usize) -> usize {
        if self.sessions < 2 {
            return self.sessions + 1;
        }
        (1 + (k as f64 * (self.sessions - 1) as f64 / 4.0).round() as usize).clamp(2, self.sessions)
    }
}

/// Sessions `a..=b` (empty when a > b).
pub(crate) fn span(a: usize, b: usize) -> Vec<usize> {
    (a..=b).collect()
}

impl Site {
    /// Lays out the site for `sessions` sessions.
    ///
    /// Permanent: fence, building core, crane, offices, trees, light poles,
    /// some containers, materials and a stockpile, the neighbours outside.
    /// Building progress on four events spread over the sessions (walls built,
    /// a level poured, shoring and scaffolding dismantled). For every session
    /// after the first, 3-5 objects appear and 3-5 disappear (materials,
    /// containers, skips, stockpiles, one of each in the building's apron),
    /// containers move, parked cars come and go.
    pub(crate) fn generate(seed: u64, sessions: usize) -> Site {
        let roads = Roads::site();
        let surfaces = roads.surfaces();
        let ground = Ground::new(seeds::derive(seed, &[tag::SITE, 1]), |x, y| {
            surfaces.iter().any(|r| x >= r[0] && x <= r[2] && y >= r[1] && y <= r[3])
        });
        let mut forbidden: Vec<Footprint> = (surfaces.iter())
            .map(|r| {
                let c = ROAD_CLEARANCE_M;
                Footprint::rect([r[0] - c, r[1] - c, r[2] + c, r[3] + c])
            })
            .collect();
        forbidden.push(Footprint::rect([-15.1, -8.1, 15.1, 8.1])); // the building
        let mut b = Builder {
            ground,
            forbidden,
            taken: Vec::new(),
            objects: Vec::new(),
            sessions,
            rng: seeds::rng(seed, &[tag::SITE, 2]),
        };
        layout::building(&mut b);
        layout::fence(&mut b);
        layout::fixtures(&mut b);
        layout::changes(&mut b);
        Site { ground: b.ground, roads, objects: b.objects }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_later_session_gains_and_loses_objects() {
        for (seed, sessions) in [(1, 2), (5, 5), (6, 5), (7, 5), (8, 10), (9, 10)] {
            let site = Site::generate(seed, sessions);
            for s in 2..=sessions {
                let changed = |first: bool| {
                    (site.objects.iter())
                        .filter(|o| {
                            if first { o.sessions.first() == Some(&s) } else { o.sessions.last() == Some(&(s - 1)) }
                        })
                        .map(|o| o.bbox.center)
                        .collect::<Vec<_>>()
                };
                let (appear, vanish) = (changed(true), changed(false));
                assert!(
                    appear.len() >= 3 && vanish.len() >= 3,
                    "seed {seed} session {s}: +{} -{}",
                    appear.len(),
                    vanish.len()
                );
                let middle = |c: &[f64; 3]| c[0].abs() < 21.0 && c[1].abs() < 14.0;
                assert!(
                    appear.iter().any(middle) && vanish.iter().any(middle),
                    "seed {seed} session {s}: none in the apron"
                );
            }
            assert!(site.objects.len() < 65_000);
            for (k, o) in site.objects.iter().enumerate() {
                assert_eq!(o.id, ObjectId(k as u32 + 1));
                assert!(o.sessions.windows(2).all(|w| w[0] < w[1]) && !o.sessions.is_empty());
            }
        }
    }

    #[test]
    fn static_objects_keep_off_the_roads() {
        let site = Site::generate(11, 4);
        let roads: Vec<Footprint> = site.roads.surfaces().into_iter().map(Footprint::rect).collect();
        for o in site.objects.iter().filter(|o| o.class != "crane_jib") {
            let (lo, _) = o.bbox.z_range();
            let f = Footprint::of(o.bbox.size, o.bbox.center[0], o.bbox.center[1], o.bbox.yaw, 0.0);
            assert!(!roads.iter().any(|r| r.overlaps(&f)) || lo > 5.0, "{} {:?} is on a road", o.class, o.bbox);
        }
    }

    #[test]
    fn footprints_overlap_like_rectangles() {
        let a = Footprint { c: [0.0, 0.0], half: [2.0, 0.5], yaw: 0.0 };
        let b = Footprint { c: [2.3, 0.0], half: [0.5, 0.5], yaw: 0.7 };
        assert!(a.overlaps(&b));
        let c = Footprint { c: [3.0, 1.5], half: [0.5, 0.5], yaw: 0.7 };
        assert!(!a.overlaps(&c));
    }
}
