//! Object builders: what a container, a pallet stack or a tree is made of,
//! as primitives with a SemanticKITTI label and a surface (people and
//! machines are built in `dynamics.rs`).
//!
//! An [`Asset`] is built in its *base frame* (x forward, footprint centred on
//! the origin, z = 0 on the ground) and stored in its *body frame* (origin at
//! the centre of its bounding box), which is the frame `primitives.csv` uses
//! for movers and whose pose `gt/dynamic.csv` gives. Sizes are those of real site
//! equipment (ISO containers, Euro pallets, 48.3 mm scaffold tubes).

use rand::Rng;

use super::shapes::Shape;

/// How a surface returns a laser pulse.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Surface {
    /// Every ray that meets it returns from its skin.
    Solid,
    /// A mesh (fence panels): a ray passes through with probability `pass`.
    Mesh { pass: f32 },
    /// Foliage: returns from inside the volume, with a free path of mean
    /// `1 / extinction_per_m`; a ray may pass through entirely.
    Foliage { extinction_per_m: f32 },
}

/// One primitive of an object.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Part {
    pub shape: Shape,
    /// SemanticKITTI class of the points it returns.
    pub label: u16,
    /// Diffuse reflectivity in [0, 1] at the sensor's wavelength.
    pub reflectivity: f32,
    pub surface: Surface,
}

/// SemanticKITTI classes used by the site.
pub mod label {
    pub const CAR: u16 = 10;
    pub const BUILDING: u16 = 50;
    pub const FENCE: u16 = 51;
    pub const OTHER_STRUCTURE: u16 = 52;
    pub const VEGETATION: u16 = 70;
    pub const TRUNK: u16 = 71;
    pub const TERRAIN: u16 = 72;
    pub const POLE: u16 = 80;
    pub const OTHER_OBJECT: u16 = 99;
    pub const MOVING_CAR: u16 = 252;
    pub const MOVING_PERSON: u16 = 254;
    pub const MOVING_TRUCK: u16 = 258;
    pub const MOVING_OTHER_VEHICLE: u16 = 259;
}

/// A solid box standing on `z0` of the base frame.
pub(crate) fn slab(c: [f64; 2], z0: f64, size: [f64; 3], label: u16, refl: f32) -> Part {
    let shape = Shape::cuboid([c[0], c[1], z0 + size[2] / 2.0], size, 0.0);
    Part { shape, label, reflectivity: refl, surface: Surface::Solid }
}

/// A solid vertical cylinder standing on `z0`.
pub(crate) fn post(c: [f64; 2], z0: f64, radius: f64, height: f64, label: u16, refl: f32) -> Part {
    Part {
        shape: Shape::cylinder([c[0], c[1], z0], radius, height),
        label,
        reflectivity: refl,
        surface: Surface::Solid,
    }
}

/// An object's geometry in its body frame, with its bounding box size.
#[derive(Debug, Clone)]
pub(crate) struct Asset {
    pub class: &'static str,
    pub label: u16,
    pub size: [f64; 3],
    pub parts: Vec<Part>,
}

impl Asset {
    /// From base-frame parts; the box is their bounds.
    pub(crate) fn fitted(class: &'static str, label: u16, parts: Vec<Part>) -> Asset {
        let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
        for p in &parts {
            let b = p.shape.xy_bounds();
            let (z0, z1) = p.shape.z_range();
            for (k, (l, h)) in [(b[0], b[2]), (b[1], b[3]), (z0, z1)].into_iter().enumerate() {
                lo[k] = lo[k].min(l);
                hi[k] = hi[k].max(h);
            }
        }
        let c = [(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0, (lo[2] + hi[2]) / 2.0];
        let parts =
            parts.into_iter().map(|p| Part { shape: p.shape.transformed(-c[0], -c[1], -c[2], 0.0), ..p }).collect();
        Asset { class, label, size: [hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]], parts }
    }

    /// From base-frame parts inside a nominal box centred on the origin in x-y
    /// and standing on z = 0 (movers: their box is what ground truth reports).
    pub(crate) fn boxed(class: &'static str, label: u16, size: [f64; 3], parts: Vec<Part>) -> Asset {
        let parts = parts
            .into_iter()
            .map(|p| Part { shape: p.shape.transformed(0.0, 0.0, -size[2] / 2.0, 0.0), ..p })
            .collect();
        Asset { class, label, size, parts }
    }

