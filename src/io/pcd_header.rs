//! The PCD text header: `VERSION`, `FIELDS`, `SIZE`, `TYPE`, `COUNT`,
//! `WIDTH`, `HEIGHT`, `VIEWPOINT`, `POINTS`, `DATA`, checked against each
//! other line by line so that a lying header is reported where it lies.

use std::io::Read;
use std::path::Path;

use crate::io::error::{Location, ReadError, ReadErrorKind};

/// Largest header accepted, so that reading a `VIEWPOINT` never reads a scan.
const MAX_HEADER_BYTES: u64 = 1 << 20;

/// The `DATA` encoding.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Data {
    Ascii,
    Binary,
    BinaryCompressed,
}

/// One `FIELDS` entry with its `SIZE`, `TYPE` (b'I', b'U', b'F') and `COUNT`.
#[derive(Debug, Clone)]
pub(super) struct Field {
    pub(super) name: String,
    pub(super) size: usize,
    pub(super) kind: u8,
    pub(super) count: usize,
    /// Byte offset of the field inside one point record.
    pub(super) offset: usize,
}

/// A header whose lines agree with each other (see `parse_header`).
#[derive(Debug, Clone)]
pub(super) struct Header {
    pub(super) fields: Vec<Field>,
    pub(super) points: usize,
    /// `VIEWPOINT tx ty tz qw qx qy qz` and its line, when present.
    pub(super) viewpoint: Option<(usize, [f64; 7])>,
    pub(super) data: Data,
    /// First byte after the `DATA` line.
    pub(super) data_offset: usize,
    /// Lines in the header, so that ascii data lines get file line numbers.
    pub(super) header_lines: usize,
    pub(super) point_size: usize,
}

pub(super) fn bad_header(path: &Path, line: usize, message: impl Into<String>) -> ReadError {
    ReadError::new(ReadErrorKind::BadHeader, path, message)
        .at(Location::Line(line))
        .hint("the PCD header contradicts itself; re-export the cloud with PCL (pcl::io::savePCDFile)")
}

/// Lines of `bytes` as `(1-based number, text without \r\n, offset after the line)`.
pub(super) fn lines(bytes: &[u8]) -> impl Iterator<Item = (usize, &[u8], usize)> {
    let mut start = 0;
    let mut n = 0;
    std::iter::from_fn(move || {
        if start >= bytes.len() {
            return None;
        }
        let rest = bytes.get(start..)?;
        let end = rest.iter().position(|&b| b == b'\n').map_or(bytes.len(), |p| start + p);
        let text = bytes.get(start..end)?;
        let text = text.strip_suffix(b"\r").unwrap_or(text);
        start = end + 1;
        n += 1;
        Some((n, text, start.min(bytes.len())))
    })
}

fn parse_usize(path: &Path, line: usize, key: &str, tok: &str) -> Result<usize, ReadError> {
    tok.parse().map_err(|_| bad_header(path, line, format!("{key} value `{tok}` is not a whole number")))
}

