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
}
