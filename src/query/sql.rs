//! Compiling a [`Plan`] to one SQL statement with `?` placeholders and its
//! parameters. Every value the user typed (coordinates, radii, session
//! numbers, category names, thresholds, row counts, a zone's polygon) is a
//! parameter; the SQL text holds only identifiers from [`super::subjects`]
//! and constants of this file.
//!
//! Shape: the subject's base `SELECT` (region, time and filters in its
//! `WHERE`), wrapped once per pipeline stage that changes the rows
//! (`count`, `sum`, `limit`), and finally
//! `SELECT <visible fields> FROM (...) ORDER BY <order>`. SQLite flattens
//! the nesting. A region is two index lookups and an exact test:
//!
//! ```sql
//! e.tile IN (SELECT tile FROM map_tiles WHERE min_x <= ? AND max_x >= ? ...)  -- R*Tree
//!   AND e.x_m BETWEEN ? AND ? AND ...                                          -- exact box
//!   [AND (e.x_m - ?) * (e.x_m - ?) + ... <= ?]                                 -- near: r:
//!   [AND seam_in_polygon(?, e.x_m, e.y_m)]                                     -- polygon zone
//! ```

use super::ast::Subject;
use super::plan::{Area, FilterOp, Plan, ResolvedFilter, Window};
use super::stages::ResolvedStage;
use super::subjects::{Col, spec};
use rusqlite::types::Value;

/// SQL text with `?` placeholders and the values for them, in order.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Sql {
    pub text: String,
    pub params: Vec<Value>,
}

impl Sql {
    fn push(&mut self, s: &str) -> &mut Sql {
        self.text.push_str(s);
        self
    }
    fn param(&mut self, v: impl Into<Value>) -> &mut Sql {
        self.text.push('?');
        self.params.push(v.into());
        self
    }
    fn append(&mut self, other: Sql) -> &mut Sql {
        self.text.push_str(&other.text);
        self.params.extend(other.params);
        self
    }
    /// `SELECT <fields> FROM (self) <tail>`.
    fn wrap(self, fields: &str, tail: impl FnOnce(&mut Sql)) -> Sql {
        let mut q = Sql::default();
        q.push("SELECT ").push(fields).push(" FROM (").append(self).push(")");
        tail(&mut q);
        q
    }
}

/// A double-quoted identifier. Only names from `subjects` and `count` get
/// here, never user text.
fn ident(name: &str) -> String {
    format!("\"{}\"", name.replace('"', "\"\""))
}

/// The `WHERE` of a list of conditions (`1` when there are none).
fn and(parts: Vec<Sql>) -> Sql {
    let mut q = Sql::default();
    if parts.is_empty() {
        q.push("1");
    }
    for (i, p) in parts.into_iter().enumerate() {
        if i > 0 {
            q.push(" AND ");
        }
        q.append(p);
    }
    q
}

/// Rows of `alias` (a table with `tile`, `x_m`, `y_m`, `z_m`) in the area.
fn region(alias: &str, area: &Area) -> Sql {
    let (lo, hi) = area.bounds();
    let mut q = Sql::default();
    q.push(&format!("{alias}.tile IN (SELECT tile FROM map_tiles WHERE min_x <= "))
        .param(hi[0])
        .push(" AND max_x >= ")
        .param(lo[0])
        .push(" AND min_y <= ")
        .param(hi[1])
        .push(" AND max_y >= ")
        .param(lo[1])
        .push(" AND min_z <= ")
        .param(hi[2])
        .push(" AND max_z >= ")
        .param(lo[2])
        .push(")");
    for (k, axis) in ["x_m", "y_m", "z_m"].iter().enumerate() {
        q.push(&format!(" AND {alias}.{axis} BETWEEN ")).param(lo[k]).push(" AND ").param(hi[k]);
    }
    match area {
        Area::Box { .. } => {}
        Area::Sphere { centre_m, r_m } => {
            q.push(" AND ");
            for (k, axis) in ["x_m", "y_m", "z_m"].iter().enumerate() {
                if k > 0 {
                    q.push(" + ");
                }
                q.push(&format!("({alias}.{axis} - ")).param(centre_m[k]);
                q.push(&format!(") * ({alias}.{axis} - ")).param(centre_m[k]).push(")");
            }
            q.push(" <= ").param(r_m * r_m);
        }
        Area::Polygon { wkt, .. } => {
            q.push(" AND seam_in_polygon(").param(wkt.clone()).push(&format!(", {alias}.x_m, {alias}.y_m)"));
        }
    }
    q
}

