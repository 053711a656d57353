"""affcorr batch on a pair list in which some pairs do not overlap, at several view budgets.

    .venv/bin/python -m affcorr_bench.batch_mixed [--pairs 16] [--workers 2]
        [--budgets off,12,30]

The list: ``--pairs`` pairs of synthetic 640x512 views of graffiti 1 (mild random homographies;
they overlap and verify in the plain pass) and as many pairs of different images that do not
overlap (training and held-out textures of affcorr.train.sources, each at most 640 px a side),
shuffled (seed 0). Each budget runs ``affcorr.batch.run`` on the whole list (``--workers``
local workers of 1 thread, homography and fundamental per pair, feature cache on) from a fresh
output: pairs/s over the whole run and over each half (from the per-pair times the batch
records), and the pairs whose homography has at least 15 inliers. ``off`` is
``views="off"``; a number is ``view_relative_budget`` (12: the batch's default, 30: a single
pair's). What it shows: the cost of the pairs that do not overlap, which is the budget
(benches/results/views_budget.md), set against the pairs that do.

Writes benches/results/batch_mixed.md.
"""

from __future__ import annotations

import argparse
import os
import random
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from . import common
from .batch_throughput import make_views

OUT = common.RESULTS / "batch_mixed.md"


def _unrelated_images(folder: Path, n_pairs: int) -> list[tuple[str, str]]:
    """``n_pairs`` pairs of different textures (eval.data.unrelated_pairs) written as PNG
    files into ``folder``."""
    from PIL import Image

    from .eval.data import _u8, unrelated_pairs

    out = []
    for a, b, img0, img1 in unrelated_pairs(n_pairs):
        files = (f"tex_{Path(a).stem}.png", f"tex_{Path(b).stem}.png")
        for f, img in zip(files, (img0, img1)):
            if not (folder / f).exists():
                Image.fromarray(_u8(img)).save(folder / f)
        out.append(files)
    return out


def _read_pairs(output: Path) -> dict[str, tuple[float, int]]:
    """{pair group: (seconds in its worker, homography inliers)} of a batch's matches.h5."""
    import h5py

    out = {}
    with h5py.File(output / "matches.h5", "r") as fd:

        def visit(name: str, obj) -> None:
            if isinstance(obj, h5py.Group) and "seconds" in obj.attrs:
                inliers = int(np.sum(obj["H_inliers"][()])) if "H_inliers" in obj else 0
                out[name] = (float(obj.attrs["seconds"]), inliers)

        fd.visititems(visit)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pairs", type=int, default=16, help="pairs of each kind")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--budgets", default="off,12,30")
    ap.add_argument("--out", type=Path, default=OUT)
    args = ap.parse_args(argv)

    from affcorr import batch

    budgets = [b.strip() for b in args.budgets.split(",") if b.strip()]
    rows = []
    t0 = time.time()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        images = tmp / "images"
        images.mkdir()
        # Views of graffiti 1: every pair of them overlaps.
        views = make_views(images, 8)
        overlapping = list(zip(views, views[1:] + views[:1]))
        overlapping += [(views[i], views[(i + 3) % len(views)]) for i in range(len(views))]
        overlapping = overlapping[: args.pairs]
        unrelated = _unrelated_images(images, args.pairs)
        kind = {p: "overlap" for p in overlapping} | {p: "no overlap" for p in unrelated}
        pair_list = overlapping + unrelated
        random.Random(0).shuffle(pair_list)
        for b in budgets:
            options = dict(views="off") if b == "off" else dict(view_relative_budget=float(b))
            out = tmp / f"out-{b}"
            s = batch.run(
                pair_list, images, out, geometry=["homography", "fundamental"],
                workers=args.workers, progress=False, **options,
            )  # fmt: skip
            assert s.failed == 0, s.failures
            per_pair = _read_pairs(out)
            row = [
                "views off" if b == "off" else f"budget {b}",
                f"{s.pairs_per_second:.2f}",
                f"{s.seconds:.1f}",
            ]
            for k in ("overlap", "no overlap"):
                mine = [per_pair[batch.names_to_pair(*p)] for p in pair_list if kind[p] == k]
                secs = [m[0] for m in mine]
                solved = sum(m[1] >= 15 for m in mine)
                row += [f"{np.median(secs):.2f}", f"{solved} / {len(mine)}"]
            rows.append(row)
            print(" | ".join(row), file=sys.stderr)
    load = os.getloadavg()
    lines = [
        "# affcorr batch on a list where half the pairs do not overlap",
        "",
        f"Command: `{common.command(__spec__.name, argv)}`",
        "",
        f"Date: {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; {time.time() - t0:.0f} s; "
        f"{args.workers} local workers of 1 thread, the batch's other defaults; load average "
        f"at the end {load[0]:.1f} / {load[1]:.1f} / {load[2]:.1f} on {os.cpu_count()} cores.",
        "",
        f"{args.pairs} pairs of overlapping synthetic views of graffiti 1 and {args.pairs} pairs "
        "of different textures, shuffled. s / pair: the median of the seconds each pair took in "
        "its worker (features of an image it sees first, matching, views, estimation); "
        "'H ≥ 15 inliers': pairs whose homography kept at least 15 inliers.",
        "",
    ]
    lines += common.md_table(
        [
            "views",
            "pairs / s",
            "run (s)",
            "s / pair, overlapping",
            "H ≥ 15 inliers, overlapping",
            "s / pair, no overlap",
            "H ≥ 15 inliers, no overlap",
        ],
        rows,
    )
    common.write_report(args.out, lines + [""])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
