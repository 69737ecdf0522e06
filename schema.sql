-- seam store schema: the single source of truth for seam.db.
--
-- The file is a list of forward migrations. Each starts with a line
-- `-- @migration N` and is applied, in one transaction, to stores whose
-- `PRAGMA user_version` is below N; the transaction also sets user_version to
-- N. A migration, once released, is never edited: changes come as a new one.
--
-- Conventions: poses are stored as 7 REALs (x_m, y_m, z_m, qx, qy, qz, qw);
-- times are UTC ISO-8601 text (`*_at`) or seconds (`*_s`); ids are INTEGER.
-- Rows that reference a Parquet file go through `files`; a file row is only
-- committed after the file is durably renamed into place (see store/mod.rs).

-- @migration 1
CREATE TABLE meta (
    key   TEXT PRIMARY KEY,
    value TEXT NOT NULL
) WITHOUT ROWID;

-- One row per ingested session, numbered 1, 2, ... in ingest order.
CREATE TABLE sessions (
    session_id      INTEGER PRIMARY KEY,
    name            TEXT NOT NULL UNIQUE,
    content_hash    TEXT NOT NULL UNIQUE,   -- blake3 over the files that define the session
    source_dir      TEXT NOT NULL,
    layout          TEXT NOT NULL,          -- kitti | scans-pcd | dynamic-map-benchmark
    date            TEXT,                   -- from session.toml, as given
    sensor_model    TEXT,
    fov_json        TEXT,
    keyframe_count  INTEGER NOT NULL,
    point_count     INTEGER NOT NULL,
    status          TEXT NOT NULL CHECK (status IN ('ingesting', 'complete')),
    created_at      TEXT NOT NULL,
    completed_at    TEXT
);

-- Every immutable Parquet file the store references, with its size and hash
-- so that `seam check` can prove nothing is missing or altered.
CREATE TABLE files (
    file_id     INTEGER PRIMARY KEY,
    rel_path    TEXT NOT NULL UNIQUE,
    kind        TEXT NOT NULL,              -- scans | evidence | cleaned_map | ...
    session_id  INTEGER REFERENCES sessions(session_id),
    size_bytes  INTEGER NOT NULL,
    blake3      TEXT NOT NULL,
    row_count   INTEGER NOT NULL,
    created_at  TEXT NOT NULL
);

-- Submaps cut each session's trajectory by travel distance (MATH.md §1).
CREATE TABLE submaps (
    submap_id       INTEGER PRIMARY KEY,
    session_id      INTEGER NOT NULL REFERENCES sessions(session_id),
    submap_index    INTEGER NOT NULL,       -- 0-based within the session
    first_keyframe  INTEGER NOT NULL,       -- keyframe_index of its first keyframe
    last_keyframe   INTEGER NOT NULL,
    length_m        REAL NOT NULL,          -- odometry travel within the submap
    UNIQUE (session_id, submap_index)
);

-- Keyframes: one scan each, with its odometry pose t_session_keyframe.
CREATE TABLE keyframes (
    keyframe_id     INTEGER PRIMARY KEY,
    session_id      INTEGER NOT NULL REFERENCES sessions(session_id),
    keyframe_index  INTEGER NOT NULL,       -- the scan's index in its session
    source_file     TEXT NOT NULL,          -- scan file name in the session folder
    stamp_s         REAL,
    point_count     INTEGER NOT NULL,
    scan_file_id    INTEGER NOT NULL REFERENCES files(file_id),
    scan_row_group  INTEGER NOT NULL,       -- row group of this scan in its Parquet file
    odom_x_m REAL NOT NULL, odom_y_m REAL NOT NULL, odom_z_m REAL NOT NULL,
    odom_qx  REAL NOT NULL, odom_qy  REAL NOT NULL, odom_qz  REAL NOT NULL, odom_qw REAL NOT NULL,
    submap_id       INTEGER REFERENCES submaps(submap_id),
    UNIQUE (session_id, keyframe_index)
);
CREATE INDEX keyframes_by_submap ON keyframes(submap_id);

-- Every optimisation of the pose graph is a new version; nothing is overwritten,
-- so later steps can tell how each keyframe moved (MATH.md §7).
CREATE TABLE graph_versions (
    graph_version   INTEGER PRIMARY KEY,
    session_id      INTEGER NOT NULL REFERENCES sessions(session_id), -- the ingest that made it
    mode            TEXT NOT NULL,          -- odometry | fixed | session | submap
    created_at      TEXT NOT NULL,
    details_json    TEXT NOT NULL DEFAULT '{}'
);

