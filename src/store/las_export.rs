//! The static and lifelong maps as LAS 1.4 / LAZ point clouds (`seam export
//! --las`): one point per map voxel at its centroid, point format 6, scale
//! 1 mm, with two documented extra-bytes dimensions that LAStools, PDAL,
//! laspy and CloudCompare read by name:
//!
//! | name | type | meaning |
//! |------|------|---------|
//! | `eps_g` | float32 | global ephemerality in [0, 1] (static below the threshold) |
//! | `change_class` | uint8 | last change category, [`CHANGE_CLASS_CODES`] |
//!
//! The `las` crate writes extra bytes but not their description, so the
//! Extra Bytes VLR (`LASF_Spec` 4, one 192-byte descriptor per dimension) is
//! built here ([`extra_bytes_vlr`]). The code table of `change_class` does not
//! fit the descriptor's 32-byte description, which holds an abbreviation;
//! the whole table is in a `seam` VLR (record 1, UTF-8 text), in
//! `_catalog.json` and in the README. The CRS is an OGC WKT VLR
//! (`LASF_Projection` 2112) where seam can write a complete WKT (local frames,
//! WGS 84 / UTM); for other EPSG codes the file has none (the catalog says so).
//!
//! Files are written under a temporary name, fsynced and renamed
//! ([`super::files::publish`]), like every export file.

use super::files::publish;
use super::geoparquet::Crs;
use super::{StoreError, evidence_files::WrittenFile};
use crate::change::Category;
use std::fs::File;
use std::io::{BufWriter, Read};
use std::path::Path;

/// `change_class` codes: the index of the category in [`Category::ALL`].
pub const CHANGE_CLASS_CODES: [(u8, &str); 6] = [
    (0, "initial"),
    (1, "coexist"),
    (2, "deleted_overlap"),
    (3, "deleted_non_overlap"),
    (4, "emerged_overlap"),
    (5, "emerged_non_overlap"),
];

/// What the `change_class` descriptor's 32-byte description says.
const CHANGE_CLASS_SHORT: &str = "0ini 1coe 2delO 3delN 4emO 5emN";

/// Bytes each point carries after the format-6 record: `eps_g`, `change_class`.
const EXTRA_BYTES: u16 = 5;

/// The `change_class` code of a category.
pub fn change_class(c: Category) -> u8 {
    Category::ALL.iter().position(|a| *a == c).unwrap_or(0) as u8
}

/// One exported point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LasMapPoint {
    pub xyz_m: [f64; 3],
    pub eps_g: f32,
    pub change_class: u8,
}

/// A written LAS/LAZ file.
#[derive(Debug, Clone, PartialEq)]
pub struct LasWritten {
    pub file: WrittenFile,
    pub scale_m: f64,
    pub offset_m: [f64; 3],
    /// Whether the file carries a WKT CRS record.
    pub has_crs: bool,
}

/// One 192-byte Extra Bytes descriptor (LAS 1.4 R15, Table 24): reserved,
/// data type (1 = uint8, 9 = float32), options (none: no no-data, min, max,
/// scale or offset), name, unused, five deprecated/unused value slots, and
/// a description, both NUL-padded.
fn descriptor(data_type: u8, name: &str, description: &str) -> [u8; 192] {
    let mut d = [0u8; 192];
    d[2] = data_type;
    let n = name.len().min(32);
    d[4..4 + n].copy_from_slice(&name.as_bytes()[..n]);
    let k = description.len().min(32);
    d[160..160 + k].copy_from_slice(&description.as_bytes()[..k]);
    d
}

/// The Extra Bytes VLR describing `eps_g` (float32) then `change_class` (uint8).
pub fn extra_bytes_vlr() -> las::Vlr {
    let mut data = Vec::with_capacity(2 * 192);
    data.extend_from_slice(&descriptor(9, "eps_g", "global ephemerality in [0, 1]"));
    data.extend_from_slice(&descriptor(1, "change_class", CHANGE_CLASS_SHORT));
    las::Vlr { user_id: "LASF_Spec".into(), record_id: 4, description: "seam extra bytes".into(), data }
}

