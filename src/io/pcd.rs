//! PCD v0.7 (Point Cloud Library) scans: `ascii`, `binary` and
//! `binary_compressed`, any `FIELDS` with `SIZE` 1/2/4/8, `TYPE` I/U/F and
//! `COUNT` ≥ 1. Only `x y z` (required) and `intensity` or `i` (optional,
//! first element when `COUNT` > 1) are kept; other fields are skipped.
//!
//! # Why hand-written and not `pcd-rs`
//!
//! Validation is the point of this module: a truncated file must say at which
//! byte it ends, a lying header at which line it lies (`POINTS` ≠ `WIDTH` ×
//! `HEIGHT`, `SIZE`/`TYPE`/`COUNT` not one per field, an unknown `DATA`), and
//! no byte sequence may panic. `pcd-rs` reports neither lines nor byte
//! offsets, and its dynamic-record reader allocates a `Vec` per field per
//! point where we need four numbers. The format is small: a text header and
//! three encodings, the compressed one being an LZF block (the `lzf` crate) of
//! the fields stored column by column. About 300 lines buy exact errors,
//! bounded allocations (never more than the file's size implies) and a
//! property test over random and truncated inputs.
//!
//! Trailing bytes after the binary data are ignored (some tools pad files);
//! extra ascii lines are not (they mean `POINTS` is wrong).

use std::path::Path;

use crate::geometry::{Pose, Scan, pose_from_tum};

use super::error::{Location, ReadError, ReadErrorKind, read_bytes};

#[path = "pcd_header.rs"]
mod header;

use header::{Data, Field, Header, bad_header, lines, parse_header, read_header_only};

/// LZF cannot expand data by more than this factor (a 3-byte back reference
/// covers at most 264 bytes), so a larger claim is a lie, not a large cloud.
const MAX_LZF_RATIO: u64 = 100;

/// Decodes one little-endian value of the given SIZE/TYPE, `None` if out of bounds.
fn decode(bytes: &[u8], at: usize, size: usize, kind: u8) -> Option<f64> {
    let b = bytes.get(at..at.checked_add(size)?)?;
    let a = |n: usize| -> Option<[u8; 8]> {
        let mut out = [0u8; 8];
        out.get_mut(..n)?.copy_from_slice(b.get(..n)?);
        Some(out)
    };
    let v = a(size)?;
    Some(match (kind, size) {
        (b'F', 4) => f64::from(f32::from_le_bytes([v[0], v[1], v[2], v[3]])),
        (b'F', 8) => f64::from_le_bytes(v),
        (b'I', 1) => f64::from(v[0] as i8),
        (b'I', 2) => f64::from(i16::from_le_bytes([v[0], v[1]])),
        (b'I', 4) => f64::from(i32::from_le_bytes([v[0], v[1], v[2], v[3]])),
        (b'I', 8) => i64::from_le_bytes(v) as f64,
        (b'U', 1) => f64::from(v[0]),
        (b'U', 2) => f64::from(u16::from_le_bytes([v[0], v[1]])),
        (b'U', 4) => f64::from(u32::from_le_bytes([v[0], v[1], v[2], v[3]])),
        (b'U', 8) => u64::from_le_bytes(v) as f64,
        _ => return None,
    })
}

/// Indices of x, y, z and (optionally) intensity in `fields`.
fn wanted(h: &Header) -> ([usize; 3], Option<usize>) {
    let find = |n: &str| h.fields.iter().position(|f| f.name == n);
    // parse_header guarantees x, y, z exist.
    let xyz = [find("x").unwrap_or(0), find("y").unwrap_or(0), find("z").unwrap_or(0)];
    (xyz, find("intensity").or_else(|| find("i")))
}

/// Reads a PCD scan, points as stored.
pub fn read_pcd(path: &Path) -> Result<Scan, ReadError> {
    parse_pcd(path, &read_bytes(path)?)
}

/// Decodes the bytes of a PCD file; `path` only names the file in errors.
pub(crate) fn parse_pcd(path: &Path, bytes: &[u8]) -> Result<Scan, ReadError> {
    let h = parse_header(path, bytes)?;
    match h.data {
        Data::Ascii => parse_ascii(path, bytes, &h),
        Data::Binary => {
            let body = binary_body(path, bytes, &h)?;
            Ok(extract(&h, body, |f, i| i * h.point_size + f.offset))
        }
        Data::BinaryCompressed => {
            let body = decompress_body(path, bytes, &h)?;
            Ok(extract(&h, &body, |f, i| h.points * f.offset + i * f.size * f.count))
        }
    }
}

