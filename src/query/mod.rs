//! The query language: what site managers type to ask a store questions.
//!
//! ```text
//! changes in zone:"Tower B" since:s3
//! changes in bbox:10,20,0,40,60,5 between:s3..s5 class:emerged,deleted
//! changes near:12.5,3,1 r:2 | count by session
//! static in bbox:0,0,-2,50,50,10 | count
//! history near:12.5,3,1 r:0.5          # one spot through every session
//! sessions since:2026-01-01
//! loops session:s4 accepted:false      # why did s4 not merge?
//! volume in zone:stockpile since:s2    # m³ emerged / deleted
//! ```
//!
//! # Grammar
//!
//! ```text
//! query    = subject clause* ( "|" stage )*
//! subject  = changes | static | lifelong | history | sessions | loops | volume | coverage
//! clause   = "in"? region | "r:" NUMBER | time | filter
//! region   = "bbox:" x0,y0,z0,x1,y1,z1          world frame (`seam poses`), metres
//!          | "near:" x,y,z   (with "r:" R)       a ball of radius R
//!          | "zone:" NAME | "zone:" "QUOTED"     a zone stored with `seam zones add`
//! time     = "since:" ref | "between:" ref ".." ref | "at:" ref | "session:" ref ("," ref)*
//! ref      = NAME (`s3`) | NUMBER (`3`, ingest order) | DATE (`2026-01-01`)
//! filter   = FIELD ":" [ "<" | "<=" | ">" | ">=" | "=" | "!=" ] value
//!          | FIELD ":" value ("," value)+         any of
//!          | FIELD ":" value ".." value           both ends included
//! stage    = "count" [ "by" FIELD ("," FIELD)* ] | "top" N "by" FIELD | "sort" FIELD [ "asc" | "desc" ]
//!          | "fields" FIELD ("," FIELD)* | "limit" N | "sum"
//! ```
//!
//! Keywords are case-insensitive; `in` is optional noise; `#` starts a
//! comment. `class:` is the change category (`emerged` and `deleted` mean
//! both kinds of each), `eps:` is ε_g (after the change, for `changes`;
//! compared at the `f32` precision it is stored in). A
//! name `sN` that is no session's name means session number N. What each
//! subject returns is in [`subjects`]; what time means for each in [`plan`].
//!
//! # Stages
//!
//! [`lexer`] (tokens with byte spans) → [`parser`] (→ [`ast`]) → [`plan`]
//! (names resolved against the store's [`catalog`]; did-you-mean on every
//! unknown name; [`stages`] for the pipeline) → [`sql`] (one statement, `?` placeholders, values as
//! parameters, never spliced) → [`exec`] (run on a read-only connection,
//! polygons tested in Rust through `seam_in_polygon`). Errors are
//! [`QueryError`]s with a span, rendered like rustc's ([`error`]).
//!
//! Not here: printing and files (the `seam query` command), zones' storage
//! (`store::zones`).

pub mod ast;
pub mod catalog;
pub mod error;
pub mod exec;
pub mod lexer;
pub mod parser;
pub mod plan;
pub mod sql;
pub mod stages;
pub mod subjects;

pub use catalog::{Catalog, SessionInfo};
pub use error::{QueryError, Report, Span};
pub use exec::{QueryResult, execute, sqlite_plan};
pub use parser::parse;
pub use plan::Plan;

/// Parses and plans `src` against a store's catalog.
pub fn compile(src: &str, catalog: &Catalog) -> Result<Plan, QueryError> {
    plan::plan(&parse(src)?, catalog)
}

/// The `--explain` text: what the plan does, the SQL with its placeholders,
/// the parameters apart, and SQLite's own plan when a connection is given.
pub fn explain(plan: &Plan, sqlite: Option<&[String]>) -> String {
    let mut out = String::from("plan:\n");
    for s in &plan.steps {
        out.push_str(&format!("  {s}\n"));
    }
    out.push_str("sql:\n");
    out.push_str(&format!("  {}\n", plan.sql.text));
    out.push_str("parameters:\n");
    for (i, v) in plan.sql.params.iter().enumerate() {
        let v = match v {
            rusqlite::types::Value::Null => "NULL".to_string(),
            rusqlite::types::Value::Integer(i) => i.to_string(),
            rusqlite::types::Value::Real(r) => format!("{r:?}"),
            rusqlite::types::Value::Text(t) => format!("{t:?}"),
            rusqlite::types::Value::Blob(b) => format!("<{} bytes>", b.len()),
        };
        out.push_str(&format!("  ?{} = {v}\n", i + 1));
    }
    if let Some(lines) = sqlite {
        out.push_str("sqlite plan:\n");
        for l in lines {
            out.push_str(&format!("  {l}\n"));
        }
    }
    for n in &plan.notes {
        out.push_str(&format!("note: {n}\n"));
    }
    out
}
