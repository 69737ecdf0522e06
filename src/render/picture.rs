//! One picture, laid out and drawn: title band on top, the map area with
//! its metre grid and axes on the left, the legend panel on the right with
//! the scale bar and frame arrows at its foot.
//!
//! ```text
//! ┌──────────────────────────────────────────────────────────┐
//! │ site: what                                               │
//! │ subtitle (voxels, sessions, frame)                       │
//! │   y ┌──────────────────────────────┐  legend heading     │
//! │  20 ┤                              │  colour bar / rows  │
//! │  10 ┤        map area              │                     │
//! │   0 ┤  (x right, y up, 1 scale)    │  scale bar          │
//! │     └──┬───────┬───────┬───────────┘  +y ↑ → +x          │
//! │        0      10      20      x (m)                      │
//! └──────────────────────────────────────────────────────────┘
//! ```

use super::canvas::{Align, Canvas};
use super::colormap::{CATEGORY_STYLES, PLASMA, Rgb, VIRIDIS, session_colour};
use super::font;
use super::frame::{Extent, View, tick_label, ticks};
use super::layers;
use super::legend::{self, Sizes};
use super::scene::{Scene, Window};
use super::{CategoryCount, Picture, RenderError, RenderOptions, RenderSummary, TrajectorySummary, What, thousands};
use crate::store::{self, ChangeEventRow};
use rusqlite::Connection;

/// What the legend shows, with the values it needs.
enum LegendData {
    Height { lo: f32, hi: f32 },
    EpsG { lo: f32, hi: f32, threshold: f32 },
    Changes { window: String, counts: [u64; 5] },
    Trajectories { rows: Vec<(Rgb, String, String)> },
}

/// Draws the legend from `(x, y)` in a panel `w` wide; returns the cursor.
fn draw_legend(c: &mut Canvas, z: &Sizes, x: f32, y: f32, w: f32, d: &LegendData) -> f32 {
    match d {
        LegendData::Height { lo, hi } => {
            let mut y = legend::heading(c, z, x, y, "height of the highest voxel");
            y = legend::note(c, z, x, y, "z in metres, world frame");
            let t = ticks(*lo as f64, *hi as f64, 6);
            y = legend::colour_bar(c, z, x, y, VIRIDIS, (*lo, *hi), &t, None);
            y = legend::note(c, z, x, y, &format!("colours span {:.1} to {:.1} m,", lo, hi).replace('-', "−"));
            legend::note(c, z, x, y, "the 2nd to 98th percentile of tops")
        }
        LegendData::EpsG { lo, hi, threshold } => {
            let mut y = legend::heading(c, z, x, y, "global ephemerality ε_g");
            y = legend::note(c, z, x, y, "largest ε_g per pixel: an ephemeral");
            y = legend::note(c, z, x, y, "voxel shows over static ground");
            let t = ticks(*lo as f64, *hi as f64, 8);
            y = legend::colour_bar(c, z, x, y, PLASMA, (*lo, *hi), &t, Some((*threshold, "static threshold")));
            y = legend::note(c, z, x, y, &format!("below {}: the static map", tick_label2(*threshold)));
            legend::note(c, z, x, y, "high: gone, moved or seen once")
        }
        LegendData::Changes { window, counts } => {
            let mut y = legend::heading(c, z, x, y, &format!("change events, {window}"));
            y = legend::note(c, z, x, y, "voxels, counted per session");
            y += z.small * 0.6;
            for (s, n) in CATEGORY_STYLES.iter().zip(counts) {
                y = legend::swatch_row(c, z, x, y, w, s.colour, s.label, Some(*n), Some(s.note));
            }
            y = legend::swatch_row(
                c,
                z,
                x,
                y,
                w,
                Rgb([200, 200, 200]),
                "static map",
                None,
                Some("context, grey by height"),
            );
            legend::note(c, z, x, y, "events sit where their session saw them")
        }
        LegendData::Trajectories { rows } => {
            let mut y = legend::heading(c, z, x, y, "sessions");
            y += z.small * 0.4;
            for (colour, name, detail) in rows {
                y = legend::line_row(c, z, x, y, *colour, name, detail);
            }
            y = legend::note(c, z, x, y, "● start of each session");
            y = legend::swatch_row(c, z, x, y + z.small * 0.5, w, Rgb([200, 200, 200]), "static map", None, None);
            if rows.is_empty() {
                y = legend::note(c, z, x, y, "no session in the window has poses");
            }
            y
        }
    }
}

