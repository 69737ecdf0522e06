//! GeoParquet 1.1 for every positional export table: a `geometry` column in
//! ISO WKB (`Point Z`, `LineString Z`), a `bbox` covering column (a struct of
//! `xmin, ymin, xmax, ymax` float64, what DuckDB and pyarrow filter on without
//! decoding WKB), and the `geo` key of the Parquet file's key-value metadata:
//!
//! ```json
//! {"version": "1.1.0", "primary_column": "geometry",
//!  "columns": {"geometry": {"encoding": "WKB", "geometry_types": ["Point Z"],
//!    "crs": {…PROJJSON…}, "edges": "planar", "bbox": [xmin, ymin, zmin, xmax, ymax, zmax],
//!    "covering": {"bbox": {"xmin": ["bbox", "xmin"], "ymin": ["bbox", "ymin"],
//!                          "xmax": ["bbox", "xmax"], "ymax": ["bbox", "ymax"]}}}}}
//! ```
//!
//! # CRS
//! GeoParquet 1.1 wants PROJJSON; an absent `crs` means OGC:CRS84
//! (longitude, latitude), which seam's metres never are, and `null` means
//! "unknown", so every file names one ([`Crs::projjson`]):
//! - a `--local` store: an `EngineeringCRS` with a Cartesian x, y, z system in
//!   metres (the first session's frame: seam's world frame);
//! - `EPSG:326zz` / `EPSG:327zz` (WGS 84 / UTM, the usual site grids): the
//!   complete `ProjectedCRS`, generated, with its EPSG `id`;
//! - any other EPSG code: seam has no CRS database, so the object is
//!   abbreviated to `type`, `name` and `id` (`{"authority": "EPSG", "code":
//!   n}`); readers that resolve ids (pyproj, GDAL) get the right CRS, strict
//!   PROJJSON validators do not. [`Crs::is_complete`] says which.
//!
//! Not here: which rows a table has or how they are sorted (`map_export`,
//! `trajectory_export`), the publish protocol ([`super::evidence_files`]).

use super::StoreError;
use super::evidence_files::{WrittenFile, write_batch_with};
use arrow_array::builder::BinaryBuilder;
use arrow_array::{ArrayRef, Float64Array, RecordBatch, StructArray};
use arrow_buffer::NullBuffer;
use arrow_schema::{DataType, Field, Fields};
use serde_json::{Value, json};
use std::collections::HashMap;
use std::path::Path;
use std::sync::Arc;

/// The GeoParquet version written.
pub const GEOPARQUET_VERSION: &str = "1.1.0";
/// Name of the geometry column (GeoParquet's primary column).
pub const GEOMETRY_COLUMN: &str = "geometry";
/// Name of the bbox covering column.
pub const BBOX_COLUMN: &str = "bbox";
/// Rows per row group of an export file.
pub const EXPORT_ROW_GROUP_ROWS: usize = 100_000;

const PROJJSON_SCHEMA: &str = "https://proj.org/schemas/v0.7/projjson.schema.json";

/// ISO WKB type codes of the 3D geometries seam writes (1000 + 2D code).
const WKB_POINT_Z: u32 = 1001;
const WKB_LINESTRING_Z: u32 = 1002;

/// One row's geometry, world frame, metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Geometry<'a> {
    PointZ([f64; 3]),
    /// At least two vertices (a one-vertex path is written with its vertex twice).
    LineStringZ(&'a [[f64; 3]]),
}

/// The GeoParquet type names, as `geometry_types` lists them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GeometryType {
    PointZ,
    LineStringZ,
}

impl GeometryType {
    pub fn as_str(self) -> &'static str {
        match self {
            GeometryType::PointZ => "Point Z",
            GeometryType::LineStringZ => "LineString Z",
        }
    }
}

/// Little-endian ISO WKB of a `Point Z`: byte order 1, type 1001, x y z.
pub fn wkb_point_z(p: [f64; 3]) -> [u8; 29] {
    let mut out = [0u8; 29];
    out[0] = 1;
    out[1..5].copy_from_slice(&WKB_POINT_Z.to_le_bytes());
    for (i, c) in p.iter().enumerate() {
        out[5 + 8 * i..13 + 8 * i].copy_from_slice(&c.to_le_bytes());
    }
    out
}

