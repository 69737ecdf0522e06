//! What is drawn around the map: title, metre grid with labelled axes, the
//! legend (colour bar with ticks, or category / session swatches), a metre
//! scale bar of a round length, and the x/y arrows of the world frame.
//!
//! Sizes scale with the picture's width ([`Sizes`]), with floors so text
//! stays legible in small pictures.

use super::canvas::{Align, Canvas};
use super::colormap::{Colormap, Rgb};
use super::font;
use super::frame::{View, round_length, tick_label, ticks};
use super::thousands;

/// Text sizes and spacings for a picture `width` pixels wide (tuned at 1600).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sizes {
    pub s: f32,
    pub title: f32,
    pub text: f32,
    pub small: f32,
    pub pad: f32,
    pub legend_w: f32,
    pub line: f32,
}

impl Sizes {
    /// `text_scale` enlarges text (and the legend panel with it) for
    /// pictures shown smaller than their pixel size, as in the report.
    pub fn for_width(width: u32, text_scale: f32) -> Sizes {
        let s = (width as f32 / 1600.0).clamp(0.4, 3.0);
        let t = s * text_scale.clamp(0.5, 3.0);
        Sizes {
            s,
            title: (28.0 * t).max(17.0),
            text: (18.0 * t).max(13.0),
            small: (15.0 * t).max(11.0),
            pad: (22.0 * s).max(10.0),
            legend_w: (380.0 * t).max(230.0).min(width as f32 * 0.4),
            line: (3.5 * s).max(2.0),
        }
    }
}

/// The title line and a muted subtitle, from the top-left corner.
pub fn title(c: &mut Canvas, z: &Sizes, x: f32, y: f32, title: &str, subtitle: &str) -> f32 {
    let base = y + z.title;
    c.text(x, base, z.title, Rgb::INK, Align::Left, title);
    let base2 = base + z.text * 1.5;
    c.text(x, base2, z.text, Rgb::MUTED, Align::Left, subtitle);
    base2 + z.text * 0.6 - y
}

/// Grid lines every round number of metres, under the map (they show in
/// its gaps and around it).
pub fn grid(c: &mut Canvas, view: &View) {
    let w = &view.world;
    let (l, t, r, b) = (view.left_px as i32, view.top_px as i32, view.right_px() as i32, view.bottom_px() as i32);
    for x in ticks(w.x0, w.x1, 8) {
        let px = view.to_px(x, 0.0).0.floor() as i32;
        for py in t..b {
            c.set(px, py, Rgb::GRID);
        }
    }
    for y in ticks(w.y0, w.y1, 8) {
        let py = view.to_px(0.0, y).1.floor() as i32;
        for px in l..r {
            c.set(px, py, Rgb::GRID);
        }
    }
}

/// The frame around the map, tick marks and their labels (metres, world
/// frame) below and left of it, and the axis names.
pub fn axes(c: &mut Canvas, z: &Sizes, view: &View) {
    let (l, t, r, b) = (view.left_px as f32, view.top_px as f32, view.right_px() as f32, view.bottom_px() as f32);
    c.stroke_rect(l - 0.5, t - 0.5, r - l + 1.0, b - t + 1.0, 1.0, Rgb::MUTED);
    let tick = 6.0 * z.s.max(0.7);
    let w = &view.world;
    let xs = ticks(w.x0, w.x1, 8);
    for &x in &xs {
        let px = view.to_px(x, 0.0).0.floor() as f32 + 0.5;
        c.polyline(&[(px, b), (px, b + tick)], 1.0, Rgb::MUTED);
        c.text(px, b + tick + z.small * 1.1, z.small, Rgb::MUTED, Align::Centre, &tick_label(x));
    }
    for y in ticks(w.y0, w.y1, 8) {
        let py = view.to_px(0.0, y).1.floor() as f32 + 0.5;
        c.polyline(&[(l - tick, py), (l, py)], 1.0, Rgb::MUTED);
        let cy = py + font::cap_height(z.small) / 2.0;
        c.text(l - tick - 4.0, cy, z.small, Rgb::MUTED, Align::Right, &tick_label(y));
    }
    // Axis names where they cannot collide with tick labels: x past the
    // last tick below the frame's right end, y above the frame's left end.
    c.text(r, b + tick + z.small * 2.4, z.small, Rgb::MUTED, Align::Right, "x (m)");
    c.text(l - tick - 4.0, t - z.small * 1.1, z.small, Rgb::MUTED, Align::Right, "y (m)");
}

