//! Running a compiled plan on a store connection, and the result as data:
//! text cells for tables and CSV, JSON values, an Arrow batch for Parquet.

use super::plan::{OutCol, Plan};
use super::subjects::Ty;
use crate::geometry::polygon::Polygon;
use crate::store::{DB_FILE, StoreError};
use arrow_array::{ArrayRef, BooleanArray, Float64Array, Int64Array, RecordBatch, StringArray};
use arrow_schema::{DataType, Field, Schema};
use rusqlite::Connection;
use rusqlite::functions::FunctionFlags;
use rusqlite::types::Value;
use std::sync::Arc;

/// What a query returned.
#[derive(Debug, Clone, PartialEq)]
pub struct QueryResult {
    pub columns: Vec<OutCol>,
    /// One value per column; integers, reals, text or NULL as SQLite gives
    /// them (booleans are 0/1 here, `true`/`false` in every output).
    pub rows: Vec<Vec<Value>>,
    pub notes: Vec<String>,
}

fn sql_err(conn: &Connection, source: rusqlite::Error) -> StoreError {
    StoreError::Sql { path: conn.path().map_or_else(|| DB_FILE.into(), Into::into), source }
}

/// Registers `seam_in_polygon(wkt, x, y)`: true when (x, y) is inside the
/// polygon. The polygon is parsed once per statement (SQLite keeps it as
/// auxiliary data of the constant argument).
pub fn register_functions(conn: &Connection) -> rusqlite::Result<()> {
    conn.create_scalar_function(
        "seam_in_polygon",
        3,
        FunctionFlags::SQLITE_UTF8 | FunctionFlags::SQLITE_DETERMINISTIC,
        |ctx| {
            let polygon =
                ctx.get_or_create_aux(0, |v| -> Result<Polygon, Box<dyn std::error::Error + Send + Sync>> {
                    Polygon::from_wkt(v.as_str()?).map_err(Into::into)
                })?;
            let (x, y): (f64, f64) = (ctx.get(1)?, ctx.get(2)?);
            Ok(polygon.contains(x, y))
        },
    )
}

/// Runs the plan.
pub fn execute(conn: &Connection, plan: &Plan) -> Result<QueryResult, StoreError> {
    register_functions(conn).map_err(|e| sql_err(conn, e))?;
    let mut st = conn.prepare(&plan.sql.text).map_err(|e| sql_err(conn, e))?;
    let n = plan.columns.len();
    let rows = st
        .query_map(rusqlite::params_from_iter(plan.sql.params.iter()), |r| {
            (0..n).map(|i| r.get::<_, Value>(i)).collect::<Result<Vec<_>, _>>()
        })
        .map_err(|e| sql_err(conn, e))?
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| sql_err(conn, e))?;
    Ok(QueryResult { columns: plan.columns.clone(), rows, notes: plan.notes.clone() })
}

/// SQLite's own plan for the statement (`EXPLAIN QUERY PLAN`), one line per
/// step, indented by depth.
pub fn sqlite_plan(conn: &Connection, plan: &Plan) -> Result<Vec<String>, StoreError> {
    register_functions(conn).map_err(|e| sql_err(conn, e))?;
    let mut st = conn.prepare(&format!("EXPLAIN QUERY PLAN {}", plan.sql.text)).map_err(|e| sql_err(conn, e))?;
    let rows = st
        .query_map(rusqlite::params_from_iter(plan.sql.params.iter()), |r| {
            Ok((r.get::<_, i64>(0)?, r.get::<_, i64>(1)?, r.get::<_, String>(3)?))
        })
        .map_err(|e| sql_err(conn, e))?
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| sql_err(conn, e))?;
    // Indent each step under its parent.
    let mut depth: Vec<(i64, usize)> = Vec::new();
    let mut out = Vec::new();
    for (id, parent, detail) in rows {
        let d = depth.iter().find(|(i, _)| *i == parent).map_or(0, |(_, d)| d + 1);
        depth.push((id, d));
        out.push(format!("{}{detail}", "  ".repeat(d)));
    }
    Ok(out)
}

fn real(v: &Value) -> Option<f64> {
    match v {
        Value::Integer(i) => Some(*i as f64),
        Value::Real(r) => Some(*r),
        _ => None,
    }
}

fn int(v: &Value) -> Option<i64> {
    match v {
        Value::Integer(i) => Some(*i),
        Value::Real(r) => Some(*r as i64),
        _ => None,
    }
}

