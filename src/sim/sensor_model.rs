//! Beam patterns and return models of the simulated sensors.
//!
//! Spinning sensors fire a fixed column of beams (elevation table) at evenly
//! spaced azimuths; the first column's azimuth changes from scan to scan by a
//! fraction of a column, as a real free-running sensor's does. The Livox Avia
//! draws a non-repetitive rosette: each of its six lasers is deflected by two
//! counter-rotating Risley prisms (7294 and 4664 rpm, as in Livox's Mid/Avia
//! family), so a 0.1 s frame covers a flower of ~20 petals whose orientation
//! keeps turning from frame to frame.
//!
//! Directions are in the LiDAR frame: x forward, y left, z up.

use crate::sensor::SensorModel;

/// What a sensor returns and how well.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct SensorSpec {
    /// Range at which a target of 80 % reflectivity at normal incidence is
    /// still detected, m; also the hard limit.
    pub max_range_m: f64,
    /// Closer returns are blanked.
    pub min_range_m: f64,
    /// Standard deviation of the range noise, m.
    pub range_sigma_m: f64,
    /// Fraction of returns lost at random.
    pub dropout: f64,
}

pub(crate) fn spec(model: SensorModel) -> SensorSpec {
    let (max_range_m, min_range_m, range_sigma_m, dropout) = match model {
        SensorModel::Os1_64 => (120.0, 0.5, 0.015, 0.03),
        SensorModel::Vlp16 => (100.0, 0.5, 0.02, 0.03),
        SensorModel::Hdl64e => (120.0, 0.9, 0.015, 0.03),
        SensorModel::Hdl32e => (100.0, 0.5, 0.02, 0.03),
        SensorModel::Avia => (190.0, 1.0, 0.02, 0.02),
    };
    SensorSpec { max_range_m, min_range_m, range_sigma_m, dropout }
}

fn direction(azimuth_rad: f64, elevation_rad: f64) -> [f64; 3] {
    let (se, ce) = elevation_rad.sin_cos();
    let (sa, ca) = azimuth_rad.sin_cos();
    [ce * ca, ce * sa, se]
}

/// Avia: 6 lasers × 4000 shots in a 0.1 s frame (240 k points/s).
const AVIA_LASERS: usize = 6;
const AVIA_SHOTS_PER_LASER: usize = 4000;
const AVIA_HALF_FOV_DEG: [f64; 2] = [35.2, 38.6];
/// Prism rotation rates, Hz (7294 rpm and -4664 rpm).
const AVIA_PRISM_HZ: [f64; 2] = [7294.0 / 60.0, 4664.0 / 60.0];

/// The unit ray directions of one scan starting at `time_s`; `phase` in
/// [0, 1) shifts a spinning sensor's columns by that fraction of a column.
pub(crate) fn ray_directions(model: SensorModel, time_s: f64, phase: f64) -> Vec<[f64; 3]> {
    let deg = std::f64::consts::PI / 180.0;
    if let Some((elev, cols)) = model.beams() {
        let elev_rad: Vec<f64> = elev.iter().map(|e| e * deg).collect();
        let mut dirs = Vec::with_capacity(elev.len() * cols);
        for c in 0..cols {
            let az = std::f64::consts::TAU * (c as f64 + phase) / cols as f64;
            for &e in &elev_rad {
                dirs.push(direction(az, e));
            }
        }
        return dirs;
    }
    let tau = std::f64::consts::TAU;
    let mut dirs = Vec::with_capacity(AVIA_LASERS * AVIA_SHOTS_PER_LASER);
    for i in 0..AVIA_SHOTS_PER_LASER {
        let t = time_s + 0.1 * i as f64 / AVIA_SHOTS_PER_LASER as f64;
        let (a1, a2) = (tau * AVIA_PRISM_HZ[0] * t, -tau * AVIA_PRISM_HZ[1] * t);
        let u = 0.5 * (a1.cos() + a2.cos());
        let v = 0.5 * (a1.sin() + a2.sin());
        for l in 0..AVIA_LASERS {
            // The six lasers sit in a short vertical line, 1.2° apart.
            let az = u * AVIA_HALF_FOV_DEG[0];
            let el = v * AVIA_HALF_FOV_DEG[1] + (l as f64 - 2.5) * 1.2;
            if az.abs() <= AVIA_HALF_FOV_DEG[0] && el.abs() <= AVIA_HALF_FOV_DEG[1] {
                dirs.push(direction(az * deg, el * deg));
            }
        }
    }
    dirs
}