/// Little-endian ISO WKB of a `LineString Z`: byte order 1, type 1002, the
/// vertex count, the vertices. A single vertex is repeated: a LineString has
/// none or at least two.
pub fn wkb_linestring_z(vertices: &[[f64; 3]]) -> Vec<u8> {
    let repeat = if vertices.len() == 1 { 2 } else { 1 };
    let n = vertices.len() * repeat;
    let mut out = Vec::with_capacity(9 + 24 * n);
    out.push(1);
    out.extend_from_slice(&WKB_LINESTRING_Z.to_le_bytes());
    out.extend_from_slice(&(n as u32).to_le_bytes());
    for v in vertices {
        for _ in 0..repeat {
            v.iter().for_each(|c| out.extend_from_slice(&c.to_le_bytes()));
        }
    }
    out
}

/// The coordinate reference system of a store's world frame (`meta.crs`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Crs {
    /// A local engineering frame: seam's world frame, named after the site.
    Local {
        site: String,
    },
    Epsg(u32),
}

impl Crs {
    /// From the store's `meta` (`local` or `EPSG:<code>`); anything else
    /// (only a hand-edited store has it) is treated as local.
    pub fn from_meta(crs: &str, site: &str) -> Crs {
        let upper = crs.trim().to_ascii_uppercase();
        match upper.strip_prefix("EPSG:").and_then(|c| c.parse::<u32>().ok()) {
            Some(code) => Crs::Epsg(code),
            None => Crs::Local { site: site.to_string() },
        }
    }

    /// `(zone, north)` for WGS 84 / UTM codes.
    fn utm(&self) -> Option<(u32, bool)> {
        match *self {
            Crs::Epsg(c @ 32601..=32660) => Some((c - 32600, true)),
            Crs::Epsg(c @ 32701..=32760) => Some((c - 32700, false)),
            _ => None,
        }
    }

    /// Whether [`Crs::projjson`] is a complete PROJJSON (not only an id).
    pub fn is_complete(&self) -> bool {
        matches!(self, Crs::Local { .. }) || self.utm().is_some()
    }

    /// The CRS as PROJJSON (see the module doc for what each kind holds).
    pub fn projjson(&self) -> Value {
        match self {
            Crs::Local { site } => {
                let axis = |n: &str| json!({"name": n, "abbreviation": n, "direction": "unspecified", "unit": "metre"});
                json!({
                    "$schema": PROJJSON_SCHEMA,
                    "type": "EngineeringCRS",
                    "name": format!("seam world frame of {site}"),
                    "datum": {
                        "type": "EngineeringDatum",
                        "name": "seam world frame (the first session's odometry frame)"
                    },
                    "coordinate_system": {"subtype": "Cartesian", "axis": [axis("x"), axis("y"), axis("z")]}
                })
            }
            Crs::Epsg(code) => match self.utm() {
                Some((zone, north)) => utm_projjson(*code, zone, north),
                None => json!({
                    "$schema": PROJJSON_SCHEMA,
                    "type": "ProjectedCRS",
                    "name": format!("EPSG:{code}"),
                    "id": {"authority": "EPSG", "code": code}
                }),
            },
        }
    }

    /// OGC WKT 1 for a LAS `LASF_Projection` 2112 record, where seam can
    /// write a complete one (local frames and WGS 84 / UTM).
    pub fn las_wkt(&self) -> Option<String> {
        match self {
            Crs::Local { site } => Some(format!(
                "LOCAL_CS[\"seam world frame of {}\",LOCAL_DATUM[\"seam world frame\",0],UNIT[\"metre\",1],\
                 AXIS[\"X\",OTHER],AXIS[\"Y\",OTHER],AXIS[\"Z\",OTHER]]",
                site.replace('"', "'")
            )),
            Crs::Epsg(code) => {
                let (zone, north) = self.utm()?;
                Some(format!(
                    "PROJCS[\"WGS 84 / UTM zone {zone}{h}\",GEOGCS[\"WGS 84\",DATUM[\"WGS_1984\",\
                     SPHEROID[\"WGS 84\",6378137,298.257223563,AUTHORITY[\"EPSG\",\"7030\"]],AUTHORITY[\"EPSG\",\"6326\"]],\
                     PRIMEM[\"Greenwich\",0,AUTHORITY[\"EPSG\",\"8901\"]],\
                     UNIT[\"degree\",0.0174532925199433,AUTHORITY[\"EPSG\",\"9122\"]],AUTHORITY[\"EPSG\",\"4326\"]],\
                     PROJECTION[\"Transverse_Mercator\"],PARAMETER[\"latitude_of_origin\",0],\
                     PARAMETER[\"central_meridian\",{cm}],PARAMETER[\"scale_factor\",0.9996],\
                     PARAMETER[\"false_easting\",500000],PARAMETER[\"false_northing\",{fnorth}],\
                     UNIT[\"metre\",1,AUTHORITY[\"EPSG\",\"9001\"]],AXIS[\"Easting\",EAST],AXIS[\"Northing\",NORTH],\
                     AUTHORITY[\"EPSG\",\"{code}\"]]",
                    h = if north { "N" } else { "S" },
                    cm = zone as i64 * 6 - 183,
                    fnorth = if north { 0 } else { 10_000_000 },
                ))
            }
        }
    }
}

