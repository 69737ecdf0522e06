//! Immutable Parquet files and the commit protocol that publishes them.
//!
//! Write under `<name>.tmp-<pid>`, fsync the file, rename it into place,
//! fsync the folder; only then may the caller commit the SQLite rows that
//! reference it (in the same transaction as the `files` row from
//! [`insert_file`]). Sizes and blake3 hashes are computed while writing, so
//! `seam check` can later prove the file is the one that was committed.

use super::{Store, StoreError, now_utc, sql};
use crate::geometry::Scan;
use arrow_array::{Array, ArrayRef, Float32Array, RecordBatch};
use arrow_schema::{DataType, Field, Schema};
use parquet::arrow::ArrowWriter;
use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
use parquet::basic::{Compression, Encoding, ZstdLevel};
use parquet::file::properties::WriterProperties;
use parquet::schema::types::ColumnPath;
use rusqlite::Transaction;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// `file_id → absolute path` of every file of `kind` the store references.
pub fn file_paths(store: &super::Store, kind: &str) -> Result<std::collections::HashMap<i64, PathBuf>, StoreError> {
    let conn = store.conn();
    let root = store.root();
    let mut st = conn.prepare("SELECT file_id, rel_path FROM files WHERE kind = ?1").map_err(|e| sql(root, e))?;
    let rows = st.query_map([kind], |r| Ok((r.get::<_, i64>(0)?, r.get::<_, String>(1)?))).map_err(|e| sql(root, e))?;
    let mut out = std::collections::HashMap::new();
    for row in rows {
        let (id, rel) = row.map_err(|e| sql(root, e))?;
        out.insert(id, store.path_of(&rel));
    }
    Ok(out)
}

/// A published file, ready to be recorded in `files`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FileRecord {
    /// Path relative to the store root, with `/` separators.
    pub rel_path: String,
    pub kind: String,
    pub size_bytes: u64,
    pub blake3: String,
    pub row_count: u64,
}

/// Inserts the `files` row of a published file and returns its `file_id`.
pub fn insert_file(
    tx: &Transaction<'_>,
    root: &Path,
    rec: &FileRecord,
    session_id: Option<i64>,
) -> Result<i64, StoreError> {
    // A re-run after a crash may publish the same file again under the same
    // name; the row is then replaced by the identical record.
    tx.execute("DELETE FROM files WHERE rel_path = ?1", [&rec.rel_path]).map_err(|e| sql(root, e))?;
    tx.execute(
        "INSERT INTO files(rel_path, kind, session_id, size_bytes, blake3, row_count, created_at)
         VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7)",
        rusqlite::params![
            rec.rel_path,
            rec.kind,
            session_id,
            rec.size_bytes as i64,
            rec.blake3,
            rec.row_count as i64,
            now_utc()
        ],
    )
    .map_err(|e| sql(root, e))?;
    Ok(tx.last_insert_rowid())
}

/// Counts and hashes every byte on its way to the file.
pub(super) struct HashingWriter {
    pub(super) inner: BufWriter<File>,
    pub(super) hasher: blake3::Hasher,
    pub(super) bytes: u64,
}

impl Write for HashingWriter {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let n = self.inner.write(buf)?;
        self.hasher.update(&buf[..n]);
        self.bytes += n as u64;
        Ok(n)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        self.inner.flush()
    }
}

fn scan_schema() -> Arc<Schema> {
    Arc::new(Schema::new(vec![
        Field::new("x_m", DataType::Float32, false),
        Field::new("y_m", DataType::Float32, false),
        Field::new("z_m", DataType::Float32, false),
        Field::new("intensity", DataType::Float32, true),
    ]))
}

/// Writes the scans of one session into one Parquet file, one row group per
/// scan, so that a scan is read back by its row-group index alone.
pub struct ScanWriter {
    tmp_path: PathBuf,
    final_path: PathBuf,
    rel_path: String,
    writer: ArrowWriter<HashingWriter>,
    row_groups: usize,
    rows: u64,
}

impl ScanWriter {
    /// Starts a new scans file at `rel_path` (relative to the store root).
    pub fn create(store: &Store, rel_path: &str) -> Result<ScanWriter, StoreError> {
        let final_path = store.path_of(rel_path);
        if let Some(dir) = final_path.parent() {
            std::fs::create_dir_all(dir).map_err(|e| StoreError::io(dir, e))?;
        }
        let tmp_path = final_path.with_extension(format!("tmp-{}", std::process::id()));
        let file = File::create(&tmp_path).map_err(|e| StoreError::io(&tmp_path, e))?;
        let mut props = WriterProperties::builder()
            .set_compression(Compression::ZSTD(ZstdLevel::try_new(3).unwrap_or_default()))
            // One flush per scan makes one row group; never split a scan.
            .set_max_row_group_row_count(Some(1 << 26));
        // Float coordinates compress ~2x better split into byte streams first.
        for c in ["x_m", "y_m", "z_m", "intensity"] {
            let col = ColumnPath::from(c);
            props = props
                .set_column_dictionary_enabled(col.clone(), false)
                .set_column_encoding(col, Encoding::BYTE_STREAM_SPLIT);
        }
        let sink =
            HashingWriter { inner: BufWriter::with_capacity(1 << 20, file), hasher: blake3::Hasher::new(), bytes: 0 };
        let writer = ArrowWriter::try_new(sink, scan_schema(), Some(props.build()))
            .map_err(|e| StoreError::Parquet { path: tmp_path.clone(), message: e.to_string() })?;
        Ok(ScanWriter { tmp_path, final_path, rel_path: rel_path.to_string(), writer, row_groups: 0, rows: 0 })
    }

