//! What each subject returns: its columns, their SQL over the store's
//! tables, their types, and which qualifiers it takes.
//!
//! Column names are snake_case with units (`x_m`, `volume_m3`, `area_m2`);
//! `session` is the session's number. These names are the only identifiers
//! that ever reach SQL text; values typed by the user are always parameters.

use super::ast::Subject;

/// A column's type, for filters, output and Parquet.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ty {
    Int,
    Real,
    Text,
    /// Stored 0/1, shown true/false.
    Bool,
    /// A change category (`class:` takes these and the short forms).
    Category,
}

impl Ty {
    pub fn is_numeric(self) -> bool {
        matches!(self, Ty::Int | Ty::Real)
    }
}

/// A column of a subject.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Col {
    pub name: &'static str,
    /// Its SQL over the subject's `FROM` (row subjects), or over the
    /// subject's own result (aggregate subjects, which filter on it from
    /// outside).
    pub expr: &'static str,
    pub ty: Ty,
    /// Adding it up over rows means something (`| sum`).
    pub additive: bool,
    /// Stored from an `f32` (ε): a value typed in a filter is rounded to
    /// `f32` too, so `eps:>=0.7` matches a stored 0.7.
    pub f32: bool,
}

const fn col(name: &'static str, expr: &'static str, ty: Ty) -> Col {
    Col { name, expr, ty, additive: false, f32: false }
}

const fn sum(name: &'static str, expr: &'static str, ty: Ty) -> Col {
    Col { name, expr, ty, additive: true, f32: false }
}

const fn eps(name: &'static str, expr: &'static str) -> Col {
    Col { name, expr, ty: Ty::Real, additive: false, f32: true }
}

/// A session's day: its `session.toml` date, else the day it was ingested.
pub const SESSION_DATE: &str = "coalesce(substr(s.date, 1, 10), substr(s.created_at, 1, 10))";

pub const CHANGES: &[Col] = &[
    col("event_id", "e.event_id", Ty::Int),
    col("session", "e.session_id", Ty::Int),
    col("session_name", "s.name", Ty::Text),
    col("category", "e.category", Ty::Category),
    col("x_m", "e.x_m", Ty::Real),
    col("y_m", "e.y_m", Ty::Real),
    col("z_m", "e.z_m", Ty::Real),
    eps("eps_g_before", "e.eps_g_before"),
    eps("eps_g_after", "e.eps_g_after"),
    col("voxel_id", "e.voxel_id", Ty::Int),
];

pub const MAP: &[Col] = &[
    col("voxel_id", "v.voxel_id", Ty::Int),
    col("x_m", "v.x_m", Ty::Real),
    col("y_m", "v.y_m", Ty::Real),
    col("z_m", "v.z_m", Ty::Real),
    eps("eps_g", "v.eps_g"),
    eps("eps_l", "v.eps_l"),
    col("points", "v.points", Ty::Int),
    col("category", "v.category", Ty::Category),
    col("first_session", "v.first_session", Ty::Int),
    col("last_seen_session", "v.last_seen_session", Ty::Int),
    col("category_session", "v.category_session", Ty::Int),
];

pub const SESSIONS: &[Col] = &[
    col("session", "s.session_id", Ty::Int),
    col("name", "s.name", Ty::Text),
    col("date", SESSION_DATE, Ty::Text),
    col("sensor", "s.sensor_model", Ty::Text),
    sum("keyframes", "s.keyframe_count", Ty::Int),
    sum("points", "s.point_count", Ty::Int),
    col("status", "s.status", Ty::Text),
    col("alignment", "a.method", Ty::Text),
    col("verdict", "a.verdict", Ty::Text),
    sum("change_events", "c.events", Ty::Int),
    col("static_voxels", "c.static_voxels", Ty::Int),
    col("created_at", "s.created_at", Ty::Text),
];

pub const LOOPS: &[Col] = &[
    col("candidate", "l.candidate_id", Ty::Int),
    col("session", "l.session_id", Ty::Int),
    col("session_name", "s.name", Ty::Text),
    col("kind", "l.kind", Ty::Text),
    col("source_session", "ks.session_id", Ty::Int),
    col("source_keyframe", "ks.keyframe_index", Ty::Int),
    col("target_session", "kt.session_id", Ty::Int),
    col("target_keyframe", "kt.keyframe_index", Ty::Int),
    col("distance_m", "l.distance_m", Ty::Real),
    col("accepted", "l.accepted", Ty::Bool),
    col("converged", "l.converged", Ty::Bool),
    col("inliers", "l.inliers", Ty::Int),
    col("inlier_ratio", "l.inlier_ratio", Ty::Real),
    col("fitness", "l.fitness", Ty::Real),
    col("rho_scan", "l.rho_scan", Ty::Real),
    col("rho_corr", "l.rho_corr", Ty::Real),
    col("reason", "l.reason", Ty::Text),
];

pub const HISTORY: &[Col] = &[
    col("session", "s.session_id", Ty::Int),
    col("session_name", "s.name", Ty::Text),
    col("date", SESSION_DATE, Ty::Text),
    sum("events", "coalesce(ev.events, 0)", Ty::Int),
    sum("emerged_voxels", "coalesce(ev.emerged, 0)", Ty::Int),
    sum("deleted_voxels", "coalesce(ev.deleted, 0)", Ty::Int),
    sum("out_of_view_voxels", "coalesce(ev.out_of_view, 0)", Ty::Int),
    sum("returned_voxels", "coalesce(ev.returned, 0)", Ty::Int),
    sum("first_seen_voxels", "coalesce(fv.n, 0)", Ty::Int),
    col("last_seen_voxels", "coalesce(lv.n, 0)", Ty::Int),
];

