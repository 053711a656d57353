"""Robustness of shape networks to keypoint localisation noise (graffiti 1->3).

    .venv/bin/python -m affcorr_bench.shape_noise [--model NAME=PATH ...] [--sigmas 0 1 2 3] \
        [--out benches/results/shape_noise]

Real matchers place x2 within a pixel or two of the true point, so a shape network must give
a good A when patch B is not centred exactly. Protocol: a grid of x1 (10 px spacing) on graffiti
1, x2 = H(x1) + N(0, sigma^2) per coordinate (one seeded draw per sigma, shared by all models),
A_gt = dx2/dx1 of the ground-truth H at x1; each model estimates A at (x1, x2). Metrics: median
and mean ||A - A_gt||_F and mean cosine similarity (affcorr.metrics.affine_errors). Every model
runs in the same process on the same points. `--model` defaults to the bundled network.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import affcorr
import numpy as np
from affcorr.data import graffiti_grid
from affcorr.metrics import affine_errors

from . import common


def grid_ground_truth() -> tuple[Path, Path, np.ndarray]:
    return graffiti_grid(step=10)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--model", action="append", default=None, help="NAME=PATH (repeatable)")
    ap.add_argument("--sigmas", type=float, nargs="+", default=[0.0, 1.0, 2.0, 3.0])
    ap.add_argument("--out", type=Path, default=common.RESULTS / "shape_noise")
    args = ap.parse_args(argv)
    models = [m.split("=", 1) for m in (args.model or ["bundled=" + ""])]
    img1, img2, gt = grid_ground_truth()
    rng = np.random.default_rng(0)
    rows = []
    for sigma in args.sigmas:
        x2 = gt[:, 2:4] + rng.normal(0.0, sigma, (len(gt), 2))
        for name, path in models:
            est = affcorr.ShapeEstimator(model=path or None, threads=1).estimate(
                str(img1), str(img2), gt[:, :2], x2, refine=False
            )
            fro, cos = affine_errors(est[:, 4:], gt[:, 4:])
            rows.append(
                dict(
                    model=name,
                    sigma_px=sigma,
                    n=len(gt),
                    median_fro=float(np.median(fro)),
                    mean_fro=float(fro.mean()),
                    mean_cos=float(cos.mean()),
                )
            )
            print(f"sigma {sigma:g} px  {name:>10}: median {rows[-1]['median_fro']:.3f}")
    common.write_csv(rows, args.out.with_suffix(".csv"))
    cmd = common.command(__spec__.name, argv)
    lines = [
        "# Shape networks under keypoint noise (graffiti 1->3)",
        "",
        f"Command: `{cmd}`",
        "",
        f"{len(gt)} grid points; x2 = H(x1) + N(0, sigma^2) px per coordinate. Median / mean"
        " ||A - A_gt||_F, mean cosine similarity.",
        "",
        "| sigma (px) | " + " | ".join(n for n, _ in models) + " |",
        "|---|" + "---|" * len(models),
    ]
    for sigma in args.sigmas:
        cells = [
            f"{r['median_fro']:.3f} / {r['mean_fro']:.3f} / {r['mean_cos']:.3f}"
            for r in rows
            if r["sigma_px"] == sigma
        ]
        lines.append(f"| {sigma:g} | " + " | ".join(cells) + " |")
    args.out.with_suffix(".md").write_text("\n".join(lines) + "\n")
    print(f"wrote {args.out.with_suffix('.md')}")


if __name__ == "__main__":
    main()
