//! Lean reads for pictures (`seam render`, `seam report`): the lifelong
//! map's extent, and its voxels streamed as key, centroid and ε_g without
//! building a row struct per voxel (a 600k-voxel map is drawn in one pass).

use super::rows::e;
use super::{StoreError, WorldBox};
use rusqlite::{Connection, params};

/// The box and count of the lifelong map's voxel centroids, world frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MapExtent {
    pub min_m: [f64; 3],
    pub max_m: [f64; 3],
    pub voxels: u64,
}

/// True if the database has a table (or view) of that name. A store opened
/// read-only is not migrated, so an old one may lack the newer tables.
pub fn has_table(conn: &Connection, name: &str) -> Result<bool, StoreError> {
    conn.query_row("SELECT count(*) FROM sqlite_master WHERE name = ?1", [name], |r| r.get::<_, i64>(0))
        .map(|n| n > 0)
        .map_err(e(conn))
}

/// The extent of the lifelong map; `None` while it is empty.
pub fn map_extent(conn: &Connection) -> Result<Option<MapExtent>, StoreError> {
    if !has_table(conn, "map_voxels")? {
        return Ok(None);
    }
    let row = conn
        .query_row(
            "SELECT count(*), min(x_m), min(y_m), min(z_m), max(x_m), max(y_m), max(z_m) FROM map_voxels",
            [],
            |r| {
                Ok((
                    r.get::<_, i64>(0)?,
                    [r.get::<_, Option<f64>>(1)?, r.get(2)?, r.get(3)?],
                    [r.get::<_, Option<f64>>(4)?, r.get(5)?, r.get(6)?],
                ))
            },
        )
        .map_err(e(conn))?;
    let (n, lo, hi) = row;
    match (lo, hi) {
        ([Some(a), Some(b), Some(c)], [Some(x), Some(y), Some(z)]) if n > 0 => {
            Ok(Some(MapExtent { min_m: [a, b, c], max_m: [x, y, z], voxels: n as u64 }))
        }
        _ => Ok(None),
    }
}

/// Calls `f(key, centroid, eps_g)` for every map voxel whose centroid lies
/// in `b` (and whose ε_g is below `eps_g_below`, if given: the static map),
/// in no particular order. The key is on the world grid of `map_state`'s
/// voxel size. Returns how many it visited.
pub fn for_each_map_voxel(
    conn: &Connection,
    b: &WorldBox,
    eps_g_below: Option<f64>,
    mut f: impl FnMut([i64; 3], [f64; 3], f32),
) -> Result<u64, StoreError> {
    if !has_table(conn, "map_voxels")? {
        return Ok(0);
    }
    let mut st = conn
        .prepare(
            "SELECT x_m, y_m, z_m, eps_g, kx, ky, kz FROM map_voxels
             WHERE x_m BETWEEN ?1 AND ?4 AND y_m BETWEEN ?2 AND ?5 AND z_m BETWEEN ?3 AND ?6 AND eps_g < ?7",
        )
        .map_err(e(conn))?;
    let (lo, hi) = (b.min_m, b.max_m);
    let mut rows = st
        .query(params![lo[0], lo[1], lo[2], hi[0], hi[1], hi[2], eps_g_below.unwrap_or(f64::MAX)])
        .map_err(e(conn))?;
    let mut n = 0;
    while let Some(r) = rows.next().map_err(e(conn))? {
        let p = [r.get(0).map_err(e(conn))?, r.get(1).map_err(e(conn))?, r.get(2).map_err(e(conn))?];
        let k = [r.get(4).map_err(e(conn))?, r.get(5).map_err(e(conn))?, r.get(6).map_err(e(conn))?];
        f(k, p, r.get::<_, f64>(3).map_err(e(conn))? as f32);
        n += 1;
    }
    Ok(n)
}
