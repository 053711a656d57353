"""The view cascade on rotated non-planar pairs: relative pose (E, and so F) with image B
turned by 0, 30, 90, 135 and 180 deg.

    .venv/bin/python -m affcorr_bench.views_pose [--synthetic 20] [--max-keypoints 1024]
        [--threads 2] [--matcher NAME] [--board-only --out benches/results/views_pose_board]

Pairs: experiment 3's (affcorr_bench.eval.pose_data): rendered multi-plane scenes with parallax
(the first ``--synthetic``) and the chessboard stereo set, each with exact K1, K2, R, t. Image B
is rotated about its centre on a canvas that holds it (affcorr_bench.views.rotated); each pair
runs through affcorr.Pipeline with views="off" and views="auto" (everything else the defaults
but max_keypoints, threads and, with ``--matcher``, the matcher), the ACs are mapped back into
B's original pixels by the rotation's inverse (x2 = M^-1 x2', A = M^-1 A'), and
affcorr.estimate_relative_pose estimates the pose with the original K2 at the default
threshold. The rotation only changes what the
matcher sees, so an upright pair's figures are what a rotated one should reach.

In the chessboard set's left views the camera stands still and the board moves: the pose is the
board's, and only the matches on the board count, but the matcher also sees the still room,
which it matches upright and not once B is turned. ``--board-only`` fills each image outside
the board's outline (its corners pushed ``BOARD_MARGIN`` px outwards) with its mean grey, so
that those pairs hold one motion and the rotations compare like with like.

Reported per rotation: AUC@5/10/20 of the pose error max(rotation, translation angle), pairs
solved (error < 10 deg), median time per pair, and the views that solved the rotated pairs.

Writes benches/results/views_pose.{md,csv}.
"""

from __future__ import annotations

import argparse
import time
from collections import Counter
from pathlib import Path

import numpy as np

from . import common
from .eval.pose import pair_pose_error, pose_auc
from .views import rotated

ROTATIONS = (0, 30, 90, 135, 180)
SOLVED_DEG = 10.0
BOARD_MARGIN = 8.0  # px that --board-only pushes the board outline's corners outwards


def board_only(img: np.ndarray, poly: np.ndarray, margin: float = BOARD_MARGIN) -> np.ndarray:
    """``img`` with the pixels outside the convex polygon ``poly`` (k, 2) set to the image's
    mean grey, the polygon first grown about its centroid so that each corner moves ``margin``
    px outwards."""
    from .eval.pose_data import inside_convex

    c = poly.mean(axis=0)
    d = poly - c
    grown = c + d * (1.0 + margin / np.linalg.norm(d, axis=1))[:, None]
    h, w = img.shape
    yy, xx = np.mgrid[0:h, 0:w]
    inside = inside_convex(grown, np.c_[xx.ravel(), yy.ravel()].astype(float)).reshape(h, w)
    out = np.full_like(img, int(round(float(img.mean()))))
    out[inside] = img[inside]
    return out


def back_to_original(corrs: np.ndarray, M: np.ndarray) -> np.ndarray:  # noqa: N803
    """ACs found against image B warped by x2' = M x2 (M 3x3 affine), in B's own pixels."""
    Mi = np.linalg.inv(M)  # noqa: N806
    out = corrs.copy()
    out[:, 2:4] = corrs[:, 2:4] @ Mi[:2, :2].T + Mi[:2, 2]
    A = corrs[:, 4:].reshape(-1, 2, 2)  # noqa: N806
    out[:, 4:] = (Mi[:2, :2] @ A).reshape(-1, 4)
    return out


#: What each dataset's pairs are, for the result file.
DATASET_TEXT = {
    "synthetic": "rendered multi-plane scenes with parallax",
    "chessboard": "chessboard pairs of experiment 3's moving-board left views (only their "
    "matches on the board count)",
    "chessboard-stereo": "chessboard pairs of experiment 3's stereo rig",
}


def pair_summary(counts: Counter) -> str:
    """'12 rendered multi-plane scenes with parallax and 13 chessboard pairs of …'."""
    parts = [f"{n} {DATASET_TEXT.get(d, d)}" for d, n in counts.items()]
    return ", ".join(parts[:-1]) + " and " + parts[-1] if len(parts) > 1 else parts[0]


