//! Resolution: the syntax tree checked against the store's catalog. Session
//! names, numbers and dates become session numbers, zone names become
//! shapes, fields and categories are checked, and every mistake becomes an
//! error at its span with what exists instead. The result is compiled to
//! SQL by [`super::sql`].
//!
//! Time, by subject (`since:` and `between:` include their ends):
//!
//! | subject | `since:` / `between:` / `session:` | `at:X` |
//! |---|---|---|
//! | changes, volume, history, coverage, sessions, loops | rows of those sessions | rows of session X |
//! | static, lifelong | voxels that entered the map in those sessions (`first_session`) | voxels in the map during X (`first_session ≤ X ≤ last_seen_session`) |
//!
//! A date selects the sessions of that day or later (`since:`), up to it
//! (end of `between:`), or of that day (`at:`; for the maps, the last of that
//! day). A session's day is its `session.toml` date, else its ingest day.

use super::ast::{self, Cond, Lit, Query, RefKind, Region, SessionRef, Subject, Time};
use super::catalog::{Catalog, SessionInfo};
use super::error::{QueryError, did_you_mean, suggest};
use super::lexer::CmpOp;
use super::parser::{REGION_KEYS, TIME_KEYS};
use super::sql::{Sql, compile};
use super::stages::{ResolvedStage, describe_stage, resolve_stages};
use super::subjects::{Col, EVENT_CATEGORIES, MAP_CATEGORIES, Spec, Ty, spec};
use crate::store::ZoneShape;
use rusqlite::types::Value;

/// The region, resolved to a shape in the world frame.
#[derive(Debug, Clone, PartialEq)]
pub enum Area {
    Box {
        min_m: [f64; 3],
        max_m: [f64; 3],
    },
    /// A ball: its box asks the index, the distance is tested exactly.
    Sphere {
        centre_m: [f64; 3],
        r_m: f64,
    },
    /// A polygon zone: its bounding box asks the index, the polygon is
    /// tested in Rust (`seam_in_polygon`).
    Polygon {
        wkt: String,
        min_m: [f64; 3],
        max_m: [f64; 3],
    },
}

impl Area {
    /// The box that holds the area (what the tile R*Tree is asked for).
    pub fn bounds(&self) -> ([f64; 3], [f64; 3]) {
        match self {
            Area::Box { min_m, max_m } | Area::Polygon { min_m, max_m, .. } => (*min_m, *max_m),
            Area::Sphere { centre_m: c, r_m } => (c.map(|v| v - r_m), c.map(|v| v + r_m)),
        }
    }
}

