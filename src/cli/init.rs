//! `seam init site.seam [--crs EPSG:32652 | --local] [--voxel 0.2] [--name NAME]`

use super::output::{json, log, print_json};
use super::{Ctx, UsageError};
use crate::store::{InitOptions, Store};
use clap::Args;
use std::path::PathBuf;

#[derive(Debug, Args)]
pub struct InitArgs {
    /// The store folder to create (must not exist, or be empty).
    pub store: PathBuf,
    /// Coordinate reference system of the world frame, e.g. EPSG:32652.
    #[arg(long, conflicts_with = "local")]
    pub crs: Option<String>,
    /// The world frame is a local engineering frame (the default).
    #[arg(long)]
    pub local: bool,
    /// Map voxel size in metres.
    #[arg(long, default_value_t = 0.2)]
    pub voxel: f64,
    /// Site name (default: the folder name without extension).
    #[arg(long)]
    pub name: Option<String>,
}

pub fn run(ctx: &Ctx, a: InitArgs, config_given: bool) -> anyhow::Result<()> {
    if !(a.voxel.is_finite() && a.voxel > 0.0 && a.voxel <= 10.0) {
        return Err(UsageError(format!("--voxel {} must be a size in metres in (0, 10]", a.voxel)).into());
    }
    let crs = match a.crs {
        Some(c) if c.to_ascii_uppercase().starts_with("EPSG:") && c[5..].parse::<u32>().is_ok() => {
            c.to_ascii_uppercase()
        }
        Some(c) => {
            return Err(UsageError(format!("--crs {c:?} is not of the form EPSG:<code>, e.g. EPSG:32652")).into());
        }
        None => "local".to_string(),
    };
    let site_name = a.name.unwrap_or_else(|| {
        a.store.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "site".into())
    });
    let store = Store::create(&a.store, &InitOptions { site_name, crs, voxel_size_m: a.voxel })?;
    if config_given {
        // Later commands on the store run with it; the first ingest binds it.
        store.record_config(&ctx.config.to_recorded())?;
    }
    let meta = store.meta()?;
    if json(ctx) {
        print_json(&serde_json::json!({ "store": a.store, "meta": meta }))?;
    } else {
        log(
            ctx,
            format!(
                "created {} (site {:?}, crs {}, voxel {} m)",
                a.store.display(),
                meta.site_name,
                meta.crs,
                meta.voxel_size_m
            ),
        );
    }
    Ok(())
}
