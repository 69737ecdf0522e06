//! Colours: two perceptually uniform colour maps as small tables, the change
//! categories' colours and names, and one colour per session.
//!
//! The tables are matplotlib's `viridis` and `plasma` sampled at `i / 16`
//! (17 stops, 8-bit sRGB) and interpolated linearly in between; that stays
//! within 5/255 per channel of matplotlib's 256-entry tables. Both go from
//! dark to light monotonically in lightness, so order reads the same in grey
//! and to colour-blind readers.

use crate::change::Category;

/// An opaque 8-bit sRGB colour.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Rgb(pub [u8; 3]);

impl Rgb {
    pub const WHITE: Rgb = Rgb([255, 255, 255]);
    pub const BLACK: Rgb = Rgb([0, 0, 0]);
    /// Text and frame lines.
    pub const INK: Rgb = Rgb([34, 34, 34]);
    /// Secondary text (subtitles, axis labels).
    pub const MUTED: Rgb = Rgb([100, 100, 100]);
    /// Background of the map area.
    pub const PAPER: Rgb = Rgb([255, 255, 255]);
    /// Context: the static map under changes and trajectories.
    pub const CONTEXT: Rgb = Rgb([214, 214, 214]);
    /// Metre grid lines on the map.
    pub const GRID: Rgb = Rgb([236, 236, 236]);

    /// `#rrggbb`, for the HTML report.
    pub fn hex(self) -> String {
        let [r, g, b] = self.0;
        format!("#{r:02x}{g:02x}{b:02x}")
    }
}

/// A colour map: a table of evenly spaced stops over `[0, 1]`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Colormap {
    pub name: &'static str,
    stops: &'static [[u8; 3]],
}

/// matplotlib `viridis` at `i / 16`: dark blue-violet (low) → green → yellow (high).
/// Used for height.
pub const VIRIDIS: Colormap = Colormap {
    name: "viridis",
    stops: &[
        [68, 1, 84],
        [72, 24, 106],
        [71, 45, 123],
        [66, 64, 134],
        [59, 82, 139],
        [51, 99, 141],
        [44, 114, 142],
        [38, 130, 142],
        [33, 145, 140],
        [31, 160, 136],
        [40, 174, 128],
        [63, 188, 115],
        [94, 201, 98],
        [132, 212, 75],
        [173, 220, 48],
        [216, 226, 25],
        [253, 231, 37],
    ],
};

/// matplotlib `plasma` at `i / 16`: deep blue (low) → magenta → orange → yellow
/// (high). Used for ε_g, so it never looks like the height map.
pub const PLASMA: Colormap = Colormap {
    name: "plasma",
    stops: &[
        [13, 8, 135],
        [49, 5, 151],
        [76, 2, 161],
        [102, 0, 167],
        [126, 3, 168],
        [149, 17, 161],
        [170, 35, 149],
        [188, 53, 135],
        [204, 71, 120],
        [218, 90, 106],
        [230, 108, 92],
        [240, 128, 78],
        [248, 149, 64],
        [253, 172, 51],
        [253, 197, 39],
        [248, 223, 37],
        [240, 249, 33],
    ],
};

impl Colormap {
    /// The colour at `t`, clamped to `[0, 1]`; NaN maps to the low end.
    pub fn at(&self, t: f32) -> Rgb {
        let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) };
        let last = self.stops.len() - 1;
        let f = t * last as f32;
        let i = (f.floor() as usize).min(last - 1);
        let w = f - i as f32;
        let (a, b) = (self.stops[i], self.stops[i + 1]);
        Rgb(std::array::from_fn(|c| (a[c] as f32 + (b[c] as f32 - a[c] as f32) * w).round() as u8))
    }

    /// The colour of `v` on a scale from `lo` to `hi`.
    pub fn of(&self, v: f32, lo: f32, hi: f32) -> Rgb {
        let span = hi - lo;
        self.at(if span > 0.0 { (v - lo) / span } else { 0.5 })
    }

    pub fn low(&self) -> Rgb {
        Rgb(self.stops[0])
    }
    pub fn high(&self) -> Rgb {
        Rgb(self.stops[self.stops.len() - 1])
    }
}

/// How a change category is shown: colour, the name a site manager knows it
/// by, and its place in the paint order (higher is painted over lower).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CategoryStyle {
    pub category: Category,
    pub label: &'static str,
    /// What it means, one short line.
    pub note: &'static str,
    pub colour: Rgb,
    pub priority: u8,
}

