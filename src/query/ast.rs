//! The typed syntax tree: what the parser read, every part with its span.
//! Names are not resolved here (sessions, zones and fields are checked
//! against the store by `plan`).

use super::error::Span;
use super::lexer::CmpOp;

/// A value with the span it was read from.
#[derive(Debug, Clone, PartialEq)]
pub struct Spanned<T> {
    pub value: T,
    pub span: Span,
}

impl<T> Spanned<T> {
    pub fn new(value: T, span: Span) -> Spanned<T> {
        Spanned { value, span }
    }
}

/// What a query asks about.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Subject {
    /// Change events: one row per voxel a session saw change.
    Changes,
    /// Map voxels with ε_g below the static threshold.
    Static,
    /// Every map voxel.
    Lifelong,
    /// One row per session: what happened in the region in that session.
    History,
    /// The sessions table.
    Sessions,
    /// Loop candidates, accepted or not, with why.
    Loops,
    /// m³ emerged and deleted per session.
    Volume,
    /// How much of the region's map each session saw.
    Coverage,
}

impl Subject {
    pub const ALL: [Subject; 8] = [
        Subject::Changes,
        Subject::Static,
        Subject::Lifelong,
        Subject::History,
        Subject::Sessions,
        Subject::Loops,
        Subject::Volume,
        Subject::Coverage,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Subject::Changes => "changes",
            Subject::Static => "static",
            Subject::Lifelong => "lifelong",
            Subject::History => "history",
            Subject::Sessions => "sessions",
            Subject::Loops => "loops",
            Subject::Volume => "volume",
            Subject::Coverage => "coverage",
        }
    }

    pub fn parse(word: &str) -> Option<Subject> {
        Subject::ALL.into_iter().find(|s| s.name().eq_ignore_ascii_case(word))
    }
}

#[derive(Debug, Clone, PartialEq)]
pub struct Query {
    pub subject: Spanned<Subject>,
    pub region: Option<Spanned<Region>>,
    /// `r:`, the radius of `near:` (kept apart: it may come first).
    pub radius: Option<Spanned<f64>>,
    pub time: Vec<Spanned<Time>>,
    pub filters: Vec<Filter>,
    pub stages: Vec<Spanned<Stage>>,
}

#[derive(Debug, Clone, PartialEq)]
pub enum Region {
    /// `bbox:x0,y0,z0,x1,y1,z1`, world frame metres.
    Bbox { min_m: [f64; 3], max_m: [f64; 3] },
    /// `near:x,y,z` (the radius is `r:`).
    Near { centre_m: [f64; 3] },
    /// `zone:NAME` or `zone:"NAME"`.
    Zone { name: Spanned<String> },
}

/// A reference to one session as typed: a name, a number or a date.
#[derive(Debug, Clone, PartialEq)]
pub struct SessionRef {
    /// As written (a name is looked up first whatever it looks like).
    pub text: String,
    pub kind: RefKind,
    pub span: Span,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RefKind {
    /// `s3`, `north-walk`, `"survey 3"`.
    Name,
    /// `3`: the session's number (ingest order).
    Number(i64),
    /// `2026-01-01`.
    Date { y: i32, m: u32, d: u32 },
}

#[derive(Debug, Clone, PartialEq)]
pub enum Time {
    /// `since:X`: X and every later session.
    Since(SessionRef),
    /// `between:A..B`, both ends included.
    Between(SessionRef, SessionRef),
    /// `at:X`: as of session X.
    At(SessionRef),
    /// `session:X[,Y...]`: exactly these sessions.
    Sessions(Vec<SessionRef>),
}

/// A literal value in a filter.
#[derive(Debug, Clone, PartialEq)]
pub enum Lit {
    Number(f64),
    /// A word or a quoted string.
    Text(String),
}

/// `field:value`, `field:>value`, `field:a,b,c`, `field:lo..hi`.
#[derive(Debug, Clone, PartialEq)]
pub struct Filter {
    pub field: Spanned<String>,
    pub cond: Cond,
    /// The whole `field:...` clause.
    pub span: Span,
}

#[derive(Debug, Clone, PartialEq)]
pub enum Cond {
    Cmp(CmpOp, Spanned<Lit>),
    /// Any of these (`class:emerged,deleted`).
    AnyOf(Vec<Spanned<Lit>>),
    /// `lo..hi`, both included.
    Range(Spanned<Lit>, Spanned<Lit>),
}

#[derive(Debug, Clone, PartialEq)]
pub enum Stage {
    /// `count` or `count by f[,g]`.
    Count { by: Vec<Spanned<String>> },
    /// `top N by f`: the N rows with the largest f.
    Top { n: Spanned<u64>, by: Spanned<String> },
    /// `sort f [asc|desc]`.
    Sort { by: Spanned<String>, descending: bool },
    /// `fields a,b,c`.
    Fields(Vec<Spanned<String>>),
    /// `limit N`.
    Limit(Spanned<u64>),
    /// `sum`: one row adding up the columns that add up.
    Sum,
}

impl Stage {
    pub const NAMES: [&'static str; 6] = ["count", "top", "sort", "fields", "limit", "sum"];
}
