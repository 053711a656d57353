"""A picture of an extreme-viewpoint pair solved by the view cascade (experiment 4's pairs,
issue 20): the plain matcher's matches above, the cascade's ACs below, both coloured by the
ground-truth homography (green within 3 px), each titled with what it cost.

    .venv/bin/python -m affcorr_bench.eval.extreme_figure [--pair x-leuvenA-80]

Writes benches/results/eval/extreme_pair.png.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from . import suite

OUT = suite.RESULTS / "extreme_pair.png"


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--pair", default="x-leuvenA-80", help="an experiment 4 pair id")
    p.add_argument("--max-keypoints", type=int, default=1024)
    p.add_argument("-o", "--output", type=Path, default=OUT)
    args = p.parse_args(argv)

    import matplotlib

    matplotlib.use("Agg")
    import affcorr
    import matplotlib.pyplot as plt
    from affcorr.plot import draw_matches

    from .data import extreme_pairs

    pairs = {q.id: q for q in extreme_pairs()}
    if args.pair not in pairs:
        raise SystemExit(f"--pair: {args.pair!r} is not one of {sorted(pairs)}")
    q = pairs[args.pair]
    panels = []
    for views in ("off", "auto"):
        pipe = affcorr.Pipeline(max_keypoints=args.max_keypoints, threads=1, views=views)
        t0 = time.perf_counter()
        res = pipe.match_pair(q.img1, q.img2)
        secs = time.perf_counter() - t0
        used = res.view
        what = (
            "plain matcher (views off)"
            if views == "off"
            else f"view cascade: {len(res.views)} views tried, ACs from view "
            f"'{used['label'] if used else 'plain'}'"
        )
        fig = draw_matches(q.img1, q.img2, res.corrs, H=q.H, title=f"{q.id}: {what}; {secs:.2f} s")
        fig.canvas.draw()
        panels.append(np.asarray(fig.canvas.buffer_rgba()))
        plt.close(fig)
    width = max(im.shape[1] for im in panels)
    stacked = np.concatenate(
        [
            np.pad(im, ((0, 0), (0, width - im.shape[1]), (0, 0)), constant_values=255)
            for im in panels
        ]
    )
    plt.imsave(args.output, stacked)
    print(f"wrote {args.output}")


if __name__ == "__main__":
    main()
