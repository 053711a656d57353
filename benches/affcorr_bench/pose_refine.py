"""Relative pose with and without the affine refinement of the ACs, on the same pairs.

    .venv/bin/python -m affcorr_bench.pose_refine [--synthetic 60] [--matcher xfeat-lighterglue]
        [--shape-model PATH] [--out benches/results/pose_refine.md]

Pairs: evaluation experiment 3's data (affcorr_bench.eval.pose_data): the first ``--synthetic``
rendered multi-plane pairs, the opencv-doc chessboard pairs (when benches/eval/pose_setup.sh
has fetched them) and the motorcycle stereo pair. For each pair one ``affcorr.Pipeline`` match
gives the network's ACs; ``affcorr.refine_affine`` then refines them (A, and x2 with it); both
sets go through ``affcorr.estimate_relative_pose`` (2-AC samples, defaults, threshold 1 px as in
experiment 3). Metrics as experiment 3: the pose error max(rotation, translation direction) and
its AUC at 5/10/20 degrees, median rotation and translation errors, and the time of the
refinement.

Writes benches/results/pose_refine.md.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import affcorr
import numpy as np
from affcorr._progress import progress

from . import common
from .eval import pose_data
from .eval.pose import THRESHOLD, pose_auc, rotation_error, translation_error


def pairs(synthetic: int) -> list:
    out = list(pose_data.synthetic_pairs(synthetic))
    for extra in (pose_data.chessboard_pairs, lambda: [pose_data.motorcycle_pair()]):
        try:
            out += extra()
        except (FileNotFoundError, OSError) as e:
            print(f"skipped: {e}", file=sys.stderr)
    return out


def errors(corrs, pair) -> tuple[float, float]:
    keep = pair.keep(corrs[:, :2], corrs[:, 2:4])
    if keep.sum() < 5:
        return float("inf"), float("inf")
    try:
        pose, _ = affcorr.estimate_relative_pose(
            corrs[keep], pair.K1, pair.K2, threshold=THRESHOLD, seed=0
        )
    except RuntimeError:
        return float("inf"), float("inf")
    return rotation_error(pose.R, pair.R), translation_error(pose.t, pair.t)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--synthetic", type=int, default=60)
    ap.add_argument("--matcher", default="xfeat-lighterglue")
    ap.add_argument("--shape-model", default=None, help="shape network (default: the bundled)")
    ap.add_argument("--out", type=Path, default=common.RESULTS / "pose_refine.md")
    args = ap.parse_args(argv)
    t0 = time.time()
    pipe = affcorr.Pipeline(
        args.matcher, threads=2, shape_model=args.shape_model, refine_affine=False
    )
    rows = {"network": [], "network + LK": []}
    by_set = {}
    refine_s, refined_share = [], []
    for pair in progress(pairs(args.synthetic), "pose_refine", "pairs"):
        img1, img2 = pair.load()
        corrs = pipe.match_pair(img1, img2).corrs
        t1 = time.perf_counter()
        r = affcorr.refine_affine(img1, img2, corrs)
        refine_s.append(time.perf_counter() - t1)
        refined_share.append(r.refined.mean() if len(corrs) else np.nan)
        for name, c in (("network", corrs), ("network + LK", r.corrs)):
            e = errors(c, pair)
            rows[name].append(e)
            by_set.setdefault((pair.dataset, name), []).append(e)

    def line(label, errs):
        e = np.array(errs, float)
        auc = pose_auc(np.max(e, axis=1))
        med = np.median(e, axis=0)
        return (
            f"| {label} | {len(e)} | {100 * auc[0]:.1f} / {100 * auc[1]:.1f} / "
            f"{100 * auc[2]:.1f} | {med[0]:.3f} | {med[1]:.3f} |"
        )

    lines = [
        "# Relative pose with and without the affine refinement (same matches)",
        "",
        f"Command: `{common.command(__spec__.name, argv)}`"
        f" ({time.time() - t0:.0f} s; {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}).",
        "",
        f"Matcher {args.matcher} (affcorr.Pipeline, 2 threads), shape network "
        f"{args.shape_model or 'bundled'}; estimate_relative_pose with "
        f"2-AC samples and defaults at {THRESHOLD} px; pose error = max(rotation, translation "
        "direction), a failure counts as infinite. Refinement: affcorr.refine_affine with its "
        f"defaults, median {1e3 * np.median(refine_s):.0f} ms per pair, "
        f"{100 * np.nanmean(refined_share):.0f}% of the ACs refined on average.",
        "",
        "| ACs | pairs | AUC@5/10/20 (%) | median rotation error (°) | "
        "median translation error (°) |",
        "|---|---|---|---|---|",
    ]
    for name, errs in rows.items():
        lines.append(line(f"all: {name}", errs))
    for (dataset, name), errs in sorted(by_set.items()):
        lines.append(line(f"{dataset}: {name}", errs))
    args.out.write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
