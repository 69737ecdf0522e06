//! The evidence stage's tables ([`crate::evidence`]) as immutable Parquet
//! files, published with the same protocol as the scans files
//! ([`super::files`]): written under `<name>.tmp-<pid>`, fsynced, renamed into
//! place, the folder fsynced, size and blake3 computed while writing. The
//! caller then records the returned [`FileRecord`] with
//! [`super::insert_file`] in the transaction that commits the rows using it.
//!
//! Every table is written the same way ([`write_table`]): zstd level 3, row
//! groups of [`ROW_GROUP_ROWS`] rows, float columns byte-stream-split without
//! a dictionary. Columns are flat and named so an analyst can open a file in
//! DuckDB or pandas without seam: unsigned counts and indices are stored as
//! `int32` (signed integers travel better), refusing values that do not fit.
//!
//! Readers look columns up by name (extra columns are ignored), check their
//! types, nulls and lengths, and turn any problem, including a truncated or
//! otherwise damaged file, into [`StoreError::Parquet`] naming the file.
//!
//! | kind           | columns |
//! |----------------|---------|
//! | `evidence`     | `kx ky kz` int32, `{hit,free}_n` int32, `{hit,free}_q` float32, `{hit,free}_m{xx,xy,xz,yy,yz,zz}` float32, `owner_keyframe` int32, `owner_q` float32, `hit_{lo,hi}_{x,y,z}_m` float32 (NaN: no point), `no_return_n` int32 (absent in older files: 0) |
//! | `cleaned_map`  | `x_m y_m z_m eps_l` float32, `points owner_keyframe` int32 |
//! | `point_labels` | `keyframe point_index` int32, `dynamic` boolean, `eps_l` float32 (also the export format) |

use super::files::{HashingWriter, publish};
use super::{FileRecord, SessionId, Store, StoreError, sql};
use crate::evidence::{CleanedMap, PointLabels, StatsColumns, SubmapEvidence};
use crate::geometry::{UNKNOWN_SPREAD, VoxelKey};
use arrow_array::{Array, ArrayRef, BooleanArray, Float32Array, Int32Array, RecordBatch};
use arrow_schema::{DataType, Field, Schema, SchemaRef};
use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
use parquet::arrow::{ArrowWriter, ProjectionMask};
use parquet::basic::{Compression, Encoding, ZstdLevel};
use parquet::file::properties::WriterProperties;
use parquet::schema::types::ColumnPath;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Rows per row group: large enough for good compression, small enough that
/// a reader filtering on statistics skips most of a big table.
pub const ROW_GROUP_ROWS: usize = 128 * 1024;

/// Upper-triangle suffixes of a 3×3 symmetric matrix, in `StatsColumns::m` order.
const M_SUFFIXES: [&str; 6] = ["xx", "xy", "xz", "yy", "yz", "zz"];

/// Size, content hash and rows of a file written by [`write_batch`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct WrittenFile {
    pub size_bytes: u64,
    pub blake3: String,
    pub row_count: u64,
}

/// Writes `batch` as a file at `rel_path` of the store at `root`
/// ([`Store::root`]: a path, not the store, so that files can be written
/// from several threads) and returns its record of `kind`, ready for
/// [`super::insert_file`]. Fault point `<kind>:before_rename`.
pub fn write_table(root: &Path, rel_path: &str, kind: &str, batch: &RecordBatch) -> Result<FileRecord, StoreError> {
    let w = write_batch(&root.join(rel_path), kind, batch)?;
    Ok(FileRecord {
        rel_path: rel_path.to_string(),
        kind: kind.to_string(),
        size_bytes: w.size_bytes,
        blake3: w.blake3,
        row_count: w.row_count,
    })
}

/// Writes `batch` as one Parquet file at `final_path` (any folder, created if
/// missing) with the publish protocol: nothing ever appears under
/// `final_path` but the complete, synced file. A failed write removes its
/// temporary file. Fault point `<step>:before_rename`.
pub fn write_batch(final_path: &Path, step: &str, batch: &RecordBatch) -> Result<WrittenFile, StoreError> {
    write_batch_with(final_path, step, batch, ROW_GROUP_ROWS, Vec::new())
}

/// [`write_batch`] with row groups of `row_group_rows` and `key_value`
/// pairs in the file's key-value metadata (GeoParquet's `geo`).
pub fn write_batch_with(
    final_path: &Path,
    step: &str,
    batch: &RecordBatch,
    row_group_rows: usize,
    key_value: Vec<(String, String)>,
) -> Result<WrittenFile, StoreError> {
    if let Some(dir) = final_path.parent() {
        std::fs::create_dir_all(dir).map_err(|e| StoreError::io(dir, e))?;
    }
    let tmp_path = final_path.with_extension(format!("tmp-{}", std::process::id()));
    let props = writer_props(&batch.schema(), row_group_rows, key_value);
    let (size_bytes, blake3) = match write_tmp(&tmp_path, batch, props) {
        Ok(v) => v,
        Err(e) => {
            let _ = std::fs::remove_file(&tmp_path);
            return Err(e);
        }
    };
    crate::fault::point(&format!("{step}:before_rename"));
    publish(&tmp_path, final_path)?;
    Ok(WrittenFile { size_bytes, blake3, row_count: batch.num_rows() as u64 })
}

