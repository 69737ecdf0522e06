//! The one error type of `io`: which file, where in it, what kind of problem,
//! what was expected, and what to do about it.
//!
//! Every reader returns [`ReadError`]. Its `Display` is the message a survey
//! operator sees on stderr, so it always starts with the path (as the caller
//! spelled it) and the location, and ends with a hint line:
//!
//! ```text
//! ../x/velodyne/000003.bin: file has 1000003 bytes, not a multiple of 16 (float32 x,y,z,intensity per point)
//!   hint: is it a KITTI .bin? Re-export the scan or remove it and its line in poses.txt
//! ```

use std::fmt;
use std::path::{Path, PathBuf};

/// What went wrong, for callers that branch on it (exit codes, tests).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ReadErrorKind {
    /// The operating system refused: missing file, permissions, not a directory.
    Io,
    /// A KITTI `.bin` whose size is not a whole number of 16-byte points.
    NotMultipleOf16,
    /// A NaN or infinite coordinate, pose entry or time stamp.
    NonFinite,
    /// Two counts that must agree do not (scans vs poses, labels vs points).
    CountMismatch,
    /// A 3×3 block or quaternion that is not a rotation.
    NotRotation,
    /// A header that contradicts itself or is incomplete (PCD, PLY, LAS).
    BadHeader,
    /// The data ends before the header says it should.
    Truncated,
    /// A scan with no points.
    EmptyScan,
    /// A folder that matches none of the session layouts seam accepts.
    UnknownLayout,
    /// Text or bytes that do not parse as the format says.
    Parse,
    /// A valid file seam cannot use (an extension or encoding it does not read).
    Unsupported,
}

/// Where in a file an error is. Lines are 1-based; bytes and points 0-based.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Location {
    /// 1-based line number of a text file or text header.
    Line(usize),
    /// 0-based byte offset from the start of the file.
    Byte(u64),
    /// 0-based index of a point in the scan.
    Point(usize),
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Location::Line(n) => write!(f, "line {n}"),
            Location::Byte(n) => write!(f, "byte {n}"),
            Location::Point(n) => write!(f, "point {n}"),
        }
    }
}

/// A file that could not be read or did not validate.
#[derive(Debug, thiserror::Error)]
#[error("{}", render(.path, .location, .message, .hint))]
pub struct ReadError {
    pub path: PathBuf,
    pub location: Option<Location>,
    pub kind: ReadErrorKind,
    /// What was found and what was expected.
    pub message: String,
    /// What the user should do next.
    pub hint: String,
}

fn render(path: &Path, location: &Option<Location>, message: &str, hint: &str) -> String {
    let mut s = path.display().to_string();
    if let Some(loc) = location {
        s.push_str(&format!(":{loc}"));
    }
    s.push_str(": ");
    s.push_str(message);
    if !hint.is_empty() {
        s.push_str("\n  hint: ");
        s.push_str(hint);
    }
    s
}

impl ReadError {
    /// A new error without a location or hint; add them with [`Self::at`] and [`Self::hint`].
    pub fn new(kind: ReadErrorKind, path: &Path, message: impl Into<String>) -> Self {
        ReadError { path: path.to_path_buf(), location: None, kind, message: message.into(), hint: String::new() }
    }

    /// Sets where in the file the error is.
    pub fn at(mut self, location: Location) -> Self {
        self.location = Some(location);
        self
    }

    /// Sets what the user should do.
    pub fn hint(mut self, hint: impl Into<String>) -> Self {
        self.hint = hint.into();
        self
    }

    /// An operating-system error on `path`.
    pub fn io(path: &Path, err: &std::io::Error) -> Self {
        let hint = match err.kind() {
            std::io::ErrorKind::NotFound => "check the path; session folders are read, never created",
            std::io::ErrorKind::PermissionDenied => "check the file's permissions",
            _ => "check that the file is readable and complete",
        };
        ReadError::new(ReadErrorKind::Io, path, format!("cannot read: {err}")).hint(hint)
    }

    pub fn kind(&self) -> ReadErrorKind {
        self.kind
    }
}

/// Reads a whole file, mapping the OS error to a [`ReadError`].
pub(crate) fn read_bytes(path: &Path) -> Result<Vec<u8>, ReadError> {
    std::fs::read(path).map_err(|e| ReadError::io(path, &e))
}

/// Reads a whole text file; invalid UTF-8 is a `Parse` error at the byte it starts.
pub(crate) fn read_text(path: &Path) -> Result<String, ReadError> {
    let bytes = read_bytes(path)?;
    String::from_utf8(bytes).map_err(|e| {
        let at = e.utf8_error().valid_up_to() as u64;
        ReadError::new(ReadErrorKind::Parse, path, "not UTF-8 text")
            .at(Location::Byte(at))
            .hint("this should be a plain text file; was a binary file saved under this name?")
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn display_has_path_location_message_and_hint() {
        let e = ReadError::new(
            ReadErrorKind::NotMultipleOf16,
            Path::new("../x/velodyne/000003.bin"),
            "file has 1000003 bytes, not a multiple of 16 (float32 x,y,z,intensity per point)",
        )
        .hint("is it a KITTI .bin? Re-export the scan or remove it and its line in poses.txt");
        assert_eq!(
            e.to_string(),
            "../x/velodyne/000003.bin: file has 1000003 bytes, not a multiple of 16 (float32 \
             x,y,z,intensity per point)\n  hint: is it a KITTI .bin? Re-export the scan or remove it and \
             its line in poses.txt"
        );
        assert_eq!(e.kind(), ReadErrorKind::NotMultipleOf16);
    }

    #[test]
    fn display_each_location() {
        let p = Path::new("a.txt");
        let line = ReadError::new(ReadErrorKind::Parse, p, "m").at(Location::Line(3)).hint("h");
        assert_eq!(line.to_string(), "a.txt:line 3: m\n  hint: h");
        let byte = ReadError::new(ReadErrorKind::Truncated, p, "m").at(Location::Byte(17));
        assert_eq!(byte.to_string(), "a.txt:byte 17: m");
        let point = ReadError::new(ReadErrorKind::NonFinite, p, "m").at(Location::Point(0));
        assert_eq!(point.to_string(), "a.txt:point 0: m");
    }

    #[test]
    fn missing_file_is_io() {
        let e = read_bytes(Path::new("/nonexistent/seam/x.bin")).unwrap_err();
        assert_eq!(e.kind(), ReadErrorKind::Io);
        assert!(e.to_string().starts_with("/nonexistent/seam/x.bin: cannot read"), "{e}");
    }
}
