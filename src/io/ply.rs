//! PLY scans (ascii, binary little- and big-endian) through `ply-rs-bw`.
//!
//! Only the `vertex` element is decoded: `x y z` (any scalar type, usually
//! `float` or `double`) and an optional intensity, named `intensity`,
//! `scalar_intensity` (CloudCompare's export) or `i`, in that order of
//! preference. Other elements (faces, edges) are read past and dropped.

use std::io::ErrorKind;
use std::path::Path;

use ply_rs_bw::parser::{ParseError, Parser, Reader};
use ply_rs_bw::ply::{Encoding, Header, Property, PropertyAccess, PropertyAccessResult, PropertyType};

use crate::geometry::Scan;

use super::error::{Location, ReadError, ReadErrorKind, read_bytes};

/// Intensity property names, most preferred first.
const INTENSITY_NAMES: [&str; 3] = ["intensity", "scalar_intensity", "i"];

/// One vertex as the parser fills it: coordinates and the intensity found
/// under the most preferred name (`rank` indexes [`INTENSITY_NAMES`]).
#[derive(Debug, Clone, Copy)]
struct Vertex {
    xyz: [f64; 3],
    intensity: f32,
    rank: usize,
}

impl PropertyAccess for Vertex {
    fn new() -> Self {
        Vertex { xyz: [f64::NAN; 3], intensity: 0.0, rank: usize::MAX }
    }

    fn set_property(&mut self, name: &str, property: Property) -> PropertyAccessResult {
        let v = match property {
            Property::Char(v) => f64::from(v),
            Property::UChar(v) => f64::from(v),
            Property::Short(v) => f64::from(v),
            Property::UShort(v) => f64::from(v),
            Property::Int(v) => f64::from(v),
            Property::UInt(v) => f64::from(v),
            Property::Float(v) => f64::from(v),
            Property::Double(v) => v,
            _ => return PropertyAccessResult::Ignored,
        };
        match name {
            "x" => self.xyz[0] = v,
            "y" => self.xyz[1] = v,
            "z" => self.xyz[2] = v,
            _ => match INTENSITY_NAMES.iter().position(|n| *n == name) {
                Some(rank) if rank < self.rank => {
                    self.intensity = v as f32;
                    self.rank = rank;
                }
                _ => return PropertyAccessResult::Ignored,
            },
        }
        PropertyAccessResult::Set
    }
}

/// An element seam does not use (faces, edges, ...): read and dropped.
struct Skip;

impl PropertyAccess for Skip {
    fn new() -> Self {
        Skip
    }
}

/// Reads a PLY scan, points as stored.
pub fn read_ply(path: &Path) -> Result<Scan, ReadError> {
    parse_ply(path, &read_bytes(path)?)
}

fn bad_header(path: &Path, line: Option<usize>, message: String) -> ReadError {
    let e = ReadError::new(ReadErrorKind::BadHeader, path, message)
        .hint("the PLY header is malformed or lacks a vertex element with x, y, z; re-export the cloud");
    match line {
        Some(n) => e.at(Location::Line(n)),
        None => e,
    }
}

/// Maps a payload error: an early end is `Truncated` (at the file's end for
/// binary, at the line for ascii), anything else `Parse`.
fn payload_error(path: &Path, bytes: &[u8], header: &Header, e: &ParseError) -> ReadError {
    let location = match (header.encoding, e.line()) {
        (Encoding::Ascii, Some(n)) => Location::Line(n),
        _ => Location::Byte(bytes.len() as u64),
    };
    if e.kind() == ErrorKind::UnexpectedEof {
        ReadError::new(ReadErrorKind::Truncated, path, format!("data ends before the header's element counts: {e}"))
            .at(location)
            .hint("the file was cut short (interrupted copy or write?), or `element vertex N` overstates N")
    } else {
        ReadError::new(ReadErrorKind::Parse, path, format!("cannot decode PLY data: {e}"))
            .at(location)
            .hint("the data does not match the header's properties; re-export the cloud")
    }
}