fn writer_props(schema: &Schema, row_group_rows: usize, key_value: Vec<(String, String)>) -> WriterProperties {
    let mut props = WriterProperties::builder()
        // Level 1: on SemanticKITTI 08's evidence step the files are 1-2 %
        // larger than at 3 and written in 0.09 s instead of 0.11 s (of 0.72).
        .set_compression(Compression::ZSTD(ZstdLevel::try_new(1).unwrap_or_default()))
        .set_max_row_group_row_count(Some(row_group_rows));
    if !key_value.is_empty() {
        props = props.set_key_value_metadata(Some(
            key_value.into_iter().map(|(k, v)| parquet::file::metadata::KeyValue::new(k, v)).collect(),
        ));
    }
    // Floats compress far better split into byte streams; a dictionary of
    // measured values (or of WKB geometries, each distinct) only costs.
    let is_float = |t: &DataType| matches!(t, DataType::Float16 | DataType::Float32 | DataType::Float64);
    for f in schema.fields() {
        let mut leaves: Vec<(ColumnPath, &DataType)> = vec![(ColumnPath::from(f.name().as_str()), f.data_type())];
        if let DataType::Struct(children) = f.data_type() {
            leaves = children
                .iter()
                .map(|c| (ColumnPath::new(vec![f.name().clone(), c.name().clone()]), c.data_type()))
                .collect();
        }
        for (col, t) in leaves {
            if is_float(t) {
                props = props
                    .set_column_dictionary_enabled(col.clone(), false)
                    .set_column_encoding(col, Encoding::BYTE_STREAM_SPLIT);
            } else if super::geoparquet::is_geometry_column(f) {
                props = props.set_column_dictionary_enabled(col, false);
            } else if f.name() == "point_index" {
                // 0, 1, 2, … within each scan: deltas, not a dictionary of
                // every index (SemanticKITTI 08's labels file: 5.3 MB -> 0.14 MB, and
                // the step's files written in 0.06 s instead of 0.09 s).
                props = props
                    .set_column_dictionary_enabled(col.clone(), false)
                    .set_column_encoding(col, Encoding::DELTA_BINARY_PACKED);
            }
        }
    }
    props.build()
}

/// Writes and fsyncs the temporary file; returns its size and blake3.
fn write_tmp(tmp_path: &Path, batch: &RecordBatch, props: WriterProperties) -> Result<(u64, String), StoreError> {
    let perr = |e: &dyn std::fmt::Display| StoreError::Parquet { path: tmp_path.to_path_buf(), message: e.to_string() };
    let file = File::create(tmp_path).map_err(|e| StoreError::io(tmp_path, e))?;
    let sink =
        HashingWriter { inner: BufWriter::with_capacity(1 << 20, file), hasher: blake3::Hasher::new(), bytes: 0 };
    let schema = batch.schema();
    let mut writer = ArrowWriter::try_new(sink, schema, Some(props)).map_err(|e| perr(&e))?;
    // The writer cuts the batch into row groups of ROW_GROUP_ROWS.
    writer.write(batch).map_err(|e| perr(&e))?;
    let mut sink = writer.into_inner().map_err(|e| perr(&e))?;
    sink.flush().map_err(|e| StoreError::io(tmp_path, e))?;
    let HashingWriter { inner, hasher, bytes } = sink;
    let file = inner.into_inner().map_err(|e| StoreError::io(tmp_path, e.into_error()))?;
    file.sync_all().map_err(|e| StoreError::io(tmp_path, e))?;
    Ok((bytes, hasher.finalize().to_hex().to_string()))
}

// ---------------------------------------------------------------------------
// Schemas and batches

fn field(name: impl Into<String>, t: DataType) -> Field {
    Field::new(name, t, false)
}

fn stats_fields(prefix: &str) -> Vec<Field> {
    let mut v = vec![field(format!("{prefix}_n"), DataType::Int32), field(format!("{prefix}_q"), DataType::Float32)];
    v.extend(M_SUFFIXES.iter().map(|s| field(format!("{prefix}_m{s}"), DataType::Float32)));
    v
}

/// The six `hit_box_m` columns, in its order.
const HIT_BOX_COLUMNS: [&str; 6] = ["hit_lo_x_m", "hit_lo_y_m", "hit_lo_z_m", "hit_hi_x_m", "hit_hi_y_m", "hit_hi_z_m"];

/// The `evidence` column added with `evidence::no_return`; older files lack it.
const NO_RETURN_N: &str = "no_return_n";

/// Columns of an `evidence` file.
pub fn submap_evidence_schema() -> SchemaRef {
    let mut f = vec![field("kx", DataType::Int32), field("ky", DataType::Int32), field("kz", DataType::Int32)];
    f.extend(stats_fields("hit"));
    f.extend(stats_fields("free"));
    f.push(field("owner_keyframe", DataType::Int32));
    f.push(field("owner_q", DataType::Float32));
    f.extend(HIT_BOX_COLUMNS.iter().map(|c| field(*c, DataType::Float32)));
    f.push(field(NO_RETURN_N, DataType::Int32));
    Arc::new(Schema::new(f))
}

/// Columns of a `cleaned_map` file.
pub fn cleaned_map_schema() -> SchemaRef {
    Arc::new(Schema::new(
        [
            field("x_m", DataType::Float32),
            field("y_m", DataType::Float32),
            field("z_m", DataType::Float32),
            field("eps_l", DataType::Float32),
            field("points", DataType::Int32),
            field("owner_keyframe", DataType::Int32),
        ]
        .into_iter()
        .chain(M_SUFFIXES.iter().map(|s| field(format!("spread_{s}_m2"), DataType::Float32)))
        .collect::<Vec<_>>(),
    ))
}

