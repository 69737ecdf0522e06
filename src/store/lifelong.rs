//! Rows of the lifelong map, its placement, change events and per-session
//! change summaries (schema migration 4, MATH.md §8).
//!
//! Spatial index (see `schema.sql`): an R*Tree of fixed 4 m world tiles
//! (`map_tiles`), and a `tile` column with a B-tree index on both tables. A
//! box query is two index lookups and an exact filter:
//!
//! ```sql
//! SELECT e.* FROM map_tiles t JOIN change_events e ON e.tile = t.tile
//! WHERE t.min_x <= :x1 AND t.max_x >= :x0 AND ...          -- tiles meeting the box
//!   AND e.x_m BETWEEN :x0 AND :x1 AND ... AND e.session_id >= :since
//! ```

use super::rows::e;
use super::{SessionId, StoreError};
use crate::change::{Category, ChangeEvent, LifelongMap, MapVoxel, SessionChanges};
use crate::geometry::{Sym3, UNKNOWN_SPREAD, VoxelKey};
use rusqlite::{Connection, OptionalExtension, params};

/// Edge of the fixed world tiles of the spatial index, metres.
pub const TILE_M: f64 = 4.0;

/// The tile id of a world position: its packed tile key.
fn tile_of(p: &[f64; 3]) -> i64 {
    crate::evidence::grid::packed_key(p, TILE_M).map_or(-1, |k| k as i64)
}

/// Adds the R*Tree rows of tiles not yet indexed.
fn index_tiles(conn: &Connection, tiles: impl IntoIterator<Item = i64>) -> Result<(), StoreError> {
    let mut have: std::collections::HashSet<i64> = std::collections::HashSet::new();
    {
        let mut st = conn.prepare("SELECT tile FROM map_tiles").map_err(e(conn))?;
        for t in st.query_map([], |r| r.get::<_, i64>(0)).map_err(e(conn))? {
            have.insert(t.map_err(e(conn))?);
        }
    }
    let mut ins = conn.prepare("INSERT INTO map_tiles VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7)").map_err(e(conn))?;
    for t in tiles {
        if t < 0 || !have.insert(t) {
            continue;
        }
        let k = crate::evidence::grid::unpack(t as u64).0.map(|c| c as f64 * TILE_M);
        ins.execute(params![t, k[0], k[0] + TILE_M, k[1], k[1] + TILE_M, k[2], k[2] + TILE_M]).map_err(e(conn))?;
    }
    Ok(())
}

/// Where the lifelong map stands.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MapState {
    /// The graph version its positions are on.
    pub graph_version: i64,
    /// The last session folded in.
    pub session_id: SessionId,
    pub voxel_m: f64,
}

/// An axis-aligned box in the world frame, metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WorldBox {
    pub min_m: [f64; 3],
    pub max_m: [f64; 3],
}

impl WorldBox {
    /// Everything.
    pub const ALL: WorldBox = WorldBox { min_m: [f64::MIN; 3], max_m: [f64::MAX; 3] };
}

fn category(conn: &Connection, s: &str) -> Result<Category, StoreError> {
    Category::parse(s).ok_or_else(|| StoreError::Corrupt {
        path: conn.path().map(std::path::PathBuf::from).unwrap_or_default(),
        message: format!("unknown change category {s:?} in the database"),
    })
}

pub fn map_state(conn: &Connection) -> Result<Option<MapState>, StoreError> {
    conn.query_row("SELECT graph_version, session_id, voxel_m FROM map_state WHERE id = 1", [], |r| {
        Ok(MapState { graph_version: r.get(0)?, session_id: SessionId(r.get(1)?), voxel_m: r.get(2)? })
    })
    .optional()
    .map_err(e(conn))
}

const VOXEL_COLUMNS: &str = "voxel_id, kx, ky, kz, x_m, y_m, z_m, eps_g, eps_l, points, first_session, \
     last_seen_session, category, category_session, owner_session, owner_keyframe, spread_m2";

/// `spread_m2` as stored: six little-endian float32, or NULL.
fn spread_to_blob(s: &Sym3) -> Option<Vec<u8>> {
    s.iter().all(|c| c.is_finite()).then(|| s.iter().flat_map(|c| c.to_le_bytes()).collect())
}

