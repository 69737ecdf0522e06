//! Free evidence from beams that returned nothing.
//!
//! A ray with an endpoint frees the voxels before it (`raycast`). A beam
//! that returns nothing frees nothing there, yet it says more: nothing
//! within the sensor's reach lay along it. That is the only evidence a
//! removed crane jib ever leaves. A jib is seen against the sky, so once it
//! is gone its beams return nothing at all, and no ray with an endpoint
//! crosses the space it took.
//!
//! The point cloud does not list the beams that returned nothing, so they
//! are found as holes. Each keyframe's returns are binned by direction, in
//! the sensor frame, into a [`NoReturnImage`] of 0.5° cells over the
//! sensor's field of view: a spinning sensor's 360° × elevation band
//! ([`Fov::Band`]) or a forward sensor's rectangle ([`Fov::Rect`]).
//! A direction counts as **no return** when no point fell in the window of
//! ± `margin` around it. The window is 1.5 beam spacings tall for a
//! spinning sensor seam knows (`EvidenceConfig::for_beam_spacing`: ± 1.5°
//! for a VLP-16's 2° rows, ± 0.54° for an OS1-64's 0.71°; ± 1.5° for an
//! unknown one), so it always holds a row of beams, and a lone beam lost to
//! dropout is never a hole: its neighbours returned. The Avia's rosette
//! covers the ellipse inscribed in its rectangle and leaves gaps up to
//! about 2.5° wide there in one 0.1 s frame, so a forward sensor's window
//! is twice the margin and must lie inside the ellipse whole (a test checks
//! the simulator's pattern; a real sensor's may differ, and
//! `no_return_margin_deg` sets both).
//!
//! ```text
//!   keyframe points ──► directions (sensor frame) ──► counts per 0.5° cell ──► summed-area table
//!   map voxel centre ──► R_wsᵀ (c − o) ──► window ± margin empty? ──► free, once, for this keyframe
//! ```
//!
//! What guards the static map (the evidence is only as good as "nothing
//! returned" is; a dark or grazing surface past its reach returns nothing
//! too):
//! - only directions at least `no_return_min_elevation_deg` above the
//!   horizontal in the world, so the ground and everything seen at grazing
//!   incidence below the sensor are never freed this way;
//! - only voxels within `no_return_range_m` of the sensor;
//! - only voxels of the earlier sessions' map that this session's points do
//!   not occupy: DOR and this session's cleaned map never see it, only
//!   change detection's deleted/overlap test does.
//!
//! - only voxels with none of this session's points within about
//!   `no_return_clear_m` (a building the session sees elsewhere is still
//!   there);
//! - only from at most `no_return_reach_factor` × the range the voxel was
//!   seen from ([`super::surface::MapPatch::seen_from_m`]): what returned at
//!   30 m may return nothing at 80 m.
//!
//! Change detection counts these keyframes' support in full
//! (`ChangeConfig::deleted_weight`).
//!
//! Measured (5 sessions × 150 keyframes, `seam eval changes`, permanent
//! structure kept static / removed objects' voxels left static, without →
//! with): the demo site (OS1-64, seed 1) 99.72 / 39.12 % → 99.71 / 30.45 %,
//! crane-jib leftovers 3,577 → 1,762 voxels; HDL-32E (seed 3) 99.77 / 45.47
//! → 99.69 / 44.08; VLP-16 (seed 3) 99.69 / 46.51 → 99.59 / 45.52. What the
//! sparse sensors lose is far neighbouring buildings' façades (0.5-0.6 % of
//! them): past their reach they return nothing even from close to where
//! they were seen. HDL-64E looks no higher than +2° and gets almost none
//! of this evidence. The Avia (seed 3, `omega_or_support`): 98.31 / 53.45 %
//! → 98.29 / 48.00 %, crane-jib leftovers 5,418 → 4,445 voxels, and object
//! changes with events in the right session 89.66 → 91.38 %.
//!
//! **Within a session** (`own_no_return_*`), the same beams free the
//! session's own voxels, for DOR: a truck crossing the view 30-70 m out, on
//! ground the sparse rings never reach, is seen against the sky, and once
//! it has driven on no ray with an endpoint crosses where it was. Its
//! voxels are freed by the keyframes whose beams there returned nothing,
//! under guards of their own (sparse sensors miss thin static structure
//! now and then, and that must not read as "gone"):
//! - only voxels at most `own_no_return_max_keyframes` (2) keyframes put a
//!   point in: what many keyframes saw is there;
//! - only with none of that keyframe's own points within about
//!   `own_no_return_clear_m` (2 m cells, the voxel's and its 26
//!   neighbours): a fence or scaffold is seen beside the part a few beams
//!   missed, and ground seen below keeps what stands on it;
//! - only within `own_no_return_range_m` (60 m) and at least
//!   `own_no_return_min_elevation_deg` (−1°) above the horizontal.
//!
//! Measured (`examples/dor_probe`, one 60-keyframe simulated session per
//! sensor, true poses, point-wise PR / F1, without → with): OS1-64 99.72 /
//! 92.08 → 99.67 / 94.07, HDL-32E 99.87 / 89.69 → 99.84 / 93.05, VLP-16
//! 99.60 / 87.34 → 99.49 / 91.16, HDL-64E 99.93 / 96.32 → 99.93 / 96.63,
//! Avia unchanged (95.38 → 95.37); SemanticKITTI 04 and 08 unchanged (no
//! voxel freed: the HDL-64E looks no higher than +2°, and what it sees
//! near the horizon has points beside it). On the VLP-16 (tried at 0°
//! first): keeping only the voxel itself clear, PR falls to 99.08 %,
//! fences and scaffolds first; with 1 m cells 99.36 %; a 100 m range costs
//! 0.3 (reach capped at 1.25 × the owner's range) to 1.9 points of PR;
//! without the keyframe limit PR is 0.01-0.04 lower for the same movers.
//!
//! Why by hand: a range image over the scan's own returns is a few lines of
//! binning and a summed-area table; no crate keeps one for a sensor band.