/// The cleaned map's columns files written before seam kept the points'
/// spread lack: read as `UNKNOWN_SPREAD`.
fn spread_columns() -> Vec<String> {
    M_SUFFIXES.iter().map(|s| format!("spread_{s}_m2")).collect()
}

/// Columns of a `point_labels` file, which is also the export format.
pub fn point_labels_schema() -> SchemaRef {
    Arc::new(Schema::new(vec![
        field("keyframe", DataType::Int32),
        field("point_index", DataType::Int32),
        field("dynamic", DataType::Boolean),
        field("eps_l", DataType::Float32),
    ]))
}

fn f32_col(v: impl IntoIterator<Item = f32>) -> ArrayRef {
    Arc::new(Float32Array::from_iter_values(v))
}

fn i32_col(v: impl IntoIterator<Item = i32>) -> ArrayRef {
    Arc::new(Int32Array::from_iter_values(v))
}

/// `u32` values as an int32 column, refusing any that do not fit.
fn u32_col(path: &Path, name: &str, v: &[u32]) -> Result<ArrayRef, StoreError> {
    let mut out = Vec::with_capacity(v.len());
    for (row, &x) in v.iter().enumerate() {
        out.push(i32::try_from(x).map_err(|_| StoreError::Parquet {
            path: path.to_path_buf(),
            message: format!("column {name}: value {x} in row {row} does not fit int32"),
        })?);
    }
    Ok(Arc::new(Int32Array::from(out)))
}

/// Refuses tables whose columns differ in length, naming each length.
fn check_lengths(path: &Path, what: &str, lens: &[(&str, usize)]) -> Result<(), StoreError> {
    if lens.iter().all(|(_, n)| *n == lens[0].1) {
        return Ok(());
    }
    let list: Vec<String> = lens.iter().map(|(c, n)| format!("{c} {n}")).collect();
    Err(StoreError::Parquet {
        path: path.to_path_buf(),
        message: format!("{what} columns differ in length ({}); nothing written", list.join(", ")),
    })
}

fn batch(path: &Path, schema: SchemaRef, cols: Vec<ArrayRef>) -> Result<RecordBatch, StoreError> {
    RecordBatch::try_new(schema, cols)
        .map_err(|e| StoreError::Parquet { path: path.to_path_buf(), message: e.to_string() })
}

fn stats_cols(path: &Path, prefix: &str, s: &StatsColumns) -> Result<Vec<ArrayRef>, StoreError> {
    let mut cols = vec![u32_col(path, &format!("{prefix}_n"), &s.n)?, f32_col(s.q.iter().copied())];
    cols.extend((0..6).map(|i| f32_col(s.m.iter().map(|m| m[i]))));
    Ok(cols)
}

/// The `evidence` columns of a submap's evidence.
pub fn submap_evidence_batch(path: &Path, ev: &SubmapEvidence) -> Result<RecordBatch, StoreError> {
    check_lengths(
        path,
        "submap evidence",
        &[
            ("keys", ev.keys.len()),
            ("hit_n", ev.hit.n.len()),
            ("hit_q", ev.hit.q.len()),
            ("hit_m", ev.hit.m.len()),
            ("free_n", ev.free.n.len()),
            ("free_q", ev.free.q.len()),
            ("free_m", ev.free.m.len()),
            ("owner_keyframe", ev.owner_keyframe.len()),
            ("owner_q", ev.owner_q.len()),
            ("hit_box_m", ev.hit_box_m.len()),
            ("no_return_n", ev.no_return_n.len()),
        ],
    )?;
    let mut cols: Vec<ArrayRef> = (0..3).map(|i| i32_col(ev.keys.iter().map(|k| k.0[i]))).collect();
    cols.extend(stats_cols(path, "hit", &ev.hit)?);
    cols.extend(stats_cols(path, "free", &ev.free)?);
    cols.push(u32_col(path, "owner_keyframe", &ev.owner_keyframe)?);
    cols.push(f32_col(ev.owner_q.iter().copied()));
    cols.extend((0..6).map(|i| f32_col(ev.hit_box_m.iter().map(|b| b[i]))));
    cols.push(u32_col(path, NO_RETURN_N, &ev.no_return_n)?);
    batch(path, submap_evidence_schema(), cols)
}

/// The `cleaned_map` columns of a cleaned map.
pub fn cleaned_map_batch(path: &Path, map: &CleanedMap) -> Result<RecordBatch, StoreError> {
    check_lengths(
        path,
        "cleaned map",
        &[
            ("xyz_m", map.xyz_m.len()),
            ("eps_l", map.eps_l.len()),
            ("points", map.points.len()),
            ("owner_keyframe", map.owner_keyframe.len()),
            ("spread_m2", map.spread_m2.len()),
        ],
    )?;
    let mut cols: Vec<ArrayRef> = (0..3).map(|i| f32_col(map.xyz_m.iter().map(|p| p[i]))).collect();
    cols.push(f32_col(map.eps_l.iter().copied()));
    cols.push(u32_col(path, "points", &map.points)?);
    cols.push(u32_col(path, "owner_keyframe", &map.owner_keyframe)?);
    cols.extend((0..6).map(|i| f32_col(map.spread_m2.iter().map(|c| c[i]))));
    batch(path, cleaned_map_schema(), cols)
}

/// The `point_labels` columns of a session's point labels.
pub fn point_labels_batch(path: &Path, l: &PointLabels) -> Result<RecordBatch, StoreError> {
    check_lengths(
        path,
        "point labels",
        &[
            ("keyframe", l.keyframe.len()),
            ("point_index", l.point_index.len()),
            ("dynamic", l.dynamic.len()),
            ("eps_l", l.eps_l.len()),
        ],
    )?;
    let cols: Vec<ArrayRef> = vec![
        i32_col(l.keyframe.iter().copied()),
        i32_col(l.point_index.iter().copied()),
        Arc::new(BooleanArray::from(l.dynamic.clone())),
        f32_col(l.eps_l.iter().copied()),
    ];
    batch(path, point_labels_schema(), cols)
}

