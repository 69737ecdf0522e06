//! KITTI odometry files: `velodyne/*.bin` scans, SemanticKITTI `.label`
//! files, `calib.txt` (its `Tr:` line) and `times.txt`.
//!
//! A `.bin` is nothing but little-endian float32 `x y z intensity` records,
//! so its size is the only header it has: a size that is not a multiple of 16
//! is the one sign of a cut or foreign file, and is checked before decoding.

use std::path::Path;

use crate::geometry::{Pose, Scan};

use super::error::{Location, ReadError, ReadErrorKind, read_bytes, read_text};
use super::poses::{NumberLine, check_finite, kitti_pose_from_line, parse_numbers};

/// Reads a KITTI `.bin` scan (float32 x, y, z, intensity per point).
pub fn read_bin(path: &Path) -> Result<Scan, ReadError> {
    parse_bin(path, &read_bytes(path)?)
}

/// Decodes the bytes of a `.bin`; `path` only names the file in errors.
pub(crate) fn parse_bin(path: &Path, bytes: &[u8]) -> Result<Scan, ReadError> {
    if !bytes.len().is_multiple_of(16) {
        return Err(ReadError::new(
            ReadErrorKind::NotMultipleOf16,
            path,
            format!("file has {} bytes, not a multiple of 16 (float32 x,y,z,intensity per point)", bytes.len()),
        )
        .hint("is it a KITTI .bin? Re-export the scan or remove it and its line in poses.txt"));
    }
    let n = bytes.len() / 16;
    let mut scan = Scan { points: Vec::with_capacity(n), intensity: Vec::with_capacity(n) };
    for rec in bytes.as_chunks::<16>().0 {
        if let [x, y, z, i] = rec.as_chunks::<4>().0 {
            scan.points.push([x, y, z].map(|b| f32::from_le_bytes(*b)));
            scan.intensity.push(f32::from_le_bytes(*i));
        }
    }
    Ok(scan)
}

/// Reads a SemanticKITTI `.label` file: one little-endian u32 per point,
/// class in the low 16 bits, instance in the high 16.
///
/// A size that is not a multiple of 4 is `Parse`; a size other than
/// `4 × expected_points` is `CountMismatch`.
pub fn read_labels(path: &Path, expected_points: usize) -> Result<Vec<u32>, ReadError> {
    let bytes = read_bytes(path)?;
    if !bytes.len().is_multiple_of(4) {
        return Err(ReadError::new(
            ReadErrorKind::Parse,
            path,
            format!("label file has {} bytes, not a multiple of 4 (one uint32 per point)", bytes.len()),
        )
        .hint("is it a SemanticKITTI .label file? Re-export it, or point at the right folder"));
    }
    if bytes.len() / 4 != expected_points {
        return Err(ReadError::new(
            ReadErrorKind::CountMismatch,
            path,
            format!(
                "label file has {} bytes ({} labels), but its scan has {expected_points} points \
                 (expected {} bytes)",
                bytes.len(),
                bytes.len() as f64 / 4.0,
                expected_points.saturating_mul(4)
            ),
        )
        .hint("labels must be one uint32 per point of the scan with the same file stem; is it the right sequence?"));
    }
    Ok(bytes.as_chunks::<4>().0.iter().map(|b| u32::from_le_bytes(*b)).collect())
}

/// Reads the `Tr:` line of a KITTI `calib.txt` (velodyne → camera, 3×4), if any.
///
/// Other lines (`P0:` .. `P3:`) are not read beyond their key.
pub fn read_calib_tr(path: &Path) -> Result<Option<Pose>, ReadError> {
    let text = read_text(path)?;
    for (i, raw) in text.lines().enumerate() {
        let Some(rest) = raw.trim_start().strip_prefix("Tr:") else { continue };
        let nl = NumberLine { line: i + 1, values: parse_numbers(path, i + 1, rest.split_whitespace())? };
        return kitti_pose_from_line(path, &nl, "Tr (velodyne to camera)").map(Some);
    }
    Ok(None)
}

