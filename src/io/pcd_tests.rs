//! Tests of the PCD reader: a small writer for all three encodings with
//! mixed field sizes, every header lie, truncation, and never-panic properties.

use super::*;
use proptest::prelude::*;
use std::fs;
use std::path::PathBuf;

/// One field: name, SIZE, TYPE, COUNT.
type Spec = (&'static str, usize, char, usize);

/// FIELDS x y z intensity ring time n, SIZE 4 4 8 2 1 8 4, COUNT 1 1 1 1 1 1 3.
const SPEC: [Spec; 7] = [
    ("x", 4, 'F', 1),
    ("y", 4, 'F', 1),
    ("z", 8, 'F', 1),
    ("intensity", 2, 'U', 1),
    ("ring", 1, 'U', 1),
    ("time", 8, 'F', 1),
    ("n", 4, 'F', 3),
];

/// The values of point i, field by field (each a `COUNT`-long list).
fn values(i: usize) -> Vec<Vec<f64>> {
    let f = i as f64;
    vec![
        vec![f * 0.5],
        vec![-f * 0.25],
        vec![1.0 + f * 0.125],
        vec![((i * 7919) % 65536) as f64],
        vec![(i % 64) as f64],
        vec![f * 1e-3],
        vec![0.0, 1.0, f],
    ]
}

fn encode(v: f64, size: usize, kind: char) -> Vec<u8> {
    match (kind, size) {
        ('F', 4) => (v as f32).to_le_bytes().to_vec(),
        ('F', 8) => v.to_le_bytes().to_vec(),
        ('U', 1) => vec![v as u8],
        ('U', 2) => (v as u16).to_le_bytes().to_vec(),
        _ => unreachable!("not in SPEC"),
    }
}

fn header(data: &str, n: usize, viewpoint: &str) -> String {
    let col = |f: &dyn Fn(&Spec) -> String| SPEC.iter().map(f).collect::<Vec<_>>().join(" ");
    format!(
        "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS {}\nSIZE {}\nTYPE {}\nCOUNT {}\n\
         WIDTH {n}\nHEIGHT 1\nVIEWPOINT {viewpoint}\nPOINTS {n}\nDATA {data}\n",
        col(&|s| s.0.to_string()),
        col(&|s| s.1.to_string()),
        col(&|s| s.2.to_string()),
        col(&|s| s.3.to_string()),
    )
}

/// A PCD file of `n` points in the given encoding.
fn pcd_bytes(data: &str, n: usize) -> Vec<u8> {
    let mut out = header(data, n, "1 2 3 1 0 0 0").into_bytes();
    match data {
        "ascii" => {
            for i in 0..n {
                let line: Vec<String> = values(i)
                    .iter()
                    .zip(SPEC)
                    .flat_map(|(vs, s)| {
                        vs.iter().map(move |&v| if s.1 == 4 { format!("{}", v as f32) } else { format!("{v}") })
                    })
                    .collect();
                out.extend_from_slice(line.join(" ").as_bytes());
                out.push(b'\n');
            }
        }
        "binary" => {
            for i in 0..n {
                for (vs, s) in values(i).iter().zip(SPEC) {
                    vs.iter().for_each(|&v| out.extend(encode(v, s.1, s.2)));
                }
            }
        }
        "binary_compressed" => {
            let mut cols = Vec::new();
            for (k, s) in SPEC.iter().enumerate() {
                for i in 0..n {
                    values(i)[k].iter().for_each(|&v| cols.extend(encode(v, s.1, s.2)));
                }
            }
            let packed = lzf::compress(&cols).unwrap();
            out.extend((packed.len() as u32).to_le_bytes());
            out.extend((cols.len() as u32).to_le_bytes());
            out.extend(packed);
        }
        _ => unreachable!(),
    }
    out
}

fn expected(n: usize) -> Scan {
    let v: Vec<_> = (0..n).map(values).collect();
    Scan {
        points: v.iter().map(|p| [p[0][0] as f32, p[1][0] as f32, p[2][0] as f32]).collect(),
        intensity: v.iter().map(|p| p[3][0] as f32).collect(),
    }
}

fn write(dir: &tempfile::TempDir, name: &str, bytes: &[u8]) -> PathBuf {
    let p = dir.path().join(name);
    fs::write(&p, bytes).unwrap();
    p
}

/// The valid ascii file with one header line replaced.
fn with_line(line_no: usize, text: &str) -> Vec<u8> {
    let s = String::from_utf8(pcd_bytes("ascii", 3)).unwrap();
    let lines: Vec<&str> = s.lines().enumerate().map(|(i, l)| if i + 1 == line_no { text } else { l }).collect();
    (lines.join("\n") + "\n").into_bytes()
}

#[test]
fn three_encodings_with_extra_fields_read_the_same_points() {
    let dir = tempfile::tempdir().unwrap();
    let want = expected(300);
    for data in ["ascii", "binary", "binary_compressed"] {
        let p = write(&dir, &format!("{data}.pcd"), &pcd_bytes(data, 300));
        let got = read_pcd(&p).unwrap_or_else(|e| panic!("{data}: {e}"));
        assert_eq!(got, want, "{data}");
    }
}

#[test]
fn intensity_named_i_and_missing_intensity() {
    let dir = tempfile::tempdir().unwrap();
    let text = "VERSION .7\nFIELDS x y z i\nSIZE 4 4 4 4\nTYPE F F F F\nWIDTH 1\nPOINTS 1\nDATA ascii\n1 2 3 9\n";
    assert_eq!(read_pcd(&write(&dir, "i.pcd", text.as_bytes())).unwrap().intensity, vec![9.0]);
    let text = "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 2\nHEIGHT 1\nDATA ascii\r\n1 2 3\r\nnan 5 6\r\n";
    let s = read_pcd(&write(&dir, "noi.pcd", text.as_bytes())).unwrap();
    assert!(s.intensity.is_empty());
    assert_eq!(s.points[0], [1.0, 2.0, 3.0]);
    assert!(s.points[1][0].is_nan(), "points are returned as stored");
}

/// Asserts a `BadHeader` at `line` whose display names the file and line.
fn assert_bad_header(bytes: &[u8], line: usize, needle: &str) {
    let dir = tempfile::tempdir().unwrap();
    let p = write(&dir, "liar.pcd", bytes);
    let e = read_pcd(&p).unwrap_err();
    assert_eq!(e.kind(), ReadErrorKind::BadHeader, "{e}");
    assert_eq!(e.location, Some(Location::Line(line)), "{e}");
    let s = e.to_string();
    assert!(s.contains(&format!("liar.pcd:line {line}: ")) && s.contains(needle), "{s}");
}

#[test]
fn lying_headers_are_bad_header_with_line() {
    assert_bad_header(&with_line(10, "POINTS 4"), 10, "POINTS 4 is not WIDTH × HEIGHT = 3 × 1");
    assert_bad_header(&with_line(4, "SIZE 4 4 8 2 1 8"), 4, "SIZE has 6 entries but FIELDS (line 3) names 7");
    assert_bad_header(&with_line(5, "TYPE F F F U U F F F"), 5, "TYPE has 8 entries");
    assert_bad_header(&with_line(6, "COUNT 1 1 1 1 1 1"), 6, "COUNT has 6 entries");
    assert_bad_header(&with_line(6, "COUNT 1 1 1 1 1 1 0"), 6, "COUNT 0");
    assert_bad_header(&with_line(11, "DATA binary_lz4"), 11, "DATA `binary_lz4` is not one of");
    assert_bad_header(&with_line(5, "TYPE F F F U U F X"), 5, "TYPE X");
    assert_bad_header(&with_line(4, "SIZE 4 4 8 2 1 8 2"), 4, "TYPE F with SIZE 2");
    assert_bad_header(&with_line(3, "FIELDS x y zz intensity ring time n"), 3, "FIELDS has no `z`");
    assert_bad_header(&with_line(7, "WIDTH three"), 7, "WIDTH value `three`");
    assert_bad_header(&with_line(8, "WIDTH 3"), 8, "WIDTH appears twice");
    assert_bad_header(&with_line(9, "VIEWPOINT 0 0 0 1"), 9, "VIEWPOINT needs 7 numbers");
    assert_bad_header(b"FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 1\n", 4, "no DATA line");
    assert_bad_header(b"ply\nformat ascii 1.0\n", 1, "unknown header key `ply`");
}

#[test]
fn extra_ascii_lines_mean_points_lies() {
    let mut b = pcd_bytes("ascii", 3);
    b.extend_from_slice(b"1 2 3 4 5 6 7 8 9\n");
    assert_bad_header(&b, 15, "more data lines than POINTS 3");
}

#[test]
fn ascii_data_errors_have_file_line_numbers() {
    let dir = tempfile::tempdir().unwrap();
    let mut b = pcd_bytes("ascii", 2);
    b.extend_from_slice(b"1 2\n");
    let s = String::from_utf8(b).unwrap().replace("WIDTH 2", "WIDTH 3").replace("POINTS 2", "POINTS 3");
    let e = read_pcd(&write(&dir, "short_line.pcd", s.as_bytes())).unwrap_err();
    assert_eq!((e.kind(), e.location), (ReadErrorKind::Parse, Some(Location::Line(14))), "{e}");
    assert!(e.to_string().contains("short_line.pcd:line 14: 2 values on a data line, expected 9"), "{e}");
    let s = String::from_utf8(pcd_bytes("ascii", 2)).unwrap().replacen("\n0 -0 1 ", "\nzero -0 1 ", 1);
    let e = read_pcd(&write(&dir, "word.pcd", s.as_bytes())).unwrap_err();
    assert_eq!((e.kind(), e.location), (ReadErrorKind::Parse, Some(Location::Line(12))), "{e}");
}

#[test]
fn truncated_data_is_truncated_at_the_file_end() {
    let dir = tempfile::tempdir().unwrap();
    for data in ["ascii", "binary", "binary_compressed"] {
        let full = pcd_bytes(data, 50);
        // Ascii: drop the last 10 lines; binary: drop 20 bytes.
        let cut = if data == "ascii" {
            let s = String::from_utf8(full.clone()).unwrap();
            let keep: Vec<&str> = s.lines().collect();
            (keep[..keep.len() - 10].join("\n") + "\n").into_bytes()
        } else {
            full[..full.len() - 20].to_vec()
        };
        let p = write(&dir, &format!("cut_{data}.pcd"), &cut);
        let e = read_pcd(&p).unwrap_err();
        assert_eq!(e.kind(), ReadErrorKind::Truncated, "{data}: {e}");
        assert_eq!(e.location, Some(Location::Byte(cut.len() as u64)), "{data}: {e}");
        assert!(e.to_string().contains(&format!("cut_{data}.pcd:byte {}: ", cut.len())), "{e}");
    }
    let e = parse_pcd(Path::new("b.pcd"), &pcd_bytes("binary", 50)[..600]).unwrap_err();
    assert!(e.message.contains("header says 50 points × 39 bytes = 1950 bytes"), "{e}");
}

#[test]
fn compressed_size_lie_is_bad_header_at_byte() {
    let mut b = pcd_bytes("binary_compressed", 10);
    let start = header("binary_compressed", 10, "1 2 3 1 0 0 0").len();
    b[start + 4..start + 8].copy_from_slice(&999u32.to_le_bytes());
    let e = parse_pcd(Path::new("c.pcd"), &b).unwrap_err();
    assert_eq!((e.kind(), e.location), (ReadErrorKind::BadHeader, Some(Location::Byte(start as u64 + 4))), "{e}");
    // A claim of 3.9 GB from a 3-byte block is rejected before allocating it.
    let h = header("binary_compressed", 100_000_000, "0 0 0 1 0 0 0");
    let mut b = h.clone().into_bytes();
    b.extend(3u32.to_le_bytes());
    b.extend(3_900_000_000u32.to_le_bytes());
    b.extend([0, 0, 0]);
    let e = parse_pcd(Path::new("c.pcd"), &b).unwrap_err();
    assert_eq!(e.kind(), ReadErrorKind::Parse, "{e}");
    assert!(e.message.contains("3 bytes cannot unpack to 3900000000"), "{e}");
}

#[test]
fn viewpoint_reads_pose_and_validates_quaternion() {
    let dir = tempfile::tempdir().unwrap();
    let p = write(&dir, "v.pcd", &pcd_bytes("binary", 2));
    let t = pcd_viewpoint(&p).unwrap();
    assert_eq!(t.translation.vector.as_slice(), &[1.0, 2.0, 3.0]);
    assert!(t.rotation.angle() < 1e-12);

    let s = String::from_utf8(with_line(9, "VIEWPOINT 0 0 0 0.7071068 0 0 0.7071068")).unwrap();
    let yaw = pcd_viewpoint(&write(&dir, "yaw.pcd", s.as_bytes())).unwrap().rotation.euler_angles().2;
    assert!((yaw - std::f64::consts::FRAC_PI_2).abs() < 1e-6, "w comes first in PCD: {yaw}");

    let e = pcd_viewpoint(&write(&dir, "q.pcd", &with_line(9, "VIEWPOINT 0 0 0 2 0 0 0"))).unwrap_err();
    assert_eq!((e.kind(), e.location), (ReadErrorKind::NotRotation, Some(Location::Line(9))), "{e}");
    assert!(e.to_string().contains("q.pcd:line 9:"), "{e}");
    let e = pcd_viewpoint(&write(&dir, "n.pcd", &with_line(9, "VIEWPOINT nan 0 0 1 0 0 0"))).unwrap_err();
    assert_eq!((e.kind(), e.location), (ReadErrorKind::NonFinite, Some(Location::Line(9))), "{e}");

    let none = write(&dir, "none.pcd", b"FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 0\nDATA binary\n");
    assert_eq!(pcd_viewpoint(&none).unwrap(), Pose::identity());
    assert!(read_viewpoint(&none).unwrap().is_none());
    assert!(read_pcd(&none).unwrap().is_empty());
}

proptest! {
    #[test]
    fn random_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..400)) {
        let _ = parse_pcd(Path::new("r.pcd"), &bytes);
    }

    #[test]
    fn random_header_then_bytes_never_panic(
        data in prop::sample::select(vec!["ascii", "binary", "binary_compressed"]),
        n in 0usize..100_000_000,
        tail in proptest::collection::vec(any::<u8>(), 0..300),
    ) {
        let mut b = header(data, n, "0 0 0 1 0 0 0").into_bytes();
        b.extend(tail);
        let _ = parse_pcd(Path::new("r.pcd"), &b);
    }

    #[test]
    fn truncations_never_panic_and_binary_cuts_are_errors(
        data in prop::sample::select(vec!["ascii", "binary", "binary_compressed"]),
        frac in 0.0f64..1.0,
    ) {
        let full = pcd_bytes(data, 40);
        let cut = &full[..(frac * full.len() as f64) as usize];
        let r = parse_pcd(Path::new("t.pcd"), cut);
        if data != "ascii" {
            prop_assert!(r.is_err());
        }
    }

    #[test]
    fn flipped_bytes_never_panic(
        data in prop::sample::select(vec!["ascii", "binary", "binary_compressed"]),
        at in any::<prop::sample::Index>(),
        byte in any::<u8>(),
    ) {
        let mut b = pcd_bytes(data, 20);
        let i = at.index(b.len());
        b[i] = byte;
        let _ = parse_pcd(Path::new("f.pcd"), &b);
    }
}