-- A_m = t_world_submap per graph version.
CREATE TABLE anchor_poses (
    graph_version INTEGER NOT NULL REFERENCES graph_versions(graph_version),
    submap_id     INTEGER NOT NULL REFERENCES submaps(submap_id),
    x_m REAL NOT NULL, y_m REAL NOT NULL, z_m REAL NOT NULL,
    qx  REAL NOT NULL, qy  REAL NOT NULL, qz  REAL NOT NULL, qw REAL NOT NULL,
    PRIMARY KEY (graph_version, submap_id)
) WITHOUT ROWID;

-- p_i = t_submap_keyframe per graph version.
CREATE TABLE local_poses (
    graph_version INTEGER NOT NULL REFERENCES graph_versions(graph_version),
    keyframe_id   INTEGER NOT NULL REFERENCES keyframes(keyframe_id),
    x_m REAL NOT NULL, y_m REAL NOT NULL, z_m REAL NOT NULL,
    qx  REAL NOT NULL, qy  REAL NOT NULL, qz  REAL NOT NULL, qw REAL NOT NULL,
    PRIMARY KEY (graph_version, keyframe_id)
) WITHOUT ROWID;

-- The step log: one row per committed pipeline step of a session's ingest.
-- A step's row is committed in the same transaction as the step's data, so a
-- re-run resumes at the first step without a row.
CREATE TABLE step_log (
    session_id    INTEGER NOT NULL REFERENCES sessions(session_id),
    step          TEXT NOT NULL,
    seq           INTEGER NOT NULL,         -- order of the step in the pipeline
    started_at    TEXT NOT NULL,
    finished_at   TEXT NOT NULL,
    wall_s        REAL NOT NULL,
    details_json  TEXT NOT NULL DEFAULT '{}',
    PRIMARY KEY (session_id, step)
) WITHOUT ROWID;

-- @migration 2
-- Coarse alignment of each session's frame into the world (MATH.md §2).
CREATE TABLE session_alignment (
    session_id        INTEGER PRIMARY KEY REFERENCES sessions(session_id),
    method            TEXT NOT NULL,   -- reference | global | initial_guess | unaligned
    verdict           TEXT NOT NULL CHECK (verdict IN ('success', 'failure')),
    reason            TEXT NOT NULL DEFAULT '',
    x_m REAL NOT NULL, y_m REAL NOT NULL, z_m REAL NOT NULL,   -- t_world_session
    qx  REAL NOT NULL, qy  REAL NOT NULL, qz  REAL NOT NULL, qw REAL NOT NULL,
    correspondences   INTEGER NOT NULL DEFAULT 0,
    inliers           INTEGER NOT NULL DEFAULT 0,
    inlier_ratio      REAL NOT NULL DEFAULT 0,
    overlap_fraction  REAL NOT NULL DEFAULT 0,
    elapsed_s         REAL NOT NULL DEFAULT 0
);

-- Every loop candidate evaluated, accepted or not, with why (MATH.md §3-4):
-- users ask why two sessions did not merge.
CREATE TABLE loop_candidates (
    candidate_id      INTEGER PRIMARY KEY,
    session_id        INTEGER NOT NULL REFERENCES sessions(session_id), -- the ingest that evaluated it
    kind              TEXT NOT NULL CHECK (kind IN ('intra', 'inter')),
    source_keyframe   INTEGER NOT NULL REFERENCES keyframes(keyframe_id),
    target_keyframe   INTEGER NOT NULL REFERENCES keyframes(keyframe_id),
    distance_m        REAL NOT NULL,   -- between the two keyframes in the estimate before GICP
    x_m REAL NOT NULL, y_m REAL NOT NULL, z_m REAL NOT NULL,   -- measured t_target_source
    qx  REAL NOT NULL, qy  REAL NOT NULL, qz  REAL NOT NULL, qw REAL NOT NULL,
    converged         INTEGER NOT NULL,
    iterations        INTEGER NOT NULL,
    inliers           INTEGER NOT NULL,
    fitness           REAL NOT NULL,
    inlier_ratio      REAL NOT NULL,
    rho_scan          REAL,            -- NULL when infinite (degenerate geometry)
    rho_corr          REAL,
    accepted          INTEGER NOT NULL,
    reason            TEXT NOT NULL
);
CREATE INDEX loop_candidates_by_session ON loop_candidates(session_id, accepted);
CREATE INDEX loop_candidates_by_keyframes ON loop_candidates(source_keyframe, target_keyframe);

