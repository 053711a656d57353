"""Peak memory of the main APIs at N = 10^6 correspondences (docs/reliability.md).

Each case runs in its own process under GNU time (``/usr/bin/time -v``, "Maximum resident set
size": the whole process's peak, input building included). What the call itself adds is
measured inside the process: after the input is built (and glibc's free heap trimmed), the
kernel's peak-RSS mark is reset
(``/proc/self/clear_refs`` = 5), and the call's peak is ``VmHWM`` after it minus ``VmRSS``
before it. The input is a homography scene with 30% outliers, float64 C-contiguous (64 MB at
N = 10^6).

    .venv/bin/python -m affcorr_bench.reliability.peak_memory [--n 1000000]
        [--out benches/results/peak_memory.md]
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import time
from pathlib import Path

from .. import common

CHILD = r"""
import sys, time
import numpy as np
import affcorr

n, case = int(sys.argv[1]), sys.argv[2]
rng = np.random.default_rng(0)
H = np.array([[0.9, 0.1, 20.0], [-0.05, 1.05, -10.0], [1e-4, 2e-4, 1.0]])
corrs = affcorr.correspondences_from_homography(H, rng.uniform(0, 640, (n, 2)))
out = rng.random(n) < 0.3
corrs[out, 2:4] = rng.uniform(0, 640, (int(out.sum()), 2))
K = np.array([[700.0, 0, 320], [0, 720, 240], [0, 0, 1]])
F = np.array([[1e-6, -2e-5, 3e-3], [2.2e-5, 1e-7, -4e-3], [-3e-3, 4.1e-3, 1.0]])
def status(key):
    with open("/proc/self/status") as f:
        return next(int(l.split()[1]) for l in f if l.startswith(key + ":"))
# Hand the input-building temporaries' freed heap back to the kernel, so that the call's new
# memory is not hidden in pages that are free but still resident.
import ctypes
ctypes.CDLL("libc.so.6").malloc_trim(0)
rss_before = status("VmRSS")
with open("/proc/self/clear_refs", "w") as f:
    f.write("5")  # reset VmHWM to the current RSS
t = time.perf_counter()
if case == "estimate_homography":
    affcorr.estimate_homography(corrs, threshold=2.0)
elif case == "estimate_relative_pose":
    affcorr.estimate_relative_pose(corrs, K, K, threshold=2.0)
elif case == "sampson_affine":
    affcorr.sampson_affine(F, corrs)
elif case == "sampson_point":
    affcorr.sampson_point(F, corrs)
print(f"seconds={time.perf_counter() - t:.3f}")
print(f"call_kib={status('VmHWM') - rss_before}")
"""

CASES = [
    "baseline",
    "estimate_homography",
    "estimate_relative_pose",
    "sampson_affine",
    "sampson_point",
]


def run(n: int, case: str) -> tuple[float, float, float]:
    """(process peak RSS in MiB, peak the call adds in MiB, seconds of the call)."""
    proc = subprocess.run(
        ["/usr/bin/time", "-v", sys.executable, "-c", CHILD, str(n), case],
        capture_output=True,
        text=True,
        check=True,
    )
    kib = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", proc.stderr)[1])
    seconds = float(re.search(r"seconds=([\d.]+)", proc.stdout)[1])
    call = int(re.search(r"call_kib=(-?\d+)", proc.stdout)[1])
    return kib / 1024, call / 1024, seconds


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1_000_000)
    ap.add_argument("--out", type=Path, default=common.RESULTS / "peak_memory.md")
    args = ap.parse_args(argv)
    rows = {case: run(args.n, case) for case in CASES}
    lines = [
        f"# Peak memory at N = {args.n:,} correspondences",
        "",
        f"`{common.command(__spec__.name, ['--n', args.n])}` "
        f"({time.strftime('%Y-%m-%d')}, {os.cpu_count()} cores, load average "
        f"{os.getloadavg()[0]:.1f}). Process peak: GNU time's maximum resident set size, "
        f"building the (N, 8) float64 input ({args.n * 64 / 1e6:.0f} MB) included; call "
        "peak: the peak resident set during the call minus the resident set before it.",
        "",
        "| call | process peak RSS (MiB) | call peak (MiB) | bytes per correspondence | time (s) |",
        "| --- | ---: | ---: | ---: | ---: |",
    ]
    for case, (peak, call, seconds) in rows.items():
        name = "baseline (input only, no call)" if case == "baseline" else case
        per = call * 2**20 / args.n
        lines.append(f"| {name} | {peak:.0f} | {call:.0f} | {per:.0f} | {seconds:.2f} |")
    common.write_report(args.out, [*lines, ""])


if __name__ == "__main__":
    main()
