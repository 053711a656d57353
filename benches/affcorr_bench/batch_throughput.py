"""affcorr batch throughput (issue 25) and the per-image feature cache (issue 21).

    .venv/bin/python -m affcorr_bench.batch_throughput [--images 10] [--matcher xfeat-lighterglue]
        [--max-keypoints 1024] [--no-ray]

The images: ``--images`` synthetic 640x512 views of graffiti 1 (mild random homographies),
every pair of them (10 images: 45 pairs, issue 21's "50 pairs over 10 images"). Measured in one
run, on whatever else the machine is doing:

1. The feature cache, in one process with 1 thread: ``Pipeline.match_pair`` per pair (each
   image's features extracted for every pair it is in) against ``Pipeline.extract`` once per
   image then ``Pipeline.match_features`` per pair (what ``affcorr batch`` does); the best of
   two alternated rounds of each.
2. ``affcorr.batch.run`` with 1 and 2 local worker processes (1 thread each) and on a local Ray
   cluster of two 1-CPU worker nodes: pairs/s from the wall time of the whole run (process
   start, model loading, feature extraction, matching, H + F estimation, writing HDF5), and
   the scaling efficiency (rate with 2 workers / (2 x rate with 1)).
3. The peak resident memory of a worker (``peak_rss_mb`` in matches.h5) against the number
   of pairs.

Writes benches/results/batch.md.
"""

from __future__ import annotations

import argparse
import contextlib
import itertools
import os
import platform
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import affcorr
import numpy as np
from affcorr import batch
from affcorr.data import data_dir

from . import common

OUT = common.RESULTS / "batch.md"


def make_views(folder: Path, n: int, size=(640, 512), seed: int = 0) -> list[str]:
    from PIL import Image

    folder.mkdir(parents=True, exist_ok=True)
    src = Image.open(data_dir() / "graffiti" / "graf1.png").convert("L")
    rng = np.random.default_rng(seed)
    w, h = src.size
    names = []
    for i in range(n):
        quad = np.array([[0, 0], [0, h], [w, h], [w, 0]], float)
        quad += rng.uniform(-0.08, 0.08, size=(4, 2)) * [w, h]
        im = src.transform(src.size, Image.Transform.QUAD, quad.ravel().tolist(), Image.BILINEAR)
        im.resize(size, Image.BILINEAR).save(folder / f"view{i:03d}.png")
        names.append(f"view{i:03d}.png")
    return names


def cache_comparison(folder: Path, pairs, options: dict, rounds: int = 2) -> tuple[float, float]:
    """Best of ``rounds`` alternated runs of each (the machine's load varies)."""
    p = affcorr.Pipeline(threads=1, **options)
    p.match_pair(folder / pairs[0][0], folder / pairs[0][1])  # warm-up
    without = with_cache = float("inf")
    for _ in range(rounds):
        t = time.perf_counter()
        plain = [p.match_pair(folder / a, folder / b) for a, b in pairs]
        without = min(without, time.perf_counter() - t)
        t = time.perf_counter()
        feats = {n: p.extract(folder / n) for n in {x for pr in pairs for x in pr}}
        cached = [p.match_features(feats[a], feats[b]) for a, b in pairs]
        with_cache = min(with_cache, time.perf_counter() - t)
        for x, y in zip(plain, cached):
            assert np.array_equal(x.corrs, y.corrs), "the cache changed a result"
    return len(pairs) / without, len(pairs) / with_cache


def peak_rss(output: Path) -> float:
    import h5py

    peaks = []
    with h5py.File(output / "matches.h5", "r") as fd:
        fd.visititems(
            lambda _, o: (
                peaks.append(o.attrs["peak_rss_mb"])
                if isinstance(o, h5py.Group) and "peak_rss_mb" in o.attrs
                else None
            )
        )
    return max(peaks)