/// Two decimals at most, for legend values.
fn tick_label2(v: f32) -> String {
    tick_label((v as f64 * 100.0).round() / 100.0)
}

/// The heading and subtitle of a picture.
fn titles(scene: &Scene, what: What, window: &Window, drawn: u64, threshold: f64) -> (String, String) {
    let site = &scene.meta.site_name;
    let all = Window {
        from: scene.sessions.first().map_or(window.from, |s| s.session_id),
        to: scene.sessions.last().map_or(window.to, |s| s.session_id),
    };
    let frame = format!("world frame (seam poses), {}", scene.meta.crs);
    let v = format!("{} m", tick_label(scene.voxel_m));
    let map_of = if scene.sessions.is_empty() {
        "no sessions yet".to_string()
    } else {
        format!("map after {}", scene.window_label(&Window { from: all.to, to: all.to }))
    };
    match what {
        What::Static => (
            format!("{site}: static map, coloured by height"),
            format!("{} voxels of {v} with ε_g < {threshold} · {map_of} · {frame}", thousands(drawn)),
        ),
        What::Lifelong => (
            format!("{site}: lifelong map, coloured by ε_g"),
            format!("{} voxels of {v}, every voxel any session saw · {map_of} · {frame}", thousands(drawn)),
        ),
        What::Changes => {
            let what = if window.from == window.to {
                format!("changes seen in {}", scene.window_label(window))
            } else {
                format!("changes since {} ({})", scene.name_of(window.from), scene.window_label(window))
            };
            (format!("{site}: {what}"), format!("{} change events, voxels of {v} · {frame}", thousands(drawn)))
        }
        What::Trajectories => (
            format!("{site}: trajectories, {}", scene.window_label(window)),
            format!("{} keyframes on graph version {} · {frame}", thousands(drawn), scene.graph_version.unwrap_or(0)),
        ),
    }
}

