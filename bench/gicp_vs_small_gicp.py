#!/usr/bin/env python3
"""seam's GICP against small_gicp on real scan pairs.

Usage (from the project root, after `pip install small_gicp numpy`):

    python3 bench/gicp_vs_small_gicp.py [--runs 7] [--voxel 0.25] [--threads 2]
        [--data ../shared/data] [--kitti-pairs 9] [--json out.json] [--no-build]

Pairs: the HDL-32E pair of ../shared/data/registration (reference
relative.txt = T_target_source, target 251370668, source 251371071), and
consecutive SemanticKITTI scans of sequences 04 and 08 (target scan i, source
scan i+1, reference inv(T_i) T_{i+1} with the LiDAR poses T = inv(Tr) P Tr).

Both sides use the same voxel size, k = 20 neighbours for the covariances and
the same thread count; both time preprocessing (downsampling, kd-tree,
covariances of both clouds) apart from the registration, median over --runs,
file reading excluded. small_gicp runs with its default fixed 1.0 m max
correspondence distance; seam with its default 2.0 -> 0.5 m schedule.
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
import time

import numpy as np

try:
    import small_gicp
except ImportError:  # pragma: no cover - a message, not a stack trace
    sys.exit("bench: `pip install small_gicp numpy` first")


def read_points(path):
    """x y z (float64) of a KITTI .bin or a binary x y z intensity PCD."""
    if path.endswith(".bin"):
        return np.fromfile(path, dtype=np.float32).reshape(-1, 4)[:, :3].astype(np.float64)
    if path.endswith(".pcd"):
        data = open(path, "rb").read()
        start = data.index(b"DATA binary\n") + len(b"DATA binary\n")
        return np.frombuffer(data[start:], dtype=np.float32).reshape(-1, 4)[:, :3].astype(np.float64)
    raise ValueError(f"cannot read {path}")


def read_3x4(line):
    m = np.eye(4)
    m[:3, :] = np.array([float(v) for v in line.split()]).reshape(3, 4)
    return m


def kitti_pairs(seq_dir, count):
    calib = open(os.path.join(seq_dir, "calib.txt")).read().splitlines()
    tr = read_3x4(next(l for l in calib if l.startswith("Tr:"))[3:])
    poses = [np.linalg.inv(tr) @ read_3x4(l) @ tr for l in open(os.path.join(seq_dir, "poses.txt")) if l.strip()]
    velo = os.path.join(seq_dir, "velodyne")
    pairs = []
    for i in range(min(count, len(poses) - 1)):
        ref = np.linalg.inv(poses[i]) @ poses[i + 1]
        name = f"kitti{os.path.basename(seq_dir)}_{i:02d}-{i + 1:02d}"
        pairs.append((name, os.path.join(velo, f"{i:06d}.bin"), os.path.join(velo, f"{i + 1:06d}.bin"), ref))
    return pairs


KEYS = ("preprocess_ms", "registration_ms", "total_ms", "total_min_ms", "registration_min_ms", "iterations",
        "converged")


def errors(t_est, t_ref):
    d = np.linalg.inv(t_ref) @ t_est
    trans_cm = 100.0 * np.linalg.norm(t_est[:3, 3] - t_ref[:3, 3])
    r = d[:3, :3]
    # atan2(sin, cos) keeps precision for tiny angles, where arccos does not.
    sin = 0.5 * np.linalg.norm([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    rot_deg = np.degrees(np.arctan2(sin, 0.5 * (np.trace(r) - 1.0)))
    return trans_cm, rot_deg


def run_small_gicp(target, source, args):
    pre, reg, res = [], [], None
    for _ in range(args.runs):
        t0 = time.perf_counter()
        tp, tt = small_gicp.preprocess_points(target, args.voxel, num_neighbors=20, num_threads=args.threads)
        sp, _ = small_gicp.preprocess_points(source, args.voxel, num_neighbors=20, num_threads=args.threads)
        t1 = time.perf_counter()
        res = small_gicp.align(tp, sp, tt, registration_type="GICP", num_threads=args.threads)
        t2 = time.perf_counter()
        pre.append((t1 - t0) * 1e3)
        reg.append((t2 - t1) * 1e3)
    total = [p + r for p, r in zip(pre, reg)]
    return {
        "T": np.array(res.T_target_source),
        "converged": bool(res.converged),
        "iterations": int(res.iterations),
        "preprocess_ms": statistics.median(pre),
        "registration_ms": statistics.median(reg),
        "total_ms": statistics.median(total),
        "total_min_ms": min(total),
        "registration_min_ms": min(reg),
    }


def run_seam(binary, target_path, source_path, args):
    cmd = [binary, target_path, source_path, "--voxel", str(args.voxel), "--threads", str(args.threads),
           "--runs", str(args.runs)]
    out = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
    r = json.loads(out)
    r["T"] = np.array(r["t_target_source"])
    return r


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", default="../shared/data")
    ap.add_argument("--runs", type=int, default=7)
    ap.add_argument("--voxel", type=float, default=0.25)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--kitti-pairs", type=int, default=9)
    ap.add_argument("--json", help="also write the rows here")
    ap.add_argument("--no-build", action="store_true", help="use the gicp_bench binary already built")
    args = ap.parse_args()
    if not os.path.isdir(args.data):
        print(f"notice: {args.data} not found, skipping")
        return 0

    if not args.no_build:
        subprocess.run(["cargo", "build", "--release", "--quiet", "--example", "gicp_bench"], check=True)
    binary = os.path.join("target", "release", "examples", "gicp_bench")

    reg = os.path.join(args.data, "registration")
    ref = np.loadtxt(os.path.join(reg, "relative.txt"))
    pairs = [("hdl32e_pair", os.path.join(reg, "251370668.pcd"), os.path.join(reg, "251371071.pcd"), ref)]
    for seq in ["04", "08"]:
        pairs += kitti_pairs(os.path.join(args.data, "semantickitti", seq), args.kitti_pairs)

    rows = []
    hdr = ("| pair | sg total ms | seam total ms | ratio | sg reg ms | seam reg ms | ratio | "
           "sg err cm / deg | seam err cm / deg | sg it | seam it |")
    print(f"voxel {args.voxel} m, {args.threads} threads, median of {args.runs} runs, k = 20\n")
    print(hdr)
    print("|" + "---|" * (hdr.count("|") - 1))
    for name, tgt_path, src_path, t_ref in pairs:
        sg = run_small_gicp(read_points(tgt_path), read_points(src_path), args)
        se = run_seam(binary, tgt_path, src_path, args)
        sg_t, sg_r = errors(sg["T"], t_ref)
        se_t, se_r = errors(se["T"], t_ref)
        row = {
            "pair": name,
            "small_gicp": {k: sg[k] for k in KEYS}
            | {"trans_err_cm": sg_t, "rot_err_deg": sg_r},
            "seam": {k: se[k] for k in KEYS}
            | {"trans_err_cm": se_t, "rot_err_deg": se_r},
        }
        rows.append(row)
        print(f"| {name} | {sg['total_ms']:.1f} | {se['total_ms']:.1f} | {se['total_ms'] / sg['total_ms']:.2f} | "
              f"{sg['registration_ms']:.1f} | {se['registration_ms']:.1f} | "
              f"{se['registration_ms'] / sg['registration_ms']:.2f} | {sg_t:.1f} / {sg_r:.3f} | "
              f"{se_t:.1f} / {se_r:.3f} | {sg['iterations']} | {se['iterations']} |", flush=True)

    def med(side, key):
        return statistics.median(r[side][key] for r in rows)

    print(f"\nmedian total ms: small_gicp {med('small_gicp', 'total_ms'):.1f}, seam {med('seam', 'total_ms'):.1f}"
          f" (seam/small_gicp {med('seam', 'total_ms') / med('small_gicp', 'total_ms'):.2f})")
    print(f"median registration ms: small_gicp {med('small_gicp', 'registration_ms'):.1f}, "
          f"seam {med('seam', 'registration_ms'):.1f}")
    print(f"median of per-pair minimum total ms (least disturbed by other load): small_gicp "
          f"{med('small_gicp', 'total_min_ms'):.1f}, seam {med('seam', 'total_min_ms'):.1f} (seam/small_gicp "
          f"{med('seam', 'total_min_ms') / med('small_gicp', 'total_min_ms'):.2f})")
    print(f"converged: small_gicp {sum(r['small_gicp']['converged'] for r in rows)}/{len(rows)}, "
          f"seam {sum(r['seam']['converged'] for r in rows)}/{len(rows)}")
    print(f"median error: small_gicp {med('small_gicp', 'trans_err_cm'):.1f} cm / "
          f"{med('small_gicp', 'rot_err_deg'):.3f} deg, seam {med('seam', 'trans_err_cm'):.1f} cm / "
          f"{med('seam', 'rot_err_deg'):.3f} deg")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(rows, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
