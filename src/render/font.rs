//! Text: DejaVu Sans compiled into the binary (`assets/fonts/`, Bitstream
//! Vera licence), laid out left to right with kerning and rasterised with
//! `ab_glyph`. No system fonts, so pictures look the same everywhere.

use ab_glyph::{Font, FontRef, PxScale, ScaleFont, point};
use std::sync::OnceLock;

static FONT_BYTES: &[u8] = include_bytes!("../../assets/fonts/DejaVuSans.ttf");

fn font() -> &'static FontRef<'static> {
    static FONT: OnceLock<FontRef<'static>> = OnceLock::new();
    // The bytes are compiled in and checked by a test; parsing cannot fail
    // at run time unless the binary itself is damaged.
    FONT.get_or_init(|| FontRef::try_from_slice(FONT_BYTES).expect("the bundled DejaVu Sans parses"))
}

/// Width in pixels of `text` at `px` pixels per em.
pub fn text_width(px: f32, text: &str) -> f32 {
    let f = font().as_scaled(PxScale::from(px));
    let mut w = 0.0;
    let mut prev = None;
    for c in text.chars() {
        let id = f.glyph_id(c);
        if let Some(p) = prev {
            w += f.kern(p, id);
        }
        w += f.h_advance(id);
        prev = Some(id);
    }
    w
}

/// Height of capitals above the baseline, pixels (for centring text on a line).
pub fn cap_height(px: f32) -> f32 {
    // DejaVu Sans: cap height 1493 of 2048 units per em.
    px * 1493.0 / 2048.0
}

/// Rasterises `text` with its baseline starting at (`x`, `y`); `plot(x, y,
/// coverage)` receives every pixel it touches. Returns the advance width.
pub fn draw_text(px: f32, x: f32, y: f32, text: &str, mut plot: impl FnMut(i32, i32, f32)) -> f32 {
    let f = font().as_scaled(PxScale::from(px));
    let mut caret = x;
    let mut prev = None;
    for c in text.chars() {
        let id = f.glyph_id(c);
        if let Some(p) = prev {
            caret += f.kern(p, id);
        }
        let glyph = id.with_scale_and_position(px, point(caret, y));
        caret += f.h_advance(id);
        prev = Some(id);
        if let Some(outline) = font().outline_glyph(glyph) {
            let b = outline.px_bounds();
            outline.draw(|gx, gy, cov| plot(b.min.x as i32 + gx as i32, b.min.y as i32 + gy as i32, cov));
        }
    }
    caret - x
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bundled_font_parses_and_has_the_glyphs_pictures_use() {
        let f = font();
        for c in "ε_g ≥ 0.5 m³ × 10 · – — x y ↑ → é ñ ü".chars().filter(|c| !c.is_whitespace()) {
            assert_ne!(f.glyph_id(c).0, 0, "no glyph for {c:?}");
        }
    }

    #[test]
    fn width_grows_with_text_and_size_and_ink_lands_near_the_baseline() {
        assert_eq!(text_width(16.0, ""), 0.0);
        let a = text_width(16.0, "10 m");
        assert!(a > 20.0 && a < 50.0, "{a}");
        assert!((text_width(32.0, "10 m") - 2.0 * a).abs() < 0.5);
        let mut ink = Vec::new();
        let adv = draw_text(20.0, 10.0, 40.0, "H", |x, y, c| {
            if c > 0.5 {
                ink.push((x, y))
            }
        });
        assert!((adv - text_width(20.0, "H")).abs() < 1e-3);
        let top = ink.iter().map(|p| p.1).min().unwrap();
        let bottom = ink.iter().map(|p| p.1).max().unwrap();
        assert!((38..=40).contains(&bottom), "baseline at 40, bottom {bottom}");
        assert!((40 - top) as f32 >= cap_height(20.0) - 2.0, "cap top {top}");
        assert!(ink.iter().all(|p| p.0 >= 10 && (p.0 as f32) < 10.0 + adv));
    }
}