impl std::fmt::Display for Crs {
    /// As the store's meta says it: `local` or `EPSG:<code>`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Crs::Local { .. } => f.write_str("local"),
            Crs::Epsg(code) => write!(f, "EPSG:{code}"),
        }
    }
}

/// The complete PROJJSON of WGS 84 / UTM zone `zone` (EPSG 326zz / 327zz).
fn utm_projjson(code: u32, zone: u32, north: bool) -> Value {
    let h = if north { "N" } else { "S" };
    let param = |name: &str, value: f64, unit: &str, id: u32| json!({"name": name, "value": value, "unit": unit, "id": {"authority": "EPSG", "code": id}});
    json!({
        "$schema": PROJJSON_SCHEMA,
        "type": "ProjectedCRS",
        "name": format!("WGS 84 / UTM zone {zone}{h}"),
        "base_crs": {
            "name": "WGS 84",
            "datum": {
                "type": "GeodeticReferenceFrame",
                "name": "World Geodetic System 1984",
                "ellipsoid": {"name": "WGS 84", "semi_major_axis": 6378137, "inverse_flattening": 298.257223563}
            },
            "coordinate_system": {
                "subtype": "ellipsoidal",
                "axis": [
                    {"name": "Geodetic latitude", "abbreviation": "Lat", "direction": "north", "unit": "degree"},
                    {"name": "Geodetic longitude", "abbreviation": "Lon", "direction": "east", "unit": "degree"}
                ]
            },
            "id": {"authority": "EPSG", "code": 4326}
        },
        "conversion": {
            "name": format!("UTM zone {zone}{h}"),
            "method": {"name": "Transverse Mercator", "id": {"authority": "EPSG", "code": 9807}},
            "parameters": [
                param("Latitude of natural origin", 0.0, "degree", 8801),
                param("Longitude of natural origin", zone as f64 * 6.0 - 183.0, "degree", 8802),
                param("Scale factor at natural origin", 0.9996, "unity", 8805),
                param("False easting", 500_000.0, "metre", 8806),
                param("False northing", if north { 0.0 } else { 10_000_000.0 }, "metre", 8807),
            ]
        },
        "coordinate_system": {
            "subtype": "Cartesian",
            "axis": [
                {"name": "Easting", "abbreviation": "E", "direction": "east", "unit": "metre"},
                {"name": "Northing", "abbreviation": "N", "direction": "north", "unit": "metre"}
            ]
        },
        "id": {"authority": "EPSG", "code": code}
    })
}

/// The two columns every positional table ends with: `geometry` (WKB) and
/// `bbox` (the covering struct). Nullable where a row may have no position.
pub fn geometry_fields(nullable: bool, what: &str) -> [Field; 2] {
    let desc = |d: String| HashMap::from([("description".to_string(), d)]);
    let bbox_fields: Fields =
        ["xmin", "ymin", "xmax", "ymax"].iter().map(|n| Field::new(*n, DataType::Float64, false)).collect();
    [
        Field::new(GEOMETRY_COLUMN, DataType::Binary, nullable)
            .with_metadata(desc(format!("{what}: GeoParquet WKB, world frame, metres"))),
        Field::new(BBOX_COLUMN, DataType::Struct(bbox_fields), nullable)
            .with_metadata(desc("bounding box of geometry (GeoParquet 1.1 covering), metres".into())),
    ]
}