/// A heading line in the legend; returns the new cursor.
pub fn heading(c: &mut Canvas, z: &Sizes, x: f32, y: f32, text: &str) -> f32 {
    c.text(x, y + z.text, z.text, Rgb::INK, Align::Left, text);
    y + z.text * 1.6
}

/// A muted note line in the legend; returns the new cursor.
pub fn note(c: &mut Canvas, z: &Sizes, x: f32, y: f32, text: &str) -> f32 {
    c.text(x, y + z.small, z.small, Rgb::MUTED, Align::Left, text);
    y + z.small * 1.45
}

/// A vertical colour bar for `cm` over `[lo, hi]` (high at the top) with
/// ticks, and optional marker at `mark` (value, label). Returns the cursor.
#[allow(clippy::too_many_arguments)]
pub fn colour_bar(
    c: &mut Canvas,
    z: &Sizes,
    x: f32,
    y: f32,
    cm: Colormap,
    (lo, hi): (f32, f32),
    tick_values: &[f64],
    mark: Option<(f32, &str)>,
) -> f32 {
    let (bw, bh) = (30.0 * z.s.max(0.6), 300.0 * z.s.max(0.6));
    let top = y + z.small * 0.6;
    let rows = bh.round() as i32;
    for j in 0..rows {
        let t = 1.0 - (j as f32 + 0.5) / rows as f32;
        let col = cm.at(t);
        for i in 0..bw.round() as i32 {
            c.set(x.round() as i32 + i, top.round() as i32 + j, col);
        }
    }
    c.stroke_rect(x.round() - 0.5, top.round() - 0.5, bw.round() + 1.0, rows as f32 + 1.0, 1.0, Rgb::INK);
    let y_of = |v: f32| top.round() + rows as f32 * (1.0 - (v - lo) / (hi - lo));
    let tick = 7.0 * z.s.max(0.6);
    let right = x + bw.round();
    for &v in tick_values {
        let py = y_of(v as f32).round() + 0.5;
        c.polyline(&[(right, py), (right + tick, py)], 1.0, Rgb::INK);
        let cy = py + font::cap_height(z.text) / 2.0;
        c.text(right + tick + 5.0, cy, z.text, Rgb::INK, Align::Left, &tick_label(v));
    }
    if let Some((v, label)) = mark {
        let py = y_of(v).round() + 0.5;
        c.polyline(&[(x - tick, py), (right + tick, py)], 2.0 * z.s.max(0.7), Rgb::INK);
        let lx = right + tick + 5.0 + font::text_width(z.text, "0.00") + 12.0 * z.s;
        c.text(lx, py + font::cap_height(z.small) / 2.0, z.small, Rgb::INK, Align::Left, label);
    }
    top + rows as f32 + z.small * 1.2
}

/// A filled square swatch, a label, an optional right-aligned count, and an
/// optional muted note below. Returns the cursor.
#[allow(clippy::too_many_arguments)]
pub fn swatch_row(
    c: &mut Canvas,
    z: &Sizes,
    x: f32,
    y: f32,
    width: f32,
    colour: Rgb,
    label: &str,
    count: Option<u64>,
    note_text: Option<&str>,
) -> f32 {
    let sw = (z.text * 1.1).round();
    c.fill_rect(x, y.round(), sw, sw, colour);
    c.stroke_rect(x - 0.5, y.round() - 0.5, sw + 1.0, sw + 1.0, 1.0, Rgb::MUTED);
    let base = y + sw / 2.0 + font::cap_height(z.text) / 2.0;
    c.text(x + sw + 10.0 * z.s, base, z.text, Rgb::INK, Align::Left, label);
    if let Some(n) = count {
        c.text(x + width, base, z.text, Rgb::INK, Align::Right, &thousands(n));
    }
    let mut y = y + sw + 6.0 * z.s;
    if let Some(n) = note_text {
        c.text(x + sw + 10.0 * z.s, y + z.small * 0.7, z.small, Rgb::MUTED, Align::Left, n);
        y += z.small * 1.3;
    }
    y + 6.0 * z.s
}

