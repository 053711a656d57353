"""The bundled shape network alone (refine=False) on a real pair with exact ground truth:
graffiti 1 -> 3.

Matches are ground-truth ones (a grid on image 1 mapped by H1to3p), so the error measured is
the shape network's alone. Bounds: measured values (models/shape.md) plus a margin for other
CPUs' ONNX Runtime kernels; a regression of the model or of the runner's conventions (patch
centre, A direction, O_B - O_A sign) breaks them by far.
"""

from __future__ import annotations

import affcorr
import numpy as np
import pytest
from affcorr.data import data_dir, graffiti_grid
from affcorr.metrics import affine_errors

# Measured with the shipped model, the network alone (refine=False): median 0.376, mean cosine
# 0.748, inverse product 0.121; with x2 jittered by N(0, 2²) px: median 0.417, mean cosine 0.690
# (models/shape.md). The default refinement takes these to 0.044 / 0.053 (test_affine_refine.py).
MEDIAN_FRO_BOUND = 0.43
MEAN_COS_BOUND = 0.71
NOISY_MEDIAN_FRO_BOUND = 0.48
NOISY_MEAN_COS_BOUND = 0.64


@pytest.fixture(scope="module")
def graffiti_acs():
    a, b, gt = graffiti_grid()
    est = affcorr.ShapeEstimator().estimate(str(a), str(b), gt[:, :2], gt[:, 2:4], refine=False)
    return gt, est


def test_bundled_model_is_robust_to_keypoint_noise(graffiti_acs):
    """Matchers put x2 a pixel or two off: patch B is then off-centre, A must stay good."""
    gt, _ = graffiti_acs
    d = data_dir() / "graffiti"
    x2 = gt[:, 2:4] + np.random.default_rng(0).normal(0.0, 2.0, (len(gt), 2))
    est = affcorr.ShapeEstimator().estimate(
        str(d / "graf1.png"), str(d / "graf3.png"), gt[:, :2], x2, refine=False
    )
    fro, cos = affine_errors(est[:, 4:], gt[:, 4:])
    assert np.median(fro) < NOISY_MEDIAN_FRO_BOUND, np.median(fro)
    assert cos.mean() > NOISY_MEAN_COS_BOUND, cos.mean()


def test_bundled_model_accuracy_on_graffiti(graffiti_acs):
    gt, est = graffiti_acs
    fro, cos = affine_errors(est[:, 4:], gt[:, 4:])
    assert np.median(fro) < MEDIAN_FRO_BOUND, np.median(fro)
    assert cos.mean() > MEAN_COS_BOUND, cos.mean()


def test_swapped_images_give_the_inverse_map(graffiti_acs):
    """A (1 -> 3) at x1 and A (3 -> 1) at x2 are inverses: the median product is near I."""
    gt, est = graffiti_acs
    d = data_dir() / "graffiti"
    back = affcorr.ShapeEstimator().estimate(
        str(d / "graf3.png"), str(d / "graf1.png"), gt[:, 2:4], gt[:, :2], refine=False
    )
    prod = est[:, 4:].reshape(-1, 2, 2) @ back[:, 4:].reshape(-1, 2, 2)
    assert np.median(np.linalg.norm((prod - np.eye(2)).reshape(-1, 4), axis=1)) < 0.2
