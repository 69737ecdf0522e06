//! DOP reliability of a registration (paper eq. 1, MATH.md §4).
//!
//! For unit bearings `u_k` from the sensor to the points (after downsampling
//! at `voxel_size_m`):
//!
//! ```text
//! G = (1/N) Σ u_k u_kᵀ,   DOP = sqrt(tr G⁻¹) / sqrt(N),   ρ = DOP · sqrt(N_typ) / g0
//! N_typ = Ω R̄² / v²
//! ```
//!
//! `g0` is `sqrt(tr G⁻¹)` of bearings spread uniformly over the sensor's FoV
//! and `Ω` the FoV's solid angle, so a scan that sees its whole FoV has
//! ρ ≈ 1 whatever the sensor (the paper's Fig. 3). A match is trusted only if
//! the points that found a correspondence are not much worse spread than the
//! scan itself: `ρ_corr / ρ_scan ≤ κ` and `ρ_corr ≤ ρ_max`.
//!
//! `R̄` is the mean range of the point set that ρ is computed for (the scan's
//! for ρ_scan, the corresponded points' for ρ_corr), as MATH.md §4 reads.

use super::downsample::{Point3Like, voxel_downsample};
use super::gicp::GicpResult;
use crate::sensor::Fov;
use nalgebra::{Matrix3, SymmetricEigen, Vector3};
use serde::{Deserialize, Serialize};

/// Settings of the DOP test (MATH.md §4).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DopConfig {
    /// Downsampling voxel before the bearings are counted (MATH.md: 0.5 m).
    pub voxel_size_m: f64,
    /// Largest accepted `ρ_corr / ρ_scan` (choice: 2.0).
    pub kappa: f64,
    /// Largest accepted `ρ_corr` (MATH.md's choice: 3.0; seam's: 6.0). ρ ≈ 1
    /// assumes returns from the whole FoV, but outdoors the sky returns
    /// nothing: SemanticKITTI HDL-64E scans have ρ_scan 1.8-2.1, simulated
    /// OS1-64 and VLP-16 scans 1.3-3.3, Avia scans 1.8-5.2 (`examples/rho_probe`,
    /// `examples/loop_table`). Correct matches in the Table I analogue had
    /// ρ_corr up to 3.02 (OS1-64) and 5.32 (Avia): 3.0 rejected 90-100 % of
    /// correct Avia matches and most OS1-64 loops on the simulated site.
    pub rho_max: f64,
}

impl Default for DopConfig {
    fn default() -> Self {
        DopConfig { voxel_size_m: 0.5, kappa: 2.0, rho_max: 6.0 }
    }
}

/// Smallest eigenvalue of `G` (whose trace is 1) still taken as full rank.
const MIN_EIGENVALUE: f64 = 1e-9;
/// Points closer than this to the sensor have no meaningful bearing.
const MIN_RANGE_M: f64 = 1e-3;

/// `sqrt(tr G⁻¹)` for bearings uniform over the FoV (closed forms of MATH.md §4).
pub fn g0(fov: &Fov) -> f64 {
    match *fov {
        Fov::Band { elev_min_deg, elev_max_deg } => {
            let (s1, s2) = (elev_min_deg.to_radians().sin(), elev_max_deg.to_radians().sin());
            // b = E[z²] for z = sin(elevation) uniform in [s1, s2].
            let b = (s2.powi(3) - s1.powi(3)) / (3.0 * (s2 - s1));
            (4.0 / (1.0 - b) + 1.0 / b).sqrt()
        }
        Fov::Rect { azimuth_deg, elevation_deg } => {
            let ah = 0.5 * azimuth_deg.to_radians();
            let beta = 0.5 * elevation_deg.to_radians();
            let k = (2.0 * ah).sin() / (4.0 * ah);
            let z2 = beta.sin().powi(2) / 3.0;
            let c = 1.0 - z2;
            (1.0 / (c * (0.5 + k)) + 1.0 / (c * (0.5 - k)) + 1.0 / z2).sqrt()
        }
    }
}

/// Solid angle of the FoV in steradians.
pub fn solid_angle_sr(fov: &Fov) -> f64 {
    match *fov {
        Fov::Band { elev_min_deg, elev_max_deg } => {
            2.0 * std::f64::consts::PI * (elev_max_deg.to_radians().sin() - elev_min_deg.to_radians().sin())
        }
        Fov::Rect { azimuth_deg, elevation_deg } => {
            4.0 * (0.5 * azimuth_deg.to_radians()) * (0.5 * elevation_deg.to_radians()).sin()
        }
    }
}

