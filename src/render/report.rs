//! `seam report`: one self-contained HTML page about a store — a table of
//! the sessions, a sentence per session on what changed, the pictures
//! (trajectories, static map by height, lifelong map by ε_g, changes since
//! the second session and, for a few sessions, each session's own), and the
//! commands that redraw them. CSS is inline and the PNGs are `data:` URIs,
//! so the file can be mailed or archived alone; it loads nothing.
//!
//! Everything is read in one snapshot of the store.

use super::frame::tick_label;
use super::scene::Scene;
use super::{RenderError, RenderOptions, RenderSummary, What, picture, thousands, write_atomic};
use crate::change::places::{Place, SUMMARY_LINK_M, SUMMARY_MIN_EVENTS, places};
use crate::change::{Category, SessionChanges};
use crate::store::{self, SessionId, Store, StoreError, WorldBox};
use base64::Engine;
use rustc_hash::FxHashMap;
use std::fmt::Write as _;
use std::path::Path;

/// How to build a report.
#[derive(Debug, Clone, PartialEq)]
pub struct ReportOptions {
    /// Width of the main pictures, pixels (per-session pictures are 60 % of it).
    pub width_px: u32,
    pub static_threshold: f64,
    pub eps_g_range: (f64, f64),
    /// Draw one changes picture per session when the store has at most this
    /// many sessions after the first.
    pub per_session_pictures_max: usize,
}

impl Default for ReportOptions {
    fn default() -> Self {
        let r = RenderOptions::default();
        ReportOptions {
            width_px: 1400,
            static_threshold: r.static_threshold,
            eps_g_range: r.eps_g_range,
            per_session_pictures_max: 6,
        }
    }
}

/// What a report holds.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ReportSummary {
    pub path: String,
    pub bytes: u64,
    pub sessions: usize,
    /// One per embedded picture, in page order.
    pub pictures: Vec<RenderSummary>,
    pub wall_s: f64,
}

/// One row of the sessions table.
struct Row {
    id: SessionId,
    name: String,
    date: String,
    sensor: String,
    keyframes: i64,
    points: i64,
    alignment: String,
    aligned: bool,
    inter: (usize, usize),
    intra: (usize, usize),
    /// Points removed as dynamic, of all points.
    dor: Option<(i64, i64)>,
    changes: Option<SessionChanges>,
    places: Vec<Place>,
    /// Coexist events: voxels seen again right after a removal.
    back_again: u64,
}

fn read_rows(conn: &rusqlite::Connection, scene: &Scene) -> Result<Vec<Row>, StoreError> {
    let loops = store::loops(conn, false)?;
    let has = |t: &str| store::has_table(conn, t);
    let changes: FxHashMap<i64, SessionChanges> = if has("session_changes")? {
        store::session_changes(conn)?.into_iter().map(|(s, c)| (s.0, c)).collect()
    } else {
        Default::default()
    };
    let events = if has("change_events")? && has("map_tiles")? {
        store::change_events_in(conn, &WorldBox::ALL, i64::MIN)?
    } else {
        Vec::new()
    };
    let mut rows = Vec::new();
    for s in &scene.sessions {
        let id = s.session_id;
        let a = store::alignment(conn, id)?;
        let count = |kind: &str| {
            let mine = loops.iter().filter(|l| l.session_id == id && l.kind == kind);
            (mine.clone().filter(|l| l.accepted).count(), mine.count())
        };
        let dor = if has("session_dor")? {
            store::session_dor(conn, id)?.map(|d| (d.dynamic_points, d.points))
        } else {
            None
        };
        let changed: Vec<[f64; 3]> = events
            .iter()
            .map(|e| &e.event)
            .filter(|e| {
                e.session_id == id.0 && matches!(e.category, Category::EmergedOverlap | Category::DeletedOverlap)
            })
            .map(|e| e.xyz_m)
            .collect();
        let places = places(&changed, SUMMARY_LINK_M, SUMMARY_MIN_EVENTS).places;
        rows.push(Row {
            id,
            name: s.name.clone(),
            date: s.date.clone().unwrap_or_default(),
            sensor: s.sensor_model.clone().unwrap_or_default(),
            keyframes: s.keyframe_count,
            points: s.point_count,
            alignment: a.as_ref().map_or_else(|| "—".into(), |a| a.method.clone()),
            aligned: a.as_ref().is_none_or(|a| a.success),
            inter: count("inter"),
            intra: count("intra"),
            dor,
            changes: changes.get(&id.0).cloned(),
            places,
            back_again: events
                .iter()
                .filter(|e| e.event.session_id == id.0 && e.event.category == Category::Coexist)
                .count() as u64,
        });
    }
    Ok(rows)
}

