//! Scans back from the store, and the point sets alignment works on: a
//! session's map merged by given poses, and a keyframe's local map.

use crate::geometry::{Pose, Scan};
use crate::registration::downsample::voxel_downsample;
use crate::store::{self, KeyframeRow, Store, StoreError};
use rayon::prelude::*;
use std::collections::HashMap;
use std::path::PathBuf;

/// Reads keyframe scans from the store's Parquet files. Holds only paths, so
/// it can be shared across threads while the store's connection is not.
#[derive(Debug, Clone)]
pub struct ScanLoader {
    paths: HashMap<i64, PathBuf>,
}

impl ScanLoader {
    pub fn new(store: &Store) -> Result<ScanLoader, StoreError> {
        Ok(ScanLoader { paths: store::file_paths(store, "scans")? })
    }

    /// The scan of one keyframe, in its sensor frame.
    pub fn load(&self, kf: &KeyframeRow) -> Result<Scan, StoreError> {
        let path = self.paths.get(&kf.scan_file_id).ok_or_else(|| StoreError::Corrupt {
            path: PathBuf::from(format!("file_id {}", kf.scan_file_id)),
            message: format!(
                "keyframe {} of session {} names scan file {}, which the store does not list",
                kf.keyframe_index, kf.session_id.0, kf.scan_file_id
            ),
        })?;
        store::read_scan_row_group(path, kf.scan_row_group as usize)
    }
}

pub use crate::geometry::transformed;

/// Keyframes per parallel batch when merging maps: bounds memory to about
/// this many scans at once.
const MERGE_BATCH: usize = 32;

/// The scans of `keyframes` moved by their poses into one frame and
/// voxel-downsampled at `voxel_m` (each scan first, then the union).
pub fn merged_map(
    loader: &ScanLoader,
    keyframes: &[(&KeyframeRow, Pose)],
    voxel_m: f64,
) -> Result<Vec<[f32; 3]>, StoreError> {
    let mut merged: Vec<[f64; 3]> = Vec::new();
    for batch in keyframes.chunks(MERGE_BATCH) {
        let parts = batch
            .par_iter()
            .map(|(kf, t)| Ok(voxel_downsample(&transformed(&loader.load(kf)?.points, t), voxel_m, false)))
            .collect::<Result<Vec<_>, StoreError>>()?;
        for p in parts {
            merged.extend(p);
        }
        // Keep the running union small.
        if merged.len() > 4_000_000 {
            merged = voxel_downsample(&merged, voxel_m, true);
        }
    }
    Ok(voxel_downsample(&merged, voxel_m, true).iter().map(crate::registration::kdtree::to_f32).collect())
}