    /// Footprint corners when the box centre is at (x, y) with heading `yaw`.
    pub(crate) fn footprint(&self, x: f64, y: f64, yaw: f64) -> [[f64; 2]; 4] {
        let (s, c) = yaw.sin_cos();
        let (a, b) = (self.size[0] / 2.0, self.size[1] / 2.0);
        [(-a, -b), (a, -b), (a, b), (-a, b)].map(|(u, v)| [x + c * u - s * v, y + s * u + c * v])
    }

    /// The world box and parts with the box centre at (x, y, z) and heading `yaw`.
    pub(crate) fn placed(&self, x: f64, y: f64, z: f64, yaw: f64) -> (Shape, Vec<Part>) {
        let bbox = Shape::cuboid([x, y, z], self.size, yaw);
        let parts = self.parts.iter().map(|p| Part { shape: p.shape.transformed(x, y, z, yaw), ..*p }).collect();
        (bbox, parts)
    }
}

/// An ISO shipping container, 20 ft or 40 ft, standing on corner blocks.
pub(crate) fn container(rng: &mut impl Rng, forty_ft: bool) -> Asset {
    let len = if forty_ft { 12.19 } else { 6.06 };
    let refl = [0.2, 0.35, 0.5][rng.random_range(0..3)];
    let mut parts = vec![slab([0.0, 0.0], 0.1, [len, 2.44, 2.49], label::OTHER_STRUCTURE, refl)];
    for (x, y) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
        parts.push(slab([x * (len / 2.0 - 0.2), y * 1.0], 0.0, [0.4, 0.4, 0.1], label::OTHER_STRUCTURE, 0.5));
    }
    Asset::fitted("container", label::OTHER_STRUCTURE, parts)
}

/// A site office cabin, optionally two high with an outside stair.
pub(crate) fn office_cabin(stacked: bool) -> Asset {
    let l = label::BUILDING;
    let mut parts = vec![slab([0.0, 0.0], 0.15, [6.06, 2.44, 2.7], l, 0.7)];
    for (x, y) in [(-2.8, -1.0), (2.8, -1.0), (2.8, 1.0), (-2.8, 1.0)] {
        parts.push(slab([x, y], 0.0, [0.3, 0.3, 0.15], l, 0.5));
    }
    if stacked {
        parts.push(slab([0.0, 0.0], 2.85, [6.06, 2.44, 2.7], l, 0.7));
        for k in 0..4 {
            let x = -2.0 + 0.9 * k as f64;
            parts.push(slab([x, 1.82], 0.0, [0.9, 1.0, 0.7 * (k + 1) as f64], l, 0.4));
        }
    }
    Asset::fitted("site_office", l, parts)
}

/// Euro pallets with loads (cement bags, blocks, boxes), 1-3 × 1-2.
pub(crate) fn pallet_stack(rng: &mut impl Rng) -> Asset {
    let (nx, ny) = (rng.random_range(1..=3), rng.random_range(1..=2));
    let refl = rng.random_range(0.3..0.6);
    let mut parts = Vec::new();
    for i in 0..nx {
        for j in 0..ny {
            let c = [i as f64 * 1.35, j as f64 * 1.15];
            parts.push(slab(c, 0.0, [1.2, 1.0, 0.14], label::OTHER_OBJECT, 0.45));
            parts.push(slab(c, 0.14, [1.15, 0.95, rng.random_range(0.3..1.3)], label::OTHER_OBJECT, refl));
        }
    }
    Asset::fitted("pallet_stack", label::OTHER_OBJECT, parts)
}

/// Rebar bundles, 6-12 m long, on timber bearers.
pub(crate) fn rebar_bundle(rng: &mut impl Rng) -> Asset {
    let len = rng.random_range(6.0..12.0);
    let n = rng.random_range(2..=4);
    let width = n as f64 * 0.4 - 0.1;
    let mut parts = Vec::new();
    for x in [-len / 2.0 + 0.5, 0.0, len / 2.0 - 0.5] {
        parts.push(slab([x, 0.0], 0.0, [0.1, width + 0.2, 0.1], label::OTHER_OBJECT, 0.45));
    }
    for k in 0..n {
        let y = -width / 2.0 + 0.15 + 0.4 * k as f64;
        parts.push(slab([0.0, y], 0.1, [len, 0.3, 0.22], label::OTHER_OBJECT, 0.22));
    }
    Asset::fitted("rebar_bundle", label::OTHER_OBJECT, parts)
}

