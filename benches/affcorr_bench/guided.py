"""Guided re-matching (``Pipeline(guided_matching=True)``) against the plain pipeline, on the
same pairs in one run.

    .venv/bin/python -m affcorr_bench.guided [--synthetic 20] [--max-keypoints 1024]
        [--threads 2]

Planar pairs: experiment 1's (graffiti 1->3 and held-out viewpoint / illumination sequences,
exact H): matches, correct matches (within 3 px of H(x1)), their precision, and the homography
error (mean over A's pixels seen in B) of affcorr's estimator at the default threshold.
Non-planar pairs: experiment 3's rendered multi-plane scenes (the first ``--synthetic``) and
the chessboard stereo set, with exact K, R, t: pose AUC@5/10/20 of max(rotation, translation
angle). Both with views="auto" (the default) so that the hard pairs are in, and the time per
pair.

Writes benches/results/guided.{md,csv}.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from . import common
from .eval.pose import pair_pose_error, pose_auc
from .views import overlap_error


def main(argv=None) -> None:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--synthetic", type=int, default=20)
    p.add_argument("--images", type=int, default=1, help="held-out images per sequence kind")
    p.add_argument("--max-keypoints", type=int, default=1024)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--out", default=str(common.RESULTS / "guided"))
    args = p.parse_args(argv)

    import affcorr
    from affcorr._progress import progress
    from affcorr.metrics import transfer
    from affcorr.pipeline import PIPELINE_DEFAULTS

    from .eval import data, pose_data

    pipes = {
        g: affcorr.Pipeline(max_keypoints=args.max_keypoints, threads=args.threads,
                            guided_matching=g)
        for g in (False, True)
    }  # fmt: skip
    rows = []
    t0 = time.time()
    planar = data.hpatches_pairs(images=args.images)
    for pp in progress(planar, "guided, planar", "pair"):
        for g, pipe in pipes.items():
            t = time.perf_counter()
            H, info, res = pipe.homography(pp.img1, pp.img2, return_matches=True)
            seconds = time.perf_counter() - t
            d = np.linalg.norm(transfer(pp.H, res.corrs[:, :2]) - res.corrs[:, 2:4], axis=1)
            rows.append(
                dict(kind="planar", pair=pp.id, guided=g, matches=len(res),
                     correct=int(np.sum(d < 3.0)), error=overlap_error(H, pp.H, pp.img1, pp.img2),
                     seconds=seconds)
            )  # fmt: skip
    pose_pairs = pose_data.synthetic_pairs(args.synthetic) + pose_data.chessboard_pairs()
    thr = PIPELINE_DEFAULTS["pose_threshold"]
    for pp in progress(pose_pairs, "guided, non-planar", "pair"):
        img1, img2 = pp.load()
        for g, pipe in pipes.items():
            t = time.perf_counter()
            res = pipe.match_pair(img1, img2)
            err, kept = pair_pose_error(pp, res.corrs, thr)
            rows.append(
                dict(kind=pp.dataset, pair=pp.name, guided=g, matches=kept, correct=-1,
                     error=err, seconds=time.perf_counter() - t)
            )  # fmt: skip
    out = Path(args.out)
    common.write_csv(rows, out.with_suffix(".csv"))
    table = []
    for kind in dict.fromkeys(r["kind"] for r in rows):
        for g in (False, True):
            sel = [r for r in rows if r["kind"] == kind and r["guided"] == g]
            m = float(np.median([r["matches"] for r in sel]))
            if kind == "planar":
                correct = sum(r["correct"] for r in sel)
                quality = [
                    f"{np.median([r['correct'] for r in sel]):.0f}",
                    f"{correct / max(sum(r['matches'] for r in sel), 1):.3f}",
                    f"{sum(r['error'] < 10 for r in sel)} / {len(sel)}",
                    f"{np.median([r['error'] for r in sel]):.2f} px",
                    "–",
                ]
            else:
                auc = pose_auc([r["error"] for r in sel])
                quality = ["–", "–", f"{sum(r['error'] < 10 for r in sel)} / {len(sel)}",
                           f"{np.median([r['error'] for r in sel]):.2f}°",
                           " / ".join(f"{100 * a:.1f}" for a in auc)]  # fmt: skip
            table.append(
                [kind, "on" if g else "off", f"{m:.0f}", *quality,
                 float(np.median([r["seconds"] for r in sel]))]
            )  # fmt: skip
    load = common.load_average()
    lines = [
        "# Guided re-matching",
        "",
        f"Command: `{common.command(__spec__.name)}`",
        "",
        f"Date: {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}. affcorr "
        f"{affcorr.__version__}; matcher {PIPELINE_DEFAULTS['matcher']} at "
        f"{args.max_keypoints} keypoints, {args.threads} threads, views auto. {len(rows)} runs in "
        f"{time.time() - t0:.0f} s; load average at the end {load[0]:.1f} / {load[1]:.1f} / "
        f"{load[2]:.1f} on 2 cores.",
        "",
        "Planar: experiment 1's pairs (exact H); correct = within 3 px of H(x1); solved = H "
        "within 10 px over the overlap. Non-planar: experiment 3's rendered scenes and the "
        "chessboard set (exact pose); solved = pose error < 10°; AUC@5/10/20 of the pose error.",
        "",
    ]
    lines += common.md_table(
        ["pairs", "guided", "median matches", "median correct", "precision", "solved",
         "median error", "AUC@5/10/20", "median s/pair"],
        table,
    )  # fmt: skip
    common.write_report(out.with_suffix(".md"), lines + [""])


if __name__ == "__main__":
    main()
