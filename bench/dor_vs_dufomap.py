#!/usr/bin/env python3
"""Dynamic object removal: seam (directional evidence), seam-scalar (log-odds
baseline) and DUFOMap on the same scans, scored by ONE scorer, `seam eval dor`.

Usage (from the project root, after `pip install dufomap numpy`):

    python3 bench/dor_vs_dufomap.py [--kitti 04,08] [--sensors os1-64,hdl-64e,vlp16,hdl-32e,avia]
        [--keyframes 60] [--seed 1] [--dufomap "0.1,0.2,1;0.1,0.2,2;0.2,0.2,1"] [--threads 2]
        [--seam target/release/seam] [--no-build] [--out DIR] [--json results.json] [--repeat 1] [--selfcheck]

Datasets: SemanticKITTI sequences (`--kitti-root`, default ../shared/data/semantickitti
relative to the project root; KITTI layout with labels/NNNNNN.label), and one
simulated session per sensor model (`seam simulate OUT --sessions 1 --sensor S
--keyframes N --seed SEED`, which writes labels too).

Per dataset:

1. `seam init` + `seam ingest` into a fresh store with the default config
   ("seam", directional evidence with the surface free test and the growth
   step), into another with `[evidence] model = "log_odds"` ("seam-scalar",
   same rays, test and growth), into a third with `[evidence] free_test =
   "voxel"` ("seam voxel-rule": the paper's rule, every voxel a ray crosses
   is free), and into a fourth with CEILING_TOML ("any-free-ray ceiling": a
   point is removed as soon as any ray of another keyframe crossed its
   voxel, with rays to every point, no guard, no clearance, no surface
   test, no weighing against hits and no growth or footing step). That
   row's PR is meaningless; its RR is the share of moving points that any method
   removing only space some ray saw empty can reach at 0.2 m, and
   2·RR/(1+RR) the F1 it allows at a PR of 100 %.
2. `seam poses STORE --session NAME --format kitti` (and `--format json`
   for the keyframe indices) of the seam store: the LiDAR world poses DUFOMap
   gets, so both see the same scans at the same poses.
3. DUFOMap (`dufomap(resolution, d_s, d_p)`, `run(scan, pose,
   cloud_transform=True)` per keyframe, `oncePropagateCluster(if_propagate=True,
   if_cluster=False)`, `segment(scan, pose, cloud_transform=True)` per keyframe:
   the sequence of DUFOMap's own Python example). Timed wall clock over run +
   propagate + segment (scans preloaded), on `--threads` threads.
   Its labels are written as PRED/labels/NNNNNN.label (252 = dynamic, 0 =
   static) and scored with `seam eval dor STORE --labels DIR --predicted PRED`,
   against the same truth, positions and voxels as seam's own labels.

Speed: points/s is the session's points over seam's `evidence` step wall
time (`evidence_s` of `seam eval dor`: reading the scans, ray casting, DOR,
writing its files) and over DUFOMap's run + propagate + segment wall time,
which has the scans preloaded and writes nothing. "mem pts/s" puts seam on
DUFOMap's footing: the same step without reading the scans and writing
files (`in_memory_s` of `seam eval dor`, the step log's `generate_s`: ray
casting, evidence, DOR and the cleaned map, all in memory). Both get
`--threads` threads (default 2, this machine's cores): DUFOMap's `num_threads`, and seam's rayon
pool through RAYON_NUM_THREADS (0: each picks all cores). The seam binary is
copied into the work folder first, so a concurrent `cargo build` cannot swap
it mid-run.

DUFOMap settings (`--dufomap`, `resolution,d_s,d_p;...`): DUFOMap's own
defaults are resolution 0.1 m, d_s (inflate_hits_dist) 0.2 m, d_p
(inflate_unknown, in voxels) 1 (assets/config.toml of KTH-RPL/dufomap, the
paper's default); its Python example main.py (and DynamicMap_Benchmark's)
uses d_p = 2. The default runs both, and resolution 0.2 m (seam's voxel)
with d_p = 1.

`--selfcheck` also scores every DUFOMap run in Python (same definitions as
`seam::eval::dor`: point-wise, and voxel-wise at 0.2 m with majority votes,
ties to dynamic/removed) and prints the largest difference to `seam eval
dor`. A seam binary without `seam eval dor` gets the Python numbers for
DUFOMap (rows marked "py") and n/a for seam.
"""

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path

