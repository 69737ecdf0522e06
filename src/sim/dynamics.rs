//! Movers: the people and machines of one session, what they are made of
//! and how they move.
//!
//! Each mover exists in one session only. It follows a random walk on the
//! road graph, back and forth, in its own lane: machines just right of the
//! centre line, people near a road edge, the surveyor in between, so nobody
//! walks through anybody and no mover ever overlaps a static object (roads
//! are kept clear). People walk at 1.0-1.5 m/s, machines drive at their
//! kind's speed (1-4 m/s); all machines and some people stop and go. Their
//! box stands on the highest ground under its footprint, like static objects.
//! A mover is labelled with its moving class (252-259) even while it stands:
//! SemanticKITTI labels by what an object does over the sequence.

use rand::Rng;

use super::assets::{Asset, Part, Surface, label, slab};
use super::ground::Ground;
use super::raycast::{self, Prim};
use super::seeds::{self, tag};
use super::shapes::Shape;
use super::site::{ObjectId, Roads, SiteObject};
use super::trajectory::{LANE_RADIUS_M, Polyline, random_walk};

/// A worker (legs, hi-vis torso, head) in a 0.5 × 0.5 × height box.
pub(crate) fn person(rng: &mut impl Rng) -> Asset {
    let h = rng.random_range(1.6..1.9);
    let l = label::MOVING_PERSON;
    let legs = 0.47 * h;
    let head = Part {
        shape: Shape::ellipsoid([0.0, 0.0, h - 0.14], 0.11, 0.13),
        label: l,
        reflectivity: 0.4,
        surface: Surface::Solid,
    };
    let parts = vec![
        slab([0.0, 0.0], 0.0, [0.25, 0.38, legs], l, 0.25),
        slab([0.0, 0.0], legs, [0.3, 0.45, h - 0.28 - legs], l, 0.85),
        head,
    ];
    Asset::boxed("person", l, [0.5, 0.5, h], parts)
}

/// The site machines that drive around, with realistic boxes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Machine {
    Excavator,
    WheelLoader,
    DumpTruck,
    SkidSteer,
    Pickup,
}

impl Machine {
    pub(crate) const ALL: [Machine; 5] =
        [Machine::Excavator, Machine::WheelLoader, Machine::DumpTruck, Machine::SkidSteer, Machine::Pickup];

    /// Speed range while moving, m/s.
    pub(crate) fn speed_range(self) -> (f64, f64) {
        match self {
            Machine::Excavator => (1.0, 1.8),
            Machine::WheelLoader => (1.5, 3.5),
            Machine::DumpTruck => (2.0, 4.0),
            Machine::SkidSteer => (1.0, 2.5),
            Machine::Pickup => (2.0, 4.0),
        }
    }

    pub(crate) fn asset(self) -> Asset {
        let y = 0.6; // machine yellow
        match self {
            Machine::Excavator => {
                let l = label::MOVING_OTHER_VEHICLE;
                let parts = vec![
                    slab([-0.6, 1.0], 0.0, [4.2, 0.6, 0.9], l, 0.15),
                    slab([-0.6, -1.0], 0.0, [4.2, 0.6, 0.9], l, 0.15),
                    slab([-0.9, 0.0], 0.9, [3.0, 2.4, 1.1], l, y),
                    slab([0.1, 0.7], 2.0, [1.0, 0.9, 1.0], l, y),
                    slab([1.8, -0.2], 1.5, [2.4, 0.45, 0.5], l, y),
                    slab([2.7, -0.2], 0.2, [0.6, 1.0, 0.8], l, 0.3),
                ];
                Asset::boxed("excavator", l, [6.0, 2.6, 3.0], parts)
            }
            Machine::WheelLoader => {
                let l = label::MOVING_OTHER_VEHICLE;
                let mut parts = vec![
                    slab([-0.6, 0.0], 0.5, [3.8, 2.0, 1.5], l, y),
                    slab([-0.3, 0.0], 2.0, [1.4, 1.5, 1.1], l, y),
                    slab([2.55, 0.0], 0.1, [0.9, 2.5, 0.9], l, 0.3),
                ];
                for (x, s) in [(-1.6, 1.0), (-1.6, -1.0), (0.9, 1.0), (0.9, -1.0)] {
                    parts.push(slab([x, s * 0.98], 0.0, [1.3, 0.5, 1.3], l, 0.08));
                }
                Asset::boxed("wheel_loader", l, [6.0, 2.5, 3.1], parts)
            }
            Machine::DumpTruck => {
                let l = label::MOVING_TRUCK;
                let mut parts = vec![
                    slab([2.05, 0.0], 0.5, [1.8, 2.3, 2.5], l, 0.7),
                    slab([-1.0, 0.0], 1.3, [3.9, 2.5, 1.6], l, 0.35),
                    slab([-0.2, 0.0], 0.6, [5.6, 1.2, 0.7], l, 0.15),
                ];
                for (x, s) in [(-2.0, 1.0), (-2.0, -1.0), (-0.8, 1.0), (-0.8, -1.0), (2.1, 1.0), (2.1, -1.0)] {
                    parts.push(slab([x, s * 1.0], 0.0, [1.0, 0.45, 1.0], l, 0.08));
                }
                Asset::boxed("dump_truck", l, [6.0, 2.5, 3.0], parts)
            }
            Machine::SkidSteer => {
                let l = label::MOVING_OTHER_VEHICLE;
                let parts = vec![
                    slab([-0.2, 0.0], 0.2, [2.0, 1.6, 1.2], l, y),
                    slab([-0.1, 0.0], 1.4, [1.1, 1.1, 0.7], l, 0.4),
                    slab([1.1, 0.0], 0.05, [0.5, 1.8, 0.6], l, 0.3),
                ];
                Asset::boxed("skid_steer", l, [2.8, 1.8, 2.1], parts)
            }
            Machine::Pickup => {
                let l = label::MOVING_CAR;
                let mut parts = vec![
                    slab([0.0, 0.0], 0.35, [5.2, 1.9, 0.85], l, 0.7),
                    slab([0.4, 0.0], 1.2, [2.0, 1.8, 0.6], l, 0.7),
                ];
                for (x, s) in [(-1.7, 1.0), (-1.7, -1.0), (1.7, 1.0), (1.7, -1.0)] {
                    parts.push(slab([x, s * 0.83], 0.0, [0.75, 0.24, 0.75], l, 0.08));
                }
                Asset::boxed("pickup", l, [5.3, 1.95, 1.85], parts)
            }
        }
    }
}

