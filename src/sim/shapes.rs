//! The solid primitives the site is built of, with ray intersection and
//! point containment.
//!
//! Every shape is described by its bounding box in a yaw-rotated frame
//! (`center`, full `size` = length × width × height, `yaw` about +z), which is
//! also how `primitives.csv` stores it:
//!
//! | kind | inside its box |
//! |---|---|
//! | `box` | the whole box |
//! | `cylinder` | the vertical cylinder of diameter `size[0]` |
//! | `ellipsoid` | the ellipsoid with semi-axes `size / 2` |
//! | `dome` | the upper half-ellipsoid standing on the box's bottom face (stockpiles) |
//!
//! Cylinders, ellipsoids and domes are round in x-y (`size[0] == size[1]`).

/// The kind of a primitive.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ShapeKind {
    Box,
    Cylinder,
    Ellipsoid,
    Dome,
}

impl ShapeKind {
    pub fn name(self) -> &'static str {
        match self {
            ShapeKind::Box => "box",
            ShapeKind::Cylinder => "cylinder",
            ShapeKind::Ellipsoid => "ellipsoid",
            ShapeKind::Dome => "dome",
        }
    }

    pub fn parse(s: &str) -> Option<ShapeKind> {
        [ShapeKind::Box, ShapeKind::Cylinder, ShapeKind::Ellipsoid, ShapeKind::Dome].into_iter().find(|k| k.name() == s)
    }
}

/// A primitive in the world (or, for a mover, its body) frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Shape {
    pub kind: ShapeKind,
    /// Centre of the bounding box, m.
    pub center: [f64; 3],
    /// Full extents of the bounding box along its own x, y, z, m.
    pub size: [f64; 3],
    /// Rotation of the box about +z, rad.
    pub yaw: f64,
}

/// Where a ray enters and leaves a shape, and the outward normal at entry.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Span {
    pub t_in: f64,
    pub t_out: f64,
    pub normal: [f64; 3],
}

impl Shape {
    pub fn cuboid(center: [f64; 3], size: [f64; 3], yaw: f64) -> Shape {
        Shape { kind: ShapeKind::Box, center, size, yaw }
    }

    /// A vertical cylinder standing on `base` (x, y, bottom z).
    pub fn cylinder(base: [f64; 3], radius: f64, height: f64) -> Shape {
        let center = [base[0], base[1], base[2] + height / 2.0];
        Shape { kind: ShapeKind::Cylinder, center, size: [2.0 * radius, 2.0 * radius, height], yaw: 0.0 }
    }

    pub fn ellipsoid(center: [f64; 3], radius_xy: f64, radius_z: f64) -> Shape {
        Shape { kind: ShapeKind::Ellipsoid, center, size: [2.0 * radius_xy, 2.0 * radius_xy, 2.0 * radius_z], yaw: 0.0 }
    }

    /// A half-ellipsoid standing on `base` (x, y, bottom z).
    pub fn dome(base: [f64; 3], radius_xy: f64, height: f64) -> Shape {
        let center = [base[0], base[1], base[2] + height / 2.0];
        Shape { kind: ShapeKind::Dome, center, size: [2.0 * radius_xy, 2.0 * radius_xy, height], yaw: 0.0 }
    }

    /// The same shape moved by a planar pose (`x`, `y`, `z`, `yaw`) of its frame.
    pub fn transformed(&self, x: f64, y: f64, z: f64, yaw: f64) -> Shape {
        let (s, c) = yaw.sin_cos();
        let [px, py, pz] = self.center;
        Shape { center: [x + c * px - s * py, y + s * px + c * py, z + pz], yaw: self.yaw + yaw, ..*self }
    }

    /// Lowest and highest z of the shape.
    pub fn z_range(&self) -> (f64, f64) {
        (self.center[2] - self.size[2] / 2.0, self.center[2] + self.size[2] / 2.0)
    }

    /// Axis-aligned bounds in x-y: `[x_min, y_min, x_max, y_max]`.
    pub fn xy_bounds(&self) -> [f64; 4] {
        let [cx, cy, _] = self.center;
        let (hx, hy) = match self.kind {
            ShapeKind::Box => {
                let (s, c) = self.yaw.sin_cos();
                let (a, b) = (self.size[0] / 2.0, self.size[1] / 2.0);
                (a * c.abs() + b * s.abs(), a * s.abs() + b * c.abs())
            }
            _ => (self.size[0] / 2.0, self.size[0] / 2.0),
        };
        [cx - hx, cy - hy, cx + hx, cy + hy]
    }