fn spread_from_blob(b: Option<Vec<u8>>) -> Sym3 {
    match b {
        Some(b) if b.len() == 24 => {
            std::array::from_fn(|i| f32::from_le_bytes([b[4 * i], b[4 * i + 1], b[4 * i + 2], b[4 * i + 3]]))
        }
        _ => UNKNOWN_SPREAD,
    }
}

fn voxel_row(r: &rusqlite::Row<'_>) -> rusqlite::Result<(MapVoxel, String)> {
    Ok((
        MapVoxel {
            voxel_id: r.get(0)?,
            key: VoxelKey([r.get(1)?, r.get(2)?, r.get(3)?]),
            xyz_m: [r.get(4)?, r.get(5)?, r.get(6)?],
            eps_g: r.get::<_, f64>(7)? as f32,
            eps_l: r.get::<_, f64>(8)? as f32,
            points: r.get(9)?,
            first_session: r.get(10)?,
            last_seen_session: r.get(11)?,
            category: Category::Initial,
            category_session: r.get(13)?,
            owner_session: r.get(14)?,
            owner_keyframe: r.get(15)?,
            spread_m2: spread_from_blob(r.get(16)?),
        },
        r.get(12)?,
    ))
}

fn collect_voxels(conn: &Connection, sql: &str, args: impl rusqlite::Params) -> Result<Vec<MapVoxel>, StoreError> {
    let mut st = conn.prepare(sql).map_err(e(conn))?;
    let rows = st.query_map(args, voxel_row).map_err(e(conn))?;
    let mut out = Vec::new();
    for r in rows {
        let (mut v, c) = r.map_err(e(conn))?;
        v.category = category(conn, &c)?;
        out.push(v);
    }
    Ok(out)
}

/// The whole lifelong map (empty before the first session's changes step).
pub fn read_lifelong_map(conn: &Connection) -> Result<LifelongMap, StoreError> {
    let Some(state) = map_state(conn)? else { return Ok(LifelongMap::default()) };
    let voxels = collect_voxels(conn, &format!("SELECT {VOXEL_COLUMNS} FROM map_voxels"), [])?;
    Ok(LifelongMap::from_voxels(voxels, state.voxel_m).0)
}

/// Map voxels whose centroid lies in `b`, by id. `static_below`: only those
/// with ε_g below it (the static map).
pub fn map_voxels_in(conn: &Connection, b: &WorldBox, static_below: Option<f64>) -> Result<Vec<MapVoxel>, StoreError> {
    let cols = VOXEL_COLUMNS.split(", ").map(|c| format!("v.{c}")).collect::<Vec<_>>().join(", ");
    let sql = format!(
        "SELECT {cols} FROM map_tiles t JOIN map_voxels v ON v.tile = t.tile
         WHERE t.min_x <= ?4 AND t.max_x >= ?1 AND t.min_y <= ?5 AND t.max_y >= ?2
           AND t.min_z <= ?6 AND t.max_z >= ?3
           AND v.x_m BETWEEN ?1 AND ?4 AND v.y_m BETWEEN ?2 AND ?5 AND v.z_m BETWEEN ?3 AND ?6 AND v.eps_g < ?7
         ORDER BY v.voxel_id"
    );
    let (lo, hi) = (b.min_m, b.max_m);
    collect_voxels(conn, &sql, params![lo[0], lo[1], lo[2], hi[0], hi[1], hi[2], static_below.unwrap_or(f64::MAX)])
}

