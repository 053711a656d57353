"""Photographs taken in portrait or upside down: files stored turned, with the EXIF orientation
tag a camera writes, matched with ``exif_orientation`` on (the default) and off.

    .venv/bin/python -m affcorr_bench.exif_orientation [--synthetic 12] [--threads 2]

Pairs: experiment 1's planar pairs (graffiti 1->3 and one held-out viewpoint and illumination
sequence, exact H; ``views.cases``' rotation family at 0 deg) and experiment 3's pose pairs
(``--synthetic`` rendered multi-plane scenes and the chessboard stereo rig; exact K, R, t).
Image B is written as a PNG file stored turned by 90 deg counter-clockwise, 180 deg or 90 deg
clockwise, tagged by PIL with the EXIF orientation that shows it upright again (6, 3, 8), as
a camera held that way stores it; image A is written untagged. The ACs come back in B's stored
pixels, and are mapped into B's upright pixels for scoring (the map is the tag's exact turn).
Solved: H within 10 px (``views.overlap_error``) or a pose error below 10 deg, at the
pipeline's thresholds. Reported per turn and setting: pairs solved, median and largest time
per pair, and the views the cascade ran.

Writes benches/results/exif_orientation.{md,csv}.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from collections import Counter
from pathlib import Path

import numpy as np

from . import common

#: Stored turn (counter-clockwise quarter turns, numpy's rot90 k) -> the EXIF tag that shows it
#: upright again.
TURNS = {1: 6, 2: 3, 3: 8}
SOLVED_PX, SOLVED_DEG = 10.0, 10.0


def stored_from_upright(k: int, shape: tuple[int, int]) -> np.ndarray:
    """The 3x3 map from an upright image of ``shape`` (H, W) to its pixels stored turned ``k``
    quarter turns counter-clockwise (``np.rot90(img, k)``)."""
    h, w = shape
    ccw = np.array([[0, 1, 0], [-1, 0, w - 1], [0, 0, 1.0]])  # one turn of an H x W image
    m = np.eye(3)
    for _ in range(k):
        m = ccw @ m
        h, w = w, h
        ccw = np.array([[0, 1, 0], [-1, 0, w - 1], [0, 0, 1.0]])
    return m


def write_tagged(img: np.ndarray, path: Path, tag: int | None) -> None:
    from PIL import Image

    u8 = np.clip(np.round(np.asarray(img, np.float64) * (255 if img.max() <= 1 else 1)), 0, 255)
    pil = Image.fromarray(u8.astype(np.uint8))
    if tag is None:
        pil.save(path)
        return
    exif = Image.Exif()
    exif[0x0112] = tag
    pil.save(path, exif=exif)


def to_upright(corrs: np.ndarray, m: np.ndarray) -> np.ndarray:
    """ACs with x2 in B's stored pixels (x_stored = m x_upright) into B's upright pixels."""
    inv = np.linalg.inv(m)
    out = corrs.copy()
    out[:, 2:4] = corrs[:, 2:4] @ inv[:2, :2].T + inv[:2, 2]
    a = corrs[:, 4:].reshape(-1, 2, 2)
    out[:, 4:] = (inv[:2, :2] @ a).reshape(-1, 4)
    return out


def main(argv=None) -> None:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--synthetic", type=int, default=12, help="rendered pose pairs")
    p.add_argument("--max-keypoints", type=int, default=1024)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--out", default=str(common.RESULTS / "exif_orientation"))
    args = p.parse_args(argv)

    import affcorr
    from affcorr._progress import progress
    from affcorr.pipeline import PIPELINE_DEFAULTS

    from .eval import pose_data
    from .eval.pose import pair_pose_error
    from .views import cases, overlap_error

    planar = [c for c in cases(1, ("rotation",)) if c[1] == "B rotated 0°"]
    pose = [
        pp
        for pp in pose_data.synthetic_pairs(args.synthetic) + pose_data.chessboard_pairs()
        if pp.dataset != "chessboard"
    ]
    pipes = {
        exif: affcorr.Pipeline(
            max_keypoints=args.max_keypoints, threads=args.threads, exif_orientation=exif
        )
        for exif in (True, False)
    }
    thr_h = PIPELINE_DEFAULTS["homography_threshold"]
    thr_p = PIPELINE_DEFAULTS["pose_threshold"]
    jobs = [("planar", c) for c in planar] + [("pose", pp) for pp in pose]
    rows = []
    t0 = time.time()
    with tempfile.TemporaryDirectory() as tmp:
        for kind, job in progress(jobs, "exif_orientation", "pair"):
            if kind == "planar":
                _, _, pid, a, b, H = job
                dataset = "planar"
            else:
                pid, dataset = job.name, job.dataset
                a, b = job.load()
            pa = Path(tmp) / "a.png"
            write_tagged(a, pa, None)
            for k, tag in TURNS.items():
                pb = Path(tmp) / f"b{tag}.png"
                write_tagged(np.rot90(b, k), pb, tag)
                m = stored_from_upright(k, b.shape[:2])
                for exif, pipe in pipes.items():
                    t = time.perf_counter()
                    res = pipe.match_pair(pa, pb)
                    corrs = to_upright(res.corrs, m)
                    if kind == "planar":
                        try:
                            Hest, _ = affcorr.estimate_homography(corrs, threshold=thr_h)
                            err = overlap_error(Hest, H, a, b)
                        except (RuntimeError, ValueError):
                            err = float("inf")
                        solved = err < SOLVED_PX
                    else:
                        err, _ = pair_pose_error(job, corrs, thr_p)
                        solved = err < SOLVED_DEG
                    rows.append(
                        dict(
                            dataset=dataset,
                            pair=pid,
                            tag=tag,
                            exif_orientation=exif,
                            matches=len(res),
                            error=err,
                            solved=bool(solved),
                            seconds=time.perf_counter() - t,
                            views=" | ".join(v["label"] for v in res.views),
                        )
                    )
    out = Path(args.out)
    common.write_csv(rows, out.with_suffix(".csv"))
    table = []
    for tag in TURNS.values():
        for exif in (True, False):
            sel = [r for r in rows if r["tag"] == tag and r["exif_orientation"] == exif]
            ran = Counter(v for r in sel for v in r["views"].split(" | ")[1:] if v and v != "plain")
            table.append(
                [
                    tag,
                    "on" if exif else "off",
                    " / ".join(
                        f"{sum(r['solved'] for r in sel if r['dataset'] == d)} of "
                        f"{sum(r['dataset'] == d for r in sel)}"
                        for d in dict.fromkeys(r["dataset"] for r in sel)
                    ),
                    float(np.median([r["seconds"] for r in sel])),
                    float(np.max([r["seconds"] for r in sel])),
                    sum(r["views"] == "plain" for r in sel),
                    ", ".join(f"{k} ×{n}" for k, n in ran.most_common(3)) or "–",
                ]
            )
    load = common.load_average()
    lines = [
        "# Photographs stored turned, with their EXIF orientation tag",
        "",
        f"Command: `{common.command(__spec__.name)}`",
        "",
        f"Date: {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}. affcorr "
        f"{affcorr.__version__}; matcher {PIPELINE_DEFAULTS['matcher']} at "
        f"{args.max_keypoints} keypoints, {args.threads} threads, views "
        f"{PIPELINE_DEFAULTS['views']}; {len(jobs)} pairs × {len(TURNS)} turns × 2 settings in "
        f"{time.time() - t0:.0f} s; load average at the end {load[0]:.1f} / {load[1]:.1f} / "
        f"{load[2]:.1f} on 2 cores.",
        "",
        " ".join(__doc__.split("\n\n")[2].split()),
        "",
        *common.md_table(
            [
                "EXIF tag of B",
                "exif_orientation",
                "solved (" + " / ".join(dict.fromkeys(r["dataset"] for r in rows)) + ")",
                "median s/pair",
                "max s/pair",
                "pairs matched by the plain pass alone",
                "views the cascade ran (most often)",
            ],
            table,
        ),
        "",
    ]
    common.write_report(out.with_suffix(".md"), lines)


if __name__ == "__main__":
    main()