const MAX_PEOPLE: usize = 8;
const MAX_MACHINES: usize = 3;
/// The most movers a session has.
pub(crate) const MAX_MOVERS: usize = MAX_PEOPLE + MAX_MACHINES;

/// Lateral offsets of the lanes from a road's centre line, m (left positive).
const MACHINE_LANE_M: f64 = -0.5;
const PERSON_LANE_M: f64 = 4.6;

/// A mover's box pose at one instant: centre and heading.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MoverPose {
    pub center: [f64; 3],
    pub yaw: f64,
}

pub(crate) struct Mover {
    pub object: SiteObject,
    asset: Asset,
    path: Polyline,
    speed_mps: f64,
    start_m: f64,
    /// (start time s, distance travelled by then m, moving?) per phase.
    phases: Vec<(f64, f64, bool)>,
}

impl Mover {
    /// Distance travelled along the path by time `t`.
    fn travelled(&self, t: f64) -> f64 {
        let k = self.phases.partition_point(|p| p.0 <= t).max(1) - 1;
        let (t0, d0, moving) = self.phases[k];
        if moving { d0 + self.speed_mps * (t - t0) } else { d0 }
    }

    /// The box pose at time `t` (seconds since the session's first keyframe).
    pub(crate) fn pose_at(&self, t: f64, ground: &Ground) -> MoverPose {
        let len = self.path.length();
        let a = (self.start_m + self.travelled(t)).rem_euclid(2.0 * len);
        let (s, back) = if a <= len { (a, false) } else { (2.0 * len - a, true) };
        let [x, y] = self.path.at(s);
        let yaw = self.path.heading(s) + if back { std::f64::consts::PI } else { 0.0 };
        let base = ground.max_under(&self.asset.footprint(x, y, yaw));
        MoverPose { center: [x, y, base + self.asset.size[2] / 2.0], yaw }
    }

    /// The box at a pose, in the world frame.
    pub(crate) fn bbox_at(&self, p: &MoverPose) -> Shape {
        Shape::cuboid(p.center, self.asset.size, p.yaw)
    }

    /// The mover's primitives at a pose, ready for ray casting.
    pub(crate) fn prims_at(&self, p: &MoverPose) -> Vec<Prim> {
        let (bbox, parts) = self.asset.placed(p.center[0], p.center[1], p.center[2], p.yaw);
        debug_assert_eq!(bbox.size, self.asset.size);
        let id = self.object.id.0;
        parts.iter().enumerate().map(|(k, part)| Prim::new(part, id as u16, raycast::prim_key(id, k))).collect()
    }
}

/// Alternating move/stop phases covering `duration_s`; always moving when
/// `stops` is false.
fn phases(rng: &mut impl Rng, duration_s: f64, stops: bool, speed: f64) -> Vec<(f64, f64, bool)> {
    let mut out = Vec::new();
    let (mut t, mut d) = (0.0, 0.0);
    let mut moving = !stops || rng.random_bool(0.6);
    while t <= duration_s {
        out.push((t, d, moving));
        if !stops {
            break;
        }
        let dt = if moving { rng.random_range(5.0..25.0) } else { rng.random_range(2.0..12.0) };
        if moving {
            d += speed * dt;
        }
        t += dt;
        moving = !moving;
    }
    out
}

