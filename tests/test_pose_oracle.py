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
