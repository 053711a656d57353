"""The view cascade on rotated and zoomed copies of the evaluation's planar pairs.

    .venv/bin/python -m affcorr_bench.views [--images 1] [--max-keypoints 1024] [--threads 2]
        [--families rotation,zoom,zoomset] [--zoom-seeds 4] [--relative-budget default|none|K]
        [--matcher NAME] [--no-refine-affine]

Pairs: experiment 1's (affcorr_bench.eval.data.hpatches_pairs: graffiti 1->3 plus viewpoint and
illumination sequences of held-out images, exact H), each with image B rotated about its centre
by 0, 30, 90, 135 and 180 deg (the canvas grown to hold it), and the graffiti pair and every
viewpoint pair's reference with image A a 2x, 4x and 6x zoom into its centre, into a point
drawn at random in the middle half of the image (seeded per pair), and with image B zoomed
into such a point instead; and the zoom set (``zoomset``): every reference pair (graffiti and
each held-out image's first viewpoint target) zoomed ``--zoom-seeds`` times by a factor drawn
in 2-6x into a random centre, of A or of B (``zoom_set``). H follows each warp exactly.

Each pair runs through affcorr.Pipeline twice, with views="off" and views="auto" (everything
else the defaults but max_keypoints, threads and, where given, the matcher and
refine_affine), then affcorr's 2-AC homography RANSAC at the
pipeline's threshold. Success: the mean distance between the estimated and the true H's images
of image A's pixels seen in both views is below 10 px (affcorr_bench.eval.extreme's measure).
Reported per transformation: pairs solved with and without views, the median time per pair,
and the views the cascade used.

Writes benches/results/views.{md,csv}.
"""

from __future__ import annotations

import argparse
import time
from collections import Counter
from pathlib import Path

import numpy as np

from . import common

ROTATIONS = (0, 30, 90, 135, 180)
ZOOMS = (2, 4, 6)
FAMILIES = ("rotation", "zoom", "zoomset")
ZOOM_RANGE = (2.0, 6.0)  # the zoom set's factors: uniform in this range
SUCCESS_PX = 10.0


def rotated(img: np.ndarray, H: np.ndarray, deg: float) -> tuple[np.ndarray, np.ndarray]:
    """``img`` rotated by ``deg`` about its centre on a canvas that holds it, and R @ H."""
    import cv2

    h, w = img.shape
    R = cv2.getRotationMatrix2D(((w - 1) / 2, (h - 1) / 2), deg, 1.0)
    corners = np.array([[0, 0, 1], [w - 1, 0, 1], [0, h - 1, 1], [w - 1, h - 1, 1]], float)
    p = corners @ R.T
    R[:, 2] -= p.min(0)
    size = tuple(int(v) for v in np.ceil(p.max(0) - p.min(0)) + 1)
    out = cv2.warpAffine(img, R, size, flags=cv2.INTER_LINEAR)
    R3 = np.vstack([R, [0, 0, 1]])
    return out, R3 @ H


def zoom_map(img: np.ndarray, z: float, centre=(0.5, 0.5)) -> np.ndarray:
    """The map Z that enlarges the part 1/z of ``img`` around ``centre`` (fractions of its
    size) z times, keeping the image's size."""
    h, w = img.shape
    cx, cy = centre[0] * (w - 1), centre[1] * (h - 1)
    # Centred on (cx, cy), clamped so that the enlarged part stays inside the image.
    cx = min(max(cx, (w - 1) / (2 * z)), (w - 1) * (1 - 1 / (2 * z)))
    cy = min(max(cy, (h - 1) / (2 * z)), (h - 1) * (1 - 1 / (2 * z)))
    ox, oy = (w - 1) / 2, (h - 1) / 2
    return np.array([[z, 0, ox - z * cx], [0, z, oy - z * cy], [0, 0, 1.0]])


def zoomed(img: np.ndarray, Z: np.ndarray) -> np.ndarray:
    import cv2

    h, w = img.shape
    return cv2.warpAffine(img, Z[:2], (w, h), flags=cv2.INTER_CUBIC)


def overlap_error(H: np.ndarray, gt: np.ndarray, img1: np.ndarray, img2: np.ndarray) -> float:
    """Mean distance between H's and gt's images of a grid of image 1's pixels that gt maps
    into image 2."""
    from affcorr.metrics import transfer

    h, w = img1.shape
    xs, ys = np.meshgrid(np.linspace(0, w - 1, 20), np.linspace(0, h - 1, 20))
    x = np.c_[xs.ravel(), ys.ravel()]
    y = transfer(gt, x)
    h2, w2 = img2.shape
    inside = (y[:, 0] >= 0) & (y[:, 0] < w2) & (y[:, 1] >= 0) & (y[:, 1] < h2)
    if not np.all(np.isfinite(H)) or not inside.any():
        return float("inf")
    d = np.linalg.norm(transfer(H, x[inside]) - y[inside], axis=1)
    return float(np.mean(d)) if np.all(np.isfinite(d)) else float("inf")