/// ρ of one point set, with the numbers it came from.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct RhoReport {
    /// Points after the DOP downsampling (N).
    pub n: usize,
    /// Mean range of those points (R̄, m).
    pub mean_range_m: f64,
    /// `Ω R̄² / v²`.
    pub n_typ: f64,
    pub g0: f64,
    /// `sqrt(tr G⁻¹) / sqrt(N)`; infinite when G is singular or N = 0.
    pub dop: f64,
    /// `DOP · sqrt(N_typ) / g0`; infinite when G is singular or N = 0.
    pub rho: f64,
}

/// `sqrt(tr G⁻¹)` of unit bearings, or infinity when G has rank < 3.
pub fn bearing_spread(bearings: impl Iterator<Item = Vector3<f64>>) -> f64 {
    let mut g = Matrix3::zeros();
    let mut n = 0usize;
    for u in bearings {
        g += u * u.transpose();
        n += 1;
    }
    if n == 0 {
        return f64::INFINITY;
    }
    g /= n as f64;
    let eig = SymmetricEigen::new(g);
    // `l.is_nan()` included: a NaN bearing must not pass as full rank.
    if eig.eigenvalues.iter().any(|&l| l.is_nan() || l <= MIN_EIGENVALUE) {
        return f64::INFINITY;
    }
    eig.eigenvalues.iter().map(|l| 1.0 / l).sum::<f64>().sqrt()
}

/// ρ of points given in the sensor frame (the sensor at the origin), after
/// downsampling at `voxel_size_m`, normalised for `fov`.
pub fn rho<P: Point3Like>(points_sensor: &[P], fov: &Fov, voxel_size_m: f64) -> RhoReport {
    let down = voxel_downsample(points_sensor, voxel_size_m, false);
    let bearings: Vec<(Vector3<f64>, f64)> = down
        .iter()
        .map(|p| Vector3::from(*p))
        .filter_map(|p| {
            let r = p.norm();
            (r > MIN_RANGE_M).then(|| (p / r, r))
        })
        .collect();
    let n = bearings.len();
    let mean_range_m = if n == 0 { 0.0 } else { bearings.iter().map(|b| b.1).sum::<f64>() / n as f64 };
    let n_typ = solid_angle_sr(fov) * mean_range_m * mean_range_m / (voxel_size_m * voxel_size_m);
    let g0 = g0(fov);
    let spread = bearing_spread(bearings.iter().map(|b| b.0));
    if n == 0 {
        return RhoReport { n, mean_range_m, n_typ, g0, dop: f64::INFINITY, rho: f64::INFINITY };
    }
    let dop = spread / (n as f64).sqrt();
    RhoReport { n, mean_range_m, n_typ, g0, dop, rho: dop * n_typ.sqrt() / g0 }
}

/// Why a match passed or failed the DOP test.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DopReason {
    Accepted,
    /// The scan itself does not see three independent directions (ρ_scan = ∞).
    ScanDegenerate,
    /// The matched points do not see three independent directions (ρ_corr = ∞).
    CorrespondencesDegenerate,
    /// `ρ_corr / ρ_scan > κ`: the match uses a much narrower spread than the scan has.
    RatioAboveKappa,
    /// `ρ_corr > ρ_max`: the matched points constrain the pose poorly in absolute terms.
    RhoCorrAboveMax,
}

impl std::fmt::Display for DopReason {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            DopReason::Accepted => "accepted",
            DopReason::ScanDegenerate => "the scan's bearings span fewer than 3 directions (rho_scan infinite)",
            DopReason::CorrespondencesDegenerate => {
                "the matched points' bearings span fewer than 3 directions (rho_corr infinite)"
            }
            DopReason::RatioAboveKappa => "rho_corr / rho_scan exceeds kappa: the matched points are badly spread",
            DopReason::RhoCorrAboveMax => "rho_corr exceeds rho_max: the matched points constrain the pose poorly",
        })
    }
}

/// The DOP test's verdict on one candidate edge (stored with it, MATH.md §4).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DopVerdict {
    pub rho_scan: f64,
    pub rho_corr: f64,
    /// `ρ_corr / ρ_scan` (infinite or NaN when a ρ is infinite).
    pub ratio: f64,
    pub accepted: bool,
    pub reason: DopReason,
}

