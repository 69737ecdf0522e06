//! LAS and LAZ scans (LAS 1.0-1.4, point formats 0-10, COPC, extra bytes)
//! through the `las` crate with its `laz` feature.
//!
//! # Precision
//!
//! LAS stores integers with a scale and offset per axis, so coordinates are
//! exact in `f64`. [`read_las`] returns them as stored (nothing subtracted)
//! in a [`Scan`], whose points are `f32`: with a 24-bit mantissa, airborne
//! coordinates in a projected CRS (easting ~6×10⁵ m, northing ~5×10⁶ m) keep
//! only 0.06-0.5 m of resolution. That is fine for counting and for local
//! data; georeferenced work should use [`read_las_points_f64`] and subtract
//! its own origin before going to `f32`.
//!
//! Intensity is the LAS `u16` as `f32`, not normalised.

use std::path::Path;

use las::{PointData, PointDataBuilder, Reader};

use crate::geometry::Scan;

use super::error::{Location, ReadError, ReadErrorKind};

/// Points decoded per batch: bounds memory when a header overstates its count.
const BATCH_POINTS: u64 = 1 << 20;

/// Points in `f64` (as stored, scale and offset applied) and raw intensities.
fn read_columns(path: &Path) -> Result<(Vec<[f64; 3]>, Vec<u16>), ReadError> {
    let file = std::fs::File::open(path).map_err(|e| ReadError::io(path, &e))?;
    let file_len = file.metadata().map_err(|e| ReadError::io(path, &e))?.len();
    read_from(path, std::io::BufReader::new(file), file_len)
}

/// Decodes LAS/LAZ from any seekable source; `path` only names it in errors.
fn read_from<R>(path: &Path, source: R, file_len: u64) -> Result<(Vec<[f64; 3]>, Vec<u16>), ReadError>
where
    R: std::io::Read + std::io::Seek + Send + Sync + 'static,
{
    let mut reader = Reader::new(source).map_err(|e| match e {
        las::Error::Io(io) if io.kind() == std::io::ErrorKind::UnexpectedEof => {
            truncated(path, file_len, "the file ends inside its header or VLRs".into())
        }
        other => ReadError::new(ReadErrorKind::BadHeader, path, format!("not a readable LAS/LAZ header: {other}"))
            .hint("is it a LAS or LAZ file? Check it with `pdal info` or `lasinfo`"),
    })?;
    let declared = reader.header().number_of_points();
    // Bounded by the batch size, not by the header's claim.
    let cap = usize::try_from(declared.min(BATCH_POINTS)).unwrap_or(0);
    let (mut xyz, mut intensity) = (Vec::with_capacity(cap), Vec::with_capacity(cap));
    let mut batch: PointData = PointDataBuilder::new().for_header(reader.header()).build();
    loop {
        let got = reader.fill_points(BATCH_POINTS, &mut batch).map_err(|e| {
            let done = xyz.len();
            match e {
                las::Error::Io(io) if io.kind() == std::io::ErrorKind::UnexpectedEof => truncated(
                    path,
                    file_len,
                    format!("header says {declared} points, but the data ends within the batch after point {done}"),
                ),
                other => ReadError::new(ReadErrorKind::Parse, path, format!("cannot decode points: {other}"))
                    .at(Location::Point(done))
                    .hint("the point data is damaged; copy or export the file again"),
            }
        })?;
        if got == 0 {
            break;
        }
        xyz.extend(batch.x().zip(batch.y()).zip(batch.z()).map(|((x, y), z)| [x, y, z]));
        intensity.extend(batch.intensity());
    }
    if (xyz.len() as u64) != declared {
        return Err(truncated(path, file_len, format!("header says {declared} points, read {}", xyz.len())));
    }
    Ok((xyz, intensity))
}

fn truncated(path: &Path, file_len: u64, message: String) -> ReadError {
    ReadError::new(ReadErrorKind::Truncated, path, message)
        .at(Location::Byte(file_len))
        .hint("the file was cut short (interrupted copy or write?): copy or export it again")
}

/// Reads a LAS/LAZ file as a [`Scan`]: coordinates as stored, cast to `f32`
/// (see the module doc on precision), intensity as `f32`.
pub fn read_las(path: &Path) -> Result<Scan, ReadError> {
    let (xyz, intensity) = read_columns(path)?;
    Ok(Scan {
        points: xyz.iter().map(|p| p.map(|c| c as f32)).collect(),
        intensity: intensity.into_iter().map(f32::from).collect(),
    })
}