pub fn draw(conn: &Connection, scene: &Scene, opts: &RenderOptions) -> Result<Picture, RenderError> {
    let width = opts.width_px;
    let z = Sizes::for_width(width, opts.text_scale);
    let window = scene.window(opts.session.as_deref(), opts.since.as_deref(), opts.what == What::Changes)?;
    if matches!(opts.what, What::Static | What::Lifelong) && (opts.session.is_some() || opts.since.is_some()) {
        return Err(RenderError::Usage(format!(
            "--session and --since choose sessions for --what changes or trajectories; the {} map is the store's current map",
            opts.what.as_str()
        )));
    }

    // The world box: the user's, else everything with a margin.
    let content = match opts.bbox {
        Some(b) => b,
        None => {
            let e = scene.content_extent();
            if e.is_empty() {
                Extent { x0: -10.0, y0: -10.0, x1: 10.0, y1: 10.0 }
            } else {
                e.padded((e.width().max(e.height()) * 0.02).max(2.0))
            }
        }
    };

    // Trajectory rows of the legend (also what the trajectories picture draws).
    let shown: Vec<(usize, &super::scene::Trajectory)> = scene
        .trajectories
        .iter()
        .filter(|t| window.contains(t.session.0))
        .map(|t| (scene.sessions.iter().position(|s| s.session_id == t.session).unwrap_or(0), t))
        .collect();
    let traj_rows: Vec<(Rgb, String, String)> = shown
        .iter()
        .map(|(i, t)| {
            let mut detail = format!("{} kf · {:.0} m", t.xy_m.len(), t.length_m);
            if t.unaligned {
                detail.push_str(" · unaligned");
            }
            (session_colour(*i), t.name.clone(), detail)
        })
        .collect();
    let placeholder = match opts.what {
        What::Static => LegendData::Height { lo: 0.0, hi: 1.0 },
        What::Lifelong => LegendData::EpsG { lo: 0.0, hi: 1.0, threshold: 0.5 },
        What::Changes => LegendData::Changes { window: String::new(), counts: [0; 5] },
        What::Trajectories => LegendData::Trajectories { rows: traj_rows.clone() },
    };

    // Measure the legend and the scale bar + arrows on a scratch canvas.
    let legend_w = z.legend_w;
    let mut scratch = Canvas::new(legend_w.ceil() as u32 + 1, 4000, Rgb::WHITE)
        .ok_or_else(|| RenderError::Usage("picture too large".into()))?;
    let legend_h = draw_legend(&mut scratch, &z, 0.0, 0.0, legend_w, &placeholder);
    let (scale_h, _) = legend::scale_bar(&mut scratch, &z, 0.0, 0.0, legend_w * 0.85, 1.0);
    let caption = frame_caption(scene);
    let arrows_h = legend::frame_arrows(&mut scratch, &z, 0.0, 0.0, &caption);
    let decor_h = scale_h + z.pad + arrows_h;

    // Layout.
    let title_h = z.pad * 0.8 + z.title + z.text * 2.1;
    let top = title_h + z.small * 2.4;
    let label_w = [content.x0, content.x1, content.y0, content.y1]
        .iter()
        .map(|v| font::text_width(z.small, &tick_label(v.round())))
        .fold(font::text_width(z.small, "y (m)"), f32::max);
    let left = (z.pad + label_w + 12.0 * z.s).round();
    let legend_x = width as f32 - z.pad - legend_w;
    let max_w = (legend_x - z.pad * 1.5 - left).max(50.0) as u32;
    let min_h = (legend_h + z.pad * 2.0 + decor_h).ceil() as u32;
    let max_h = ((max_w as f32 * 1.3) as u32).max(min_h);
    let view = View::fit(&content, left as f64, top.round() as f64, max_w, max_h, min_h);
    let height = (view.bottom_px() as f32 + z.small * 3.2 + z.pad).ceil() as u32;
    let mut c = Canvas::new(width, height, Rgb::PAPER)
        .ok_or_else(|| RenderError::Usage(format!("a {width} × {height} picture does not fit in memory")))?;

    // The map.
    legend::grid(&mut c, &view);
    let mut summary = RenderSummary::new(opts.what, &c, &view);
    let (legend_data, drawn) = match opts.what {
        What::Static => {
            let (tops, n) = layers::tops(conn, &view, scene.voxel_m, Some(opts.static_threshold))?;
            let (lo, hi) = layers::height_range(&tops).unwrap_or((0.0, 1.0));
            tops.paint(&mut c, &view, layers::ramp(VIRIDIS, lo, hi));
            summary.colour_range = Some([lo as f64, hi as f64]);
            summary.colormap = Some(VIRIDIS.name.into());
            (LegendData::Height { lo, hi }, n)
        }
        What::Lifelong => {
            let (raster, n) = layers::max_eps_g(conn, &view, scene.voxel_m)?;
            let (lo, hi) = (opts.eps_g_range.0 as f32, opts.eps_g_range.1 as f32);
            raster.paint(&mut c, &view, layers::ramp(PLASMA, lo, hi));
            summary.colour_range = Some([lo as f64, hi as f64]);
            summary.colormap = Some(PLASMA.name.into());
            (LegendData::EpsG { lo, hi, threshold: opts.static_threshold as f32 }, n)
        }
        What::Changes => {
            let (ctx, _) = layers::tops(conn, &view, scene.voxel_m, Some(opts.static_threshold))?;
            layers::paint_context(&mut c, &view, &ctx);
            let events = change_events(conn, &view, &window)?;
            let (raster, counts) = layers::changes(&events, &window, &view, scene.voxel_m);
            raster.paint(&mut c, &view, layers::category_colour);
            summary.categories = CATEGORY_STYLES
                .iter()
                .zip(counts)
                .map(|(s, n)| CategoryCount {
                    category: s.category.as_str().into(),
                    label: s.label.into(),
                    colour: s.colour.hex(),
                    events: n,
                })
                .collect();
            (LegendData::Changes { window: scene.window_label(&window), counts }, counts.iter().sum())
        }
        What::Trajectories => {
            let (ctx, _) = layers::tops(conn, &view, scene.voxel_m, Some(opts.static_threshold))?;
            layers::paint_context(&mut c, &view, &ctx);
            let list: Vec<_> = shown.iter().map(|(_, t)| *t).collect();
            layers::trajectories(&mut c, &view, &list, z.line, z.text, |i| session_colour(shown[i].0));
            summary.trajectories = shown
                .iter()
                .map(|(i, t)| TrajectorySummary {
                    session: t.session.0,
                    name: t.name.clone(),
                    keyframes: t.xy_m.len() as u64,
                    length_m: t.length_m,
                    colour: session_colour(*i).hex(),
                    start_xy_m: t.xy_m[0],
                })
                .collect();
            (LegendData::Trajectories { rows: traj_rows }, shown.iter().map(|(_, t)| t.xy_m.len() as u64).sum())
        }
    };
    summary.drawn = drawn;
    summary.sessions = scene.window_label(&window);
    if drawn == 0 {
        let (cx, cy) = ((view.left_px + view.right_px()) as f32 / 2.0, (view.top_px + view.bottom_px()) as f32 / 2.0);
        let msg = match opts.what {
            What::Changes
                if window.from == window.to && Some(window.from) == scene.sessions.first().map(|s| s.session_id) =>
            {
                "no changes: the first session is what later ones are compared with"
            }
            What::Trajectories => "no poses yet: ingest a session",
            _ if scene.map.is_none() => "no map yet: ingest a session (its changes step builds the map)",
            _ => "nothing here: try without --bbox or another --session",
        };
        c.text_halo(cx, cy, z.text, Rgb::MUTED, Align::Centre, msg);
    }

    // Everything around the map (also hides lines that ran past it).
    let (l, t, r, b) = (view.left_px as f32, view.top_px as f32, view.right_px() as f32, view.bottom_px() as f32);
    c.fill_rect(0.0, 0.0, width as f32, t, Rgb::PAPER);
    c.fill_rect(0.0, b, width as f32, height as f32 - b, Rgb::PAPER);
    c.fill_rect(0.0, t, l, b - t, Rgb::PAPER);
    c.fill_rect(r, t, width as f32 - r, b - t, Rgb::PAPER);
    legend::axes(&mut c, &z, &view);
    let (title, subtitle) = titles(scene, opts.what, &window, drawn, opts.static_threshold);
    legend::title(&mut c, &z, z.pad, z.pad * 0.8, &title, &subtitle);
    let legend_x = legend_x.max(r + z.pad);
    draw_legend(&mut c, &z, legend_x, t, legend_w, &legend_data);
    let decor_top = b - decor_h;
    let (after_bar, bar_m) = legend::scale_bar(&mut c, &z, legend_x + 8.0, decor_top, legend_w * 0.85, view.m_per_px);
    legend::frame_arrows(&mut c, &z, legend_x, after_bar + z.pad, &caption);
    summary.scale_bar_m = bar_m;
    Ok(Picture { canvas: c, summary })
}