/// Replaces the lifelong map and its placement (the map moves as a whole
/// with every re-optimisation, so it is rewritten; tiles are fixed and only
/// added).
pub fn replace_lifelong_map(
    conn: &Connection,
    map: &LifelongMap,
    graph_version: i64,
    session: SessionId,
) -> Result<(), StoreError> {
    // Dropping the index before the bulk insert and building it after is
    // cheaper than keeping it up to date row by row.
    conn.execute_batch("DROP INDEX map_voxels_by_tile; DELETE FROM map_voxels;").map_err(e(conn))?;
    let mut ins = conn
        .prepare(&format!(
            "INSERT INTO map_voxels({VOXEL_COLUMNS}, tile)
             VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11, ?12, ?13, ?14, ?15, ?16, ?17, ?18)"
        ))
        .map_err(e(conn))?;
    let v = map.voxel_m;
    let mut tiles = Vec::with_capacity(map.len() / 64);
    for x in &map.voxels {
        let k = x.key.0;
        let tile = tile_of(&x.xyz_m);
        if tiles.last() != Some(&tile) {
            tiles.push(tile);
        }
        ins.execute(params![
            x.voxel_id,
            k[0],
            k[1],
            k[2],
            x.xyz_m[0],
            x.xyz_m[1],
            x.xyz_m[2],
            x.eps_g as f64,
            x.eps_l as f64,
            x.points,
            x.first_session,
            x.last_seen_session,
            x.category.as_str(),
            x.category_session,
            x.owner_session,
            x.owner_keyframe,
            spread_to_blob(&x.spread_m2),
            tile,
        ])
        .map_err(e(conn))?;
    }
    conn.execute_batch("CREATE INDEX map_voxels_by_tile ON map_voxels(tile);").map_err(e(conn))?;
    tiles.sort_unstable();
    tiles.dedup();
    index_tiles(conn, tiles)?;
    conn.execute(
        "INSERT OR REPLACE INTO map_state(id, graph_version, session_id, voxel_m, tile_m) VALUES (1, ?1, ?2, ?3, ?4)",
        params![graph_version, session.0, v, TILE_M],
    )
    .map_err(e(conn))?;
    Ok(())
}

/// Adds a session's change events (ids assigned by SQLite) and indexes
/// their tiles.
pub fn insert_change_events(conn: &Connection, events: &[ChangeEvent]) -> Result<(), StoreError> {
    let mut ins = conn
        .prepare(
            "INSERT INTO change_events(session_id, voxel_id, tile, x_m, y_m, z_m, category, eps_g_before, eps_g_after)
             VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9)",
        )
        .map_err(e(conn))?;
    let mut tiles = Vec::new();
    for ev in events {
        let tile = tile_of(&ev.xyz_m);
        tiles.push(tile);
        ins.execute(params![
            ev.session_id,
            ev.voxel_id,
            tile,
            ev.xyz_m[0],
            ev.xyz_m[1],
            ev.xyz_m[2],
            ev.category.as_str(),
            ev.eps_g_before.map(|v| v as f64),
            ev.eps_g_after as f64,
        ])
        .map_err(e(conn))?;
    }
    tiles.sort_unstable();
    tiles.dedup();
    index_tiles(conn, tiles)
}

/// A stored change event with its id.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ChangeEventRow {
    pub event_id: i64,
    pub event: ChangeEvent,
}

/// Change events positioned in `b` from session `since` on (inclusive), by id.
pub fn change_events_in(conn: &Connection, b: &WorldBox, since: i64) -> Result<Vec<ChangeEventRow>, StoreError> {
    let mut st = conn
        .prepare(
            "SELECT e.event_id, e.session_id, e.voxel_id, e.x_m, e.y_m, e.z_m, e.category, e.eps_g_before, e.eps_g_after
             FROM map_tiles t JOIN change_events e ON e.tile = t.tile
             WHERE t.min_x <= ?4 AND t.max_x >= ?1 AND t.min_y <= ?5 AND t.max_y >= ?2
               AND t.min_z <= ?6 AND t.max_z >= ?3 AND e.session_id >= ?7
               AND e.x_m BETWEEN ?1 AND ?4 AND e.y_m BETWEEN ?2 AND ?5 AND e.z_m BETWEEN ?3 AND ?6
             ORDER BY e.event_id",
        )
        .map_err(e(conn))?;
    let (lo, hi) = (b.min_m, b.max_m);
    let rows = st
        .query_map(params![lo[0], lo[1], lo[2], hi[0], hi[1], hi[2], since], |r| {
            Ok((
                r.get::<_, i64>(0)?,
                r.get::<_, i64>(1)?,
                r.get::<_, i64>(2)?,
                [r.get::<_, f64>(3)?, r.get(4)?, r.get(5)?],
                r.get::<_, String>(6)?,
                r.get::<_, Option<f64>>(7)?,
                r.get::<_, f64>(8)?,
            ))
        })
        .map_err(e(conn))?;
    let mut out = Vec::new();
    for r in rows {
        let (event_id, session_id, voxel_id, xyz_m, c, before, after) = r.map_err(e(conn))?;
        out.push(ChangeEventRow {
            event_id,
            event: ChangeEvent {
                session_id,
                voxel_id,
                xyz_m,
                category: category(conn, &c)?,
                eps_g_before: before.map(|v| v as f32),
                eps_g_after: after as f32,
            },
        });
    }
    Ok(out)
}

