"""The affine terms of the estimators (issue 22): ``affine_refinement`` and
``affine_confidence`` through the Python API, on scenes of the scene-family benchmark's own
generator (affcorr_bench.scene_families.make_scene, numpy only)."""

from __future__ import annotations

import affcorr
import numpy as np
import pytest
from affcorr_bench import scene_families as sf


def scenes(aff: float, px: float, seeds: int = 7, problem: str = "relpose"):
    s = {**sf.BASE, "aff": aff, "px": px, "outliers": 0.3, "planes": 3}
    return [sf.make_scene(np.random.default_rng([7, i]), problem, 400, s) for i in range(seeds)]


POINTS = dict(affine_weight=0.0, affine_refinement="off")


def pose_error(scene, **opts) -> float:
    pose, info = affcorr.estimate_relative_pose(
        scene["corrs"], scene["K1"], scene["K2"], threshold=3.0, **opts
    )
    assert info.num_inliers > 0
    r, t = sf.pose_errors(pose.R, pose.t, scene)
    return max(r, t)


def test_accurate_acs_beat_points_on_the_same_matches():
    # 1 px on the points, A to 0.1%: the affine terms carry most of the information.
    data = scenes(aff=0.001, px=1.0)
    for scoring in ("msac", "magsac"):
        points = np.median([pose_error(s, scoring=scoring, **POINTS) for s in data])
        affine = np.median(
            [
                pose_error(s, scoring=scoring, affine_weight=0.0, affine_refinement="all")
                for s in data
            ]
        )
        assert affine < 0.7 * points, (scoring, affine, points)
    # the default (MSAC, the capped affine term in scoring, the affine final refinement) too
    default = np.median([pose_error(s) for s in data])
    assert default < 0.7 * np.median([pose_error(s, scoring="msac", **POINTS) for s in data])


def test_poor_acs_are_never_much_worse_than_points():
    data = scenes(aff=0.3, px=0.5)
    points = np.median([pose_error(s, scoring="msac", **POINTS) for s in data])
    affine = np.median([pose_error(s, scoring="msac", affine_refinement="all") for s in data])
    default = np.median([pose_error(s) for s in data])
    assert affine < 1.1 * points, (affine, points)
    assert default < 1.1 * points, (default, points)


def test_info_reports_the_affine_weight_measured_on_the_data():
    # Exact A keeps the default 50 px^2; A off by 15% is scored at the lower weight its
    # measured noise allows (the Rust test checks that this keeps more true inliers); A off by
    # 50% is too poor to score with (points: 0); an explicit weight is used as given; H and
    # points score by points.
    exact, noisy = scenes(aff=0.0, px=0.5, seeds=2), scenes(aff=0.15, px=0.5, seeds=2)
    poor = scenes(aff=0.5, px=0.5, seeds=2)

    def weights(s):
        _, pose = affcorr.estimate_relative_pose(s["corrs"], s["K1"], s["K2"], threshold=3.0)
        _, f = affcorr.estimate_fundamental(s["corrs"], threshold=3.0)
        return pose.affine_weight, f.affine_weight

    for s in exact:
        assert weights(s) == (50.0, 50.0)
    for s in poor:
        assert weights(s) == (0.0, 0.0)
    for s in noisy:
        assert all(0.0 < w < 25.0 for w in weights(s)), weights(s)
        _, info = affcorr.estimate_fundamental(s["corrs"], threshold=3.0, affine_weight=7.5)
        assert info.affine_weight == 7.5
        _, info = affcorr.estimate_fundamental(s["corrs"][:, :4].copy(), threshold=3.0)
        assert info.affine_weight == 0.0
        _, info = affcorr.estimate_homography(s["corrs"], threshold=3.0)
        assert info.affine_weight == 0.0


def test_zero_confidence_is_points_and_confidence_is_per_ac():
    s = scenes(aff=0.01, px=0.5, seeds=1)[0]
    n = len(s["corrs"])
    k = (s["corrs"], s["K1"], s["K2"])
    # points-only scoring, so that a confidence of 0 leaves points only
    off, _ = affcorr.estimate_relative_pose(
        *k, threshold=3.0, scoring="msac", affine_weight=0.0, affine_refinement="off"
    )
    zero, _ = affcorr.estimate_relative_pose(
        *k, threshold=3.0, scoring="msac", affine_refinement="all", affine_confidence=np.zeros(n)
    )
    one, _ = affcorr.estimate_relative_pose(
        *k, threshold=3.0, scoring="msac", affine_refinement="all", affine_confidence=np.ones(n)
    )
    default, _ = affcorr.estimate_relative_pose(
        *k, threshold=3.0, scoring="msac", affine_refinement="all"
    )
    np.testing.assert_array_equal(zero.R, off.R)
    np.testing.assert_array_equal(one.R, default.R)
    assert not np.array_equal(one.R, off.R)
    # F takes them too, and the batch form per pair.
    f_scene = scenes(aff=0.001, px=1.0, seeds=1, problem="fundamental")[0]
    F, info = affcorr.estimate_fundamental(
        f_scene["corrs"],
        threshold=3.0,
        affine_refinement="final",
        affine_confidence=np.full(len(f_scene["corrs"]), 0.5),
    )
    assert info.num_inliers > 0 and abs(np.linalg.det(F)) < 1e-12
    out = affcorr.estimate_relative_pose_batch(
        [s["corrs"], s["corrs"]],
        s["K1"],
        s["K2"],
        threshold=3.0,
        scoring="msac",
        affine_refinement="all",
        pair_options=[{"affine_confidence": np.zeros(n)}, None],
    )
    np.testing.assert_array_equal(out[0][0].R, off.R)
    np.testing.assert_array_equal(out[1][0].R, default.R)