use crate::sensor::Fov;
use nalgebra::UnitQuaternion;
use rayon::prelude::*;
use rustc_hash::FxHashSet;

/// One keyframe's no-return test, as [`super::grid::InterestEvidence::add_keyframe_seeing`] takes it.
#[derive(Debug, Clone, Copy)]
pub struct NoReturn<'a> {
    pub image: &'a NoReturnImage,
    /// The keyframe's orientation (sensor to world).
    pub r_world_sensor: UnitQuaternion<f64>,
    /// The rows of the evidence this keyframe may free this way, ascending.
    /// With `clear_m` = 0 they must hold none of the keyframe's points (no
    /// hit to merge with).
    pub candidates: &'a [u32],
    /// Per candidate, the farthest a beam may be from it, m; empty: `range_m`
    /// for all.
    pub candidate_range_m: &'a [f32],
    pub range_m: f64,
    /// World elevation of the direction from the sensor, at least.
    pub min_elevation_deg: f64,
    /// When given, a candidate is freed only with none of the keyframe's own
    /// points in its cell or one of the 26 around: the cells (of this many
    /// voxels a side) the keyframe's points fall in. A structure the
    /// keyframe sees there, or beside it, is still there where a few beams
    /// missed it.
    pub clear_cells: Option<(&'a FxHashSet<[i32; 3]>, i32)>,
}

/// Edge of a cell, degrees.
const CELL_DEG: f64 = 0.5;

/// A forward sensor's window is this many times the configured margin. The
/// Avia's rosette leaves gaps up to about 2.5° wide inside its ellipse in
/// one 0.1 s frame (the simulator's pattern: 89 of 3,500 directions inside
/// it look like holes at ±1.5°, 4 at ±2.5°, none at ±3°).
pub(super) const FORWARD_MARGIN_FACTOR: f64 = 2.0;