-- @migration 3
-- Directional evidence, cleaned maps and DOR labels (MATH.md §6-7). Each file
-- is immutable and holds positions on the world grid of the graph version it
-- was generated from; later versions reproject it (eqs. 9-11).
CREATE TABLE evidence_files (
    file_id        INTEGER PRIMARY KEY REFERENCES files(file_id),
    session_id     INTEGER NOT NULL REFERENCES sessions(session_id),
    submap_id      INTEGER REFERENCES submaps(submap_id),   -- NULL for per-session files
    kind           TEXT NOT NULL CHECK (kind IN ('evidence', 'cleaned_map', 'point_labels')),
    graph_version  INTEGER NOT NULL REFERENCES graph_versions(graph_version),
    row_count      INTEGER NOT NULL
);
CREATE INDEX evidence_files_by_session ON evidence_files(session_id, kind);

-- One row per session: what its evidence step generated and removed.
CREATE TABLE session_dor (
    session_id        INTEGER PRIMARY KEY REFERENCES sessions(session_id),
    graph_version     INTEGER NOT NULL REFERENCES graph_versions(graph_version),
    model             TEXT NOT NULL,            -- directional | log_odds
    points            INTEGER NOT NULL,
    dynamic_points    INTEGER NOT NULL,
    interest_voxels   INTEGER NOT NULL,
    generated_voxels  INTEGER NOT NULL,
    dynamic_voxels    INTEGER NOT NULL,
    cleaned_voxels    INTEGER NOT NULL,
    raycast_s         REAL NOT NULL,
    total_s           REAL NOT NULL
);