/// Pulls x, y, z, intensity out of decoded binary data; `at(field, i)` is the
/// byte of point i's field (the layouts differ between the two encodings).
/// The caller has checked that `body` holds `points × point_size` bytes.
fn extract(h: &Header, body: &[u8], at: impl Fn(&Field, usize) -> usize) -> Scan {
    let (xyz, inten) = wanted(h);
    let fields = &h.fields;
    let value = |k: usize, i: usize| {
        fields.get(k).and_then(|f| decode(body, at(f, i), f.size, f.kind)).unwrap_or(f64::NAN) as f32
    };
    let mut scan = Scan { points: Vec::with_capacity(h.points), intensity: Vec::new() };
    for i in 0..h.points {
        scan.points.push([value(xyz[0], i), value(xyz[1], i), value(xyz[2], i)]);
    }
    if let Some(k) = inten {
        scan.intensity = (0..h.points).map(|i| value(k, i)).collect();
    }
    scan
}

fn total_bytes(path: &Path, h: &Header) -> Result<usize, ReadError> {
    h.points.checked_mul(h.point_size).ok_or_else(|| {
        bad_header(path, h.header_lines, format!("POINTS {} × {} bytes per point overflows", h.points, h.point_size))
    })
}

fn truncated(path: &Path, file_len: usize, message: String) -> ReadError {
    ReadError::new(ReadErrorKind::Truncated, path, message)
        .at(Location::Byte(file_len as u64))
        .hint("the file was cut short (interrupted copy or write?): copy or export it again")
}

fn binary_body<'a>(path: &Path, bytes: &'a [u8], h: &Header) -> Result<&'a [u8], ReadError> {
    let need = total_bytes(path, h)?;
    let have = bytes.len().saturating_sub(h.data_offset);
    bytes.get(h.data_offset..).and_then(|b| b.get(..need)).ok_or_else(|| {
        truncated(
            path,
            bytes.len(),
            format!(
                "header says {} points × {} bytes = {need} bytes of binary data from byte {}, but the \
                 file ends after {have} ({} whole points)",
                h.points,
                h.point_size,
                h.data_offset,
                have / h.point_size.max(1)
            ),
        )
    })
}

fn decompress_body(path: &Path, bytes: &[u8], h: &Header) -> Result<Vec<u8>, ReadError> {
    let need = total_bytes(path, h)?;
    if need == 0 {
        return Ok(Vec::new());
    }
    let start = h.data_offset;
    let word = |at: usize| -> Option<u32> {
        let b: [u8; 4] = bytes.get(at..at.checked_add(4)?)?.try_into().ok()?;
        Some(u32::from_le_bytes(b))
    };
    let (Some(packed), Some(unpacked)) = (word(start), start.checked_add(4).and_then(word)) else {
        let msg = format!("binary_compressed data needs an 8-byte size prefix at byte {start}");
        return Err(truncated(path, bytes.len(), msg));
    };
    let (packed, unpacked) = (packed as usize, unpacked as usize);
    if unpacked != need {
        return Err(ReadError::new(
            ReadErrorKind::BadHeader,
            path,
            format!(
                "compressed block unpacks to {unpacked} bytes, but the header's POINTS {} × {} bytes per \
                 point = {need}",
                h.points, h.point_size
            ),
        )
        .at(Location::Byte(start as u64 + 4))
        .hint("the header and the data disagree on the number of points; re-export the cloud"));
    }
    let body = start.checked_add(8).and_then(|s| bytes.get(s..s.checked_add(packed)?)).ok_or_else(|| {
        truncated(
            path,
            bytes.len(),
            format!("compressed block of {packed} bytes starts at byte {} but the file ends first", start + 8),
        )
    })?;
    let corrupt = |why: &str| {
        ReadError::new(ReadErrorKind::Parse, path, format!("compressed block is not valid LZF: {why}"))
            .at(Location::Byte(start as u64 + 8))
            .hint("the file is damaged; copy or export it again")
    };
    if (need as u64) > (packed as u64).saturating_mul(MAX_LZF_RATIO) + 64 {
        return Err(corrupt(&format!("{packed} bytes cannot unpack to {need}")));
    }
    let out = lzf::decompress(body, need).map_err(|e| corrupt(&e.to_string()))?;
    if out.len() != need {
        return Err(corrupt(&format!("it unpacks to {} bytes, the header needs {need}", out.len())));
    }
    Ok(out)
}

