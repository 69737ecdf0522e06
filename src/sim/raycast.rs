//! Ray casting against the site of one session.
//!
//! The acceleration structure is the ground's 1 m grid: every cell lists the
//! primitives whose x-y bounds overlap it and the highest z of anything in it.
//! A ray walks the cells it crosses in x-y (Amanatides-Woo), skipping a cell
//! outright when it passes above everything in it, testing the ground
//! triangles and the listed primitives otherwise, and stops at the first cell
//! that ends beyond its nearest hit. A primitive is only tested in a cell when
//! the ray's height range there overlaps the primitive's: the hit point lies
//! in some cell that lists the primitive, and there the ranges overlap, so the
//! test is exact. Movers are few and change every keyframe; they are tested
//! per ray against bounding spheres first and are not in the grid.

use super::assets::{Part, Surface};
use super::ground::{CELL_M, GRID_CELLS, GRID_MIN, Ground};
use super::seeds::{mix, unit};
use super::shapes::Shape;

/// The key of part `part` of object `id`: distinct for every primitive.
pub(crate) fn prim_key(id: u32, part: usize) -> u64 {
    (u64::from(id) << 32) | part as u64
}

/// A primitive ready for ray tests.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Prim {
    shape: Shape,
    cos: f64,
    sin: f64,
    z_lo: f64,
    z_hi: f64,
    /// Bounding sphere, for movers' cheap rejection.
    sphere: [f64; 4],
    label: u16,
    instance: u16,
    reflectivity: f32,
    surface: Surface,
    /// Distinct per primitive, for per-ray "does it pass the mesh" hashes.
    key: u64,
}

impl Prim {
    pub(crate) fn new(part: &Part, instance: u16, key: u64) -> Prim {
        let s = part.shape;
        let (z_lo, z_hi) = s.z_range();
        let r = 0.5 * (s.size[0] * s.size[0] + s.size[1] * s.size[1] + s.size[2] * s.size[2]).sqrt();
        Prim {
            shape: s,
            cos: s.yaw.cos(),
            sin: s.yaw.sin(),
            z_lo,
            z_hi,
            sphere: [s.center[0], s.center[1], s.center[2], r],
            label: part.label,
            instance,
            reflectivity: part.reflectivity,
            surface: part.surface,
            key: mix(key),
        }
    }

    /// Does the ray pass within the bounding sphere ahead of its origin?
    fn may_hit(&self, o: [f64; 3], d: [f64; 3], t_max: f64) -> bool {
        let oc = [self.sphere[0] - o[0], self.sphere[1] - o[1], self.sphere[2] - o[2]];
        let tca = oc[0] * d[0] + oc[1] * d[1] + oc[2] * d[2];
        let r = self.sphere[3];
        if tca < -r || tca - r > t_max {
            return false;
        }
        oc[0] * oc[0] + oc[1] * oc[1] + oc[2] * oc[2] - tca * tca <= r * r
    }

    /// The nearest return from this primitive before `best_t`, if any.
    fn hit(&self, o: [f64; 3], d: [f64; 3], best_t: f64, ray: u64) -> Option<Hit> {
        let sp = self.shape.intersect_rotated(o, d, self.cos, self.sin)?;
        if sp.t_out <= 0.0 || sp.t_in >= best_t {
            return None;
        }
        let u = unit(ray ^ self.key);
        let (t, cos_override) = match self.surface {
            Surface::Solid if sp.t_in > 0.0 => (sp.t_in, None),
            Surface::Solid => return None, // the ray starts inside: no return
            Surface::Mesh { pass } if sp.t_in > 0.0 && u >= pass as f64 => (sp.t_in, None),
            Surface::Mesh { .. } => return None,
            Surface::Foliage { extinction_per_m } => {
                // Exponential free path through the leaves; leaves face any way.
                let t = sp.t_in.max(0.0) - (1.0 - u).ln() / extinction_per_m as f64;
                if t >= sp.t_out {
                    return None;
                }
                (t, Some(0.2 + 0.8 * unit(ray ^ self.key ^ 0xF01A6E)))
            }
        };
        (t < best_t).then_some(Hit {
            t,
            normal: sp.normal,
            cos_override,
            label: self.label,
            instance: self.instance,
            reflectivity: self.reflectivity,
        })
    }
}

/// The first surface a ray meets.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Hit {
    pub t: f64,
    pub normal: [f64; 3],
    /// For foliage: the cosine of incidence (leaves have no single normal).
    pub cos_override: Option<f64>,
    pub label: u16,
    /// Object id (0 for the ground).
    pub instance: u16,
    pub reflectivity: f32,
}

/// The static scene of one session, gridded.
pub(crate) struct Scene<'a> {
    ground: &'a Ground,
    prims: Vec<Prim>,
    cell_start: Vec<u32>,
    cell_items: Vec<u32>,
    /// Highest z of ground or primitive in the cell.
    cell_top: Vec<f32>,
    z_min: f64,
    z_max: f64,
}