def zoom_set(seeds: int):
    """The varied zoom set: (family, transformation, pair id, img1, img2, H) for each reference
    pair (graffiti 1->3 and every viewpoint sequence's first target, all held-out images) and
    seed: a zoom factor drawn uniformly in ZOOM_RANGE into a centre drawn in the middle 60% of
    the image, of image A or image B (alternating with the seed), one generator per pair and
    seed. Rows are labelled by the factor's band (2-4x, 4-6x)."""
    from .eval import data

    refs = [
        p
        for p in data.hpatches_pairs(images=None)
        if p.kind != "illumination" and p.meta.get("k", 1) == 1
    ]
    for i, p in enumerate(refs):
        for seed in range(seeds):
            rng = np.random.default_rng([seed, i, 20])
            z = float(rng.uniform(*ZOOM_RANGE))
            centre = rng.uniform(0.2, 0.8, 2)
            band = "2-4x" if z < 4 else "4-6x"
            pid = f"{p.id}-s{seed}-{z:.1f}x"
            if (seed + i) % 2 == 0:
                Z = zoom_map(p.img1, z, centre)  # noqa: N806
                a = zoomed(p.img1, Z)
                yield "zoomset", f"random zoom {band}, A", pid, a, p.img2, p.H @ np.linalg.inv(Z)
            else:
                Z = zoom_map(p.img2, z, centre)  # noqa: N806
                b = zoomed(p.img2, Z)
                yield "zoomset", f"random zoom {band}, B", pid, p.img1, b, Z @ p.H


def cases(images: int | None, families=FAMILIES, zoom_seeds: int = 4):
    """(family, transformation, pair id, img1, img2, H) for every case."""
    from .eval import data

    pairs = data.hpatches_pairs(images=images)
    if "rotation" in families:
        for p in pairs:
            for r in ROTATIONS:
                b, H = rotated(p.img2, p.H, r)
                yield "rotation", f"B rotated {r}°", p.id, p.img1, b, H
    for i, p in enumerate(pairs if "zoom" in families else []):
        if p.kind == "illumination" or (p.kind == "viewpoint" and p.meta.get("k", 1) != 1):
            continue
        rng = np.random.default_rng(i)
        for z in ZOOMS:
            Z = zoom_map(p.img1, z)
            yield "zoom", f"A zoomed {z}x", p.id, zoomed(p.img1, Z), p.img2, p.H @ np.linalg.inv(Z)
            Z = zoom_map(p.img1, z, rng.uniform(0.25, 0.75, 2))
            a = zoomed(p.img1, Z)
            yield "zoom", f"A zoomed {z}x off-centre", p.id, a, p.img2, p.H @ np.linalg.inv(Z)
            Z = zoom_map(p.img2, z, rng.uniform(0.25, 0.75, 2))
            b = zoomed(p.img2, Z)
            yield "zoom", f"B zoomed {z}x off-centre", p.id, p.img1, b, Z @ p.H
    if "zoomset" in families:
        yield from zoom_set(zoom_seeds)