fn text(v: &Value) -> Option<String> {
    match v {
        Value::Null => None,
        Value::Integer(i) => Some(i.to_string()),
        Value::Real(r) => Some(r.to_string()),
        Value::Text(t) => Some(t.clone()),
        Value::Blob(b) => Some(format!("<{} bytes>", b.len())),
    }
}

/// A real as the shortest decimal that means it: values stored from an
/// `f32` (ε, positions) print as that `f32` (`0.4`, not
/// `0.4000000059604645`). Parquet output keeps the exact `f64`.
fn shortest(r: f64) -> f64 {
    let f = r as f32;
    if f as f64 == r && f.is_finite() { f.to_string().parse().unwrap_or(r) } else { r }
}

/// The rows as a JSON array of objects whose keys are in column order.
pub struct JsonRows<'a>(pub &'a QueryResult);

struct JsonRow<'a>(&'a QueryResult, usize);

impl serde::Serialize for JsonRows<'_> {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeSeq;
        let mut seq = s.serialize_seq(Some(self.0.rows.len()))?;
        for r in 0..self.0.rows.len() {
            seq.serialize_element(&JsonRow(self.0, r))?;
        }
        seq.end()
    }
}

impl serde::Serialize for JsonRow<'_> {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeMap;
        let mut m = s.serialize_map(Some(self.0.columns.len()))?;
        for (c, col) in self.0.columns.iter().enumerate() {
            m.serialize_entry(&col.name, &self.0.json_cell(self.1, c))?;
        }
        m.end()
    }
}

impl QueryResult {
    /// A cell as text: reals with `digits` decimals (`None`: exact),
    /// booleans `true`/`false`, NULL as `null_text`.
    pub fn cell(&self, row: usize, col: usize, digits: Option<usize>, null_text: &str) -> String {
        let v = &self.rows[row][col];
        if matches!(v, Value::Null) {
            return null_text.to_string();
        }
        match self.columns[col].ty {
            Ty::Bool => (int(v).unwrap_or(0) != 0).to_string(),
            Ty::Real => match (real(v), digits) {
                (Some(r), Some(d)) => format!("{r:.d$}"),
                (Some(r), None) => shortest(r).to_string(),
                _ => text(v).unwrap_or_default(),
            },
            _ => text(v).unwrap_or_default(),
        }
    }

    /// The rows as JSON objects, typed by column (keys sorted; printing
    /// goes through [`JsonRows`], which keeps the column order).
    pub fn to_json(&self) -> serde_json::Value {
        serde_json::to_value(JsonRows(self)).unwrap_or(serde_json::Value::Null)
    }

    /// A cell as JSON.
    fn json_cell(&self, row: usize, col: usize) -> serde_json::Value {
        let v = &self.rows[row][col];
        match (self.columns[col].ty, v) {
            (_, Value::Null) => serde_json::Value::Null,
            (Ty::Bool, v) => (int(v).unwrap_or(0) != 0).into(),
            (Ty::Int, v) => int(v).map_or(serde_json::Value::Null, Into::into),
            (Ty::Real, v) => real(v)
                .and_then(|r| serde_json::Number::from_f64(shortest(r)))
                .map_or(serde_json::Value::Null, serde_json::Value::Number),
            (_, v) => text(v).map_or(serde_json::Value::Null, Into::into),
        }
    }

    /// The rows as one Arrow batch: int64, float64, string, boolean; every
    /// column nullable.
    pub fn to_record_batch(&self) -> Result<RecordBatch, arrow_schema::ArrowError> {
        let mut fields = Vec::new();
        let mut arrays: Vec<ArrayRef> = Vec::new();
        for (i, c) in self.columns.iter().enumerate() {
            let vals = self.rows.iter().map(|r| &r[i]);
            let (t, a): (DataType, ArrayRef) = match c.ty {
                Ty::Int => (DataType::Int64, Arc::new(vals.map(int).collect::<Int64Array>())),
                Ty::Real => (DataType::Float64, Arc::new(vals.map(real).collect::<Float64Array>())),
                Ty::Bool => {
                    (DataType::Boolean, Arc::new(vals.map(|v| int(v).map(|i| i != 0)).collect::<BooleanArray>()))
                }
                Ty::Text | Ty::Category => (DataType::Utf8, Arc::new(vals.map(text).collect::<StringArray>())),
            };
            fields.push(Field::new(c.name.clone(), t, true));
            arrays.push(a);
        }
        RecordBatch::try_new(Arc::new(Schema::new(fields)), arrays)
    }
}