from benchcommon import BUSY_FLAG, OtherLoad, SeamError, log, seam_in_work

import numpy as np

os.environ.setdefault("GLOG_minloglevel", "1")  # DUFOMap logs its settings at INFO on every construction
try:
    from dufomap import dufomap as Dufomap
except ImportError:  # checked in main(): dor_ablation.py imports this module and needs no DUFOMap
    Dufomap = None

ROOT = Path(__file__).resolve().parents[1]
MOVING = (252, 259)
REMOVED_LABEL = 252
VOXEL_M = 0.2
SCALAR_TOML = '[evidence]\nmodel = "log_odds"\n'
# seam without its surface free test: the paper's voxel rule (every voxel a
# ray crosses is free), to measure what the test buys.
VOXEL_TOML = '[evidence]\nfree_test = "voxel"\n'
# Every voxel any ray of another keyframe crossed is dynamic: ε_l > 0 iff the
# voxel has free evidence (ω's floor 1 so one direction counts; the lower
# clamp 0 so τ_dyn just above 0 separates f = 0 from f > 0).
CEILING_TOML = ('[evidence]\nfree_test = "voxel"\none_ray_per_voxel = false\nfree_guard_voxels = 0\nfree_guard_deg = 0\n'
                'free_clearance_m = 0\nomega_floor = 1\neps_min = 0\ntau_dyn = 0.000001\ngrow_max_hits = 0\n'
                'cluster_share = 0\nfooting_height_m = 0\nown_no_return_range_m = 0\nchange_once_min_frees = 0\n')
SENSORS = "os1-64,hdl-64e,vlp16,hdl-32e,avia"
DUFOMAP_DEFAULT = "0.1,0.2,1;0.1,0.2,2;0.2,0.2,1"


class Seam:
    """The seam CLI: one subprocess per command, stderr kept for errors."""

    def __init__(self, exe, threads=0):
        self.exe = str(exe)
        self.env = dict(os.environ)
        if threads > 0:  # seam's parallel steps run on rayon's global pool
            self.env["RAYON_NUM_THREADS"] = str(threads)

    def run(self, *args, config=None, fmt=None):
        cmd = [self.exe, "--quiet"]
        if config:
            cmd += ["--config", str(config)]
        if fmt:
            cmd += ["--format", fmt]
        cmd += [str(a) for a in args]
        p = subprocess.run(cmd, capture_output=True, text=True, env=self.env)
        if p.returncode != 0:
            raise SeamError(f"{p.stderr.strip() or '(nothing on stderr)'}\n[`{' '.join(cmd)}` exited with {p.returncode}]")
        return p.stdout

    def json(self, *args, config=None):
        out = self.run(*args, config=config, fmt="json")
        try:
            return json.loads(out)
        except json.JSONDecodeError as e:
            raise SeamError(f"`seam {' '.join(map(str, args))}` printed no JSON ({e}):\n{out[:500]}") from e

    def has_eval_dor(self):
        p = subprocess.run([self.exe, "eval", "dor", "--help"], capture_output=True, text=True)
        return p.returncode == 0


# ---------------------------------------------------------------- scoring in Python (selfcheck)


def is_moving(labels):
    c = labels & 0xFFFF
    return (c >= MOVING[0]) & (c <= MOVING[1])


def ratio(n, d):
    return n / d if d > 0 else None


def block(dynamic, removed):
    """A DorBlock (seam::eval::dor) from per-item truth and prediction."""
    dynamic = np.asarray(dynamic, bool)
    removed = np.asarray(removed, bool)
    st = int((~dynamic).sum())
    dt = int(dynamic.sum())
    sk = int((~dynamic & ~removed).sum())
    dr = int((dynamic & removed).sum())
    rt = int(removed.sum())
    pr, rr = ratio(sk, st), ratio(dr, dt)
    if pr is None or rr is None:
        f1 = aa = None
    else:
        f1 = 2 * pr * rr / (pr + rr) if pr + rr > 0 else 0.0
        aa = float(np.sqrt(pr * rr))
    return {
        "static_total": st, "dynamic_total": dt, "static_kept": sk, "dynamic_removed": dr, "removed_total": rt,
        "pr": pr, "rr": rr, "f1": f1, "sa": pr, "da": rr, "aa": aa, "ha": f1,
        "precision_of_removal": ratio(dr, rt),
    }


