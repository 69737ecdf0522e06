#!/usr/bin/env python3
"""Incremental update vs full rebuild: the paper's Table IV question, on a
simulated site, with seam's own two paths.

Usage (from the project root; Python 3 standard library only):

    python3 bench/incremental.py [--sensor os1-64] [--keyframes 40 | --full] [--sessions 5] [--seed 1]
        [--threads 0] [--seam target/release/seam] [--no-build] [--out DIR] [--json results.json]

What it does:

1. `seam simulate SIM --sessions N --sensor S --keyframes K --seed SEED`
   (`--full`: 300 keyframes per session, 1,500 for the default 5 sessions,
   the size of the paper's construction-site runs).
2. `seam init MAIN`, then `seam ingest MAIN SIM/session_0k` for k = 1..N, one
   at a time, each timed (wall clock of the process, and the receipt's
   `wall_s` and per-step `wall_s`, which are the ingest's step_log timings).
   This is the incremental path: session k is aligned against, optimised
   with, and its evidence and changes folded into, the k-1 sessions already
   stored (earlier evidence is reprojected, not re-cast).
3. Right after session k is ingested (k >= 2), MAIN holds exactly sessions
   1..k, and `seam rebuild MAIN --out REBUILD_k` recomputes all of it from the
   raw scans into a fresh store: k ingests in order, each with every step.
   This is the from-scratch path. (So the rebuild is of the same store, not
   of a second copy; it reads MAIN read-only and also checks every source
   folder's content hash first, reported separately as `verify_s`.)

The table, per k: session k's incremental ingest time vs the rebuild of k
sessions, their ratio, and Table IV's split of each: merge = coarse_align +
loops + optimize, update = evidence + changes (DOR, reprojection, change
detection, the lifelong map), other = everything else (reading and storing
scans, submaps, validation, hashing, commit). Ingest times are the receipt's
`wall_s` (process start-up and store opening excluded; the process wall time
is in the JSON too). The rebuild time is the sum of its k ingests' `wall_s`
(its `ingest_s`, store creation included), without the hash check.

Peak memory is the maximum resident set of each `seam` process, measured
with `/usr/bin/time -v` when it exists. Both paths get the same threads
(`--threads` sets RAYON_NUM_THREADS; 0, the default, lets rayon use every
core). Other processes' CPU use during each timed command is measured
(/proc/stat) and flagged with * when above 0.3 cores: such times are
pessimistic. The seam binary is copied into the work folder first, so a
concurrent `cargo build` cannot swap it mid-run.
"""

import argparse
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

from benchcommon import BUSY_FLAG, OtherLoad, SeamError, log, seam_in_work

ROOT = Path(__file__).resolve().parents[1]
MERGE = ("coarse_align", "loops", "optimize")
UPDATE = ("evidence", "changes")
FULL_KEYFRAMES = 300
TIME_V = "/usr/bin/time"


# ---------------------------------------------------------------- seam


class Seam:
    """The seam CLI: one subprocess per command, timed, with its peak memory."""

    def __init__(self, exe, work, threads=0):
        self.exe = str(exe)
        self.work = work
        self.env = dict(os.environ)
        if threads > 0:
            self.env["RAYON_NUM_THREADS"] = str(threads)
        self.time_v = TIME_V if os.access(TIME_V, os.X_OK) else None

    def run(self, *args, fmt=None):
        """Runs `seam --quiet [--format FMT] ARGS`; returns (stdout, stats)."""
        cmd = [self.exe, "--quiet"] + (["--format", fmt] if fmt else []) + [str(a) for a in args]
        tfile = self.work / "time-v.txt"
        full = [self.time_v, "-v", "-o", str(tfile)] + cmd if self.time_v else cmd
        other = OtherLoad()
        t0 = time.perf_counter()
        p = subprocess.run(full, capture_output=True, text=True, env=self.env)
        wall = time.perf_counter() - t0
        stats = {"process_s": wall, "other_busy_cores": other.cores(), "peak_rss_mb": None}
        if self.time_v and tfile.is_file():
            for line in tfile.read_text().splitlines():
                if "Maximum resident set size" in line:
                    stats["peak_rss_mb"] = int(line.rsplit(":", 1)[1]) / 1024.0
        if p.returncode != 0:
            raise SeamError(f"{p.stderr.strip() or '(nothing on stderr)'}\n[`{' '.join(cmd)}` exited with {p.returncode}]")
        return p.stdout, stats

    def json(self, *args):
        out, stats = self.run(*args, fmt="json")
        try:
            return json.loads(out), stats
        except json.JSONDecodeError as e:
            raise SeamError(f"`seam {' '.join(map(str, args))}` printed no JSON ({e}):\n{out[:500]}") from e