    /// `p` in the shape's frame: relative to its centre, un-rotated.
    fn local_point(&self, p: [f64; 3]) -> [f64; 3] {
        let (s, c) = self.yaw.sin_cos();
        let (dx, dy) = (p[0] - self.center[0], p[1] - self.center[1]);
        [c * dx + s * dy, -s * dx + c * dy, p[2] - self.center[2]]
    }

    /// True when `p` is inside the shape grown by `margin_m` (shrunk if negative).
    pub fn contains(&self, p: [f64; 3], margin_m: f64) -> bool {
        let [x, y, z] = self.local_point(p);
        let [hx, hy, hz] = [self.size[0] / 2.0, self.size[1] / 2.0, self.size[2] / 2.0];
        let m = margin_m;
        match self.kind {
            ShapeKind::Box => x.abs() <= hx + m && y.abs() <= hy + m && z.abs() <= hz + m,
            ShapeKind::Cylinder => hx + m > 0.0 && x * x + y * y <= (hx + m).powi(2) && z.abs() <= hz + m,
            ShapeKind::Ellipsoid => {
                let (a, c) = (hx + m, hz + m);
                a > 0.0 && c > 0.0 && (x / a).powi(2) + (y / a).powi(2) + (z / c).powi(2) <= 1.0
            }
            ShapeKind::Dome => {
                let (a, c, zb) = (hx + m, 2.0 * hz + m, z + hz);
                a > 0.0 && c > 0.0 && zb >= -m && (x / a).powi(2) + (y / a).powi(2) + (zb.max(0.0) / c).powi(2) <= 1.0
            }
        }
    }

    /// The ray `o + t d` (`d` need not be unit) against the shape.
    #[cfg(test)]
    pub(crate) fn intersect(&self, o: [f64; 3], d: [f64; 3]) -> Option<Span> {
        let (s, c) = self.yaw.sin_cos();
        self.intersect_rotated(o, d, c, s)
    }

    /// [`Shape::intersect`] with `cos(yaw)`, `sin(yaw)` precomputed.
    pub(crate) fn intersect_rotated(&self, o: [f64; 3], d: [f64; 3], c: f64, s: f64) -> Option<Span> {
        let (dx, dy) = (o[0] - self.center[0], o[1] - self.center[1]);
        let ol = [c * dx + s * dy, -s * dx + c * dy, o[2] - self.center[2]];
        let dl = [c * d[0] + s * d[1], -s * d[0] + c * d[1], d[2]];
        let h = [self.size[0] / 2.0, self.size[1] / 2.0, self.size[2] / 2.0];
        let (t_in, t_out, n) = match self.kind {
            ShapeKind::Box => slab_box(ol, dl, h)?,
            ShapeKind::Cylinder => cylinder(ol, dl, h[0], h[2])?,
            ShapeKind::Ellipsoid => ellipsoid(ol, dl, h[0], h[2])?,
            ShapeKind::Dome => dome(ol, dl, h[0], h[2])?,
        };
        // Back to the world frame: rotate the normal by +yaw.
        let normal = [c * n[0] - s * n[1], s * n[0] + c * n[1], n[2]];
        Some(Span { t_in, t_out, normal })
    }
}

/// The interval of `o + t d` inside `|x| ≤ h` along one axis, or None.
fn slab(o: f64, d: f64, h: f64) -> Option<(f64, f64)> {
    if d.abs() < 1e-15 {
        return (o.abs() <= h).then_some((f64::NEG_INFINITY, f64::INFINITY));
    }
    let (a, b) = ((-h - o) / d, (h - o) / d);
    Some(if a < b { (a, b) } else { (b, a) })
}

fn slab_box(o: [f64; 3], d: [f64; 3], h: [f64; 3]) -> Option<(f64, f64, [f64; 3])> {
    let (mut t_in, mut t_out, mut axis) = (f64::NEG_INFINITY, f64::INFINITY, 0);
    for i in 0..3 {
        let (a, b) = slab(o[i], d[i], h[i])?;
        if a > t_in {
            t_in = a;
            axis = i;
        }
        t_out = t_out.min(b);
    }
    if t_in > t_out {
        return None;
    }
    let mut n = [0.0; 3];
    n[axis] = -d[axis].signum();
    Some((t_in, t_out, n))
}

