//! The map layers, rastered straight from the store: each voxel's centre on
//! the world grid (its key, not the centroid of its points: grid-aligned
//! squares tile without the moiré of gaps and overlaps that centroids give)
//! is projected to x/y and splatted as a square of the voxel's size (at
//! least one pixel) into a per-pixel buffer that keeps the **maximum** of a
//! value —
//! the highest voxel's z for the height map, the largest ε_g for the
//! lifelong map (the most ephemeral voxel in the column shows), the
//! category's paint priority for changes. Memory is one `f32` per map-area
//! pixel, whatever the number of voxels; nothing is allocated per voxel.

use super::canvas::{Align, Canvas};
use super::colormap::{CATEGORY_STYLES, Colormap, Rgb};
use super::frame::View;
use super::scene::{Trajectory, Window};
use crate::store::{self, ChangeEventRow, StoreError, WorldBox};
use rusqlite::Connection;

/// A per-pixel maximum over the map area; `NEG_INFINITY` where nothing fell.
pub struct Raster {
    w: usize,
    h: usize,
    v: Vec<f32>,
}

impl Raster {
    pub fn new(view: &View) -> Raster {
        let (w, h) = (view.width_px as usize, view.height_px as usize);
        Raster { w, h, v: vec![f32::NEG_INFINITY; w * h] }
    }

    /// Keeps `value` in every pixel of the `side`-pixel square centred on
    /// the world point `(x, y)` where it is larger than what is there.
    ///
    /// A pixel is covered when its centre lies in the square, widened by a
    /// millionth of a pixel: two squares that touch (voxels of a regular
    /// grid) then share a pixel column at an exact tie instead of leaving a
    /// one-pixel gap between them, whichever way floating point rounds their
    /// common edge. A square smaller than a pixel covers the pixel holding
    /// its centre.
    pub fn splat(&mut self, view: &View, x: f64, y: f64, side: f64, value: f32) {
        const TIE: f64 = 1e-6;
        let (px, py) = view.to_px(x, y);
        let (px, py) = (px - view.left_px, py - view.top_px);
        let half = side / 2.0;
        let span = |c: f64| {
            let (a, b) = ((c - half - 0.5 - TIE).ceil() as i64, (c + half - 0.5 + TIE).ceil() as i64);
            if b > a { (a, b) } else { (c.floor() as i64, c.floor() as i64 + 1) }
        };
        let ((x0, x1), (y0, y1)) = (span(px), span(py));
        let (x0, x1) = (x0.max(0) as usize, x1.min(self.w as i64).max(0) as usize);
        let (y0, y1) = (y0.max(0) as usize, y1.min(self.h as i64).max(0) as usize);
        if x0 >= x1 {
            return;
        }
        for j in y0..y1 {
            for cell in &mut self.v[j * self.w + x0..j * self.w + x1] {
                if value > *cell {
                    *cell = value;
                }
            }
        }
    }

    /// The values of pixels something fell in.
    pub fn filled(&self) -> impl Iterator<Item = f32> + '_ {
        self.v.iter().copied().filter(|v| v.is_finite())
    }

    /// Paints every filled pixel with `colour(value)`.
    pub fn paint(&self, canvas: &mut Canvas, view: &View, colour: impl Fn(f32) -> Rgb) {
        let (l, t) = (view.left_px as i32, view.top_px as i32);
        for j in 0..self.h {
            for i in 0..self.w {
                let v = self.v[j * self.w + i];
                if v.is_finite() {
                    canvas.set(l + i as i32, t + j as i32, colour(v));
                }
            }
        }
    }
}

/// The world box a view shows, every height.
pub fn world_box(view: &View) -> WorldBox {
    let w = &view.world;
    WorldBox { min_m: [w.x0, w.y0, f64::MIN], max_m: [w.x1, w.y1, f64::MAX] }
}

/// The x/y centre of the voxel with key `k` on a grid of `voxel_m`.
pub fn key_centre(k: [i64; 3], voxel_m: f64) -> (f64, f64) {
    ((k[0] as f64 + 0.5) * voxel_m, (k[1] as f64 + 0.5) * voxel_m)
}

/// The centre of the grid cell holding a point (change events carry a
/// centroid, not a key).
pub fn snap(v: f64, voxel_m: f64) -> f64 {
    ((v / voxel_m).floor() + 0.5) * voxel_m
}

/// The `q`-quantile (0..1) of values; `None` if there are none.
pub fn quantile(values: &mut [f32], q: f64) -> Option<f32> {
    if values.is_empty() {
        return None;
    }
    let k = ((values.len() - 1) as f64 * q.clamp(0.0, 1.0)).round() as usize;
    let (_, v, _) = values.select_nth_unstable_by(k, f32::total_cmp);
    Some(*v)
}