/// The ratio test: accept if `ρ_corr / ρ_scan ≤ κ` and `ρ_corr ≤ ρ_max`.
pub fn ratio_test(rho_scan: f64, rho_corr: f64, cfg: &DopConfig) -> DopVerdict {
    let ratio = rho_corr / rho_scan;
    let reason = if !rho_scan.is_finite() {
        DopReason::ScanDegenerate
    } else if !rho_corr.is_finite() {
        DopReason::CorrespondencesDegenerate
    } else if ratio > cfg.kappa {
        DopReason::RatioAboveKappa
    } else if rho_corr > cfg.rho_max {
        DopReason::RhoCorrAboveMax
    } else {
        DopReason::Accepted
    };
    DopVerdict { rho_scan, rho_corr, ratio, accepted: reason == DopReason::Accepted, reason }
}

/// The DOP test of a GICP result: ρ of the whole preprocessed source against
/// ρ of its points that had a correspondence at the end. The source must be
/// in its sensor frame (a scan, not a merged map).
pub fn reliability_test(result: &GicpResult, fov: &Fov, cfg: &DopConfig) -> DopVerdict {
    let scan = rho(&result.source_points, fov, cfg.voxel_size_m);
    let matched: Vec<[f64; 3]> = result.corresponded_source.iter().map(|&i| result.source_points[i]).collect();
    let corr = rho(&matched, fov, cfg.voxel_size_m);
    ratio_test(scan.rho, corr.rho, cfg)
}

/// Azimuth coverage above which a scan is taken as a 360° band.
const BAND_COVERAGE_DEG: usize = 300;
/// Fraction of points ignored at each end of the elevation range (stray returns).
const ELEVATION_TRIM: f64 = 0.001;