pub fn insert_session_changes(
    conn: &Connection,
    session: SessionId,
    graph_version: i64,
    c: &SessionChanges,
) -> Result<(), StoreError> {
    conn.execute(
        "INSERT OR REPLACE INTO session_changes(session_id, graph_version, coexist, deleted_overlap,
             deleted_non_overlap, emerged_overlap, emerged_non_overlap, events, merged_on_move,
             lifelong_voxels, static_voxels)
         VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11)",
        params![
            session.0,
            graph_version,
            c.coexist as i64,
            c.deleted_overlap as i64,
            c.deleted_non_overlap as i64,
            c.emerged_overlap as i64,
            c.emerged_non_overlap as i64,
            c.events as i64,
            c.merged_on_move as i64,
            c.lifelong_voxels as i64,
            c.static_voxels as i64,
        ],
    )
    .map_err(e(conn))?;
    Ok(())
}

/// Every session's change summary, by session.
pub fn session_changes(conn: &Connection) -> Result<Vec<(SessionId, SessionChanges)>, StoreError> {
    let mut st = conn
        .prepare(
            "SELECT session_id, coexist, deleted_overlap, deleted_non_overlap, emerged_overlap, emerged_non_overlap,
                    events, merged_on_move, lifelong_voxels, static_voxels
             FROM session_changes ORDER BY session_id",
        )
        .map_err(e(conn))?;
    let rows = st
        .query_map([], |r| {
            let n = |i: usize| r.get::<_, i64>(i).map(|v| v as usize);
            Ok((
                SessionId(r.get(0)?),
                SessionChanges {
                    coexist: n(1)?,
                    deleted_overlap: n(2)?,
                    deleted_non_overlap: n(3)?,
                    emerged_overlap: n(4)?,
                    emerged_non_overlap: n(5)?,
                    events: n(6)?,
                    merged_on_move: n(7)?,
                    lifelong_voxels: n(8)?,
                    static_voxels: n(9)?,
                },
            ))
        })
        .map_err(e(conn))?;
    rows.collect::<Result<_, _>>().map_err(e(conn))
}

/// Positions (world frame of the session's own graph version) of session
/// `session`'s change events in `categories`, by event id.
pub fn session_event_positions(
    conn: &Connection,
    session: SessionId,
    categories: &[Category],
) -> Result<Vec<[f64; 3]>, StoreError> {
    let mut st = conn
        .prepare_cached(
            "SELECT x_m, y_m, z_m FROM change_events WHERE session_id = ?1 AND category = ?2 ORDER BY event_id",
        )
        .map_err(e(conn))?;
    let mut out = Vec::new();
    for c in categories {
        let rows = st
            .query_map(params![session.0, c.as_str()], |r| Ok([r.get::<_, f64>(0)?, r.get(1)?, r.get(2)?]))
            .map_err(e(conn))?;
        for r in rows {
            out.push(r.map_err(e(conn))?);
        }
    }
    Ok(out)
}

/// How many change events of session `session` are in `category`.
pub fn session_event_count(conn: &Connection, session: SessionId, category: Category) -> Result<usize, StoreError> {
    conn.query_row(
        "SELECT count(*) FROM change_events WHERE session_id = ?1 AND category = ?2",
        params![session.0, category.as_str()],
        |r| r.get::<_, i64>(0),
    )
    .map(|n| n as usize)
    .map_err(e(conn))
}