/// Tops of the map: the highest voxel z per pixel, of voxels with ε_g below
/// `eps_g_below` (the static map) or all. Returns the raster and the
/// number of voxels read.
pub fn tops(
    conn: &Connection,
    view: &View,
    voxel_m: f64,
    eps_g_below: Option<f64>,
) -> Result<(Raster, u64), StoreError> {
    let mut r = Raster::new(view);
    let side = view.side_px(voxel_m);
    let n = store::for_each_map_voxel(conn, &world_box(view), eps_g_below, |k, p, _| {
        let (x, y) = key_centre(k, voxel_m);
        r.splat(view, x, y, side, p[2] as f32)
    })?;
    Ok((r, n))
}

/// The colour range of a height raster: the 2nd to 98th percentile of the
/// visible tops, so a crane or a stray point does not wash out the site.
pub fn height_range(r: &Raster) -> Option<(f32, f32)> {
    let mut v: Vec<f32> = r.filled().collect();
    let lo = quantile(&mut v, 0.02)?;
    let hi = quantile(&mut v, 0.98)?;
    Some(if hi - lo < 0.5 { (lo - 0.25, lo + 0.25) } else { (lo, hi) })
}

/// The largest ε_g per pixel over the whole lifelong map.
pub fn max_eps_g(conn: &Connection, view: &View, voxel_m: f64) -> Result<(Raster, u64), StoreError> {
    let mut r = Raster::new(view);
    let side = view.side_px(voxel_m);
    let n = store::for_each_map_voxel(conn, &world_box(view), None, |k, _, eps| {
        let (x, y) = key_centre(k, voxel_m);
        r.splat(view, x, y, side, eps)
    })?;
    Ok((r, n))
}

/// Paints the static map in light greys, lighter for lower tops: context
/// under changes and trajectories that still shows the site's shape.
pub fn paint_context(canvas: &mut Canvas, view: &View, tops: &Raster) {
    let (lo, hi) = height_range(tops).unwrap_or((0.0, 1.0));
    tops.paint(canvas, view, |z| {
        let t = ((z - lo) / (hi - lo)).clamp(0.0, 1.0);
        let g = (Rgb::CONTEXT.0[0] as f32 + 14.0 - 48.0 * t).round() as u8;
        Rgb([g, g, g])
    });
}

/// Change events in the window, as the count per category (in
/// `CATEGORY_STYLES` order) and a raster of the highest paint priority per
/// pixel. Changes seen with evidence (built, removed, back again) are drawn
/// at least 2 px wide: they are the point of the picture and would vanish
/// at one pixel; the pale coverage categories keep their true size.
pub fn changes(events: &[ChangeEventRow], window: &Window, view: &View, voxel_m: f64) -> (Raster, [u64; 5]) {
    let mut r = Raster::new(view);
    let mut counts = [0u64; 5];
    let side = view.side_px(voxel_m);
    for ev in events.iter().map(|e| &e.event).filter(|e| window.contains(e.session_id)) {
        if let Some(i) = CATEGORY_STYLES.iter().position(|s| s.category == ev.category) {
            counts[i] += 1;
            let p = CATEGORY_STYLES[i].priority;
            let side = if p >= STRONG_PRIORITY { side.max(2.0) } else { side };
            r.splat(view, snap(ev.xyz_m[0], voxel_m), snap(ev.xyz_m[1], voxel_m), side, p as f32);
        }
    }
    (r, counts)
}

/// Categories from this paint priority up are changes seen with evidence.
pub const STRONG_PRIORITY: u8 = 3;

/// The colour of a changes raster value (a paint priority).
pub fn category_colour(priority: f32) -> Rgb {
    CATEGORY_STYLES.iter().find(|s| s.priority as f32 == priority).map_or(Rgb::BLACK, |s| s.colour)
}

/// Draws trajectories as polylines `width` pixels wide with a disc and the
/// session's name (`label_px` high) at each start; `colour(i)` is the
/// colour of the `i`-th.
pub fn trajectories(
    canvas: &mut Canvas,
    view: &View,
    list: &[&Trajectory],
    width: f32,
    label_px: f32,
    colour: impl Fn(usize) -> Rgb,
) {
    for (i, t) in list.iter().enumerate() {
        let pts: Vec<(f32, f32)> = t
            .xy_m
            .iter()
            .map(|p| {
                let (x, y) = view.to_px(p[0], p[1]);
                (x as f32, y as f32)
            })
            .collect();
        canvas.polyline(&pts, width, colour(i));
    }
    // Start markers over every line, so none hides under a later session.
    for (i, t) in list.iter().enumerate() {
        if let Some(p) = t.xy_m.first() {
            let (x, y) = view.to_px(p[0], p[1]);
            let r = width * 2.2;
            canvas.disc(x as f32, y as f32, r, colour(i), width * 0.6, Rgb::WHITE);
            canvas.text_halo(x as f32 + r * 1.6, y as f32 - r * 0.9, label_px, colour(i), Align::Left, &t.name);
        }
    }
}

