//! `seam render site.seam --what static|lifelong|changes|trajectories [--session N | --since N]
//! [--width PX] [--bbox x0,y0,x1,y1] -o map.png`
//!
//! Draws a top-down picture of a store (opened read-only) as a PNG, written
//! under a temporary name and renamed into place. `--format json` prints
//! what was drawn: path, pixel size, metres per pixel, the map area and
//! world box (to place a world point on the picture), counts.

use super::output::{json, log, print_json, thousands};
use super::{Ctx, UsageError};
use crate::render::{self, Extent, RenderOptions, What};
use clap::Args;
use std::path::PathBuf;

#[derive(Debug, Args)]
pub struct RenderArgs {
    /// The store (opened read-only).
    pub store: PathBuf,
    /// What to draw.
    #[arg(long, value_enum)]
    pub what: What,
    /// Only this session (number, `s3`, or name): changes it saw, its trajectory.
    #[arg(long, value_name = "N")]
    pub session: Option<String>,
    /// This session and every later one (number, `s3`, or name).
    #[arg(long, value_name = "SESSION")]
    pub since: Option<String>,
    /// Width of the picture in pixels (the height follows from the map's shape).
    #[arg(long, value_name = "PX", default_value_t = 1600)]
    pub width: u32,
    /// Crop to a world box, metres: x0,y0,x1,y1 (the frame of `seam poses`).
    #[arg(long, value_name = "x0,y0,x1,y1", allow_hyphen_values = true)]
    pub bbox: Option<String>,
    /// The PNG to write (its folder must exist).
    #[arg(short, long, value_name = "FILE")]
    pub out: PathBuf,
}

/// Parses `x0,y0,x1,y1` (metres) into a non-empty box.
pub fn parse_bbox(s: &str) -> Result<Extent, UsageError> {
    let v: Vec<f64> = s
        .split(',')
        .map(|p| p.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| UsageError(format!("--bbox {s:?}: expected four numbers x0,y0,x1,y1 in metres")))?;
    match v[..] {
        [x0, y0, x1, y1] if v.iter().all(|c| c.is_finite()) && x1 > x0 && y1 > y0 => Ok(Extent { x0, y0, x1, y1 }),
        [_, _, _, _] => Err(UsageError(format!("--bbox {s:?}: needs x0 < x1 and y0 < y1"))),
        _ => Err(UsageError(format!("--bbox {s:?}: expected four numbers x0,y0,x1,y1 in metres"))),
    }
}

pub fn run(ctx: &Ctx, a: RenderArgs) -> anyhow::Result<()> {
    let bbox = a.bbox.as_deref().map(parse_bbox).transpose()?;
    let c = &ctx.config.change;
    let opts = RenderOptions {
        what: a.what,
        width_px: a.width,
        bbox,
        session: a.session,
        since: a.since,
        static_threshold: c.static_threshold,
        eps_g_range: (c.eps_g_min, c.eps_g_max),
        ..RenderOptions::default()
    };
    let t0 = std::time::Instant::now();
    let s = render::render_to_file(&a.store, &a.out, &opts)?;
    if json(ctx) {
        return print_json(&s);
    }
    println!(
        "{}: {} × {} px, {:.3} m per pixel, {} {} drawn ({}), scale bar {} m",
        a.out.display(),
        s.width_px,
        s.height_px,
        s.m_per_px,
        thousands(s.drawn),
        match a.what {
            What::Static | What::Lifelong => "voxels",
            What::Changes => "change events",
            What::Trajectories => "keyframes",
        },
        s.sessions,
        s.scale_bar_m
    );
    log(ctx, format!("rendered in {:.2} s", t0.elapsed().as_secs_f64()));
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bbox_parses_four_ordered_numbers() {
        assert_eq!(parse_bbox("-10, 0,20.5,30").unwrap(), Extent { x0: -10.0, y0: 0.0, x1: 20.5, y1: 30.0 });
        for bad in ["1,2,3", "1,2,3,4,5", "a,b,c,d", "5,0,1,10", "0,0,1,0", "0,0,inf,1", ""] {
            assert!(parse_bbox(bad).is_err(), "{bad}");
        }
    }
}
