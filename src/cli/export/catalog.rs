//! `OUT/_catalog.json`: what an export holds, for people and for tools that
//! do not read Parquet metadata. Per table: its folder, partitions (path,
//! rows, bytes, blake3, bbox), columns (name, Arrow type, nullable, unit,
//! description), sort order, filter, frame and CRS, and for GeoParquet
//! tables the geometry column's types, CRS (PROJJSON) and covering; per LAS
//! file: points, bytes, scale and offset, and the extra-bytes dimensions with
//! the `change_class` code table.

use super::KNOWN_TABLES;
use crate::store::geoparquet::{BBOX_COLUMN, Crs, GEOMETRY_COLUMN, GEOPARQUET_VERSION, GeoSummary};
use crate::store::las_export::CHANGE_CLASS_CODES;
use crate::store::{StoreError, StoreMeta, now_utc};
use arrow_schema::{DataType, Field, SchemaRef};
use serde_json::{Value, json};
use std::fs::File;
use std::path::{Path, PathBuf};

/// One written file.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct Partition {
    /// The Hive partition; `None` for tables that are not partitioned.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub session: Option<i64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub session_name: Option<String>,
    /// The graph version the file's positions are on, for positional tables.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub graph_version: Option<i64>,
    /// Relative to OUT, `/`-separated.
    pub path: String,
    pub row_count: u64,
    pub size_bytes: u64,
    pub blake3: String,
    /// `[xmin, ymin, zmin, xmax, ymax, zmax]` of the file's geometries.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bbox: Option<[f64; 6]>,
}

#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct Column {
    pub name: String,
    #[serde(rename = "type")]
    pub type_name: String,
    pub nullable: bool,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub unit: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub description: Option<String>,
}

/// The frame positional columns (`x_m`, `y_m`, `z_m`, `geometry`) are in.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct Frame {
    /// Always `world`: the store's world frame (what `seam poses` prints).
    pub name: String,
    /// The store's CRS (`local` or an EPSG code).
    pub crs: String,
    /// The graph version positions are on; `None` where it differs per
    /// partition (each partition names its own).
    pub graph_version: Option<i64>,
    /// Edge of the voxel grid `kx`/`ky`/`kz` count in, metres.
    pub voxel_m: f64,
}

/// The GeoParquet geometry column of a table.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct GeometryEntry {
    pub column: String,
    pub encoding: String,
    pub geometry_types: Vec<String>,
    /// PROJJSON, as in each file's `geo` metadata.
    pub crs: Value,
    /// `false`: the PROJJSON is abbreviated to an EPSG id (see the README).
    pub crs_complete: bool,
    /// The covering column (`bbox.xmin`, ...), for filters without WKB.
    pub covering: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bbox: Option<[f64; 6]>,
}

#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct TableEntry {
    pub name: String,
    pub description: String,
    /// `GeoParquet 1.1.0` or `Parquet`.
    pub format: String,
    /// Relative to OUT.
    pub path: String,
    pub partition_by: Vec<String>,
    pub columns: Vec<Column>,
    pub row_count: u64,
    pub size_bytes: u64,
    /// How rows are ordered within each file.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sorted_by: Option<String>,
    /// The row filter that defines the table, if any.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub filter: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frame: Option<Frame>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub geometry: Option<GeometryEntry>,
    pub partitions: Vec<Partition>,
}

/// The unit a column's name (or type) states: `_m` metres, `_m3` cubic
/// metres, `_s` seconds, timestamps UTC, ε dimensionless.
pub fn unit_of(f: &Field) -> Option<&'static str> {
    let n = f.name().as_str();
    if matches!(f.data_type(), DataType::Timestamp(..)) {
        Some("UTC")
    } else if n.ends_with("_m3") {
        Some("m^3")
    } else if n.ends_with("_m") || n == GEOMETRY_COLUMN || n == BBOX_COLUMN {
        Some("m")
    } else if n.ends_with("_s") {
        Some("s")
    } else if n.starts_with("eps_") {
        Some("1")
    } else {
        None
    }
}

/// Arrow type names as analysts know them (`int32`, `float32`, `boolean`,
/// `string`, `binary`, `timestamp[us, tz=UTC]`, `struct<…>`).
pub fn type_name(t: &DataType) -> String {
    match t {
        DataType::Int32 => "int32".into(),
        DataType::Int64 => "int64".into(),
        DataType::Float32 => "float32".into(),
        DataType::Float64 => "float64".into(),
        DataType::Boolean => "boolean".into(),
        DataType::Utf8 => "string".into(),
        DataType::Binary => "binary".into(),
        DataType::Timestamp(unit, tz) => {
            let u = match unit {
                arrow_schema::TimeUnit::Second => "s",
                arrow_schema::TimeUnit::Millisecond => "ms",
                arrow_schema::TimeUnit::Microsecond => "us",
                arrow_schema::TimeUnit::Nanosecond => "ns",
            };
            match tz {
                Some(tz) => format!("timestamp[{u}, tz={tz}]"),
                None => format!("timestamp[{u}]"),
            }
        }
        DataType::Struct(fields) => {
            let inner: Vec<String> =
                fields.iter().map(|f| format!("{}: {}", f.name(), type_name(f.data_type()))).collect();
            format!("struct<{}>", inner.join(", "))
        }
        other => other.to_string().to_lowercase(),
    }
}

pub fn columns(schema: &SchemaRef) -> Vec<Column> {
    schema
        .fields()
        .iter()
        .map(|f| Column {
            name: f.name().clone(),
            type_name: type_name(f.data_type()),
            nullable: f.is_nullable(),
            unit: unit_of(f).map(str::to_string),
            description: f.metadata().get("description").cloned(),
        })
        .collect()
}