@pytest.mark.parametrize(
    "value, match",
    [
        (np.ones(10), "one value per correspondence"),
        (np.full(50, 1.5), r"\[0, 1\]"),
        (np.full(50, -0.1), r"\[0, 1\]"),
        (np.full(50, np.nan), "affine_confidence"),
        ("high", "affine_confidence"),
    ],
)
def test_bad_confidences_raise_value_errors_naming_the_option(value, match):
    s = scenes(aff=0.01, px=0.5, seeds=1)[0]
    c = s["corrs"][:50]
    for call in (
        lambda **o: affcorr.estimate_homography(c, **o),
        lambda **o: affcorr.estimate_fundamental(c, **o),
        lambda **o: affcorr.estimate_relative_pose(c, s["K1"], s["K2"], **o),
    ):
        with pytest.raises(ValueError, match=match):
            call(affine_confidence=value)


def test_confidence_needs_acs_and_refinement_a_known_choice():
    s = scenes(aff=0.01, px=0.5, seeds=1)[0]
    with pytest.raises(ValueError, match=r"affine_confidence.*\(N, 8\)"):
        affcorr.estimate_fundamental(s["corrs"][:, :4], affine_confidence=np.ones(400))
    with pytest.raises(ValueError, match="affine_refinement must be one of"):
        affcorr.estimate_fundamental(s["corrs"], affine_refinement="lo")
    assert {"affine_refinement", "affine_confidence"} <= set(affcorr.ESTIMATOR_OPTIONS)


def test_the_planar_twin_fits_every_ac_exactly():
    """Two calibrated views of one plane have a second pose (the other physically valid
    decomposition of the plane's homography) under which every AC of the plane is exact: the
    same points and the same A = dx2/dx1. No estimator, points or ACs, can choose between the
    two (scene_families.planar_twin; the chessboard board views of the real-pair table)."""
    cv2 = pytest.importorskip("cv2")
    from types import SimpleNamespace

    from affcorr_bench.common import skew

    rng = np.random.default_rng(3)
    K = np.array([[520.0, 0.0, 330.0], [0.0, 500.0, 235.0], [0.0, 0.0, 1.0]])
    Ki = np.linalg.inv(K)
    found = 0
    for _ in range(200):
        R = cv2.Rodrigues(rng.normal(0.0, 0.3, 3))[0]
        t = rng.normal(0.0, 1.0, 3)
        n = np.array([0.0, 0.0, 1.0]) + rng.normal(0.0, 0.3, 3)
        n /= np.linalg.norm(n)  # the plane n^T X = 5 in camera 1
        x1 = rng.uniform([0.0, 0.0], [640.0, 480.0], (150, 2))
        X = np.c_[x1, np.ones(len(x1))] @ Ki.T
        X *= (5.0 / (X @ n))[:, None]
        if (X[:, 2] <= 0).any() or ((X @ R.T + t)[:, 2] <= 0).any():
            continue
        H = K @ (R + np.outer(t, n) / 5.0) @ Ki
        corrs = affcorr.correspondences_from_homography(H / H[2, 2], x1)
        pair = SimpleNamespace(K1=K, K2=K, R=R, t=t / np.linalg.norm(t))
        twin = sf.planar_twin(corrs, pair)
        if twin is None:  # the other decomposition puts the plane behind a camera
            continue
        found += 1
        R2, t2 = twin
        assert max(sf.pose_errors(R2, t2, dict(R=R, t=pair.t))) > 5.0
        for Ra, ta in ((R, pair.t), (R2, t2)):
            F = Ki.T @ skew(ta) @ Ra @ Ki
            F /= np.linalg.norm(F)
            assert np.max(np.abs(affcorr.sampson_point(F, corrs))) < 1e-9
            assert np.max(np.abs(affcorr.sampson_affine(F, corrs))) < 1e-9
        if found == 3:
            break
    assert found == 3


