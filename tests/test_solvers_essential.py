"""Essential solvers through the bindings: ground truth built in numpy, bad inputs."""

import affcorr
import numpy as np
import pytest


def rotation(rng, max_angle=0.5):
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    angle = rng.uniform(-max_angle, max_angle)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def intrinsics(rng):
    f = rng.uniform(500, 1000)
    return np.array(
        [
            [f, 0, rng.uniform(300, 340)],
            [0, f * rng.uniform(0.8, 1.2), rng.uniform(220, 260)],
            [0, 0, 1.0],
        ]
    )


def skew(t):
    return np.array([[0, -t[2], t[1]], [t[2], 0, -t[0]], [-t[1], t[0], 0]])


def scene(rng):
    R = rotation(rng)
    t = rng.normal(size=3)
    t *= rng.uniform(0.3, 1.0) / np.linalg.norm(t)
    E = skew(t) @ R
    return R, t, E / np.linalg.norm(E), intrinsics(rng), intrinsics(rng)


def points(rng, R, t, K1, K2, n):
    """Pixels of random 3D points, returned in normalised coordinates (via K^-1 in numpy)."""
    z = rng.uniform(2, 8, n)
    X = np.stack([rng.uniform(-0.6, 0.6, n) * z, rng.uniform(-0.45, 0.45, n) * z, z], axis=1)
    X2 = X @ R.T + t
    p1 = X @ K1.T
    p2 = X2 @ K2.T
    p1, p2 = p1[:, :2] / p1[:, 2:], p2[:, :2] / p2[:, 2:]

    def norm(K, p):
        return (np.c_[p, np.ones(len(p))] @ np.linalg.inv(K).T)[:, :2]

    return norm(K1, p1), norm(K2, p2)


def plane_acs(rng, R, t, K1, K2, n, normal=None, d=None):
    """Pixel ACs of a plane n^T X = d, normalised with affcorr.normalize_correspondences."""
    if normal is None:
        normal = rotation(rng, 0.6) @ np.array([0, 0, 1.0])
        d = rng.uniform(3, 6)
    H = K2 @ (R + np.outer(t, normal) / d) @ np.linalg.inv(K1)
    x1 = np.stack([rng.uniform(100, 540, n), rng.uniform(80, 400, n)], axis=1)
    corrs = affcorr.correspondences_from_homography(H, x1)
    return affcorr.normalize_correspondences(corrs, K1, K2)


def best_error(models, E):
    return min((min(np.linalg.norm(M - E), np.linalg.norm(M + E)) for M in models), default=np.inf)


def test_five_point_recovers_ground_truth():
    rng = np.random.default_rng(0)
    errors = []
    for _ in range(200):
        R, t, E, K1, K2 = scene(rng)
        x1, x2 = points(rng, R, t, K1, K2, 5)
        models = affcorr.essential_5pt(x1, x2)
        assert len(models) <= 10
        for M in models:
            assert M.shape == (3, 3) and abs(np.linalg.norm(M) - 1) < 1e-12
        errors.append(best_error(models, E))
    assert np.mean(np.array(errors) < 1e-8) >= 0.99


def test_two_ac_recovers_ground_truth_one_and_two_planes():
    rng = np.random.default_rng(1)
    one, two, first = [], [], 0
    for _ in range(200):
        R, t, E, K1, K2 = scene(rng)
        corrs = plane_acs(rng, R, t, K1, K2, 2)
        one.append(best_error(affcorr.essential_2ac(corrs), E))
        corrs = np.vstack([plane_acs(rng, R, t, K1, K2, 1), plane_acs(rng, R, t, K1, K2, 1)])
        models = affcorr.essential_2ac(corrs)
        two.append(best_error(models, E))
        first += best_error(models[:1], E) < 1e-8
    assert np.mean(np.array(one) < 1e-8) >= 0.97
    assert np.mean(np.array(two) < 1e-8) >= 0.99
    assert first >= 0.97 * 200


def test_one_ac_and_two_points_recover_ground_truth():
    """The hybrid sample: the AC on a plane, the two points anywhere in the scene."""
    rng = np.random.default_rng(5)
    errors = []
    for _ in range(200):
        R, t, E, K1, K2 = scene(rng)
        corr = plane_acs(rng, R, t, K1, K2, 1)
        x1, x2 = points(rng, R, t, K1, K2, 2)
        models = affcorr.essential_1ac2pt(corr, x1, x2)
        assert len(models) <= 10
        errors.append(best_error(models, E))
    assert np.mean(np.array(errors) < 1e-8) >= 0.99
    # A point at the AC's centre adds no equation.
    at_centre = np.vstack([x1[0], corr[0, :2]]), np.vstack([x2[0], corr[0, 2:4]])
    assert affcorr.essential_1ac2pt(corr, *at_centre) == []