/// `v` voxels as cubic metres.
fn m3(voxels: usize, voxel_m: f64) -> String {
    format!("{:.1}", voxels as f64 * voxel_m.powi(3))
}

/// The sentence on what session `r` changed.
fn sentence(r: &Row, first: bool, voxel_m: f64) -> String {
    let date = if r.date.is_empty() { String::new() } else { format!(" ({})", r.date) };
    let Some(c) = &r.changes else {
        return format!("{}{date}: no change detection yet (its ingest has not reached the changes step).", r.name);
    };
    if first {
        return format!(
            "{}{date} is the first session: it defines the world frame and starts the map with {} voxels.",
            r.name,
            thousands(c.lifelong_voxels as u64)
        );
    }
    let mut s = format!(
        "{}{date}: {} voxels appeared ({} m³) and {} were removed ({} m³)",
        r.name,
        thousands(c.emerged_overlap as u64),
        m3(c.emerged_overlap, voxel_m),
        thousands(c.deleted_overlap as u64),
        m3(c.deleted_overlap, voxel_m)
    );
    match r.places.len() {
        0 => {
            let _ = write!(s, ", none in a group of {SUMMARY_MIN_EVENTS} or more");
        }
        n => {
            let big = &r.places[0];
            let _ = write!(
                s,
                ", in {n} place{} (the largest, {} m³, near x = {} m, y = {} m)",
                if n == 1 { "" } else { "s" },
                m3(big.events, voxel_m),
                tick_label(big.centroid_m[0].round()),
                tick_label(big.centroid_m[1].round())
            );
        }
    }
    let _ = write!(s, "; {} voxels first seen in areas not surveyed before", thousands(c.emerged_non_overlap as u64));
    if r.back_again > 0 {
        let _ = write!(s, "; {} back again after a removal", thousands(r.back_again));
    }
    let _ = write!(
        s,
        ". The map then held {} voxels, {} of them static.",
        thousands(c.lifelong_voxels as u64),
        thousands(c.static_voxels as u64)
    );
    s
}

fn esc(s: &str) -> String {
    let mut o = String::with_capacity(s.len());
    for ch in s.chars() {
        match ch {
            '&' => o.push_str("&amp;"),
            '<' => o.push_str("&lt;"),
            '>' => o.push_str("&gt;"),
            '"' => o.push_str("&quot;"),
            '\'' => o.push_str("&#39;"),
            c => o.push(c),
        }
    }
    o
}

/// A word for a shell command line, quoted when it needs to be.
fn shell_word(s: &str) -> String {
    if !s.is_empty() && s.chars().all(|c| c.is_ascii_alphanumeric() || "._/-:=+,".contains(c)) {
        s.to_string()
    } else {
        format!("'{}'", s.replace('\'', "'\\''"))
    }
}