/// A colour map's colour for a raster value on `[lo, hi]`.
pub fn ramp(cm: Colormap, lo: f32, hi: f32) -> impl Fn(f32) -> Rgb {
    move |v| cm.of(v, lo, hi)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::frame::Extent;

    #[test]
    fn splat_keeps_the_maximum_and_stays_inside() {
        let view = View::fit(&Extent { x0: 0.0, y0: 0.0, x1: 10.0, y1: 10.0 }, 0.0, 0.0, 100, 100, 0);
        let mut r = Raster::new(&view);
        r.splat(&view, 5.0, 5.0, 4.0, 1.0);
        r.splat(&view, 5.0, 5.0, 2.0, 3.0);
        r.splat(&view, 5.0, 5.0, 2.0, 2.0); // lower: loses
        r.splat(&view, -3.0, 5.0, 4.0, 9.0); // outside: nothing
        r.splat(&view, 0.0, 10.0, 4.0, 7.0); // corner: clipped
        // (5, 5) is pixel (50, 50); a 4 px square covers 48..52.
        let at = |r: &Raster, i: usize, j: usize| r.v[j * 100 + i];
        assert_eq!(at(&r, 50, 50), 3.0);
        assert_eq!(at(&r, 48, 48), 1.0);
        assert_eq!(at(&r, 49, 49), 3.0);
        assert_eq!(at(&r, 51, 51), 1.0);
        assert_eq!(at(&r, 52, 50), f32::NEG_INFINITY);
        assert_eq!(at(&r, 0, 0), 7.0);
        assert_eq!(at(&r, 1, 1), 7.0);
        assert_eq!(r.filled().count(), 16 + 4);
        // A point smaller than a pixel still fills one.
        r.splat(&view, 2.05, 2.05, 0.3, 5.0);
        assert_eq!(at(&r, 20, 79), 5.0);
    }

    #[test]
    fn a_regular_grid_of_voxels_leaves_no_gaps_at_any_scale() {
        // Voxel edges landing exactly on pixel centres (0.04 m per pixel,
        // 0.2 m voxels: 5 px) used to leave one-pixel gaps.
        for m_per_px in [0.04, 0.05, 0.0333, 0.0625, 0.1, 0.2, 0.41] {
            let e = Extent { x0: -1.9, y0: -1.9, x1: -1.9 + 100.0 * m_per_px, y1: -1.9 + 100.0 * m_per_px };
            let view = View::fit(&e, 0.0, 0.0, 100, 100, 0);
            let mut r = Raster::new(&view);
            let side = view.side_px(0.2);
            for ix in 0..100 {
                for iy in 0..100 {
                    r.splat(&view, ix as f64 * 0.2 + 0.1, iy as f64 * 0.2 + 0.1, side, 1.0);
                }
            }
            let mut inside = 0;
            for j in 0..100 {
                for i in 0..100 {
                    let (wx, wy) = view.to_world(i as f64 + 0.5, j as f64 + 0.5);
                    if (0.01..19.99).contains(&wx) && (0.01..19.99).contains(&wy) {
                        inside += 1;
                        assert!(r.v[j * 100 + i].is_finite(), "gap at ({i}, {j}) with {m_per_px} m per pixel");
                    }
                }
            }
            assert!(inside > 100, "{m_per_px}: {inside}");
        }
    }

    #[test]
    fn voxels_are_drawn_at_their_grid_cells() {
        assert_eq!(key_centre([0, -1, 7], 0.2), (0.1, -0.1));
        assert!((snap(0.37, 0.2) - 0.3).abs() < 1e-12);
        assert!((snap(-0.05, 0.2) + 0.1).abs() < 1e-12);
    }

    #[test]
    fn quantiles() {
        let mut v: Vec<f32> = (0..101).map(|i| i as f32).collect();
        v.reverse();
        assert_eq!(quantile(&mut v, 0.02), Some(2.0));
        assert_eq!(quantile(&mut v, 0.98), Some(98.0));
        assert_eq!(quantile(&mut [], 0.5), None);
    }
}
