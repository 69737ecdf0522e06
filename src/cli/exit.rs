//! The one place where errors become exit codes.

use crate::config::ConfigError;
use crate::io::ReadError;
use crate::pipeline::IngestError;
use crate::sim::SimError;
use crate::store::StoreError;

/// Process exit codes, as DESIGN.md lists them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum ExitKind {
    Ok = 0,
    Internal = 1,
    Usage = 2,
    Query = 3,
    Data = 4,
    Busy = 5,
}

fn store_kind(e: &StoreError) -> ExitKind {
    match e {
        StoreError::Busy { .. } => ExitKind::Busy,
        StoreError::NotAStore { .. }
        | StoreError::AlreadyExists { .. }
        | StoreError::NewerSchema { .. }
        | StoreError::NotSeamDb { .. }
        | StoreError::Corrupt { .. } => ExitKind::Data,
        StoreError::Io { .. } | StoreError::Sql { .. } | StoreError::Parquet { .. } => ExitKind::Internal,
    }
}

/// The exit code for an error, by the first typed error in its chain.
pub fn exit_kind(err: &anyhow::Error) -> ExitKind {
    for cause in err.chain() {
        if let Some(e) = cause.downcast_ref::<IngestError>() {
            return match e {
                IngestError::Store(s) => store_kind(s),
                IngestError::Read(_) | IngestError::NameTaken { .. } => ExitKind::Data,
                IngestError::ConfigChanged { .. } => ExitKind::Usage,
            };
        }
        if let Some(e) = cause.downcast_ref::<StoreError>() {
            return store_kind(e);
        }
        if cause.downcast_ref::<ReadError>().is_some() {
            return ExitKind::Data;
        }
        if cause.downcast_ref::<ConfigError>().is_some() {
            return ExitKind::Usage;
        }
        if let Some(e) = cause.downcast_ref::<SimError>() {
            return match e {
                SimError::Config(_) => ExitKind::Usage,
                _ => ExitKind::Internal,
            };
        }
        if let Some(e) = cause.downcast_ref::<crate::eval::EvalError>() {
            return match e {
                crate::eval::EvalError::Store(s) => store_kind(s),
                crate::eval::EvalError::Truth(_) | crate::eval::EvalError::Mismatch(_) => ExitKind::Data,
                crate::eval::EvalError::Solve(_) => ExitKind::Internal,
            };
        }
        if cause.downcast_ref::<crate::query::Report>().is_some()
            || cause.downcast_ref::<crate::query::QueryError>().is_some()
        {
            return ExitKind::Query;
        }
        if let Some(e) = cause.downcast_ref::<crate::render::RenderError>() {
            use crate::render::RenderError as R;
            return match e {
                R::Store(s) => store_kind(s),
                R::NoSuchSession { .. } => ExitKind::Data,
                R::Usage(_) => ExitKind::Usage,
                R::Io { .. } | R::Encode(_) => ExitKind::Internal,
            };
        }
        if cause.downcast_ref::<super::UsageError>().is_some() {
            return ExitKind::Usage;
        }
    }
    ExitKind::Internal
}
