//! What stands where, and when: the building and its progress, the fence,
//! the fixtures that stay, and the objects that come and go between sessions.
//!
//! Every function adds objects through the [`Builder`], which keeps them off
//! the roads and apart from each other in the sessions they share.

use rand::Rng;

use super::assets::{self, Asset, Part, Surface, label, post, slab};
use super::ground::Ground;
use super::shapes::Shape;
use super::site::{Builder, FENCE, Footprint, OBJECT_CLEARANCE_M, span};

const BUILDING_HALF: [f64; 2] = [15.0, 8.0];

/// The laydown strips between the ring and perimeter roads.
const LAYDOWN: [[f64; 4]; 4] =
    [[31.0, -33.0, 42.0, 33.0], [-42.0, -33.0, -31.0, 33.0], [-31.0, 24.0, 31.0, 33.0], [-31.0, -33.0, 31.0, -24.0]];
/// The apron between the building and the ring road: the middle of the
/// site, which every route circles.
const APRON: [[f64; 4]; 4] =
    [[-21.0, 8.0, 21.0, 14.0], [-21.0, -14.0, 21.0, -8.0], [15.0, -14.0, 21.0, 14.0], [-21.0, -14.0, -15.0, 14.0]];

/// The building under construction, its scaffolding and shoring.
pub(crate) fn building(b: &mut Builder) {
    let [hx, hy] = BUILDING_HALF;
    let z0 = b.ground.max_under(&[[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]]);
    let floor = |k: usize| z0 + 0.3 + 3.6 * k as f64;
    let xs = [-14.75, -9.0, -3.0, 3.0, 9.0, 14.75];
    let ys = [-7.75, 0.0, 7.75];
    let bl = label::BUILDING;
    let columns = |k: usize| -> Vec<Part> {
        let mut v = Vec::new();
        for &x in &xs {
            for &y in &ys {
                v.push(slab([x, y], floor(k - 1), [0.5, 0.5, 3.35], bl, 0.55));
            }
        }
        v
    };
    let deck = |k: usize| slab([0.0, 0.0], floor(k) - 0.25, [2.0 * hx, 2.0 * hy, 0.25], bl, 0.5);
    let (e1, e2, e3, e4) = (b.event(1), b.event(2), b.event(3), b.event(4));
    let s = b.sessions;

    // Ground slab, first-level columns and deck, stair core: from the start.
    // The ground slab sits on a foundation reaching a metre into the ground.
    let mut core = vec![slab([0.0, 0.0], z0 - 1.0, [2.0 * hx, 2.0 * hy, 1.3], bl, 0.5), deck(1)];
    core.extend(columns(1));
    let top = floor(3) + 1.0 - z0;
    core.push(slab([-11.0, 2.9], z0, [4.0, 0.2, top], bl, 0.55));
    core.push(slab([-11.0, -2.9], z0, [4.0, 0.2, top], bl, 0.55));
    core.push(slab([-12.9, 0.0], z0, [0.2, 5.6, top], bl, 0.55));
    core.push(slab([-9.1, 1.8], z0, [0.2, 2.0, top], bl, 0.55)); // door in the east wall
    core.push(slab([-9.1, -1.8], z0, [0.2, 2.0, top], bl, 0.55));
    core.push(slab([-9.1, 0.0], z0 + 2.5, [0.2, 1.6, top - 2.5], bl, 0.55));
    let all = b.all();
    b.add_world("building", bl, core, all);

    let mut level2 = columns(2);
    level2.push(deck(2));
    b.add_world("building_level", bl, level2, span(e2, s));
    b.add_world("building_columns", bl, columns(3), span(e3, s));

    // Shoring props (60 mm tubes on a 1.5 m grid) under a deck until it cures.
    let shoring = |k: usize| -> Vec<Part> {
        let mut v = Vec::new();
        for i in 0..19 {
            for j in 0..10 {
                let (x, y) = (-13.5 + 1.5 * i as f64, -6.75 + 1.5 * j as f64);
                let in_core = (-13.4..=-8.6).contains(&x) && (-3.4..=3.4).contains(&y);
                let at_column = xs.iter().any(|&c| (c - x).abs() < 0.6) && ys.iter().any(|&c| (c - y).abs() < 0.6);
                if !in_core && !at_column {
                    v.push(post([x, y], floor(k - 1), 0.03, 3.35, label::OTHER_STRUCTURE, 0.6));
                }
            }
        }
        v
    };
    b.add_world("shoring", label::OTHER_STRUCTURE, shoring(1), span(1, e2 - 1));
    b.add_world("shoring", label::OTHER_STRUCTURE, shoring(2), span(e2, e4 - 1));

    // North facade infill: per bay a sill, two piers and a lintel (a 4 m window).
    let mut north = Vec::new();
    for w in xs.windows(2) {
        let (a, c) = (w[0] + 0.25, w[1] - 0.25);
        let mid = (a + c) / 2.0;
        north.push(slab([mid, 7.75], floor(0), [c - a, 0.25, 0.9], bl, 0.45));
        north.push(slab([mid, 7.75], floor(0) + 2.4, [c - a, 0.25, 0.95], bl, 0.45));
        let pier = (c - a - 4.0) / 2.0;
        north.push(slab([a + pier / 2.0, 7.75], floor(0) + 0.9, [pier, 0.25, 1.5], bl, 0.45));
        north.push(slab([c - pier / 2.0, 7.75], floor(0) + 0.9, [pier, 0.25, 1.5], bl, 0.45));
    }
    b.add_world("wall", bl, north, span(e1, s));
    // West facade blockwork with a door.
    let west = vec![
        slab([-14.75, -4.25], floor(0), [0.25, 7.5, 3.35], bl, 0.45),
        slab([-14.75, 4.25], floor(0), [0.25, 7.5, 3.35], bl, 0.45),
        slab([-14.75, 0.0], floor(0) + 2.2, [0.25, 1.0, 1.15], bl, 0.45),
    ];
    b.add_world("wall", bl, west, span(e3, s));

    // Scaffolding: 48.3 mm standards every 2 m, ledgers every 2 m up, boards on three lifts.
    let scaffold = |along_x: bool, from: f64, to: f64, off: f64, dir: f64, ground: &Ground| -> Vec<Part> {
        let os = label::OTHER_STRUCTURE;
        let at = |u: f64, v: f64| if along_x { [u, v] } else { [v, u] };
        let n = ((to - from) / 2.0).round() as usize;
        let len = to - from;
        let mid = (from + to) / 2.0;
        let corners = [at(from, off), at(to, off), at(from, off + 1.2 * dir), at(to, off + 1.2 * dir)];
        let zb = ground.max_under(&corners);
        let mut v = Vec::new();
        for k in 0..=n {
            let u = from + len * k as f64 / n as f64;
            for w in [off, off + 1.2 * dir] {
                v.push(post(at(u, w), zb, 0.024, 8.6, os, 0.6));
            }
        }
        let size = |l: f64, w: f64, h: f64| if along_x { [l, w, h] } else { [w, l, h] };
        for lift in 1..=4 {
            for w in [off, off + 1.2 * dir] {
                v.push(slab(at(mid, w), zb + 2.0 * lift as f64, size(len, 0.05, 0.05), os, 0.6));
            }
            if lift < 4 {
                v.push(slab(at(mid, off + 0.6 * dir), zb + 2.0 * lift as f64 - 0.05, size(len, 1.0, 0.04), os, 0.45));
            }
        }
        v
    };
    let east = scaffold(false, -hy, hy, hx + 0.4, 1.0, &b.ground);
    let all = b.all();
    b.add_world_reserved("scaffolding", label::OTHER_STRUCTURE, east, all);
    let south = scaffold(true, -hx, hx, -hy - 0.4, -1.0, &b.ground);
    b.add_world_reserved("scaffolding", label::OTHER_STRUCTURE, south, span(1, e3 - 1));
}

