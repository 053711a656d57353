"""The main demo: the whole pipeline on a real pair with a ground-truth homography.

graffiti 1 -> 3 (bundled, with H1to3p): XFeat matches -> 32x32 patches -> shape network ->
ACs -> AC-based robust homography. Prints per-stage timings, the number of ACs, how many are
correct within 3 px of the ground truth, the inlier ratio, the homography's mean corner error and
the ACs' affine accuracy (median ||A - A_gt||_F on correct matches), and draws the matches with
their affine frames.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

import affcorr
from affcorr.data import graffiti_files, picture_note
from affcorr.metrics import affine_errors, corner_error, correct_mask
from affcorr.pipeline import PIPELINE_DEFAULTS


def run(
    out: Path | None = Path("affcorr_demo.png"),
    matcher: str = PIPELINE_DEFAULTS["matcher"],
    max_keypoints: int = PIPELINE_DEFAULTS["max_keypoints"],
) -> dict:
    """Runs the demo, prints its report and returns its figures."""
    file_a, file_b, H_gt = graffiti_files()
    path_a, path_b = str(file_a), str(file_b)
    img_a = affcorr.read_gray_image(path_a)

    t0 = time.perf_counter()
    pipe = affcorr.Pipeline(matcher=matcher, max_keypoints=max_keypoints)
    t_load = time.perf_counter() - t0
    res = pipe.match_pair(path_a, path_b)
    corrs = res.corrs
    t0 = time.perf_counter()
    H, info = affcorr.estimate_homography(corrs, threshold=3.0)
    t_ransac = time.perf_counter() - t0

    correct = correct_mask(corrs, H_gt, 3.0)
    A = corrs[:, 4:].reshape(-1, 2, 2)
    A_gt = affcorr.affine_from_homography(H_gt, corrs[:, :2])
    fro, cos = affine_errors(A, A_gt)
    h, w = img_a.shape
    err = corner_error(H, H_gt, w, h)
    inliers = info.inliers

    print(f"affcorr {affcorr.__version__} — images → ACs → homography on graffiti 1 → 3\n")
    print(
        f"matcher {matcher} (≤ {max_keypoints} keypoints), shape network "
        f"{Path(pipe.shape_model).name}"
    )
    print("timings:")
    print(f"  {'load models':<12} {1e3 * t_load:8.1f} ms")
    for k, v in res.timings.items():
        print(f"  {k:<12} {1e3 * v:8.1f} ms")
    print(f"  {'RANSAC (H)':<12} {1e3 * t_ransac:8.1f} ms")
    print(f"\nACs: {len(corrs)}, correct within 3 px of the ground truth: {int(correct.sum())}")
    print(
        f"RANSAC inliers: {int(inliers.sum())} / {len(corrs)} "
        f"({inliers.mean():.1%}), {info.num_iterations} iterations"
    )
    print(f"homography mean corner error vs ground truth: {err:.2f} px")
    print(
        f"affine accuracy on correct matches: median ||A − A_gt||_F = "
        f"{np.median(fro[correct]):.3f}, mean cosine similarity "
        f"{cos[correct].mean():.3f}"
    )
    if out is not None and picture_note() is not None:
        print(f"\n{picture_note()}")
    elif out is not None:
        from affcorr.plot import draw_matches

        draw_matches(path_a, path_b, corrs, out, H=H_gt, title="affcorr on graffiti 1→3")
        print(f"\npicture: {out}")
    return {
        "corrs": corrs,
        "correct": correct,
        "H": H,
        "corner_error": err,
        "affine_fro_median": float(np.median(fro[correct])),
        "timings": res.timings,
    }
