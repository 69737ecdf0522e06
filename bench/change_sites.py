#!/usr/bin/env python3
"""Change detection on simulated multi-session sites, one per sensor model:
the table of issue 5's goals (`seam eval changes`) with the ingest times.

Usage (from the project root):

    python3 bench/change_sites.py [--sensors os1-64,hdl-64e,hdl-32e,vlp16,avia]
        [--sessions 5] [--keyframes 150] [--seed 3] [--config A.toml ...]
        [--seam target/release/seam] [--no-build] [--out DIR] [--json results.json]

Per sensor: `seam simulate SIM --sessions N --keyframes K --seed S --sensor
X` (the OS1-64 with seed 1: the README demo's site), then for every
`--config` (none: the defaults; `default` names them too) `seam init` +
`seam ingest` of each session into a fresh store, and `seam eval changes
STORE --gt SIM`. Several `--config` files are compared on the same
simulation, so a before/after is one run.

Columns: permanent structure static (goal >= 98 %), removed-object voxels
left static (<= 5 %), the same among voxels some session saw free and among
voxels some session after the object's removal had within its sensor's
range and field of view (occlusion not modelled), appeared objects present
(>= 90 %), mover voxels as a share of the static map (<= 1 %), object
changes with events in the right session, and how many of the wrong ones
had none of their voxels in view in that session ("unseen"); the largest
per-session ATE RMSE of the store's poses (`seam eval align`); the ingest
wall time of all sessions.
With `--out`, simulations are kept and reused when their folder exists.
"""

import argparse
import json
import shutil
import sys
import time
from pathlib import Path

from benchcommon import SeamError, log, seam_in_work
from incremental import Seam

SENSORS = ["os1-64", "hdl-64e", "hdl-32e", "vlp16", "avia"]


def score(scores, key):
    v = scores.get(key) or {}
    return v.get("value")


def run_site(seam, work, sensor, args, configs):
    seed = 1 if sensor == "os1-64" else args.seed
    sim = work / f"sim-{sensor}-{args.sessions}x{args.keyframes}-s{seed}"
    if not (sim / "objects.csv").is_file():
        shutil.rmtree(sim, ignore_errors=True)
        log(f"[{sensor}] simulate {args.sessions} x {args.keyframes} keyframes, seed {seed}")
        seam.run("simulate", sim, "--sessions", args.sessions, "--keyframes", args.keyframes,
                 "--seed", seed, "--sensor", sensor)
    sessions = sorted(p for p in sim.iterdir() if p.is_dir() and p.name.startswith("session_"))
    rows = []
    for cfg in configs:
        name = "default" if cfg is None else Path(cfg).stem
        store = work / f"{sensor}-{name}.seam"
        shutil.rmtree(store, ignore_errors=True)
        seam.run("init", store, "--local")
        extra = [] if cfg is None else ["--config", cfg]
        ingest_s = 0.0
        for s in sessions:
            log(f"[{sensor}] {name}: ingest {s.name}")
            _, st = seam.run(*extra, "ingest", store, s)
            ingest_s += st["process_s"]
        ev, _ = seam.json("eval", "changes", store, "--gt", sim)
        al, _ = seam.json("eval", "align", store, "--gt", sim)
        sc = ev["scores"]
        rows.append({
            "sensor": sensor,
            "config": name,
            "permanent_static": score(sc, "permanent_static"),
            "removed_static": score(sc, "removed_static"),
            "removed_static_seen_free": score(sc, "removed_static_seen_free"),
            "removed_static_in_view": score(sc, "removed_static_in_view"),
            "events_wrong_out_of_view": sum(1 for c in sc.get("changes", [])
                                            if c.get("scored") and not c.get("correct")
                                            and c.get("in_view_voxels") == 0),
            "appeared_present": score(sc, "appeared_present"),
            "mover_static_of_static_map": score(sc, "mover_static_of_static_map"),
            "events_correct": score(sc, "events_correct"),
            "ate_max_session_m": max((s.get("ate_rmse_m") or 0.0 for s in al.get("sessions", [])), default=None),
            "ingest_s": ingest_s,
        })
        if not args.keep_stores:
            shutil.rmtree(store, ignore_errors=True)
    return rows


def pct(v):
    return "n/a" if v is None else f"{100 * v:.2f}"


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sensors", default=",".join(SENSORS))
    ap.add_argument("--sessions", type=int, default=5)
    ap.add_argument("--keyframes", type=int, default=150)
    ap.add_argument("--seed", type=int, default=3, help="simulation seed (the OS1-64 always uses 1, the demo's)")
    ap.add_argument("--config", action="append", default=[],
                    help="a seam config TOML to compare (repeatable; 'default' for none)")
    ap.add_argument("--threads", type=int, default=0)
    ap.add_argument("--seam", default=str(Path(__file__).resolve().parents[1] / "target" / "release" / "seam"))
    ap.add_argument("--no-build", action="store_true")
    ap.add_argument("--out", help="keep simulations here (default: a temp dir, removed)")
    ap.add_argument("--keep-stores", action="store_true",
                    help="keep each store (~1 GB for 5 x 150 keyframes) in --out after it is scored")
    ap.add_argument("--json", help="write every number here")
    args = ap.parse_args()
    if args.keep_stores and not args.out:
        sys.exit("change_sites: --keep-stores needs --out")
    configs = [None if c == "default" else str(Path(c).resolve()) for c in args.config] or [None]
    for c in configs:
        if c is not None and not Path(c).is_file():
            sys.exit(f"change_sites: no config file at {c}")

    work, exe = seam_in_work("change_sites", args.seam, args.no_build, args.out, "seam-change-sites-")
    seam = Seam(exe, work, args.threads)
    t0 = time.perf_counter()
    rows = []
    try:
        for sensor in [s for s in args.sensors.split(",") if s]:
            rows += run_site(seam, work, sensor, args, configs)
    except SeamError as e:
        sys.exit(f"change_sites: {e}")
    finally:
        if not args.out:
            shutil.rmtree(work, ignore_errors=True)

    head = f"{'sensor':<9} {'config':<16} {'perm%':>7} {'removed%':>9} {'seenfree%':>9} {'inview%':>8} " \
           f"{'appeared%':>9} {'movers%':>8} {'events%':>8} {'unseen':>6} {'ATE mm':>7} {'ingest s':>9}"
    print(head)
    print("-" * len(head))
    for r in rows:
        ate = "n/a" if r["ate_max_session_m"] is None else f"{1000 * r['ate_max_session_m']:.0f}"
        print(f"{r['sensor']:<9} {r['config']:<16} {pct(r['permanent_static']):>7} {pct(r['removed_static']):>9} "
              f"{pct(r['removed_static_seen_free']):>9} {pct(r['removed_static_in_view']):>8} "
              f"{pct(r['appeared_present']):>9} "
              f"{pct(r['mover_static_of_static_map']):>8} {pct(r['events_correct']):>8} "
              f"{r['events_wrong_out_of_view']:>6} {ate:>7} "
              f"{r['ingest_s']:>9.1f}")
    print(f"\n{args.sessions} sessions x {args.keyframes} keyframes per site; goals: perm >= 98, removed <= 5, "
          f"appeared >= 90, movers <= 1 (% of the static map). {time.perf_counter() - t0:.0f} s in all.")
    if args.json:
        Path(args.json).write_text(json.dumps({"sessions": args.sessions, "keyframes": args.keyframes,
                                               "seed": args.seed, "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