/// A stack of sawn timber or formwork panels on bearers.
pub(crate) fn timber_stack(rng: &mut impl Rng) -> Asset {
    let formwork = rng.random_bool(0.5);
    let (size, refl, class) =
        if formwork { ([2.7, 1.35], 0.55, "formwork_stack") } else { ([4.8, 1.2], 0.48, "timber_stack") };
    let h = rng.random_range(0.4..1.5);
    let mut parts = vec![slab([0.0, 0.0], 0.1, [size[0], size[1], h], label::OTHER_OBJECT, refl)];
    for x in [-size[0] / 2.0 + 0.3, size[0] / 2.0 - 0.3] {
        parts.push(slab([x, 0.0], 0.0, [0.1, size[1], 0.1], label::OTHER_OBJECT, 0.45));
    }
    Asset::fitted(class, label::OTHER_OBJECT, parts)
}

/// A pyramid of pipes (as square sections), 6 m long.
pub(crate) fn pipe_stack(rng: &mut impl Rng) -> Asset {
    let n = rng.random_range(4..=6);
    let mut parts = Vec::new();
    for layer in 0..3.min(n) {
        for k in 0..n - layer {
            let y = (k as f64 - (n - layer - 1) as f64 / 2.0) * 0.35;
            parts.push(slab([0.0, y], layer as f64 * 0.3, [6.0, 0.3, 0.3], label::OTHER_OBJECT, 0.25));
        }
    }
    Asset::fitted("pipe_stack", label::OTHER_OBJECT, parts)
}

/// An open-top skip (dumpster): a floor and four thin walls.
pub(crate) fn skip_bin() -> Asset {
    let (l, w, h, t) = (3.6, 1.8, 1.6, 0.08);
    let o = label::OTHER_OBJECT;
    let parts = vec![
        slab([0.0, 0.0], 0.0, [l, w, 0.1], o, 0.3),
        slab([0.0, (w - t) / 2.0], 0.1, [l, t, h - 0.1], o, 0.3),
        slab([0.0, -(w - t) / 2.0], 0.1, [l, t, h - 0.1], o, 0.3),
        slab([(l - t) / 2.0, 0.0], 0.1, [t, w - 2.0 * t, h - 0.1], o, 0.3),
        slab([-(l - t) / 2.0, 0.0], 0.1, [t, w - 2.0 * t, h - 0.1], o, 0.3),
    ];
    Asset::fitted("skip", o, parts)
}

/// A gravel or soil stockpile.
pub(crate) fn stockpile(radius: f64, height: f64) -> Asset {
    let shape = Shape::dome([0.0, 0.0, 0.0], radius, height);
    let part = Part { shape, label: label::TERRAIN, reflectivity: 0.28, surface: Surface::Solid };
    Asset::fitted("stockpile", label::TERRAIN, vec![part])
}

/// A generator or compressor on a skid.
pub(crate) fn generator() -> Asset {
    let o = label::OTHER_OBJECT;
    let parts = vec![
        slab([0.0, 0.0], 0.0, [3.0, 1.1, 0.1], o, 0.3),
        slab([0.0, 0.0], 0.1, [2.9, 1.2, 1.5], o, 0.55),
        post([1.0, 0.3], 1.6, 0.06, 0.5, o, 0.2),
    ];
    Asset::fitted("generator", o, parts)
}

/// A row of concrete jersey barriers.
pub(crate) fn barrier_row(rng: &mut impl Rng) -> Asset {
    let n = rng.random_range(3..=6);
    let mut parts = Vec::new();
    for k in 0..n {
        let x = k as f64 * 2.05;
        parts.push(slab([x, 0.0], 0.0, [2.0, 0.6, 0.3], label::OTHER_OBJECT, 0.6));
        parts.push(slab([x, 0.0], 0.3, [2.0, 0.25, 0.5], label::OTHER_OBJECT, 0.6));
    }
    Asset::fitted("barrier_row", label::OTHER_OBJECT, parts)
}

