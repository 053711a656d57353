"""Local optimisation's threshold schedules from Python: ``lo_schedule``.

The scenes are the scene-family benchmark's "cluster 20%" homographies: a plane at 50%
outliers, a fifth of the matches moved into a cluster 5 px off the plane in one region of
image 1. The widening schedule alone fits a compromise between the two in many of them; the
homography's default (``"both"``) stays on the plane. For F and the relative pose the default is
the widening schedule.
"""

from __future__ import annotations

import affcorr
import numpy as np
import pytest
from affcorr_bench import scene_families as sf


@pytest.fixture(scope="module")
def cluster_scenes():
    return sf.make_jobs(["homography"], [("cluster 20%", {"cluster": 0.2})], 24, 800)


def misses(jobs, **opts) -> int:
    """How many of the scenes' homographies are more than 1 px (mean transfer) off."""
    out = 0
    for job in jobs:
        sc = job["scene"]
        H, _ = affcorr.estimate_homography(sc["corrs"], threshold=job["thr"], **opts)
        out += sf.errors("homography", dict(H=H), sc)[0] > 1.0
    return out


def test_the_homography_default_stays_on_the_plane_beside_a_cluster(cluster_scenes):
    widening = misses(cluster_scenes, lo_schedule="widening")
    default = misses(cluster_scenes)
    # The premise: the widening schedule alone misses in a good share of the scenes (14 of 24
    # when written; the default 5).
    assert widening >= 9, f"widening missed {widening} of 24"
    assert default * 2 <= widening, f"default {default} vs widening {widening} of 24"


def test_auto_is_both_for_h_and_widening_for_f_and_pose(cluster_scenes):
    sc = cluster_scenes[0]["scene"]
    c = sc["corrs"]
    same = lambda a, b: np.array_equal(a[0], b[0]) and np.array_equal(a[1].inliers, b[1].inliers)  # noqa: E731
    h = lambda **o: affcorr.estimate_homography(c, threshold=3.0, **o)  # noqa: E731
    assert same(h(), h(lo_schedule="both")) and same(h(), h(lo_schedule="auto"))
    f = lambda **o: affcorr.estimate_fundamental(c, threshold=2.0, **o)  # noqa: E731
    assert same(f(), f(lo_schedule="widening"))
    pose = lambda **o: affcorr.estimate_relative_pose(c, sc["K1"], sc["K2"], threshold=2.0, **o)  # noqa: E731
    (a, ia), (b, ib) = pose(), pose(lo_schedule="widening")
    assert np.array_equal(a.R, b.R) and np.array_equal(ia.inliers, ib.inliers)
    # Upper case is accepted, as for every named option.
    assert same(f(lo_schedule="BOTH"), f(lo_schedule="both"))


def test_bad_lo_schedule_names_the_option_and_its_choices(cluster_scenes):
    c = cluster_scenes[0]["scene"]["corrs"]
    with pytest.raises(ValueError, match=r"lo_schedule must be one of \['auto', 'widening'"):
        affcorr.estimate_homography(c, lo_schedule="wide")
    with pytest.raises(ValueError, match="lo_schedule must be one of"):
        affcorr.estimate_homography(c, lo_schedule=2)
    assert "lo_schedule" in affcorr.ESTIMATOR_OPTIONS
