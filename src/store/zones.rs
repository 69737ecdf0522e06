//! Named zones (schema migration 5): boxes or xy polygons with a z range in
//! the world frame, which queries name as `zone:"Tower B"`.
//!
//! A zone's `min_*`/`max_*` columns always hold its bounding box, so a query
//! can ask the tile R*Tree with them whatever the shape; a polygon zone also
//! keeps its polygon as WKT for the exact test.

use super::rows::e;
use super::{StoreError, WorldBox, now_utc};
use crate::geometry::polygon::Polygon;
use rusqlite::{Connection, params};

/// The shape of a zone, world frame, metres.
#[derive(Debug, Clone, PartialEq)]
pub enum ZoneShape {
    /// An axis-aligned box.
    Box(WorldBox),
    /// A polygon in the xy plane between two heights.
    Polygon { polygon: Polygon, min_z_m: f64, max_z_m: f64 },
}

#[derive(Debug, Clone, PartialEq)]
pub struct Zone {
    pub name: String,
    pub shape: ZoneShape,
    pub created_at: String,
}

impl ZoneShape {
    /// The box that holds the shape.
    pub fn bounds(&self) -> WorldBox {
        match self {
            ZoneShape::Box(b) => *b,
            ZoneShape::Polygon { polygon, min_z_m, max_z_m } => {
                let (lo, hi) = polygon.bounds();
                WorldBox { min_m: [lo[0], lo[1], *min_z_m], max_m: [hi[0], hi[1], *max_z_m] }
            }
        }
    }

    /// `bbox` or `polygon`, as stored.
    pub fn kind(&self) -> &'static str {
        match self {
            ZoneShape::Box(_) => "bbox",
            ZoneShape::Polygon { .. } => "polygon",
        }
    }
}

/// True if the store has the zones table: a store written before migration 5
/// and opened read-only (so not migrated) has none, and so no zones.
fn has_zones_table(conn: &Connection) -> Result<bool, StoreError> {
    conn.query_row("SELECT count(*) FROM sqlite_master WHERE type = 'table' AND name = 'zones'", [], |r| {
        r.get::<_, i64>(0)
    })
    .map(|n| n > 0)
    .map_err(e(conn))
}

/// Adds a zone. The caller checks the name is free (a taken name fails on
/// the UNIQUE constraint).
pub fn insert_zone(conn: &Connection, name: &str, shape: &ZoneShape) -> Result<(), StoreError> {
    let b = shape.bounds();
    let wkt = match shape {
        ZoneShape::Box(_) => None,
        ZoneShape::Polygon { polygon, .. } => Some(polygon.to_wkt()),
    };
    conn.execute(
        "INSERT INTO zones(name, kind, min_x_m, min_y_m, min_z_m, max_x_m, max_y_m, max_z_m, polygon_wkt, created_at)
         VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10)",
        params![
            name,
            shape.kind(),
            b.min_m[0],
            b.min_m[1],
            b.min_m[2],
            b.max_m[0],
            b.max_m[1],
            b.max_m[2],
            wkt,
            now_utc()
        ],
    )
    .map_err(e(conn))?;
    Ok(())
}

/// Every zone, by name.
pub fn zones(conn: &Connection) -> Result<Vec<Zone>, StoreError> {
    if !has_zones_table(conn)? {
        return Ok(Vec::new());
    }
    let mut st = conn
        .prepare(
            "SELECT name, kind, min_x_m, min_y_m, min_z_m, max_x_m, max_y_m, max_z_m, polygon_wkt, created_at
             FROM zones ORDER BY name",
        )
        .map_err(e(conn))?;
    let rows = st
        .query_map([], |r| {
            Ok((
                r.get::<_, String>(0)?,
                r.get::<_, String>(1)?,
                [r.get::<_, f64>(2)?, r.get(3)?, r.get(4)?],
                [r.get::<_, f64>(5)?, r.get(6)?, r.get(7)?],
                r.get::<_, Option<String>>(8)?,
                r.get::<_, String>(9)?,
            ))
        })
        .map_err(e(conn))?;
    let mut out = Vec::new();
    for row in rows {
        let (name, kind, min_m, max_m, wkt, created_at) = row.map_err(e(conn))?;
        let corrupt = |message: String| StoreError::Corrupt {
            path: conn.path().map(std::path::PathBuf::from).unwrap_or_default(),
            message,
        };
        let shape = match (kind.as_str(), wkt) {
            ("bbox", _) => ZoneShape::Box(WorldBox { min_m, max_m }),
            ("polygon", Some(w)) => ZoneShape::Polygon {
                polygon: Polygon::from_wkt(&w).map_err(|m| corrupt(format!("zone {name:?}: polygon: {m}")))?,
                min_z_m: min_m[2],
                max_z_m: max_m[2],
            },
            (k, _) => return Err(corrupt(format!("zone {name:?} has kind {k:?} without a usable shape"))),
        };
        out.push(Zone { name, shape, created_at });
    }
    Ok(out)
}

/// Removes a zone; false if there was none of that name.
pub fn remove_zone(conn: &Connection, name: &str) -> Result<bool, StoreError> {
    if !has_zones_table(conn)? {
        return Ok(false);
    }
    conn.execute("DELETE FROM zones WHERE name = ?1", [name]).map(|n| n > 0).map_err(e(conn))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::store::{InitOptions, Store};

    #[test]
    fn zones_round_trip_by_name() {
        let dir = tempfile::tempdir().unwrap();
        let opts = InitOptions { site_name: "t".into(), crs: "local".into(), voxel_size_m: 0.2 };
        let store = Store::create(&dir.path().join("s.seam"), &opts).unwrap();
        let c = store.conn();
        assert!(zones(c).unwrap().is_empty());
        let b = ZoneShape::Box(WorldBox { min_m: [1.0, 2.0, 3.0], max_m: [4.0, 5.0, 6.0] });
        let p = ZoneShape::Polygon {
            polygon: Polygon::from_wkt("POLYGON((0 0, 10 0, 5 8))").unwrap(),
            min_z_m: -1.0,
            max_z_m: 12.5,
        };
        insert_zone(c, "Tower B", &b).unwrap();
        insert_zone(c, "pile", &p).unwrap();
        assert!(insert_zone(c, "pile", &b).is_err(), "names are unique");
        let z = zones(c).unwrap();
        assert_eq!(z.iter().map(|z| z.name.as_str()).collect::<Vec<_>>(), ["Tower B", "pile"]);
        assert_eq!(z[0].shape, b);
        assert_eq!(z[1].shape, p);
        assert_eq!(p.bounds(), WorldBox { min_m: [0.0, 0.0, -1.0], max_m: [10.0, 8.0, 12.5] });
        assert!(remove_zone(c, "pile").unwrap());
        assert!(!remove_zone(c, "pile").unwrap());
        assert_eq!(zones(c).unwrap().len(), 1);
    }
}
