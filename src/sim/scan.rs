//! One keyframe's scan: cast every beam, keep the returns a real sensor
//! would report, and label them.
//!
//! A return is kept when
//! - the surface is within reach: range ≤ `max_range · (ρ cos θ / 0.8)^0.4`,
//!   with ±10 % log-normal spread (the data-sheet range holds for 80 %
//!   reflectivity at normal incidence; dark or grazing surfaces are lost
//!   sooner, which is what thins out distant ground),
//! - the incidence is not grazing (cos θ ≥ 0.03),
//! - it is not one of the random dropouts,
//! - the noisy range is beyond the blanking distance.
//!
//! Range noise is Gaussian along the beam. Intensity is in [0, 1] like
//! KITTI's: `ρ (0.3 + 0.7 cos θ)` with 8 % multiplicative noise.

use nalgebra::{Point3, Vector3};

use super::assets::label;
use super::raycast::{Prim, Scene};
use super::seeds::{gauss, ray_key, tag, unit};
use super::sensor_model::{self, SensorSpec};
use crate::geometry::Pose;
use crate::sensor::SensorModel;

/// The points (sensor frame, x y z intensity) and SemanticKITTI labels of a scan.
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct KeyframeScan {
    pub points: Vec<[f32; 4]>,
    pub labels: Vec<u32>,
    pub moving: u64,
}

/// True for SemanticKITTI's moving classes.
pub(crate) fn is_moving_label(class: u16) -> bool {
    (label::MOVING_CAR..=259).contains(&class)
}

/// Simulates the scan taken at `t_world_lidar` at `time_s`; `movers` are
/// the movers' primitives at that time. `keyframe_seed` fixes every random
/// decision of the scan.
pub(crate) fn scan_keyframe(
    scene: &Scene,
    movers: &[Prim],
    model: SensorModel,
    t_world_lidar: &Pose,
    time_s: f64,
    keyframe_seed: u64,
) -> KeyframeScan {
    let spec: SensorSpec = sensor_model::spec(model);
    let dirs = sensor_model::ray_directions(model, time_s, unit(keyframe_seed ^ tag::FRAME));
    let o = t_world_lidar.translation.vector;
    let origin = [o.x, o.y, o.z];
    let rot = t_world_lidar.rotation.to_rotation_matrix();
    let mut out =
        KeyframeScan { points: Vec::with_capacity(dirs.len()), labels: Vec::with_capacity(dirs.len()), moving: 0 };
    for (i, ds) in dirs.iter().enumerate() {
        let key = ray_key(keyframe_seed, i as u64);
        let dw = rot * Vector3::new(ds[0], ds[1], ds[2]);
        let Some(hit) = scene.cast(origin, [dw.x, dw.y, dw.z], spec.max_range_m, key, movers) else { continue };
        let cos =
            hit.cos_override.unwrap_or_else(|| -(hit.normal[0] * dw.x + hit.normal[1] * dw.y + hit.normal[2] * dw.z));
        if cos < 0.03 {
            continue;
        }
        let rho = f64::from(hit.reflectivity).clamp(0.01, 1.0);
        let reach = spec.max_range_m * (rho * cos / 0.8).powf(0.4) * (0.1 * gauss(key ^ 0x5EAC)).exp();
        if hit.t > reach.min(spec.max_range_m) || unit(key ^ 0xD409) < spec.dropout {
            continue;
        }
        let range = hit.t + spec.range_sigma_m * gauss(key ^ 0x4A17);
        if range < spec.min_range_m {
            continue;
        }
        let intensity = (rho * (0.3 + 0.7 * cos) * (0.08 * gauss(key ^ 0x1A7E)).exp()).clamp(0.0, 1.0);
        let p = Point3::new(ds[0] * range, ds[1] * range, ds[2] * range);
        out.points.push([p.x as f32, p.y as f32, p.z as f32, intensity as f32]);
        out.labels.push((u32::from(hit.instance) << 16) | u32::from(hit.label));
        out.moving += u64::from(is_moving_label(hit.label));
    }
    out
}