impl<'a> Scene<'a> {
    /// Grids `prims` (static primitives) over `ground`.
    pub(crate) fn new(ground: &'a Ground, prims: Vec<Prim>) -> Scene<'a> {
        let [nx, ny] = GRID_CELLS;
        let cells_of = |p: &Prim| {
            let b = p.shape.xy_bounds();
            let (i0, j0) = Ground::cell_of(b[0], b[1]);
            let (i1, j1) = Ground::cell_of(b[2], b[3]);
            (i0, j0, i1, j1)
        };
        let mut count = vec![0u32; nx * ny + 1];
        let mut cell_top = vec![f32::NEG_INFINITY; nx * ny];
        let (mut z_min, mut z_max) = (f64::INFINITY, f64::NEG_INFINITY);
        for j in 0..ny {
            for i in 0..nx {
                let h = ground.corners(i, j);
                let top = h.iter().fold(f64::NEG_INFINITY, |a, &b| a.max(b));
                cell_top[j * nx + i] = top as f32 + 1e-4;
                z_max = z_max.max(top);
                z_min = z_min.min(h.iter().fold(f64::INFINITY, |a, &b| a.min(b)));
            }
        }
        for p in &prims {
            let (i0, j0, i1, j1) = cells_of(p);
            for j in j0..=j1 {
                for i in i0..=i1 {
                    count[j * nx + i] += 1;
                    let top = &mut cell_top[j * nx + i];
                    *top = top.max(p.z_hi as f32 + 1e-4);
                }
            }
            z_max = z_max.max(p.z_hi);
        }
        let mut cell_start = vec![0u32; nx * ny + 1];
        for c in 0..nx * ny {
            cell_start[c + 1] = cell_start[c] + count[c];
        }
        let mut fill = cell_start.clone();
        let mut cell_items = vec![0u32; cell_start[nx * ny] as usize];
        for (k, p) in prims.iter().enumerate() {
            let (i0, j0, i1, j1) = cells_of(p);
            for j in j0..=j1 {
                for i in i0..=i1 {
                    cell_items[fill[j * nx + i] as usize] = k as u32;
                    fill[j * nx + i] += 1;
                }
            }
        }
        Scene { ground, prims, cell_start, cell_items, cell_top, z_min: z_min - 0.1, z_max: z_max + 0.1 }
    }

    /// The first hit of the ray `o + t d` (`d` unit, `o` inside the grid) up to
    /// `t_max`, against the scene and the `movers`; `ray` keys the per-ray
    /// random decisions (mesh, foliage).
    pub(crate) fn cast(&self, o: [f64; 3], d: [f64; 3], t_max: f64, ray: u64, movers: &[Prim]) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        let mut best_t = t_max;
        for m in movers {
            if m.may_hit(o, d, best_t)
                && let Some(h) = m.hit(o, d, best_t, ray)
            {
                best_t = h.t;
                best = Some(h);
            }
        }
        // Leave the slab of heights that holds anything, and the grid.
        let mut t_end = best_t;
        if d[2] > 1e-12 {
            t_end = t_end.min((self.z_max - o[2]) / d[2]);
        } else if d[2] < -1e-12 {
            t_end = t_end.min((self.z_min - o[2]) / d[2]);
        }
        let [nx, ny] = GRID_CELLS;
        let fx = (o[0] - GRID_MIN[0]) / CELL_M;
        let fy = (o[1] - GRID_MIN[1]) / CELL_M;
        if fx < 0.0 || fy < 0.0 || fx >= nx as f64 || fy >= ny as f64 {
            return best;
        }
        let (mut i, mut j) = (fx as usize, fy as usize);
        let axis = |f: f64, dd: f64, idx: usize| -> (f64, f64) {
            if dd > 1e-12 {
                (((idx + 1) as f64 - f) * CELL_M / dd, CELL_M / dd)
            } else if dd < -1e-12 {
                ((idx as f64 - f) * CELL_M / dd, -CELL_M / dd)
            } else {
                (f64::INFINITY, f64::INFINITY)
            }
        };
        let (mut tx, dtx) = axis(fx, d[0], i);
        let (mut ty, dty) = axis(fy, d[1], j);
        let mut t0 = 0.0;
        while t0 < t_end {
            let t1 = tx.min(ty).min(t_end);
            let c = j * nx + i;
            let z_low = o[2] + d[2] * if d[2] > 0.0 { t0 } else { t1 };
            if z_low <= self.cell_top[c] as f64 {
                let z_high = o[2] + d[2] * if d[2] > 0.0 { t1 } else { t0 };
                if let Some((t, normal)) = self.ground.intersect_cell(i, j, o, d, t0, t1)
                    && t < best_t
                {
                    let (label, reflectivity) = self.ground.surface(i, j);
                    best_t = t;
                    best = Some(Hit { t, normal, cos_override: None, label, instance: 0, reflectivity });
                }
                for &k in &self.cell_items[self.cell_start[c] as usize..self.cell_start[c + 1] as usize] {
                    let p = &self.prims[k as usize];
                    if p.z_hi < z_low || p.z_lo > z_high {
                        continue;
                    }
                    if let Some(h) = p.hit(o, d, best_t, ray) {
                        best_t = h.t;
                        best = Some(h);
                    }
                }
            }
            if best_t <= t1 {
                break;
            }
            if tx < ty {
                i = match (d[0] > 0.0, i) {
                    (true, i) if i + 1 < nx => i + 1,
                    (false, i) if i > 0 => i - 1,
                    _ => break,
                };
                t0 = tx;
                tx += dtx;
            } else {
                j = match (d[1] > 0.0, j) {
                    (true, j) if j + 1 < ny => j + 1,
                    (false, j) if j > 0 => j - 1,
                    _ => break,
                };
                t0 = ty;
                ty += dty;
            }
        }
        best
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::assets::label;
    use crate::sim::seeds::gauss;

    fn part(shape: Shape) -> Part {
        Part { shape, label: label::OTHER_OBJECT, reflectivity: 0.5, surface: Surface::Solid }
    }

    /// The slow reference: every primitive and every ground cell on the way.
    fn brute(scene: &Scene, o: [f64; 3], d: [f64; 3], t_max: f64) -> Option<f64> {
        let mut best = t_max;
        for p in &scene.prims {
            if let Some(h) = p.hit(o, d, best, 0) {
                best = h.t;
            }
        }
        let [nx, ny] = GRID_CELLS;
        for j in 0..ny {
            for i in 0..nx {
                if let Some((t, _)) = scene.ground.intersect_cell(i, j, o, d, 0.0, f64::INFINITY) {
                    // Only hits that really are in the cell count.
                    let x = o[0] + t * d[0];
                    let y = o[1] + t * d[1];
                    if Ground::cell_of(x, y) == (i, j) && t < best {
                        best = t;
                    }
                }
            }
        }
        (best < t_max).then_some(best)
    }

    #[test]
    fn grid_walk_finds_the_same_first_hit_as_brute_force() {
        let ground = Ground::new(5, |_, _| false);
        let mut prims = Vec::new();
        for k in 0..60u64 {
            let c = [40.0 * (unit(k) - 0.5), 40.0 * (unit(k + 100) - 0.5)];
            let z = ground.height_at(c[0], c[1]);
            let shape = match k % 3 {
                0 => Shape::cuboid([c[0], c[1], z + 1.0], [3.0 * unit(k + 7) + 0.1, 0.5, 2.0], unit(k + 8) * 3.0),
                1 => Shape::cylinder([c[0], c[1], z], 0.05 + unit(k + 9) * 0.5, 4.0),
                _ => Shape::ellipsoid([c[0], c[1], z + 3.0], 1.5, 1.0),
            };
            prims.push(Prim::new(&part(shape), k as u16 + 1, k));
        }
        let scene = Scene::new(&ground, prims);
        let o = [0.3, -0.2, ground.height_at(0.3, -0.2) + 1.8];
        let mut hits = 0;
        for r in 0..400u64 {
            let d = [gauss(r), gauss(r + 1000), 0.4 * gauss(r + 2000) - 0.1];
            let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            let d = [d[0] / n, d[1] / n, d[2] / n];
            let fast = scene.cast(o, d, 60.0, 0, &[]).map(|h| h.t);
            let slow = brute(&scene, o, d, 60.0);
            match (fast, slow) {
                (Some(a), Some(b)) => {
                    hits += 1;
                    assert!((a - b).abs() < 1e-6, "ray {r}: grid {a} brute {b}");
                }
                (None, None) => {}
                other => panic!("ray {r}: {other:?}"),
            }
        }
        assert!(hits > 200, "{hits}");
    }

    #[test]
    fn movers_occlude_and_mesh_lets_some_rays_through() {
        let ground = Ground::new(6, |_, _| false);
        let z = ground.height_at(5.0, 0.0);
        let mesh = Part {
            surface: Surface::Mesh { pass: 0.6 },
            ..part(Shape::cuboid([5.0, 0.0, z + 1.0], [0.04, 20.0, 2.0], 0.0))
        };
        let scene = Scene::new(&ground, vec![Prim::new(&mesh, 1, 1)]);
        let o = [0.0, 0.0, z + 1.0];
        let through = (0..2000u64)
            .filter(|&r| scene.cast(o, [1.0, 0.0, 0.0], 100.0, r, &[]).is_none_or(|h| h.instance != 1))
            .count();
        assert!((1000..1400).contains(&through), "{through} of 2000 passed a 60 % mesh");
        let mover = Prim::new(&part(Shape::cuboid([3.0, 0.0, z + 1.0], [0.5, 0.5, 1.8], 0.0)), 7, 9);
        let h = scene.cast(o, [1.0, 0.0, 0.0], 100.0, 0, &[mover]).unwrap();
        assert_eq!(h.instance, 7);
        assert!((h.t - 2.75).abs() < 1e-9);
    }
}