def voxel_codes(world, voxel):
    k = np.floor(world / voxel).astype(np.int64) + (1 << 20)
    if k.size and (k.min() < 0 or k.max() >= (1 << 21)):
        raise ValueError("selfcheck: points beyond ±200 km of the origin; cannot pack voxel keys")
    return (k[:, 0] << 42) | (k[:, 1] << 21) | k[:, 2]


def score_py(scans, poses, truths, removeds, voxel=VOXEL_M):
    """Point-wise and voxel-wise scores; voxels pooled over all keyframes,
    majority votes with ties to dynamic / removed (as seam::eval::dor)."""
    codes = np.concatenate([voxel_codes(pts.astype(np.float64) @ T[:3, :3].T + T[:3, 3], voxel)
                            for pts, T in zip(scans, poses)])
    dyn = np.concatenate(truths)
    rem = np.concatenate(removeds)
    _, inv = np.unique(codes, return_inverse=True)
    total = np.bincount(inv)
    vd = np.bincount(inv, weights=dyn)
    vr = np.bincount(inv, weights=rem)
    return {"voxel_m": voxel, "point": block(dyn, rem), "voxel": block(2 * vd >= total, 2 * vr >= total)}


def same_counts(a, b):
    keys = ("static_total", "dynamic_total", "static_kept", "dynamic_removed", "removed_total")
    return all(a[blk][k] == b[blk][k] for blk in ("point", "voxel") for k in keys)


def max_rate_diff(a, b):
    keys = ("pr", "rr", "f1", "precision_of_removal")
    d = 0.0
    for blk in ("point", "voxel"):
        for k in keys:
            x, y = a[blk][k], b[blk][k]
            if (x is None) != (y is None):
                return float("inf")
            if x is not None:
                d = max(d, abs(x - y))
    return d


# ---------------------------------------------------------------- data


def read_poses(seam, store, session):
    """World LiDAR poses (4x4) of the session's keyframes and their indices."""
    rows = seam.run("poses", store, "--session", session, fmt="kitti").split()
    mats = np.array([float(v) for v in rows]).reshape(-1, 3, 4)
    poses = np.tile(np.eye(4), (len(mats), 1, 1))
    poses[:, :3, :] = mats
    index = [int(r["keyframe"]) for r in seam.json("poses", store, "--session", session)]
    if len(index) != len(poses):
        raise SeamError(f"seam poses printed {len(poses)} KITTI rows but {len(index)} JSON rows")
    return index, poses


def load_session(dir_, keyframes):
    """Scans (Nx3 float32, sensor frame) and truth (moving flags) per keyframe."""
    bins = sorted((dir_ / "velodyne").glob("*.bin"))
    scans, truths = [], []
    for k in keyframes:
        if k >= len(bins):
            raise SystemExit(f"dor_vs_dufomap: keyframe {k} but {dir_ / 'velodyne'} has {len(bins)} scans")
        pts = np.fromfile(bins[k], dtype="<f4").reshape(-1, 4)[:, :3]
        lab_path = dir_ / "labels" / (bins[k].stem + ".label")
        if not lab_path.is_file():
            raise SystemExit(f"dor_vs_dufomap: {lab_path} is missing; every scan needs its SemanticKITTI label file")
        lab = np.fromfile(lab_path, dtype="<u4")
        if len(lab) != len(pts):
            raise SystemExit(f"dor_vs_dufomap: {lab_path} has {len(lab)} labels for {len(pts)} points")
        scans.append(np.ascontiguousarray(pts))
        truths.append(is_moving(lab))
    return scans, truths


# ---------------------------------------------------------------- methods


def run_dufomap(scans, poses, res, d_s, d_p, threads):
    m = Dufomap(res, d_s, d_p, num_threads=threads)
    other = OtherLoad()
    c0 = time.process_time()  # CPU of all threads of this process
    t0 = time.perf_counter()
    for pts, T in zip(scans, poses):
        m.run(pts, T, cloud_transform=True)
    t1 = time.perf_counter()
    m.oncePropagateCluster(if_propagate=True, if_cluster=False)
    t2 = time.perf_counter()
    labels = [m.segment(pts, T, cloud_transform=True).astype(bool) for pts, T in zip(scans, poses)]
    t3 = time.perf_counter()
    cpu = time.process_time() - c0
    busy = other.cores()
    del m
    return labels, {"run_s": t1 - t0, "propagate_s": t2 - t1, "segment_s": t3 - t2, "total_s": t3 - t0,
                    "cpu_s": cpu, "other_busy_cores": busy}