/// `expr` is one of the window's sessions.
fn window(expr: &str, w: &Window) -> Sql {
    let mut q = Sql::default();
    let ids = &w.ids;
    let (Some(first), Some(last)) = (ids.first(), ids.last()) else {
        q.push("0");
        return q;
    };
    if first == last {
        // One session: an equality lets an index use the next column too.
        q.push(&format!("{expr} = ")).param(*first);
    } else if ids.len() as i64 == last - first + 1 {
        q.push(&format!("{expr} BETWEEN ")).param(*first).push(" AND ").param(*last);
    } else {
        q.push(&format!("{expr} IN ("));
        for (i, id) in ids.iter().enumerate() {
            if i > 0 {
                q.push(", ");
            }
            q.param(*id);
        }
        q.push(")");
    }
    q
}

/// Map voxels in the map during session `ids[0]`, or that entered it in the
/// window's sessions.
fn map_window(w: &Window) -> Sql {
    match (w.present_at, w.ids.first()) {
        (true, Some(id)) => {
            let mut q = Sql::default();
            q.push("v.first_session <= ").param(*id).push(" AND v.last_seen_session >= ").param(*id);
            q
        }
        _ => window("v.first_session", w),
    }
}

fn filter(expr: &str, f: &ResolvedFilter) -> Sql {
    let mut q = Sql::default();
    q.push(expr);
    let list = |q: &mut Sql, kw: &str| {
        q.push(kw).push(" (");
        for (i, v) in f.values.iter().enumerate() {
            if i > 0 {
                q.push(", ");
            }
            q.param(v.clone());
        }
        q.push(")");
    };
    match f.op {
        FilterOp::Cmp(op) => {
            q.push(&format!(" {} ", op.sql())).param(f.values[0].clone());
        }
        FilterOp::In => list(&mut q, " IN"),
        FilterOp::NotIn => list(&mut q, " NOT IN"),
        FilterOp::Range => {
            q.push(" BETWEEN ").param(f.values[0].clone()).push(" AND ").param(f.values[1].clone());
        }
    }
    q
}

/// `expr AS "name", ...`; a `?` in an expression is the voxel's volume
/// (`*_m3`) or footprint (`*_m2`).
fn select_list(cols: &[Col], voxel_m: f64) -> Sql {
    let mut q = Sql::default();
    for (i, c) in cols.iter().enumerate() {
        if i > 0 {
            q.push(", ");
        }
        let unit = if c.name.ends_with("_m3") { voxel_m.powi(3) } else { voxel_m.powi(2) };
        for (k, part) in c.expr.split('?').enumerate() {
            if k > 0 {
                q.param(unit);
            }
            q.push(part);
        }
        q.push(" AS ").push(&ident(c.name));
    }
    q
}