/// Reads `times.txt`: one time stamp in seconds per line.
pub fn read_times(path: &Path) -> Result<Vec<f64>, ReadError> {
    let text = read_text(path)?;
    let mut out = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let line = raw.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let nl = NumberLine { line: i + 1, values: parse_numbers(path, i + 1, line.split_whitespace())? };
        let &[t] = nl.values.as_slice() else {
            return Err(ReadError::new(
                ReadErrorKind::Parse,
                path,
                format!("{} numbers on a line, expected one time stamp in seconds", nl.values.len()),
            )
            .at(Location::Line(nl.line))
            .hint("times.txt holds one number (seconds) per scan, one per line"));
        };
        check_finite(path, &nl, &format!("time stamp {}", out.len()))?;
        out.push(t);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::fs;

    fn bin_bytes(points: &[[f32; 4]]) -> Vec<u8> {
        points.iter().flatten().flat_map(|v| v.to_le_bytes()).collect()
    }

    #[test]
    fn bin_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("000000.bin");
        fs::write(&p, bin_bytes(&[[1.0, 2.0, 3.0, 0.5], [-4.0, 5.5, -6.25, 0.0]])).unwrap();
        let s = read_bin(&p).unwrap();
        assert_eq!(s.points, vec![[1.0, 2.0, 3.0], [-4.0, 5.5, -6.25]]);
        assert_eq!(s.intensity, vec![0.5, 0.0]);
    }

    #[test]
    fn bin_not_multiple_of_16() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("000003.bin");
        let mut b = bin_bytes(&[[1.0, 2.0, 3.0, 0.5]]);
        b.extend_from_slice(&[0, 0, 0]);
        fs::write(&p, b).unwrap();
        let e = read_bin(&p).unwrap_err();
        assert_eq!(e.kind(), ReadErrorKind::NotMultipleOf16);
        let s = e.to_string();
        assert!(s.contains("000003.bin: file has 19 bytes, not a multiple of 16"), "{s}");
        assert!(s.contains("hint: is it a KITTI .bin?"), "{s}");
    }

    #[test]
    fn labels_read_and_count_mismatch() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("000000.label");
        let labels: Vec<u32> = vec![252 | (7 << 16), 40, 10];
        fs::write(&p, labels.iter().flat_map(|v| v.to_le_bytes()).collect::<Vec<u8>>()).unwrap();
        assert_eq!(read_labels(&p, 3).unwrap(), labels);
        let e = read_labels(&p, 4).unwrap_err();
        assert_eq!(e.kind(), ReadErrorKind::CountMismatch);
        assert!(e.to_string().contains("000000.label: label file has 12 bytes (3 labels)"), "{e}");
        assert!(e.message.contains("4 points"), "{e}");
    }

    #[test]
    fn calib_tr_present_absent_and_bad() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("calib.txt");
        fs::write(&p, "P0: 1 0 0 0 0 1 0 0 0 0 1 0\nTr: 0 -1 0 0.1 0 0 -1 0.2 1 0 0 0.3\n").unwrap();
        let tr = read_calib_tr(&p).unwrap().unwrap();
        assert_eq!(tr.translation.vector.as_slice(), &[0.1, 0.2, 0.3]);
        fs::write(&p, "P0: 1 0 0 0 0 1 0 0 0 0 1 0\n").unwrap();
        assert!(read_calib_tr(&p).unwrap().is_none());
        fs::write(&p, "P0: 1\nTr: 0 -1 0 0.1 0 0 -1 0.2 1 0 0\n").unwrap();
        let e = read_calib_tr(&p).unwrap_err();
        assert_eq!(e.kind(), ReadErrorKind::Parse);
        assert!(e.to_string().contains("calib.txt:line 2:"), "{e}");
        fs::write(&p, "Tr: 0 -1 0 0.1 0 0 -1 0.2 1 0 1 0.3\n").unwrap();
        assert_eq!(read_calib_tr(&p).unwrap_err().kind(), ReadErrorKind::NotRotation);
    }

    #[test]
    fn times_read_and_validate() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("times.txt");
        fs::write(&p, "0.000000e+00\n1.041284e-01\n\n").unwrap();
        assert_eq!(read_times(&p).unwrap(), vec![0.0, 0.1041284]);
        fs::write(&p, "0.0\nNaN\n").unwrap();
        let e = read_times(&p).unwrap_err();
        assert_eq!(e.kind(), ReadErrorKind::NonFinite);
        assert!(e.to_string().contains("times.txt:line 2:"), "{e}");
        fs::write(&p, "0.0 1.0\n").unwrap();
        let e = read_times(&p).unwrap_err();
        assert_eq!(e.kind(), ReadErrorKind::Parse);
        assert!(e.to_string().contains("times.txt:line 1:"), "{e}");
    }

    proptest! {
        #[test]
        fn bin_never_panics(bytes in proptest::collection::vec(any::<u8>(), 0..200)) {
            let r = parse_bin(Path::new("x.bin"), &bytes);
            prop_assert_eq!(r.is_ok(), bytes.len() % 16 == 0);
            if let Ok(s) = r {
                prop_assert_eq!(s.points.len(), bytes.len() / 16);
            }
        }

        #[test]
        fn bin_truncation_is_detected(n in 1usize..20, cut in 1usize..16) {
            let bytes = bin_bytes(&vec![[1.0, 2.0, 3.0, 4.0]; n]);
            let e = parse_bin(Path::new("x.bin"), &bytes[..bytes.len() - cut]).unwrap_err();
            prop_assert_eq!(e.kind(), ReadErrorKind::NotMultipleOf16);
        }
    }
}