def write_labels(pred_dir, keyframes, removed):
    d = pred_dir / "labels"
    d.mkdir(parents=True, exist_ok=True)
    for k, r in zip(keyframes, removed):
        np.where(r, REMOVED_LABEL, 0).astype("<u4").tofile(d / f"{k:06d}.label")


def ingest(seam, store, dir_, config=None):
    if store.exists():
        shutil.rmtree(store)
    seam.run("init", store, config=config)
    other = OtherLoad()
    t0 = time.perf_counter()
    receipt = seam.json("ingest", store, dir_, config=config)
    wall = time.perf_counter() - t0
    receipt["_other_busy_cores"] = other.cores()  # over the whole ingest, of which evidence is most
    return receipt, wall


def eval_dor(seam, store, labels_dir, session, predicted=None, config=None):
    args = ["eval", "dor", store, "--labels", labels_dir, "--session", session]
    if predicted:
        args += ["--predicted", predicted]
    return seam.json(*args, config=config)


def dataset_rows(args, seam, name, dir_, work, eval_ok, variants):
    out = {"dataset": name, "dir": str(dir_), "rows": [], "errors": []}
    stores = work / "stores" / name
    stores.mkdir(parents=True, exist_ok=True)

    log(f"[{name}] ingest (seam)")
    receipt, wall = ingest(seam, stores / "seam.seam", dir_)
    busy = {"seam": receipt.pop("_other_busy_cores")}
    session = receipt["name"]
    out.update(session=session, keyframes=receipt["keyframes"], points=receipt["points"], seam_ingest_s=wall)
    keyframes, poses = read_poses(seam, stores / "seam.seam", session)
    scans, truths = load_session(dir_, keyframes)
    npts = sum(len(s) for s in scans)
    out["dynamic_points"] = int(sum(t.sum() for t in truths))

    def seam_row(method, store, config, model):
        row = {"method": method, "source": "seam eval dor"}
        if not eval_ok:
            row["error"] = "`seam eval dor` is not in this seam binary"
            return row
        try:
            r = eval_dor(seam, store, dir_, session, config=config)
        except SeamError as e:
            row["error"] = str(e)
            return row
        if r.get("model") != model:  # a config seam ignored would give a mislabelled row
            row["error"] = f"the store's DOR model is {r.get('model')!r}, expected {model!r}"
            return row
        t = r.get("evidence_s")  # the evidence step's wall time; points/s over it
        m = r.get("in_memory_s")  # the same step without reading scans and writing files
        row.update(scores=r["scores"], model=r["model"], time_s=t, eval=r,
                   points_per_s=r["points"] / t if t else None,
                   in_memory_s=m, in_memory_points_per_s=r["points"] / m if m else None,
                   other_busy_cores=busy.get(method))
        return row

    out["rows"].append(seam_row("seam", stores / "seam.seam", None, "directional"))
    for method, cfg, model in variants:
        if cfg is None:
            out["rows"].append({"method": method, "skipped": "seam rejects its config (see above)"})
            continue
        log(f"[{name}] ingest ({method})")
        store = stores / (method.replace(" ", "-") + ".seam")
        try:
            r2, wall2 = ingest(seam, store, dir_, config=cfg)
            busy[method] = r2.pop("_other_busy_cores")
            out[method.replace(" ", "_").replace("-", "_") + "_ingest_s"] = wall2
            out["rows"].append(seam_row(method, store, cfg, model))
        except SeamError as e:
            out["rows"].append({"method": method, "error": str(e)})

    for res, d_s, d_p in args.dufomap_cfgs:
        method = f"dufomap {res:g}/{d_s:g}/{d_p:g}"
        log(f"[{name}] {method}: {len(scans)} scans, {npts:,} points")
        removed, timing = run_dufomap(scans, poses, res, d_s, d_p, args.threads)
        pred = work / "pred" / name / f"dufomap-{res:g}-{d_s:g}-{d_p:g}"
        if pred.exists():
            shutil.rmtree(pred)
        write_labels(pred, keyframes, removed)
        row = {
            "method": method, "resolution_m": res, "d_s_m": d_s, "d_p_voxels": d_p, "timing": timing,
            "time_s": timing["total_s"], "points_per_s": npts / timing["total_s"], "predicted_dir": str(pred),
            "other_busy_cores": timing["other_busy_cores"],
        }
        py = score_py(scans, poses, truths, removed) if (args.selfcheck or not eval_ok) else None
        if eval_ok:
            try:
                r = eval_dor(seam, stores / "seam.seam", dir_, session, predicted=pred)
                row.update(scores=r["scores"], source="seam eval dor", eval=r)
            except SeamError as e:
                row["error"] = str(e)
        if py is not None:
            row["selfcheck"] = py
            if "scores" in row:
                row["selfcheck_max_rate_diff"] = max_rate_diff(py, row["scores"])
                row["selfcheck_same_counts"] = same_counts(py, row["scores"])
            else:
                row.update(scores=py, source="python selfcheck")
        out["rows"].append(row)
    if args.repeat > 1:
        repeat_timings(args, seam, name, dir_, stores, session, scans, poses, out["rows"])
    return out