/// What the `geo` metadata says about a file's geometries.
#[derive(Debug, Clone, PartialEq)]
pub struct GeoSummary {
    /// The types the table holds (declared per table, so an empty file says
    /// the same as a full one).
    pub types: Vec<GeometryType>,
    /// `[xmin, ymin, zmin, xmax, ymax, zmax]` over every geometry; `None`: no geometry.
    pub bbox: Option<[f64; 6]>,
}

impl GeoSummary {
    /// The union of two summaries' boxes (types of `self`).
    pub fn union(&self, other: &GeoSummary) -> GeoSummary {
        let bbox = match (self.bbox, other.bbox) {
            (Some(a), Some(b)) => Some(std::array::from_fn(|i| if i < 3 { a[i].min(b[i]) } else { a[i].max(b[i]) })),
            (a, b) => a.or(b),
        };
        GeoSummary { types: self.types.clone(), bbox }
    }
}

/// The `geometry` and `bbox` arrays of some rows, and their summary.
pub struct GeoColumns {
    pub geometry: ArrayRef,
    pub bbox: ArrayRef,
    pub summary: GeoSummary,
}

/// Builds the geometry and covering columns of rows whose geometries are
/// `geoms` (`None`: the row has no position; both columns are null there).
pub fn geo_columns<'a>(types: &[GeometryType], geoms: impl Iterator<Item = Option<Geometry<'a>>>) -> GeoColumns {
    let mut wkb = BinaryBuilder::new();
    let mut boxes: [Vec<f64>; 4] = Default::default();
    let mut valid = Vec::new();
    let mut total: Option<[f64; 6]> = None;
    for g in geoms {
        let Some(g) = g else {
            wkb.append_null();
            boxes.iter_mut().for_each(|b| b.push(0.0));
            valid.push(false);
            continue;
        };
        let b = match g {
            Geometry::PointZ(p) => {
                wkb.append_value(wkb_point_z(p));
                [p[0], p[1], p[2], p[0], p[1], p[2]]
            }
            Geometry::LineStringZ(v) => {
                wkb.append_value(wkb_linestring_z(v));
                v.iter().fold(
                    [
                        f64::INFINITY,
                        f64::INFINITY,
                        f64::INFINITY,
                        f64::NEG_INFINITY,
                        f64::NEG_INFINITY,
                        f64::NEG_INFINITY,
                    ],
                    |a, p| {
                        [a[0].min(p[0]), a[1].min(p[1]), a[2].min(p[2]), a[3].max(p[0]), a[4].max(p[1]), a[5].max(p[2])]
                    },
                )
            }
        };
        for (col, v) in boxes.iter_mut().zip([b[0], b[1], b[3], b[4]]) {
            col.push(v);
        }
        valid.push(true);
        total = Some(match total {
            None => b,
            Some(t) => std::array::from_fn(|i| if i < 3 { t[i].min(b[i]) } else { t[i].max(b[i]) }),
        });
    }
    let nulls = valid.iter().any(|v| !v).then(|| NullBuffer::from(valid));
    let [fields_xmin, fields_ymin, fields_xmax, fields_ymax] = boxes;
    let children: Vec<ArrayRef> = [fields_xmin, fields_ymin, fields_xmax, fields_ymax]
        .into_iter()
        .map(|v| Arc::new(Float64Array::from(v)) as ArrayRef)
        .collect();
    let DataType::Struct(fields) = geometry_fields(false, "")[1].data_type().clone() else {
        unreachable!("the bbox field is a struct")
    };
    let bbox = StructArray::new(fields, children, nulls);
    GeoColumns {
        geometry: Arc::new(wkb.finish()),
        bbox: Arc::new(bbox),
        summary: GeoSummary { types: types.to_vec(), bbox: total },
    }
}

/// The `geo` metadata of a file (see the module doc).
pub fn geo_metadata(summary: &GeoSummary, crs: &Crs) -> Value {
    let mut column = json!({
        "encoding": "WKB",
        "geometry_types": summary.types.iter().map(|t| t.as_str()).collect::<Vec<_>>(),
        "crs": crs.projjson(),
        "edges": "planar",
        "covering": {"bbox": {
            "xmin": [BBOX_COLUMN, "xmin"],
            "ymin": [BBOX_COLUMN, "ymin"],
            "xmax": [BBOX_COLUMN, "xmax"],
            "ymax": [BBOX_COLUMN, "ymax"]
        }}
    });
    if let Some(b) = summary.bbox {
        column["bbox"] = json!(b);
    }
    json!({
        "version": GEOPARQUET_VERSION,
        "primary_column": GEOMETRY_COLUMN,
        "columns": {GEOMETRY_COLUMN: column}
    })
}