# ---------------------------------------------------------------- numbers


def split(steps):
    """Step name -> seconds, summed over the given receipts' steps (those that ran)."""
    out = {}
    for st in steps:
        if st.get("ran", True):
            out[st["step"]] = out.get(st["step"], 0.0) + float(st["wall_s"])
    return out


def groups(step_s, total_s):
    merge = sum(step_s.get(s, 0.0) for s in MERGE)
    update = sum(step_s.get(s, 0.0) for s in UPDATE)
    return {"merge_s": merge, "update_s": update, "other_s": max(0.0, total_s - merge - update)}


def ingest_row(receipt, stats):
    steps = split(receipt["steps"])
    row = {"wall_s": receipt["wall_s"], "steps": steps, "keyframes": receipt["keyframes"],
           "points": receipt["points"], "status": receipt["status"], **stats}
    row.update(groups(steps, receipt["wall_s"]))
    return row


def rebuild_row(report, stats):
    sessions = report["sessions"]
    steps = split([st for s in sessions for st in s["steps"]])
    total = report["ingest_s"]
    row = {"wall_s": total, "verify_s": report["verify_s"], "command_s": report["wall_s"], "steps": steps,
           "sessions": [{"name": s["name"], "wall_s": s["wall_s"], "steps": split(s["steps"])} for s in sessions],
           "keyframes": sum(s["keyframes"] for s in sessions), **stats}
    row.update(groups(steps, total))
    return row


# ---------------------------------------------------------------- output


def table(rows, has_rss):
    head = ["k", "kf", "ingest k s", "merge", "update", "other", "rebuild 1..k s", "merge", "update", "other",
            "rebuild/ingest", "sum ingests 1..k"]
    if has_rss:
        head += ["rss ingest MB", "rss rebuild MB"]
    lines_in = []
    flagged = False
    stored = 0
    summed = 0.0
    for r in rows:
        stored += r["ingest"]["keyframes"]
        summed += r["ingest"]["wall_s"]
        i, b = r["ingest"], r.get("rebuild")
        star_i = "*" if (i.get("other_busy_cores") or 0) > BUSY_FLAG else ""
        line = [str(r["k"]), str(stored),
                f"{i['wall_s']:.2f}{star_i}", f"{i['merge_s']:.2f}", f"{i['update_s']:.2f}", f"{i['other_s']:.2f}"]
        if b:
            star_b = "*" if (b.get("other_busy_cores") or 0) > BUSY_FLAG else ""
            line += [f"{b['wall_s']:.2f}{star_b}", f"{b['merge_s']:.2f}", f"{b['update_s']:.2f}",
                     f"{b['other_s']:.2f}", f"{b['wall_s'] / i['wall_s']:.2f}x" if i["wall_s"] > 0 else "-",
                     f"{summed:.2f}"]
            flagged |= bool(star_b)
        else:
            line += ["-"] * 5 + [f"{summed:.2f}"]
        flagged |= bool(star_i)
        if has_rss:
            mb = lambda x: "-" if x is None else f"{x:.0f}"  # noqa: E731
            line += [mb(i.get("peak_rss_mb")), mb(b.get("peak_rss_mb") if b else None)]
        lines_in.append(line)
    w = [max(len(x[c]) for x in lines_in + [head]) for c in range(len(head))]
    lines = ["  ".join(c.rjust(w[n]) for n, c in enumerate(x)) for x in [head] + lines_in]
    lines.insert(1, "-" * len(lines[0]))
    out = "\n".join(lines)
    out += ("\n\nkf: keyframes stored after session k. ingest k: session k added to the store holding 1..k-1 "
            "(receipt wall_s). rebuild 1..k: `seam rebuild` of that store, k ingests from scratch (sum of their "
            "wall_s, hash check excluded).\nsum ingests 1..k: the incremental ingests' times added up; a rebuild "
            "runs the same k ingests, so it should be close to this (a check on timing noise).\nmerge = coarse_align + loops + optimize; update = evidence + changes; "
            "other = scans, submaps, validation, complete (Table IV's Merge / Update / Total).")
    if flagged:
        out += (f"\n* other processes kept more than {BUSY_FLAG} of a core busy on average while this was timed: "
                "the time is pessimistic; re-run on a quiet machine.")
    return out