/// Heras-style mesh fence panels (3.5 m × 2 m on concrete feet) with two gates.
pub(crate) fn fence(b: &mut Builder) {
    let [fx, fy] = FENCE;
    // (start, end) of each run; gates of 12 m at the south and west spokes.
    let runs = [
        ([-fx, fy], [fx, fy]),
        ([fx, -fy], [fx, fy]),
        ([-fx, -fy], [-6.0, -fy]),
        ([6.0, -fy], [fx, -fy]),
        ([-fx, -fy], [-fx, -6.0]),
        ([-fx, 6.0], [-fx, fy]),
    ];
    for (a, c) in runs {
        let len = ((c[0] - a[0]).powi(2) + (c[1] - a[1]).powi(2)).sqrt();
        let n = (len / 3.55).ceil() as usize;
        let step = len / n as f64;
        let yaw = (c[1] - a[1]).atan2(c[0] - a[0]);
        let (s, co) = yaw.sin_cos();
        let mut parts = Vec::new();
        for k in 0..n {
            let u = (k as f64 + 0.5) * step;
            let (x, y) = (a[0] + co * u, a[1] + s * u);
            let half = (step - 0.05) / 2.0;
            let zb = b.ground.max_under(&[[x - co * half, y - s * half], [x + co * half, y + s * half]]);
            let panel = Shape::cuboid([x, y, zb + 0.12 + 1.0], [step - 0.05, 0.04, 2.0], yaw);
            parts.push(Part {
                shape: panel,
                label: label::FENCE,
                reflectivity: 0.5,
                surface: Surface::Mesh { pass: 0.6 },
            });
            let foot = Shape::cuboid([x - co * half, y - s * half, zb + 0.06], [0.6, 0.2, 0.12], yaw);
            parts.push(Part { shape: foot, label: label::FENCE, reflectivity: 0.55, surface: Surface::Solid });
        }
        let all = b.all();
        b.add_world("fence", label::FENCE, parts, all);
    }
}