-- @migration 4
-- Change detection (MATH.md §8). The lifelong map holds every voxel any
-- session's cleaned map ever had, placed on the world grid of the graph
-- version in `map_state` (each ingest moves it to the new version with its
-- owner keyframes' ΔT and re-bins it). The static map is `eps_g < 0.5`.
--
-- Spatial index: two levels. `map_tiles` is an R*Tree of fixed world cubes
-- (`map_state.tile_m`, 4 m), keyed by the tile's packed key; voxels and change
-- events carry their tile, with a B-tree index on it. A box query asks the
-- R*Tree for the tiles, then the B-tree for their rows, then filters exactly.
-- Rewriting the map (it moves with every re-optimisation) then costs B-tree
-- inserts, not one R*Tree insert per voxel (≈8 µs each).
CREATE TABLE map_voxels (
    voxel_id           INTEGER PRIMARY KEY,              -- stable while the voxel lives
    kx                 INTEGER NOT NULL,                 -- key on the world grid, voxel map_state.voxel_m
    ky                 INTEGER NOT NULL,
    kz                 INTEGER NOT NULL,
    tile               INTEGER NOT NULL,                 -- map_tiles id of the centroid
    x_m                REAL NOT NULL,                    -- centroid of its points, world frame (`seam poses`)
    y_m                REAL NOT NULL,
    z_m                REAL NOT NULL,
    eps_g              REAL NOT NULL,                    -- global ephemerality, clamped [0.1, 0.9]
    eps_l              REAL NOT NULL,                    -- ε_l in the last session that saw it
    points             INTEGER NOT NULL,                 -- points behind the centroid, last session that saw it
    first_session      INTEGER NOT NULL REFERENCES sessions(session_id),
    last_seen_session  INTEGER NOT NULL REFERENCES sessions(session_id),
    category           TEXT NOT NULL CHECK (category IN ('initial', 'coexist', 'deleted_overlap',
                           'deleted_non_overlap', 'emerged_overlap', 'emerged_non_overlap')),
    category_session   INTEGER NOT NULL REFERENCES sessions(session_id),  -- session that set `category`
    owner_session      INTEGER NOT NULL REFERENCES sessions(session_id),  -- the voxel moves with this
    owner_keyframe     INTEGER NOT NULL                                   -- keyframe (index in owner_session)
);
CREATE INDEX map_voxels_by_tile ON map_voxels(tile);

-- Fixed world cubes that hold any map voxel or change event, world frame.
CREATE VIRTUAL TABLE map_tiles USING rtree(tile, min_x, max_x, min_y, max_y, min_z, max_z);

-- Where the lifelong map stands: the graph version its positions are on.
CREATE TABLE map_state (
    id             INTEGER PRIMARY KEY CHECK (id = 1),
    graph_version  INTEGER NOT NULL REFERENCES graph_versions(graph_version),
    session_id     INTEGER NOT NULL REFERENCES sessions(session_id),   -- last session folded in
    voxel_m        REAL NOT NULL,
    tile_m         REAL NOT NULL
);

-- Every change a session saw: emerged (either kind) and deleted-with-overlap
-- voxels, a voxel seen again right after a deleted-with-overlap (`coexist`),
-- and the first deleted-non-overlap of a run. Positions are the voxel
-- centroid on the graph version of that session's ingest.
CREATE TABLE change_events (
    event_id       INTEGER PRIMARY KEY,
    session_id     INTEGER NOT NULL REFERENCES sessions(session_id),
    voxel_id       INTEGER NOT NULL,                  -- map_voxels.voxel_id at the time
    tile           INTEGER NOT NULL,                  -- map_tiles id of the position
    x_m            REAL NOT NULL,
    y_m            REAL NOT NULL,
    z_m            REAL NOT NULL,
    category       TEXT NOT NULL CHECK (category IN ('coexist', 'deleted_overlap', 'deleted_non_overlap',
                       'emerged_overlap', 'emerged_non_overlap')),
    eps_g_before   REAL,                              -- NULL: the voxel was new to the map
    eps_g_after    REAL NOT NULL
);
CREATE INDEX change_events_by_tile ON change_events(tile, session_id);
CREATE INDEX change_events_by_session ON change_events(session_id, category);

-- One row per session: its five categories and the map after it.
CREATE TABLE session_changes (
    session_id            INTEGER PRIMARY KEY REFERENCES sessions(session_id),
    graph_version         INTEGER NOT NULL REFERENCES graph_versions(graph_version),
    coexist               INTEGER NOT NULL,
    deleted_overlap       INTEGER NOT NULL,
    deleted_non_overlap   INTEGER NOT NULL,
    emerged_overlap       INTEGER NOT NULL,
    emerged_non_overlap   INTEGER NOT NULL,
    events                INTEGER NOT NULL,
    merged_on_move        INTEGER NOT NULL,    -- map voxels merged when re-binned to this version
    lifelong_voxels       INTEGER NOT NULL,
    static_voxels         INTEGER NOT NULL
);

-- @migration 5
-- Named zones for queries (`seam zones add`, `zone:"Tower B"` in a query),
-- world frame (`seam poses`). A `bbox` zone is its box; a `polygon` zone is
-- a polygon in the xy plane (`polygon_wkt`, `POLYGON((x y, ...))`, holes
-- allowed) between min_z_m and max_z_m, and its min/max are the polygon's
-- bounding box: a query asks the tile R*Tree with them, then tests the
-- polygon.
CREATE TABLE zones (
    zone_id      INTEGER PRIMARY KEY,
    name         TEXT NOT NULL UNIQUE,
    kind         TEXT NOT NULL CHECK (kind IN ('bbox', 'polygon')),
    min_x_m REAL NOT NULL, min_y_m REAL NOT NULL, min_z_m REAL NOT NULL,
    max_x_m REAL NOT NULL, max_y_m REAL NOT NULL, max_z_m REAL NOT NULL,
    polygon_wkt  TEXT,                       -- kind = 'polygon' only
    created_at   TEXT NOT NULL,
    CHECK (min_x_m <= max_x_m AND min_y_m <= max_y_m AND min_z_m <= max_z_m),
    CHECK ((kind = 'polygon') = (polygon_wkt IS NOT NULL))
);

-- Change events in a box, answered from this index alone (`seam query`): the
-- tile and session they are found by, then every other column a query
-- returns, so no row is read from the table (`examples/query_bench.rs`, 1M
-- events: a 50 m box of 80k events 273 → 85 ms, a 20 m box 22 → 3 ms, a
-- count of the whole site 885 → 49 ms; about 75 bytes per event). It
-- replaces change_events_by_tile, its prefix.
DROP INDEX change_events_by_tile;
CREATE INDEX change_events_by_tile_cover
    ON change_events(tile, session_id, x_m, y_m, z_m, category, eps_g_before, eps_g_after, voxel_id);

-- @migration 6
-- The spread of each lifelong voxel's points: their covariance about the
-- centroid (m², world frame of map_state's graph version), as six
-- little-endian float32 `[xx, xy, xz, yy, yz, zz]`. Later sessions' rays must
-- cross the patch it describes to count as seeing the voxel gone
-- (`evidence::surface`). NULL for voxels stored before.
ALTER TABLE map_voxels ADD COLUMN spread_m2 BLOB;