/// The change categories in legend order: what matters first, strong
/// colours (Okabe-Ito, distinguishable with colour-blindness) for changes
/// seen with evidence, pale tints for "not surveyed then" / "not seen now"
/// (coverage rather than change: they cover large areas and must not drown
/// the rest).
pub const CATEGORY_STYLES: [CategoryStyle; 5] = [
    CategoryStyle {
        category: Category::EmergedOverlap,
        label: "built / appeared",
        note: "next to structure seen before",
        colour: Rgb([0, 158, 115]),
        priority: 5,
    },
    CategoryStyle {
        category: Category::DeletedOverlap,
        label: "removed",
        note: "seen free now",
        colour: Rgb([213, 94, 0]),
        priority: 4,
    },
    CategoryStyle {
        category: Category::Coexist,
        label: "back again",
        note: "seen again after a removal",
        colour: Rgb([0, 114, 178]),
        priority: 3,
    },
    CategoryStyle {
        category: Category::EmergedNonOverlap,
        label: "first seen",
        note: "area not surveyed before",
        colour: Rgb([196, 224, 242]),
        priority: 2,
    },
    CategoryStyle {
        category: Category::DeletedNonOverlap,
        label: "not seen this time",
        note: "out of view, kept in the map",
        colour: Rgb([244, 224, 190]),
        priority: 1,
    },
];

/// The style of a change category (`Initial` has none: it is not a change).
pub fn category_style(c: Category) -> Option<&'static CategoryStyle> {
    CATEGORY_STYLES.iter().find(|s| s.category == c)
}

/// One colour per session, cycling: Okabe-Ito's eight without its yellow
/// (too light on white) plus two darker ones, in an order that keeps
/// neighbouring sessions far apart in hue.
const SESSION_COLOURS: [[u8; 3]; 9] = [
    [0, 114, 178],   // blue
    [213, 94, 0],    // vermillion
    [0, 158, 115],   // bluish green
    [204, 121, 167], // reddish purple
    [230, 159, 0],   // orange
    [86, 180, 233],  // sky blue
    [0, 0, 0],       // black
    [140, 86, 75],   // brown
    [120, 120, 120], // grey
];

/// The colour of the `index`-th session drawn (0-based).
pub fn session_colour(index: usize) -> Rgb {
    Rgb(SESSION_COLOURS[index % SESSION_COLOURS.len()])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ends_and_stops_are_exact() {
        for cm in [VIRIDIS, PLASMA] {
            assert_eq!(cm.at(0.0), cm.low());
            assert_eq!(cm.at(1.0), cm.high());
            assert_eq!(cm.at(-3.0), cm.low(), "clamped below");
            assert_eq!(cm.at(7.0), cm.high(), "clamped above");
            assert_eq!(cm.at(f32::NAN), cm.low());
            for (i, s) in cm.stops.iter().enumerate() {
                assert_eq!(cm.at(i as f32 / 16.0).0, *s, "{} stop {i}", cm.name);
            }
        }
        assert_eq!(VIRIDIS.at(0.5).0, [33, 145, 140]);
        assert_eq!(VIRIDIS.of(5.0, 0.0, 10.0), VIRIDIS.at(0.5));
        assert_eq!(VIRIDIS.of(3.0, 3.0, 3.0), VIRIDIS.at(0.5), "an empty range maps to the middle");
    }

    #[test]
    fn midpoints_interpolate_and_lightness_rises() {
        // Halfway between the first two viridis stops.
        assert_eq!(VIRIDIS.at(0.5 / 16.0).0, [70, 13, 95]);
        // Rec. 709 luma grows along both maps (what makes them readable in grey).
        for cm in [VIRIDIS, PLASMA] {
            let luma = |c: Rgb| 0.2126 * c.0[0] as f32 + 0.7152 * c.0[1] as f32 + 0.0722 * c.0[2] as f32;
            let mut last = -1.0;
            for i in 0..=64 {
                let l = luma(cm.at(i as f32 / 64.0));
                assert!(l > last, "{} luma falls at {i}/64", cm.name);
                last = l;
            }
        }
    }

    #[test]
    fn category_colours_are_distinct_and_every_change_has_one() {
        for (i, a) in CATEGORY_STYLES.iter().enumerate() {
            for b in &CATEGORY_STYLES[i + 1..] {
                let d: i32 = (0..3).map(|c| (a.colour.0[c] as i32 - b.colour.0[c] as i32).abs()).sum();
                assert!(d > 60, "{} and {} look alike", a.label, b.label);
                assert_ne!(a.priority, b.priority);
            }
            assert_ne!(a.colour, Rgb::CONTEXT);
        }
        for c in Category::ALL {
            assert_eq!(category_style(c).is_some(), c != Category::Initial, "{c}");
        }
        assert_eq!(session_colour(0), session_colour(9));
        assert_ne!(session_colour(0), session_colour(1));
        assert_eq!(Rgb([0, 114, 178]).hex(), "#0072b2");
    }
}
