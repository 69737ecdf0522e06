//! Pose files: KITTI (12 numbers per line, the 3×4 `[R|t]` row-major) and TUM
//! (`t x y z qx qy qz qw`).
//!
//! Each pose is checked where it is read: every number finite (`NonFinite`),
//! the rotation a rotation (`NotRotation`, with the error value, against
//! [`MAX_ORTHONORMALITY_ERROR`]), and the column count right (`Parse`). Errors
//! carry the 1-based line number. Blank lines and lines starting with `#` are
//! skipped, so line numbers and pose indices can differ.

use std::path::Path;

use crate::geometry::{MAX_ORTHONORMALITY_ERROR, Pose, pose_from_kitti_row, pose_from_tum};

use super::error::{Location, ReadError, ReadErrorKind, read_text};

/// The numbers on one data line of a text file, with its 1-based line number.
pub(crate) struct NumberLine {
    pub line: usize,
    pub values: Vec<f64>,
}

/// Splits a text file into lines of whitespace-separated numbers.
///
/// Skips blank lines and `#` comments. A token that is not a number is a
/// `Parse` error naming the token; NaN and infinities parse (callers decide).
pub(crate) fn number_lines(path: &Path, text: &str) -> Result<Vec<NumberLine>, ReadError> {
    let mut out = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let line = raw.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let values = parse_numbers(path, i + 1, line.split_whitespace())?;
        out.push(NumberLine { line: i + 1, values });
    }
    Ok(out)
}

/// Parses every token as `f64`, or reports the first that is not a number.
pub(crate) fn parse_numbers<'a>(
    path: &Path,
    line: usize,
    tokens: impl Iterator<Item = &'a str>,
) -> Result<Vec<f64>, ReadError> {
    tokens
        .map(|tok| {
            tok.parse::<f64>().map_err(|_| {
                ReadError::new(ReadErrorKind::Parse, path, format!("`{tok}` is not a number"))
                    .at(Location::Line(line))
                    .hint("pose and time files hold whitespace-separated decimal numbers only")
            })
        })
        .collect()
}

/// Checks that every value on a line is finite.
pub(crate) fn check_finite(path: &Path, nl: &NumberLine, what: &str) -> Result<(), ReadError> {
    if let Some((col, v)) = nl.values.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        return Err(ReadError::new(
            ReadErrorKind::NonFinite,
            path,
            format!("{what} has a non-finite value {v} in column {}", col + 1),
        )
        .at(Location::Line(nl.line))
        .hint("the odometry diverged or the file was written with NaNs; fix or drop this entry and its scan"));
    }
    Ok(())
}

/// Builds a pose from a line's 12 numbers, with finiteness and rotation checks.
pub(crate) fn kitti_pose_from_line(path: &Path, nl: &NumberLine, what: &str) -> Result<Pose, ReadError> {
    let row: [f64; 12] = nl.values.as_slice().try_into().map_err(|_| {
        ReadError::new(
            ReadErrorKind::Parse,
            path,
            format!("{what} has {} numbers, expected 12 (a 3×4 [R|t] matrix, row-major)", nl.values.len()),
        )
        .at(Location::Line(nl.line))
        .hint("KITTI poses are 12 numbers per line; TUM poses (t x y z qx qy qz qw) are 8 and go in poses_tum.txt")
    })?;
    check_finite(path, nl, what)?;
    pose_from_kitti_row(&row).map_err(|err| not_rotation(path, nl.line, what, err))
}

fn not_rotation(path: &Path, line: usize, what: &str, err: f64) -> ReadError {
    ReadError::new(
        ReadErrorKind::NotRotation,
        path,
        format!(
            "{what} is not a rotation: orthonormality error ‖RᵀR − I‖ + |det R − 1| = {err:.3e} \
             (at most {MAX_ORTHONORMALITY_ERROR:.0e} accepted)"
        ),
    )
    .at(Location::Line(line))
    .hint("the 3×3 block must be a rotation: check for a scale, a swapped column, or a transposed matrix")
}

/// Number of columns on the first data line (12: KITTI, 8: TUM), or 0 for an empty file.
pub(crate) fn pose_file_columns(path: &Path) -> Result<usize, ReadError> {
    let text = read_text(path)?;
    let first = text.lines().map(str::trim).find(|l| !l.is_empty() && !l.starts_with('#'));
    Ok(first.map_or(0, |l| l.split_whitespace().count()))
}

/// Reads a KITTI pose file: one 3×4 row-major `[R|t]` per line.
pub fn read_kitti_poses(path: &Path) -> Result<Vec<Pose>, ReadError> {
    let text = read_text(path)?;
    number_lines(path, &text)?
        .iter()
        .enumerate()
        .map(|(i, nl)| kitti_pose_from_line(path, nl, &format!("pose {i}")))
        .collect()
}