def main(argv=None) -> None:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--synthetic", type=int, default=20, help="rendered pairs")
    p.add_argument("--max-keypoints", type=int, default=1024)
    p.add_argument(
        "--matcher", default=None, help="the pipeline's matcher (default: the pipeline's default)"
    )
    p.add_argument("--threads", type=int, default=2)
    p.add_argument(
        "--rotations",
        default=",".join(map(str, ROTATIONS)),
        help="comma-separated degrees (default: all)",
    )
    p.add_argument("--modes", default="off,auto", help="comma-separated views modes")
    p.add_argument(
        "--refine-affine",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="the pipeline's refine_affine (default: the pipeline's default)",
    )
    p.add_argument(
        "--board-only",
        action="store_true",
        help="only the chessboard's moving-board pairs, each image blanked outside the board",
    )
    p.add_argument(
        "--datasets",
        default=None,
        help="comma-separated datasets to keep (synthetic, chessboard, chessboard-stereo; "
        "default: all)",
    )
    p.add_argument("--out", default=str(common.RESULTS / "views_pose"))
    args = p.parse_args(argv)

    import affcorr
    from affcorr._progress import progress
    from affcorr.pipeline import PIPELINE_DEFAULTS

    from .eval import pose_data

    if args.board_only:
        pairs = [pp for pp in pose_data.chessboard_pairs() if pp.region is not None]
    else:
        pairs = pose_data.synthetic_pairs(args.synthetic) + pose_data.chessboard_pairs()
    if args.datasets:
        keep = {d.strip() for d in args.datasets.split(",") if d.strip()}
        unknown = keep - {pp.dataset for pp in pairs}
        if unknown:
            p.error(f"--datasets {args.datasets}: no pairs of {', '.join(sorted(unknown))}")
        pairs = [pp for pp in pairs if pp.dataset in keep]
    matcher = args.matcher or PIPELINE_DEFAULTS["matcher"]
    rotations = [int(r) for r in args.rotations.split(",") if r.strip()]
    modes = [m.strip() for m in args.modes.split(",") if m.strip()]
    refine = (
        PIPELINE_DEFAULTS["refine_affine"] if args.refine_affine is None else args.refine_affine
    )
    pipes = {
        mode: affcorr.Pipeline(
            matcher=matcher,
            max_keypoints=args.max_keypoints,
            threads=args.threads,
            views=mode,
            refine_affine=refine,
        )
        for mode in modes
    }
    thr = PIPELINE_DEFAULTS["pose_threshold"]
    cases = [(pp, r) for pp in pairs for r in rotations]
    rows = []
    t0 = time.time()
    for pp, r in progress(cases, "views_pose", "pair"):
        img1, img2 = pp.load()
        if args.board_only:
            img1, img2 = board_only(img1, pp.region[0]), board_only(img2, pp.region[1])
        b, M = rotated(img2, np.eye(3), r)  # noqa: N806 (M: B's pixels -> the rotated view)
        for mode, pipe in pipes.items():
            t = time.perf_counter()
            res = pipe.match_pair(img1, b)
            err, kept = pair_pose_error(pp, back_to_original(res.corrs, M), thr)
            view = res.view
            rows.append(
                dict(
                    dataset=pp.dataset,
                    pair=pp.name,
                    rotation_deg=r,
                    views=mode,
                    matches=kept,
                    pose_error_deg=err,
                    solved=bool(err < SOLVED_DEG),
                    seconds=time.perf_counter() - t,
                    view=view["label"] if view else "",
                    views_tried=len(res.views),
                )
            )
    out = Path(args.out)
    common.write_csv(rows, out.with_suffix(".csv"))
    table = []
    datasets = list(dict.fromkeys(x["dataset"] for x in rows))
    for r in rotations:
        for mode in modes:
            sel = [x for x in rows if x["rotation_deg"] == r and x["views"] == mode]
            used = Counter(x["view"] for x in sel if x["solved"] and x["view"] not in ("plain", ""))
            auc = pose_auc([x["pose_error_deg"] for x in sel])
            table.append(
                [
                    f"B rotated {r}°",
                    mode,
                    f"{sum(x['solved'] for x in sel)} / {len(sel)}",
                    " / ".join(
                        f"{sum(x['solved'] for x in sel if x['dataset'] == d)}" for d in datasets
                    ),
                    *[100 * a for a in auc],
                    float(np.median([x["matches"] for x in sel])),
                    float(np.median([x["seconds"] for x in sel])),
                    ", ".join(f"{k} ×{v}" for k, v in used.most_common(3)) or "–",
                ]
            )
    load = common.load_average()
    lines = [
        "# The view cascade on rotated "
        + ("chessboard views, the board alone" if args.board_only else "non-planar pairs")
        + ": relative pose",
        "",
        f"Command: `{common.command(__spec__.name)}`",
        "",
        f"Date: {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}. affcorr "
        f"{affcorr.__version__}; matcher {matcher} at "
        f"{args.max_keypoints} keypoints, {args.threads} threads; refine_affine {refine}; "
        f"pose threshold {thr} px. "
        f"{len(cases)} cases in {time.time() - t0:.0f} s; load average at the end "
        f"{load[0]:.1f} / {load[1]:.1f} / {load[2]:.1f} on 2 cores.",
        "",
        (
            f"Pairs: the {len(pairs)} moving-board pairs of experiment 3's chessboard set, each "
            "image filled with its mean grey outside the board's outline, its corners pushed "
            f"{BOARD_MARGIN:.0f} px outwards (one motion: the board's)"
            if args.board_only
            else "Pairs: " + pair_summary(Counter(pp.dataset for pp in pairs))
        )
        + ", image B rotated about its centre; the ACs are mapped back to B's pixels and the "
        "pose is estimated with the true intrinsics. Error: max(rotation, translation angle); "
        f"solved: < {SOLVED_DEG:.0f}°.",
        "",
    ]
    lines += common.md_table(
        [
            "transformation",
            "views",
            "solved",
            "solved per set (" + " / ".join(datasets) + ")",
            "AUC@5",
            "AUC@10",
            "AUC@20",
            "median matches",
            "median s/pair",
            "views that solved",
        ],
        table,
    )
    common.write_report(out.with_suffix(".md"), lines + [""])


if __name__ == "__main__":
    main()