fn parse_ascii(path: &Path, bytes: &[u8], h: &Header) -> Result<Scan, ReadError> {
    let (xyz, inten) = wanted(h);
    // Token index of each wanted field's first element on a line.
    let token_of = |k: usize| h.fields.iter().take(k).map(|f| f.count).sum::<usize>();
    let per_line: usize = h.fields.iter().map(|f| f.count).sum();
    let (tx, ty, tz, ti) = (token_of(xyz[0]), token_of(xyz[1]), token_of(xyz[2]), inten.map(token_of));
    let body = bytes.get(h.data_offset..).unwrap_or_default();
    // Every point needs at least a byte, so this bounds the allocation by the file.
    let cap = h.points.min(body.len());
    let mut scan =
        Scan { points: Vec::with_capacity(cap), intensity: Vec::with_capacity(if ti.is_some() { cap } else { 0 }) };
    let mut toks: Vec<&str> = Vec::with_capacity(per_line);
    for (n, raw, _) in lines(body) {
        let line = n + h.header_lines;
        let text = std::str::from_utf8(raw).map_err(|_| {
            ReadError::new(ReadErrorKind::Parse, path, "ascii data line is not text").at(Location::Line(line))
        })?;
        toks.clear();
        toks.extend(text.split_whitespace());
        if toks.is_empty() {
            continue;
        }
        if scan.points.len() == h.points {
            return Err(bad_header(path, line, format!("more data lines than POINTS {}", h.points)));
        }
        if toks.len() != per_line {
            return Err(ReadError::new(
                ReadErrorKind::Parse,
                path,
                format!("{} values on a data line, expected {per_line} (one per FIELDS entry × COUNT)", toks.len()),
            )
            .at(Location::Line(line))
            .hint("every ascii data line holds one point with all its fields"));
        }
        let num = |t: usize| -> Result<f32, ReadError> {
            let tok = toks.get(t).copied().unwrap_or_default();
            tok.parse::<f64>().map(|v| v as f32).map_err(|_| {
                ReadError::new(ReadErrorKind::Parse, path, format!("`{tok}` is not a number"))
                    .at(Location::Line(line))
                    .hint("ascii PCD data holds decimal numbers only")
            })
        };
        scan.points.push([num(tx)?, num(ty)?, num(tz)?]);
        if let Some(ti) = ti {
            scan.intensity.push(num(ti)?);
        }
    }
    if scan.points.len() < h.points {
        return Err(truncated(
            path,
            bytes.len(),
            format!("header says {} points, but the ascii data ends after {}", h.points, scan.points.len()),
        ));
    }
    Ok(scan)
}

/// The `VIEWPOINT` of a PCD file as a pose, `None` when the header has none.
pub(crate) fn read_viewpoint(path: &Path) -> Result<Option<Pose>, ReadError> {
    let Some((line, [tx, ty, tz, qw, qx, qy, qz])) = read_header_only(path)?.viewpoint else {
        return Ok(None);
    };
    if [tx, ty, tz, qw, qx, qy, qz].iter().any(|v| !v.is_finite()) {
        return Err(ReadError::new(ReadErrorKind::NonFinite, path, "VIEWPOINT has a non-finite value")
            .at(Location::Line(line))
            .hint("the sensor pose was not set when the cloud was saved"));
    }
    pose_from_tum([tx, ty, tz], [qx, qy, qz, qw]).map(Some).map_err(|norm| {
        ReadError::new(
            ReadErrorKind::NotRotation,
            path,
            format!("VIEWPOINT quaternion (qw qx qy qz = {qw} {qx} {qy} {qz}) has norm {norm:.6}, not 1"),
        )
        .at(Location::Line(line))
        .hint("PCD stores VIEWPOINT as tx ty tz qw qx qy qz (w first)")
    })
}

/// The PCD `VIEWPOINT tx ty tz qw qx qy qz` as a pose (identity when absent, as in PCL).
pub fn pcd_viewpoint(path: &Path) -> Result<Pose, ReadError> {
    Ok(read_viewpoint(path)?.unwrap_or_else(Pose::identity))
}

#[cfg(test)]
#[path = "pcd_tests.rs"]
mod tests;