/// The catalog's geometry entry of a GeoParquet table.
pub fn geometry_entry(summary: &GeoSummary, crs: &Crs) -> GeometryEntry {
    GeometryEntry {
        column: GEOMETRY_COLUMN.into(),
        encoding: "WKB".into(),
        geometry_types: summary.types.iter().map(|t| t.as_str().to_string()).collect(),
        crs: crs.projjson(),
        crs_complete: crs.is_complete(),
        covering: BBOX_COLUMN.into(),
        bbox: summary.bbox,
    }
}

/// One written LAS/LAZ file.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct LasFile {
    /// `static_map` or `lifelong_map`.
    pub name: String,
    pub path: String,
    pub point_count: u64,
    pub size_bytes: u64,
    pub blake3: String,
    pub scale_m: f64,
    pub offset_m: [f64; 3],
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub filter: Option<String>,
    pub graph_version: Option<i64>,
    /// Whether the file has a WKT CRS record (not for EPSG codes seam cannot spell out).
    pub has_crs: bool,
}

/// The `las` section: the files and what their extra bytes mean.
pub fn las_section(files: &[LasFile], compressed: bool) -> Value {
    let codes: serde_json::Map<String, Value> =
        CHANGE_CLASS_CODES.iter().map(|(c, n)| (c.to_string(), json!(n))).collect();
    json!({
        "format": if compressed { "LAZ (LAS 1.4, point format 6)" } else { "LAS 1.4, point format 6" },
        "points": "one per map voxel, at its centroid (x_m, y_m, z_m), in the rows' order of map_voxels",
        "extra_bytes": [
            {"name": "eps_g", "type": "float32", "unit": "1", "description": "global ephemerality in [0, 1]"},
            {"name": "change_class", "type": "uint8", "description": "last change category of the voxel", "codes": codes},
        ],
        "files": files,
    })
}

/// Writes `OUT/_catalog.json` under a temporary name and renames it into
/// place. Tables (and LAS files) of an earlier export that this one did not
/// touch stay listed while their folders exist.
pub fn write_catalog(
    out: &Path,
    store: &Path,
    meta: &StoreMeta,
    crs: &Crs,
    entries: &[TableEntry],
    las: Option<Value>,
) -> anyhow::Result<()> {
    let path = out.join("_catalog.json");
    let mut tables: Vec<Value> = Vec::new();
    let mut old_las = None;
    if let Ok(text) = std::fs::read_to_string(&path)
        && let Ok(old) = serde_json::from_str::<Value>(&text)
    {
        for t in old.get("tables").and_then(|t| t.as_array()).into_iter().flatten() {
            let name = t.get("name").and_then(|n| n.as_str()).unwrap_or_default();
            let kept = !name.is_empty() && !entries.iter().any(|e| e.name == name) && out.join(name).is_dir();
            if kept {
                tables.push(t.clone());
            }
        }
        old_las = old.get("las").filter(|_| out.join("las").is_dir()).cloned();
    }
    for e in entries {
        tables.push(serde_json::to_value(e)?);
    }
    let order = |t: &Value| {
        let name = t.get("name").and_then(|n| n.as_str()).unwrap_or_default();
        KNOWN_TABLES.iter().position(|k| *k == name).unwrap_or(usize::MAX)
    };
    tables.sort_by_key(order);
    let mut catalog = json!({
        "format": "seam-export",
        "version": 2,
        "seam_version": env!("CARGO_PKG_VERSION"),
        "geoparquet_version": GEOPARQUET_VERSION,
        "store": std::fs::canonicalize(store).unwrap_or_else(|_| PathBuf::from(store)).display().to_string(),
        "site_name": meta.site_name,
        "crs": meta.crs,
        "crs_projjson": crs.projjson(),
        "exported_at": now_utc(),
        "tables": tables,
    });
    if let Some(l) = las.or(old_las) {
        catalog["las"] = l;
    }
    let tmp = path.with_extension(format!("json.tmp-{}", std::process::id()));
    let write = || -> std::io::Result<()> {
        let mut f = File::create(&tmp)?;
        serde_json::to_writer_pretty(&mut f, &catalog)?;
        std::io::Write::write_all(&mut f, b"\n")?;
        f.sync_all()?;
        std::fs::rename(&tmp, &path)
    };
    if let Err(e) = write() {
        let _ = std::fs::remove_file(&tmp);
        return Err(StoreError::io(&path, e).into());
    }
    super::sync_dir(out)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn type_names_and_units() {
        assert_eq!(type_name(&DataType::Boolean), "boolean");
        assert_eq!(type_name(&DataType::Utf8), "string");
        let ts = DataType::Timestamp(arrow_schema::TimeUnit::Microsecond, Some("UTC".into()));
        assert_eq!(type_name(&ts), "timestamp[us, tz=UTC]");
        let f = crate::store::geoparquet::geometry_fields(false, "x");
        assert_eq!(type_name(f[1].data_type()), "struct<xmin: float64, ymin: float64, xmax: float64, ymax: float64>");
        assert_eq!(unit_of(&Field::new("volume_m3", DataType::Float64, false)), Some("m^3"));
        assert_eq!(unit_of(&Field::new("x_m", DataType::Float64, false)), Some("m"));
        assert_eq!(unit_of(&Field::new("created_at", ts, true)), Some("UTC"));
        assert_eq!(unit_of(&Field::new("eps_g", DataType::Float32, false)), Some("1"));
        assert_eq!(unit_of(&Field::new("qx", DataType::Float64, false)), None);
    }
}
