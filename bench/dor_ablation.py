#!/usr/bin/env python3
"""Direction awareness against the scalar baseline at equal removal: the
paper's ablation as operating points, not one threshold each.

Usage (from the project root, after `pip install numpy pyarrow`):

    python3 bench/dor_ablation.py [--kitti 04,08] [--sensors os1-64,hdl-64e,vlp16,hdl-32e,avia]
        [--keyframes 60] [--seed 1] [--seam target/release/seam] [--no-build] [--out DIR]

`bench/dor_vs_dufomap.py` scores each model at its one threshold (τ_dyn =
0.5): directional evidence then removes more (higher RR) and keeps a little
less (lower PR) than the log-odds baseline, so "better PR at equal RR"
cannot be read off it. Here both models' whole trade-off is measured on the
same rays:

1. Per dataset (SemanticKITTI sequences; one simulated session per sensor,
   `seam simulate --sessions 1`, the same recipe as `dor_vs_dufomap.py`),
   `seam ingest` into a store with the default config ("seam") and into one
   with `[evidence] model = "log_odds"` ("seam-scalar"), both with the
   growth, cluster and footing steps off (`grow_max_hits = 0`,
   `cluster_share = 0`, `footing_height_m = 0`, `evidence::grow`) and the
   single-change test off
   (`change_once_min_frees = 0`): they work beside or on the verdicts
   either model gives, so they are no part of the evidence model this
   compares, and a grown or changed-once point's verdict is not its
   voxel's ε > τ.
2. `seam export STORE OUT --tables point_labels`: every point's clamped ε of
   its voxel (ε_l, or 1 − P(occupied) for the scalar model). A point is
   removed at threshold τ when ε > τ, the rule DOR applies at τ_dyn (checked:
   at τ = 0.5 this reproduces the stored verdicts exactly, else the script
   stops).
3. Against the labels (moving classes 252-259), point-wise PR (static kept)
   and RR (dynamic removed) for τ = 0.10, 0.11, ..., 0.89.

Printed per dataset: each model at τ = 0.5; the best PR each model reaches
with an RR at least the other's at τ = 0.5 ("PR at the other's RR"); and
each model's best F1 over the τ that keep PR ≥ 99 % (the goal's bar;
without it the best F1 of either model sits at a τ that removes several per
cent of the static points). Direction awareness beats the scalar baseline
on PR at equal or better RR when seam's PR at τ = 0.5 is above the scalar
model's best PR at seam's RR (column "seam wins").
"""

import argparse
import shutil
import sys
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from benchcommon import SeamError, log, seam_in_work
from dor_vs_dufomap import ROOT, SCALAR_TOML, SENSORS, Seam, datasets_of, ingest, load_session, read_poses

TAUS = np.round(np.arange(0.10, 0.90, 0.01), 2)
TAU_DEFAULT = 0.5
PR_GOAL = 0.99  # the bar: static structure kept


def point_eps(seam, store, session, work):
    """(keyframe, point_index, eps, dynamic) of every point of `session`."""
    out = work / "export"
    shutil.rmtree(out, ignore_errors=True)
    seam.run("export", store, out, "--tables", "point_labels")
    files = sorted((out / "point_labels").rglob("*.parquet"))
    if not files:
        raise SeamError(f"`seam export {store} --tables point_labels` wrote no files")
    t = pa.concat_tables([pq.read_table(f) for f in files])
    shutil.rmtree(out, ignore_errors=True)
    cols = {c: t.column(c).to_numpy() for c in ("keyframe", "point_index", "eps_l", "dynamic")}
    if len(cols["keyframe"]) == 0:
        raise SeamError(f"{store}: session {session} has no point labels")
    return cols


def curve(cols, truth_of):
    """PR and RR per τ of TAUS from exported labels (`truth_of`: keyframe →
    moving flag per point of its scan)."""
    order = np.argsort(cols["keyframe"], kind="stable")
    runs = np.split(order, np.flatnonzero(np.diff(cols["keyframe"][order])) + 1)
    truth = np.concatenate([truth_of[int(cols["keyframe"][r[0]])][cols["point_index"][r]] for r in runs])
    eps, stored = cols["eps_l"][order], cols["dynamic"][order]
    mismatch = int(((eps > TAU_DEFAULT) != stored).sum())
    if mismatch:
        raise SystemExit(f"dor_ablation: {mismatch} points' stored verdict is not ε > {TAU_DEFAULT}: the store's "
                         "config has another tau_dyn, the static-neighbour veto or the growth step; this "
                         "script assumes none of them")
    static, dynamic = ~truth, truth
    n_s, n_d = static.sum(), dynamic.sum()
    pr = np.array([((eps <= t) & static).sum() / n_s for t in TAUS])
    rr = np.array([((eps > t) & dynamic).sum() / n_d if n_d else np.nan for t in TAUS])
    return pr, rr