def main(argv=None) -> None:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--images", type=int, default=1, help="held-out images per sequence kind")
    p.add_argument("--max-keypoints", type=int, default=1024)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--families", default=",".join(FAMILIES), help="comma-separated")
    p.add_argument(
        "--zoom-seeds", type=int, default=4, help="the zoom set's cases per reference pair"
    )
    p.add_argument(
        "--relative-budget",
        default="default",
        help="the cascade's view_relative_budget: 'default', 'none' or a number",
    )
    p.add_argument(
        "--matcher", default=None, help="the pipeline's matcher (default: the pipeline's default)"
    )
    p.add_argument(
        "--refine-affine",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="the pipeline's refine_affine (default: the pipeline's default)",
    )
    p.add_argument("--out", default=str(common.RESULTS / "views"))
    args = p.parse_args(argv)

    import affcorr
    from affcorr._progress import progress
    from affcorr.pipeline import PIPELINE_DEFAULTS

    budget = {"default": PIPELINE_DEFAULTS["view_relative_budget"], "none": None}.get(
        args.relative_budget.lower(), None
    )
    if args.relative_budget.lower() not in ("default", "none"):
        budget = float(args.relative_budget)
    matcher = args.matcher or PIPELINE_DEFAULTS["matcher"]
    refine = (
        PIPELINE_DEFAULTS["refine_affine"] if args.refine_affine is None else args.refine_affine
    )
    pipes = {
        mode: affcorr.Pipeline(
            matcher,
            refine_affine=refine,
            max_keypoints=args.max_keypoints,
            threads=args.threads,
            views=mode,
            view_relative_budget=budget,
        )
        for mode in ("off", "auto")
    }
    thr = PIPELINE_DEFAULTS["homography_threshold"]
    families = tuple(f.strip() for f in args.families.split(",") if f.strip())
    all_cases = list(cases(args.images, families, args.zoom_seeds))
    rows = []
    t0 = time.time()
    for family, what, pid, a, b, H in progress(all_cases, "views", "pair"):
        for mode, pipe in pipes.items():
            t = time.perf_counter()
            Hest, info, res = pipe.homography(a, b, threshold=thr, return_matches=True)
            seconds = time.perf_counter() - t
            err = overlap_error(Hest, H, a, b)
            view = res.view
            rows.append(
                dict(
                    family=family,
                    transformation=what,
                    pair=pid,
                    views=mode,
                    matches=len(res),
                    inliers=int(info.num_inliers),
                    error_px=err,
                    solved=bool(err < SUCCESS_PX),
                    seconds=seconds,
                    view=view["label"] if view else "",
                    views_tried=len(res.views),
                    # The cascade's cost in plain passes: its time over the plain pass's.
                    cost=(
                        res.timings["total"]
                        / max(res.timings["total"] - res.timings["views"], 1e-9)
                    ),
                    # The work the relative budget counts, in plain passes (the plain one's 1
                    # included): deterministic, unlike the time.
                    work=sum(v["work"] for v in res.views),
                )
            )
    out = Path(args.out)
    common.write_csv(rows, out.with_suffix(".csv"))
    table = []
    for what in dict.fromkeys(r["transformation"] for r in rows):
        sel = {m: [r for r in rows if r["transformation"] == what and r["views"] == m]
               for m in ("off", "auto")}  # fmt: skip
        used = Counter(r["view"] for r in sel["auto"] if r["solved"] and r["view"] != "plain")
        table.append(
            [
                what,
                f"{sum(r['solved'] for r in sel['off'])} / {len(sel['off'])}",
                f"{sum(r['solved'] for r in sel['auto'])} / {len(sel['auto'])}",
                float(np.median([r["seconds"] for r in sel["off"]])),
                float(np.median([r["seconds"] for r in sel["auto"]])),
                float(np.max([r["seconds"] for r in sel["auto"]])),
                max((r["views_tried"] for r in sel["auto"]), default=0),
                max((r["cost"] for r in sel["auto"] if r["solved"]), default=float("nan")),
                max((r["work"] for r in sel["auto"] if r["solved"]), default=float("nan")),
                ", ".join(f"{k} ×{v}" for k, v in used.most_common(3)) or "–",
            ]
        )
    load = common.load_average()
    lines = [
        "# The view cascade on rotated and zoomed pairs",
        "",
        f"Command: `{common.command(__spec__.name)}`",
        "",
        f"Date: {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}. affcorr "
        f"{affcorr.__version__}; matcher {matcher} at "
        f"{args.max_keypoints} keypoints, {args.threads} threads; refine_affine {refine}; "
        f"homography threshold {thr} "
        f"px; view_relative_budget {budget}. {len(all_cases)} cases in "
        f"{time.time() - t0:.0f} s; load average at the end "
        f"{load[0]:.1f} / {load[1]:.1f} / {load[2]:.1f} on 2 cores.",
        "",
        "Pairs: experiment 1's planar pairs (graffiti 1->3 and held-out viewpoint / "
        "illumination sequences, exact H) with B rotated, and the reference pairs (graffiti, "
        "each viewpoint sequence's first target) with A zoomed into its centre or into a "
        "random point of its middle half, or B zoomed so. Solved: H "
        f"within {SUCCESS_PX:.0f} px of the truth on average over A's pixels seen in B. "
        "*views tried*: the most views (the plain pair included) of a pair; *cost*: the most "
        "time a solved pair's cascade took, in plain passes (total time / time without the "
        "cascade's views); *work*: the most work a solved pair's cascade did, in plain passes "
        "as the budget counts it (pixels extracted, keypoints matched, ACs made: the same on "
        "any machine).",
        "",
    ]
    lines += common.md_table(
        [
            "transformation",
            "solved, views off",
            "solved, views auto",
            "median s/pair, off",
            "median s/pair, auto",
            "max s/pair, auto",
            "max views tried",
            "max cost of a solved pair (× plain)",
            "max work of a solved pair (× plain)",
            "views that solved",
        ],
        table,
    )
    common.write_report(out.with_suffix(".md"), lines + [""])


if __name__ == "__main__":
    main()