/// Writes `batch` (whose last two columns are [`geometry_fields`]) as a
/// GeoParquet file at `path` with the publish protocol, row groups of
/// [`EXPORT_ROW_GROUP_ROWS`] and the `geo` metadata.
pub fn write_geoparquet(
    path: &Path,
    batch: &RecordBatch,
    summary: &GeoSummary,
    crs: &Crs,
) -> Result<WrittenFile, StoreError> {
    let geo = geo_metadata(summary, crs).to_string();
    // In the file's key-value metadata (what DuckDB and GDAL read) and in the
    // embedded Arrow schema's (what pyarrow shows when that is present).
    let schema = batch.schema().as_ref().clone().with_metadata(HashMap::from([("geo".to_string(), geo.clone())]));
    let batch = batch
        .clone()
        .with_schema(Arc::new(schema))
        .map_err(|e| StoreError::Parquet { path: path.to_path_buf(), message: e.to_string() })?;
    write_batch_with(path, "export", &batch, EXPORT_ROW_GROUP_ROWS, vec![("geo".to_string(), geo)])
}

/// Whether a column is the WKB geometry (which gets no dictionary: every
/// value is distinct).
pub fn is_geometry_column(f: &Field) -> bool {
    f.name() == GEOMETRY_COLUMN && matches!(f.data_type(), DataType::Binary)
}

