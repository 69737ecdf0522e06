//! `seam zones add|list|rm`: named zones that queries use as `zone:NAME`.
//!
//! ```text
//! seam zones add site.seam "Tower B" bbox:10,20,0,40,60,30
//! seam zones add site.seam stockpile --wkt 'POLYGON((0 0, 12 0, 14 9, 2 11))' --z -1..8
//! seam zones list site.seam
//! seam zones rm site.seam stockpile
//! ```
//!
//! Coordinates are the world frame of `seam poses`, metres. Adding and
//! removing take the writer lock (and migrate an older store); listing is
//! read-only.

use super::output::{json, print_json, print_table};
use super::{Ctx, UsageError};
use crate::geometry::polygon::Polygon;
use crate::query::error::did_you_mean;
use crate::store::{self, Store, StoreError, WorldBox, Zone, ZoneShape};
use clap::{Args, Subcommand};
use std::path::PathBuf;

#[derive(Debug, Subcommand)]
pub enum ZonesCommand {
    /// Add a zone: a box `bbox:x0,y0,z0,x1,y1,z1`, or `--wkt 'POLYGON((x y, ...))' --z Z0..Z1`.
    Add(AddArgs),
    /// List the zones of a store.
    List(StoreOnly),
    /// Remove a zone.
    Rm(RmArgs),
}

#[derive(Debug, Args)]
pub struct AddArgs {
    /// The store.
    pub store: PathBuf,
    /// The zone's name (quote it in queries if it has spaces: zone:"Tower B").
    pub name: String,
    /// `bbox:x0,y0,z0,x1,y1,z1`, world frame metres (min corner, then max corner).
    pub bbox: Option<String>,
    /// A polygon in the world xy plane: 'POLYGON((x y, x y, x y, ...))' (holes allowed).
    #[arg(long, conflicts_with = "bbox")]
    pub wkt: Option<String>,
    /// The polygon's height range, `Z0..Z1` metres (with --wkt).
    #[arg(long, value_name = "Z0..Z1", allow_hyphen_values = true)]
    pub z: Option<String>,
}

#[derive(Debug, Args)]
pub struct StoreOnly {
    /// The store (opened read-only).
    pub store: PathBuf,
}

#[derive(Debug, Args)]
pub struct RmArgs {
    /// The store.
    pub store: PathBuf,
    /// The zone to remove.
    pub name: String,
}

pub fn run(ctx: &Ctx, c: ZonesCommand) -> anyhow::Result<()> {
    match c {
        ZonesCommand::Add(a) => add(ctx, a),
        ZonesCommand::List(a) => list(ctx, &Store::open_read_only(&a.store)?),
        ZonesCommand::Rm(a) => rm(ctx, a),
    }
}

fn number(s: &str, what: &str) -> Result<f64, UsageError> {
    s.trim()
        .parse::<f64>()
        .ok()
        .filter(|v| v.is_finite())
        .ok_or_else(|| UsageError(format!("{what}: {:?} is not a number", s.trim())))
}

/// `bbox:x0,y0,z0,x1,y1,z1` (the `bbox:` prefix optional).
fn parse_bbox(text: &str) -> Result<WorldBox, UsageError> {
    let body = text.trim().strip_prefix("bbox:").unwrap_or(text.trim());
    let parts: Vec<&str> = body.split(',').collect();
    if parts.len() != 6 {
        return Err(UsageError(format!(
            "bbox: expected 6 numbers x0,y0,z0,x1,y1,z1, found {}\n  hint: e.g. bbox:10,20,0,40,60,30",
            parts.len()
        )));
    }
    let v = parts.iter().map(|p| number(p, "bbox")).collect::<Result<Vec<_>, _>>()?;
    let b = WorldBox { min_m: [v[0], v[1], v[2]], max_m: [v[3], v[4], v[5]] };
    for (k, axis) in ["x", "y", "z"].iter().enumerate() {
        if b.min_m[k] > b.max_m[k] {
            return Err(UsageError(format!(
                "bbox: {axis}0 = {} is above {axis}1 = {}\n  hint: give the min corner first, then the max corner",
                b.min_m[k], b.max_m[k]
            )));
        }
    }
    Ok(b)
}

/// `Z0..Z1`.
fn parse_z(text: &str) -> Result<(f64, f64), UsageError> {
    let (a, b) =
        text.split_once("..").ok_or_else(|| UsageError(format!("--z {text:?}: expected Z0..Z1, e.g. --z 0..12")))?;
    let (a, b) = (number(a, "--z")?, number(b, "--z")?);
    if a > b {
        return Err(UsageError(format!("--z {text:?}: the lower height comes first")));
    }
    Ok((a, b))
}