// ---------------------------------------------------------------------------
// Writers

/// Publishes a submap's evidence at `rel_path` (of the store at `root`) as a file of kind `evidence`.
pub fn write_submap_evidence(root: &Path, rel_path: &str, ev: &SubmapEvidence) -> Result<FileRecord, StoreError> {
    let b = submap_evidence_batch(&root.join(rel_path), ev)?;
    write_table(root, rel_path, "evidence", &b)
}

/// Publishes a submap's cleaned map at `rel_path` (of the store at `root`) as a file of kind `cleaned_map`.
pub fn write_cleaned_map(root: &Path, rel_path: &str, map: &CleanedMap) -> Result<FileRecord, StoreError> {
    let b = cleaned_map_batch(&root.join(rel_path), map)?;
    write_table(root, rel_path, "cleaned_map", &b)
}

/// Publishes a session's point labels at `rel_path` (of the store at `root`) as a file of kind `point_labels`.
pub fn write_point_labels(root: &Path, rel_path: &str, labels: &PointLabels) -> Result<FileRecord, StoreError> {
    let b = point_labels_batch(&root.join(rel_path), labels)?;
    write_table(root, rel_path, "point_labels", &b)
}

/// Writes point labels to `path` outside any store (`seam export`), with
/// the same publish protocol. Fault point `export:before_rename`.
pub fn export_point_labels(path: &Path, labels: &PointLabels) -> Result<WrittenFile, StoreError> {
    let rows = super::geoparquet::EXPORT_ROW_GROUP_ROWS;
    write_batch_with(path, "export", &point_labels_batch(path, labels)?, rows, Vec::new())
}

// ---------------------------------------------------------------------------
// Readers

/// The columns of `schema` read from the file at `path`, validated.
struct Table {
    path: PathBuf,
    rows: usize,
    batches: Vec<RecordBatch>,
}

impl Table {
    fn err(&self, message: String) -> StoreError {
        StoreError::Parquet { path: self.path.clone(), message }
    }

    /// Reads the named columns of `schema` from `path`, checking each exists
    /// with the expected type. A reader panic on a damaged file is turned
    /// into an error too: a corrupt file must never take the process down.
    fn read(path: &Path, schema: &Schema) -> Result<Table, StoreError> {
        Table::read_with_optional(path, schema, &[])
    }

    /// As [`Table::read`], but the columns named in `optional` may be
    /// missing ([`Table::has`] tells).
    fn read_with_optional(path: &Path, schema: &Schema, optional: &[String]) -> Result<Table, StoreError> {
        let run = std::panic::AssertUnwindSafe(|| Table::read_inner(path, schema, optional));
        std::panic::catch_unwind(run).unwrap_or_else(|panic| {
            let what = panic
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_else(|| "unknown reason".into());
            Err(StoreError::Parquet { path: path.to_path_buf(), message: format!("damaged file: {what}") })
        })
    }

    fn read_inner(path: &Path, schema: &Schema, optional: &[String]) -> Result<Table, StoreError> {
        let perr = |m: String| StoreError::Parquet { path: path.to_path_buf(), message: m };
        let file = File::open(path).map_err(|e| StoreError::io(path, e))?;
        let builder = ParquetRecordBatchReaderBuilder::try_new(file).map_err(|e| perr(e.to_string()))?;
        let file_schema = builder.schema().clone();
        let mut roots = Vec::with_capacity(schema.fields().len());
        for f in schema.fields() {
            let Ok(i) = file_schema.index_of(f.name()) else {
                if optional.contains(f.name()) {
                    continue;
                }
                let have: Vec<&str> = file_schema.fields().iter().map(|f| f.name().as_str()).collect();
                return Err(perr(format!("no column {:?} (the file has {})", f.name(), have.join(", "))));
            };
            let t = file_schema.field(i).data_type();
            if t != f.data_type() {
                return Err(perr(format!("column {:?} is {t}, expected {}", f.name(), f.data_type())));
            }
            roots.push(i);
        }
        let rows = usize::try_from(builder.metadata().file_metadata().num_rows())
            .map_err(|_| perr("negative row count in the footer".into()))?;
        let mask = ProjectionMask::roots(builder.parquet_schema(), roots);
        let reader =
            builder.with_projection(mask).with_batch_size(64 * 1024).build().map_err(|e| perr(e.to_string()))?;
        let batches = reader.collect::<Result<Vec<_>, _>>().map_err(|e| perr(e.to_string()))?;
        // Checked before anything is sized by the footer's (untrusted) count.
        let got: usize = batches.iter().map(|b| b.num_rows()).sum();
        if got != rows {
            return Err(perr(format!("the footer says {rows} rows, the row groups hold {got}")));
        }
        Ok(Table { path: path.to_path_buf(), rows, batches })
    }

