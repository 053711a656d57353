"""Graffiti 1->3: affcorr's pipeline vs OpenCV SIFT + USAC_MAGSAC, in one run.

For each method: matches, correct matches (transfer error under the ground truth H1to3p < 3 px),
and the homography's mean corner error (the four corner pixels of image 1 mapped by the estimate
and by the ground truth). affcorr: ``affcorr.Pipeline(matcher).match_pair`` with the pipeline's
defaults (ACs from the matcher, the shape network and the affine refinement; with
``--also-unrefined``, also without the refinement), then ``affcorr.estimate_homography`` on the
ACs (2-AC samples, local optimisation) and on the same matches' points alone (4-point samples)
over 10 seeds; OpenCV: SIFT
(``cv2.SIFT_create()`` defaults) + Lowe's ratio test 0.8 + ``cv2.findHomography(...,
cv2.USAC_MAGSAC, threshold, maxIters=10000, confidence=0.9999)``, whose USAC runs with a fixed
internal seed (one result). Both at the same inlier thresholds (2 and 3 px). For context, the
same SIFT matches with OpenCV's USAC_ACCURATE and RANSAC, and an oracle: the least-squares H of
SIFT's correct matches (what a perfect robust estimator could reach from them).

Times are of a second call on warm models (each affcorr pipeline matches the pair once before
the timed call; SIFT detects on image A once before), so that neither side's first-call set-up
is counted.

OpenCV runs in benches/peers/.venv-peers (OpenCV 5 needs numpy 2; the project's .venv keeps
numpy < 2; benches/peers/setup.sh makes it) as a subprocess of this script, on the same image
files, in the same run.

    OMP_NUM_THREADS=1 .venv/bin/python -m affcorr_bench.pipeline_vs_sift [--also-unrefined]
        [--matchers xfeat-lighterglue xfeat ...]

writes benches/results/pipeline_vs_sift.md and .csv.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from . import common

ROOT = common.ROOT
PEERS_PYTHON = common.PEERS_PYTHON
MODULE = "affcorr_bench.pipeline_vs_sift"
THRESHOLDS = (2.0, 3.0)
#: OpenCV estimators run on the SIFT matches; the first is the baseline affcorr's pipeline is
#: measured against (the "Against SIFT + USAC_MAGSAC" lines of the report).
OPENCV_METHODS = ("USAC_MAGSAC", "USAC_ACCURATE", "RANSAC")


def sift_worker(a: str, b: str, out: str, thresholds: list[float]) -> None:
    """Runs in .venv-peers: SIFT + ratio test + USAC_MAGSAC; writes JSON."""
    import cv2
    import numpy as np

    sift = cv2.SIFT_create()
    sift.detectAndCompute(cv2.imread(a, cv2.IMREAD_GRAYSCALE), None)  # warm-up, not timed
    t0 = time.perf_counter()
    ia = cv2.imread(a, cv2.IMREAD_GRAYSCALE)
    ib = cv2.imread(b, cv2.IMREAD_GRAYSCALE)
    ka, da = sift.detectAndCompute(ia, None)
    kb, db = sift.detectAndCompute(ib, None)
    t_detect = time.perf_counter() - t0
    t0 = time.perf_counter()
    knn = cv2.BFMatcher(cv2.NORM_L2).knnMatch(da, db, k=2)
    good = [m for m, n in (p for p in knn if len(p) == 2) if m.distance < 0.8 * n.distance]
    t_match = time.perf_counter() - t0
    src = np.float64([ka[m.queryIdx].pt for m in good])
    dst = np.float64([kb[m.trainIdx].pt for m in good])
    results = {}
    for method in OPENCV_METHODS:
        for thr in thresholds:
            t0 = time.perf_counter()
            H, mask = cv2.findHomography(
                src, dst, getattr(cv2, method), thr, maxIters=10000, confidence=0.9999
            )
            t_ransac = time.perf_counter() - t0
            results[f"{method}/{thr}"] = {
                "H": None if H is None else H.tolist(),
                "inliers": 0 if mask is None else int(mask.sum()),
                "ransac_s": t_ransac,
            }
    json.dump(
        {
            "version": cv2.__version__,
            "numpy": np.__version__,
            "keypoints": [len(ka), len(kb)],
            "src": src.tolist(),
            "dst": dst.tolist(),
            "detect_s": t_detect,
            "match_s": t_match,
            "homography": results,
        },
        open(out, "w"),
    )


def run_sift(a: Path, b: Path) -> dict:
    if not PEERS_PYTHON.is_file():
        raise SystemExit(f"{PEERS_PYTHON} missing: run bash benches/peers/setup.sh first")
    with tempfile.TemporaryDirectory() as d:
        out = Path(d) / "sift.json"
        cmd = common.module_cmd(PEERS_PYTHON, MODULE, "--sift-worker", a, b, out, *THRESHOLDS)
        # Only benches/ on the path: nothing of .venv's may leak into the numpy-2 venv.
        env = common.child_env({**os.environ, "PYTHONPATH": ""})
        p = subprocess.run(cmd, capture_output=True, text=True, env=env)
        if p.returncode != 0:
            raise SystemExit(f"SIFT worker failed:\n{p.stderr}")
        return json.loads(out.read_text())


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=10, help="RANSAC seeds for affcorr")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--matchers", nargs="+", default=["xfeat-lighterglue", "xfeat", "xfeat-star"])
    ap.add_argument("--out", type=Path, default=common.RESULTS / "pipeline_vs_sift")
    ap.add_argument("--build", default="", help="a note on the affcorr build, for the table")
    ap.add_argument(
        "--also-unrefined",
        action="store_true",
        help="also each matcher with Pipeline(refine_affine=False) (the network's ACs as they are)",
    )
    args = ap.parse_args(argv)

    import affcorr
    import numpy as np
    from affcorr.data import data_dir, read_opencv_matrix
    from affcorr.metrics import corner_error, correct_mask

    g = data_dir() / "graffiti"
    a, b = g / "graf1.png", g / "graf3.png"
    H_gt = read_opencv_matrix(g / "H1to3p.xml")  # noqa: N806
    W, Hh = 800, 640  # noqa: N806
    rows: list[dict] = []

    t0 = time.perf_counter()
    sift = run_sift(a, b)
    sift_wall = time.perf_counter() - t0
    src, dst = np.array(sift["src"]), np.array(sift["dst"])
    ok = correct_mask(np.hstack([src, dst]), H_gt, 3.0)
    sift_correct = int(ok.sum())
    for method, thr in ((m, t) for m in OPENCV_METHODS for t in THRESHOLDS):
        r = sift["homography"][f"{method}/{thr}"]
        err = float("inf") if r["H"] is None else corner_error(np.array(r["H"]), H_gt, W, Hh)
        rows.append(
            {
                "method": f"OpenCV SIFT + {method}",
                "threshold_px": thr,
                "matches": len(src),
                "correct_3px": sift_correct,
                "inliers": r["inliers"],
                "corner_err_median_px": err,
                "corner_err_min_px": err,
                "corner_err_max_px": err,
                "runs": 1,
                "time_ms": 1e3 * (sift["detect_s"] + sift["match_s"] + r["ransac_s"]),
            }
        )
    H_lsq = affcorr.homography_lsq(src[ok], dst[ok])[0]  # noqa: N806
    err = corner_error(H_lsq, H_gt, W, Hh)
    rows.append(
        {
            "method": "oracle: LSQ H of SIFT's correct matches",
            "threshold_px": 3.0,
            "matches": sift_correct,
            "correct_3px": sift_correct,
            "inliers": sift_correct,
            "corner_err_median_px": err,
            "corner_err_min_px": err,
            "corner_err_max_px": err,
            "runs": 1,
            "time_ms": float("nan"),
        }
    )

    variants = [(m, True) for m in args.matchers]
    if args.also_unrefined:
        variants += [(m, False) for m in args.matchers]
    for matcher, refine in variants:
        pipe = affcorr.Pipeline(matcher, threads=args.threads, refine_affine=refine)
        pipe.match_pair(a, b)  # warm-up: the sessions' first run is not timed
        res = pipe.match_pair(a, b)
        correct = int(correct_mask(res.corrs, H_gt, 3.0).sum())
        # The ACs (2-AC minimal samples, the default), and their points alone (4-point samples).
        for (label, data), thr in (
            (d, t)
            for d in (("2-AC RANSAC", res.corrs), ("4-pt RANSAC on the points", res.corrs[:, :4]))
            for t in THRESHOLDS
        ):
            errs, inl, times = [], [], []
            for seed in range(args.seeds):
                t1 = time.perf_counter()
                H, info = affcorr.estimate_homography(data, threshold=thr, seed=seed)
                times.append(time.perf_counter() - t1)
                errs.append(corner_error(H, H_gt, W, Hh))
                inl.append(info.num_inliers)
            rows.append(
                {
                    "method": f"affcorr {matcher}{'' if refine else ', unrefined'} ({label})",
                    "threshold_px": thr,
                    "matches": len(res),
                    "correct_3px": correct,
                    "inliers": int(np.median(inl)),
                    "corner_err_median_px": float(np.median(errs)),
                    "corner_err_min_px": float(np.min(errs)),
                    "corner_err_max_px": float(np.max(errs)),
                    "runs": args.seeds,
                    "time_ms": 1e3 * (res.timings["total"] + float(np.median(times))),
                }
            )

    common.write_csv(
        [{k: (f"{v:.4f}" if isinstance(v, float) else v) for k, v in r.items()} for r in rows],
        args.out.with_suffix(".csv"),
    )

    try:
        head = subprocess.run(
            ["git", "-C", str(ROOT), "describe", "--always", "--dirty"],
            capture_output=True,
            text=True,
        ).stdout.strip()
    except OSError:
        head = "?"
    load = os.getloadavg()
    lines = [
        "# Graffiti 1→3: affcorr pipeline vs OpenCV SIFT + USAC_MAGSAC (same run)",
        "",
        f"Command: `{common.command(MODULE, argv, prefix='OMP_NUM_THREADS=1 ')}`",
        "",
        f"Machine: {platform.machine()}, {os.cpu_count()} cores, load average "
        f"{load[0]:.1f} / {load[1]:.1f}; git {head}; affcorr pipelines with "
        f"{args.threads} threads; OpenCV {sift['version']} (numpy {sift['numpy']}) in "
        "benches/peers/.venv-peers; SIFT keypoints "
        f"{sift['keypoints'][0]} / {sift['keypoints'][1]}; SIFT wall time incl. the "
        f"subprocess {sift_wall:.1f} s. affcorr from {Path(affcorr.__file__).parent}"
        + (f" ({args.build})" if args.build else "")
        + ".",
        "",
        "H error = mean distance (px) between the 4 corner pixels of graf1 mapped by the "
        "estimate and by H1to3p; correct = matches with transfer error < 3 px under H1to3p. "
        "affcorr: median (min–max) over RANSAC seeds 0..N−1 on the same ACs; OpenCV's USAC "
        "has a fixed internal seed. Time: matching + one estimation (affcorr: its per-stage "
        "total incl. the shape network; SIFT: detection + ratio-test matching + "
        "findHomography).",
        "",
        "| method | thr (px) | matches | correct < 3 px | inliers | H error median (min–max) px"
        " | time ms |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        rng = (
            f"{r['corner_err_median_px']:.2f}"
            if r["runs"] == 1
            else f"{r['corner_err_median_px']:.2f} ({r['corner_err_min_px']:.2f}–"
            f"{r['corner_err_max_px']:.2f})"
        )
        ms = "–" if np.isnan(r["time_ms"]) else f"{r['time_ms']:.0f}"
        lines.append(
            f"| {r['method']} | {r['threshold_px']:g} | {r['matches']} | {r['correct_3px']} | "
            f"{r['inliers']} | {rng} | {ms} |"
        )
    best_sift = min(
        r["corner_err_median_px"] for r in rows if r["method"] == "OpenCV SIFT + USAC_MAGSAC"
    )
    sift_ms = next(r["time_ms"] for r in rows if r["method"] == "OpenCV SIFT + USAC_MAGSAC")
    lines += [
        "",
        f"Against SIFT + USAC_MAGSAC's best threshold ({best_sift:.2f} px; {sift_ms:.0f} ms):",
        "",
    ]
    for r in rows:
        if r["method"].startswith("affcorr"):
            verdict = "below" if r["corner_err_median_px"] < best_sift else "NOT below"
            lines.append(
                f"- {r['method']} at {r['threshold_px']:g} px: median "
                f"{r['corner_err_median_px']:.2f} px — {verdict}; time "
                f"{r['time_ms'] / sift_ms:.2f}× SIFT's"
            )
    text = "\n".join(lines) + "\n"
    args.out.with_suffix(".md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--sift-worker":
        sift_worker(sys.argv[2], sys.argv[3], sys.argv[4], [float(t) for t in sys.argv[5:]])
        raise SystemExit(0)
    raise SystemExit(main())
