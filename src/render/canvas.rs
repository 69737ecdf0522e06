//! The raster canvas: an opaque RGB picture on a `tiny-skia` pixmap, with
//! the few shapes pictures need (rectangles, anti-aliased strokes, circles,
//! polygons, text) and PNG encoding.
//!
//! Every pixel stays opaque (the canvas starts filled and only opaque
//! colours or coverage blends are drawn), so tiny-skia's premultiplied RGBA
//! equals straight RGBA and the PNG is written as 8-bit RGB.

use super::colormap::Rgb;
use super::font;
use tiny_skia::{FillRule, LineCap, LineJoin, Paint, PathBuilder, Pixmap, Rect, Stroke, Transform};

/// Where a text's x coordinate is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Align {
    Left,
    Centre,
    Right,
}

pub struct Canvas {
    pixmap: Pixmap,
}

fn paint(c: Rgb) -> Paint<'static> {
    let mut p = Paint::default();
    p.set_color_rgba8(c.0[0], c.0[1], c.0[2], 255);
    p.anti_alias = true;
    p
}

impl Canvas {
    /// A `width` × `height` canvas filled with `background`; `None` if a side
    /// is zero or the picture would not fit in memory.
    pub fn new(width: u32, height: u32, background: Rgb) -> Option<Canvas> {
        let mut pixmap = Pixmap::new(width, height)?;
        pixmap.fill(tiny_skia::Color::from_rgba8(background.0[0], background.0[1], background.0[2], 255));
        Some(Canvas { pixmap })
    }

    pub fn width(&self) -> u32 {
        self.pixmap.width()
    }
    pub fn height(&self) -> u32 {
        self.pixmap.height()
    }

    /// The colour at a pixel (`None` outside).
    pub fn get(&self, x: u32, y: u32) -> Option<Rgb> {
        self.pixmap.pixel(x, y).map(|p| Rgb([p.red(), p.green(), p.blue()]))
    }

    /// Sets one pixel; outside the canvas nothing happens.
    #[inline]
    pub fn set(&mut self, x: i32, y: i32, c: Rgb) {
        let (w, h) = (self.width() as i32, self.height() as i32);
        if x < 0 || y < 0 || x >= w || y >= h {
            return;
        }
        let i = (y as usize * w as usize + x as usize) * 4;
        self.pixmap.data_mut()[i..i + 4].copy_from_slice(&[c.0[0], c.0[1], c.0[2], 255]);
    }

    /// Mixes `c` into a pixel with weight `alpha` in `[0, 1]`.
    #[inline]
    pub fn blend(&mut self, x: i32, y: i32, c: Rgb, alpha: f32) {
        let (w, h) = (self.width() as i32, self.height() as i32);
        if x < 0 || y < 0 || x >= w || y >= h || alpha <= 0.0 {
            return;
        }
        let a = alpha.min(1.0);
        let i = (y as usize * w as usize + x as usize) * 4;
        let d = &mut self.pixmap.data_mut()[i..i + 3];
        for (dst, src) in d.iter_mut().zip(c.0) {
            *dst = (*dst as f32 + (src as f32 - *dst as f32) * a).round() as u8;
        }
    }

    /// Fills an axis-aligned rectangle (anti-aliased edges).
    pub fn fill_rect(&mut self, x: f32, y: f32, w: f32, h: f32, c: Rgb) {
        if let Some(r) = Rect::from_xywh(x, y, w, h) {
            self.pixmap.fill_rect(r, &paint(c), Transform::identity(), None);
        }
    }

    /// Outlines a rectangle with a line of `width` pixels centred on its edge.
    pub fn stroke_rect(&mut self, x: f32, y: f32, w: f32, h: f32, width: f32, c: Rgb) {
        let pts = [(x, y), (x + w, y), (x + w, y + h), (x, y + h)];
        self.stroke_path(&pts, true, width, c);
    }

    /// A polyline with round joins and caps.
    pub fn polyline(&mut self, pts: &[(f32, f32)], width: f32, c: Rgb) {
        self.stroke_path(pts, false, width, c);
    }

    fn stroke_path(&mut self, pts: &[(f32, f32)], closed: bool, width: f32, c: Rgb) {
        let Some(&(x0, y0)) = pts.first() else { return };
        let mut pb = PathBuilder::new();
        pb.move_to(x0, y0);
        for &(x, y) in &pts[1..] {
            pb.line_to(x, y);
        }
        if closed {
            pb.close();
        }
        let Some(path) = pb.finish() else { return };
        let stroke = Stroke { width, line_cap: LineCap::Round, line_join: LineJoin::Round, ..Stroke::default() };
        self.pixmap.stroke_path(&path, &paint(c), &stroke, Transform::identity(), None);
    }