/// Which directions of one keyframe returned nothing.
#[derive(Debug, Clone)]
pub struct NoReturnImage {
    elev_min_deg: f64,
    elev_max_deg: f64,
    /// Azimuth of the first column's left edge, degrees.
    az_min_deg: f64,
    /// A band's columns go round (360°); a forward sensor's do not, and
    /// its pattern covers the ellipse inscribed in its rectangle, half-axes
    /// (azimuth, elevation) in degrees.
    ellipse_deg: Option<(f64, f64)>,
    rows: usize,
    cols: usize,
    /// Summed-area table of the counts, `(rows + 1) × (cols + 1)`.
    sat: Vec<u32>,
    margin_deg: f64,
}

/// Azimuth and elevation of direction `d`, degrees; `None` for a zero or
/// non-finite one. Cells are 0.5° wide, so [`atan2_deg`]'s 0.001° is exact
/// enough; libm's `atan2` and `hypot` were a third of what the no-return
/// images cost on a SemanticKITTI sequence.
fn deg_of(d: &[f64; 3]) -> Option<(f64, f64)> {
    let h = (d[0] * d[0] + d[1] * d[1]).sqrt();
    if !(h.is_finite() && d[2].is_finite()) || (h == 0.0 && d[2] == 0.0) {
        return None;
    }
    Some((atan2_deg(d[1], d[0]), atan2_deg(d[2], h)))
}

/// `y.atan2(x)` in degrees, within 0.001° (a minimax polynomial for atan on
/// [0, 1], after folding the octants); 0 for (0, 0).
fn atan2_deg(y: f64, x: f64) -> f64 {
    let (ax, ay) = (x.abs(), y.abs());
    let (lo, hi) = if ay > ax { (ax, ay) } else { (ay, ax) };
    if hi == 0.0 {
        return 0.0;
    }
    let t = lo / hi;
    let t2 = t * t;
    let mut a = t
        * (0.999_977_26
            + t2 * (-0.332_623_47
                + t2 * (0.193_543_46 + t2 * (-0.116_432_87 + t2 * (0.052_653_32 - t2 * 0.011_721_20)))));
    if ay > ax {
        a = std::f64::consts::FRAC_PI_2 - a;
    }
    if x < 0.0 {
        a = std::f64::consts::PI - a;
    }
    if y < 0.0 {
        a = -a;
    }
    a.to_degrees()
}

impl NoReturnImage {
    /// Bins a keyframe's returns (sensor frame) over the sensor's field of
    /// view: a spinning band's 360° × elevations, or a forward sensor's
    /// azimuth × elevation rectangle about +x. `None` for an empty field of
    /// view or margin.
    pub fn build(points_sensor_m: &[[f32; 3]], fov: &Fov, margin_deg: f64) -> Option<NoReturnImage> {
        Self::build_above(points_sensor_m, fov, margin_deg, -90.0)
    }