/// Things that stay: crane, offices, toilets, trees, light poles, neighbours.
pub(crate) fn fixtures(b: &mut Builder) {
    let all = b.all();
    let crane = assets::crane();
    let mast = [36.5, -18.0];
    b.add(&crane, mast[0], mast[1], 0.0, all.clone());
    let jib_z = b.objects.last().map_or(30.0, |o| o.bbox.center[2] + o.bbox.size[2] / 2.0) + 0.3;
    // The jib slews between sessions: one object per session.
    for s in 1..=b.sessions {
        let yaw = b.rng.random_range(-std::f64::consts::PI..std::f64::consts::PI);
        let (sn, cs) = yaw.sin_cos();
        let at = |u: f64, z: f64| [mast[0] + cs * u, mast[1] + sn * u, z];
        let os = label::OTHER_STRUCTURE;
        let solid = |shape| Part { shape, label: os, reflectivity: 0.6, surface: Surface::Solid };
        let parts = vec![
            solid(Shape::cuboid(at(10.0, jib_z + 0.8), [40.0, 1.2, 1.6], yaw)),
            solid(Shape::cuboid(at(-8.0, jib_z - 1.1), [3.0, 2.0, 2.2], yaw)),
        ];
        b.add_world("crane_jib", os, parts, vec![s]);
    }
    let half_pi = std::f64::consts::FRAC_PI_2;
    b.add(&assets::office_cabin(false), -37.0, 12.0, half_pi, all.clone());
    b.add(&assets::office_cabin(true), -37.0, 21.0, half_pi, all.clone());
    b.add(&assets::toilet(), -33.5, 26.5, 0.0, all.clone());
    b.add(&assets::toilet(), -33.5, 28.0, 0.0, all.clone());
    // Lamp heads point into the site.
    let pi = std::f64::consts::PI;
    for (x, y, yaw) in
        [(53.5, -20.0, pi), (53.5, 20.0, pi), (-53.5, 20.0, 0.0), (-25.0, 44.6, -half_pi), (25.0, 44.6, -half_pi)]
    {
        b.add(&assets::light_pole(), x, y, yaw, all.clone());
    }
    for _ in 0..2 {
        let t = assets::tree(&mut b.rng);
        b.place(&t, &[[31.0, 6.0, 42.0, 33.0]], &all);
    }
    // Outside the fence: rows of trees and the neighbours' buildings.
    for k in 0..9 {
        let t = assets::tree(&mut b.rng);
        let x = -48.0 + 12.0 * k as f64 + b.rng.random_range(-2.0..2.0);
        let y = 52.0 + b.rng.random_range(-1.5..1.5);
        b.add(&t, x, y, 0.0, all.clone());
    }
    for k in 0..6 {
        let t = assets::tree(&mut b.rng);
        let x = 61.5 + b.rng.random_range(-1.0..1.0);
        b.add(&t, x, -35.0 + 14.0 * k as f64, 0.0, all.clone());
    }
    for (c, size) in [
        ([82.0, 0.0], [20.0, 50.0, 14.0]),
        ([-20.0, 66.0], [50.0, 16.0, 10.0]),
        ([-84.0, -30.0], [14.0, 30.0, 8.0]),
        ([40.0, -74.0], [30.0, 14.0, 20.0]),
    ] {
        // Big buildings are founded a metre below the ground rather than
        // standing on its highest point, so no daylight shows beneath them.
        let a = Asset::fitted(
            "neighbour_building",
            label::BUILDING,
            vec![slab([0.0, 0.0], 0.0, size, label::BUILDING, 0.5)],
        );
        let z = b.ground.height_at(c[0], c[1]) - 1.0 + size[2] / 2.0;
        b.add_at(&a, c[0], c[1], z, 0.0, all.clone());
    }
}

