"""Per-AC confidence (issue 19): every AC carries ``affine_confidence`` in [0, 1] and a
``reliable`` flag; a refinement that failed is never passed off as a good AC.

Ground truth: an analytic texture under a known plane-induced homography (A_gt = dH/dx at x1,
exact), built here in numpy independently of the Rust code. The confidence is recomputed in
numpy from the features and the calibrated weights and must equal the Rust one.
"""

from __future__ import annotations

import affcorr
import numpy as np
import pytest
from affcorr.metrics import affine_errors
from affcorr.shape import REFINE_STATUSES, confidence_model

H = np.array([[1.05, 0.12, 6.0], [-0.08, 0.95, 4.0], [2e-4, -1e-4, 1.0]])


def texture(x, y):
    """A smooth analytic texture (sum of sinusoids)."""
    rng = np.random.default_rng(5)
    v = np.zeros_like(x, dtype=np.float64)
    for _ in range(24):
        f, th, ph = 0.05 + 0.25 * rng.random(), 2 * np.pi * rng.random(), 6.3 * rng.random()
        v += np.sin(f * np.cos(th) * x + f * np.sin(th) * y + ph)
    return 0.5 + 0.08 * v


def apply_h(x1):
    p = np.c_[x1, np.ones(len(x1))] @ H.T
    return p[:, :2] / p[:, 2:]


def jacobian(x1):
    """dx2/dx1 of H at x1, (N, 4) row-major."""
    p = np.c_[x1, np.ones(len(x1))] @ H.T
    w = p[:, 2:3]
    top = H[:2, :2][None] / w[:, :, None]
    corr = (p[:, :2] / w**2)[:, :, None] * H[2, :2][None, None, :]
    return (top - corr).reshape(-1, 4)


@pytest.fixture(scope="module")
def plane_pair():
    """Image A = texture; image B = 0.9 texture(H^-1 x) + 0.05 (float32, 200 x 200)."""
    y, x = np.mgrid[:200, :200].astype(np.float64)
    a = texture(x, y)
    hi = np.linalg.inv(H)
    q = np.stack([x.ravel(), y.ravel(), np.ones(x.size)], 1) @ hi.T
    u, v = (q[:, 0] / q[:, 2]).reshape(x.shape), (q[:, 1] / q[:, 2]).reshape(x.shape)
    b = 0.9 * texture(u, v) + 0.05
    return a.astype(np.float32), b.astype(np.float32)


def grid_points():
    g = np.arange(50.0, 141.0, 10.0)
    return np.array([[gx, gy] for gy in g for gx in g])


def logistic(features, name):
    w, t, names = confidence_model(name)
    assert features.shape[1] == len(w) == len(names)
    return 1.0 / (1.0 + np.exp(-(features @ w))), t


def test_reliable_refined_acs_match_the_plane_and_python_agrees_with_rust(plane_pair):
    a, b = plane_pair
    x1 = grid_points()
    gt = jacobian(x1)
    # Start 0.2 off in A and ~1 px off in x2, as a matcher and the network would be.
    rng = np.random.default_rng(0)
    start = np.c_[x1, apply_h(x1) + rng.normal(0, 0.7, x1.shape), gt + rng.normal(0, 0.1, gt.shape)]
    r = affcorr.refine_affine(a, b, start)
    n = len(x1)
    assert r.affine_confidence.shape == (n,) and r.affine_confidence.dtype == np.float64
    assert r.reliable.shape == (n,) and r.reliable.dtype == np.bool_
    assert r.status.shape == (n,) and set(r.status) <= set(REFINE_STATUSES)
    assert np.all((r.affine_confidence >= 0) & (r.affine_confidence <= 1))
    assert np.array_equal(r.refined, r.status == "refined")
    # Reliable only where refined; on this clean plane most are.
    assert not np.any(r.reliable & ~r.refined)
    assert r.reliable.mean() > 0.8, r.status
    fro, cos = affine_errors(r.corrs[r.reliable, 4:], gt[r.reliable])
    assert fro.max() < 0.02 and cos.min() > 0.999, fro.max()
    # The same confidence from the features and the calibrated weights, in numpy.
    conf, t = logistic(r.confidence_features, "refinement")
    np.testing.assert_allclose(r.affine_confidence, conf, rtol=0, atol=1e-12)
    assert np.array_equal(r.reliable, (conf >= t) & r.refined)