/// True when a sensor-frame point lies in the model's field of view
/// (with `tol_deg` of slack for noise and round-off).
#[cfg(test)]
pub(crate) fn in_fov(model: SensorModel, p: [f64; 3], tol_deg: f64) -> bool {
    let r_xy = p[0].hypot(p[1]);
    let elev = p[2].atan2(r_xy).to_degrees();
    match model.fov() {
        crate::sensor::Fov::Band { elev_min_deg, elev_max_deg } => {
            elev >= elev_min_deg - tol_deg && elev <= elev_max_deg + tol_deg
        }
        crate::sensor::Fov::Rect { azimuth_deg, elevation_deg } => {
            let az = p[1].atan2(p[0]).to_degrees();
            az.abs() <= azimuth_deg / 2.0 + tol_deg && elev.abs() <= elevation_deg / 2.0 + tol_deg
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ray_counts_match_the_data_sheets() {
        assert_eq!(ray_directions(SensorModel::Os1_64, 0.0, 0.0).len(), 65_536);
        assert_eq!(ray_directions(SensorModel::Vlp16, 0.0, 0.0).len(), 28_800);
        assert_eq!(ray_directions(SensorModel::Hdl64e, 0.0, 0.3).len(), 64 * 2083);
        let avia = ray_directions(SensorModel::Avia, 12.3, 0.0).len();
        assert!((20_000..=24_000).contains(&avia), "{avia}");
    }

    #[test]
    fn every_ray_is_unit_and_in_the_field_of_view() {
        for m in SensorModel::ALL {
            for d in ray_directions(m, 3.7, 0.5) {
                assert!(((d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt() - 1.0).abs() < 1e-12);
                assert!(in_fov(m, d, 1e-9), "{m:?} {d:?}");
            }
        }
    }

    #[test]
    fn avia_rosette_changes_between_frames_and_fills_the_centre() {
        let a = ray_directions(SensorModel::Avia, 0.0, 0.0);
        let b = ray_directions(SensorModel::Avia, 0.8, 0.0);
        let same = a.iter().zip(&b).filter(|(p, q)| (p[1] - q[1]).abs() + (p[2] - q[2]).abs() < 1e-3).count();
        assert!(same < a.len() / 10, "{same} of {} rays repeat", a.len());
        let central = a.iter().filter(|d| d[1].abs() < 0.1 && d[2].abs() < 0.1).count();
        let per_area_centre = central as f64 / 0.04;
        assert!(per_area_centre > a.len() as f64 / 2.0, "the rosette is densest at its centre");
        // Coverage: most 2°×2° cells of the inner field get a ray within 5 frames.
        let mut seen = std::collections::HashSet::new();
        for f in 0..5 {
            for d in ray_directions(SensorModel::Avia, 0.8 * f as f64, 0.0) {
                let az = d[1].atan2(d[0]).to_degrees();
                let el = d[2].atan2(d[0].hypot(d[1])).to_degrees();
                seen.insert(((az / 2.0).floor() as i32, (el / 2.0).floor() as i32));
            }
        }
        let inner = (-12..12).flat_map(|i| (-12..12).map(move |j| (i, j))).filter(|(i, j)| {
            let (a, e) = ((*i as f64 + 0.5) * 2.0 / 30.0, (*j as f64 + 0.5) * 2.0 / 33.0);
            a * a + e * e < 1.0
        });
        let (n, hit) = inner.fold((0, 0), |(n, h), c| (n + 1, h + seen.contains(&c) as usize));
        assert!(hit as f64 > 0.9 * n as f64, "{hit} of {n} cells covered");
    }
}