/// The objects that change between sessions.
pub(crate) fn changes(b: &mut Builder) {
    let s = b.sessions;
    let all = b.all();
    parked_cars(b);
    // Big things first, while there is room: stockpiles (one grows at the
    // second event), containers, then materials in the apron and laydown.
    b.place(&assets::stockpile(3.5, 1.8), &LAYDOWN, &all);
    let e2 = b.event(2);
    if let Some([x, y]) = b.place(&assets::stockpile(2.8, 1.4), &LAYDOWN, &span(1, e2 - 1)) {
        let big = assets::stockpile(3.8, 2.2);
        if b.free(&Footprint::of(big.size, x, y, 0.0, OBJECT_CLEARANCE_M), &span(e2, s)) {
            b.add(&big, x, y, 0.0, span(e2, s));
        }
    }
    for forty in [false, false, true, true] {
        let c = assets::container(&mut b.rng, forty);
        b.place(&c, &LAYDOWN, &all);
    }
    for k in 0..16 {
        material(b, k < 4, &all);
    }
    // Containers moved at the first and third events.
    for k in [1, 3] {
        let e = b.event(k);
        if e <= s {
            let forty = b.rng.random_bool(0.5);
            let c = assets::container(&mut b.rng, forty);
            b.place(&c, &LAYDOWN, &span(1, e - 1));
            b.place(&c, &LAYDOWN, &span(e, s));
        }
    }
    // Deliveries and removals: every later session gains and loses 3-5 objects.
    for t in 2..=s {
        for k in 0..b.rng.random_range(3..=5) {
            let last = b.rng.random_range(t..=s);
            material(b, k == 0, &span(t, last));
        }
        for k in 0..b.rng.random_range(3..=5) {
            let first = b.rng.random_range(1..t);
            material(b, k == 0, &span(first, t - 1));
        }
    }
}

/// Places one material object (in the building's apron when `apron`),
/// trying other kinds when a big one does not fit.
fn material(b: &mut Builder, apron: bool, sessions: &[usize]) {
    for _ in 0..30 {
        let a = if apron {
            match b.rng.random_range(0..4) {
                0 => assets::pallet_stack(&mut b.rng),
                1 => assets::rebar_bundle(&mut b.rng),
                2 => assets::timber_stack(&mut b.rng),
                _ => assets::pipe_stack(&mut b.rng),
            }
        } else {
            match b.rng.random_range(0..14) {
                0..=2 => assets::pallet_stack(&mut b.rng),
                3 | 4 => assets::rebar_bundle(&mut b.rng),
                5 | 6 => assets::timber_stack(&mut b.rng),
                7 => assets::pipe_stack(&mut b.rng),
                8 => assets::container(&mut b.rng, false),
                9 => assets::container(&mut b.rng, true),
                10 => assets::skip_bin(),
                11 => assets::generator(),
                12 => assets::barrier_row(&mut b.rng),
                _ => {
                    let r = b.rng.random_range(2.0..3.5);
                    assets::stockpile(r, r * b.rng.random_range(0.4..0.6))
                }
            }
        };
        if b.place(&a, if apron { &APRON } else { &LAYDOWN }, sessions).is_some() {
            return;
        }
    }
}

/// Cars in eight parking bays by the offices: a bay is empty or holds a car
/// that may stay for the next session or leave.
fn parked_cars(b: &mut Builder) {
    for bay in 0..8 {
        let y = -8.0 - 2.7 * bay as f64;
        let mut current: Option<(Asset, f64, f64, usize)> = None;
        for t in 1..=b.sessions + 1 {
            let stays = t <= b.sessions && current.is_some() && b.rng.random_bool(0.5);
            if !stays {
                if let Some((a, x, yaw, first)) = current.take() {
                    b.add(&a, x, y, yaw, span(first, t - 1));
                }
                if t <= b.sessions && b.rng.random_bool(0.65) {
                    let yaw = if b.rng.random_bool(0.5) { 0.0 } else { std::f64::consts::PI }
                        + b.rng.random_range(-0.05..0.05);
                    current = Some((assets::parked_car(&mut b.rng), -36.5 + b.rng.random_range(-0.3..0.3), yaw, t));
                }
            }
        }
    }
}