/// A portable toilet.
pub(crate) fn toilet() -> Asset {
    Asset::fitted(
        "toilet",
        label::OTHER_OBJECT,
        vec![slab([0.0, 0.0], 0.0, [1.1, 1.1, 2.3], label::OTHER_OBJECT, 0.45)],
    )
}

/// A parked car or van: wheels, body and cabin.
pub(crate) fn parked_car(rng: &mut impl Rng) -> Asset {
    let van = rng.random_bool(0.3);
    let (len, h_cab) = if van { (5.2, 1.1) } else { (4.5, 0.55) };
    let refl = [0.12, 0.35, 0.7][rng.random_range(0..3)];
    let c = label::CAR;
    let mut parts = vec![
        slab([0.0, 0.0], 0.3, [len, 1.8, 0.75], c, refl),
        slab([if van { -0.4 } else { -0.3 }, 0.0], 1.05, [len * 0.55, 1.65, h_cab], c, refl),
    ];
    for (x, y) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
        parts.push(slab([x * (len / 2.0 - 0.8), y * 0.79], 0.0, [0.66, 0.22, 0.66], c, 0.08));
    }
    Asset::fitted(if van { "parked_van" } else { "parked_car" }, c, parts)
}

/// A tree: trunk and a porous canopy.
pub(crate) fn tree(rng: &mut impl Rng) -> Asset {
    let (r, h) = (rng.random_range(0.12..0.25), rng.random_range(2.0..3.5));
    let (cr, cz) = (rng.random_range(1.5..3.0), rng.random_range(1.5..3.0));
    let canopy = Part {
        shape: Shape::ellipsoid([0.0, 0.0, h + 0.7 * cz], cr, cz),
        label: label::VEGETATION,
        reflectivity: 0.5,
        surface: Surface::Foliage { extinction_per_m: rng.random_range(0.8..1.5) },
    };
    Asset::fitted("tree", label::VEGETATION, vec![post([0.0, 0.0], 0.0, r, h + cz, label::TRUNK, 0.3), canopy])
}

/// A lighting mast with its lamp head.
pub(crate) fn light_pole() -> Asset {
    let p = label::POLE;
    Asset::fitted(
        "light_pole",
        p,
        vec![post([0.0, 0.0], 0.0, 0.09, 8.0, p, 0.55), slab([0.35, 0.0], 7.85, [0.7, 0.3, 0.15], p, 0.6)],
    )
}

/// A tower crane's concrete base and lattice mast (four chords and rungs).
pub(crate) fn crane() -> Asset {
    let s = label::OTHER_STRUCTURE;
    let mut parts =
        vec![slab([0.0, 0.0], 0.0, [6.0, 6.0, 1.5], s, 0.5), slab([0.0, 0.0], 28.0, [2.4, 2.4, 2.0], s, 0.6)];
    for (x, y) in [(-0.9, -0.9), (0.9, -0.9), (0.9, 0.9), (-0.9, 0.9)] {
        parts.push(post([x, y], 1.5, 0.1, 26.5, s, 0.6));
    }
    for k in 1..9 {
        let z = 1.5 + 3.0 * k as f64;
        parts.push(slab([0.0, -0.9], z, [1.8, 0.08, 0.08], s, 0.6));
        parts.push(slab([0.0, 0.9], z, [1.8, 0.08, 0.08], s, 0.6));
        parts.push(slab([-0.9, 0.0], z, [0.08, 1.8, 0.08], s, 0.6));
        parts.push(slab([0.9, 0.0], z, [0.08, 1.8, 0.08], s, 0.6));
    }
    Asset::fitted("crane", s, parts)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn fitted_assets_stand_on_their_box_bottom() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(2);
        for a in [container(&mut rng, true), pallet_stack(&mut rng), tree(&mut rng), stockpile(3.0, 1.5), crane()] {
            let lowest = a.parts.iter().map(|p| p.shape.z_range().0).fold(f64::INFINITY, f64::min);
            assert!((lowest + a.size[2] / 2.0).abs() < 1e-9, "{}", a.class);
        }
    }
}