def f1(pr, rr):
    return np.where(pr + rr > 0, 2 * pr * rr / np.maximum(pr + rr, 1e-12), 0.0)


def best_pr_at(pr, rr, rr_min):
    """The highest PR over τ with RR ≥ rr_min (None: no τ reaches it)."""
    ok = rr >= rr_min - 1e-12
    return float(pr[ok].max()) if ok.any() else None


def pct(x):
    return "-" if x is None or (isinstance(x, float) and np.isnan(x)) else f"{100 * x:.2f}"


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--kitti", default="04,08", help="SemanticKITTI sequences ('' for none)")
    ap.add_argument("--kitti-root", default=str(ROOT / ".." / "shared" / "data" / "semantickitti"))
    ap.add_argument("--sensors", default=SENSORS, help="simulated sensors, one session each ('' for none)")
    ap.add_argument("--keyframes", type=int, default=60)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--seam", default=str(ROOT / "target" / "release" / "seam"))
    ap.add_argument("--no-build", action="store_true", help="do not run `cargo build --release` first")
    ap.add_argument("--out", help="keep stores and simulations here (default: a temp dir)")
    args = ap.parse_args()

    work, binary = seam_in_work("dor_ablation", args.seam, args.no_build, args.out, "dor_ablation-")
    seam = Seam(binary)
    no_grow = "grow_max_hits = 0\ncluster_share = 0\nfooting_height_m = 0\nchange_once_min_frees = 0\n"
    seam_cfg = work / "directional_no_grow.toml"
    seam_cfg.write_text("[evidence]\n" + no_grow)
    scalar_cfg = work / "log_odds.toml"
    scalar_cfg.write_text(SCALAR_TOML + no_grow)

    datasets = datasets_of(args, work, seam, "dor_ablation")

    head = (f"{'dataset':<12} {'model':<12} {'PR@0.5':>7} {'RR@0.5':>7} {'F1@0.5':>7}  "
            f"{'PR at other RR':>14}  {'best F1, PR ≥ 99 % (τ)':>24}  seam wins")
    lines = [head, "-" * len(head)]
    for name, d in datasets:
        curves = {}
        for model, cfg in (("seam", seam_cfg), ("seam-scalar", scalar_cfg)):
            log(f"[{name}] ingest ({model})")
            store = work / "stores" / name / f"{model}.seam"
            store.parent.mkdir(parents=True, exist_ok=True)
            receipt, _ = ingest(seam, store, d, config=cfg)
            session = receipt["name"]
            keyframes, _ = read_poses(seam, store, session)
            _, truths = load_session(d, keyframes)
            truth_of = dict(zip(keyframes, truths))
            curves[model] = curve(point_eps(seam, store, session, work), truth_of)
        i0 = int(np.flatnonzero(TAUS == TAU_DEFAULT)[0])
        at = {m: (pr[i0], rr[i0]) for m, (pr, rr) in curves.items()}
        for m, other in (("seam", "seam-scalar"), ("seam-scalar", "seam")):
            pr, rr = curves[m]
            f = np.where(pr >= PR_GOAL, f1(pr, rr), -1.0)
            b = int(np.nanargmax(f))
            best = f"{pct(float(f[b]))} ({TAUS[b]:.2f}, PR {pct(float(pr[b]))})" if f[b] >= 0 else "-"
            cross = best_pr_at(pr, rr, at[other][1])
            wins = ""
            if m == "seam":
                rival = best_pr_at(*curves["seam-scalar"], at["seam"][1])
                wins = "yes" if rival is None or at["seam"][0] > rival else "no"
            lines.append(f"{name:<12} {m:<12} {pct(at[m][0]):>7} {pct(at[m][1]):>7} "
                         f"{pct(float(f1(pr, rr)[i0])):>7}  {pct(cross):>14}  {best:>24}  {wins}")
    print("\n".join(lines))
    print("\nPR at other RR: the model's best PR over τ = 0.10..0.89 with RR at least the other model's RR at "
          "τ = 0.5 (-: no τ reaches it). seam wins: seam's PR at τ = 0.5 is above the scalar model's PR at "
          "seam's RR. best F1: over the τ with PR ≥ 99 % (-: none). Point-wise, moving classes 252-259.")
    if not args.out:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