/// The FoV a scan (in its sensor frame) covers: a 360° band of its elevation
/// range when more than 300° of azimuth hold points, else a rectangle of its
/// azimuth and elevation extents. An empty scan gives the full sphere.
pub fn estimate_fov(points: &[[f32; 3]]) -> Fov {
    let mut elev = Vec::with_capacity(points.len());
    let mut occupied = [false; 360];
    for p in points {
        let (x, y, z) = (p[0] as f64, p[1] as f64, p[2] as f64);
        let h = (x * x + y * y).sqrt();
        if !h.is_finite() || !z.is_finite() || h * h + z * z <= MIN_RANGE_M * MIN_RANGE_M {
            continue;
        }
        elev.push(z.atan2(h).to_degrees());
        let az = y.atan2(x).to_degrees().rem_euclid(360.0);
        occupied[(az as usize).min(359)] = true;
    }
    if elev.is_empty() {
        return Fov::Band { elev_min_deg: -90.0, elev_max_deg: 90.0 };
    }
    let trim = ((elev.len() as f64) * ELEVATION_TRIM) as usize;
    let lo = *elev.select_nth_unstable_by(trim, f64::total_cmp).1;
    let last = elev.len() - 1 - trim;
    let hi = *elev.select_nth_unstable_by(last, f64::total_cmp).1;
    let coverage = occupied.iter().filter(|&&o| o).count();
    if coverage > BAND_COVERAGE_DEG {
        return Fov::Band { elev_min_deg: lo, elev_max_deg: hi };
    }
    // The azimuth extent is 360° minus the largest circular run of empty bins.
    let mut largest_gap = 0;
    let mut run = 0;
    for i in 0..720 {
        if occupied[i % 360] {
            run = 0;
        } else {
            run += 1;
            largest_gap = largest_gap.max(run.min(360));
        }
    }
    Fov::Rect { azimuth_deg: (360 - largest_gap) as f64, elevation_deg: hi - lo }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use std::f64::consts::PI;

    fn band(h: f64) -> Fov {
        Fov::Band { elev_min_deg: -h, elev_max_deg: h }
    }

    #[test]
    fn g0_reference_values() {
        let cases = [
            (band(7.5), 13.421),
            (band(11.25), 9.104),
            (band(15.0), 6.991),
            (band(22.5), 4.969),
            (Fov::Rect { azimuth_deg: 70.4, elevation_deg: 77.2 }, 4.343),
            (band(90.0), 3.0),
        ];
        for (fov, want) in cases {
            let got = g0(&fov);
            // The reference values are printed to 3 decimals.
            assert!((got - want).abs() < 1e-3, "{fov:?}: {got} vs {want}");
        }
    }

    /// Uniform bearings over a FoV: azimuth uniform, sin(elevation) uniform.
    fn sample_bearings(fov: &Fov, n: usize, seed: u64) -> Vec<Vector3<f64>> {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let (az_half, s1, s2) = match *fov {
            Fov::Band { elev_min_deg, elev_max_deg } => {
                (PI, elev_min_deg.to_radians().sin(), elev_max_deg.to_radians().sin())
            }
            Fov::Rect { azimuth_deg, elevation_deg } => {
                let s = (0.5 * elevation_deg).to_radians().sin();
                (0.5 * azimuth_deg.to_radians(), -s, s)
            }
        };
        (0..n)
            .map(|_| {
                let az: f64 = rng.random_range(-az_half..az_half);
                let z: f64 = rng.random_range(s1..s2);
                let h = (1.0 - z * z).sqrt();
                Vector3::new(h * az.cos(), h * az.sin(), z)
            })
            .collect()
    }

    #[test]
    fn g0_matches_monte_carlo() {
        let fovs = [
            band(7.5),
            band(15.0),
            Fov::Band { elev_min_deg: -24.8, elev_max_deg: 2.0 },
            Fov::Rect { azimuth_deg: 70.4, elevation_deg: 77.2 },
            Fov::Rect { azimuth_deg: 120.0, elevation_deg: 25.0 },
            band(90.0),
        ];
        for (i, fov) in fovs.iter().enumerate() {
            let mc = bearing_spread(sample_bearings(fov, 200_000, i as u64).into_iter());
            let exact = g0(fov);
            assert!((mc - exact).abs() / exact < 0.01, "{fov:?}: monte carlo {mc} vs {exact}");
        }
    }

    #[test]
    fn solid_angles() {
        assert!((solid_angle_sr(&band(90.0)) - 4.0 * PI).abs() < 1e-12);
        assert!((solid_angle_sr(&Fov::Rect { azimuth_deg: 360.0, elevation_deg: 180.0 }) - 4.0 * PI).abs() < 1e-12);
        assert!((solid_angle_sr(&Fov::Rect { azimuth_deg: 180.0, elevation_deg: 180.0 }) - 2.0 * PI).abs() < 1e-12);
    }

    #[test]
    fn collinear_and_planar_bearings_are_singular() {
        let line: Vec<[f64; 3]> = (1..50).map(|i| [i as f64, 0.0, 0.0]).collect();
        let r = rho(&line, &band(15.0), 0.5);
        assert!(r.rho.is_infinite() && r.dop.is_infinite());
        // All points in the sensor's horizontal plane: rank 2.
        let ring: Vec<[f64; 3]> =
            (0..360).map(|d| (d as f64).to_radians()).map(|a| [10.0 * a.cos(), 10.0 * a.sin(), 0.0]).collect();
        assert!(rho(&ring, &band(15.0), 0.5).rho.is_infinite());
        assert!(rho(&Vec::<[f64; 3]>::new(), &band(15.0), 0.5).rho.is_infinite());
        let v = ratio_test(1.0, f64::INFINITY, &DopConfig::default());
        assert_eq!(v.reason, DopReason::CorrespondencesDegenerate);
        assert!(!v.accepted);
    }

    #[test]
    fn ratio_test_thresholds() {
        let cfg = DopConfig::default();
        assert_eq!(ratio_test(1.0, 1.9, &cfg).reason, DopReason::Accepted);
        assert_eq!(ratio_test(1.0, 2.1, &cfg).reason, DopReason::RatioAboveKappa);
        let above = cfg.rho_max * 1.02;
        assert_eq!(ratio_test(above / 1.9, above, &cfg).reason, DopReason::RhoCorrAboveMax);
        assert_eq!(ratio_test(above / 1.9, cfg.rho_max * 0.98, &cfg).reason, DopReason::Accepted);
        assert_eq!(ratio_test(f64::INFINITY, 1.0, &cfg).reason, DopReason::ScanDegenerate);
        let v = ratio_test(1.2, 1.8, &cfg);
        assert!(v.accepted && (v.ratio - 1.5).abs() < 1e-12);
    }

    /// Points on a sphere of radius `r_m` spread uniformly over `fov`, minus
    /// occluders: each 5° × 5° cell of (azimuth, elevation) is hidden with
    /// probability `occluded_frac` (a fixed pseudo-random pattern).
    fn sphere_scan(fov: &Fov, r_m: f64, n: usize, occluded_frac: f64) -> Vec<[f64; 3]> {
        let hidden = |u: &Vector3<f64>| {
            let ia = (u.y.atan2(u.x).to_degrees() / 5.0).floor() as i64;
            let ie = (u.z.asin().to_degrees() / 5.0).floor() as i64;
            let h = (ia.wrapping_mul(73_856_093) ^ ie.wrapping_mul(19_349_663)).wrapping_mul(2_654_435_761);
            ((h >> 8).rem_euclid(1000) as f64) < occluded_frac * 1000.0
        };
        sample_bearings(fov, n, 99)
            .into_iter()
            .filter(|u| !hidden(u))
            .map(|u| [u.x * r_m, u.y * r_m, u.z * r_m])
            .collect()
    }

    #[test]
    fn rho_is_about_fov_independent_while_dop_is_not() {
        // The paper's Fig. 3: sensors of different FoVs, each seeing a uniform
        // scene at 20 m, with growing occlusion. ρ should agree across
        // sensors at each occlusion level; DOP should not. (Occluders are
        // scattered patches: a single wedge of the same fraction of the
        // azimuth width hurts a narrow FoV more — 60% of Avia's 70° leaves a
        // 28° slit and ρ doubles, while a band keeps 144° — and ρ rightly
        // says so.)
        let fovs = [band(7.5), band(15.0), band(22.5), Fov::Rect { azimuth_deg: 70.4, elevation_deg: 77.2 }];
        for occluded in [0.0, 0.3, 0.6, 0.8] {
            let reports: Vec<RhoReport> =
                fovs.iter().map(|f| rho(&sphere_scan(f, 20.0, 150_000, occluded), f, 0.5)).collect();
            let spread = |v: Vec<f64>| {
                let max = v.iter().copied().fold(f64::MIN, f64::max);
                let min = v.iter().copied().fold(f64::MAX, f64::min);
                max / min
            };
            let rhos: Vec<f64> = reports.iter().map(|r| r.rho).collect();
            let dops: Vec<f64> = reports.iter().map(|r| r.dop).collect();
            eprintln!("occlusion {occluded}: rho {rhos:?} dop {dops:?}");
            assert!(spread(rhos.clone()) < 1.25, "occlusion {occluded}: rho {rhos:?}");
            assert!(spread(dops.clone()) > 2.0, "occlusion {occluded}: DOP {dops:?}");
        }
    }

    #[test]
    fn narrow_sector_has_much_larger_rho_than_full_scan() {
        let fov = band(15.0);
        let full = sphere_scan(&fov, 20.0, 150_000, 0.0);
        let sector: Vec<[f64; 3]> =
            full.iter().copied().filter(|p| p[1].atan2(p[0]).abs() < 15f64.to_radians()).collect();
        let r_full = rho(&full, &fov, 0.5).rho;
        let r_sector = rho(&sector, &fov, 0.5).rho;
        assert!(r_full < 1.5, "{r_full}");
        // A 30° sector keeps 1/12 of the points (ρ × sqrt(12) = 3.5) and
        // spreads them worse: measured 4.8×.
        assert!(r_sector > 4.0 * r_full, "{r_sector} vs {r_full}");
        let v = ratio_test(r_full, r_sector, &DopConfig::default());
        assert_eq!(v.reason, DopReason::RatioAboveKappa);
    }

    #[test]
    fn estimate_fov_band_and_rect() {
        let to_f32 = |v: Vec<[f64; 3]>| v.iter().map(|p| [p[0] as f32, p[1] as f32, p[2] as f32]).collect::<Vec<_>>();
        let hdl = Fov::Band { elev_min_deg: -24.8, elev_max_deg: 2.0 };
        match estimate_fov(&to_f32(sphere_scan(&hdl, 20.0, 100_000, 0.0))) {
            Fov::Band { elev_min_deg, elev_max_deg } => {
                assert!(
                    (elev_min_deg + 24.8).abs() < 0.3 && (elev_max_deg - 2.0).abs() < 0.3,
                    "{elev_min_deg} {elev_max_deg}"
                );
            }
            f => panic!("expected a band, got {f:?}"),
        }
        let avia = Fov::Rect { azimuth_deg: 70.4, elevation_deg: 77.2 };
        match estimate_fov(&to_f32(sphere_scan(&avia, 20.0, 100_000, 0.0))) {
            Fov::Rect { azimuth_deg, elevation_deg } => {
                assert!(
                    (azimuth_deg - 70.4).abs() < 2.0 && (elevation_deg - 77.2).abs() < 0.5,
                    "{azimuth_deg} {elevation_deg}"
                );
            }
            f => panic!("expected a rectangle, got {f:?}"),
        }
        assert_eq!(estimate_fov(&[]), Fov::Band { elev_min_deg: -90.0, elev_max_deg: 90.0 });
    }
}