/// A time qualifier resolved to session numbers.
#[derive(Debug, Clone, PartialEq)]
pub struct Window {
    pub ids: Vec<i64>,
    /// `at:` on a map subject: voxels in the map during `ids[0]`.
    pub present_at: bool,
    /// As typed, for `--explain`.
    pub text: String,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FilterOp {
    Cmp(CmpOp),
    In,
    NotIn,
    /// `values[0] ≤ x ≤ values[1]`.
    Range,
}

#[derive(Debug, Clone, PartialEq)]
pub struct ResolvedFilter {
    pub col: Col,
    pub op: FilterOp,
    pub values: Vec<Value>,
}

/// A column of the result.
#[derive(Debug, Clone, PartialEq)]
pub struct OutCol {
    pub name: String,
    pub ty: Ty,
    pub additive: bool,
}

/// A query resolved and compiled.
#[derive(Debug, Clone, PartialEq)]
pub struct Plan {
    pub subject: Subject,
    pub area: Option<Area>,
    pub windows: Vec<Window>,
    pub filters: Vec<ResolvedFilter>,
    pub stages: Vec<ResolvedStage>,
    pub voxel_m: f64,
    pub static_threshold: f64,
    /// The result's columns.
    pub columns: Vec<OutCol>,
    /// Things worth telling the user (printed on stderr), e.g. a date that
    /// matches no session.
    pub notes: Vec<String>,
    /// What the plan does, step by step, for `--explain`.
    pub steps: Vec<String>,
    pub sql: Sql,
}

/// Resolves `q` against the store's catalog and compiles it.
pub fn plan(q: &Query, cat: &Catalog) -> Result<Plan, QueryError> {
    let subject = q.subject.value;
    let sp = spec(subject);
    if let Some(missing) = sp.tables.iter().find(|t| !cat.has_table(t)) {
        return Err(QueryError::new(q.subject.span, format!("this store has no `{missing}` table yet"))
            .label("needs a newer store schema")
            .help("the store was written by an older seam; a command that writes migrates it (`seam check STORE --repair`)"));
    }
    let mut steps = vec![format!("subject: {} — {}", subject.name(), sp.what)];
    let mut notes = Vec::new();
    let area = resolve_area(q, cat, &sp, &mut steps)?;
    let windows = resolve_time(q, cat, subject, &mut steps, &mut notes)?;
    let filters = q.filters.iter().map(|f| resolve_filter(f, subject, &sp)).collect::<Result<Vec<_>, _>>()?;
    for f in &filters {
        steps.push(format!("filter: {} {}", f.col.name, describe_op(f)));
    }
    if subject == Subject::Static {
        steps.push(format!(
            "filter: eps_g < {} (the static threshold, [change] static_threshold)",
            cat.static_threshold
        ));
    }
    let mut cols: Vec<OutCol> =
        sp.columns.iter().map(|c| OutCol { name: c.name.into(), ty: c.ty, additive: c.additive }).collect();
    let (stages, visible) = resolve_stages(&q.stages, &mut cols, sp.order)?;
    for s in &stages {
        steps.push(format!("stage: {}", describe_stage(s)));
    }
    let columns = visible.iter().filter_map(|n| cols.iter().find(|c| &c.name == n).cloned()).collect();
    let mut p = Plan {
        subject,
        area,
        windows,
        filters,
        stages,
        voxel_m: cat.voxel_m,
        static_threshold: cat.static_threshold,
        columns,
        notes,
        steps,
        sql: Sql::default(),
    };
    p.sql = compile(&p);
    Ok(p)
}

fn fmt3(v: [f64; 3]) -> String {
    format!("{}, {}, {}", v[0], v[1], v[2])
}

fn resolve_area(q: &Query, cat: &Catalog, sp: &Spec, steps: &mut Vec<String>) -> Result<Option<Area>, QueryError> {
    let subject = q.subject.value;
    if let Some(r) = &q.radius
        && !matches!(q.region.as_ref().map(|r| &r.value), Some(Region::Near { .. }))
    {
        return Err(QueryError::new(r.span, "`r:` is the radius of `near:`, and this query has no `near:`")
            .label("radius of nothing")
            .help("e.g. `near:12.5,3,1 r:2`"));
    }
    let Some(region) = &q.region else { return Ok(None) };
    if !sp.spatial {
        let spatial: Vec<&str> = Subject::ALL.iter().filter(|s| spec(**s).spatial).map(|s| s.name()).collect();
        return Err(QueryError::new(region.span, format!("`{}` rows have no position", subject.name()))
            .label("a region needs positions")
            .help(format!("regions apply to {}", spatial.join(", "))));
    }
    let index = "tiles from the map_tiles R*Tree meeting the box, then their rows by the `tile` index";
    let area = match &region.value {
        Region::Bbox { min_m, max_m } => {
            for (k, axis) in ["x", "y", "z"].iter().enumerate() {
                if min_m[k] > max_m[k] {
                    return Err(QueryError::new(
                        region.span,
                        format!(
                            "the box is inside out in {axis}: {axis}0 = {} is above {axis}1 = {}",
                            min_m[k], max_m[k]
                        ),
                    )
                    .label("min corner first, then max corner")
                    .help("write `bbox:x0,y0,z0,x1,y1,z1` with x0 ≤ x1, y0 ≤ y1, z0 ≤ z1"));
                }
            }
            steps.push(format!(
                "region: box ({}) to ({}) m — {index}, then the exact box test",
                fmt3(*min_m),
                fmt3(*max_m)
            ));
            Area::Box { min_m: *min_m, max_m: *max_m }
        }
        Region::Near { centre_m } => {
            let Some(r) = &q.radius else {
                return Err(QueryError::new(region.span, "`near:` needs a radius")
                    .label("how near?")
                    .help("add `r:` in metres, e.g. `near:12.5,3,1 r:2`"));
            };
            steps.push(format!(
                "region: ball of radius {} m around ({}) — {index} (the ball's box), then the exact distance test",
                r.value,
                fmt3(*centre_m)
            ));
            Area::Sphere { centre_m: *centre_m, r_m: r.value }
        }
        Region::Zone { name } => {
            let Some(z) = cat.zones.iter().find(|z| z.name == name.value) else {
                let names: Vec<&str> = cat.zones.iter().map(|z| z.name.as_str()).collect();
                let help = if names.is_empty() {
                    "this store has no zones yet; add one with `seam zones add STORE NAME bbox:x0,y0,z0,x1,y1,z1`"
                        .to_string()
                } else {
                    suggest(&name.value, "zones", &names)
                };
                return Err(QueryError::new(name.span, format!("no zone named `{}`", name.value))
                    .label("not a zone of this store")
                    .help(help));
            };
            let b = z.shape.bounds();
            match &z.shape {
                ZoneShape::Box(_) => {
                    steps.push(format!(
                        "region: zone {:?}, box ({}) to ({}) m — {index}, then the exact box test",
                        z.name,
                        fmt3(b.min_m),
                        fmt3(b.max_m)
                    ));
                    Area::Box { min_m: b.min_m, max_m: b.max_m }
                }
                ZoneShape::Polygon { polygon, .. } => {
                    steps.push(format!(
                        "region: zone {:?}, polygon of {} vertices, z {}..{} m — {index} with its bounding box \
                         ({}) to ({}), the exact box test, then the polygon tested in Rust (seam_in_polygon) on each row the box let through",
                        z.name,
                        polygon.rings.iter().map(Vec::len).sum::<usize>(),
                        b.min_m[2],
                        b.max_m[2],
                        fmt3(b.min_m),
                        fmt3(b.max_m)
                    ));
                    Area::Polygon { wkt: polygon.to_wkt(), min_m: b.min_m, max_m: b.max_m }
                }
            }
        }
    };
    Ok(Some(area))
}

/// One end of a time qualifier: a session or a day.
#[derive(Debug, Clone, PartialEq)]
enum Point {
    Id(i64),
    Day(String),
}

fn point(cat: &Catalog, r: &SessionRef) -> Result<Point, QueryError> {
    if let Some(s) = cat.sessions.iter().find(|s| s.name == r.text) {
        return Ok(Point::Id(s.id));
    }
    let number = match r.kind {
        RefKind::Number(n) => Some(n),
        RefKind::Date { y, m, d } => return Ok(Point::Day(format!("{y:04}-{m:02}-{d:02}"))),
        // `s3` names session number 3 when no session is called `s3`.
        RefKind::Name => r
            .text
            .strip_prefix(['s', 'S'])
            .filter(|d| !d.is_empty() && d.len() <= 15 && d.bytes().all(|b| b.is_ascii_digit()))
            .and_then(|d| d.parse::<i64>().ok()),
    };
    if let Some(n) = number {
        if cat.sessions.iter().any(|s| s.id == n) {
            return Ok(Point::Id(n));
        }
        return Err(QueryError::new(r.span, format!("there is no session {}", r.text))
            .label("not in this store")
            .help(cat.session_list()));
    }
    let names: Vec<&str> = cat.sessions.iter().map(|s| s.name.as_str()).collect();
    let help = match did_you_mean(&r.text, names.iter().copied()) {
        Some(m) => format!("did you mean `{m}`?\n{}", cat.session_list()),
        None => cat.session_list(),
    };
    Err(QueryError::new(r.span, format!("no session named `{}`", r.text)).label("not in this store").help(help))
}

fn on_or_after(s: &SessionInfo, p: &Point) -> bool {
    match p {
        Point::Id(id) => s.id >= *id,
        Point::Day(d) => s.date.as_str() >= d.as_str(),
    }
}

fn on_or_before(s: &SessionInfo, p: &Point) -> bool {
    match p {
        Point::Id(id) => s.id <= *id,
        Point::Day(d) => s.date.as_str() <= d.as_str(),
    }
}

fn at(s: &SessionInfo, p: &Point) -> bool {
    match p {
        Point::Id(id) => s.id == *id,
        Point::Day(d) => s.date == *d,
    }
}

fn resolve_time(
    q: &Query,
    cat: &Catalog,
    subject: Subject,
    steps: &mut Vec<String>,
    notes: &mut Vec<String>,
) -> Result<Vec<Window>, QueryError> {
    let is_map = matches!(subject, Subject::Static | Subject::Lifelong);
    let mut out = Vec::new();
    for t in &q.time {
        let pick = |f: &dyn Fn(&SessionInfo) -> bool| -> Vec<i64> {
            cat.sessions.iter().filter(|s| f(s)).map(|s| s.id).collect()
        };
        let (mut ids, present_at, text) = match &t.value {
            Time::Since(r) => {
                let p = point(cat, r)?;
                (pick(&|s| on_or_after(s, &p)), false, format!("since:{}", r.text))
            }
            Time::Between(a, b) => {
                let (pa, pb) = (point(cat, a)?, point(cat, b)?);
                let backwards = match (&pa, &pb) {
                    (Point::Id(x), Point::Id(y)) => x > y,
                    (Point::Day(x), Point::Day(y)) => x > y,
                    _ => false,
                };
                if backwards {
                    return Err(QueryError::new(a.span.to(b.span), format!("`{}` comes after `{}`", a.text, b.text))
                        .label("backwards")
                        .help(format!("write the earlier one first: `between:{}..{}`", b.text, a.text)));
                }
                (
                    pick(&|s| on_or_after(s, &pa) && on_or_before(s, &pb)),
                    false,
                    format!("between:{}..{}", a.text, b.text),
                )
            }
            Time::At(r) => {
                let p = point(cat, r)?;
                (pick(&|s| at(s, &p)), is_map, format!("at:{}", r.text))
            }
            Time::Sessions(refs) => {
                let points = refs.iter().map(|r| point(cat, r)).collect::<Result<Vec<_>, _>>()?;
                let text = refs.iter().map(|r| r.text.as_str()).collect::<Vec<_>>().join(",");
                (pick(&|s| points.iter().any(|p| at(s, p))), false, format!("session:{text}"))
            }
        };
        if present_at && ids.len() > 1 {
            // The map as of a day is the map after that day's last session.
            ids = ids.split_off(ids.len() - 1);
        }
        let names: Vec<String> = ids
            .iter()
            .filter_map(|id| cat.sessions.iter().find(|s| s.id == *id))
            .map(|s| format!("{} ({})", s.id, s.name))
            .collect();
        if ids.is_empty() {
            let span = match (cat.sessions.first(), cat.sessions.last()) {
                (Some(a), Some(b)) => format!(" (sessions run {} to {})", a.date, b.date),
                _ => String::new(),
            };
            notes.push(format!("{text} matches no session{span}, so nothing is returned"));
        }
        let meaning = match (is_map, present_at) {
            (true, true) => "voxels in the map during session",
            (true, false) => "voxels that entered the map in sessions",
            _ => "sessions",
        };
        steps.push(format!(
            "time: {text} → {meaning} {}",
            if names.is_empty() { "(none)".to_string() } else { names.join(", ") }
        ));
        out.push(Window { ids, present_at, text });
    }
    Ok(out)
}

fn resolve_filter(f: &ast::Filter, subject: Subject, sp: &Spec) -> Result<ResolvedFilter, QueryError> {
    let key = f.field.value.to_ascii_lowercase();
    let name = sp.aliases.iter().find(|(a, _)| *a == key).map_or(key.as_str(), |(_, c)| *c);
    let Some(col) = sp.columns.iter().find(|c| c.name == name) else {
        let mut known: Vec<&str> = sp.columns.iter().map(|c| c.name).collect();
        known.extend(sp.aliases.iter().map(|(a, _)| *a));
        let mut all = known.clone();
        all.extend(REGION_KEYS.iter().chain(TIME_KEYS.iter()).copied());
        all.push("r");
        let help = match did_you_mean(&f.field.value, all.iter().copied()) {
            Some(m) => format!("did you mean `{m}:`?\nfields of {}: {}", subject.name(), known.join(", ")),
            None => format!(
                "fields of {}: {}\nregions: bbox:, near: r:, zone:; time: since:, between:, at:, session:",
                subject.name(),
                known.join(", ")
            ),
        };
        return Err(QueryError::new(
            f.field.span,
            format!("`{}` is not a field of `{}`", f.field.value, subject.name()),
        )
        .label("unknown field")
        .help(help));
    };
    let col = *col;
    let (op, lits): (FilterOp, Vec<&ast::Spanned<Lit>>) = match &f.cond {
        Cond::Cmp(op, l) => (FilterOp::Cmp(*op), vec![l]),
        Cond::AnyOf(v) => (FilterOp::In, v.iter().collect()),
        Cond::Range(a, b) => (FilterOp::Range, vec![a, b]),
    };
    let eq_only = |what: &str| -> Result<(), QueryError> {
        match op {
            FilterOp::Cmp(CmpOp::Eq | CmpOp::Ne) | FilterOp::In => Ok(()),
            _ => Err(QueryError::new(
                f.span,
                format!("`{}` is {what}: it compares only with `:` (equal), `:!=` or a list", col.name),
            )
            .label("no order here")),
        }
    };
    let mut values = Vec::new();
    match col.ty {
        Ty::Int | Ty::Real => {
            for l in &lits {
                match &l.value {
                    Lit::Number(v) if col.ty == Ty::Int && v.fract() == 0.0 && v.abs() < 9.0e15 => {
                        values.push(Value::Integer(*v as i64))
                    }
                    Lit::Number(v) if col.f32 => values.push(Value::Real(*v as f32 as f64)),
                    Lit::Number(v) => values.push(Value::Real(*v)),
                    Lit::Text(t) => {
                        return Err(QueryError::new(l.span, format!("`{}` is a number, not `{t}`", col.name))
                            .label("expected a number")
                            .help(format!("e.g. `{}:>0.5`, `{}:0.2..0.4`", key, key)));
                    }
                }
            }
            if op == FilterOp::Range && num(&values[0]) > num(&values[1]) {
                return Err(QueryError::new(lits[0].span.to(lits[1].span), "the range is backwards")
                    .label("low end first")
                    .help(format!("write `{key}:LOW..HIGH`")));
            }
        }
        Ty::Text => {
            for l in &lits {
                values.push(Value::Text(match &l.value {
                    Lit::Number(v) => format!("{v}"),
                    Lit::Text(t) => t.clone(),
                }));
            }
        }
        Ty::Bool => {
            eq_only("true or false")?;
            for l in &lits {
                let b = match &l.value {
                    Lit::Text(t) if ["true", "yes"].contains(&t.to_ascii_lowercase().as_str()) => 1,
                    Lit::Text(t) if ["false", "no"].contains(&t.to_ascii_lowercase().as_str()) => 0,
                    Lit::Number(v) if *v == 1.0 => 1,
                    Lit::Number(v) if *v == 0.0 => 0,
                    _ => {
                        return Err(QueryError::new(l.span, format!("`{}` is true or false", col.name))
                            .label("expected true or false")
                            .help(format!("e.g. `{key}:false`")));
                    }
                };
                values.push(Value::Integer(b));
            }
        }
        Ty::Category => {
            eq_only("a category")?;
            let known: &[&str] = if matches!(subject, Subject::Changes) { &EVENT_CATEGORIES } else { &MAP_CATEGORIES };
            for l in &lits {
                let t = match &l.value {
                    Lit::Text(t) => t.to_ascii_lowercase(),
                    Lit::Number(v) => format!("{v}"),
                };
                let expanded: Vec<&str> = match t.as_str() {
                    "emerged" | "deleted" => known.iter().filter(|c| c.starts_with(t.as_str())).copied().collect(),
                    _ => known.iter().filter(|c| **c == t).copied().collect(),
                };
                if expanded.is_empty() {
                    let mut names = vec!["emerged", "deleted"];
                    names.extend(known.iter().copied());
                    return Err(QueryError::new(
                        l.span,
                        format!("`{t}` is not a change category of {}", subject.name()),
                    )
                    .label("unknown category")
                    .help(suggest(
                        &t,
                        "categories (`emerged` and `deleted` mean both kinds)",
                        &names,
                    )));
                }
                for c in expanded {
                    if !values.iter().any(|v| v == &Value::Text(c.to_string())) {
                        values.push(Value::Text(c.to_string()));
                    }
                }
            }
            let op = if op == FilterOp::Cmp(CmpOp::Ne) { FilterOp::NotIn } else { FilterOp::In };
            return Ok(ResolvedFilter { col, op, values });
        }
    }
    Ok(ResolvedFilter { col, op, values })
}

fn num(v: &Value) -> f64 {
    match v {
        Value::Integer(i) => *i as f64,
        Value::Real(r) => *r,
        _ => 0.0,
    }
}

fn describe_op(f: &ResolvedFilter) -> String {
    let n = f.values.len();
    match f.op {
        FilterOp::Cmp(op) => format!("{} ?", op.sql()),
        FilterOp::In => format!("IN ({} values)", n),
        FilterOp::NotIn => format!("NOT IN ({} values)", n),
        FilterOp::Range => "BETWEEN ? AND ?".into(),
    }
}