    /// Appends one scan as its own row group and returns the row-group index.
    pub fn write_scan(&mut self, scan: &Scan) -> Result<usize, StoreError> {
        let col =
            |f: fn(&[f32; 3]) -> f32| Arc::new(Float32Array::from_iter_values(scan.points.iter().map(f))) as ArrayRef;
        let intensity: ArrayRef = if scan.intensity.len() == scan.points.len() {
            Arc::new(Float32Array::from(scan.intensity.clone()))
        } else {
            Arc::new(Float32Array::from(vec![None::<f32>; scan.points.len()]))
        };
        let batch = RecordBatch::try_new(scan_schema(), vec![col(|p| p[0]), col(|p| p[1]), col(|p| p[2]), intensity])
            .map_err(|e| self.err(e))?;
        self.writer.write(&batch).map_err(|e| self.err(e))?;
        self.writer.flush().map_err(|e| self.err(e))?;
        self.rows += scan.points.len() as u64;
        self.row_groups += 1;
        Ok(self.row_groups - 1)
    }

    fn err(&self, e: impl std::fmt::Display) -> StoreError {
        StoreError::Parquet { path: self.tmp_path.clone(), message: e.to_string() }
    }

    /// Closes the file and publishes it: fsync, rename, fsync the folder.
    pub fn finish(self) -> Result<FileRecord, StoreError> {
        let ScanWriter { tmp_path, final_path, rel_path, writer, rows, .. } = self;
        let mut sink =
            writer.into_inner().map_err(|e| StoreError::Parquet { path: tmp_path.clone(), message: e.to_string() })?;
        sink.flush().map_err(|e| StoreError::io(&tmp_path, e))?;
        let HashingWriter { inner, hasher, bytes } = sink;
        let file = inner.into_inner().map_err(|e| StoreError::io(&tmp_path, e.into_error()))?;
        file.sync_all().map_err(|e| StoreError::io(&tmp_path, e))?;
        drop(file);
        crate::fault::point("scans:before_rename");
        publish(&tmp_path, &final_path)?;
        Ok(FileRecord {
            rel_path,
            kind: "scans".into(),
            size_bytes: bytes,
            blake3: hasher.finalize().to_hex().to_string(),
            row_count: rows,
        })
    }
}

/// Renames a fully written and synced file into place and syncs the folder,
/// so that the rename itself survives a power loss.
pub(super) fn publish(tmp_path: &Path, final_path: &Path) -> Result<(), StoreError> {
    std::fs::rename(tmp_path, final_path).map_err(|e| StoreError::io(final_path, e))?;
    if let Some(dir) = final_path.parent() {
        File::open(dir).and_then(|d| d.sync_all()).map_err(|e| StoreError::io(dir, e))?;
    }
    Ok(())
}

/// Reads one scan (one row group) back from a scans file.
pub fn read_scan_row_group(path: &Path, row_group: usize) -> Result<Scan, StoreError> {
    let perr = |e: &dyn std::fmt::Display| StoreError::Parquet { path: path.to_path_buf(), message: e.to_string() };
    let file = File::open(path).map_err(|e| StoreError::io(path, e))?;
    let builder = ParquetRecordBatchReaderBuilder::try_new(file).map_err(|e| perr(&e))?;
    let n_groups = builder.metadata().num_row_groups();
    if row_group >= n_groups {
        return Err(perr(&format!("row group {row_group} requested, file has {n_groups}")));
    }
    let reader = builder.with_row_groups(vec![row_group]).with_batch_size(1 << 20).build().map_err(|e| perr(&e))?;
    let mut scan = Scan::default();
    let mut all_null = true;
    for batch in reader {
        let batch = batch.map_err(|e| perr(&e))?;
        let f = |i: usize| -> Result<&Float32Array, StoreError> {
            batch
                .column(i)
                .as_any()
                .downcast_ref::<Float32Array>()
                .ok_or_else(|| perr(&format!("column {i} is not float32")))
        };
        let (x, y, z, it) = (f(0)?, f(1)?, f(2)?, f(3)?);
        scan.points.extend((0..x.len()).map(|k| [x.value(k), y.value(k), z.value(k)]));
        all_null &= it.null_count() == it.len();
        scan.intensity.extend(it.values().iter().copied());
    }
    if all_null {
        scan.intensity.clear();
    }
    Ok(scan)
}
