"""Graph-cut local optimisation from Python: ``lo="graph_cut"``.

The scenes are test_estimation.py's (50% outliers, sigma = 0.5 px); graph-cut LO must find
models as accurate and inlier sets as complete as the default IRLS LO, deterministically.
"""

from __future__ import annotations

import affcorr
import numpy as np
import pytest
from conftest import random_scene
from test_estimation import E_THRESHOLD, H_THRESHOLD, angle_deg, corrupt, multi_plane


def recall(found: np.ndarray, truth: np.ndarray) -> float:
    return float((found & truth).sum() / truth.sum())


@pytest.fixture(scope="module")
def scenes():
    rng = np.random.default_rng(31)
    h_scene = random_scene(rng)
    h, h_truth = corrupt(rng, h_scene.correspondences(h_scene.sample_pixels(rng, 800)), 0.5)
    e_scene = random_scene(rng)
    e, e_truth = corrupt(rng, multi_plane(rng, e_scene, 800), 0.5)
    return (h_scene, h, h_truth), (e_scene, e, e_truth)


def test_graph_cut_lo_matches_irls(scenes):
    (hs, h, ht), (es, e, et) = scenes
    for lo in ("irls", "graph_cut"):
        H, info = affcorr.estimate_homography(h, threshold=H_THRESHOLD, lo=lo)
        corners = np.array([[0, 0, 1], [640, 0, 1], [0, 480, 1], [640, 480, 1.0]]).T
        a, b = H @ corners, hs.H @ corners
        assert np.abs(a[:2] / a[2] - b[:2] / b[2]).max() < 1.0, lo
        assert recall(info.inliers, ht) >= 0.99, lo
        pose, info = affcorr.estimate_relative_pose(e, es.K1, es.K2, threshold=E_THRESHOLD, lo=lo)
        assert angle_deg(pose.R @ es.R.T) < 0.5, lo
        assert recall(info.inliers, et) >= 0.99, lo
        F, info = affcorr.estimate_fundamental(e, threshold=E_THRESHOLD, lo=lo)
        assert recall(info.inliers, et) >= 0.99, lo


def test_graph_cut_lo_is_deterministic(scenes):
    _, (es, e, _) = scenes
    a = affcorr.estimate_relative_pose(e, es.K1, es.K2, lo="graph_cut", seed=3)
    b = affcorr.estimate_relative_pose(e, es.K1, es.K2, lo="graph_cut", seed=3)
    assert np.array_equal(a[0].R, b[0].R) and np.array_equal(a[1].inliers, b[1].inliers)


def test_bad_lo_names_the_option(scenes):
    (_, h, _), _ = scenes
    with pytest.raises(ValueError, match="lo must be one of"):
        affcorr.estimate_homography(h, lo="graphcut")
    assert "lo" in affcorr.ESTIMATOR_OPTIONS