/// The base `SELECT` of a subject, region, time and (row subjects) filters
/// applied.
fn base(p: &Plan) -> Sql {
    let sp = spec(p.subject);
    let mut q = Sql::default();
    q.push("SELECT ").append(select_list(sp.columns, p.voxel_m));
    let row_filters = |q: &mut Vec<Sql>| {
        for f in &p.filters {
            q.push(filter(f.col.expr, f));
        }
    };
    let region_of = |alias: &str| p.area.as_ref().map_or_else(|| and(Vec::new()), |a| region(alias, a));
    let session_windows = |expr: &str| p.windows.iter().map(|w| window(expr, w)).collect::<Vec<_>>();
    match p.subject {
        Subject::Changes => {
            q.push(" FROM change_events e JOIN sessions s ON s.session_id = e.session_id WHERE ");
            let mut w = vec![region_of("e")];
            w.extend(session_windows("e.session_id"));
            row_filters(&mut w);
            q.append(and(w));
        }
        Subject::Static | Subject::Lifelong => {
            q.push(" FROM map_voxels v WHERE ");
            let mut w = vec![region_of("v")];
            if p.subject == Subject::Static {
                let mut s = Sql::default();
                s.push("v.eps_g < ").param(p.static_threshold);
                w.push(s);
            }
            w.extend(p.windows.iter().map(map_window));
            row_filters(&mut w);
            q.append(and(w));
        }
        Subject::Sessions => {
            q.push(
                " FROM sessions s LEFT JOIN session_alignment a ON a.session_id = s.session_id \
                 LEFT JOIN session_changes c ON c.session_id = s.session_id WHERE ",
            );
            let mut w = session_windows("s.session_id");
            row_filters(&mut w);
            q.append(and(w));
        }
        Subject::Loops => {
            q.push(
                " FROM loop_candidates l JOIN sessions s ON s.session_id = l.session_id \
                 JOIN keyframes ks ON ks.keyframe_id = l.source_keyframe \
                 JOIN keyframes kt ON kt.keyframe_id = l.target_keyframe WHERE ",
            );
            let mut w = session_windows("l.session_id");
            row_filters(&mut w);
            q.append(and(w));
        }
        Subject::History => {
            q.push(
                " FROM sessions s LEFT JOIN (SELECT e.session_id AS sid, count(*) AS events, \
                 sum(e.category IN ('emerged_overlap', 'emerged_non_overlap')) AS emerged, \
                 sum(e.category = 'deleted_overlap') AS deleted, \
                 sum(e.category = 'deleted_non_overlap') AS out_of_view, \
                 sum(e.category = 'coexist') AS returned \
                 FROM change_events e WHERE ",
            )
            .append(region_of("e"))
            .push(" GROUP BY e.session_id) ev ON ev.sid = s.session_id")
            .push(" LEFT JOIN (SELECT v.first_session AS sid, count(*) AS n FROM map_voxels v WHERE ")
            .append(region_of("v"))
            .push(" GROUP BY v.first_session) fv ON fv.sid = s.session_id")
            .push(" LEFT JOIN (SELECT v.last_seen_session AS sid, count(*) AS n FROM map_voxels v WHERE ")
            .append(region_of("v"))
            .push(" GROUP BY v.last_seen_session) lv ON lv.sid = s.session_id WHERE ")
            .append(and(session_windows("s.session_id")));
        }
        Subject::Volume => {
            q.push(
                " FROM sessions s LEFT JOIN (SELECT e.session_id AS sid, \
                 sum(e.category IN ('emerged_overlap', 'emerged_non_overlap')) AS emerged, \
                 sum(e.category = 'deleted_overlap') AS deleted \
                 FROM change_events e WHERE ",
            )
            .append(region_of("e"))
            .push(" GROUP BY e.session_id) ev ON ev.sid = s.session_id WHERE ")
            .append(and(session_windows("s.session_id")));
        }
        Subject::Coverage => {
            // Voxel keys packed into one integer per xy column (keys are
            // within ±2^21 on any site seam handles).
            q.push(
                " FROM sessions s LEFT JOIN (SELECT s2.session_id AS sid, count(*) AS voxels, \
                 count(DISTINCT v.kx * 4194304 + v.ky) AS cells \
                 FROM sessions s2 JOIN map_voxels v \
                 ON v.first_session <= s2.session_id AND v.last_seen_session >= s2.session_id WHERE ",
            )
            .append(region_of("v"))
            .push(" GROUP BY s2.session_id) cv ON cv.sid = s.session_id")
            .push(" CROSS JOIN (SELECT count(*) AS n FROM map_voxels v WHERE ")
            .append(region_of("v"))
            .push(") tot WHERE ")
            .append(and(session_windows("s.session_id")));
        }
    }
    if sp.aggregate && !p.filters.is_empty() {
        // Filters on what the subject computed.
        let parts: Vec<Sql> = p.filters.iter().map(|f| filter(&ident(f.col.name), f)).collect();
        q = q.wrap("*", |w| {
            w.push(" WHERE ").append(and(parts));
        });
    }
    q
}

fn order_by(order: &[(String, bool)]) -> String {
    if order.is_empty() {
        return String::new();
    }
    let keys: Vec<String> =
        order.iter().map(|(n, desc)| format!("{}{}", ident(n), if *desc { " DESC" } else { "" })).collect();
    format!(" ORDER BY {}", keys.join(", "))
}

/// The whole statement.
pub fn compile(p: &Plan) -> Sql {
    let sp = spec(p.subject);
    let mut q = base(p);
    let mut order: Vec<(String, bool)> = vec![(sp.order.to_string(), false)];
    let mut visible: Vec<String> = sp.columns.iter().map(|c| c.name.to_string()).collect();
    for st in &p.stages {
        match st {
            ResolvedStage::Count { by, name } => {
                let keys: Vec<String> = by.iter().map(|n| ident(n)).collect();
                let mut fields = keys.clone();
                fields.push(format!("count(*) AS {}", ident(name)));
                q = q.wrap(&fields.join(", "), |w| {
                    if !keys.is_empty() {
                        w.push(&format!(" GROUP BY {}", keys.join(", ")));
                    }
                });
                order = by.iter().map(|n| (n.clone(), false)).collect();
                visible = by.clone();
                visible.push(name.clone());
            }
            ResolvedStage::Order(o) => order = o.clone(),
            ResolvedStage::Limit(n) => {
                let ob = order_by(&order);
                q = q.wrap("*", |w| {
                    w.push(&ob).push(" LIMIT ").param(i64::try_from(*n).unwrap_or(i64::MAX));
                });
            }
            ResolvedStage::Fields(f) => visible = f.clone(),
            ResolvedStage::Sum(cols) => {
                let fields: Vec<String> =
                    cols.iter().map(|c| format!("coalesce(sum({}), 0) AS {}", ident(c), ident(c))).collect();
                q = q.wrap(&fields.join(", "), |_| {});
                order = Vec::new();
                visible = cols.clone();
            }
        }
    }
    let fields: Vec<String> = visible.iter().map(|n| ident(n)).collect();
    let ob = order_by(&order);
    q.wrap(&fields.join(", "), |w| {
        w.push(&ob);
    })
}