    /// [`Self::build`] for tests that never look at directions within the
    /// margin of elevations below `skip_below_deg` (sensor frame): the
    /// returns below it are not binned (most of a scan is the ground below
    /// the sensor; this spares them the trigonometry).
    pub fn build_above(
        points_sensor_m: &[[f32; 3]],
        fov: &Fov,
        margin_deg: f64,
        skip_below_deg: f64,
    ) -> Option<NoReturnImage> {
        let (elev_min_deg, elev_max_deg, az_min_deg, az_span_deg, ellipse_deg, margin_deg) = match *fov {
            Fov::Band { elev_min_deg, elev_max_deg } => (elev_min_deg, elev_max_deg, -180.0, 360.0, None, margin_deg),
            Fov::Rect { azimuth_deg, elevation_deg } => {
                let half = (azimuth_deg / 2.0, elevation_deg / 2.0);
                (-half.1, half.1, -half.0, azimuth_deg, Some(half), FORWARD_MARGIN_FACTOR * margin_deg)
            }
        };
        let wraps = ellipse_deg.is_none();
        if !(elev_max_deg > elev_min_deg && az_span_deg > 0.0 && margin_deg > 0.0) {
            return None;
        }
        let rows = ((elev_max_deg - elev_min_deg) / CELL_DEG).ceil() as usize + 1;
        let cols = if wraps { (360.0 / CELL_DEG) as usize } else { (az_span_deg / CELL_DEG).ceil() as usize + 1 };
        let skip_tan = skip_below_deg.clamp(-89.0, 89.0).to_radians().tan() as f32;
        // The cell of each return binned, in parallel; then counted.
        let cells: Vec<u32> = points_sensor_m
            .par_iter()
            .with_min_len(8192)
            .filter_map(|p| {
                if p[2] < skip_tan * (p[0] * p[0] + p[1] * p[1]).sqrt() {
                    return None;
                }
                let (az, el) = deg_of(&p.map(f64::from))?;
                let r = ((el - elev_min_deg) / CELL_DEG).floor();
                let c = ((az - az_min_deg) / CELL_DEG).floor();
                if !(0.0..rows as f64).contains(&r) || !(0.0..cols as f64 + 1.0).contains(&c) {
                    return None;
                }
                Some((r as usize * cols + (c as usize).min(cols - 1)) as u32)
            })
            .collect();
        let mut counts = vec![0u32; rows * cols];
        for c in cells {
            counts[c as usize] += 1;
        }
        let w = cols + 1;
        let mut sat = vec![0u32; (rows + 1) * w];
        for r in 0..rows {
            let mut line = 0u32;
            for c in 0..cols {
                line += counts[r * cols + c];
                sat[(r + 1) * w + c + 1] = sat[r * w + c + 1] + line;
            }
        }
        Some(NoReturnImage { elev_min_deg, elev_max_deg, az_min_deg, ellipse_deg, rows, cols, sat, margin_deg })
    }

    /// Returns in rows `r0..r1`, columns `c0..c1` (half-open, no wrap).
    fn sum(&self, r0: usize, r1: usize, c0: usize, c1: usize) -> u32 {
        let w = self.cols + 1;
        let at = |r: usize, c: usize| self.sat[r * w + c];
        at(r1, c1) + at(r0, c0) - at(r0, c1) - at(r1, c0)
    }