/// Parses the header up to and including the `DATA` line.
pub(super) fn parse_header(path: &Path, bytes: &[u8]) -> Result<Header, ReadError> {
    let mut keys: Vec<(String, usize, Vec<String>)> = Vec::new();
    let mut data = None;
    let mut last_line = 0;
    for (n, raw, next) in lines(bytes) {
        last_line = n;
        let text = std::str::from_utf8(raw).map_err(|_| bad_header(path, n, "header line is not text"))?;
        let text = text.trim();
        if text.is_empty() || text.starts_with('#') {
            continue;
        }
        let mut toks = text.split_whitespace();
        let key = toks.next().unwrap_or_default().to_string();
        let vals: Vec<String> = toks.map(str::to_string).collect();
        if !matches!(
            key.as_str(),
            "VERSION" | "FIELDS" | "SIZE" | "TYPE" | "COUNT" | "WIDTH" | "HEIGHT" | "VIEWPOINT" | "POINTS" | "DATA"
        ) {
            return Err(bad_header(path, n, format!("unknown header key `{key}` (is this a PCD file?)")));
        }
        if keys.iter().any(|(k, _, _)| *k == key) {
            return Err(bad_header(path, n, format!("{key} appears twice")));
        }
        if key == "DATA" {
            data = Some((n, vals.first().cloned().unwrap_or_default(), next));
            break;
        }
        keys.push((key, n, vals));
    }
    let Some((data_line, data_kind, data_offset)) = data else {
        let msg = format!("no DATA line in the first {} header lines", last_line);
        return Err(bad_header(path, last_line.max(1), msg));
    };
    let data = match data_kind.as_str() {
        "ascii" => Data::Ascii,
        "binary" => Data::Binary,
        "binary_compressed" => Data::BinaryCompressed,
        other => {
            return Err(bad_header(
                path,
                data_line,
                format!("DATA `{other}` is not one of ascii, binary, binary_compressed"),
            ));
        }
    };
    let get = |key: &str| keys.iter().find(|(k, _, _)| k == key).map(|(_, n, v)| (*n, v.as_slice()));
    let missing = |key: &str| bad_header(path, data_line, format!("header has no {key} line before DATA"));

    let (fields_line, names) = get("FIELDS").ok_or_else(|| missing("FIELDS"))?;
    let per_field = |key: &str| -> Result<Option<(usize, &[String])>, ReadError> {
        let Some((n, v)) = get(key) else { return Ok(None) };
        if v.len() != names.len() {
            return Err(bad_header(
                path,
                n,
                format!("{key} has {} entries but FIELDS (line {fields_line}) names {}", v.len(), names.len()),
            ));
        }
        Ok(Some((n, v)))
    };
    let (size_line, sizes) = per_field("SIZE")?.ok_or_else(|| missing("SIZE"))?;
    let (type_line, types) = per_field("TYPE")?.ok_or_else(|| missing("TYPE"))?;
    let counts = per_field("COUNT")?;

    let mut fields = Vec::with_capacity(names.len());
    let mut offset = 0usize;
    for (k, name) in names.iter().enumerate() {
        let size_tok = sizes.get(k).map_or("", String::as_str);
        let size = parse_usize(path, size_line, "SIZE", size_tok)?;
        let kind = match types.get(k).map(String::as_str) {
            Some("F") if size == 4 || size == 8 => b'F',
            Some("I") if matches!(size, 1 | 2 | 4 | 8) => b'I',
            Some("U") if matches!(size, 1 | 2 | 4 | 8) => b'U',
            Some(t) => {
                let line = if matches!(t, "F" | "I" | "U") { size_line } else { type_line };
                return Err(bad_header(path, line, format!("field `{name}` has TYPE {t} with SIZE {size}")));
            }
            None => return Err(missing("TYPE")),
        };
        let count = match counts {
            Some((n, c)) => match parse_usize(path, n, "COUNT", c.get(k).map_or("", String::as_str))? {
                0 => return Err(bad_header(path, n, format!("field `{name}` has COUNT 0"))),
                c => c,
            },
            None => 1,
        };
        fields.push(Field { name: name.clone(), size, kind, count, offset });
        offset = size
            .checked_mul(count)
            .and_then(|b| offset.checked_add(b))
            .ok_or_else(|| bad_header(path, size_line, "point record size overflows"))?;
    }
    for axis in ["x", "y", "z"] {
        if !fields.iter().any(|f| f.name == axis) {
            return Err(bad_header(path, fields_line, format!("FIELDS has no `{axis}` (found: {})", names.join(" ")))
                .hint("seam needs x, y and z; a cloud without coordinates cannot be mapped"));
        }
    }

    let one = |key: &str| -> Result<Option<(usize, usize)>, ReadError> {
        match get(key) {
            None => Ok(None),
            Some((n, [v])) => Ok(Some((n, parse_usize(path, n, key, v)?))),
            Some((n, v)) => Err(bad_header(path, n, format!("{key} has {} values, expected one", v.len()))),
        }
    };
    let (_, width) = one("WIDTH")?.ok_or_else(|| missing("WIDTH"))?;
    let height = one("HEIGHT")?.map_or(1, |(_, h)| h);
    let wh = width.checked_mul(height);
    let points = match one("POINTS")? {
        Some((n, p)) if Some(p) != wh => {
            return Err(bad_header(path, n, format!("POINTS {p} is not WIDTH × HEIGHT = {width} × {height}")));
        }
        Some((_, p)) => p,
        None => wh.ok_or_else(|| bad_header(path, data_line, "WIDTH × HEIGHT overflows"))?,
    };
    let viewpoint = match get("VIEWPOINT") {
        None => None,
        Some((n, v)) => {
            let nums: Vec<f64> = v.iter().filter_map(|t| t.parse().ok()).collect();
            let arr: [f64; 7] = nums.as_slice().try_into().map_err(|_| {
                bad_header(
                    path,
                    n,
                    format!("VIEWPOINT needs 7 numbers (tx ty tz qw qx qy qz), found `{}`", v.join(" ")),
                )
            })?;
            Some((n, arr))
        }
    };
    Ok(Header { fields, points, viewpoint, data, data_offset, header_lines: data_line, point_size: offset })
}

/// Reads the header of a PCD file (at most 1 MiB, never the data).
pub(super) fn read_header_only(path: &Path) -> Result<Header, ReadError> {
    let file = std::fs::File::open(path).map_err(|e| ReadError::io(path, &e))?;
    let mut prefix = Vec::new();
    file.take(MAX_HEADER_BYTES).read_to_end(&mut prefix).map_err(|e| ReadError::io(path, &e))?;
    parse_header(path, &prefix)
}
