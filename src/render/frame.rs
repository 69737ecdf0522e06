//! Top-down projection: the world frame's x/y (metres, the frame of `seam
//! poses`) onto canvas pixels, x to the right and y **up** (image rows grow
//! downwards, so y is flipped), with one scale for both axes; plus the round
//! numbers for scale bars and grid ticks.

/// An axis-aligned rectangle of the world's x/y plane, metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Extent {
    pub x0: f64,
    pub y0: f64,
    pub x1: f64,
    pub y1: f64,
}

impl Extent {
    /// Nothing yet; `include` grows it.
    pub const EMPTY: Extent =
        Extent { x0: f64::INFINITY, y0: f64::INFINITY, x1: f64::NEG_INFINITY, y1: f64::NEG_INFINITY };

    pub fn is_empty(&self) -> bool {
        !(self.x0 <= self.x1 && self.y0 <= self.y1)
    }
    pub fn include(&mut self, x: f64, y: f64) {
        if x.is_finite() && y.is_finite() {
            self.x0 = self.x0.min(x);
            self.y0 = self.y0.min(y);
            self.x1 = self.x1.max(x);
            self.y1 = self.y1.max(y);
        }
    }
    pub fn width(&self) -> f64 {
        self.x1 - self.x0
    }
    pub fn height(&self) -> f64 {
        self.y1 - self.y0
    }
    /// Grown by `m` metres on every side.
    pub fn padded(&self, m: f64) -> Extent {
        Extent { x0: self.x0 - m, y0: self.y0 - m, x1: self.x1 + m, y1: self.y1 + m }
    }
}

/// Where the map area sits on the canvas and what it shows.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct View {
    /// The world rectangle the map area shows exactly.
    pub world: Extent,
    pub m_per_px: f64,
    /// Top-left corner of the map area on the canvas, pixels.
    pub left_px: f64,
    pub top_px: f64,
    pub width_px: u32,
    pub height_px: u32,
}

impl View {
    /// Fits `content` into at most `max_w` × `max_h` pixels at `(left, top)`
    /// with the largest scale that shows all of it. The map area is then
    /// shrunk to the content's aspect (at least `min_h` pixels high), and
    /// the world rectangle centred on the content to fill it exactly.
    pub fn fit(content: &Extent, left: f64, top: f64, max_w: u32, max_h: u32, min_h: u32) -> View {
        let (cw, ch) = (content.width().max(1e-3), content.height().max(1e-3));
        let m_per_px = (cw / max_w.max(1) as f64).max(ch / max_h.max(1) as f64);
        let width_px = ((cw / m_per_px).ceil() as u32).clamp(1, max_w.max(1));
        let height_px = ((ch / m_per_px).ceil() as u32).clamp(min_h.min(max_h).max(1), max_h.max(1));
        let (cx, cy) = ((content.x0 + content.x1) / 2.0, (content.y0 + content.y1) / 2.0);
        let (hw, hh) = (width_px as f64 * m_per_px / 2.0, height_px as f64 * m_per_px / 2.0);
        let world = Extent { x0: cx - hw, y0: cy - hh, x1: cx + hw, y1: cy + hh };
        View { world, m_per_px, left_px: left, top_px: top, width_px, height_px }
    }

    /// Canvas position of a world point (continuous pixel coordinates: the
    /// pixel `(i, j)` covers `[i, i+1) × [j, j+1)`).
    pub fn to_px(&self, x: f64, y: f64) -> (f64, f64) {
        (self.left_px + (x - self.world.x0) / self.m_per_px, self.top_px + (self.world.y1 - y) / self.m_per_px)
    }

    /// World position of a canvas point (inverse of [`View::to_px`]).
    pub fn to_world(&self, px: f64, py: f64) -> (f64, f64) {
        (self.world.x0 + (px - self.left_px) * self.m_per_px, self.world.y1 - (py - self.top_px) * self.m_per_px)
    }

    /// Side in pixels of a square `size_m` wide, at least one pixel.
    pub fn side_px(&self, size_m: f64) -> f64 {
        (size_m / self.m_per_px).max(1.0)
    }

    pub fn right_px(&self) -> f64 {
        self.left_px + self.width_px as f64
    }
    pub fn bottom_px(&self) -> f64 {
        self.top_px + self.height_px as f64
    }
}

/// The largest 1, 2 or 5 × 10^k metres no longer than `max_m`: the length
/// of a scale bar that fits in `max_m`.
pub fn round_length(max_m: f64) -> f64 {
    if max_m.is_nan() || max_m <= 0.0 || !max_m.is_finite() {
        return 0.0;
    }
    let mut p = 10f64.powf(max_m.log10().floor());
    // log10 rounding can land one decade off at exact powers of ten.
    if p > max_m {
        p /= 10.0;
    }
    if p * 10.0 <= max_m {
        p *= 10.0;
    }
    [5.0, 2.0, 1.0].into_iter().map(|m| m * p).find(|l| *l <= max_m).unwrap_or(p)
}

/// Grid ticks over `[lo, hi]`: the multiples of the round step (1/2/5 ×
/// 10^k) nearest to `(hi - lo) / target` that fall inside.
pub fn ticks(lo: f64, hi: f64, target: usize) -> Vec<f64> {
    if !lo.is_finite() || !hi.is_finite() || hi <= lo {
        return Vec::new();
    }
    let step = round_step_near((hi - lo) / target.max(1) as f64);
    // A tolerance of a millionth of a step, so ends given as f32 (0.1f32 is
    // 0.10000000149) still get their tick.
    let first = (lo / step - 1e-6).ceil() as i64;
    let last = (hi / step + 1e-6).floor() as i64;
    // Multiplying an integer by the step keeps values like 0.6 exact enough
    // for labels; `tick_label` rounds the rest.
    (first..=last).map(|i| i as f64 * step).collect()
}

