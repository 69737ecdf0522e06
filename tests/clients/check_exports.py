#!/usr/bin/env python3
"""Open a `seam export` folder with the readers analysts use and check it.

    python3 tests/clients/check_exports.py OUT [--expect EXPECT.json]

pyarrow and DuckDB (from PyPI, no extensions: nothing is downloaded at run
time) read every table of `OUT/_catalog.json`; laspy (with lazrs for LAZ)
reads the LAS export. Checked, per table:

- the schema of every file: the catalog's columns, names in snake_case,
  types (signed integers only, `*_at` timestamps in UTC), and pyarrow and
  DuckDB see the same columns;
- row counts: each file's against its catalog partition, the table's against
  the catalog and against EXPECT (what the Rust test counted in the store),
  through pyarrow and through DuckDB, per Hive `session` partition too;
- the files: zstd, row groups of at most 100,000 rows, sizes as catalogued;
- GeoParquet 1.1 metadata (`geo` in the file's key-value metadata and in the
  schema pyarrow shows): version, primary column, WKB, geometry types, a CRS
  that is a PROJJSON object (never null), the bbox covering, and a file bbox
  that encloses every row's; WKB decodes to the row's x_m/y_m/z_m;
- a bbox query on the covering columns in DuckDB's SQL returns the same rows
  as a pyarrow filter (and, for points, as a filter on x_m/y_m);
- the LAS files: LAS 1.4, the catalogued point count, `eps_g` (float32) and
  `change_class` (uint8) extra dimensions found by name, with the values of
  the Parquet map table row by row.

Exit status: 0 all checks passed, 1 a check failed, 77 a module is missing.
"""

import argparse
import json
import math
import re
import struct
import sys
from pathlib import Path

try:
    import duckdb
    import laspy
    import numpy as np
    import pyarrow as pa
    import pyarrow.compute as pc
    import pyarrow.dataset as ds
    import pyarrow.parquet as pq
except ImportError as e:  # pragma: no cover - the Rust test decides what this means
    print(f"check_exports: missing module: {e.name} (pip install pyarrow duckdb 'laspy[lazrs]')", file=sys.stderr)
    sys.exit(77)

MAX_ROW_GROUP = 100_000
# One column unique per row of each table, to compare query results.
KEYS = {
    "sessions": "session_id",
    "keyframes": "keyframe_id",
    "loop_edges": "candidate_id",
    "map_voxels": "voxel_id",
    "lifelong_map": "voxel_id",
    "static_map": "voxel_id",
    "changes": "event_id",
    "point_labels": None,
}
SIMPLE_TYPES = {
    "int32": pa.int32(),
    "int64": pa.int64(),
    "float32": pa.float32(),
    "float64": pa.float64(),
    "boolean": pa.bool_(),
    "string": pa.string(),
    "binary": pa.binary(),
    "timestamp[us, tz=UTC]": pa.timestamp("us", tz="UTC"),
}

checks = 0


def check(cond, what):
    global checks
    checks += 1
    if not cond:
        raise AssertionError(what)


def expected_type(name):
    if name in SIMPLE_TYPES:
        return SIMPLE_TYPES[name]
    m = re.fullmatch(r"struct<(.*)>", name)
    check(m is not None, f"unknown catalog type {name!r}")
    fields = []
    for part in m.group(1).split(", "):
        n, t = part.split(": ")
        fields.append(pa.field(n, SIMPLE_TYPES[t], nullable=False))
    return pa.struct(fields)


def same_type(got, want):
    if pa.types.is_struct(want):
        return pa.types.is_struct(got) and [(f.name, f.type) for f in got] == [(f.name, f.type) for f in want]
    return got == want


def glob_of(out, table):
    parts = table["partitions"]
    deep = any("session" in p for p in parts)
    return str(out / table["path"] / ("*/*.parquet" if deep else "*.parquet"))


def check_schema(table, path):
    schema = pq.read_schema(path)
    cols = table["columns"]
    check(schema.names == [c["name"] for c in cols], f"{path}: columns {schema.names}")
    for c in cols:
        f = schema.field(c["name"])
        check(re.fullmatch(r"[a-z][a-z0-9_]*", c["name"]) is not None, f"{c['name']}: not snake_case")
        check(same_type(f.type, expected_type(c["type"])), f"{path}: {c['name']} is {f.type}, catalog {c['type']}")
        check(f.nullable == c["nullable"], f"{path}: {c['name']} nullable {f.nullable}")
        check(not pa.types.is_unsigned_integer(f.type), f"{path}: {c['name']} is unsigned")
        if c["name"].endswith("_at"):
            check(pa.types.is_timestamp(f.type) and f.type.tz == "UTC", f"{path}: {c['name']} is {f.type}")
    return schema


