"""The confidence's calibration (benches/affcorr_bench/confidence.py): its fitting helpers do
what they say, and the constants compiled into Rust are the ones the committed calibration
result file records."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from affcorr.shape import confidence_model
from affcorr_bench import confidence as bench

ROOT = Path(__file__).resolve().parents[1]


def test_fit_logistic_recovers_known_weights_and_keeps_unused_features_at_zero():
    rng = np.random.default_rng(0)
    n = 20000
    X = np.c_[np.ones(n), rng.normal(size=n), np.zeros(n), rng.normal(size=n)]
    w_true = np.array([0.5, 2.0, 0.0, -1.0])
    y = (rng.random(n) < 1 / (1 + np.exp(-(X @ w_true)))).astype(float)
    w = bench.fit_logistic(X, y, l2=0.0)
    assert w[2] == 0.0
    np.testing.assert_allclose(w, w_true, atol=0.1)


def test_choose_threshold_is_the_least_confidence_with_few_bad():
    conf = np.array([0.99, 0.98, 0.97, 0.96, 0.95, 0.5, 0.4])
    good = np.array([True, True, True, True, False, True, False])
    allowed = np.ones(7, bool)
    # Over the top 4 nothing is bad; adding the fifth makes 1/5 bad.
    assert bench.choose_threshold(conf, good, allowed, 0.1) == 0.96
    assert bench.choose_threshold(conf, good, allowed, 0.25) == 0.5
    # An AC that may not be reliable does not count.
    allowed[4] = False
    assert bench.choose_threshold(conf, good, allowed, 0.1) == 0.5


def test_auc():
    assert bench.auc(np.array([0.9, 0.8, 0.1]), np.array([True, True, False])) == 1.0
    assert bench.auc(np.array([0.1, 0.9]), np.array([True, False])) == 0.0


def test_rust_constants_are_the_recorded_calibration():
    path = ROOT / "benches" / "results" / "confidence_calibration.json"
    cal = json.loads(path.read_text())
    for name, fitted in cal["models"].items():
        weights, threshold, names = confidence_model(name)
        assert names == cal["features"]
        np.testing.assert_allclose(weights, fitted["weights"], rtol=0, atol=1e-6)
        assert threshold == pytest.approx(fitted["threshold"], abs=1e-6)
        # The recorded fit meets its own bound on held-out data.
        assert fitted["bad_among_reliable"] < cal["max_bad"]
        assert threshold >= cal["min_marginal"]
