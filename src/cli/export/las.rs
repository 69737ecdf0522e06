//! `--las`: the static and lifelong maps as `OUT/las/{static_map,lifelong_map}.laz`,
//! staged and swapped in like a table.

use super::Job;
use super::catalog::LasFile;
use super::tables::stage_and_swap;
use crate::cli::output::{log, thousands};
use crate::store::las_export::{LasMapPoint, change_class, write_map_las};

/// Writes both LAS files and returns what the catalog says about them.
pub fn export_las(job: &Job<'_>, compressed: bool) -> anyhow::Result<Vec<LasFile>> {
    let empty = crate::store::map_export::MapExport::default();
    let map = job.map.as_ref().unwrap_or(&empty);
    let ext = if compressed { "laz" } else { "las" };
    let graph_version = map.state.map(|s| s.graph_version);
    if job.crs.las_wkt().is_none() {
        log(job.ctx, format!("las: seam cannot spell out {:?} as WKT; the LAS files carry no CRS record", job.crs));
    }
    stage_and_swap(job.out, "las", |staging| {
        let mut files = Vec::new();
        let threshold = job.static_threshold;
        for (name, filter) in [("static_map", Some(threshold)), ("lifelong_map", None)] {
            // Same order as the Parquet map tables: LAS point i is row i.
            let points: Vec<LasMapPoint> = map
                .voxels
                .iter()
                .filter(|v| filter.is_none_or(|t| (v.eps_g as f64) < t))
                .map(|v| LasMapPoint { xyz_m: v.xyz_m, eps_g: v.eps_g, change_class: change_class(v.category) })
                .collect();
            let rel = format!("{name}.{ext}");
            let w = write_map_las(&staging.join(&rel), &points, &job.crs, compressed)?;
            log(job.ctx, format!("las/{rel}: {} points", thousands(w.file.row_count)));
            files.push(LasFile {
                name: name.to_string(),
                path: format!("las/{rel}"),
                point_count: w.file.row_count,
                size_bytes: w.file.size_bytes,
                blake3: w.file.blake3,
                scale_m: w.scale_m,
                offset_m: w.offset_m,
                filter: filter.map(|t| format!("eps_g < {t}")),
                graph_version,
                has_crs: w.has_crs,
            });
        }
        Ok(files)
    })
}