/// `?` is the volume of one voxel, m³.
pub const VOLUME: &[Col] = &[
    col("session", "s.session_id", Ty::Int),
    col("session_name", "s.name", Ty::Text),
    col("date", SESSION_DATE, Ty::Text),
    sum("emerged_voxels", "coalesce(ev.emerged, 0)", Ty::Int),
    sum("deleted_voxels", "coalesce(ev.deleted, 0)", Ty::Int),
    sum("emerged_m3", "coalesce(ev.emerged, 0) * ?", Ty::Real),
    sum("deleted_m3", "coalesce(ev.deleted, 0) * ?", Ty::Real),
    sum("net_m3", "(coalesce(ev.emerged, 0) - coalesce(ev.deleted, 0)) * ?", Ty::Real),
];

/// `?` in `area_m2` is one voxel's footprint (m²), in `volume_m3` its volume.
pub const COVERAGE: &[Col] = &[
    col("session", "s.session_id", Ty::Int),
    col("session_name", "s.name", Ty::Text),
    col("date", SESSION_DATE, Ty::Text),
    col("voxels", "coalesce(cv.voxels, 0)", Ty::Int),
    col("area_m2", "coalesce(cv.cells, 0) * ?", Ty::Real),
    col("volume_m3", "coalesce(cv.voxels, 0) * ?", Ty::Real),
    col("share", "CASE WHEN tot.n > 0 THEN coalesce(cv.voxels, 0) * 1.0 / tot.n END", Ty::Real),
];

/// The change categories a change event can have.
pub const EVENT_CATEGORIES: [&str; 5] =
    ["coexist", "deleted_overlap", "deleted_non_overlap", "emerged_overlap", "emerged_non_overlap"];
/// A map voxel's category may also be `initial` (first session's voxels).
pub const MAP_CATEGORIES: [&str; 6] =
    ["initial", "coexist", "deleted_overlap", "deleted_non_overlap", "emerged_overlap", "emerged_non_overlap"];

/// What a subject is built from and what it takes.
#[derive(Debug, Clone, Copy)]
pub struct Spec {
    pub columns: &'static [Col],
    /// One row per stored row (filters go into its `WHERE`), or one row per
    /// session computed from others (filters apply to its result).
    pub aggregate: bool,
    /// Takes a region (the rows have a position).
    pub spatial: bool,
    /// The column rows are ordered by when nothing else is asked.
    pub order: &'static str,
    /// Tables it reads, to tell an older store it needs migrating.
    pub tables: &'static [&'static str],
    /// Other names for columns in `key:value` filters.
    pub aliases: &'static [(&'static str, &'static str)],
    /// One line for `--explain`.
    pub what: &'static str,
}

pub fn spec(s: Subject) -> Spec {
    let map_aliases: &[(&str, &str)] = &[("class", "category"), ("eps", "eps_g")];
    match s {
        Subject::Changes => Spec {
            columns: CHANGES,
            aggregate: false,
            spatial: true,
            order: "event_id",
            tables: &["change_events", "map_tiles"],
            aliases: &[("class", "category"), ("eps", "eps_g_after"), ("eps_g", "eps_g_after")],
            what: "change events (change_events joined with sessions), one row per voxel a session saw change",
        },
        Subject::Static => Spec {
            columns: MAP,
            aggregate: false,
            spatial: true,
            order: "voxel_id",
            tables: &["map_voxels", "map_tiles"],
            aliases: map_aliases,
            what: "the static map: map_voxels with eps_g below the static threshold",
        },
        Subject::Lifelong => Spec {
            columns: MAP,
            aggregate: false,
            spatial: true,
            order: "voxel_id",
            tables: &["map_voxels", "map_tiles"],
            aliases: map_aliases,
            what: "the lifelong map: every map voxel",
        },
        Subject::History => Spec {
            columns: HISTORY,
            aggregate: true,
            spatial: true,
            order: "session",
            tables: &["change_events", "map_voxels", "map_tiles"],
            aliases: &[],
            what: "one row per session: its change events in the region by kind, and the region's map voxels it first and last saw",
        },
        Subject::Sessions => Spec {
            columns: SESSIONS,
            aggregate: false,
            spatial: false,
            order: "session",
            tables: &["sessions", "session_alignment", "session_changes"],
            aliases: &[("sensor_model", "sensor"), ("session_name", "name")],
            what: "sessions with their alignment and change summary",
        },
        Subject::Loops => Spec {
            columns: LOOPS,
            aggregate: false,
            spatial: false,
            order: "candidate",
            tables: &["loop_candidates"],
            aliases: &[("rho", "rho_scan")],
            what: "loop candidates, accepted or not, with the DOP test's ρ and the reason; `session` is the ingest that evaluated them",
        },
        Subject::Volume => Spec {
            columns: VOLUME,
            aggregate: true,
            spatial: true,
            order: "session",
            tables: &["change_events", "map_tiles"],
            aliases: &[],
            what: "per session: emerged voxels (both emerged categories) and deleted voxels (deleted_overlap: the session saw the space empty) × voxel volume",
        },
        Subject::Coverage => Spec {
            columns: COVERAGE,
            aggregate: true,
            spatial: true,
            order: "session",
            tables: &["map_voxels", "map_tiles"],
            aliases: &[],
            what: "per session: the region's map voxels in the map during that session (first seen at or before it, last seen at or after it), their footprint and volume, and their share of the region's map",
        },
    }
}
