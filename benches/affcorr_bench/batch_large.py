"""affcorr batch at the size issue 25 names: 1000 pairs over 100 images, with the on-disk
feature cache and without, on 2 local workers and on a local 2-worker Ray cluster.

    .venv/bin/python -m affcorr_bench.batch_large [--images 100] [--pairs 1000]
        [--max-keypoints 1024] [--no-ray]

The images: synthetic 640x512 views of graffiti 1 (affcorr_bench.batch_throughput.make_views);
the pairs: ``--pairs`` distinct pairs drawn at random (seed 0) from all of them. Each run is
``affcorr.batch.run`` with H and F per pair, 1 thread per worker; pairs/s from the wall time of
the whole run (process start, model loading, extraction, matching, estimation, HDF5). With the
cache every image's features are computed once per worker and kept on disk; without it every
pair extracts both of its images. Writes benches/results/batch_large.md.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from affcorr import batch

from . import common
from .batch_throughput import make_views, peak_rss, ray_cluster

OUT = common.RESULTS / "batch_large.md"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--images", type=int, default=100)
    ap.add_argument("--pairs", type=int, default=1000)
    ap.add_argument("--max-keypoints", type=int, default=1024)
    ap.add_argument("--no-ray", action="store_true")
    ap.add_argument("--out", type=Path, default=OUT)
    args = ap.parse_args(argv)

    options = dict(matcher="xfeat-lighterglue", max_keypoints=args.max_keypoints)
    rows = []
    t_all = time.time()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        names = make_views(tmp / "images", args.images)
        rng = np.random.default_rng(0)
        every = [(a, b) for i, a in enumerate(names) for b in names[i + 1 :]]
        pick = rng.choice(len(every), size=min(args.pairs, len(every)), replace=False)
        pairs = [every[k] for k in sorted(pick)]

        def run(label: str, **kw) -> None:
            out = tmp / f"out-{label}"
            t = time.time()
            s = batch.run(
                pairs, tmp / "images", out, geometry=["homography", "fundamental"],
                progress=False, threads_per_worker=1, **options, **kw,
            )  # fmt: skip
            assert s.failed == 0, s.failures
            print(f"{label}: {s}", file=sys.stderr, flush=True)
            rows.append([label, s.pairs_per_second, time.time() - t, peak_rss(out)])

        run("2 local workers, feature cache", workers=2)
        run("2 local workers, no cache", workers=2, cache=False)
        if not args.no_ray:
            with ray_cluster() as address:
                run("2 Ray workers, feature cache", ray_address=address)
    load = os.getloadavg()
    lines = [
        "# affcorr batch: 1000 pairs over 100 images",
        "",
        f"Command: `{common.command(__spec__.name)}`",
        "",
        f"Date: {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; {len(pairs)} pairs over "
        f"{args.images} images (640x512 synthetic views of graffiti 1), "
        f"{options['matcher']} at {args.max_keypoints} keypoints, H and F per pair, 1 thread "
        f"per worker; {time.time() - t_all:.0f} s in all; load average at the end "
        f"{load[0]:.1f} / {load[1]:.1f} / {load[2]:.1f} on 2 cores.",
        "",
    ]
    lines += common.md_table(["run", "pairs/s", "wall s", "worker peak RSS (MB)"], rows)
    if len(rows) >= 2:
        lines += [
            "",
            f"The feature cache: {rows[0][1] / rows[1][1]:.2f}× the pairs/s of extracting both "
            "images for every pair.",
        ]
    common.write_report(args.out, lines + [""])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