    /// One column, all batches concatenated; refuses nulls and a length
    /// other than the table's row count.
    fn column<A: Array + 'static, T>(&self, name: &str, values: impl Fn(&A) -> Vec<T>) -> Result<Vec<T>, StoreError> {
        let mut out = Vec::with_capacity(self.rows);
        for b in &self.batches {
            let col = b.column_by_name(name).ok_or_else(|| self.err(format!("no column {name:?}")))?;
            let a = col
                .as_any()
                .downcast_ref::<A>()
                .ok_or_else(|| self.err(format!("column {name:?} is {}, not the expected type", col.data_type())))?;
            if a.null_count() > 0 {
                return Err(self.err(format!("column {name:?} has {} null values", a.null_count())));
            }
            out.extend(values(a));
        }
        if out.len() != self.rows {
            return Err(self.err(format!("column {name:?} has {} values, the other columns {}", out.len(), self.rows)));
        }
        Ok(out)
    }

    /// Whether the file has column `name` (an optional one may be missing).
    fn has(&self, name: &str) -> bool {
        self.batches.first().is_some_and(|b| b.column_by_name(name).is_some())
    }

    fn f32s(&self, name: &str) -> Result<Vec<f32>, StoreError> {
        self.column(name, |a: &Float32Array| a.values().to_vec())
    }

    fn i32s(&self, name: &str) -> Result<Vec<i32>, StoreError> {
        self.column(name, |a: &Int32Array| a.values().to_vec())
    }

    /// An int32 column holding counts or indices: refuses negative values.
    fn u32s(&self, name: &str) -> Result<Vec<u32>, StoreError> {
        let v = self.i32s(name)?;
        if let Some((row, x)) = v.iter().enumerate().find(|(_, x)| **x < 0) {
            return Err(self.err(format!("column {name:?} has negative value {x} in row {row}")));
        }
        Ok(v.into_iter().map(|x| x as u32).collect())
    }

    fn bools(&self, name: &str) -> Result<Vec<bool>, StoreError> {
        self.column(name, |a: &BooleanArray| a.values().iter().collect())
    }

    fn stats(&self, prefix: &str) -> Result<StatsColumns, StoreError> {
        let n = self.u32s(&format!("{prefix}_n"))?;
        let q = self.f32s(&format!("{prefix}_q"))?;
        let parts: Vec<Vec<f32>> =
            M_SUFFIXES.iter().map(|s| self.f32s(&format!("{prefix}_m{s}"))).collect::<Result<_, _>>()?;
        let m = (0..self.rows).map(|r| std::array::from_fn(|i| parts[i][r])).collect();
        Ok(StatsColumns { n, q, m })
    }
}

/// Reads an `evidence` file back.
pub fn read_submap_evidence(path: &Path) -> Result<SubmapEvidence, StoreError> {
    let t = Table::read_with_optional(path, &submap_evidence_schema(), &[NO_RETURN_N.to_string()])?;
    let (kx, ky, kz) = (t.i32s("kx")?, t.i32s("ky")?, t.i32s("kz")?);
    let keys = (0..t.rows).map(|r| VoxelKey([kx[r], ky[r], kz[r]])).collect();
    let boxes: Vec<Vec<f32>> = HIT_BOX_COLUMNS.iter().map(|c| t.f32s(c)).collect::<Result<_, _>>()?;
    Ok(SubmapEvidence {
        hit_box_m: (0..t.rows).map(|r| std::array::from_fn(|i| boxes[i][r])).collect(),
        keys,
        hit: t.stats("hit")?,
        free: t.stats("free")?,
        owner_keyframe: t.u32s("owner_keyframe")?,
        owner_q: t.f32s("owner_q")?,
        no_return_n: if t.has(NO_RETURN_N) { t.u32s(NO_RETURN_N)? } else { vec![0; t.rows] },
    })
}

/// Reads a `cleaned_map` file back.
pub fn read_cleaned_map(path: &Path) -> Result<CleanedMap, StoreError> {
    let spread = spread_columns();
    let t = Table::read_with_optional(path, &cleaned_map_schema(), &spread)?;
    let (x, y, z) = (t.f32s("x_m")?, t.f32s("y_m")?, t.f32s("z_m")?);
    let spread_m2 = if spread.iter().all(|c| t.has(c)) {
        let parts: Vec<Vec<f32>> = spread.iter().map(|c| t.f32s(c)).collect::<Result<_, _>>()?;
        (0..t.rows).map(|r| std::array::from_fn(|i| parts[i][r])).collect()
    } else {
        vec![UNKNOWN_SPREAD; t.rows]
    };
    Ok(CleanedMap {
        spread_m2,
        xyz_m: (0..t.rows).map(|r| [x[r], y[r], z[r]]).collect(),
        eps_l: t.f32s("eps_l")?,
        points: t.u32s("points")?,
        owner_keyframe: t.u32s("owner_keyframe")?,
    })
}

/// Reads a `point_labels` file back.
pub fn read_point_labels(path: &Path) -> Result<PointLabels, StoreError> {
    let t = Table::read(path, &point_labels_schema())?;
    Ok(PointLabels {
        keyframe: t.i32s("keyframe")?,
        point_index: t.i32s("point_index")?,
        dynamic: t.bools("dynamic")?,
        eps_l: t.f32s("eps_l")?,
    })
}

// ---------------------------------------------------------------------------
// Finding files

/// A stored file of one kind and the session it belongs to.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SessionFile {
    pub rel_path: String,
    pub session_id: SessionId,
    pub session_name: String,
}