/// Reads a TUM pose file: `timestamp_s x y z qx qy qz qw` per line.
///
/// The quaternion's norm must be within [`MAX_ORTHONORMALITY_ERROR`] of 1.
pub fn read_tum_poses(path: &Path) -> Result<Vec<(f64, Pose)>, ReadError> {
    let text = read_text(path)?;
    let mut out = Vec::new();
    for (i, nl) in number_lines(path, &text)?.iter().enumerate() {
        let what = format!("pose {i}");
        let &[t, x, y, z, qx, qy, qz, qw] = nl.values.as_slice() else {
            return Err(ReadError::new(
                ReadErrorKind::Parse,
                path,
                format!("{what} has {} numbers, expected 8 (TUM: t x y z qx qy qz qw)", nl.values.len()),
            )
            .at(Location::Line(nl.line))
            .hint("TUM poses are 8 numbers per line; KITTI poses (12 numbers) go in poses.txt"));
        };
        check_finite(path, nl, &what)?;
        let pose = pose_from_tum([x, y, z], [qx, qy, qz, qw]).map_err(|norm| {
            ReadError::new(
                ReadErrorKind::NotRotation,
                path,
                format!("{what}'s quaternion has norm {norm:.6}, not 1 (within {MAX_ORTHONORMALITY_ERROR:.0e})"),
            )
            .at(Location::Line(nl.line))
            .hint("TUM order is t x y z qx qy qz qw (w last); check the column order and normalisation")
        })?;
        out.push((t, pose));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::fs;

    fn write(dir: &tempfile::TempDir, name: &str, text: &str) -> std::path::PathBuf {
        let p = dir.path().join(name);
        fs::write(&p, text).unwrap();
        p
    }

    const IDENTITY: &str = "1 0 0 0 0 1 0 0 0 0 1 0\n";

    #[test]
    fn kitti_poses_read_translation_and_skip_blank_lines() {
        let dir = tempfile::tempdir().unwrap();
        let p = write(&dir, "poses.txt", &format!("{IDENTITY}\n1 0 0 1.5 0 1 0 -2 0 0 1 3\n"));
        let poses = read_kitti_poses(&p).unwrap();
        assert_eq!(poses.len(), 2);
        assert_eq!(poses[1].translation.vector.as_slice(), &[1.5, -2.0, 3.0]);
    }

    #[test]
    fn kitti_nan_is_non_finite_with_line() {
        let dir = tempfile::tempdir().unwrap();
        let p = write(&dir, "poses.txt", &format!("{IDENTITY}{IDENTITY}1 0 0 nan 0 1 0 0 0 0 1 0\n"));
        let e = read_kitti_poses(&p).unwrap_err();
        assert_eq!(e.kind(), ReadErrorKind::NonFinite);
        assert_eq!(e.location, Some(Location::Line(3)));
        assert!(e.to_string().contains("poses.txt:line 3:"), "{e}");
    }

    #[test]
    fn kitti_scaled_rotation_is_not_rotation_with_error_value() {
        let dir = tempfile::tempdir().unwrap();
        let p = write(&dir, "poses.txt", &format!("{IDENTITY}2 0 0 0 0 1 0 0 0 0 1 0\n"));
        let e = read_kitti_poses(&p).unwrap_err();
        assert_eq!(e.kind(), ReadErrorKind::NotRotation);
        assert!(e.to_string().contains("poses.txt:line 2:"), "{e}");
        // ‖diag(4,1,1) − I‖ + |2 − 1| = 3 + 1
        assert!(e.message.contains("4.000e0"), "{e}");
    }

    #[test]
    fn kitti_wrong_column_count_and_garbage_are_parse_errors() {
        let dir = tempfile::tempdir().unwrap();
        let p = write(&dir, "poses.txt", "1 0 0 0 0 1 0 0 0 0 1\n");
        let e = read_kitti_poses(&p).unwrap_err();
        assert_eq!(e.kind(), ReadErrorKind::Parse);
        assert!(e.to_string().contains("poses.txt:line 1:") && e.message.contains("11 numbers"), "{e}");
        let p = write(&dir, "poses2.txt", &format!("{IDENTITY}1 0 0 x 0 1 0 0 0 0 1 0\n"));
        let e = read_kitti_poses(&p).unwrap_err();
        assert_eq!(e.kind(), ReadErrorKind::Parse);
        assert!(e.to_string().contains("poses2.txt:line 2:") && e.message.contains("`x`"), "{e}");
    }

    #[test]
    fn tum_poses_read_and_validate() {
        let dir = tempfile::tempdir().unwrap();
        let p = write(
            &dir,
            "poses_tum.txt",
            "# t x y z qx qy qz qw\n0.5 1 2 3 0 0 0 1\n0.6 1 2 3 0 0 0.7071068 0.7071068\n",
        );
        let poses = read_tum_poses(&p).unwrap();
        assert_eq!(poses.len(), 2);
        assert_eq!(poses[0].0, 0.5);
        let rz = poses[1].1.rotation.euler_angles().2;
        assert!((rz - std::f64::consts::FRAC_PI_2).abs() < 1e-6, "{rz}");

        let p = write(&dir, "bad.txt", "0.5 1 2 3 0 0 0 1\n0.6 1 2 3 0 0 0 2\n");
        let e = read_tum_poses(&p).unwrap_err();
        assert_eq!(e.kind(), ReadErrorKind::NotRotation);
        assert!(e.to_string().contains("bad.txt:line 2:"), "{e}");

        let p = write(&dir, "inf.txt", "0.5 1 2 inf 0 0 0 1\n");
        let e = read_tum_poses(&p).unwrap_err();
        assert_eq!(e.kind(), ReadErrorKind::NonFinite);
        assert!(e.to_string().contains("inf.txt:line 1:"), "{e}");
    }

    #[test]
    fn column_count_detects_format() {
        let dir = tempfile::tempdir().unwrap();
        assert_eq!(pose_file_columns(&write(&dir, "a.txt", IDENTITY)).unwrap(), 12);
        assert_eq!(pose_file_columns(&write(&dir, "b.txt", "\n# c\n0 1 2 3 0 0 0 1\n")).unwrap(), 8);
        assert_eq!(pose_file_columns(&write(&dir, "c.txt", "")).unwrap(), 0);
    }
}
