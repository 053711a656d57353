"""The relative pose's oracle (affcorr_bench.pose_oracle): its whitening matches the scene
generator's noise, and it gains from A exactly as much as A's noise allows."""

from __future__ import annotations

import numpy as np
import pytest
from affcorr_bench import pose_oracle as po
from affcorr_bench import scene_families as sf


def scene(seed, **over):
    s = {**sf.BASE, "outliers": 0.0, **over}
    return sf.make_scene(np.random.default_rng(seed), "relpose", 3000, s), s


@pytest.mark.parametrize("px,aff", [(0.5, 0.02), (1.0, 0.0), (0.25, 0.10)])
def test_whitened_residuals_at_the_truth_are_unit_normal(px, aff):
    sc, _ = scene(7, px=px, aff=aff)
    f = po.fundamental(sc["K1"], sc["K2"], sc["R"], sc["t"])
    for use_a in (False, True):
        w = po.whitened_residuals(f, sc["corrs"], sc["exact_a"], px, aff, use_a)
        assert w.shape == (3000 * (3 if use_a else 1),)
        assert abs(np.mean(w)) < 0.06
        assert 0.9 < np.var(w) < 1.1, (use_a, np.var(w))
    # a wrong noise model is seen: A's noise left out makes the affine rows too large
    if aff > 0:
        w = po.whitened_residuals(f, sc["corrs"], sc["exact_a"], px, 0.0, True).reshape(-1, 3)
        assert np.var(w[:, 1:]) > 1.5


def test_the_oracle_fits_exact_data_exactly_and_gains_from_a_as_its_noise_allows():
    sc, s = scene(8, px=1e-6, aff=1e-6)
    err = sf.pose_errors(*po.oracle_fit(sc, sc["inlier"], s["px"], s["aff"], True), sc)
    assert max(err) < 1e-4
    gains = {}
    for aff in (0.002, 5.0):
        ratios = []
        for seed in range(6):
            sc, s = scene(20 + seed, px=1.0, aff=aff)
            pts = sf.pose_errors(*po.oracle_fit(sc, sc["inlier"], s["px"], s["aff"], False), sc)
            acs = sf.pose_errors(*po.oracle_fit(sc, sc["inlier"], s["px"], s["aff"], True), sc)
            ratios.append(np.sqrt(acs[0] * acs[1] / (pts[0] * pts[1])))
        gains[aff] = float(np.exp(np.mean(np.log(ratios))))
    # nearly exact A pins the pose far better than 1 px points; A at 500 % adds nothing
    assert gains[0.002] < 0.3
    assert 0.9 < gains[5.0] < 1.1


def test_paired_ratios_are_per_scene_geometric_means():
    rows = [
        dict(family="f", seed=0, method="a", rot=2.0, trans=1.0),
        dict(family="f", seed=0, method="b", rot=1.0, trans=1.0),
        dict(family="f", seed=1, method="a", rot=1.0, trans=4.0),
        dict(family="f", seed=1, method="b", rot=2.0, trans=1.0),
        dict(family="g", seed=0, method="a", rot=9.0, trans=9.0),
    ]
    assert po.paired(rows, "f", "a", "b") == pytest.approx((1.0, 2.0))
    assert po.paired(rows, "g", "a", "b") is None


def test_the_mixture_weights_find_the_scales_and_keep_the_outliers_out():
    rng = np.random.default_rng(3)
    vp, va = 0.25, 4e-5  # (0.5 px)², (A's noise in the affine Sampson units)²
    n_in, n_out = 3000, 1500
    inl = rng.normal(size=(n_in, 3))
    out = rng.uniform(-40, 40, size=(n_out, 3))
    z = np.r_[inl, out]
    sp, sa = vp * z[:, 0] ** 2, va * (z[:, 1] ** 2 + z[:, 2] ** 2)
    start = np.r_[np.ones(n_in), np.zeros(n_out)]
    start[rng.choice(n_in, 200, replace=False)] = 0.0  # a hard set that missed some inliers
    w, vp_hat, va_hat = po.mixture_weights(sp, sa, start)
    assert vp_hat == pytest.approx(vp, rel=0.06)
    assert va_hat == pytest.approx(va, rel=0.06)
    # the inliers are in, including those the start left out; the outliers far out are not
    assert w[:n_in].mean() > 0.97
    q = z[n_in:] ** 2
    far = q.sum(axis=1) > 49  # 7σ
    assert w[n_in:][far].max() < 1e-3
    assert w[n_in:].sum() < 5


def test_the_soft_fit_keeps_an_exact_pose_and_lands_near_the_oracle_from_a_wrong_start():
    sc, s = scene(31, px=1e-6, aff=1e-6)
    exact = sf.pose_errors(*po.soft_fit(sc, sc["R"], sc["t"], sc["inlier"]), sc)
    assert max(exact) < 1e-4
    ratios = []
    for seed in range(3):
        rng = np.random.default_rng(40 + seed)
        s = {**sf.BASE, "px": 1.0}  # half the matches outliers
        sc = sf.make_scene(rng, "relpose", 3000, s)
        # from a pose 0.45° off and the true pose: the same fit (the weights follow the pose)
        r0 = po.Rotation.from_rotvec([0.006, -0.004, 0.003]).as_matrix() @ sc["R"]
        soft = po.soft_fit(sc, r0, sc["t"], sc["inlier"])
        again = po.soft_fit(sc, sc["R"], sc["t"], sc["inlier"])
        assert max(sf.pose_errors(*soft, dict(R=again[0], t=again[1]))) < 0.01
        # as close to the truth as the oracle, within the scatter of three scenes (an
        # outlier let in would cost far more)
        soft_err = sf.pose_errors(*soft, sc)
        oracle = sf.pose_errors(*po.oracle_fit(sc, sc["inlier"], s["px"], s["aff"], True), sc)
        ratios.append(np.sqrt(soft_err[0] * soft_err[1] / (oracle[0] * oracle[1])))
    assert float(np.exp(np.mean(np.log(ratios)))) < 2.0, ratios
