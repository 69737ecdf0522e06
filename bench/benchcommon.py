"""Helpers the benchmark scripts share: logging, the CLI error type, and
how busy other processes kept the machine while something was timed (a
speed measured on a busy machine is flagged, not trusted)."""

import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def log(msg):
    print(msg, file=sys.stderr, flush=True)


class SeamError(RuntimeError):
    pass


# ---------------------------------------------------------------- other processes' CPU


BUSY_FLAG = 0.3  # other processes busier than this many cores during a timed section: its speed is flagged


def _system_busy_s():
    """CPU seconds all processes have used since boot (Linux /proc/stat), or None."""
    try:
        f = Path("/proc/stat").read_text().split("\n", 1)[0].split()[1:]
        user, nice, system, _idle, _iowait, irq, softirq, steal = (int(v) for v in f[:8])
        return (user + nice + system + irq + softirq + steal) / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError):
        return None


def _own_cpu_s():
    t = os.times()  # this process and its waited-for children (seam subprocesses)
    return t.user + t.system + t.children_user + t.children_system


class OtherLoad:
    """Cores other processes kept busy on average between start and stop:
    system-wide CPU time minus this process's and its children's, over wall time."""

    def __init__(self):
        self.sys0, self.own0, self.t0 = _system_busy_s(), _own_cpu_s(), time.perf_counter()

    def cores(self):
        sys1, own1, t1 = _system_busy_s(), _own_cpu_s(), time.perf_counter()
        if self.sys0 is None or sys1 is None or t1 <= self.t0:
            return None
        return max(0.0, ((sys1 - self.sys0) - (own1 - self.own0)) / (t1 - self.t0))


# ---------------------------------------------------------------- the seam binary and the work folder


def seam_in_work(tool, seam_path, no_build, out, prefix):
    """Runs `cargo build --release` (unless `no_build`), makes the work folder
    (`out`, or a temporary one) and copies the seam binary into it, so that a
    concurrent `cargo build` cannot swap it mid-run. Returns (work, binary)."""
    root = Path(__file__).resolve().parents[1]
    if not no_build:
        log("cargo build --release")
        if subprocess.run(["cargo", "build", "--release", "--quiet"], cwd=root).returncode != 0:
            sys.exit(f"{tool}: `cargo build --release` failed; fix the build or pass --no-build "
                     "to use the existing binary")
    exe = Path(seam_path)
    if not exe.is_file():
        sys.exit(f"{tool}: no seam binary at {exe}: run `cargo build --release` or pass --seam PATH")
    work = Path(out) if out else Path(tempfile.mkdtemp(prefix=prefix))
    work.mkdir(parents=True, exist_ok=True)
    work = work.resolve()
    binary = work / "seam-bin"
    shutil.copy2(exe, binary)
    return work, binary
