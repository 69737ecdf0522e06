//! Sensor descriptions: the models seam knows by name and their fields of view.
//!
//! The FoV is what the DOP test (MATH.md §4) normalises by; the simulator uses
//! the same models for its beam layouts.

use serde::{Deserialize, Serialize};

/// A LiDAR model seam knows by name.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SensorModel {
    /// Ouster OS1-64: 64 beams over ±22.5°, 1024 columns, 360°.
    #[serde(rename = "os1-64")]
    Os1_64,
    /// Velodyne VLP-16: 16 beams over ±15°, 0.2° azimuth steps, 360°.
    Vlp16,
    /// Velodyne HDL-64E (KITTI): 64 beams from +2° to −24.8°, 360°.
    #[serde(rename = "hdl-64e")]
    Hdl64e,
    /// Velodyne HDL-32E: 32 beams from +10.67° to −30.67°, 360°.
    #[serde(rename = "hdl-32e")]
    Hdl32e,
    /// Livox Avia: non-repetitive rosette, 70.4° × 77.2°, forward-looking.
    Avia,
}

impl SensorModel {
    pub const ALL: [SensorModel; 5] =
        [SensorModel::Os1_64, SensorModel::Vlp16, SensorModel::Hdl64e, SensorModel::Hdl32e, SensorModel::Avia];

    /// The name used on the command line and in `session.toml`.
    pub fn name(self) -> &'static str {
        match self {
            SensorModel::Os1_64 => "os1-64",
            SensorModel::Vlp16 => "vlp16",
            SensorModel::Hdl64e => "hdl-64e",
            SensorModel::Hdl32e => "hdl-32e",
            SensorModel::Avia => "avia",
        }
    }

    /// Parses a model name, case-insensitively, accepting common spellings.
    pub fn parse(s: &str) -> Option<SensorModel> {
        let k: String = s.to_ascii_lowercase().chars().filter(|c| c.is_ascii_alphanumeric()).collect();
        match k.as_str() {
            "os164" | "ouster" | "ousteros164" => Some(SensorModel::Os1_64),
            "vlp16" | "velodynevlp16" | "puck" => Some(SensorModel::Vlp16),
            "hdl64e" | "hdl64" | "velodynehdl64e" => Some(SensorModel::Hdl64e),
            "hdl32e" | "hdl32" | "velodynehdl32e" => Some(SensorModel::Hdl32e),
            "avia" | "livoxavia" => Some(SensorModel::Avia),
            _ => None,
        }
    }

    /// The model's field of view.
    pub fn fov(self) -> Fov {
        match self {
            SensorModel::Os1_64 => Fov::Band { elev_min_deg: -22.5, elev_max_deg: 22.5 },
            SensorModel::Vlp16 => Fov::Band { elev_min_deg: -15.0, elev_max_deg: 15.0 },
            SensorModel::Hdl64e => Fov::Band { elev_min_deg: -24.8, elev_max_deg: 2.0 },
            SensorModel::Hdl32e => Fov::Band { elev_min_deg: -30.67, elev_max_deg: 10.67 },
            SensorModel::Avia => Fov::Rect { azimuth_deg: 70.4, elevation_deg: 77.2 },
        }
    }

    /// A spinning sensor's beam elevations (degrees, the order it fires
    /// them) and columns per revolution; `None` for a forward sensor's
    /// pattern. The simulator fires these beams.
    pub fn beams(self) -> Option<(Vec<f64>, usize)> {
        let uniform =
            |lo: f64, hi: f64, n: usize| (0..n).map(|i| lo + (hi - lo) * i as f64 / (n - 1) as f64).collect::<Vec<_>>();
        match self {
            SensorModel::Os1_64 => Some((uniform(-22.5, 22.5, 64), 1024)),
            SensorModel::Vlp16 => Some((uniform(-15.0, 15.0, 16), 1800)),
            SensorModel::Hdl32e => Some((uniform(-30.67, 10.67, 32), 2187)),
            SensorModel::Hdl64e => {
                // Upper block: +2° to -8.33° in 1/3° steps; lower block to -24.8°.
                let mut e = uniform(-8.33, 2.0, 32);
                e.extend(uniform(-24.8, -8.83, 32));
                Some((e, 2083))
            }
            SensorModel::Avia => None,
        }
    }

    /// The widest gap between neighbouring beam elevations of a spinning
    /// sensor, degrees (2° for a VLP-16, 0.71° for an OS1-64).
    pub fn beam_spacing_deg(self) -> Option<f64> {
        let (mut e, _) = self.beams()?;
        e.sort_by(f64::total_cmp);
        e.windows(2).map(|w| w[1] - w[0]).reduce(f64::max)
    }
}

/// A field of view: a 360° band of elevations, or a forward rectangle.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Fov {
    /// 360° in azimuth, elevations from `elev_min_deg` to `elev_max_deg`.
    Band { elev_min_deg: f64, elev_max_deg: f64 },
    /// Forward-looking along +x: full widths `azimuth_deg` × `elevation_deg`.
    Rect { azimuth_deg: f64, elevation_deg: f64 },
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip() {
        for m in SensorModel::ALL {
            assert_eq!(SensorModel::parse(m.name()), Some(m));
        }
        assert_eq!(SensorModel::parse("Ouster OS1-64"), Some(SensorModel::Os1_64));
        assert_eq!(SensorModel::parse("kinect"), None);
    }

    #[test]
    fn beam_spacing_is_the_widest_gap_and_the_beams_fill_the_band() {
        let close = |a: Option<f64>, b: f64| a.is_some_and(|a| (a - b).abs() < 1e-3);
        assert!(close(SensorModel::Vlp16.beam_spacing_deg(), 2.0));
        assert!(close(SensorModel::Os1_64.beam_spacing_deg(), 45.0 / 63.0));
        assert!(close(SensorModel::Hdl32e.beam_spacing_deg(), 41.34 / 31.0));
        // The HDL-64E's lower block is the sparser one.
        assert!(close(SensorModel::Hdl64e.beam_spacing_deg(), (24.8 - 8.83) / 31.0));
        assert_eq!(SensorModel::Avia.beam_spacing_deg(), None);
        for m in SensorModel::ALL {
            let (Some((e, _)), Fov::Band { elev_min_deg, elev_max_deg }) = (m.beams(), m.fov()) else { continue };
            let (lo, hi) = e.iter().fold((f64::MAX, f64::MIN), |(l, h), &x| (l.min(x), h.max(x)));
            assert!((lo - elev_min_deg).abs() < 1e-9 && (hi - elev_max_deg).abs() < 1e-9, "{m:?}");
        }
    }
}