def check_file(table, part, out):
    path = out / part["path"]
    check(path.stat().st_size == part["size_bytes"], f"{path}: size differs from the catalog")
    meta = pq.ParquetFile(path).metadata
    check(meta.num_rows == part["row_count"], f"{path}: {meta.num_rows} rows, catalog {part['row_count']}")
    for g in range(meta.num_row_groups):
        rg = meta.row_group(g)
        check(rg.num_rows <= MAX_ROW_GROUP, f"{path}: row group {g} has {rg.num_rows} rows")
        for c in range(rg.num_columns):
            check(rg.column(c).compression == "ZSTD", f"{path}: column {c} is {rg.column(c).compression}")
    if meta.num_rows > MAX_ROW_GROUP:
        check(meta.num_row_groups > 1, f"{path}: {meta.num_rows} rows in one row group")
    schema = check_schema(table, path)
    if table.get("geometry"):
        check_geo(table, path, schema, meta)


def check_geo(table, path, schema, meta):
    kv = meta.metadata or {}
    check(b"geo" in kv, f"{path}: no geo key in the file's key-value metadata")
    geo = json.loads(kv[b"geo"])
    check(schema.metadata is not None and json.loads(schema.metadata[b"geo"]) == geo, f"{path}: schema geo differs")
    check(geo["version"] == "1.1.0", f"{path}: geo version {geo['version']}")
    primary = geo["primary_column"]
    check(primary == "geometry" and primary in schema.names, f"{path}: primary column {primary}")
    col = geo["columns"][primary]
    check(col["encoding"] == "WKB", f"{path}: encoding {col['encoding']}")
    check(pa.types.is_binary(schema.field(primary).type), f"{path}: geometry is {schema.field(primary).type}")
    check(col["geometry_types"] == table["geometry"]["geometry_types"], f"{path}: types {col['geometry_types']}")
    crs = col.get("crs")
    check(isinstance(crs, dict) and crs.get("type"), f"{path}: crs must be a PROJJSON object, got {crs!r}")
    check(crs == table["geometry"]["crs"], f"{path}: crs differs from the catalog")
    cov = col["covering"]["bbox"]
    for k in ("xmin", "ymin", "xmax", "ymax"):
        check(cov[k] == ["bbox", k], f"{path}: covering {k} = {cov[k]}")
    check([f.name for f in schema.field("bbox").type] == ["xmin", "ymin", "xmax", "ymax"], f"{path}: bbox fields")
    t = pq.read_table(path)
    if t.num_rows == 0:
        return
    b = t.column("bbox").combine_chunks()
    valid = b.is_valid()
    lo = [pc.min(pc.filter(b.field(k), valid)).as_py() for k in ("xmin", "ymin")]
    hi = [pc.max(pc.filter(b.field(k), valid)).as_py() for k in ("xmax", "ymax")]
    fb = col["bbox"]
    check(len(fb) == 6, f"{path}: bbox {fb}")
    check([fb[0], fb[1], fb[3], fb[4]] == lo + hi, f"{path}: file bbox {fb} vs rows {lo + hi}")
    # WKB decodes to the row's coordinates.
    wkb = t.column("geometry").combine_chunks()
    names = t.column_names
    for r in range(0, t.num_rows, max(1, t.num_rows // 50)):
        w = wkb[r].as_py()
        if w is None:
            check(not valid[r].as_py(), f"{path}: row {r} has a bbox but no geometry")
            continue
        order, kind = struct.unpack_from("<BI", w)
        check(order == 1 and kind in (1001, 1002), f"{path}: row {r} WKB type {kind}")
        if kind == 1001:
            x, y, z = struct.unpack_from("<3d", w, 5)
            if "x_m" in names:
                want = [t.column(c)[r].as_py() for c in ("x_m", "y_m", "z_m")]
                check([x, y, z] == want, f"{path}: row {r} WKB {x, y, z} vs {want}")
            box = b[r].as_py()
            check(box == {"xmin": x, "ymin": y, "xmax": x, "ymax": y}, f"{path}: row {r} bbox {box}")
        else:
            (n,) = struct.unpack_from("<I", w, 5)
            check(n >= 2 and len(w) == 9 + 24 * n, f"{path}: row {r} LineString of {n} vertices")


def check_table(out, table, expect, con):
    name = table["name"]
    parts = table["partitions"]
    for p in parts:
        check_file(table, p, out)
    total = sum(p["row_count"] for p in parts)
    check(total == table["row_count"], f"{name}: partitions add up to {total}, catalog {table['row_count']}")
    want = expect.get("tables", {}).get(name)
    if want is not None:
        check(table["row_count"] == want, f"{name}: catalog says {table['row_count']} rows, the store {want}")
    for s, n in expect.get("partitions", {}).get(name, {}).items():
        got = [p["row_count"] for p in parts if str(p.get("session")) == s]
        check(got == [n], f"{name}: session {s} has {got} rows, the store {n}")
    if not parts:
        check(total == 0, f"{name}: no files but {total} rows")
        return
    partitioned = table["partition_by"] == ["session"]

    # pyarrow: the whole table as a dataset, Hive partitions as a column.
    dataset = ds.dataset(out / table["path"], format="parquet", partitioning="hive" if partitioned else None)
    t = dataset.to_table()
    check(t.num_rows == total, f"{name}: pyarrow reads {t.num_rows} rows, catalog {total}")
    if partitioned:
        check("session" in t.column_names, f"{name}: no session column from the Hive partitions")
        sessions = pc.value_counts(t.column("session")).to_pylist()
        per = {v["values"]: v["counts"] for v in sessions}
        for p in parts:
            check(per.get(p["session"], 0) == p["row_count"], f"{name}: session {p['session']} via pyarrow")

    # DuckDB: the same table through its own Parquet reader.
    src = f"read_parquet('{glob_of(out, table)}', hive_partitioning = {str(partitioned).lower()})"
    (n,) = con.execute(f"SELECT count(*) FROM {src}").fetchone()
    check(n == total, f"{name}: DuckDB reads {n} rows, catalog {total}")
    described = {r[0]: r[1] for r in con.execute(f"DESCRIBE SELECT * FROM {src}").fetchall()}
    for c in table["columns"]:
        check(c["name"] in described, f"{name}: DuckDB has no column {c['name']}")
        if c["type"].startswith("timestamp"):
            check(described[c["name"]] == "TIMESTAMP WITH TIME ZONE", f"{name}: DuckDB {c['name']} {described[c['name']]}")
        if c["type"] in ("int32", "int64"):
            check(described[c["name"]] in ("INTEGER", "BIGINT"), f"{name}: DuckDB {c['name']} {described[c['name']]}")
    if partitioned:
        rows = con.execute(f"SELECT session, count(*) FROM {src} GROUP BY session").fetchall()
        per = dict(rows)
        for p in parts:
            check(per.get(p["session"], 0) == p["row_count"], f"{name}: session {p['session']} via DuckDB")

    if table.get("geometry") and table["geometry"].get("bbox"):
        check_bbox_query(name, table, t, con, src)


def check_bbox_query(name, table, t, con, src):
    """A box around a middle row, a fifth of the table's extent wide, queried
    on the covering columns: never empty, rarely everything."""
    key = KEYS[name]
    xmin, ymin, _, xmax, ymax, _ = table["geometry"]["bbox"]
    boxes = t.column("bbox").combine_chunks().drop_null().to_pylist()
    mid = boxes[len(boxes) // 2]
    cx, cy = (mid["xmin"] + mid["xmax"]) / 2, (mid["ymin"] + mid["ymax"]) / 2
    hx, hy = max((xmax - xmin) / 10, 0.5), max((ymax - ymin) / 10, 0.5)
    qx, qy = (cx - hx, cx + hx), (cy - hy, cy + hy)
    sql = (
        f"SELECT {key} FROM {src} WHERE bbox.xmax >= ? AND bbox.xmin <= ? AND bbox.ymax >= ? AND bbox.ymin <= ?"
    )
    got = sorted(r[0] for r in con.execute(sql, [qx[0], qx[1], qy[0], qy[1]]).fetchall())
    f = pc.field("bbox", "xmax") >= qx[0]
    f = f & (pc.field("bbox", "xmin") <= qx[1]) & (pc.field("bbox", "ymax") >= qy[0]) & (pc.field("bbox", "ymin") <= qy[1])
    want = sorted(t.filter(f).column(key).to_pylist())
    check(got == want, f"{name}: bbox query: DuckDB {len(got)} rows, pyarrow {len(want)}")
    if "x_m" in t.column_names:
        x, y = t.column("x_m"), t.column("y_m")
        inside = pc.and_(
            pc.and_(pc.greater_equal(x, qx[0]), pc.less_equal(x, qx[1])),
            pc.and_(pc.greater_equal(y, qy[0]), pc.less_equal(y, qy[1])),
        )
        by_xy = sorted(t.filter(inside).column(key).to_pylist())
        check(got == by_xy, f"{name}: bbox query {len(got)} rows, x_m/y_m filter {len(by_xy)}")
    check(len(got) > 0, f"{name}: a box around row {len(boxes) // 2} holds nothing")
    print(f"  {name}: bbox query returned {len(got)} of {t.num_rows} rows in both readers")


def check_las(out, catalog, expect):
    las = catalog["las"]
    codes = {v: int(k) for k, v in las["extra_bytes"][1]["codes"].items()}
    tables = {t["name"]: t for t in catalog["tables"]}
    source = tables.get("map_voxels") or tables.get("lifelong_map")
    rows = None
    if source and source["partitions"]:
        rows = pq.read_table(out / source["partitions"][0]["path"], columns=["x_m", "y_m", "z_m", "eps_g", "category"])
    for f in las["files"]:
        path = out / f["path"]
        check(path.stat().st_size == f["size_bytes"], f"{path}: size differs from the catalog")
        data = laspy.read(path)
        h = data.header
        check((h.version.major, h.version.minor) == (1, 4), f"{path}: LAS {h.version}")
        check(h.point_format.id in (6, 7), f"{path}: point format {h.point_format.id}")
        check(h.point_count == f["point_count"], f"{path}: {h.point_count} points, catalog {f['point_count']}")
        want = expect.get("las", {}).get(f["name"])
        if want is not None:
            check(h.point_count == want, f"{path}: {h.point_count} points, the store {want}")
        dims = {d.name: d for d in data.point_format.extra_dimensions}
        check(set(dims) == {"eps_g", "change_class"}, f"{path}: extra dimensions {sorted(dims)}")
        check(np.dtype(dims["eps_g"].dtype) == np.float32, f"{path}: eps_g is {dims['eps_g'].dtype}")
        check(np.dtype(dims["change_class"].dtype) == np.uint8, f"{path}: change_class is {dims['change_class'].dtype}")
        vlrs = {(v.user_id, v.record_id): v for v in h.vlrs}
        check(("LASF_Spec", 4) in vlrs, f"{path}: no Extra Bytes VLR")
        check(("seam", 1) in vlrs, f"{path}: no change_class code table VLR")
        check(f["has_crs"] == (("LASF_Projection", 2112) in vlrs), f"{path}: WKT record vs catalog has_crs")
        if rows is None:
            continue
        keep = np.ones(rows.num_rows, dtype=bool)
        if f.get("filter"):
            m = re.fullmatch(r"eps_g < ([0-9.eE+-]+)", f["filter"])
            check(m is not None, f"{path}: filter {f['filter']}")
            keep = np.asarray(rows.column("eps_g")) < np.float32(float(m.group(1)))
        sel = rows.filter(pa.array(keep))
        check(len(data.points) == sel.num_rows, f"{path}: {len(data.points)} points, {sel.num_rows} map rows")
        if sel.num_rows == 0:
            continue
        check(np.array_equal(np.asarray(data.eps_g), np.asarray(sel.column("eps_g"))), f"{path}: eps_g differs")
        classes = np.array([codes[c] for c in sel.column("category").to_pylist()], dtype=np.uint8)
        check(np.array_equal(np.asarray(data.change_class), classes), f"{path}: change_class differs")
        tol = f["scale_m"] / 2 + 1e-9
        for a in ("x", "y", "z"):
            d = np.abs(np.asarray(getattr(data, a)) - np.asarray(sel.column(f"{a}_m")))
            check(float(d.max()) <= tol, f"{path}: {a} off by {d.max()} (scale {f['scale_m']})")
        print(f"  las/{path.name}: {h.point_count} points, eps_g and change_class equal the Parquet rows")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("--expect", type=Path, help="JSON of row counts the store holds")
    a = ap.parse_args()
    catalog = json.loads((a.out / "_catalog.json").read_text())
    expect = json.loads(a.expect.read_text()) if a.expect else {}
    check(catalog["geoparquet_version"] == "1.1.0", "catalog geoparquet_version")
    names = [t["name"] for t in catalog["tables"]]
    for name in expect.get("tables", {}):
        check(name in names, f"{name}: not in the catalog ({names})")
    con = duckdb.connect()
    print(f"check_exports: pyarrow {pa.__version__}, duckdb {duckdb.__version__}, laspy {laspy.__version__}")
    for table in catalog["tables"]:
        check_table(a.out, table, expect, con)
        print(f"  {table['name']}: {table['row_count']} rows in {len(table['partitions'])} files read by both")
    if expect.get("las"):
        check("las" in catalog, "no las section in the catalog")
    if "las" in catalog:
        check_las(a.out, catalog, expect)
    print(f"check_exports: {checks} passed, 0 failed")


if __name__ == "__main__":
    try:
        main()
    except AssertionError as e:
        print(f"check_exports: FAILED after {checks} checks: {e}", file=sys.stderr)
        sys.exit(1)