def repeat_timings(args, seam, name, dir_, stores, session, scans, poses, rows):
    """`--repeat`: `seam` (default config) and each DUFOMap setting timed
    `--repeat` times in all, in turns, so that a slow spell of this machine
    falls on both; each row's times become the medians, the runs kept."""
    seam_row = next((r for r in rows if r["method"] == "seam" and "scores" in r), None)
    duf_rows = [r for r in rows if r["method"].startswith("dufomap") and "timing" in r]
    if seam_row is not None:
        seam_row["runs"] = [{"time_s": seam_row["time_s"], "in_memory_s": seam_row["in_memory_s"]}]
    for r in duf_rows:
        r["runs"] = [r["time_s"]]
    for i in range(1, args.repeat):
        log(f"[{name}] timing round {i + 1} of {args.repeat}")
        if seam_row is not None:
            store = stores / "seam-repeat.seam"
            ingest(seam, store, dir_)
            r = eval_dor(seam, store, dir_, session)
            seam_row["runs"].append({"time_s": r.get("evidence_s"), "in_memory_s": r.get("in_memory_s")})
        for row in duf_rows:
            _, timing = run_dufomap(scans, poses, row["resolution_m"], row["d_s_m"], row["d_p_voxels"], args.threads)
            row["runs"].append(timing["total_s"])
    npts = sum(len(s) for s in scans)
    if seam_row is not None:
        for key, rate in (("time_s", "points_per_s"), ("in_memory_s", "in_memory_points_per_s")):
            ts = [x[key] for x in seam_row["runs"] if x[key]]
            if ts:
                seam_row[key] = statistics.median(ts)
                seam_row[rate] = seam_row["eval"]["points"] / seam_row[key]
    for row in duf_rows:
        row["time_s"] = statistics.median(row["runs"])
        row["points_per_s"] = npts / row["time_s"]


# ---------------------------------------------------------------- output


def pct(x):
    return "-" if x is None else f"{100 * x:.2f}"


