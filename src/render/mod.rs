//! # Pictures and the HTML report
//!
//! `seam render` draws top-down PNGs of a store; `seam report` puts them,
//! with a table of the sessions and what changed in each, into one
//! self-contained HTML page.
//!
//! ```text
//!  store (read-only, one snapshot) ──► scene.rs   sessions, map extent, trajectories, session window
//!                                       │
//!        frame.rs  world x/y → pixels (y up, one scale), round scale-bar lengths and ticks
//!                                       │
//!        layers.rs voxels streamed from SQLite, splatted as squares into a per-pixel max:
//!                  static  → highest z        → viridis
//!                  lifelong→ largest ε_g      → plasma
//!                  changes → category priority over a grey static map
//!                  trajectories → polylines over a grey static map
//!                                       │
//!        legend.rs title, grid + axes, legend, scale bar, x/y arrows   (picture.rs lays them out)
//!                                       │
//!        canvas.rs + font.rs  tiny-skia pixmap, DejaVu Sans via ab_glyph → PNG (RGB)
//!                                       │
//!        report.rs four pictures + tables → report.html (PNGs as base64 data URIs)
//! ```
//!
//! Owns: drawing and the report's HTML. Not here: SQL (the reads are in
//! `store::render_rows` and the existing store functions), printing (cli).
//! Output files are written under a temporary name, fsynced and renamed, so
//! a failed or interrupted run never leaves a half picture under the name
//! asked for.

mod canvas;
pub mod colormap;
mod font;
pub mod frame;
mod layers;
mod legend;
mod picture;
pub mod report;
mod scene;

pub use canvas::Canvas;
pub use frame::Extent;
pub use report::{ReportOptions, ReportSummary, write_report};

use crate::store::{Store, StoreError};
use std::path::{Path, PathBuf};

/// What a picture shows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum What {
    /// The static map (ε_g below the threshold), coloured by height.
    Static,
    /// Every voxel of the lifelong map, coloured by global ephemerality ε_g.
    Lifelong,
    /// Change events by category over the static map.
    Changes,
    /// Every session's trajectory over the static map.
    Trajectories,
}

impl What {
    pub const ALL: [What; 4] = [What::Trajectories, What::Static, What::Lifelong, What::Changes];

    pub fn as_str(self) -> &'static str {
        match self {
            What::Static => "static",
            What::Lifelong => "lifelong",
            What::Changes => "changes",
            What::Trajectories => "trajectories",
        }
    }
}

/// How to draw one picture.
#[derive(Debug, Clone, PartialEq)]
pub struct RenderOptions {
    pub what: What,
    /// Width of the PNG; the height follows from the map's shape.
    pub width_px: u32,
    /// Crop to this world box (metres); `None`: the whole map and every
    /// trajectory, with a margin.
    pub bbox: Option<Extent>,
    /// Only this session (its number, `s3`, or its name).
    pub session: Option<String>,
    /// This session and every later one.
    pub since: Option<String>,
    /// The static map is ε_g below this (`[change] static_threshold`).
    pub static_threshold: f64,
    /// The ε_g colour scale (`[change] eps_g_min`, `eps_g_max`).
    pub eps_g_range: (f64, f64),
    /// Text size relative to the default for the width (1.0); larger for
    /// pictures that will be shown scaled down.
    pub text_scale: f32,
}

/// Widths `seam render --width` accepts.
pub const WIDTH_RANGE_PX: (u32, u32) = (480, 8000);

impl Default for RenderOptions {
    fn default() -> Self {
        let c = crate::change::ChangeConfig::default();
        RenderOptions {
            what: What::Static,
            width_px: 1600,
            bbox: None,
            session: None,
            since: None,
            static_threshold: c.static_threshold,
            eps_g_range: (c.eps_g_min, c.eps_g_max),
            text_scale: 1.0,
        }
    }
}

/// Change events of one category in a picture.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct CategoryCount {
    /// As stored (`emerged_overlap`, ...).
    pub category: String,
    /// As the legend names it (`built / appeared`, ...).
    pub label: String,
    /// `#rrggbb`.
    pub colour: String,
    pub events: u64,
}

/// One trajectory in a picture.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct TrajectorySummary {
    pub session: i64,
    pub name: String,
    pub keyframes: u64,
    pub length_m: f64,
    pub colour: String,
    pub start_xy_m: [f64; 2],
}