/// The movers of session `session`, with ids from `first_id` on.
pub(crate) fn session_movers(
    roads: &Roads,
    ground: &Ground,
    seed: u64,
    session: usize,
    duration_s: f64,
    first_id: u32,
) -> Vec<Mover> {
    let mut rng = seeds::rng(seed, &[tag::MOVERS, session as u64]);
    let people = rng.random_range(4..=MAX_PEOPLE);
    let machines = rng.random_range(1..=MAX_MACHINES);
    let mut movers = Vec::with_capacity(people + machines);
    for k in 0..people + machines {
        let (asset, speed, stops, lane) = if k < people {
            let side = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
            (person(&mut rng), rng.random_range(1.0..1.5), rng.random_bool(0.4), side * PERSON_LANE_M)
        } else {
            let m = Machine::ALL[rng.random_range(0..Machine::ALL.len())];
            let (lo, hi) = m.speed_range();
            (m.asset(), rng.random_range(lo..hi), true, MACHINE_LANE_M)
        };
        let start = rng.random_range(0..roads.nodes.len());
        let walk_m = rng.random_range(60.0..160.0);
        let nodes = random_walk(roads, &mut rng, vec![start], walk_m);
        let raw = Polyline::new(nodes.iter().map(|&n| roads.nodes[n]).collect());
        let path = raw.lane(LANE_RADIUS_M, 0.25, |_| lane);
        let start_m = rng.random_range(0.0..path.length());
        let phases = phases(&mut rng, duration_s, stops, speed);
        let object = SiteObject {
            id: ObjectId(first_id + k as u32),
            class: asset.class.into(),
            label: asset.label,
            dynamic: true,
            bbox: Shape::cuboid([0.0; 3], asset.size, 0.0),
            parts: asset.parts.clone(),
            sessions: vec![session],
        };
        let mut mover = Mover { object, asset, path, speed_mps: speed, start_m, phases };
        mover.object.bbox = mover.bbox_at(&mover.pose_at(0.0, ground));
        movers.push(mover);
    }
    movers
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::site::Site;

    #[test]
    fn movers_fit_their_boxes() {
        let mut rng = crate::sim::seeds::rng(1, &[]);
        let mut assets: Vec<Asset> = Machine::ALL.iter().map(|m| m.asset()).collect();
        assets.push(person(&mut rng));
        for a in assets {
            let bbox = Shape::cuboid([0.0; 3], a.size, 0.0);
            for p in &a.parts {
                let b = p.shape.xy_bounds();
                let (z0, z1) = p.shape.z_range();
                for c in [[b[0], b[1], z0], [b[2], b[3], z1]] {
                    assert!(bbox.contains(c, 1e-9), "{}: part {:?} sticks out of {:?}", a.class, p.shape, a.size);
                }
            }
            assert!(a.size[0] <= 6.0 + 1e-9 && a.size[1] <= 2.6 && a.size[2] <= 3.1, "{}", a.class);
        }
    }

    #[test]
    fn movers_move_at_their_speed_and_keep_off_static_objects() {
        let site = Site::generate(3, 2);
        let movers = session_movers(&site.roads, &site.ground, 3, 1, 200.0, 1000);
        assert!(movers.len() >= 5 && movers.len() <= 11);
        let statics: Vec<&SiteObject> = site.objects.iter().filter(|o| o.present_in(1)).collect();
        let mut moved = 0;
        for m in &movers {
            let (lo, hi) = if m.object.class == "person" { (1.0, 1.5) } else { (1.0, 4.0) };
            assert!(m.speed_mps >= lo && m.speed_mps <= hi, "{} at {}", m.object.class, m.speed_mps);
            let mut prev = m.pose_at(0.0, &site.ground);
            for k in 1..=250 {
                let p = m.pose_at(0.8 * k as f64, &site.ground);
                let step = (p.center[0] - prev.center[0]).hypot(p.center[1] - prev.center[1]);
                assert!(step <= m.speed_mps * 0.8 + 1e-6 + 0.3, "{} jumped {step} m", m.object.class);
                let b = m.bbox_at(&p);
                for o in &statics {
                    for part in &o.parts {
                        let c = part.shape.center;
                        assert!(
                            !b.contains(c, 0.0) || part.shape.z_range().0 > b.z_range().1,
                            "{} inside {}",
                            m.object.class,
                            o.class
                        );
                    }
                }
                prev = p;
            }
            moved += (m.pose_at(200.0, &site.ground).center[0] != m.pose_at(0.0, &site.ground).center[0]) as usize;
        }
        assert!(moved >= movers.len() - 1);
    }
}