def _plane_pair(tilt: float, t, n_points: int = 120, outliers: int = 0):
    """ACs of the plane z = 4 (tilted about y by ``tilt``) seen by K, K with X2 = R X1 + t."""
    K = np.array([[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]])
    c, s = np.cos(0.1), np.sin(0.1)
    R = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    n = np.array([np.sin(tilt), 0.0, np.cos(tilt)])
    H = K @ (R + np.outer(t, n) / 4.0) @ np.linalg.inv(K)
    rng = np.random.default_rng(5)
    corrs = affcorr.correspondences_from_homography(H, rng.uniform(0, 480, (n_points, 2)))
    corrs[:outliers, 2:4] = rng.uniform(0, 480, (outliers, 2))
    return corrs, K, R, np.asarray(t, float) / np.linalg.norm(t)


def test_planar_twin_finds_the_other_motion_and_agrees_with_opencv():
    cv2 = pytest.importorskip("cv2")  # noqa: F841 - sf.planar_twin decomposes with OpenCV
    from types import SimpleNamespace

    corrs, K, R, t = _plane_pair(0.3, [-1.0, 0.0, 0.3], outliers=20)
    pose, info = affcorr.estimate_relative_pose(corrs, K, K)
    twin = affcorr.planar_twin(corrs, K, K, pose, info.inliers)
    assert isinstance(twin, affcorr.PlanarTwin)
    assert 0.98 <= twin.planar_share <= 1.0  # an outlier may sit on an epipolar line
    assert np.linalg.norm(twin.t) == pytest.approx(1.0)
    assert np.linalg.norm(twin.normal) == pytest.approx(1.0)
    # The plane's homography maps every true match (the first 20 are outliers) exactly.
    assert np.linalg.norm(twin.H) == pytest.approx(1.0)
    p = np.c_[corrs[20:, :2], np.ones(len(corrs) - 20)] @ twin.H.T
    np.testing.assert_allclose(p[:, :2] / p[:, 2:], corrs[20:, 2:4], atol=1e-6)
    truth = dict(R=R, t=t)
    errors = [max(sf.pose_errors(p.R, p.t, truth)) for p in (pose, twin)]
    assert min(errors) < 1e-3 and max(errors) > 5.0, errors  # one of them is the truth
    # The two decompositions are the truth and the benchmark's OpenCV twin (the one farther
    # from the truth): the twin is one of them, whichever of the two the estimate took.
    ref = sf.planar_twin(corrs[info.inliers], SimpleNamespace(K1=K, K2=K, R=R, t=t))
    to = [max(sf.pose_errors(twin.R, twin.t, dict(R=m[0], t=m[1]))) for m in ((R, t), ref)]
    assert min(to) < 1e-6, to


def test_planar_twin_is_none_off_a_plane():
    # two planes (z = 4 and one tilted by 46 degrees), the same motion
    a, K, _, _ = _plane_pair(0.0, [-1.0, 0.0, 0.3])
    b, _, _, _ = _plane_pair(0.8, [-1.0, 0.0, 0.3])
    corrs = np.vstack([a, b])
    pose, info = affcorr.estimate_relative_pose(corrs, K, K)
    assert info.num_inliers > 0.9 * len(corrs)
    assert affcorr.planar_twin(corrs, K, K, pose, info.inliers) is None
    # fewer than 8 inliers: nothing to tell
    few = np.zeros(len(corrs), bool)
    few[:5] = True
    assert affcorr.planar_twin(corrs, K, K, pose, few) is None


@pytest.mark.parametrize(
    "change, match",
    [
        (dict(inliers=np.ones(7, bool)), "inliers"),
        (dict(inliers=np.arange(10)), "boolean mask"),
        (dict(threshold=0.0), "threshold"),
        (dict(threshold=float("nan")), "threshold"),
        (dict(K1=np.zeros((3, 3))), "K1"),
        (dict(corrs=np.zeros((10, 5))), "corrs"),
    ],
)
def test_planar_twin_bad_inputs_raise_value_errors_naming_them(change, match):
    corrs, K, _, _ = _plane_pair(0.3, [-1.0, 0.0, 0.3])
    pose, info = affcorr.estimate_relative_pose(corrs, K, K)
    args = dict(corrs=corrs, K1=K, K2=K, pose=pose, inliers=info.inliers, threshold=2.0)
    args.update(change)
    with pytest.raises(ValueError, match=match):
        affcorr.planar_twin(**args)


def test_planar_twin_rejects_a_zero_translation():
    corrs, K, _, _ = _plane_pair(0.3, [-1.0, 0.0, 0.3])
    pose, info = affcorr.estimate_relative_pose(corrs, K, K)
    still = affcorr.RelativePose(pose.R, np.zeros(3), pose.E, pose.F)
    with pytest.raises(ValueError, match="t must be"):
        affcorr.planar_twin(corrs, K, K, still, info.inliers)
