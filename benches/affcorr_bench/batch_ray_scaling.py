"""Ray scaling of affcorr batch: 1 and 2 Ray worker nodes, and where the CPU time goes.

    .venv/bin/python -m affcorr_bench.batch_ray_scaling [--images 40] [--pairs 200]

The same pairs (``--pairs`` drawn at random, seed 0, from ``--images`` synthetic 640x512 views
of graffiti 1; xfeat-lighterglue at 1024 keypoints, H and F, the feature cache on) run on a
local Ray cluster (affcorr_bench.batch_throughput.ray_cluster: a head without CPUs and 1 or
2 one-CPU worker nodes on 127.0.0.1). While each run goes, every process's CPU time is
sampled once a second (psutil), grouped by kind: Ray's task workers (``ray::``), its daemons
(raylet, gcs_server, log_monitor, agents) and the driver. The efficiency of the added
worker is rate(2) / (2 x rate(1)); the CPU seconds per pair of the task workers say whether
a worker does more work with a neighbour or only gets less of the machine.
Writes benches/results/batch_ray_scaling.md.
"""

from __future__ import annotations

import argparse
import collections
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
import psutil
from affcorr import batch

from . import common
from .batch_throughput import make_views, ray_cluster

OUT = common.RESULTS / "batch_ray_scaling.md"
#: Substrings of a command line -> the kind its CPU time is counted under.
KINDS = ("ray::", "raylet", "gcs_server", "log_monitor", "dashboard", "runtime_env", "monitor.py")


def _kind(p: psutil.Process) -> str:
    try:
        line = " ".join(p.cmdline())
    except psutil.Error:
        return "gone"
    return next((k for k in KINDS if k in line), "other")


def _cpu_by_process() -> dict[int, tuple[str, float]]:
    out = {}
    for p in psutil.process_iter():
        try:
            t = p.cpu_times()
            out[p.pid] = (_kind(p), t.user + t.system)
        except psutil.Error:
            pass
    return out


def _measured_run(pairs, images: Path, out: Path, address: str) -> tuple[float, dict]:
    """(pairs/s, {kind: CPU seconds}) of one batch run on the cluster at ``address``."""
    before = _cpu_by_process()
    last: dict[int, tuple[str, float]] = {}
    done = threading.Event()

    def sample() -> None:  # processes that exit keep their last reading
        while not done.wait(1.0):
            last.update(_cpu_by_process())

    sampler = threading.Thread(target=sample)
    sampler.start()
    try:
        s = batch.run(
            pairs, images, out, geometry=["homography", "fundamental"], progress=False,
            threads_per_worker=1, matcher="xfeat-lighterglue", max_keypoints=1024,
            ray_address=address,
        )  # fmt: skip
    finally:
        done.set()
        sampler.join()
    last.update(_cpu_by_process())
    assert s.failed == 0, s.failures
    cpu: collections.Counter = collections.Counter()
    for pid, (kind, t) in last.items():
        cpu[kind] += t - before.get(pid, (kind, 0.0))[1]
    return s.pairs_per_second, dict(cpu)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--images", type=int, default=40)
    ap.add_argument("--pairs", type=int, default=200)
    ap.add_argument("--out", type=Path, default=OUT)
    args = ap.parse_args(argv)
    rows, rates, cpu_per_pair = [], {}, {}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        names = make_views(tmp / "images", args.images)
        every = [(a, b) for i, a in enumerate(names) for b in names[i + 1 :]]
        pick = np.random.default_rng(0).choice(len(every), min(args.pairs, len(every)), False)
        pairs = [every[k] for k in sorted(pick)]
        for workers in (1, 2):
            with ray_cluster(workers) as address:
                rate, cpu = _measured_run(pairs, tmp / "images", tmp / f"out{workers}", address)
            wall = len(pairs) / rate
            rates[workers] = rate
            cpu_per_pair[workers] = cpu.get("ray::", 0) / len(pairs)
            daemons = sum(v for k, v in cpu.items() if k not in ("ray::", "other"))
            rows.append(
                [workers, f"{rate:.2f}", f"{wall:.1f}", f"{cpu.get('ray::', 0) / wall:.2f}",
                 f"{1000 * cpu.get('ray::', 0) / len(pairs):.0f}", f"{daemons / wall:.2f}",
                 f"{cpu.get('other', 0) / wall:.2f}"]
            )  # fmt: skip
    load = common.load_average()
    lines = [
        "# affcorr batch on Ray: scaling from 1 to 2 worker nodes, and where the CPU goes",
        "",
        f"Command: `{common.command(__spec__.name)}`",
        "",
        f"Date: {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; {len(pairs)} pairs over "
        f"{args.images} images; load average at the end {load[0]:.1f} / {load[1]:.1f} / "
        f"{load[2]:.1f} on 2 cores.",
        "",
        __doc__.split("\n\n", 2)[2].rsplit("Writes", 1)[0].strip(),
        "",
    ]
    lines += common.md_table(
        ["Ray worker nodes", "pairs/s", "wall s", "task workers (cores)",
         "task CPU ms per pair", "Ray daemons (cores)", "other processes (cores)"],
        rows,
    )  # fmt: skip
    lines += [
        "",
        f"Efficiency of the second worker: {rates[2] / (2 * rates[1]):.2f} "
        "(rate with 2 / (2 x rate with 1)); it depends on the cores the task workers got "
        "(the table's columns), i.e. on whatever else runs on the machine.",
        "",
        f"Work efficiency: {cpu_per_pair[1] / cpu_per_pair[2]:.2f} (task CPU per pair with "
        "1 node / with 2): whether a pair costs more CPU when a second worker runs beside it; "
        "independent of other load.",
        "",
    ]
    common.write_report(args.out, lines)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