def table(results, threads, repeat=1):
    head = ["dataset", "method", "PR%", "RR%", "F1%", "prec%", "vPR%", "vRR%", "vF1%", "vprec%", "mRR%", "mF1%",
            "points/s", "time s", "mem pts/s"]
    rows = []
    notes = []
    checks = []  # (dataset / method, max |Δrate|, same counts)
    flagged = False
    for d in results:
        for r in d["rows"]:
            s = r.get("scores")
            tag = " (py)" if r.get("source") == "python selfcheck" else ""
            if s is None:
                rows.append([d["dataset"], r["method"]] + ["n/a"] * 10 + ["-", "-", "-"])
                if r.get("skipped"):
                    rows[-1][-3:] = ["skipped", "-", "-"]
                if r.get("error"):
                    err = "\n      ".join(r["error"].splitlines())
                    notes.append(f"{d['dataset']} / {r['method']}:\n      {err}")
                continue
            p, v, m = s["point"], s["voxel"], s.get("moved") or {}
            pps = r.get("points_per_s")
            # DUFOMap's own time is in memory already (scans preloaded).
            mem = r.get("in_memory_points_per_s", pps)
            t = r.get("time_s")
            busy = r.get("other_busy_cores")
            star = "*" if busy is not None and busy > BUSY_FLAG else ""
            flagged |= bool(star)
            rows.append([
                d["dataset"], r["method"] + tag,
                pct(p["pr"]), pct(p["rr"]), pct(p["f1"]), pct(p["precision_of_removal"]),
                pct(v["pr"]), pct(v["rr"]), pct(v["f1"]), pct(v["precision_of_removal"]),
                pct(m.get("rr")), pct(m.get("f1")),
                (f"{pps:,.0f}" if pps else "-") + star, f"{t:.2f}" if t is not None else "-",
                f"{mem:,.0f}" if mem else "-",
            ])
            if "selfcheck_max_rate_diff" in r:
                checks.append((f"{d['dataset']} / {r['method']}", r["selfcheck_max_rate_diff"],
                               r["selfcheck_same_counts"]))
    w = [max(len(str(x[i])) for x in rows + [head]) for i in range(len(head))]
    lines = ["  ".join(str(c).ljust(w[i]) if i < 2 else str(c).rjust(w[i]) for i, c in enumerate(x))
             for x in [head] + rows]
    lines.insert(1, "-" * len(lines[0]))
    out = "\n".join(lines)
    out += ("\n\nPR/RR/F1/prec: point-wise; vPR..vprec: voxel-wise at 0.2 m (majority vote per voxel). "
            "prec = precision of removal.\nmRR/mF1: point-wise without the moving-labelled points that stayed "
            "in place (within one voxel of their own object in another scan; `seam eval dor`'s moved block)."
            "\npoints/s and time: seam = wall time of its ingest's evidence step "
            "(reading its scans, ray casting, DOR, writing its files), DUFOMap = run+propagate+segment wall time "
            f"(scans preloaded); {threads if threads > 0 else 'all'} threads each"
            + (f"; seam and DUFOMap rows: medians of {repeat} runs in turns" if repeat > 1 else "")
            + ".\nmem pts/s: seam without reading "
            "scans and writing files (the step's `generate_s`: ray casting, evidence, DOR, cleaned map in memory), "
            "the like of DUFOMap's timing; DUFOMap: its points/s again.")
    if flagged:
        out += (f"\n* other processes kept more than {BUSY_FLAG} of a core busy on average while this was timed "
                "(seam: over its whole ingest): the speed is pessimistic; re-run on a quiet machine.")
    if checks:
        worst = max(c[1] for c in checks)
        bad = [c[0] for c in checks if not c[2]]
        notes.insert(0, f"selfcheck: python scorer vs `seam eval dor --predicted` on {len(checks)} DUFOMap runs: "
                        f"max |Δrate| = {worst:.3g}; counts (point and voxel) "
                        + ("identical in every run" if not bad else "DIFFER in: " + ", ".join(bad)))
    for d in results:
        for e in d.get("errors", []):
            err = "\n      ".join(e.splitlines())
            notes.append(f"{d['dataset']} skipped:\n      {err}")
    if notes:
        out += "\n" + "\n".join("note: " + n for n in notes)
    return out


def parse_cfgs(s):
    cfgs = []
    for part in s.split(";"):
        part = part.strip()
        if not part:
            continue
        vals = part.split(",")
        if len(vals) != 3:
            raise argparse.ArgumentTypeError(f"{part!r}: DUFOMap settings are resolution,d_s,d_p")
        cfgs.append((float(vals[0]), float(vals[1]), int(vals[2])))
    return cfgs


