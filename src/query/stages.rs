//! Pipeline stages checked in order against the columns each one leaves:
//! `count [by]`, `top`, `sort`, `fields`, `limit`, `sum`. Unknown and
//! dropped fields get help naming what is there.

use super::ast::{self, Stage};
use super::error::{QueryError, suggest};
use super::plan::OutCol;
use super::subjects::Ty;

/// A pipeline stage with its fields checked; `top` is an order plus a limit.
#[derive(Debug, Clone, PartialEq)]
pub enum ResolvedStage {
    /// `name` is `count`, or another name when a field grouped by has it.
    Count {
        by: Vec<String>,
        name: String,
    },
    /// The whole order from here on (ties broken by the previous order).
    Order(Vec<(String, bool)>),
    Limit(u64),
    Fields(Vec<String>),
    Sum(Vec<String>),
}

/// Finds a field of the current relation; dropped and unknown fields get
/// help naming what is there.
fn field<'a>(
    f: &ast::Spanned<String>,
    cols: &'a [OutCol],
    visible: &[String],
    stage: &str,
) -> Result<&'a OutCol, QueryError> {
    let name = f.value.to_ascii_lowercase();
    if visible.contains(&name)
        && let Some(c) = cols.iter().find(|c| c.name == name)
    {
        return Ok(c);
    }
    let names: Vec<&str> = visible.iter().map(String::as_str).collect();
    if cols.iter().any(|c| c.name == name) {
        return Err(QueryError::new(f.span, format!("`{}` was left out by an earlier `| fields`", f.value))
            .label("dropped")
            .help(format!("fields left here: {}", names.join(", "))));
    }
    Err(QueryError::new(f.span, format!("`{}` has no field `{}` here", stage, f.value))
        .label("unknown field")
        .help(suggest(&f.value, "fields here", &names)))
}

/// Checks the stages in order against the columns each one leaves, and
/// returns them with the visible columns at the end.
pub fn resolve_stages(
    stages: &[ast::Spanned<Stage>],
    cols: &mut Vec<OutCol>,
    base_order: &str,
) -> Result<(Vec<ResolvedStage>, Vec<String>), QueryError> {
    let mut out = Vec::new();
    let mut visible: Vec<String> = cols.iter().map(|c| c.name.clone()).collect();
    let mut order: Vec<(String, bool)> = vec![(base_order.to_string(), false)];
    let reorder = |order: &Vec<(String, bool)>, by: &str, desc: bool| {
        let mut o = vec![(by.to_string(), desc)];
        o.extend(order.iter().filter(|(n, _)| n != by).cloned());
        o
    };
    for st in stages {
        match &st.value {
            Stage::Count { by } => {
                let mut names: Vec<String> = Vec::new();
                let mut new_cols = Vec::new();
                for f in by {
                    let c = field(f, cols, &visible, "count by")?;
                    if names.contains(&c.name) {
                        return Err(QueryError::new(f.span, format!("`{}` is named twice", c.name)).label("again"));
                    }
                    names.push(c.name.clone());
                    new_cols.push(OutCol { additive: false, ..c.clone() });
                    // A session number alone is hard to read: its name comes along.
                    let with_name =
                        c.name == "session" && !by.iter().any(|b| b.value.eq_ignore_ascii_case("session_name"));
                    if with_name
                        && visible.iter().any(|v| v == "session_name")
                        && let Some(n) = cols.iter().find(|c| c.name == "session_name")
                    {
                        names.push(n.name.clone());
                        new_cols.push(n.clone());
                    }
                }
                let name =
                    ["count", "rows", "groups"].into_iter().find(|n| !names.iter().any(|b| b == n)).unwrap_or("n");
                new_cols.push(OutCol { name: name.into(), ty: Ty::Int, additive: true });
                order = names.iter().map(|n| (n.clone(), false)).collect();
                out.push(ResolvedStage::Count { by: names, name: name.into() });
                *cols = new_cols;
                visible = cols.iter().map(|c| c.name.clone()).collect();
            }
            Stage::Top { n, by } => {
                let c = field(by, cols, &visible, "top")?.name.clone();
                order = reorder(&order, &c, true);
                out.push(ResolvedStage::Order(order.clone()));
                out.push(ResolvedStage::Limit(n.value));
            }
            Stage::Sort { by, descending } => {
                let c = field(by, cols, &visible, "sort")?.name.clone();
                order = reorder(&order, &c, *descending);
                out.push(ResolvedStage::Order(order.clone()));
            }
            Stage::Fields(list) => {
                let mut names: Vec<String> = Vec::new();
                for f in list {
                    let c = field(f, cols, &visible, "fields")?;
                    if names.contains(&c.name) {
                        return Err(QueryError::new(f.span, format!("`{}` is named twice", c.name)).label("again"));
                    }
                    names.push(c.name.clone());
                }
                visible = names.clone();
                out.push(ResolvedStage::Fields(names));
            }
            Stage::Limit(n) => out.push(ResolvedStage::Limit(n.value)),
            Stage::Sum => {
                let add: Vec<OutCol> = cols
                    .iter()
                    .filter(|c| c.additive && c.ty.is_numeric() && visible.contains(&c.name))
                    .cloned()
                    .collect();
                if add.is_empty() {
                    return Err(QueryError::new(st.span, "nothing here adds up")
                        .label("no column to sum")
                        .help(format!("`sum` adds counts and volumes; fields here: {}", visible.join(", "))));
                }
                out.push(ResolvedStage::Sum(add.iter().map(|c| c.name.clone()).collect()));
                *cols = add;
                visible = cols.iter().map(|c| c.name.clone()).collect();
                order = Vec::new();
            }
        }
    }
    Ok((out, visible))
}

pub fn describe_stage(s: &ResolvedStage) -> String {
    match s {
        ResolvedStage::Count { by, .. } if by.is_empty() => "count rows".into(),
        ResolvedStage::Count { by, .. } => format!("count rows by {}", by.join(", ")),
        ResolvedStage::Order(o) => format!(
            "order by {}",
            o.iter().map(|(n, d)| format!("{n}{}", if *d { " desc" } else { "" })).collect::<Vec<_>>().join(", ")
        ),
        ResolvedStage::Limit(n) => format!("keep the first {n} rows"),
        ResolvedStage::Fields(f) => format!("keep fields {}", f.join(", ")),
        ResolvedStage::Sum(c) => format!("add up {}", c.join(", ")),
    }
}
