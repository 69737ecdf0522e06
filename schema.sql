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