/// Microseconds since the epoch of an ISO-8601 UTC time as seam writes it
/// (`2026-11-23T19:25:25Z`, also with fractional seconds or `+00:00`);
/// `None` for anything else.
pub fn parse_utc_micros(s: &str) -> Option<i64> {
    let s = s.trim();
    let s = s.strip_suffix('Z').or_else(|| s.strip_suffix("+00:00")).unwrap_or(s);
    let (date, time) = s.split_once(['T', ' '])?;
    let mut d = date.splitn(3, '-');
    let (y, m, day): (i64, i64, i64) = (d.next()?.parse().ok()?, d.next()?.parse().ok()?, d.next()?.parse().ok()?);
    let mut t = time.splitn(3, ':');
    let (hh, mm): (i64, i64) = (t.next()?.parse().ok()?, t.next()?.parse().ok()?);
    let sec: f64 = t.next()?.parse().ok()?;
    if !(1..=12).contains(&m) || !(1..=31).contains(&day) || hh > 23 || mm > 59 || !(0.0..61.0).contains(&sec) {
        return None;
    }
    // Days from civil (H. Hinnant's algorithm), the inverse of `format_utc`.
    let y = if m <= 2 { y - 1 } else { y };
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let doy = (153 * (m + if m > 2 { -3 } else { 9 }) + 2) / 5 + day - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    let days = era * 146_097 + doe - 719_468;
    Some((days * 86_400 + hh * 3600 + mm * 60) * 1_000_000 + (sec * 1e6).round() as i64)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::store::format_utc;
    use arrow_array::Array;

    #[test]
    fn wkb_of_a_known_point_and_line() {
        // POINT Z (1 2 3), little endian: 01, e9 03 00 00, then three doubles.
        let w = wkb_point_z([1.0, 2.0, 3.0]);
        let hex: String = w.iter().map(|b| format!("{b:02x}")).collect();
        assert_eq!(hex, "01e9030000000000000000f03f00000000000000400000000000000840", "ISO WKB of POINT Z (1 2 3)");
        let l = wkb_linestring_z(&[[0.0, 0.0, 0.0], [1.0, 2.0, 3.0]]);
        assert_eq!(&l[..9], &[1, 0xea, 0x03, 0, 0, 2, 0, 0, 0]);
        assert_eq!(l.len(), 9 + 48);
        assert_eq!(&l[33..], &w[5..], "the second vertex");
        // One vertex: repeated, so the LineString is valid.
        let one = wkb_linestring_z(&[[1.0, 2.0, 3.0]]);
        assert_eq!(one[5], 2);
        assert_eq!(&one[9..33], &one[33..57]);
    }

    #[test]
    fn geo_metadata_has_the_spec_keys() {
        let cols = geo_columns(
            &[GeometryType::PointZ],
            [Some(Geometry::PointZ([1.0, -2.0, 3.0])), None, Some(Geometry::PointZ([-4.0, 5.0, 0.5]))].into_iter(),
        );
        assert_eq!(cols.summary.bbox, Some([-4.0, -2.0, 0.5, 1.0, 5.0, 3.0]));
        assert_eq!(cols.geometry.null_count(), 1);
        assert_eq!(cols.bbox.null_count(), 1);
        let b = cols.bbox.as_any().downcast_ref::<StructArray>().unwrap();
        let xmin = b.column_by_name("xmin").unwrap().as_any().downcast_ref::<Float64Array>().unwrap();
        assert_eq!(xmin.value(2), -4.0);
        let text = geo_metadata(&cols.summary, &Crs::Epsg(32652)).to_string();
        let v: Value = serde_json::from_str(&text).unwrap();
        assert_eq!(v["version"], "1.1.0");
        assert_eq!(v["primary_column"], "geometry");
        let g = &v["columns"]["geometry"];
        assert_eq!(g["encoding"], "WKB");
        assert_eq!(g["geometry_types"], json!(["Point Z"]));
        assert_eq!(g["bbox"], json!([-4.0, -2.0, 0.5, 1.0, 5.0, 3.0]));
        for k in ["xmin", "ymin", "xmax", "ymax"] {
            assert_eq!(g["covering"]["bbox"][k], json!(["bbox", k]));
        }
        let crs = &g["crs"];
        assert_eq!(crs["type"], "ProjectedCRS");
        assert_eq!(crs["id"], json!({"authority": "EPSG", "code": 32652}));
        assert_eq!(crs["name"], "WGS 84 / UTM zone 52N");
        assert_eq!(crs["conversion"]["parameters"][1]["value"], 129.0);
        // An empty file: no bbox key, types still declared.
        let empty = geo_columns(&[GeometryType::LineStringZ], std::iter::empty());
        let v = geo_metadata(&empty.summary, &Crs::Local { site: "s".into() });
        assert!(v["columns"]["geometry"].get("bbox").is_none());
        assert_eq!(v["columns"]["geometry"]["geometry_types"], json!(["LineString Z"]));
        assert_eq!(v["columns"]["geometry"]["crs"]["type"], "EngineeringCRS");
        assert_eq!(v["columns"]["geometry"]["crs"]["coordinate_system"]["axis"][2]["unit"], "metre");
    }

    #[test]
    fn crs_from_meta_and_its_encodings() {
        assert_eq!(Crs::from_meta("EPSG:32652", "x"), Crs::Epsg(32652));
        assert_eq!(Crs::from_meta("local", "x"), Crs::Local { site: "x".into() });
        assert_eq!(Crs::from_meta("epsg:32652", "x").to_string(), "EPSG:32652");
        assert!(Crs::Epsg(32733).is_complete());
        let south = Crs::Epsg(32733).projjson();
        assert_eq!(south["conversion"]["parameters"][4]["value"], 10_000_000.0);
        assert_eq!(south["conversion"]["parameters"][1]["value"], 15.0);
        assert!(!Crs::Epsg(2056).is_complete());
        assert_eq!(Crs::Epsg(2056).projjson()["id"]["code"], 2056);
        assert!(Crs::Epsg(2056).las_wkt().is_none());
        let wkt = Crs::Epsg(32652).las_wkt().unwrap();
        assert!(wkt.starts_with("PROJCS[\"WGS 84 / UTM zone 52N\"") && wkt.ends_with("AUTHORITY[\"EPSG\",\"32652\"]]"));
        assert!(wkt.contains("PARAMETER[\"central_meridian\",129]"));
        assert!(
            Crs::Local { site: "a\"b".into() }.las_wkt().unwrap().starts_with("LOCAL_CS[\"seam world frame of a'b\"")
        );
    }

    #[test]
    fn utc_parsing_inverts_formatting() {
        for secs in [0, 951_782_400, 1_795_461_925, -86_400] {
            assert_eq!(parse_utc_micros(&format_utc(secs)), Some(secs * 1_000_000), "{secs}");
        }
        assert_eq!(parse_utc_micros("2026-11-23T19:25:25.5+00:00"), Some(1_795_461_925_500_000));
        assert_eq!(parse_utc_micros("yesterday"), None);
        assert_eq!(parse_utc_micros("2026-13-01T00:00:00Z"), None);
    }
}
