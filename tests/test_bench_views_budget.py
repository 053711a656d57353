"""The view-budget benchmark's premise (benches/affcorr_bench/views_budget.py): one run of the
cascade at a large budget tells what any smaller budget would have run, because the budget only
decides where the cascade stops. Checked against the pipeline itself on a pair with nothing to
find (graffiti against noise), where the cascade runs until its budget is spent."""

from __future__ import annotations

import affcorr
import numpy as np
import pytest
from affcorr_bench.views_budget import cost_at, solved_after


@pytest.fixture(scope="module")
def unrelated_views():
    from affcorr.data import graffiti

    a = np.ascontiguousarray(graffiti()[0][::2, ::2])  # 400 x 320
    rng = np.random.default_rng(0)
    b = rng.integers(0, 256, a.shape, dtype=np.uint8)

    def run(budget: float) -> list[dict]:
        pipe = affcorr.Pipeline(max_keypoints=256, threads=2, view_relative_budget=budget)
        return pipe.match_pair(a, b).views

    return run


def test_a_smaller_budget_runs_the_views_a_larger_one_started_below_it(unrelated_views):
    long = unrelated_views(12.0)
    assert not any(v["verified"] for v in long)
    assert cost_at(long, float("inf")) >= 8.0  # nothing verified: most of the budget spent
    started = [v["started"] for v in long]
    assert started[0] == 0.0 and started == sorted(started)
    # The work before view i (the plain pass's verification, in no view's work, included),
    # from a view with no screen before it: it started where the views before it ended.
    unscreened = next(i for i, v in enumerate(long) if i > 0 and v["screen_extraction"] == 0)
    verification = started[unscreened] - sum(v["work"] for v in long[1:unscreened])

    def before(i: int) -> float:
        return verification + sum(v["work"] for v in long[1:i])

    # Budgets that stop the cascade before the first group's extractions (the rotations'),
    # at a later group's screen (before its extractions; between them and its screens) and at
    # a view with no screen before it, read off the run itself.
    assert long[1]["screen_extraction"] > 0
    first = before(1) + 0.5 * long[1]["screen_extraction"]
    k = next(i for i, v in enumerate(long) if i > 1 and v["screen_extraction"] > 0)
    e = long[k]["screen_extraction"]
    budgets = (
        first,
        before(k) + 0.5 * e,
        0.5 * (before(k) + e + started[k]),
        0.5 * (started[unscreened] + started[unscreened + 1]),
    )
    for budget in budgets:
        short = unrelated_views(budget)
        ran = [v["label"] for v in long if v["started"] < budget]
        assert [v["label"] for v in short] == ran
        assert [v["started"] for v in short] == pytest.approx(started[: len(ran)], rel=1e-12)
        total = sum(v["work"] for v in short)  # the plain pass's 1 included
        assert total == pytest.approx(cost_at(long, budget), rel=1e-9)
    # Below the rotations' extractions their screen could not be followed by a view: it is not
    # paid for.
    assert cost_at(long, first) == 1.0


def test_the_budget_a_pair_needs_is_where_its_used_view_started():
    views = [
        {"label": "plain", "work": 1.0, "started": 0.0, "screen_extraction": 0.0, "used": False},
        # After the verification (0.1), the rotations' screen: 2.2 of extractions, 0.2 of
        # screens; then the first rotated view's matching (1.0).
        {
            "label": "B rot 90°",
            "work": 3.4,
            "started": 2.5,
            "screen_extraction": 2.2,
            "used": False,
        },
        {
            "label": "A zoom 0.5",
            "work": 0.5,
            "started": 3.5,
            "screen_extraction": 0.0,
            "used": True,
        },
    ]
    assert solved_after(views) == 3.5
    assert solved_after(views[:1]) == 0.0
    # A budget that the rotations' extractions would reach skips their screen; one that only
    # their screens would reach stops after the extractions.
    assert cost_at(views, 1.0) == 1.0
    assert cost_at(views, 2.3) == 1.0
    assert cost_at(views, 2.4) == pytest.approx(1.0 + 2.2)
    assert cost_at(views, 3.0) == pytest.approx(1.0 + 3.4)
    assert cost_at(views, 4.0) == pytest.approx(1.0 + 3.9)
    assert cost_at(views[:1], 4.0) == 1.0