/// What was drawn, for `--format json` and tests.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct RenderSummary {
    pub what: String,
    /// The PNG written, if any.
    pub path: Option<String>,
    pub width_px: u32,
    pub height_px: u32,
    pub m_per_px: f64,
    /// The world box the map area shows exactly: `[x0, y0, x1, y1]`, metres.
    pub world_bbox_m: [f64; 4],
    /// The map area on the picture: `[left, top, width, height]`, pixels;
    /// world `(x, y)` is at `(left + (x - x0) / m_per_px, top + (y1 - y) / m_per_px)`.
    pub map_area_px: [u32; 4],
    /// Length of the scale bar, metres.
    pub scale_bar_m: f64,
    /// Voxels (static, lifelong), change events (changes) or keyframes
    /// (trajectories) drawn.
    pub drawn: u64,
    /// The session window, e.g. `s2–s3`.
    pub sessions: String,
    pub colormap: Option<String>,
    /// The values at the colour map's two ends.
    pub colour_range: Option<[f64; 2]>,
    pub categories: Vec<CategoryCount>,
    pub trajectories: Vec<TrajectorySummary>,
}

/// A drawn picture.
pub struct Picture {
    pub canvas: Canvas,
    pub summary: RenderSummary,
}

impl Picture {
    pub fn png(&self) -> Result<Vec<u8>, RenderError> {
        self.canvas.encode_png().map_err(|e| RenderError::Encode(e.to_string()))
    }
}

/// Errors of `seam render` and `seam report`; each says what to do.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    #[error(transparent)]
    Store(#[from] StoreError),
    #[error("no session {arg:?} in this store; it has: {known}\n  hint: pass a session's number or name")]
    NoSuchSession { arg: String, known: String },
    /// A bad option (exit 2).
    #[error("{0}")]
    Usage(String),
    #[error("{path}: {source}")]
    Io { path: PathBuf, source: std::io::Error },
    #[error("encoding the PNG failed: {0}")]
    Encode(String),
}

/// Draws a picture of an open store (read in one snapshot).
pub fn render(store: &Store, opts: &RenderOptions) -> Result<Picture, RenderError> {
    check_width(opts.width_px)?;
    let meta = store.meta()?;
    // A deferred read transaction: every read sees the same WAL snapshot,
    // even while an ingest commits. Dropping it is a no-op rollback.
    let tx = store
        .conn()
        .unchecked_transaction()
        .map_err(|e| StoreError::Sql { path: store.root().join(crate::store::DB_FILE), source: e })?;
    let scene = scene::Scene::read(&tx, meta)?;
    picture::draw(&tx, &scene, opts)
}

/// Opens the store read-only, draws, and writes the PNG to `out`
/// atomically. The output folder must exist; it is checked before anything
/// is read.
pub fn render_to_file(store_path: &Path, out: &Path, opts: &RenderOptions) -> Result<RenderSummary, RenderError> {
    check_width(opts.width_px)?;
    check_output_dir(out)?;
    let store = Store::open_read_only(store_path)?;
    let pic = render(&store, opts)?;
    write_atomic(out, &pic.png()?)?;
    Ok(RenderSummary { path: Some(out.display().to_string()), ..pic.summary })
}

fn check_width(w: u32) -> Result<(), RenderError> {
    let (lo, hi) = WIDTH_RANGE_PX;
    if (lo..=hi).contains(&w) {
        Ok(())
    } else {
        Err(RenderError::Usage(format!("--width {w} is outside {lo}..{hi} pixels")))
    }
}

/// Refuses an output path whose folder does not exist (or is not a folder).
pub fn check_output_dir(out: &Path) -> Result<(), RenderError> {
    let dir = out.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    if out.is_dir() {
        return Err(RenderError::Usage(format!("{} is a folder; name the file to write", out.display())));
    }
    if !dir.is_dir() {
        return Err(RenderError::Usage(format!(
            "folder {} does not exist\n  hint: create it first (`mkdir -p {}`)",
            dir.display(),
            dir.display()
        )));
    }
    Ok(())
}

/// Writes `bytes` to `path` under a temporary name in the same folder,
/// fsyncs and renames it into place; on failure nothing is left behind.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), RenderError> {
    check_output_dir(path)?;
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_else(|| "out".into());
    let tmp = path.with_file_name(format!(".{name}.tmp-{}", std::process::id()));
    let write = || -> std::io::Result<()> {
        use std::io::Write;
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)
    };
    write().map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        RenderError::Io { path: path.to_path_buf(), source: e }
    })
}

pub(crate) use crate::text::thousands;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn atomic_write_leaves_only_the_file_and_refuses_missing_folders() {
        let tmp = tempfile::tempdir().unwrap();
        let p = tmp.path().join("a.png");
        write_atomic(&p, b"one").unwrap();
        write_atomic(&p, b"two").unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"two");
        assert_eq!(std::fs::read_dir(tmp.path()).unwrap().count(), 1);
        let err = write_atomic(&tmp.path().join("nope/a.png"), b"x").unwrap_err();
        assert!(matches!(err, RenderError::Usage(_)), "{err}");
        assert!(matches!(check_output_dir(tmp.path()), Err(RenderError::Usage(_))));
        assert!(check_output_dir(Path::new("here.png")).is_ok(), "a bare name is in the current folder");
        assert_eq!(thousands(1234567), "1,234,567");
        assert_eq!(thousands(12), "12");
    }
}
