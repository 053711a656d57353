"""Would the view cascade's rotation screen rank as well at half resolution? (A feasibility
probe for a cheaper first step: the screen extracts seven rotated images of B, about 2.3 of the
3.7 plain passes a rotated pair costs, benches/results/views_budget.md.)

    .venv/bin/python -m affcorr_bench.screen_scale [--images 1] [--out benches/results/screen_scale]

For every pair of affcorr_bench.views' rotation family (B rotated by 30, 90, 135 and 180 deg),
each of the cascade's seven rotations of B (``views::ROTATIONS_DEG``) is scored as the screen
scores it, approximately: XFeat's mutual nearest neighbours (``Pipeline("xfeat")``, 1024
keypoints) and the inliers of a homography fitted to their points at 5 px; once on the images
as they are, once on both halved (area averaging; the threshold in the halved pixels). A pair
is ranked right when its best-scored rotation is the one that brings B nearest upright against
A (the in-plane angle of the true homography's Jacobian at A's centre). The margin is the best
score over the second best. Writes ``<out>.{md,csv}``.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from . import common
from . import views as V

# The cascade's rotations of B (crates/affcorr-pipeline/src/views.rs, ROTATIONS_DEG).
CANDIDATES = (90, 270, 180, 45, 315, 135, 225)
TURNS = (30, 90, 135, 180)
THRESHOLD_PX = 5.0


def residual_angle(H: np.ndarray, centre: np.ndarray) -> float:
    """The in-plane rotation (deg, in (-180, 180]) of H's Jacobian at ``centre``."""
    x = np.array([centre[0], centre[1], 1.0])
    y = H @ x
    J = (H[:2, :2] * y[2] - np.outer(y[:2], H[2, :2])) / y[2] ** 2
    return float(np.degrees(np.arctan2(J[1, 0] - J[0, 1], J[0, 0] + J[1, 1])))


def _half(img: np.ndarray) -> np.ndarray:
    import cv2

    h, w = img.shape
    return cv2.resize(img, (w // 2, h // 2), interpolation=cv2.INTER_AREA)


def main(argv=None) -> None:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--images", type=int, default=1, help="hpatches_pairs' images per kind")
    p.add_argument("--out", default=str(common.RESULTS / "screen_scale"))
    args = p.parse_args(argv)

    import affcorr
    from affcorr._progress import progress

    from .eval import data

    pipe = affcorr.Pipeline(
        "xfeat", max_keypoints=1024, threads=2, refine_affine=False, views="off"
    )

    def score(a: np.ndarray, b: np.ndarray) -> int:
        res = pipe.match_pair(np.ascontiguousarray(a), np.ascontiguousarray(b))
        if len(res) < 8:
            return 0
        pts = np.ascontiguousarray(res.corrs[:, :4])
        try:
            _, info = affcorr.estimate_homography(pts, threshold=THRESHOLD_PX)
        except RuntimeError:  # no model
            return 0
        return int(info.inliers.sum())

    cases = [(p, t) for p in data.hpatches_pairs(images=args.images) for t in TURNS]
    rows, t0 = [], time.time()
    for pair, turn in progress(cases, "screen_scale", "pair"):
        b, H = V.rotated(pair.img2, pair.H, turn)
        centre = np.array(pair.img1.shape[::-1], float) / 2
        views = {c: V.rotated(b, H, c) for c in CANDIDATES}
        right = min(CANDIDATES, key=lambda c: abs(residual_angle(views[c][1], centre)))
        for scale, f in (("full", lambda x: x), ("half", _half)):
            a = f(pair.img1).astype(np.float32)
            s = {c: score(a, f(views[c][0]).astype(np.float32)) for c in CANDIDATES}
            ranked = sorted(s, key=s.get, reverse=True)
            rows.append(
                dict(
                    pair=pair.id,
                    turn=turn,
                    scale=scale,
                    right=right,
                    best=ranked[0],
                    ranked_right=ranked[0] == right,
                    best_score=s[ranked[0]],
                    second_score=s[ranked[1]],
                    right_score=s[right],
                    margin=s[ranked[0]] / max(s[ranked[1]], 1),
                )
            )
    out = Path(args.out)
    common.write_csv(rows, out.with_suffix(".csv"))
    table = []
    for scale in ("full", "half"):
        sel = [r for r in rows if r["scale"] == scale]
        right = [r for r in sel if r["ranked_right"]]
        table.append(
            [
                scale,
                f"{len(right)} / {len(sel)}",
                f"{np.median([r['margin'] for r in right]):.1f}" if right else "–",
                f"{min((r['margin'] for r in right), default=float('nan')):.1f}",
                f"{np.median([r['right_score'] for r in sel]):.0f}",
            ]
        )
    wrong = [
        f"{r['pair']} turned {r['turn']}° ({r['scale']}: best {r['best']}°, right {r['right']}°)"
        for r in rows
        if not r["ranked_right"]
    ]
    load = common.load_average()
    lines = [
        "# The rotation screen at half resolution: does it rank as at full?",
        "",
        f"Command: `{common.command(__spec__.name, argv)}`",
        "",
        f"Date: {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}. affcorr "
        f"{affcorr.__version__}; XFeat mutual nearest neighbours at 1024 keypoints, homography "
        f"inliers at {THRESHOLD_PX:g} px; {len(cases)} rotated pairs in {time.time() - t0:.0f} s; "
        f"load average at the end {load[0]:.1f} / {load[1]:.1f} / {load[2]:.1f} on 2 cores.",
        "",
        "Ranked right: the best-scored of the seven rotations of B is the one nearest upright. "
        "Margin: its score over the second best's (median, and the smallest, over the pairs "
        "ranked right). Right score: the right rotation's score (median over all pairs).",
        "",
    ]
    lines += common.md_table(
        ["screen", "ranked right", "median margin", "smallest margin", "right score"], table
    )
    lines += ["", "Ranked wrong: " + ("; ".join(wrong) if wrong else "none") + "."]
    common.write_report(out.with_suffix(".md"), lines)


if __name__ == "__main__":
    main()