    /// A filled polygon.
    pub fn fill_polygon(&mut self, pts: &[(f32, f32)], c: Rgb) {
        let Some(&(x0, y0)) = pts.first() else { return };
        let mut pb = PathBuilder::new();
        pb.move_to(x0, y0);
        for &(x, y) in &pts[1..] {
            pb.line_to(x, y);
        }
        pb.close();
        if let Some(path) = pb.finish() {
            self.pixmap.fill_path(&path, &paint(c), FillRule::Winding, Transform::identity(), None);
        }
    }

    /// A filled disc with an outline ring of `ring` pixels (0 for none).
    pub fn disc(&mut self, cx: f32, cy: f32, r: f32, fill: Rgb, ring: f32, ring_colour: Rgb) {
        if ring > 0.0
            && let Some(p) = PathBuilder::from_circle(cx, cy, r + ring)
        {
            self.pixmap.fill_path(&p, &paint(ring_colour), FillRule::Winding, Transform::identity(), None);
        }
        if let Some(p) = PathBuilder::from_circle(cx, cy, r) {
            self.pixmap.fill_path(&p, &paint(fill), FillRule::Winding, Transform::identity(), None);
        }
    }

    /// Draws `text` at `px` pixels per em with its baseline at `y`; returns
    /// its width.
    pub fn text(&mut self, x: f32, y: f32, px: f32, c: Rgb, align: Align, text: &str) -> f32 {
        let w = font::text_width(px, text);
        let x0 = match align {
            Align::Left => x,
            Align::Centre => x - w / 2.0,
            Align::Right => x - w,
        };
        font::draw_text(px, x0.round(), y.round(), text, |x, y, cov| self.blend(x, y, c, cov));
        w
    }

    /// Text with a white halo, readable over any map colour.
    pub fn text_halo(&mut self, x: f32, y: f32, px: f32, c: Rgb, align: Align, text: &str) -> f32 {
        let halo = (px / 8.0).clamp(1.0, 3.0);
        for (dx, dy) in
            [(-1.0, 0.0), (1.0, 0.0), (0.0, -1.0), (0.0, 1.0), (-0.7, -0.7), (0.7, 0.7), (-0.7, 0.7), (0.7, -0.7)]
        {
            self.text(x + dx * halo, y + dy * halo, px, Rgb::WHITE, align, text);
        }
        self.text(x, y, px, c, align, text)
    }

    /// The picture as an 8-bit RGB PNG.
    pub fn encode_png(&self) -> Result<Vec<u8>, png::EncodingError> {
        let rgb: Vec<u8> = self.pixmap.data().chunks_exact(4).flat_map(|p| [p[0], p[1], p[2]]).collect();
        let mut out = Vec::new();
        let mut enc = png::Encoder::new(&mut out, self.width(), self.height());
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        enc.set_compression(png::Compression::Balanced);
        let mut w = enc.write_header()?;
        w.write_image_data(&rgb)?;
        w.finish()?;
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shapes_land_where_asked_and_png_round_trips() {
        let mut c = Canvas::new(40, 30, Rgb::WHITE).unwrap();
        c.fill_rect(5.0, 5.0, 10.0, 10.0, Rgb([255, 0, 0]));
        c.set(39, 29, Rgb([0, 0, 255]));
        c.set(40, 0, Rgb::BLACK); // outside: ignored
        c.blend(0, 0, Rgb::BLACK, 0.5);
        c.polyline(&[(20.0, 20.0), (35.0, 20.0)], 3.0, Rgb([0, 128, 0]));
        assert_eq!(c.get(10, 10), Some(Rgb([255, 0, 0])));
        assert_eq!(c.get(4, 10), Some(Rgb::WHITE));
        assert_eq!(c.get(39, 29), Some(Rgb([0, 0, 255])));
        assert_eq!(c.get(0, 0), Some(Rgb([128, 128, 128])));
        assert_eq!(c.get(27, 20), Some(Rgb([0, 128, 0])));
        let png = c.encode_png().unwrap();
        let dec = png::Decoder::new(std::io::Cursor::new(png));
        let mut r = dec.read_info().unwrap();
        let mut buf = vec![0; r.output_buffer_size().unwrap()];
        let info = r.next_frame(&mut buf).unwrap();
        assert_eq!((info.width, info.height, info.color_type), (40, 30, png::ColorType::Rgb));
        assert_eq!(&buf[(10 * 40 + 10) * 3..][..3], &[255, 0, 0]);
    }
}