/// The `change_class` code table as text, for the `seam` VLR.
pub fn change_class_table() -> String {
    let rows: Vec<String> = CHANGE_CLASS_CODES.iter().map(|(c, n)| format!("{c} = {n}")).collect();
    format!("change_class (uint8 extra bytes): last change category of the voxel\n{}\n", rows.join("\n"))
}

/// The scale and offset that fit every point in LAS's int32 coordinates:
/// 1 mm where the extent allows (±2,147 m around the box centre), coarser
/// by tens otherwise.
fn transform(points: &[LasMapPoint]) -> (f64, [f64; 3]) {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in points {
        for i in 0..3 {
            lo[i] = lo[i].min(p.xyz_m[i]);
            hi[i] = hi[i].max(p.xyz_m[i]);
        }
    }
    if points.is_empty() {
        return (0.001, [0.0; 3]);
    }
    let offset: [f64; 3] = std::array::from_fn(|i| ((lo[i] + hi[i]) / 2.0).round());
    let half = (0..3).map(|i| (hi[i] - offset[i]).max(offset[i] - lo[i])).fold(0.0, f64::max);
    let mut scale = 0.001;
    while half / scale > 2.0e9 {
        scale *= 10.0;
    }
    (scale, offset)
}

/// Writes `points` to `path` (LAZ if `compressed`) in `crs` with the
/// publish protocol.
pub fn write_map_las(
    path: &Path,
    points: &[LasMapPoint],
    crs: &Crs,
    compressed: bool,
) -> Result<LasWritten, StoreError> {
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(|e| StoreError::io(dir, e))?;
    }
    let tmp = path.with_extension(format!("tmp-{}", std::process::id()));
    let result = write_tmp(&tmp, points, crs, compressed);
    let (scale_m, offset_m, has_crs) = match result {
        Ok(v) => v,
        Err(e) => {
            let _ = std::fs::remove_file(&tmp);
            return Err(e);
        }
    };
    let (size_bytes, blake3) = hash_file(&tmp)?;
    crate::fault::point("export:before_rename");
    publish(&tmp, path)?;
    Ok(LasWritten {
        file: WrittenFile { size_bytes, blake3, row_count: points.len() as u64 },
        scale_m,
        offset_m,
        has_crs,
    })
}

fn las_err(path: &Path, e: las::Error) -> StoreError {
    StoreError::Io { path: path.to_path_buf(), source: std::io::Error::other(e.to_string()) }
}

fn write_tmp(
    tmp: &Path,
    points: &[LasMapPoint],
    crs: &Crs,
    compressed: bool,
) -> Result<(f64, [f64; 3], bool), StoreError> {
    let err = |e| las_err(tmp, e);
    let (scale, offset) = transform(points);
    let mut b = las::Builder::from((1, 4));
    b.point_format = las::point::Format::new(6).map_err(err)?;
    b.point_format.extra_bytes = EXTRA_BYTES;
    b.point_format.is_compressed = compressed;
    b.transforms = las::Vector {
        x: las::Transform { scale, offset: offset[0] },
        y: las::Transform { scale, offset: offset[1] },
        z: las::Transform { scale, offset: offset[2] },
    };
    b.system_identifier = "seam export".into();
    b.generating_software = format!("seam {}", env!("CARGO_PKG_VERSION"));
    b.vlrs.push(extra_bytes_vlr());
    let wkt = crs.las_wkt();
    if let Some(w) = &wkt {
        let mut data = w.clone().into_bytes();
        data.push(0);
        b.vlrs.push(las::Vlr {
            user_id: "LASF_Projection".into(),
            record_id: 2112,
            description: "OGC WKT".into(),
            data,
        });
    }
    b.vlrs.push(las::Vlr {
        user_id: "seam".into(),
        record_id: 1,
        description: "change_class codes".into(),
        data: change_class_table().into_bytes(),
    });
    let header = b.into_header().map_err(err)?;
    let file = File::create(tmp).map_err(|e| StoreError::io(tmp, e))?;
    let mut w = las::Writer::new(BufWriter::with_capacity(1 << 20, file), header).map_err(err)?;
    for p in points {
        let mut extra = Vec::with_capacity(EXTRA_BYTES as usize);
        extra.extend_from_slice(&p.eps_g.to_le_bytes());
        extra.push(p.change_class);
        w.write_point(las::Point {
            x: p.xyz_m[0],
            y: p.xyz_m[1],
            z: p.xyz_m[2],
            return_number: 1,
            number_of_returns: 1,
            gps_time: Some(0.0),
            extra_bytes: extra,
            ..Default::default()
        })
        .map_err(err)?;
    }
    let inner = w.into_inner().map_err(err)?;
    let file = inner.into_inner().map_err(|e| StoreError::io(tmp, e.into_error()))?;
    file.sync_all().map_err(|e| StoreError::io(tmp, e))?;
    Ok((scale, offset, wkt.is_some()))
}