def test_eight_point_and_lsq():
    rng = np.random.default_rng(2)
    for _ in range(50):
        R, t, E, K1, K2 = scene(rng)
        x1, x2 = points(rng, R, t, K1, K2, 20)
        (M,) = affcorr.essential_8pt(x1, x2)
        assert best_error([M], E) < 1e-8
        s = np.linalg.svd(M, compute_uv=False)
        assert abs(s[0] - s[1]) < 1e-12 and s[2] < 1e-12
        corrs = np.vstack([plane_acs(rng, R, t, K1, K2, 1) for _ in range(3)])
        (M,) = affcorr.essential_lsq(np.zeros((0, 2)), np.zeros((0, 2)), corrs)
        assert best_error([M], E) < 1e-8
        (M,) = affcorr.essential_lsq(x1[:2], x2[:2], corrs)
        assert best_error([M], E) < 1e-8
    # Noise of ~0.5 px keeps the estimate close.
    R, t, E, K1, K2 = scene(rng)
    x1, x2 = points(rng, R, t, K1, K2, 200)
    x1 += rng.normal(scale=6e-4, size=x1.shape)
    x2 += rng.normal(scale=6e-4, size=x2.shape)
    assert best_error(affcorr.essential_8pt(x1, x2), E) < 0.05


def test_pose_from_solver_output():
    rng = np.random.default_rng(3)
    R, t, E, K1, K2 = scene(rng)
    x1, x2 = points(rng, R, t, K1, K2, 5)
    poses = [affcorr.pose_from_essential(M, x1, x2) for M in affcorr.essential_5pt(x1, x2)]
    best = min(
        poses, key=lambda p: np.linalg.norm(p[0] - R) + np.linalg.norm(p[1] - t / np.linalg.norm(t))
    )
    assert np.linalg.norm(best[0] - R) < 1e-8 and best[2] == 5


def test_degenerate_samples_give_no_model():
    rng = np.random.default_rng(4)
    R, t, E, K1, K2 = scene(rng)
    x1, x2 = points(rng, R, t, K1, K2, 5)
    x1[4], x2[4] = x1[0], x2[0]
    assert affcorr.essential_5pt(x1, x2) == []
    corrs = plane_acs(rng, R, t, K1, K2, 2)
    assert affcorr.essential_2ac(np.vstack([corrs[0], corrs[0]])) == []
    flipped = corrs.copy()
    flipped[1, [4, 6]] *= -1  # det A < 0
    assert affcorr.essential_2ac(flipped) == []
    p = plane_acs(rng, R, t, K1, K2, 12)
    assert affcorr.essential_8pt(p[:, :2], p[:, 2:4]) == []  # coplanar


def hybrid(corr, x1, x2):
    return affcorr.essential_1ac2pt(corr, x1, x2)


@pytest.mark.parametrize(
    "call, name",
    [
        (lambda: affcorr.essential_5pt(np.zeros((4, 2)), np.zeros((5, 2))), "x1"),
        (lambda: affcorr.essential_5pt(np.zeros((5, 2)), np.zeros((5, 3))), "x2"),
        (lambda: affcorr.essential_5pt(np.full((5, 2), np.nan), np.zeros((5, 2))), "x1"),
        (lambda: affcorr.essential_5pt(np.zeros((5, 2)), np.full((5, 2), np.inf)), "x2"),
        (lambda: affcorr.essential_2ac(np.zeros((3, 8))), "corrs"),
        (lambda: affcorr.essential_2ac(np.zeros((2, 6))), "corrs"),
        (lambda: affcorr.essential_2ac(np.full((2, 8), np.nan)), "corrs"),
        (lambda: affcorr.essential_8pt(np.zeros((7, 2)), np.zeros((7, 2))), "x1"),
        (lambda: affcorr.essential_8pt(np.zeros((9, 2)), np.zeros((8, 2))), "x1"),
        (lambda: affcorr.essential_8pt(np.zeros((9, 2)), np.full((9, 2), np.nan)), "x2"),
        (
            lambda: affcorr.essential_lsq(np.zeros((2, 2)), np.zeros((2, 2)), np.zeros((1, 8))),
            "corrs",
        ),
        (
            lambda: affcorr.essential_lsq(np.zeros((9, 2)), np.zeros((9, 2)), np.zeros((1, 7))),
            "corrs",
        ),
        (lambda: affcorr.essential_5pt("abc", np.zeros((5, 2))), "x1"),
        (lambda: hybrid(np.zeros((2, 8)), np.zeros((2, 2)), np.zeros((2, 2))), "corr"),
        (lambda: hybrid(np.zeros((1, 8)), np.zeros((3, 2)), np.zeros((2, 2))), "x1"),
        (lambda: hybrid(np.zeros((1, 8)), np.zeros((2, 2)), np.full((2, 2), np.nan)), "x2"),
    ],
)
def test_bad_inputs_raise_value_error_naming_the_argument(call, name):
    with pytest.raises(ValueError, match=name):
        call()