const CSS: &str = "
body { font-family: system-ui, -apple-system, 'Segoe UI', 'DejaVu Sans', sans-serif; color: #222; margin: 0; background: #fafafa; }
main { max-width: 1200px; margin: 0 auto; padding: 24px 32px 48px; background: #fff; }
h1 { font-size: 28px; margin: 8px 0 4px; } h2 { font-size: 21px; margin: 36px 0 10px; border-bottom: 1px solid #ddd; padding-bottom: 4px; }
.meta { color: #666; margin: 0 0 8px; }
table { border-collapse: collapse; font-size: 13.5px; width: 100%; }
th, td { padding: 5px 7px; border-bottom: 1px solid #e4e4e4; text-align: left; vertical-align: top; }
th { background: #f2f2f2; font-weight: 600; white-space: nowrap; }
td.nw { white-space: nowrap; }
td.n { text-align: right; font-variant-numeric: tabular-nums; white-space: nowrap; }
.bad { color: #b00020; font-weight: 600; }
.note { color: #666; font-size: 13px; }
ul.changes li { margin: 6px 0; line-height: 1.45; }
figure { margin: 18px 0 30px; } figure img { width: 100%; height: auto; border: 1px solid #ddd; }
figcaption { color: #444; font-size: 14px; margin-top: 6px; }
.scroll { overflow-x: auto; }
th .sub, td .sub { display: block; font-weight: normal; color: #777; font-size: 12px; }
pre { background: #f4f4f4; padding: 10px 12px; overflow-x: auto; font-size: 13px; }
footer { color: #666; font-size: 13px; margin-top: 40px; }
";

/// A picture to embed.
struct Figure {
    opts: RenderOptions,
    caption: String,
    file: String,
    /// Extra `seam render` flags that redraw it.
    flags: String,
}

fn figures(scene: &Scene, o: &ReportOptions) -> Vec<Figure> {
    // Pictures are shown about 1,140 px wide: text a quarter larger than a
    // 1:1 PNG's keeps the legends readable there.
    let base = RenderOptions {
        what: What::Static,
        width_px: o.width_px,
        bbox: None,
        session: None,
        since: None,
        static_threshold: o.static_threshold,
        eps_g_range: o.eps_g_range,
        text_scale: 1.25,
    };
    let with = |what: What| RenderOptions { what, ..base.clone() };
    let mut out = vec![
        Figure {
            opts: with(What::Trajectories),
            caption: "Every session's trajectory on the newest pose graph, over the static map (grey). A disc marks where each session started.".into(),
            file: "trajectories.png".into(),
            flags: "--what trajectories".into(),
        },
        Figure {
            opts: with(What::Static),
            caption: format!("The static map (voxels with ε_g < {}), coloured by the height of the highest voxel in each pixel.", tick_label(o.static_threshold)),
            file: "static.png".into(),
            flags: "--what static".into(),
        },
        Figure {
            opts: with(What::Lifelong),
            caption: "The lifelong map: every voxel any session saw, coloured by its global ephemerality ε_g (the largest in each pixel). Bright: gone, moved or seen only once; dark: seen again and again.".into(),
            file: "lifelong.png".into(),
            flags: "--what lifelong".into(),
        },
    ];
    let later: Vec<&store::SessionRow> = scene.sessions.iter().skip(1).collect();
    if let Some(second) = later.first() {
        let mut opts = with(What::Changes);
        opts.since = Some(second.session_id.0.to_string());
        out.push(Figure {
            opts,
            caption: format!(
                "Every change event from {} on, by category, over the static map: green where something was built or placed, orange-red where something was removed.",
                second.name
            ),
            file: "changes.png".into(),
            flags: format!("--what changes --since {}", shell_word(&second.name)),
        });
    }
    if later.len() >= 2 && later.len() <= o.per_session_pictures_max {
        for s in &later {
            let mut opts = with(What::Changes);
            opts.session = Some(s.session_id.0.to_string());
            out.push(Figure {
                opts,
                caption: format!("The changes {} saw, alone:", s.name),
                file: format!("changes-{}.png", s.session_id.0),
                flags: format!("--what changes --session {}", shell_word(&s.name)),
            });
        }
    }
    out
}

/// Writes the report of the store at `store_path` to `out` (atomically).
pub fn write_report(store_path: &Path, out: &Path, opts: &ReportOptions) -> Result<ReportSummary, RenderError> {
    let t0 = std::time::Instant::now();
    super::check_output_dir(out)?;
    let store = Store::open_read_only(store_path)?;
    let (html, pictures, sessions) = build(&store, store_path, opts)?;
    write_atomic(out, html.as_bytes())?;
    Ok(ReportSummary {
        path: out.display().to_string(),
        bytes: html.len() as u64,
        sessions,
        pictures,
        wall_s: t0.elapsed().as_secs_f64(),
    })
}

/// The page, the pictures' summaries, and the number of sessions.
fn build(
    store: &Store,
    store_path: &Path,
    o: &ReportOptions,
) -> Result<(String, Vec<RenderSummary>, usize), RenderError> {
    let meta = store.meta()?;
    let tx = store
        .conn()
        .unchecked_transaction()
        .map_err(|e| StoreError::Sql { path: store.root().join(store::DB_FILE), source: e })?;
    let scene = Scene::read(&tx, meta.clone())?;
    let rows = read_rows(&tx, &scene)?;
    let v = scene.voxel_m;

    let mut h = String::with_capacity(1 << 20);
    let title = format!("seam report: {}", meta.site_name);
    let _ = write!(
        h,
        "<!doctype html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n<title>{}</title>\n<style>{CSS}</style>\n</head>\n<body>\n<main>\n",
        esc(&title)
    );
    let _ = write!(
        h,
        "<h1>{}</h1>\n<p class=\"meta\">CRS {} · voxel {} m · {} session{} · map on graph version {} · generated {} by seam {}</p>\n",
        esc(&meta.site_name),
        esc(&meta.crs),
        tick_label(v),
        rows.len(),
        if rows.len() == 1 { "" } else { "s" },
        scene.graph_version.map_or_else(|| "—".into(), |g| g.to_string()),
        store::now_utc(),
        env!("CARGO_PKG_VERSION")
    );

    // Sessions table: one row per session, every number in a cell named by
    // `data-col` (the `session_changes` column it comes from, where there is one).
    h.push_str(
        "<h2>Sessions</h2>\n<div class=\"scroll\">\n<table class=\"sessions\">\n<tr><th>#</th><th>name</th><th>date</th>\
         <th>sensor</th><th>keyframes</th><th>points</th><th>alignment</th><th>loops<span class=\"sub\">inter · intra</span></th>\
         <th>removed as dynamic</th><th>appeared</th><th>removed</th><th>first seen</th><th>map voxels<span class=\"sub\">static</span></th></tr>\n",
    );
    let num =
        |k: &str, v: Option<u64>| format!("<span data-col=\"{k}\">{}</span>", v.map_or_else(|| "—".into(), thousands));
    for r in &rows {
        let c = r.changes.as_ref();
        let vol = |k: &str, v: Option<usize>| {
            v.map_or_else(String::new, |x| {
                format!("<span class=\"sub\" data-col=\"{k}\">{} m³</span>", m3(x, scene.voxel_m))
            })
        };
        let dor = r.dor.map_or_else(
            || "—".into(),
            |(d, p)| {
                let pct = if p > 0 { 100.0 * d as f64 / p as f64 } else { 0.0 };
                format!("{pct:.1} %<span class=\"sub\">{} points</span>", thousands(d.max(0) as u64))
            },
        );
        let align_class = if r.aligned { "" } else { " bad" };
        let _ = writeln!(
            h,
            "<tr data-session=\"{id}\"><td class=\"n\">{id}</td><td data-col=\"name\">{}</td><td class=\"nw\">{}</td><td>{}</td>\
             <td class=\"n\">{}</td><td class=\"n\">{}</td><td class=\"{align_class}\" data-col=\"alignment\">{}</td>\
             <td class=\"n\" data-col=\"loops\">{} / {} · {} / {}</td><td class=\"n\" data-col=\"dynamic\">{dor}</td>\
             <td class=\"n\">{}{}</td><td class=\"n\">{}{}</td><td class=\"n\">{}</td><td class=\"n\">{}<span class=\"sub\">{}</span></td></tr>",
            esc(&r.name),
            esc(&r.date),
            esc(&r.sensor),
            num("keyframes", Some(r.keyframes.max(0) as u64)),
            num("points", Some(r.points.max(0) as u64)),
            esc(&r.alignment),
            r.inter.0,
            r.inter.1,
            r.intra.0,
            r.intra.1,
            num("emerged_overlap", c.map(|c| c.emerged_overlap as u64)),
            vol("emerged_overlap_m3", c.map(|c| c.emerged_overlap)),
            num("deleted_overlap", c.map(|c| c.deleted_overlap as u64)),
            vol("deleted_overlap_m3", c.map(|c| c.deleted_overlap)),
            num("emerged_non_overlap", c.map(|c| c.emerged_non_overlap as u64)),
            num("lifelong_voxels", c.map(|c| c.lifelong_voxels as u64)),
            num("static_voxels", c.map(|c| c.static_voxels as u64)),
            id = r.id.0,
        );
    }
    h.push_str("</table>\n</div>\n<p class=\"note\">Loops: accepted / tried, inter (to earlier sessions) · intra (within the session). Removed as dynamic: points the evidence step took out as moving. Appeared: new voxels within τ_o ([change] tau_o_m, 2 m by default) of structure an earlier session also saw; removed: voxels this session saw free; first seen: voxels in areas no earlier session surveyed; m³ counts whole voxels. Map voxels: the lifelong map after the session, and how many of them are static.</p>\n");

    // What changed.
    h.push_str("<h2>What changed</h2>\n<ul class=\"changes\">\n");
    for (i, r) in rows.iter().enumerate() {
        let _ = writeln!(h, "<li data-session=\"{}\">{}</li>", r.id.0, esc(&sentence(r, i == 0, v)));
    }
    let _ = writeln!(
        h,
        "</ul>\n<p class=\"note\">A place is a group of at least {SUMMARY_MIN_EVENTS} appeared or removed voxels, each within {} m of another.</p>",
        tick_label(SUMMARY_LINK_M)
    );

    // Pictures.
    h.push_str("<h2>Pictures</h2>\n");
    let mut summaries = Vec::new();
    let figs = figures(&scene, o);
    for f in &figs {
        let pic = picture::draw(&tx, &scene, &f.opts)?;
        let png = pic.png()?;
        let mut caption = f.caption.clone();
        if f.opts.session.is_some() {
            let n = |cat: &str| pic.summary.categories.iter().find(|c| c.category == cat).map_or(0, |c| c.events);
            let _ = write!(
                caption,
                " {} voxels built or appeared (green), {} removed (orange-red), {} back again (blue).",
                thousands(n("emerged_overlap")),
                thousands(n("deleted_overlap")),
                thousands(n("coexist"))
            );
        }
        let _ = writeln!(
            h,
            "<figure data-what=\"{}\" data-file=\"{}\"><img alt=\"{}\" width=\"{}\" height=\"{}\" src=\"data:image/png;base64,{}\"><figcaption>{}</figcaption></figure>",
            f.opts.what.as_str(),
            esc(&f.file),
            esc(&caption),
            pic.summary.width_px,
            pic.summary.height_px,
            base64::engine::general_purpose::STANDARD.encode(&png),
            esc(&caption)
        );
        summaries.push(RenderSummary { path: Some(f.file.clone()), ..pic.summary });
    }

    // How to redraw.
    let sp = shell_word(&store_path.display().to_string());
    h.push_str("<footer>\n<p>Redraw these pictures as PNG files (add <code>--width PX</code> or <code>--bbox x0,y0,x1,y1</code> to zoom in):</p>\n<pre>");
    for f in &figs {
        let _ = writeln!(h, "{}", esc(&format!("seam render {sp} {} -o {}", f.flags, f.file)));
    }
    let _ = writeln!(h, "{}", esc(&format!("seam report {sp} -o report.html")));
    h.push_str("</pre>\n<p>Positions are metres in the store's world frame, the frame of <code>seam poses</code>. Tables as Parquet: <code>seam export</code>.</p>\n</footer>\n</main>\n</body>\n</html>\n");
    Ok((h, summaries, rows.len()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_is_escaped_and_shell_words_quoted() {
        assert_eq!(esc("<a href=\"x\">&'"), "&lt;a href=&quot;x&quot;&gt;&amp;&#39;");
        assert_eq!(shell_word("site.seam"), "site.seam");
        assert_eq!(shell_word("my site"), "'my site'");
        assert_eq!(shell_word("it's"), "'it'\\''s'");
    }
}
