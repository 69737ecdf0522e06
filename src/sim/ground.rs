//! The ground: a gently uneven triangulated height field on a 1 m grid.
//!
//! The same grid is the ray caster's acceleration grid (see `raycast.rs`), so a
//! ray meets the ground of a cell while it visits the cell. Each cell is split
//! along its anti-diagonal into two planar triangles; `height_at` and the ray
//! intersection use the same triangles, so what the sensor sees is exactly
//! the surface that objects and movers are placed on.

use super::seeds::{mix, unit};

/// Grid extent: the site (110 m × 92 m) plus the neighbourhood a
/// 120 m sensor sees over the fence.
pub(crate) const GRID_MIN: [f64; 2] = [-100.0, -90.0];
pub(crate) const GRID_CELLS: [usize; 2] = [200, 180];
pub(crate) const CELL_M: f64 = 1.0;

/// SemanticKITTI classes of the ground.
pub(crate) const LABEL_ROAD: u16 = 40;
pub(crate) const LABEL_TERRAIN: u16 = 72;

pub(crate) struct Ground {
    /// Node heights, `(nx + 1) × (ny + 1)`, row-major in y.
    heights: Vec<f64>,
    /// Per cell: true on site roads and the streets outside.
    road: Vec<bool>,
    seed: u64,
}

impl Ground {
    /// A height field from the seed; `is_road(x, y)` marks road cells (flatter, darker).
    pub(crate) fn new(seed: u64, is_road: impl Fn(f64, f64) -> bool) -> Ground {
        let [nx, ny] = GRID_CELLS;
        let p = [unit(seed ^ 1), unit(seed ^ 2), unit(seed ^ 3)].map(|u| u * std::f64::consts::TAU);
        let road: Vec<bool> = (0..nx * ny)
            .map(|c| {
                let (i, j) = (c % nx, c / nx);
                is_road(GRID_MIN[0] + (i as f64 + 0.5) * CELL_M, GRID_MIN[1] + (j as f64 + 0.5) * CELL_M)
            })
            .collect();
        let mut heights = Vec::with_capacity((nx + 1) * (ny + 1));
        for j in 0..=ny {
            for i in 0..=nx {
                let (x, y) = (GRID_MIN[0] + i as f64 * CELL_M, GRID_MIN[1] + j as f64 * CELL_M);
                // A few long waves (±0.5 m over the site, slopes under 4 %) plus a
                // slight tilt; rough terrain gets ±1.5 cm of node noise, roads ±0.4 cm.
                let smooth = 0.30 * (0.09 * x + p[0]).sin() * (0.07 * y + p[1]).cos()
                    + 0.18 * (0.045 * (x - 0.6 * y) + p[2]).sin()
                    + 0.003 * x
                    - 0.002 * y;
                let near_road =
                    [(i, j), (i.wrapping_sub(1), j), (i, j.wrapping_sub(1)), (i.wrapping_sub(1), j.wrapping_sub(1))]
                        .iter()
                        .any(|&(ci, cj)| ci < nx && cj < ny && road[cj * nx + ci]);
                let rough = if near_road { 0.004 } else { 0.015 };
                let n = (unit(mix(seed ^ (((j * (nx + 1) + i) as u64) << 1))) - 0.5) * 2.0 * rough;
                heights.push(smooth + n);
            }
        }
        Ground { heights, road, seed }
    }

    fn node(&self, i: usize, j: usize) -> f64 {
        self.heights[j * (GRID_CELLS[0] + 1) + i]
    }

    /// The four corner heights `[h00, h10, h01, h11]` of cell (i, j).
    pub(crate) fn corners(&self, i: usize, j: usize) -> [f64; 4] {
        [self.node(i, j), self.node(i + 1, j), self.node(i, j + 1), self.node(i + 1, j + 1)]
    }

    /// The cell containing (x, y), clamped to the grid.
    pub(crate) fn cell_of(x: f64, y: f64) -> (usize, usize) {
        let i = ((x - GRID_MIN[0]) / CELL_M).floor().clamp(0.0, (GRID_CELLS[0] - 1) as f64) as usize;
        let j = ((y - GRID_MIN[1]) / CELL_M).floor().clamp(0.0, (GRID_CELLS[1] - 1) as f64) as usize;
        (i, j)
    }

    /// Height of the triangulated surface at (x, y).
    pub(crate) fn height_at(&self, x: f64, y: f64) -> f64 {
        let (i, j) = Ground::cell_of(x, y);
        let fx = ((x - GRID_MIN[0]) / CELL_M - i as f64).clamp(0.0, 1.0);
        let fy = ((y - GRID_MIN[1]) / CELL_M - j as f64).clamp(0.0, 1.0);
        let [h00, h10, h01, h11] = self.corners(i, j);
        if fx + fy <= 1.0 {
            h00 + (h10 - h00) * fx + (h01 - h00) * fy
        } else {
            h11 - (h11 - h01) * (1.0 - fx) - (h11 - h10) * (1.0 - fy)
        }
    }