    /// Whether no return fell within the margin of direction `d` (sensor
    /// frame, any length). Directions outside the field of view are never
    /// "no return": the sensor did not look there. A forward sensor's
    /// window must lie inside the ellipse its pattern covers, whole.
    pub fn is_empty_around(&self, d: &[f64; 3]) -> bool {
        let Some((az, el)) = deg_of(d) else { return false };
        if el < self.elev_min_deg || el > self.elev_max_deg {
            return false;
        }
        let m = self.margin_deg;
        if let Some((a, b)) = self.ellipse_deg
            && ((az.abs() + m) / a).powi(2) + ((el.abs() + m) / b).powi(2) > 1.0
        {
            return false;
        }
        let row = |e: f64| (((e - self.elev_min_deg) / CELL_DEG).floor().max(0.0) as usize).min(self.rows - 1);
        let (r0, r1) = (row(el - m), row(el + m) + 1);
        let col = |a: f64| ((a - self.az_min_deg) / CELL_DEG).floor() as i64;
        let (c0, c1) = (col(az - m), col(az + m) + 1);
        let n = self.cols as i64;
        let count = if self.ellipse_deg.is_some() {
            self.sum(r0, r1, c0.clamp(0, n) as usize, c1.clamp(0, n) as usize)
        } else if c1 - c0 >= n {
            self.sum(r0, r1, 0, self.cols)
        } else {
            let (a, b) = (c0.rem_euclid(n) as usize, c1.rem_euclid(n) as usize);
            if a < b || b == 0 {
                self.sum(r0, r1, a, if b == 0 { self.cols } else { b })
            } else {
                self.sum(r0, r1, a, self.cols) + self.sum(r0, r1, 0, b)
            }
        };
        count == 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const OS1: Fov = Fov::Band { elev_min_deg: -22.5, elev_max_deg: 22.5 };

    fn dir(az_deg: f64, el_deg: f64) -> [f64; 3] {
        let (a, e) = (az_deg.to_radians(), el_deg.to_radians());
        [e.cos() * a.cos(), e.cos() * a.sin(), e.sin()]
    }

    /// A spinning sensor's returns: `beams` rows over the band, 1024 columns,
    /// except where `hole(az, el)` says the beam returned nothing.
    fn scan(beams: usize, lo: f64, hi: f64, hole: impl Fn(f64, f64) -> bool) -> Vec<[f32; 3]> {
        let mut out = Vec::new();
        for b in 0..beams {
            let el = lo + (hi - lo) * b as f64 / (beams - 1) as f64;
            for c in 0..1024 {
                let az = -180.0 + 360.0 * c as f64 / 1024.0;
                if !hole(az, el) {
                    out.push(dir(az, el).map(|x| (x * 20.0) as f32));
                }
            }
        }
        out
    }

    #[test]
    fn atan2_deg_is_libms_within_a_thousandth_of_a_degree() {
        let mut worst = 0.0f64;
        for i in 0..20_000 {
            let a = (i as f64 / 20_000.0) * std::f64::consts::TAU - std::f64::consts::PI;
            for r in [1e-3, 0.7, 35.0] {
                let (y, x) = (r * a.sin(), r * a.cos());
                worst = worst.max((atan2_deg(y, x) - y.atan2(x).to_degrees()).abs());
            }
        }
        assert!(worst < 1e-3, "worst error {worst}°");
        assert_eq!(atan2_deg(0.0, 0.0), 0.0);
        assert_eq!(atan2_deg(0.0, -2.0), 180.0);
        assert_eq!(atan2_deg(3.0, 0.0), 90.0);
        assert_eq!(atan2_deg(-3.0, 0.0), -90.0);
    }

    #[test]
    fn a_full_scan_has_no_holes_and_a_sky_region_is_one() {
        let full = NoReturnImage::build(&scan(64, -22.5, 22.5, |_, _| false), &OS1, 1.5).unwrap();
        for az in [-179.9, -90.0, 0.0, 45.3, 179.9] {
            for el in [-22.5, -10.0, 0.0, 12.2, 22.5] {
                assert!(!full.is_empty_around(&dir(az, el)), "{az} {el}");
            }
        }
        // Above 5° between azimuths 20° and 80° nothing returned.
        let sky =
            NoReturnImage::build(&scan(64, -22.5, 22.5, |az, el| el > 5.0 && (20.0..80.0).contains(&az)), &OS1, 1.5)
                .unwrap();
        assert!(sky.is_empty_around(&dir(50.0, 15.0)));
        assert!(sky.is_empty_around(&dir(50.0, 22.4)), "at the top of the band");
        assert!(!sky.is_empty_around(&dir(50.0, 5.5)), "within the margin of the returns below");
        assert!(!sky.is_empty_around(&dir(21.0, 15.0)), "within the margin of the returns beside");
        assert!(!sky.is_empty_around(&dir(50.0, 30.0)), "above the band: not looked at");
        assert!(!sky.is_empty_around(&dir(100.0, 15.0)));
    }

    #[test]
    fn lone_dropouts_and_sparse_rows_are_not_holes() {
        // Every 7th beam of every 3rd column lost, and a VLP-16's 2° rows.
        let dropped = NoReturnImage::build(
            &scan(64, -22.5, 22.5, |az, el| ((az * 10.0) as i64 % 3 == 0) && ((el * 10.0) as i64 % 7 == 0)),
            &OS1,
            1.5,
        )
        .unwrap();
        let vlp = NoReturnImage::build(
            &scan(16, -15.0, 15.0, |_, _| false),
            &Fov::Band { elev_min_deg: -15.0, elev_max_deg: 15.0 },
            1.5,
        )
        .unwrap();
        for az in (-180..180).step_by(7) {
            for el in (-150..=150).step_by(5) {
                let d = dir(az as f64 + 0.3, el as f64 / 10.0);
                assert!(!dropped.is_empty_around(&d), "{az} {el}");
                assert!(!vlp.is_empty_around(&d), "{az} {el}");
            }
        }
    }

    #[test]
    fn the_window_wraps_around_the_back() {
        let img =
            NoReturnImage::build(&scan(64, -22.5, 22.5, |az, el| el > 0.0 && az.abs() > 170.0), &OS1, 1.5).unwrap();
        assert!(img.is_empty_around(&dir(180.0, 10.0)));
        assert!(img.is_empty_around(&dir(-179.0, 10.0)));
        assert!(!img.is_empty_around(&dir(171.0, 10.0)), "returns at 170° are within the margin");
    }

    #[test]
    fn an_empty_field_of_view_or_margin_has_no_image() {
        assert!(NoReturnImage::build(&[], &Fov::Rect { azimuth_deg: 0.0, elevation_deg: 77.0 }, 1.5).is_none());
        assert!(NoReturnImage::build(&[], &OS1, 0.0).is_none());
    }

    /// The Avia's rosette covers the ellipse inscribed in its 70.4° × 77.2°
    /// rectangle and, at a forward sensor's wider window, leaves no hole
    /// there in one 0.1 s frame: a window with no return is a beam that
    /// returned nothing. The corners and the ellipse's rim never count.
    #[test]
    fn a_forward_sensors_rosette_has_no_holes_but_a_sky_region_is_one() {
        use crate::sensor::SensorModel;
        use crate::sim::ray_directions;
        let avia = Fov::Rect { azimuth_deg: 70.4, elevation_deg: 77.2 };
        let grid = || (-36..=36).flat_map(|az| (-40..=40).map(move |el| dir(az as f64 + 0.25, el as f64 + 0.25)));
        for frame in 0..5 {
            let dirs = ray_directions(SensorModel::Avia, 0.1 * frame as f64 + 0.037, 0.0);
            let all: Vec<[f32; 3]> = dirs.iter().map(|d| d.map(|x| (x * 20.0) as f32)).collect();
            let img = NoReturnImage::build(&all, &avia, 1.5).unwrap();
            let holes = grid().filter(|d| img.is_empty_around(d)).count();
            assert_eq!(holes, 0, "frame {frame}: {holes} directions look like holes");
            // Above 10° elevation nothing returned: the sky.
            let below: Vec<[f32; 3]> =
                all.iter().copied().filter(|p| deg_of(&p.map(f64::from)).unwrap().1 <= 10.0).collect();
            let sky = NoReturnImage::build(&below, &avia, 1.5).unwrap();
            let sky_holes = grid().filter(|d| sky.is_empty_around(d)).count();
            assert!(sky_holes > 700, "frame {frame}: only {sky_holes} sky directions are holes");
            assert!(sky.is_empty_around(&dir(0.0, 20.0)));
            assert!(sky.is_empty_around(&dir(-15.0, 25.0)));
            assert!(!sky.is_empty_around(&dir(0.0, 12.0)), "within the margin of the returns below");
            assert!(!sky.is_empty_around(&dir(-30.0, 30.0)), "a corner of the rectangle, outside the ellipse");
            assert!(!sky.is_empty_around(&dir(0.0, 37.0)), "at the rim");
            assert!(!sky.is_empty_around(&dir(60.0, 20.0)), "outside the field of view");
            assert!(!sky.is_empty_around(&dir(180.0, 20.0)), "behind the sensor");
        }
    }
}