/// Every file of `kind` that belongs to a session, by session then file id.
pub fn session_files(store: &Store, kind: &str) -> Result<Vec<SessionFile>, StoreError> {
    let root = store.root();
    let mut st = store
        .conn()
        .prepare(
            "SELECT f.rel_path, s.session_id, s.name FROM files f JOIN sessions s ON s.session_id = f.session_id
             WHERE f.kind = ?1 ORDER BY s.session_id, f.file_id",
        )
        .map_err(|e| sql(root, e))?;
    let rows = st
        .query_map([kind], |r| {
            Ok(SessionFile { rel_path: r.get(0)?, session_id: SessionId(r.get(1)?), session_name: r.get(2)? })
        })
        .map_err(|e| sql(root, e))?;
    rows.collect::<Result<Vec<_>, _>>().map_err(|e| sql(root, e))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::store::InitOptions;
    use parquet::file::reader::{FileReader, SerializedFileReader};
    use std::io::{Seek, SeekFrom};

    fn store(dir: &tempfile::TempDir) -> Store {
        let opts = InitOptions { site_name: "t".into(), crs: "local".into(), voxel_size_m: 0.2 };
        Store::create(&dir.path().join("s.seam"), &opts).unwrap()
    }

    fn stats(n: usize, seed: f32) -> StatsColumns {
        StatsColumns {
            n: (0..n as u32).map(|i| i * 7 + 1).collect(),
            q: (0..n).map(|i| i as f32 * 0.5 + seed).collect(),
            m: (0..n).map(|i| std::array::from_fn(|k| (i * 6 + k) as f32 * 0.01 - seed)).collect(),
        }
    }

    fn evidence(n: usize) -> SubmapEvidence {
        SubmapEvidence {
            keys: (0..n as i32).map(|i| VoxelKey([i - 5, -2 * i, i * i])).collect(),
            hit: stats(n, 0.25),
            free: stats(n, 1.5),
            owner_keyframe: (0..n as u32).map(|i| i % 4).collect(),
            owner_q: (0..n).map(|i| 1.0 / (i as f32 + 1.0)).collect(),
            hit_box_m: (0..n).map(|i| std::array::from_fn(|k| (i % 5 + k) as f32 * 0.02)).collect(),
            no_return_n: (0..n as u32).map(|i| i % 3).collect(),
        }
    }

    fn cleaned(n: usize) -> CleanedMap {
        CleanedMap {
            xyz_m: (0..n).map(|i| [i as f32 * 0.2, -(i as f32), 3.5]).collect(),
            eps_l: (0..n).map(|i| 0.1 + (i % 10) as f32 * 0.09).collect(),
            points: (0..n as u32).map(|i| i + 1).collect(),
            owner_keyframe: (0..n as u32).map(|i| i / 3).collect(),
            spread_m2: (0..n).map(|i| [1e-4 * i as f32, -2e-5, 3e-6, 4e-4, 0.0, 1e-6]).collect(),
        }
    }

    fn labels(n: usize) -> PointLabels {
        PointLabels {
            keyframe: (0..n as i32).map(|i| i / 1000).collect(),
            point_index: (0..n as i32).map(|i| i % 1000).collect(),
            dynamic: (0..n).map(|i| i % 7 == 0).collect(),
            eps_l: (0..n).map(|i| 0.1 + (i % 19) as f32 * 0.05).collect(),
        }
    }

    fn metadata(path: &Path) -> parquet::file::metadata::ParquetMetaData {
        SerializedFileReader::new(File::open(path).unwrap()).unwrap().metadata().clone()
    }

    /// The record matches the bytes on disk.
    fn assert_record(store: &Store, rec: &FileRecord, kind: &str, rows: usize) {
        let bytes = std::fs::read(store.path_of(&rec.rel_path)).unwrap();
        assert_eq!(rec.kind, kind);
        assert_eq!(rec.size_bytes, bytes.len() as u64);
        assert_eq!(rec.blake3, blake3::hash(&bytes).to_hex().to_string());
        assert_eq!(rec.row_count, rows as u64);
    }

    #[test]
    fn submap_evidence_round_trips_including_empty() {
        let dir = tempfile::tempdir().unwrap();
        let s = store(&dir);
        for n in [0, 1, 1000] {
            let ev = evidence(n);
            let rel = format!("data/evidence/e{n}.parquet");
            let rec = write_submap_evidence(s.root(), &rel, &ev).unwrap();
            assert_record(&s, &rec, "evidence", n);
            assert_eq!(read_submap_evidence(&s.path_of(&rel)).unwrap(), ev);
        }
        let cols: Vec<String> = submap_evidence_schema().fields().iter().map(|f| f.name().clone()).collect::<Vec<_>>();
        assert_eq!(cols.len(), 3 + 8 + 8 + 2 + 6 + 1);
        assert_eq!(cols.last().map(String::as_str), Some("no_return_n"));
        assert!(cols.contains(&"free_mzz".to_string()) && cols.contains(&"hit_mxy".to_string()));
        // A voxel no point fell in keeps its NaN box.
        let mut ev = evidence(3);
        ev.hit_box_m[1] = crate::evidence::NO_HIT_BOX;
        write_submap_evidence(s.root(), "data/evidence/nan.parquet", &ev).unwrap();
        let back = read_submap_evidence(&s.path_of("data/evidence/nan.parquet")).unwrap();
        assert!(back.hit_box_m[1].iter().all(|v| v.is_nan()));
        assert_eq!(back.hit_box_m[2], ev.hit_box_m[2]);
    }

    #[test]
    fn cleaned_map_round_trips_including_empty() {
        let dir = tempfile::tempdir().unwrap();
        let s = store(&dir);
        for n in [0, 5, 3000] {
            let m = cleaned(n);
            let rel = format!("data/cleaned/c{n}.parquet");
            let rec = write_cleaned_map(s.root(), &rel, &m).unwrap();
            assert_record(&s, &rec, "cleaned_map", n);
            assert_eq!(read_cleaned_map(&s.path_of(&rel)).unwrap(), m);
        }
    }

    /// An evidence file written before the no-return count reads with it 0.
    #[test]
    fn evidence_without_the_no_return_column_reads_as_zero() {
        let dir = tempfile::tempdir().unwrap();
        let s = store(&dir);
        let ev = evidence(4);
        let full = submap_evidence_batch(Path::new("x"), &ev).unwrap();
        let n = full.num_columns() - 1;
        let old = RecordBatch::try_new(
            Arc::new(Schema::new(submap_evidence_schema().fields()[..n].to_vec())),
            full.columns()[..n].to_vec(),
        )
        .unwrap();
        write_table(s.root(), "data/old_ev.parquet", "evidence", &old).unwrap();
        let back = read_submap_evidence(&s.path_of("data/old_ev.parquet")).unwrap();
        assert_eq!(back.no_return_n, vec![0; 4]);
        assert_eq!(SubmapEvidence { no_return_n: ev.no_return_n.iter().map(|_| 0).collect(), ..ev }, back);
    }

    /// A cleaned map written before seam kept the points' spread reads with
    /// the spread unknown, and the rest as written.
    #[test]
    fn cleaned_map_without_spread_columns_reads_as_unknown_spread() {
        let dir = tempfile::tempdir().unwrap();
        let s = store(&dir);
        let old = Arc::new(Schema::new(cleaned_map_schema().fields()[..6].to_vec()));
        let b = RecordBatch::try_new(
            old,
            vec![
                f32_col([1.0, 2.0]),
                f32_col([0.0, 0.5]),
                f32_col([3.0, 3.0]),
                f32_col([0.1, 0.9]),
                i32_col([4, 7]),
                i32_col([0, 2]),
            ],
        )
        .unwrap();
        write_table(s.root(), "data/old.parquet", "cleaned_map", &b).unwrap();
        let m = read_cleaned_map(&s.path_of("data/old.parquet")).unwrap();
        assert_eq!((m.xyz_m[1], m.points.clone(), m.owner_keyframe.clone()), ([2.0, 0.5, 3.0], vec![4, 7], vec![0, 2]));
        assert_eq!(m.spread_m2.len(), 2);
        assert!(m.spread_m2.iter().flatten().all(|c| c.is_nan()));
        // Some spread columns but not all is damage, not an old file: still
        // read as unknown rather than half a matrix.
        let fields = cleaned_map_schema().fields()[..7].to_vec();
        let partial = Arc::new(Schema::new(fields));
        let b = RecordBatch::try_new(
            partial,
            vec![
                f32_col([1.0]),
                f32_col([0.0]),
                f32_col([3.0]),
                f32_col([0.1]),
                i32_col([4]),
                i32_col([0]),
                f32_col([0.2]),
            ],
        )
        .unwrap();
        write_table(s.root(), "data/part.parquet", "cleaned_map", &b).unwrap();
        let m = read_cleaned_map(&s.path_of("data/part.parquet")).unwrap();
        assert!(m.spread_m2[0].iter().all(|c| c.is_nan()));
    }

    #[test]
    fn point_labels_round_trip_in_row_groups_with_split_floats() {
        let dir = tempfile::tempdir().unwrap();
        let s = store(&dir);
        for n in [0, 3, 300_000] {
            let l = labels(n);
            let rel = format!("data/labels/l{n}.parquet");
            let rec = write_point_labels(s.root(), &rel, &l).unwrap();
            assert_record(&s, &rec, "point_labels", n);
            assert_eq!(read_point_labels(&s.path_of(&rel)).unwrap(), l);
        }
        let md = metadata(&s.path_of("data/labels/l300000.parquet"));
        assert_eq!(md.num_row_groups(), 300_000usize.div_ceil(ROW_GROUP_ROWS));
        let rg = md.row_group(0);
        assert_eq!(rg.num_rows(), ROW_GROUP_ROWS as i64);
        let cols: Vec<String> = rg.columns().iter().map(|c| c.column_path().string()).collect();
        assert_eq!(cols, ["keyframe", "point_index", "dynamic", "eps_l"]);
        let eps = rg.column(3);
        assert!(eps.encodings().any(|e| e == Encoding::BYTE_STREAM_SPLIT), "{:?}", eps.encodings().collect::<Vec<_>>());
        assert!(!eps.encodings().any(|e| e == Encoding::RLE_DICTIONARY || e == Encoding::PLAIN_DICTIONARY));
        assert!(matches!(eps.compression(), Compression::ZSTD(_)));
        // No temporary file is left behind.
        let left: Vec<_> =
            std::fs::read_dir(s.path_of("data/labels")).unwrap().flatten().map(|e| e.file_name()).collect();
        assert_eq!(left.len(), 3, "{left:?}");
    }

    #[test]
    fn truncated_or_damaged_file_is_an_error_naming_it() {
        let dir = tempfile::tempdir().unwrap();
        let s = store(&dir);
        let rel = "data/labels/l.parquet";
        write_point_labels(s.root(), rel, &labels(20_000)).unwrap();
        let path = s.path_of(rel);
        let bytes = std::fs::read(&path).unwrap();
        let bad = dir.path().join("bad.parquet");
        for cut in [0, 4, 12, bytes.len() / 2, bytes.len() - 9, bytes.len() - 1] {
            std::fs::write(&bad, &bytes[..cut]).unwrap();
            let err = read_point_labels(&bad).unwrap_err();
            assert!(matches!(err, StoreError::Parquet { .. }), "cut {cut}: {err}");
            assert!(err.to_string().contains(&bad.display().to_string()), "cut {cut}: {err}");
        }
        // Any flipped byte of a small file: an error naming it, or (if the
        // flip is not detectable here; `seam check`'s hash catches it) some
        // data, never a panic. parquet 60 panics on some damaged footers
        // ("column start and length should not be negative"); the reader
        // turns those into errors.
        let path = dir.path().join("small.parquet");
        export_point_labels(&path, &labels(50)).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        std::fs::write(&bad, &bytes).unwrap();
        let mut damaged = 0;
        // Patching one byte in place is ~100x faster than rewriting the file.
        let patch = |at: usize, v: u8| {
            let mut f = std::fs::OpenOptions::new().write(true).open(&bad).unwrap();
            f.seek(SeekFrom::Start(at as u64)).unwrap();
            f.write_all(&[v]).unwrap();
        };
        for (at, &byte) in bytes.iter().enumerate() {
            patch(at, byte ^ 0x01);
            let got = read_point_labels(&bad);
            patch(at, byte);
            if let Err(e) = got {
                assert!(e.to_string().contains(&bad.display().to_string()), "{e}");
                damaged += 1;
            }
        }
        assert!(damaged > 0);
        let missing = read_point_labels(&dir.path().join("nope.parquet")).unwrap_err();
        assert!(matches!(missing, StoreError::Io { .. }), "{missing}");
    }

    #[test]
    fn wrong_file_names_what_is_wrong() {
        let dir = tempfile::tempdir().unwrap();
        let s = store(&dir);
        write_cleaned_map(s.root(), "data/c.parquet", &cleaned(4)).unwrap();
        let err = read_point_labels(&s.path_of("data/c.parquet")).unwrap_err().to_string();
        assert!(err.contains("no column \"keyframe\"") && err.contains("c.parquet"), "{err}");

        // Right names, wrong type.
        let schema = Arc::new(Schema::new(vec![
            field("keyframe", DataType::Float32),
            field("point_index", DataType::Int32),
            field("dynamic", DataType::Boolean),
            field("eps_l", DataType::Float32),
        ]));
        let b = RecordBatch::try_new(
            schema,
            vec![f32_col([1.0]), i32_col([2]), Arc::new(BooleanArray::from(vec![true])), f32_col([0.5])],
        )
        .unwrap();
        write_table(s.root(), "data/t.parquet", "point_labels", &b).unwrap();
        let err = read_point_labels(&s.path_of("data/t.parquet")).unwrap_err().to_string();
        assert!(err.contains("column \"keyframe\" is Float32, expected Int32"), "{err}");

        // Negative counts are refused on read; too-large ones on write.
        let schema = Arc::new(Schema::new(cleaned_map_schema().fields()[..6].to_vec()));
        let b = RecordBatch::try_new(
            schema,
            vec![f32_col([0.0]), f32_col([0.0]), f32_col([0.0]), f32_col([0.5]), i32_col([-3]), i32_col([0])],
        )
        .unwrap();
        write_table(s.root(), "data/neg.parquet", "cleaned_map", &b).unwrap();
        let err = read_cleaned_map(&s.path_of("data/neg.parquet")).unwrap_err().to_string();
        assert!(err.contains("column \"points\" has negative value -3"), "{err}");
        let mut m = cleaned(2);
        m.points[1] = u32::MAX;
        let err = write_cleaned_map(s.root(), "data/big.parquet", &m).unwrap_err().to_string();
        assert!(err.contains("column points: value 4294967295 in row 1 does not fit int32"), "{err}");
        assert!(!s.path_of("data/big.parquet").exists());

        // Columns of different lengths are refused before anything is written.
        let mut l = labels(3);
        l.dynamic.pop();
        let err = write_point_labels(s.root(), "data/l.parquet", &l).unwrap_err().to_string();
        assert!(err.contains("dynamic 2"), "{err}");
        assert!(!s.path_of("data/l.parquet").exists());
    }

    #[test]
    fn extra_columns_are_ignored_and_session_files_are_listed() {
        let dir = tempfile::tempdir().unwrap();
        let mut s = store(&dir);
        let l = labels(10);
        let mut cols = point_labels_batch(Path::new("x"), &l).unwrap().columns().to_vec();
        let mut fields: Vec<Field> = point_labels_schema().fields().iter().map(|f| f.as_ref().clone()).collect();
        fields.insert(0, field("extra", DataType::Int32));
        cols.insert(0, i32_col(0..10));
        let b = RecordBatch::try_new(Arc::new(Schema::new(fields)), cols).unwrap();
        let rec = write_table(s.root(), "data/labels/x.parquet", "point_labels", &b).unwrap();
        assert_eq!(read_point_labels(&s.path_of("data/labels/x.parquet")).unwrap(), l);

        let root = s.root().to_path_buf();
        s.transaction(|tx| -> Result<(), StoreError> {
            let ns = crate::store::NewSession {
                name: "a",
                content_hash: "h",
                source_dir: "/d",
                layout: "kitti",
                date: None,
                sensor_model: None,
                fov_json: None,
                keyframe_count: 1,
                point_count: 10,
            };
            let sid = crate::store::insert_session(tx, &ns)?;
            crate::store::insert_file(tx, &root, &rec, Some(sid.0))?;
            Ok(())
        })
        .unwrap();
        let files = session_files(&s, "point_labels").unwrap();
        assert_eq!(
            files,
            [SessionFile {
                rel_path: "data/labels/x.parquet".into(),
                session_id: SessionId(1),
                session_name: "a".into()
            }]
        );
        assert!(session_files(&s, "evidence").unwrap().is_empty());
    }
}