fn shape_of(a: &AddArgs) -> Result<ZoneShape, UsageError> {
    match (&a.bbox, &a.wkt) {
        (Some(b), None) => {
            if a.z.is_some() {
                return Err(UsageError("--z goes with --wkt; a bbox has its own heights".into()));
            }
            Ok(ZoneShape::Box(parse_bbox(b)?))
        }
        (None, Some(w)) => {
            let polygon = Polygon::from_wkt(w).map_err(|m| UsageError(format!("--wkt: {m}")))?;
            let z = a.z.as_deref().ok_or_else(|| {
                UsageError("--wkt needs --z Z0..Z1, the heights the zone spans (e.g. --z 0..12)".into())
            })?;
            let (min_z_m, max_z_m) = parse_z(z)?;
            Ok(ZoneShape::Polygon { polygon, min_z_m, max_z_m })
        }
        _ => Err(UsageError(
            "give the zone's shape: bbox:x0,y0,z0,x1,y1,z1, or --wkt 'POLYGON((x y, ...))' --z Z0..Z1".into(),
        )),
    }
}

fn add(ctx: &Ctx, a: AddArgs) -> anyhow::Result<()> {
    let name = a.name.trim().to_string();
    if name.is_empty() || name.chars().any(char::is_control) {
        return Err(
            UsageError(format!("zone name {:?}: give a non-empty name without control characters", a.name)).into()
        );
    }
    let shape = shape_of(&a)?;
    let mut store = Store::open(&a.store)?;
    store.transaction(|tx| -> anyhow::Result<()> {
        if store::zones(tx)?.iter().any(|z| z.name == name) {
            return Err(UsageError(format!(
                "zone {name:?} already exists\n  hint: remove it first with `seam zones rm {} {}`",
                a.store.display(),
                shell_word(&name)
            ))
            .into());
        }
        store::insert_zone(tx, &name, &shape)?;
        Ok(())
    })?;
    list(ctx, &store)
}

fn rm(ctx: &Ctx, a: RmArgs) -> anyhow::Result<()> {
    let mut store = Store::open(&a.store)?;
    let removed = store.transaction(|tx| -> Result<bool, StoreError> { store::remove_zone(tx, &a.name) })?;
    if !removed {
        let zones = store::zones(store.conn())?;
        let names: Vec<&str> = zones.iter().map(|z| z.name.as_str()).collect();
        let hint = match did_you_mean(&a.name, names.iter().copied()) {
            Some(m) => format!("did you mean {m:?}? zones: {}", names.join(", ")),
            None if names.is_empty() => "this store has no zones".into(),
            None => format!("zones: {}", names.join(", ")),
        };
        return Err(UsageError(format!("no zone named {:?}\n  hint: {hint}", a.name)).into());
    }
    list(ctx, &store)
}

/// How to name the zone in a query.
fn in_query(name: &str) -> String {
    let plain = !name.is_empty()
        && name.chars().all(|c| !c.is_whitespace() && !":,|<>=!\"'#()[]{};`\\".contains(c))
        && !name.contains("..")
        && name.parse::<f64>().is_err();
    if plain { format!("zone:{name}") } else { format!("zone:\"{}\"", name.replace('\\', "\\\\").replace('"', "\\\"")) }
}

fn shell_word(s: &str) -> String {
    if s.chars().all(|c| c.is_ascii_alphanumeric() || "-_.".contains(c)) { s.into() } else { format!("'{s}'") }
}

fn list(ctx: &Ctx, store: &Store) -> anyhow::Result<()> {
    let zones: Vec<Zone> = store::zones(store.conn())?;
    if json(ctx) {
        let v: Vec<serde_json::Value> = zones
            .iter()
            .map(|z| {
                let b = z.shape.bounds();
                let wkt = match &z.shape {
                    ZoneShape::Polygon { polygon, .. } => Some(polygon.to_wkt()),
                    ZoneShape::Box(_) => None,
                };
                serde_json::json!({
                    "name": z.name, "kind": z.shape.kind(), "min_m": b.min_m, "max_m": b.max_m,
                    "polygon_wkt": wkt, "query": in_query(&z.name), "created_at": z.created_at,
                })
            })
            .collect();
        return print_json(&v);
    }
    let rows: Vec<Vec<String>> = zones
        .iter()
        .map(|z| {
            let b = z.shape.bounds();
            let f = |v: [f64; 3]| format!("{},{},{}", v[0], v[1], v[2]);
            vec![z.name.clone(), z.shape.kind().into(), f(b.min_m), f(b.max_m), in_query(&z.name)]
        })
        .collect();
    print_table(&["name", "kind", "min_m", "max_m", "in a query"], &rows);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shapes_and_query_names() {
        assert_eq!(parse_bbox("bbox:0,1,2,3,4,5").unwrap().max_m, [3.0, 4.0, 5.0]);
        assert!(parse_bbox("bbox:0,1,2,3,4").unwrap_err().0.contains("found 5"));
        assert!(parse_bbox("3,0,0,1,1,1").unwrap_err().0.contains("x0 = 3 is above"));
        assert_eq!(parse_z("-1..8").unwrap(), (-1.0, 8.0));
        assert!(parse_z("8..1").is_err());
        assert_eq!(in_query("stockpile"), "zone:stockpile");
        assert_eq!(in_query("Tower B"), "zone:\"Tower B\"");
        assert_eq!(in_query("a..b"), "zone:\"a..b\"");
        assert_eq!(in_query("12"), "zone:\"12\"");
    }
}