# ---------------------------------------------------------------- main


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sensor", default="os1-64", help="sensor model for `seam simulate` (default os1-64)")
    ap.add_argument("--keyframes", type=int, default=40, help="keyframes per session (default 40)")
    ap.add_argument("--full", action="store_true", help=f"{FULL_KEYFRAMES} keyframes per session (paper scale)")
    ap.add_argument("--sessions", type=int, default=5, help="sessions of the site (default 5)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--threads", type=int, default=0,
                    help="RAYON_NUM_THREADS for every seam command; 0: all cores (default)")
    ap.add_argument("--seam", default=str(ROOT / "target" / "release" / "seam"))
    ap.add_argument("--no-build", action="store_true", help="do not run `cargo build --release` first")
    ap.add_argument("--out", help="keep the simulation and the stores here (default: a temp dir, removed)")
    ap.add_argument("--json", help="write every number here")
    args = ap.parse_args()
    keyframes = FULL_KEYFRAMES if args.full else args.keyframes
    if args.sessions < 2 or keyframes < 2:
        sys.exit("incremental: --sessions must be at least 2 and --keyframes at least 2")

    work, exe_copy = seam_in_work("incremental", args.seam, args.no_build, args.out, "seam-incremental-")
    seam = Seam(exe_copy, work, args.threads)
    if seam.time_v is None:
        log(f"note: {TIME_V} not found: no peak memory")
    load_before = os.getloadavg()
    t_start = time.perf_counter()

    sim = work / "sim"
    main_store = work / "main.seam"
    for p in [sim, main_store] + sorted(work.glob("rebuild-*.seam")):
        shutil.rmtree(p, ignore_errors=True)
    log(f"simulate {args.sessions} sessions x {keyframes} keyframes ({args.sensor}, seed {args.seed})")
    try:
        summary, _ = seam.json("simulate", sim, "--sessions", args.sessions, "--sensor", args.sensor,
                               "--keyframes", keyframes, "--seed", args.seed)
        dirs = [Path(s["dir"]) for s in summary["sessions"]]
        dirs = [d if d.is_absolute() else (Path.cwd() / d) for d in dirs]
        seam.run("init", main_store)
        rows = []
        for k, d in enumerate(dirs, start=1):
            log(f"[{k}/{len(dirs)}] ingest {d.name}")
            receipt, stats = seam.json("ingest", main_store, d)
            row = {"k": k, "session": receipt["name"], "ingest": ingest_row(receipt, stats)}
            if k >= 2:
                out = work / f"rebuild-{k}.seam"
                log(f"[{k}/{len(dirs)}] rebuild sessions 1..{k}")
                report, rstats = seam.json("rebuild", main_store, "--out", out)
                if len(report["sessions"]) != k:
                    raise SeamError(f"rebuild of {main_store} rebuilt {len(report['sessions'])} sessions, not {k}")
                row["rebuild"] = rebuild_row(report, rstats)
                if not args.out:
                    shutil.rmtree(out, ignore_errors=True)  # keep the disk small; the numbers are in `row`
            rows.append(row)
    except SeamError as e:
        sys.exit(f"incremental: {e}")

    steps_seen = sorted({s for r in rows for s in r["ingest"]["steps"]})
    missing = [s for s in MERGE + UPDATE if s not in steps_seen]
    print(f"{args.sessions} sessions x {keyframes} keyframes, {args.sensor}, seed {args.seed}, "
          f"threads {args.threads or 'all'} ({os.cpu_count()} cpus)")
    print(table(rows, seam.time_v is not None))
    if missing:
        print(f"note: this seam has no step(s) {', '.join(missing)}: their group sums what exists")
    last = rows[-1]
    if "rebuild" in last:
        i, b = last["ingest"], last["rebuild"]
        print(f"\nsession {last['k']}: incremental {i['merge_s']:.2f} + {i['update_s']:.2f} + {i['other_s']:.2f} = "
              f"{i['wall_s']:.2f} s (merge + update + other) vs rebuild {b['merge_s']:.2f} + {b['update_s']:.2f} + "
              f"{b['other_s']:.2f} = {b['wall_s']:.2f} s: {b['wall_s'] / i['wall_s']:.2f}x")

    if args.json:
        doc = {
            "seam": str(Path(args.seam)), "sensor": args.sensor, "keyframes_per_session": keyframes, "sessions": args.sessions,
            "seed": args.seed, "threads": args.threads, "cpus": os.cpu_count(), "load_before": load_before,
            "load_after": os.getloadavg(), "runtime_s": time.perf_counter() - t_start, "work_dir": str(work),
            "merge_steps": MERGE, "update_steps": UPDATE, "steps_seen": steps_seen, "rows": rows,
        }
        Path(args.json).write_text(json.dumps(doc, indent=1))
        log(f"wrote {args.json}")
    if not args.out:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