/// A line swatch with a start disc, for a trajectory. Returns the cursor.
pub fn line_row(c: &mut Canvas, z: &Sizes, x: f32, y: f32, colour: Rgb, label: &str, detail: &str) -> f32 {
    let sw = 44.0 * z.s.max(0.6);
    let cy = y + z.text * 0.6;
    c.polyline(&[(x + 4.0, cy), (x + sw, cy)], z.line, colour);
    c.disc(x + 4.0, cy, z.line * 2.2, colour, z.line * 0.6, Rgb::WHITE);
    let base = cy + font::cap_height(z.text) / 2.0;
    let w = c.text(x + sw + 12.0 * z.s, base, z.text, Rgb::INK, Align::Left, label);
    c.text(x + sw + 12.0 * z.s + w + 8.0 * z.s, base, z.small, Rgb::MUTED, Align::Left, detail);
    y + z.text * 1.7
}

/// A scale bar of a round length (1, 2 or 5 × 10^k m) at most `max_px`
/// long: four alternating segments with labels. Returns the cursor and the
/// length in metres.
pub fn scale_bar(c: &mut Canvas, z: &Sizes, x: f32, y: f32, max_px: f32, m_per_px: f64) -> (f32, f64) {
    let len_m = round_length(max_px as f64 * m_per_px);
    let len_px = (len_m / m_per_px) as f32;
    let h = (10.0 * z.s).max(7.0).round();
    let top = (y + z.text * 1.3).round();
    let seg = len_px / 4.0;
    for i in 0..4 {
        let colour = if i % 2 == 0 { Rgb::INK } else { Rgb::WHITE };
        c.fill_rect(x + seg * i as f32, top, seg, h, colour);
    }
    c.stroke_rect(x - 0.5, top - 0.5, len_px + 1.0, h + 1.0, 1.0, Rgb::INK);
    let label_y = top - 6.0 * z.s.max(0.7);
    c.text(x, label_y, z.small, Rgb::INK, Align::Centre, "0");
    c.text(x + len_px / 2.0, label_y, z.small, Rgb::INK, Align::Centre, &tick_label(len_m / 2.0));
    c.text(x + len_px, label_y, z.small, Rgb::INK, Align::Centre, &format!("{} m", tick_label(len_m)));
    (top + h + z.small * 0.8, len_m)
}

/// Arrows of the world frame's +x and +y from a corner, labelled. Returns
/// the cursor.
pub fn frame_arrows(c: &mut Canvas, z: &Sizes, x: f32, y: f32, caption: &str) -> f32 {
    let len = 56.0 * z.s.max(0.6);
    let head = 11.0 * z.s.max(0.6);
    let w = 2.5 * z.s.max(0.6);
    let (ox, oy) = (x + head, y + len + head * 0.8);
    c.polyline(&[(ox, oy), (ox + len - head * 0.6, oy)], w, Rgb::INK);
    c.fill_polygon(&[(ox + len, oy), (ox + len - head, oy - head * 0.5), (ox + len - head, oy + head * 0.5)], Rgb::INK);
    c.polyline(&[(ox, oy), (ox, oy - len + head * 0.6)], w, Rgb::INK);
    c.fill_polygon(&[(ox, oy - len), (ox - head * 0.5, oy - len + head), (ox + head * 0.5, oy - len + head)], Rgb::INK);
    let cap = font::cap_height(z.text);
    c.text(ox + len + 6.0 * z.s, oy + cap / 2.0, z.text, Rgb::INK, Align::Left, "+x");
    c.text(ox + head * 0.8, oy - len + cap, z.text, Rgb::INK, Align::Left, "+y");
    let below = oy + head * 0.5 + z.small * 1.4;
    c.text(x, below, z.small, Rgb::MUTED, Align::Left, caption);
    below + z.small * 0.5
}