    /// Highest ground under a footprint given by its corners: the corners and
    /// every grid node inside the footprint's bounding rectangle. Objects stand
    /// at this height so that no ground is ever inside them.
    pub(crate) fn max_under(&self, corners: &[[f64; 2]]) -> f64 {
        let mut top = f64::NEG_INFINITY;
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for c in corners {
            top = top.max(self.height_at(c[0], c[1]));
            for k in 0..2 {
                lo[k] = lo[k].min(c[k]);
                hi[k] = hi[k].max(c[k]);
            }
        }
        let (i0, j0) = Ground::cell_of(lo[0], lo[1]);
        let (i1, j1) = Ground::cell_of(hi[0], hi[1]);
        for j in j0..=j1 + 1 {
            for i in i0..=i1 + 1 {
                top = top.max(self.node(i, j));
            }
        }
        top
    }

    /// True on roads.
    pub(crate) fn is_road_cell(&self, i: usize, j: usize) -> bool {
        self.road[j * GRID_CELLS[0] + i]
    }

    /// Label and reflectivity of the ground in cell (i, j): asphalt or
    /// compacted gravel roads are darker than the surrounding soil, and
    /// reflectivity varies a little from cell to cell.
    pub(crate) fn surface(&self, i: usize, j: usize) -> (u16, f32) {
        let v = (unit(mix(self.seed ^ 0xC0FFEE ^ (j * GRID_CELLS[0] + i) as u64)) - 0.5) as f32 * 0.06;
        if self.is_road_cell(i, j) { (LABEL_ROAD, 0.14 + v) } else { (LABEL_TERRAIN, 0.26 + v) }
    }

    /// The ray `o + t d` against the ground of cell (i, j) for `t` in
    /// `[t0, t1]` (the ray's stay in the cell): the hit `t` and the normal.
    pub(crate) fn intersect_cell(
        &self,
        i: usize,
        j: usize,
        o: [f64; 3],
        d: [f64; 3],
        t0: f64,
        t1: f64,
    ) -> Option<(f64, [f64; 3])> {
        const EPS: f64 = 1e-9;
        let [h00, h10, h01, h11] = self.corners(i, j);
        let fx0 = (o[0] - GRID_MIN[0]) / CELL_M - i as f64;
        let fy0 = (o[1] - GRID_MIN[1]) / CELL_M - j as f64;
        let (dfx, dfy) = (d[0] / CELL_M, d[1] / CELL_M);
        // Each triangle is the plane z = a + b·fx + c·fy restricted to one side
        // of fx + fy = 1.
        let planes = [(h00, h10 - h00, h01 - h00, true), (h01 + h10 - h11, h11 - h01, h11 - h10, false)];
        let mut best: Option<(f64, [f64; 3])> = None;
        for (a, b, c, lower) in planes {
            let den = d[2] - b * dfx - c * dfy;
            if den >= -1e-15 {
                continue; // parallel, or coming from below
            }
            let t = (a + b * fx0 + c * fy0 - o[2]) / den;
            if t < t0 - EPS || t > t1 + EPS || t <= 0.0 || best.is_some_and(|(bt, _)| bt <= t) {
                continue;
            }
            let s = fx0 + t * dfx + fy0 + t * dfy;
            if (lower && s > 1.0 + EPS) || (!lower && s < 1.0 - EPS) {
                continue;
            }
            let n = [-b / CELL_M, -c / CELL_M, 1.0];
            let len = (n[0] * n[0] + n[1] * n[1] + 1.0).sqrt();
            best = Some((t, [n[0] / len, n[1] / len, n[2] / len]));
        }
        best
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ray_hits_the_surface_that_height_at_describes() {
        let g = Ground::new(9, |x, _| x.abs() < 5.0);
        for k in 0..500u64 {
            let (x, y) = (60.0 * (unit(k) - 0.5), 60.0 * (unit(k + 99) - 0.5));
            let o = [x, y, g.height_at(x, y) + 1.0 + 3.0 * unit(k + 5)];
            let (i, j) = Ground::cell_of(x, y);
            // Straight down: must hit in the cell at the surface height.
            let (t, n) = g.intersect_cell(i, j, o, [0.0, 0.0, -1.0], 0.0, 100.0).unwrap();
            assert!((o[2] - t - g.height_at(x, y)).abs() < 1e-9);
            assert!(n[2] > 0.99);
        }
    }

    #[test]
    fn terrain_is_gentle() {
        let g = Ground::new(3, |_, _| false);
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for j in 0..88 {
            for i in 0..110 {
                let (x, y) = (i as f64 - 55.0, j as f64 - 44.0);
                let h = g.height_at(x, y);
                lo = lo.min(h);
                hi = hi.max(h);
                let slope = (g.height_at(x + 1.0, y) - h).abs();
                assert!(slope < 0.1, "slope {slope} at {x},{y}");
            }
        }
        assert!(hi - lo > 0.3 && hi - lo < 2.0, "relief {}", hi - lo);
        let corners = [[0.0, 0.0], [4.0, 0.0], [4.0, 3.0], [0.0, 3.0]];
        let m = g.max_under(&corners);
        for k in 0..100 {
            let (x, y) = (4.0 * unit(k), 3.0 * unit(k + 1000));
            assert!(g.height_at(x, y) <= m + 1e-12);
        }
    }
}