@contextlib.contextmanager
def ray_cluster(workers: int = 2):
    """`ray start --head` (no CPUs) and ``workers`` 1-CPU nodes on 127.0.0.1, stopped after."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    ray_cli = str(Path(sys.executable).with_name("ray"))
    env = dict(os.environ, RAY_USAGE_STATS_ENABLED="0")

    def node(*args):
        return subprocess.Popen(
            [ray_cli, "start", "--block", "--node-ip-address=127.0.0.1", *args],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True,
            env=env,
        )  # fmt: skip

    nodes = [node("--head", f"--port={port}", "--num-cpus=0", "--include-dashboard=false")]
    try:
        for _ in range(240):
            try:
                socket.create_connection(("127.0.0.1", port), timeout=1).close()
                break
            except OSError:
                time.sleep(0.5)
        import ray

        ray.init(address=f"127.0.0.1:{port}", log_to_driver=False)
        # One node at a time: two raylets starting together can pick the same free port.
        for cpus in range(1, workers + 1):
            nodes.append(node(f"--address=127.0.0.1:{port}", "--num-cpus=1"))
            for _ in range(240):
                if ray.cluster_resources().get("CPU", 0) >= cpus:
                    break
                if nodes[-1].poll() is not None:
                    raise RuntimeError("a Ray worker node did not start")
                time.sleep(0.5)
        yield f"127.0.0.1:{port}"
    finally:
        import ray

        if ray.is_initialized():
            ray.shutdown()
        for p in reversed(nodes):
            with contextlib.suppress(ProcessLookupError):
                os.killpg(p.pid, signal.SIGTERM)
        for p in nodes:
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(p.pid, signal.SIGKILL)


def crash_trials(n: int, seed: int = 0) -> list[str]:
    """Failure injection: ``n`` times, SIGKILL the whole ``affcorr batch`` run (driver and
    workers) after a random 1.5-3.5 s and restart it with ``--resume``; then check that the
    HDF5 files open, every pair is there once and equals the serial ``match_pair``."""
    import random

    import h5py

    random.seed(seed)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        names = make_views(tmp / "images", 10)
        pairs = list(itertools.combinations(names, 2))
        pf = tmp / "pairs.txt"
        pf.write_text("".join(f"{a} {b}\n" for a, b in pairs))
        out = tmp / "out"
        cmd = [
            sys.executable, "-m", "affcorr.cli", "batch", str(pf), str(tmp / "images"), "-o",
            str(out), "--matcher", "xfeat", "--max-keypoints", "512", "--workers", "2",
            "--chunk-size", "1", "--geometry", "homography,fundamental", "-q", "--no-progress",
        ]  # fmt: skip
        counts = []
        for _ in range(n):
            p = subprocess.Popen(
                cmd + (["--resume"] if out.exists() else []), start_new_session=True,
                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
            )  # fmt: skip
            time.sleep(random.uniform(1.5, 3.5))
            with contextlib.suppress(ProcessLookupError):
                os.killpg(p.pid, signal.SIGKILL)
            p.wait()
            with h5py.File(out / "matches.h5", "r") as f:  # raises if the crash broke it
                counts.append(sum(len(f[a]) for a in f))
        r = subprocess.run(cmd + ["--resume"], capture_output=True, text=True)
        ref = affcorr.Pipeline("xfeat", max_keypoints=512, threads=2)
        differ = 0
        with h5py.File(out / "matches.h5", "r") as f:
            got = {(a, b): f[a][b]["acs"][()] for a in f for b in f[a]}
        for a, b in pairs:
            want = ref.match_pair(tmp / "images" / a, tmp / "images" / b).corrs
            differ += not np.array_equal(got[(a, b)], want)
        rows += [
            "## Failure injection: the whole run killed and resumed",
            "",
            f"Command: `.venv/bin/python -m affcorr_bench.batch_throughput --crash {n}` "
            f"(`xfeat`, 512 keypoints, 2 workers, {len(pairs)} pairs over 10 images). {n} "
            "times: SIGKILL of the process group (driver and workers) 1.5-3.5 s after a start "
            "with `--resume`, then a last run to the end.",
            "",
            f"- pairs in matches.h5 after each kill: {', '.join(map(str, counts))}; the files "
            "opened every time;",
            f"- last run: exit {r.returncode}, {len(got)} of {len(pairs)} pairs present, "
            f"{differ} different from the serial `match_pair`.",
            "",
            "In the tests: a SIGKILL of the run then a resume (tests/test_batch.py), a killed "
            "local worker and a killed Ray worker on a 127.0.0.1 cluster (tests/test_batch.py, "
            "tests/test_batch_ray.py): every pair present and equal to the serial result.",
            "",
        ]
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--images", type=int, default=10)
    ap.add_argument("--matcher", default="xfeat-lighterglue")
    ap.add_argument("--max-keypoints", type=int, default=1024)
    ap.add_argument("--no-ray", action="store_true")
    ap.add_argument("--out", type=Path, default=OUT)
    ap.add_argument(
        "--crash", type=int, default=0, metavar="N",
        help="only the failure injection: N kills of the whole run, appended to --out",
    )  # fmt: skip
    args = ap.parse_args(argv)
    if args.crash:
        rows = crash_trials(args.crash)
        text = args.out.read_text() if args.out.exists() else ""
        text = text.split("## Failure injection")[0].rstrip("\n") + "\n\n" + "\n".join(rows)
        args.out.write_text(text)
        print("\n".join(rows))
        return 0
    options = dict(matcher=args.matcher, max_keypoints=args.max_keypoints)
    rows: list[str] = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        names = make_views(tmp / "images", args.images)
        pairs = list(itertools.combinations(names, 2))
        print(f"{len(pairs)} pairs over {len(names)} images", file=sys.stderr)

        r_without, r_with = cache_comparison(tmp / "images", pairs, options)
        print(f"cache: {r_without:.2f} -> {r_with:.2f} pairs/s", file=sys.stderr)

        def batch_rate(label: str, pair_list, **kw) -> tuple[float, float]:
            out = tmp / f"out-{label}"
            s = batch.run(
                pair_list, tmp / "images", out, geometry=["homography", "fundamental"],
                progress=False, **options, **kw,
            )  # fmt: skip
            assert s.failed == 0, s.failures
            print(f"{label}: {s}", file=sys.stderr)
            return s.pairs_per_second, peak_rss(out)

        r1, m1 = batch_rate("local1", pairs, workers=1)
        r2, m2 = batch_rate("local2", pairs, workers=2)
        rr = mr = float("nan")
        if not args.no_ray:
            with ray_cluster() as address:
                rr, mr = batch_rate("ray2", pairs, ray_address=address)
        mem = []
        for n in (len(pairs) // 4, len(pairs) // 2, len(pairs)):
            mem.append((n, batch_rate(f"mem{n}", pairs[:n], workers=1)[1]))

    load = os.getloadavg()
    eff = r2 / (2 * r1)
    eff_ray = rr / (2 * r1)
    rows += [
        "# affcorr batch: throughput, scaling, feature cache, memory",
        "",
        "Command: `.venv/bin/python -m affcorr_bench.batch_throughput"
        + (" ".join([""] + (argv or sys.argv[1:])) if (argv or sys.argv[1:]) else "")
        + "`",
        "",
        f"Machine: {platform.machine()}, {os.cpu_count()} cores, shared with other work while "
        f"it ran (load average {load[0]:.1f} / {load[1]:.1f} / {load[2]:.1f} at the end; the "
        "rates are of that moment). "
        f"Pipeline: `{args.matcher}`, {args.max_keypoints} keypoints, the other options at "
        f"their defaults; {len(names)} synthetic 640x512 views of graffiti, all {len(pairs)} "
        "pairs; batch runs estimate H and F per pair and write features.h5 + matches.h5.",
        "",
        "## Feature cache (one process, 1 thread)",
        "",
        "| | pairs/s |",
        "|---|---:|",
        f"| `match_pair` per pair (features extracted per pair) | {r_without:.2f} |",
        f"| `extract` once per image + `match_features` per pair | {r_with:.2f} |",
        f"| speed-up | {r_with / r_without:.2f}x |",
        "",
        "Results are identical (checked pair by pair).",
        "",
        "## Throughput (`affcorr.batch.run`, wall time of the whole run)",
        "",
        "| executor | workers x threads | pairs/s | scaling efficiency | worker peak RSS (MB) |",
        "|---|---|---:|---:|---:|",
        f"| local | 1 x 1 | {r1:.2f} | 1.00 | {m1:.0f} |",
        f"| local | 2 x 1 | {r2:.2f} | {eff:.2f} | {m2:.0f} |",
        f"| Ray (2 nodes of 1 CPU, 127.0.0.1) | 2 x 1 | {rr:.2f} | {eff_ray:.2f} | {mr:.0f} |",
        "",
        "Scaling efficiency: rate / (workers x the 1-worker rate).",
        "",
        "## Peak memory of a worker against the number of pairs (local, 1 worker)",
        "",
        "| pairs | worker peak RSS (MB) |",
        "|---:|---:|",
        *[f"| {n} | {m:.0f} |" for n, m in mem],
        "",
    ]
    args.out.write_text("\n".join(rows))
    print("\n".join(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