fn hash_file(path: &Path) -> Result<(u64, String), StoreError> {
    let mut f = File::open(path).map_err(|e| StoreError::io(path, e))?;
    let mut h = blake3::Hasher::new();
    let mut buf = vec![0u8; 1 << 20];
    let mut n = 0u64;
    loop {
        let k = f.read(&mut buf).map_err(|e| StoreError::io(path, e))?;
        if k == 0 {
            break;
        }
        h.update(&buf[..k]);
        n += k as u64;
    }
    Ok((n, h.finalize().to_hex().to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn descriptors_follow_the_las_1_4_layout() {
        let v = extra_bytes_vlr();
        assert_eq!((v.user_id.as_str(), v.record_id, v.data.len()), ("LASF_Spec", 4, 384));
        let eps = &v.data[..192];
        assert_eq!(eps[2], 9, "float");
        assert_eq!(&eps[4..9], b"eps_g");
        assert!(eps[9..36].iter().all(|&b| b == 0));
        let class = &v.data[192..];
        assert_eq!(class[2], 1, "unsigned char");
        assert_eq!(&class[4..16], b"change_class");
        assert_eq!(&class[160..160 + CHANGE_CLASS_SHORT.len()], CHANGE_CLASS_SHORT.as_bytes());
        assert!(CHANGE_CLASS_SHORT.len() < 32, "NUL-terminated in 32 bytes");
        for (code, name) in CHANGE_CLASS_CODES {
            let c = Category::parse(name).unwrap();
            assert_eq!(change_class(c), code, "{name}");
        }
    }

    #[test]
    fn writes_and_reads_back_with_the_las_crate() {
        let dir = tempfile::tempdir().unwrap();
        let pts: Vec<LasMapPoint> = (0..1000)
            .map(|i| LasMapPoint {
                xyz_m: [i as f64 * 0.0137 - 3.0, 500_000.0 + (i % 17) as f64, -(i as f64) * 0.002],
                eps_g: (i % 9) as f32 / 10.0,
                change_class: (i % 6) as u8,
            })
            .collect();
        for (name, compressed) in [("m.laz", true), ("m.las", false)] {
            let path = dir.path().join(name);
            let w = write_map_las(&path, &pts, &Crs::Epsg(32652), compressed).unwrap();
            assert!(w.has_crs);
            assert_eq!(w.file.size_bytes, std::fs::metadata(&path).unwrap().len());
            let mut r = las::Reader::from_path(&path).unwrap();
            let h = r.header().clone();
            assert_eq!((h.version().major, h.version().minor), (1, 4));
            assert_eq!(h.point_format().to_u8().unwrap(), 6);
            assert_eq!(h.number_of_points(), 1000);
            assert!(h.all_vlrs().any(|v| v.user_id == "LASF_Spec" && v.record_id == 4));
            for (p, want) in r.read_all().unwrap().points().map(|p| p.unwrap()).zip(&pts) {
                for (got, w) in [p.x, p.y, p.z].iter().zip(want.xyz_m) {
                    assert!((got - w).abs() <= 0.0005 + 1e-9, "{got} vs {w}");
                }
                assert_eq!(f32::from_le_bytes(p.extra_bytes[..4].try_into().unwrap()), want.eps_g);
                assert_eq!(p.extra_bytes[4], want.change_class);
            }
        }
        // No points: still a valid file.
        let path = dir.path().join("empty.laz");
        write_map_las(&path, &[], &Crs::Local { site: "s".into() }, true).unwrap();
        assert_eq!(las::Reader::from_path(&path).unwrap().header().number_of_points(), 0);
    }
}