/// Decodes the bytes of a PLY file; `path` only names the file in errors.
pub(crate) fn parse_ply(path: &Path, bytes: &[u8]) -> Result<Scan, ReadError> {
    let mut reader = Reader::new(bytes);
    let header = Parser::<Skip>::new()
        .read_header(&mut reader)
        .map_err(|e| bad_header(path, e.line(), format!("cannot parse PLY header: {e}")))?;
    let Some(vdef) = header.elements.get("vertex") else {
        let found: Vec<&str> = header.elements.keys().map(String::as_str).collect();
        return Err(bad_header(path, None, format!("no `element vertex` (elements: {})", found.join(", "))));
    };
    let scalar = |n: &str| vdef.properties.get(n).is_some_and(|p| matches!(p.data_type, PropertyType::Scalar(_)));
    if let Some(axis) = ["x", "y", "z"].into_iter().find(|a| !scalar(a)) {
        let props: Vec<&str> = vdef.properties.keys().map(String::as_str).collect();
        let msg = format!("vertex has no scalar property `{axis}` (properties: {})", props.join(", "));
        return Err(bad_header(path, None, msg));
    }
    let has_intensity = INTENSITY_NAMES.iter().any(|n| scalar(n));

    for (name, def) in &header.elements {
        if name != "vertex" {
            Parser::<Skip>::new()
                .read_payload_for_element(&mut reader, def, &header)
                .map_err(|e| payload_error(path, bytes, &header, &e))?;
            continue;
        }
        let vertices = Parser::<Vertex>::new()
            .read_payload_for_element(&mut reader, def, &header)
            .map_err(|e| payload_error(path, bytes, &header, &e))?;
        let points = vertices.iter().map(|v| v.xyz.map(|c| c as f32)).collect();
        let intensity = if has_intensity { vertices.iter().map(|v| v.intensity).collect() } else { Vec::new() };
        return Ok(Scan { points, intensity });
    }
    // Unreachable: the vertex element exists; kept so that no input can panic.
    Err(bad_header(path, None, "no `element vertex`".into()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const PTS: [[f64; 4]; 3] = [[1.0, 2.0, 3.0, 10.0], [-1.5, 0.25, 8.0, 20.0], [1e5, -2e5, 0.5, 30.0]];

    fn ply(format: &str, coord: &str, inten: &str, n_claimed: usize) -> Vec<u8> {
        let mut out = format!(
            "ply\nformat {format} 1.0\ncomment seam test\nelement face 1\nproperty list uchar int vertex_indices\n\
             element vertex {n_claimed}\nproperty {coord} x\nproperty {coord} y\nproperty {coord} z\n\
             property uchar ring\nproperty float {inten}\nend_header\n"
        )
        .into_bytes();
        let be = format.contains("big");
        let put = |out: &mut Vec<u8>, b4: [u8; 4], b4be: [u8; 4]| out.extend(if be { b4be } else { b4 });
        if format == "ascii" {
            out.extend(b"3 0 1 2\n");
            for p in PTS {
                out.extend(format!("{} {} {} 7 {}\n", p[0], p[1], p[2], p[3]).bytes());
            }
            return out;
        }
        out.push(3);
        for i in 0..3i32 {
            put(&mut out, i.to_le_bytes(), i.to_be_bytes());
        }
        for p in PTS {
            for c in &p[..3] {
                match coord {
                    "double" => out.extend(if be { c.to_be_bytes() } else { c.to_le_bytes() }),
                    _ => put(&mut out, (*c as f32).to_le_bytes(), (*c as f32).to_be_bytes()),
                }
            }
            out.push(7);
            put(&mut out, (p[3] as f32).to_le_bytes(), (p[3] as f32).to_be_bytes());
        }
        out
    }

    fn want(with_intensity: bool) -> Scan {
        Scan {
            points: PTS.iter().map(|p| [p[0] as f32, p[1] as f32, p[2] as f32]).collect(),
            intensity: if with_intensity { PTS.iter().map(|p| p[3] as f32).collect() } else { vec![] },
        }
    }

    #[test]
    fn all_encodings_float_and_double_read_the_same() {
        let dir = tempfile::tempdir().unwrap();
        for format in ["ascii", "binary_little_endian", "binary_big_endian"] {
            for coord in ["float", "double"] {
                let p = dir.path().join(format!("{format}_{coord}.ply"));
                std::fs::write(&p, ply(format, coord, "scalar_intensity", 3)).unwrap();
                let got = read_ply(&p).unwrap_or_else(|e| panic!("{format} {coord}: {e}"));
                assert_eq!(got, want(true), "{format} {coord}");
            }
        }
    }

    #[test]
    fn other_property_names_mean_no_intensity() {
        let got = parse_ply(Path::new("a.ply"), &ply("ascii", "float", "reflectivity", 3)).unwrap();
        assert_eq!(got, want(false));
    }

    #[test]
    fn missing_coordinate_is_bad_header() {
        let b =
            String::from_utf8(ply("ascii", "float", "i", 3)).unwrap().replace("property float z", "property float w");
        let e = parse_ply(Path::new("noz.ply"), b.as_bytes()).unwrap_err();
        assert_eq!(e.kind(), ReadErrorKind::BadHeader, "{e}");
        assert!(e.to_string().starts_with("noz.ply: vertex has no scalar property `z`"), "{e}");
        let e = parse_ply(Path::new("junk.ply"), b"ply\nformat ascii 1.0\nelement vertex x\nend_header\n").unwrap_err();
        assert_eq!((e.kind(), e.location), (ReadErrorKind::BadHeader, Some(Location::Line(3))), "{e}");
    }

    #[test]
    fn overstated_vertex_count_is_truncated() {
        let ascii = ply("ascii", "float", "intensity", 5);
        let e = parse_ply(Path::new("a.ply"), &ascii).unwrap_err();
        assert_eq!(e.kind(), ReadErrorKind::Truncated, "{e}");
        assert!(matches!(e.location, Some(Location::Line(_))), "{e}");
        let bin = ply("binary_little_endian", "float", "intensity", 5);
        let e = parse_ply(Path::new("b.ply"), &bin).unwrap_err();
        assert_eq!((e.kind(), e.location), (ReadErrorKind::Truncated, Some(Location::Byte(bin.len() as u64))), "{e}");
        assert!(e.to_string().starts_with(&format!("b.ply:byte {}: ", bin.len())), "{e}");
    }

    proptest! {
        #[test]
        fn random_bytes_and_truncations_never_panic(
            tail in proptest::collection::vec(any::<u8>(), 0..200),
            frac in 0.0f64..1.0,
            be in any::<bool>(),
        ) {
            let _ = parse_ply(Path::new("r.ply"), &tail);
            let full = ply(if be { "binary_big_endian" } else { "binary_little_endian" }, "double", "intensity", 3);
            let cut = &full[..(frac * full.len() as f64) as usize];
            prop_assert!(parse_ply(Path::new("t.ply"), cut).is_err());
            let mut head = full[..full.len().min(300)].to_vec();
            head.extend(&tail);
            let _ = parse_ply(Path::new("h.ply"), &head);
        }
    }
}