/// Reads the coordinates of a LAS/LAZ file in full `f64` precision.
pub fn read_las_points_f64(path: &Path) -> Result<Vec<[f64; 3]>, ReadError> {
    Ok(read_columns(path)?.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use las::{Builder, Point, Writer};
    use proptest::prelude::*;
    use std::io::Cursor;

    /// A small LAS 1.2 file (point format 0) in memory.
    fn las_bytes(points: &[[f64; 3]]) -> Vec<u8> {
        let mut builder = Builder::from((1, 2));
        builder.transforms = las::Vector {
            x: las::Transform { scale: 0.001, offset: 600_000.0 },
            y: las::Transform { scale: 0.001, offset: 5_000_000.0 },
            z: las::Transform { scale: 0.001, offset: 0.0 },
        };
        let header = builder.into_header().unwrap();
        let mut writer = Writer::new(Cursor::new(Vec::new()), header).unwrap();
        for (k, p) in points.iter().enumerate() {
            let point = Point { x: p[0], y: p[1], z: p[2], intensity: k as u16 * 10, ..Default::default() };
            writer.write_point(point).unwrap();
        }
        writer.into_inner().unwrap().into_inner()
    }

    const PTS: [[f64; 3]; 3] =
        [[600_001.5, 5_000_002.25, 10.0], [600_100.0, 5_000_100.125, -3.5], [600_000.0, 5_000_000.0, 0.0]];

    fn read(bytes: Vec<u8>) -> Result<(Vec<[f64; 3]>, Vec<u16>), ReadError> {
        let len = bytes.len() as u64;
        read_from(Path::new("mem.las"), Cursor::new(bytes), len)
    }

    #[test]
    fn round_trip_keeps_f64_coordinates() {
        let (xyz, intensity) = read(las_bytes(&PTS)).unwrap();
        assert_eq!(xyz, PTS.to_vec());
        assert_eq!(intensity, vec![0, 10, 20]);
    }

    #[test]
    fn file_round_trip_and_f32_precision_loss_is_bounded() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.las");
        std::fs::write(&p, las_bytes(&PTS)).unwrap();
        let scan = read_las(&p).unwrap();
        assert_eq!(scan.intensity, vec![0.0, 10.0, 20.0]);
        for (a, b) in scan.points.iter().zip(PTS) {
            // f32 spacing at 5e6 is 0.5 m: this is the documented loss.
            assert!((f64::from(a[1]) - b[1]).abs() <= 0.25, "{a:?} {b:?}");
        }
        assert_eq!(read_las_points_f64(&p).unwrap(), PTS.to_vec());
    }

    #[test]
    fn truncated_las_is_truncated_and_garbage_is_bad_header() {
        let full = las_bytes(&PTS);
        let cut = full[..full.len() - 5].to_vec();
        let len = cut.len() as u64;
        let e = read(cut).unwrap_err();
        assert_eq!((e.kind(), e.location), (ReadErrorKind::Truncated, Some(Location::Byte(len))), "{e}");
        assert!(e.to_string().starts_with(&format!("mem.las:byte {len}: header says 3 points")), "{e}");
        let e = read(b"LASF but not really".to_vec()).unwrap_err();
        assert!(matches!(e.kind(), ReadErrorKind::BadHeader | ReadErrorKind::Truncated), "{e}");
        let e = read(vec![0; 400]).unwrap_err();
        assert_eq!(e.kind(), ReadErrorKind::BadHeader, "{e}");
        assert!(e.to_string().starts_with("mem.las: not a readable LAS/LAZ header"), "{e}");
    }

    proptest! {
        #[test]
        fn flipped_bytes_never_panic(at in any::<prop::sample::Index>(), byte in any::<u8>()) {
            let mut b = las_bytes(&PTS);
            let i = at.index(b.len());
            b[i] = byte;
            let _ = read(b);
        }

        #[test]
        fn truncations_never_panic(frac in 0.0f64..1.0) {
            let full = las_bytes(&PTS);
            let cut = full[..(frac * full.len() as f64) as usize].to_vec();
            prop_assert!(read(cut).is_err());
        }
    }
}