/// Roots of `a t² + b t + c = 0` as an ordered interval, or None.
fn quadratic(a: f64, b: f64, c: f64) -> Option<(f64, f64)> {
    let disc = b * b - 4.0 * a * c;
    if disc < 0.0 {
        return None;
    }
    let q = -0.5 * (b + b.signum() * disc.sqrt());
    let (r1, r2) = (q / a, if q != 0.0 { c / q } else { -b / (2.0 * a) });
    Some(if r1 < r2 { (r1, r2) } else { (r2, r1) })
}

fn cylinder(o: [f64; 3], d: [f64; 3], r: f64, hz: f64) -> Option<(f64, f64, [f64; 3])> {
    let a = d[0] * d[0] + d[1] * d[1];
    let cc = o[0] * o[0] + o[1] * o[1] - r * r;
    let (s_in, s_out) = if a < 1e-24 {
        if cc > 0.0 {
            return None;
        }
        (f64::NEG_INFINITY, f64::INFINITY)
    } else {
        quadratic(a, 2.0 * (o[0] * d[0] + o[1] * d[1]), cc)?
    };
    let (z_in, z_out) = slab(o[2], d[2], hz)?;
    let (t_in, t_out) = (s_in.max(z_in), s_out.min(z_out));
    if t_in > t_out {
        return None;
    }
    let n = if s_in >= z_in {
        [(o[0] + t_in * d[0]) / r, (o[1] + t_in * d[1]) / r, 0.0]
    } else {
        [0.0, 0.0, -d[2].signum()]
    };
    Some((t_in, t_out, n))
}

/// The ellipsoid with semi-axes (a, a, c) centred at the origin.
fn ellipsoid_interval(o: [f64; 3], d: [f64; 3], a: f64, c: f64) -> Option<(f64, f64)> {
    let os = [o[0] / a, o[1] / a, o[2] / c];
    let ds = [d[0] / a, d[1] / a, d[2] / c];
    let qa = ds[0] * ds[0] + ds[1] * ds[1] + ds[2] * ds[2];
    let qb = 2.0 * (os[0] * ds[0] + os[1] * ds[1] + os[2] * ds[2]);
    let qc = os[0] * os[0] + os[1] * os[1] + os[2] * os[2] - 1.0;
    quadratic(qa, qb, qc)
}

fn ellipsoid_normal(p: [f64; 3], a: f64, c: f64) -> [f64; 3] {
    let g = [p[0] / (a * a), p[1] / (a * a), p[2] / (c * c)];
    let n = (g[0] * g[0] + g[1] * g[1] + g[2] * g[2]).sqrt().max(1e-300);
    [g[0] / n, g[1] / n, g[2] / n]
}

fn ellipsoid(o: [f64; 3], d: [f64; 3], a: f64, c: f64) -> Option<(f64, f64, [f64; 3])> {
    let (t_in, t_out) = ellipsoid_interval(o, d, a, c)?;
    let p = [o[0] + t_in * d[0], o[1] + t_in * d[1], o[2] + t_in * d[2]];
    Some((t_in, t_out, ellipsoid_normal(p, a, c)))
}