def datasets_of(args, work, seam, tool):
    """(name, session folder) of every dataset `--kitti` and `--sensors`
    ask for; each simulated session made here (`seam simulate --sessions 1`)."""
    datasets = []
    for seq in filter(None, (s.strip() for s in args.kitti.split(","))):
        d = Path(args.kitti_root) / seq
        if not (d / "velodyne").is_dir():
            sys.exit(f"{tool}: {d} is not a KITTI sequence folder (velodyne/, poses.txt, labels/)")
        datasets.append((f"kitti-{seq}", d.resolve()))
    for sensor in filter(None, (s.strip() for s in args.sensors.split(","))):
        sim = work / "sim" / sensor
        if sim.exists():
            shutil.rmtree(sim)
        log(f"[sim-{sensor}] simulate {args.keyframes} keyframes")
        seam.run("simulate", sim, "--sessions", 1, "--sensor", sensor, "--keyframes", args.keyframes,
                 "--seed", args.seed)
        datasets.append((f"sim-{sensor}", sim / "session_01"))
    return datasets


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--kitti", default="04,08", help="SemanticKITTI sequences ('' for none)")
    ap.add_argument("--kitti-root", default=str(ROOT / ".." / "shared" / "data" / "semantickitti"))
    ap.add_argument("--sensors", default=SENSORS, help="simulated sensors, one session each ('' for none)")
    ap.add_argument("--keyframes", type=int, default=60, help="keyframes per simulated session")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--dufomap", default=DUFOMAP_DEFAULT, type=parse_cfgs,
                    help=f"DUFOMap settings 'resolution,d_s,d_p;...' (default {DUFOMAP_DEFAULT})")
    ap.add_argument("--threads", type=int, default=2,
                    help="threads for DUFOMap and for seam (RAYON_NUM_THREADS); 0: all cores (default 2)")
    ap.add_argument("--seam", default=str(ROOT / "target" / "release" / "seam"))
    ap.add_argument("--no-build", action="store_true", help="do not run `cargo build --release` first")
    ap.add_argument("--out", help="keep stores, simulations and DUFOMap labels here (default: a temp dir)")
    ap.add_argument("--json", help="write every number here")
    ap.add_argument("--repeat", type=int, default=1,
                    help="time seam (default config) and each DUFOMap setting this many times, in turns, "
                         "and report the medians (default 1)")
    ap.add_argument("--selfcheck", action="store_true",
                    help="also score DUFOMap in Python and compare with `seam eval dor`")
    args = ap.parse_args()
    if Dufomap is None:
        sys.exit("dor_vs_dufomap: DUFOMap's Python package is missing: run `pip install dufomap` (it needs numpy)")
    args.dufomap_cfgs = args.dufomap

    load_before = os.getloadavg()
    t_start = time.perf_counter()
    work, exe_copy = seam_in_work("dor_vs_dufomap", args.seam, args.no_build, args.out, "dor_vs_dufomap-")
    seam = Seam(exe_copy, args.threads)
    eval_ok = seam.has_eval_dor()
    if not eval_ok:
        log("note: this seam binary has no `seam eval dor`: seam rows are n/a and DUFOMap is scored in Python "
            "(rows marked py)")
    def variant_config(method, name, text):
        """The config file of a seam variant, or None (and a note) when this
        seam rejects it: checked once, rather than one identical failure per
        dataset."""
        cfg = work / f"{name}.toml"
        cfg.write_text(text)
        probe = work / f"probe-{name}.seam"
        try:
            shutil.rmtree(probe, ignore_errors=True)
            seam.run("init", probe, config=cfg)
            shutil.rmtree(probe, ignore_errors=True)
            return cfg, None
        except SeamError as e:
            note = f"{method} skipped everywhere: seam rejects {text.strip()!r}:\n{e}"
            log("note: " + note)
            return None, note

    scalar_cfg, scalar_note = variant_config("seam-scalar", "log_odds", SCALAR_TOML)
    voxel_cfg, _ = variant_config("seam voxel-rule", "voxel_rule", VOXEL_TOML)
    ceiling_cfg, _ = variant_config("any-free-ray ceiling", "ceiling", CEILING_TOML)
    variants = [("seam-scalar", scalar_cfg, "log_odds"), ("seam voxel-rule", voxel_cfg, "directional"),
                ("any-free-ray ceiling", ceiling_cfg, "directional")]

    datasets = datasets_of(args, work, seam, "dor_vs_dufomap")

    results = []
    for name, d in datasets:
        try:
            results.append(dataset_rows(args, seam, name, d, work, eval_ok, variants))
        except SeamError as e:
            log(f"[{name}] skipped: {e}")
            results.append({"dataset": name, "dir": str(d), "rows": [], "errors": [str(e)]})

    print(table(results, args.threads, args.repeat))
    if scalar_note:
        print("note: " + "\n      ".join(scalar_note.splitlines()))
    if args.json:
        import dufomap as dufomap_pkg

        doc = {
            "seam": str(Path(args.seam)), "dufomap_version": getattr(dufomap_pkg, "__version__", None),
            "threads": args.threads, "repeat": args.repeat, "cpus": os.cpu_count(), "keyframes": args.keyframes,
            "seed": args.seed,
            "sensors": args.sensors, "kitti": args.kitti, "load_before": load_before, "load_after": os.getloadavg(),
            "runtime_s": time.perf_counter() - t_start,
            "dufomap_settings": args.dufomap_cfgs, "work_dir": str(work), "seam_eval_dor": eval_ok,
            "seam_scalar_note": scalar_note, "datasets": results,
        }
        Path(args.json).write_text(json.dumps(doc, indent=1, default=float))
        log(f"wrote {args.json}")
    if not args.out:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