/// The 1, 2 or 5 × 10^k nearest to `v` (> 0) on a log scale.
fn round_step_near(v: f64) -> f64 {
    let p = 10f64.powf(v.log10().floor());
    [1.0, 2.0, 5.0, 10.0]
        .map(|m| m * p)
        .into_iter()
        .min_by(|a, b| (a / v).ln().abs().total_cmp(&(b / v).ln().abs()))
        .unwrap_or(p)
}

/// A tick value as short text: no trailing zeros, no `-0`.
pub fn tick_label(v: f64) -> String {
    let v = if v.abs() < 1e-9 { 0.0 } else { v };
    let s = format!("{v:.3}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    s.replace('-', "−")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn projection_puts_y_up_and_round_trips() {
        let content = Extent { x0: -10.0, y0: 0.0, x1: 30.0, y1: 20.0 };
        let v = View::fit(&content, 100.0, 50.0, 400, 400, 0);
        // 40 m over 400 px: 0.1 m per px; 20 m high → 200 px.
        assert!((v.m_per_px - 0.1).abs() < 1e-12);
        assert_eq!((v.width_px, v.height_px), (400, 200));
        // The world's top-left corner is the map area's top-left corner.
        let (px, py) = v.to_px(-10.0, 20.0);
        assert!((px - 100.0).abs() < 1e-9 && (py - 50.0).abs() < 1e-9);
        // y grows upwards: a point further north is higher in the image.
        assert!(v.to_px(0.0, 15.0).1 < v.to_px(0.0, 5.0).1);
        assert!(v.to_px(5.0, 0.0).0 > v.to_px(-5.0, 0.0).0);
        let (px, py) = v.to_px(30.0, 0.0);
        assert!((px - 500.0).abs() < 1e-9 && (py - 250.0).abs() < 1e-9);
        for (x, y) in [(0.0, 0.0), (12.3, 4.56), (-9.99, 19.0)] {
            let (px, py) = v.to_px(x, y);
            let (bx, by) = v.to_world(px, py);
            assert!((bx - x).abs() < 1e-9 && (by - y).abs() < 1e-9);
        }
        assert_eq!(v.side_px(0.2), 2.0);
        assert_eq!(v.side_px(0.01), 1.0, "at least a pixel");
    }

    #[test]
    fn fit_keeps_one_scale_and_centres_a_tall_site() {
        let content = Extent { x0: 0.0, y0: 0.0, x1: 10.0, y1: 100.0 };
        let v = View::fit(&content, 0.0, 0.0, 400, 200, 0);
        assert!((v.m_per_px - 0.5).abs() < 1e-12, "height limits the scale");
        assert_eq!((v.width_px, v.height_px), (20, 200));
        assert!((v.world.x0 + v.world.x1 - 10.0).abs() < 1e-9, "centred on the content");
        // A minimum height grows the world box, not the scale.
        let flat = Extent { x0: 0.0, y0: 0.0, x1: 100.0, y1: 1.0 };
        let v = View::fit(&flat, 0.0, 0.0, 100, 500, 300);
        assert_eq!(v.height_px, 300);
        assert!((v.world.height() - 300.0).abs() < 1e-9 && (v.world.y0 + v.world.y1 - 1.0).abs() < 1e-9);
    }

    #[test]
    fn scale_bar_lengths_are_round() {
        for (max, want) in [
            (1.0, 1.0),
            (1.9, 1.0),
            (2.0, 2.0),
            (4.99, 2.0),
            (5.0, 5.0),
            (9.99, 5.0),
            (10.0, 10.0),
            (37.0, 20.0),
            (99.0, 50.0),
            (100.0, 100.0),
            (0.3, 0.2),
            (0.07, 0.05),
            (1234.0, 1000.0),
        ] {
            assert!((round_length(max) - want).abs() < 1e-9, "{max} → {} not {want}", round_length(max));
        }
        assert_eq!(round_length(0.0), 0.0);
        assert_eq!(round_length(f64::NAN), 0.0);
    }

    #[test]
    fn ticks_are_round_multiples_inside_the_range() {
        let close = |a: Vec<f64>, b: &[f64]| a.len() == b.len() && a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-9);
        assert!(close(ticks(0.0, 100.0, 5), &[0.0, 20.0, 40.0, 60.0, 80.0, 100.0]));
        assert!(close(ticks(-73.0, 88.0, 8), &[-60.0, -40.0, -20.0, 0.0, 20.0, 40.0, 60.0, 80.0]));
        assert!(close(ticks(0.1, 0.9, 4), &[0.2, 0.4, 0.6, 0.8]));
        assert!(close(ticks(-1.3, 31.5, 6), &[0.0, 5.0, 10.0, 15.0, 20.0, 25.0, 30.0]));
        assert!(close(ticks(0.1, 0.9, 8), &[0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9]));
        let from_f32 = ticks(0.1f32 as f64, 0.9f32 as f64, 8);
        assert!(close(from_f32, &[0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9]), "ends given as f32 keep their ticks");
        assert!(ticks(1.0, 1.0, 5).is_empty());
        assert_eq!(tick_label(-0.0), "0");
        assert_eq!(tick_label(-20.0), "−20");
        assert_eq!(tick_label(0.25), "0.25");
    }
}