/// Upper half of the ellipsoid (a, a, 2 hz) centred on the box's bottom face.
fn dome(o: [f64; 3], d: [f64; 3], a: f64, hz: f64) -> Option<(f64, f64, [f64; 3])> {
    let ob = [o[0], o[1], o[2] + hz];
    let (e_in, e_out) = ellipsoid_interval(ob, d, a, 2.0 * hz)?;
    let (h_in, h_out) = if d[2].abs() < 1e-15 {
        if ob[2] < 0.0 {
            return None;
        }
        (f64::NEG_INFINITY, f64::INFINITY)
    } else if d[2] > 0.0 {
        (-ob[2] / d[2], f64::INFINITY)
    } else {
        (f64::NEG_INFINITY, -ob[2] / d[2])
    };
    let (t_in, t_out) = (e_in.max(h_in), e_out.min(h_out));
    if t_in > t_out {
        return None;
    }
    let n = if h_in > e_in {
        [0.0, 0.0, -1.0]
    } else {
        ellipsoid_normal([ob[0] + t_in * d[0], ob[1] + t_in * d[1], ob[2] + t_in * d[2]], a, 2.0 * hz)
    };
    Some((t_in, t_out, n))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::seeds::{gauss, unit};

    fn shapes() -> Vec<Shape> {
        vec![
            Shape::cuboid([1.0, 2.0, 0.5], [3.0, 1.0, 2.0], 0.7),
            Shape::cylinder([-1.0, 0.5, -0.5], 0.4, 2.5),
            Shape::ellipsoid([0.5, -1.0, 1.0], 1.5, 0.8),
            Shape::dome([0.0, 0.0, -0.2], 2.0, 1.2),
        ]
    }

    /// First `t` at which the ray is inside, by marching (the slow reference).
    fn march(s: &Shape, o: [f64; 3], d: [f64; 3]) -> Option<f64> {
        let step = 1e-3;
        (0..12_000)
            .map(|i| i as f64 * step)
            .find(|&t| s.contains([o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2]], 0.0))
    }

    #[test]
    fn intersection_agrees_with_marching_reference() {
        let mut hits = 0;
        for (k, s) in shapes().iter().enumerate() {
            for i in 0..300u64 {
                let key = (k as u64) << 32 | i;
                let o = [6.0 * (unit(key) - 0.5) * 2.0, 6.0 * (unit(key + 7) - 0.5) * 2.0, 4.0 * (unit(key + 9) - 0.5)];
                if s.contains(o, 1e-6) {
                    continue;
                }
                // Aim near the shape so that about half the rays hit.
                let c = s.center;
                let d = [c[0] - o[0] + gauss(key + 1), c[1] - o[1] + gauss(key + 2), c[2] - o[2] + gauss(key + 3)];
                let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
                let d = [d[0] / n, d[1] / n, d[2] / n];
                let fast = s.intersect(o, d).filter(|sp| sp.t_in >= 0.0).map(|sp| sp.t_in);
                let slow = march(s, o, d);
                match (fast, slow) {
                    (Some(a), Some(b)) => {
                        hits += 1;
                        assert!((a - b).abs() < 2e-3, "{:?}: fast {a} slow {b}", s.kind);
                    }
                    (None, None) => {}
                    // Grazing rays may miss the marching grid by a hair.
                    (Some(a), None) => {
                        let sp = s.intersect(o, d).unwrap();
                        assert!(sp.t_out - a < 5e-3, "{:?}: fast {a} slow none", s.kind);
                    }
                    (None, Some(b)) => panic!("{:?}: fast none, slow {b}", s.kind),
                }
            }
        }
        assert!(hits > 100, "only {hits} hits");
    }

    #[test]
    fn normals_are_unit_and_face_the_ray() {
        for s in shapes() {
            for i in 0..200u64 {
                let o = [8.0 * (unit(i) - 0.5), 8.0 * (unit(i + 1000) - 0.5), 3.0];
                let d = [s.center[0] - o[0] + 0.3 * gauss(i), s.center[1] - o[1], s.center[2] - o[2]];
                if let Some(sp) = s.intersect(o, d) {
                    let n = sp.normal;
                    let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
                    assert!((len - 1.0).abs() < 1e-9, "{:?} normal {n:?}", s.kind);
                    assert!(n[0] * d[0] + n[1] * d[1] + n[2] * d[2] <= 1e-9, "{:?} normal faces away", s.kind);
                }
            }
        }
    }

    #[test]
    fn transformed_shape_contains_transformed_points() {
        let s = Shape::cuboid([1.0, 0.0, 0.9], [2.0, 1.0, 1.8], 0.2);
        let w = s.transformed(10.0, -5.0, 3.0, 1.0);
        let (sn, cs) = 1.0f64.sin_cos();
        for p in [[1.5, 0.3, 0.2], [0.1, -0.4, 1.7], [2.2, 0.0, 0.9]] {
            let q = [10.0 + cs * p[0] - sn * p[1], -5.0 + sn * p[0] + cs * p[1], 3.0 + p[2]];
            assert_eq!(s.contains(p, 0.0), w.contains(q, 0.0), "{p:?}");
        }
        let b = w.xy_bounds();
        assert!(b[0] < w.center[0] && w.center[0] < b[2] && b[1] < w.center[1] && w.center[1] < b[3]);
    }

    #[test]
    fn dome_is_the_upper_half_only() {
        let d = Shape::dome([0.0, 0.0, 1.0], 2.0, 1.0);
        assert!(d.contains([0.0, 0.0, 1.5], 0.0));
        assert!(!d.contains([0.0, 0.0, 0.9], 0.0));
        assert!(d.contains([1.9, 0.0, 1.05], 0.0));
        assert!(!d.contains([1.9, 0.0, 1.9], 0.0));
        // A ray from below enters through the flat base.
        let sp = d.intersect([0.5, 0.0, 0.0], [0.0, 0.0, 1.0]).unwrap();
        assert!((sp.t_in - 1.0).abs() < 1e-12 && sp.normal == [0.0, 0.0, -1.0]);
    }
}
