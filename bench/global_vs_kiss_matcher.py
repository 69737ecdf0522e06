#!/usr/bin/env python3
"""seam's global map-to-map registration against KISS-Matcher on simulated sites.

Usage (from the project root, after `pip install kiss-matcher numpy`):

    python3 bench/global_vs_kiss_matcher.py [--seeds 1-10] [--sensor os1-64] [--drift 0.25]
        [--keyframes 60] [--voxel 0.5] [--out DIR] [--json results.json] [--no-build]

For every seed, `examples/global_bench.rs` simulates a two-session site,
merges each session's keyframes into a map by its (drifting) odometry, runs
seam's `register_maps` (session 2's map onto session 1's) and writes both maps
(f32 x y z, 0.2 m voxel centroids) with the true `t_target_source`. This
script then runs KISS-Matcher (`KISSMatcherConfig(voxel)`, `estimate(src,
tgt)`) on the same maps. With `--same-session` the pairs are two halves of
one session instead (even keyframes, and odd ones moved by a random yaw and
offset), where local descriptors repeat.

Per pair it reports, for both methods: the error against the truth, whether
the method *claims* success (seam: its verdict; KISS-Matcher: at least 5
final inliers, the threshold of its examples, and the stricter >= 100), and
the time (seam: everything from the raw maps, as `elapsed_s`; KISS-Matcher:
`estimate`, voxelization included). A claimed success is *correct* within
0.5 m / 2 deg and *wrong* beyond 1.5 m or 5 deg (between the two: neither).
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

try:
    import kiss_matcher
except ImportError:  # pragma: no cover - a message, not a stack trace
    sys.exit("bench: `pip install kiss-matcher numpy` first")

ACCURATE = (0.5, 2.0)
WRONG = (1.5, 5.0)


def read_3x4(path):
    m = np.eye(4)
    m[:3, :] = np.array([float(v) for v in open(path).read().split()]).reshape(3, 4)
    return m


def pose_error(truth, est):
    """|t_est - t_true| (m) and the angle of R_true^T R_est (deg)."""
    dt = float(np.linalg.norm(est[:3, 3] - truth[:3, 3]))
    c = (np.trace(truth[:3, :3].T @ est[:3, :3]) - 1.0) / 2.0
    return dt, float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def classify(claimed, err):
    if not claimed:
        return "fail"
    if err[0] <= ACCURATE[0] and err[1] <= ACCURATE[1]:
        return "ok"
    if err[0] > WRONG[0] or err[1] > WRONG[1]:
        return "WRONG"
    return "coarse"


def run_kiss(pair_dir, voxel):
    tgt = np.fromfile(os.path.join(pair_dir, "target.bin"), dtype=np.float32).reshape(-1, 3)
    src = np.fromfile(os.path.join(pair_dir, "source.bin"), dtype=np.float32).reshape(-1, 3)
    matcher = kiss_matcher.KISSMatcher(kiss_matcher.KISSMatcherConfig(voxel))
    t0 = time.perf_counter()
    sol = matcher.estimate(src, tgt)
    elapsed = time.perf_counter() - t0
    est = np.eye(4)
    est[:3, :3] = np.array(sol.rotation)
    est[:3, 3] = np.array(sol.translation)
    return est, matcher.get_num_final_inliers(), elapsed


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", default="1-10")
    ap.add_argument("--sensor", default="os1-64")
    ap.add_argument("--drift", type=float, default=0.25)
    ap.add_argument("--keyframes", type=int, default=60)
    ap.add_argument("--voxel", type=float, default=0.5, help="KISS-Matcher's voxel (seam's default is 0.5 m)")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--out", help="keep the maps here (default: a temporary directory)")
    ap.add_argument("--json", help="write every row here")
    ap.add_argument("--no-build", action="store_true")
    ap.add_argument("--same-session", action="store_true",
                    help="pair two halves of one session (even / odd keyframes, moved): descriptors repeat")
    a = ap.parse_args()

    out = a.out or tempfile.mkdtemp(prefix="seam_global_bench_")
    if not a.no_build:
        subprocess.run(["cargo", "build", "--release", "--example", "global_bench"], check=True)
    cmd = [
        "target/release/examples/global_bench", "--seeds", a.seeds, "--sensor", a.sensor,
        "--drift", str(a.drift), "--keyframes", str(a.keyframes), "--threads", str(a.threads), "--out", out,
    ]
    if a.same_session:
        cmd.append("--same-session")
    seam_rows = [json.loads(l) for l in subprocess.run(cmd, check=True, capture_output=True, text=True).stdout.splitlines()]

    rows = []
    hdr = (f"{'seed':>4} | {'seam':>6} {'err m':>6} {'err deg':>7} {'time s':>6} | "
           f"{'KISS':>6} {'>=100':>6} {'err m':>6} {'err deg':>7} {'inl':>5} {'time s':>6}")
    pairs = "halves of one session" if a.same_session else "session 2 onto session 1"
    print(f"{pairs}; sensor {a.sensor}, drift {a.drift}, {a.keyframes} keyframes per session, voxel {a.voxel} m")
    print(hdr)
    print("-" * len(hdr))
    for s in seam_rows:
        pair_dir = os.path.join(out, f"seed_{s['seed']:02d}")
        truth = read_3x4(os.path.join(pair_dir, "truth.txt"))
        est, inliers, k_time = run_kiss(pair_dir, a.voxel)
        k_err = pose_error(truth, est)
        seam_err = (s["err_t_m"], s["err_r_deg"])
        row = {
            "seed": s["seed"],
            "seam": classify(s["success"], seam_err),
            "seam_err_m": seam_err[0], "seam_err_deg": seam_err[1], "seam_s": s["elapsed_s"],
            "seam_reason": s["reason"],
            "kiss": classify(inliers >= 5, k_err),
            "kiss100": classify(inliers >= 100, k_err),
            "kiss_err_m": k_err[0], "kiss_err_deg": k_err[1], "kiss_inliers": inliers, "kiss_s": k_time,
        }
        rows.append(row)
        print(f"{row['seed']:>4} | {row['seam']:>6} {seam_err[0]:6.2f} {seam_err[1]:7.2f} {row['seam_s']:6.2f} | "
              f"{row['kiss']:>6} {row['kiss100']:>6} {k_err[0]:6.2f} {k_err[1]:7.2f} {inliers:5d} {k_time:6.2f}")

    def count(key, what):
        return sum(r[key] == what for r in rows)

    seam_t = sum(r["seam_s"] for r in rows)
    kiss_t = sum(r["kiss_s"] for r in rows)
    print("-" * len(hdr))
    for key, name in (("seam", "seam"), ("kiss", "KISS-Matcher (>=5 inliers)"), ("kiss100", "KISS-Matcher (>=100 inliers)")):
        print(f"{name:28s}: ok {count(key, 'ok')}, coarse {count(key, 'coarse')}, "
              f"WRONG {count(key, 'WRONG')}, failed {count(key, 'fail')} of {len(rows)}")
    ratio = kiss_t / seam_t if seam_t > 0 else float("nan")
    print(f"time: seam {seam_t:.1f} s, KISS-Matcher {kiss_t:.1f} s (KISS-Matcher / seam = {ratio:.2f})")
    if a.json:
        with open(a.json, "w") as f:
            json.dump(rows, f, indent=1)


if __name__ == "__main__":
    main()