def test_a_failed_refinement_is_flagged_unreliable(plane_pair):
    a, b = plane_pair
    # Image B replaced by an unrelated texture: no window fits, every input comes back.
    rng = np.random.default_rng(1)
    other = np.clip(0.5 + 0.2 * rng.standard_normal(b.shape), 0, 1).astype(np.float32)
    flat = np.full_like(a, 0.5)
    x1 = grid_points()[:20]
    start = np.c_[x1, apply_h(x1), jacobian(x1)]
    for img_a, img_b in ((a, other), (flat, flat)):
        r = affcorr.refine_affine(img_a, img_b, start)
        assert not r.refined.any(), r.status
        assert np.array_equal(r.corrs, start)  # the input, unchanged ...
        assert not r.reliable.any()  # ... but never passed off as good
        assert np.all(r.status != "refined")
    assert set(r.status) == {"flat"}


def test_estimate_detailed_carries_confidence(plane_pair):
    a, b = plane_pair
    x1 = grid_points()
    x2 = apply_h(x1)
    est = affcorr.ShapeEstimator(threads=1)
    plain = est.estimate_detailed(a, b, x1, x2)
    assert plain.status is None and plain.confidence_model == "network"
    refined = est.estimate_detailed(a, b, x1, x2, refine=True)
    assert refined.confidence_model == "network_refinement"
    for d, name in ((plain, "network"), (refined, "network_refinement")):
        assert d.affine_confidence.shape == d.reliable.shape == (len(x1),)
        assert np.all((d.affine_confidence >= 0) & (d.affine_confidence <= 1))
        conf, t = logistic(d.confidence_features, name)
        np.testing.assert_allclose(d.affine_confidence, conf, rtol=0, atol=1e-12)
        assert np.all(d.angle_spread >= 0) and np.all(d.angle_spread <= 2)
        assert np.all(d.scale_spread >= 0)
    ok = refined.status == "refined"
    assert np.array_equal(refined.reliable, (conf >= t) & ok)
    # The refined rows equal estimate()'s default output; reliable ones match the plane.
    np.testing.assert_array_equal(refined.corrs, est.estimate(a, b, x1, x2))
    assert refined.reliable.mean() > 0.5, refined.status
    fro, _ = affine_errors(refined.corrs[refined.reliable, 4:], jacobian(x1)[refined.reliable])
    assert fro.max() < 0.02


def test_pipeline_result_and_drop_unreliable():
    from affcorr.data import data_dir

    d = data_dir() / "graffiti"
    kw = dict(max_keypoints=512, threads=2, views="off")
    res = affcorr.Pipeline("xfeat", **kw).match_pair(d / "graf1.png", d / "graf3.png")
    n = len(res)
    assert n > 50 and res.corrs.shape == (n, 8)
    assert res.affine_confidence.shape == (n,) and res.reliable.shape == (n,)
    assert res.reliable.dtype == np.bool_
    assert np.all((res.affine_confidence >= 0) & (res.affine_confidence <= 1))
    assert 0 < res.reliable.sum() < n
    kept = affcorr.Pipeline("xfeat", drop_unreliable=True, **kw).match_pair(
        d / "graf1.png", d / "graf3.png"
    )
    assert kept.reliable.all() and len(kept) == res.reliable.sum()
    np.testing.assert_array_equal(kept.corrs, res.corrs[res.reliable])
    np.testing.assert_array_equal(kept.certainty, res.certainty[res.reliable])


def test_bad_input_names_the_argument():
    with pytest.raises(ValueError, match="name"):
        confidence_model("bogus")
    with pytest.raises(ValueError, match="name"):
        confidence_model(3)
    img = np.zeros((40, 40), np.float32)
    with pytest.raises(ValueError, match="corrs"):
        affcorr.refine_affine(img, img, np.zeros((2, 7)))


def test_pipeline_and_estimator_give_the_same_confidence():
    """The Rust pipeline's scores equal the estimator's on the same matches (no downscaling,
    no views): one computation behind both APIs."""
    from affcorr.data import data_dir

    d = data_dir() / "graffiti"
    a, b = d / "graf1.png", d / "graf3.png"
    kw = dict(max_keypoints=512, threads=2, views="off")
    raw = affcorr.Pipeline("xfeat", refine_affine=False, **kw).match_pair(a, b)
    res = affcorr.Pipeline("xfeat", **kw).match_pair(a, b)
    est = affcorr.ShapeEstimator(threads=2)
    for refine, r in ((False, raw), (True, res)):
        e = est.estimate_detailed(a, b, raw.corrs[:, :2], raw.corrs[:, 2:4], refine=refine)
        np.testing.assert_allclose(e.corrs, r.corrs, rtol=0, atol=1e-9)
        np.testing.assert_allclose(e.affine_confidence, r.affine_confidence, rtol=0, atol=1e-9)
        np.testing.assert_array_equal(e.reliable, r.reliable)