/// What the frame arrows' caption says.
fn frame_caption(scene: &Scene) -> String {
    format!("world frame ({})", scene.meta.crs)
}

/// Change events whose position lies in the view, from the window's first
/// session on (later sessions are filtered when drawing).
fn change_events(conn: &Connection, view: &View, window: &Window) -> Result<Vec<ChangeEventRow>, RenderError> {
    if !store::has_table(conn, "change_events")? || !store::has_table(conn, "map_tiles")? {
        return Ok(Vec::new());
    }
    Ok(store::change_events_in(conn, &layers::world_box(view), window.from.0)?)
}

impl RenderSummary {
    fn new(what: What, c: &Canvas, view: &View) -> RenderSummary {
        let w = &view.world;
        RenderSummary {
            what: what.as_str().into(),
            path: None,
            width_px: c.width(),
            height_px: c.height(),
            m_per_px: view.m_per_px,
            world_bbox_m: [w.x0, w.y0, w.x1, w.y1],
            map_area_px: [view.left_px as u32, view.top_px as u32, view.width_px, view.height_px],
            scale_bar_m: 0.0,
            drawn: 0,
            sessions: String::new(),
            colormap: None,
            colour_range: None,
            categories: Vec::new(),
            trajectories: Vec::new(),
        }
    }
}
