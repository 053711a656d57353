"""Homography and fundamental-matrix solver bindings.

Ground truth is built here in numpy, independently of the Rust scene generator: two cameras with
K1 != K2 and fx != fy, planes n^T X1 = d, H = K2 (R + t n^T / d) K1^-1, F = K2^-T [t]x R K1^-1,
and exact ACs A = (H[:2,:2] - x2 H[2,:2]) / (H[2] . p1). F needs correspondences off a single
plane, so each one of those comes from its own plane.
"""

import affcorr
import numpy as np
import pytest

TOL = 1e-8


def skew(t):
    return np.array([[0, -t[2], t[1]], [t[2], 0, -t[0]], [-t[1], t[0], 0]])


def rotation(axis, angle):
    k = skew(axis / np.linalg.norm(axis))
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


class Scene:
    def __init__(self, rng):
        self.rng = rng
        self.K1, self.K2 = intrinsics(rng), intrinsics(rng)
        self.R = rotation(rng.normal(size=3), rng.uniform(-0.45, 0.45))
        t = rng.normal(size=3)
        self.t = t / np.linalg.norm(t) * rng.uniform(0.3, 1.0)
        self.F = np.linalg.inv(self.K2).T @ skew(self.t) @ self.R @ np.linalg.inv(self.K1)

    def plane(self):
        n = rotation(self.rng.normal(size=3), self.rng.uniform(-0.7, 0.7)) @ np.array([0, 0, 1.0])
        return n, self.rng.uniform(3, 6)

    def homography(self, plane):
        n, d = plane
        return self.K2 @ (self.R + np.outer(self.t, n) / d) @ np.linalg.inv(self.K1)

    def acs(self, plane, count):
        """`count` exact ACs (count, 8) of `plane`, in front of both cameras."""
        n, d = plane
        h = self.homography(plane)
        rows = []
        while len(rows) < count:
            x1 = np.array([self.rng.uniform(0, 640), self.rng.uniform(0, 480), 1.0])
            ray = np.linalg.inv(self.K1) @ x1
            depth = d / (n @ ray)
            if depth <= 0 or (self.R @ (ray * depth) + self.t)[2] <= 0:
                continue
            q = h @ x1
            x2 = q / q[2]
            a = (h[:2, :2] - np.outer(x2[:2], h[2, :2])) / q[2]
            rows.append([x1[0], x1[1], x2[0], x2[1], *a.ravel()])
        return np.array(rows)

    def multi_plane_acs(self, count):
        return np.vstack([self.acs(self.plane(), 1) for _ in range(count)])


def rel_err(est, gt):
    e, g = est / np.linalg.norm(est), gt / np.linalg.norm(gt)
    return min(np.linalg.norm(e - g), np.linalg.norm(e + g))


def best(models, gt):
    assert isinstance(models, list)
    for m in models:
        assert m.shape == (3, 3) and m.dtype == np.float64
        assert abs(np.linalg.norm(m) - 1) < 1e-12
    return min((rel_err(m, gt) for m in models), default=np.inf)


TRIALS = 200


def success_rate(seed, fn):
    rng = np.random.default_rng(seed)
    ok = sum(fn(Scene(rng)) < TOL for _ in range(TRIALS))
    return ok / TRIALS


def test_homography_solvers_recover_ground_truth():
    def four_pt(s):
        p = s.plane()
        c = s.acs(p, 4)
        return best(affcorr.homography_4pt(c[:, :2], c[:, 2:4]), s.homography(p))

    def two_ac(s):
        p = s.plane()
        return best(affcorr.homography_2ac(s.acs(p, 2)), s.homography(p))

    def one_ac_f(s):
        p = s.plane()
        return best(affcorr.homography_1ac_given_f(s.acs(p, 1), s.F), s.homography(p))

    def hybrid(s):
        p = s.plane()
        c = s.acs(p, 3)
        return best(affcorr.homography_1ac2pt(c[:1], c[1:, :2], c[1:, 2:4]), s.homography(p))

    def lsq(s):
        p = s.plane()
        c = s.acs(p, 25)
        return max(
            best(affcorr.homography_lsq(c[:, :2], c[:, 2:4]), s.homography(p)),
            best(affcorr.homography_ac_lsq(c), s.homography(p)),
        )

    for seed, fn in enumerate([four_pt, two_ac, one_ac_f, lsq, hybrid]):
        assert success_rate(seed, fn) >= 0.99, fn.__name__


def test_fundamental_solvers_recover_ground_truth():
    def seven_pt(s):
        c = s.multi_plane_acs(7)
        models = affcorr.fundamental_7pt(c[:, :2], c[:, 2:4])
        assert 1 <= len(models) <= 3
        return best(models, s.F)

    def eight_pt(s):
        c = s.multi_plane_acs(20)
        return best(affcorr.fundamental_8pt(c[:, :2], c[:, 2:4]), s.F)

    def three_ac(s):
        models = affcorr.fundamental_3ac(s.multi_plane_acs(3))
        assert len(models) == 1
        return best(models, s.F)

    def ac_lsq(s):
        return best(affcorr.fundamental_ac_lsq(s.multi_plane_acs(10)), s.F)

    def hybrid(s):
        c = s.multi_plane_acs(5)
        models = affcorr.fundamental_1ac4pt(c[:1], c[1:, :2], c[1:, 2:4])
        assert 1 <= len(models) <= 3
        return best(models, s.F)

    for seed, fn in enumerate([seven_pt, eight_pt, three_ac, ac_lsq, hybrid], start=10):
        assert success_rate(seed, fn) >= 0.99, fn.__name__


def test_degenerate_samples_give_no_model():
    rng = np.random.default_rng(20)
    s = Scene(rng)
    plane = s.plane()
    c = s.acs(plane, 8)
    # All on one plane: F is not determined.
    assert affcorr.fundamental_7pt(c[:7, :2], c[:7, 2:4]) == []
    assert affcorr.fundamental_8pt(c[:, :2], c[:, 2:4]) == []
    assert affcorr.fundamental_3ac(c[:3]) == []
    assert affcorr.fundamental_1ac4pt(c[:1], c[1:5, :2], c[1:5, 2:4]) == []
    # A point repeating the AC's centre.
    assert affcorr.homography_1ac2pt(c[:1], c[[0, 1], :2], c[[0, 1], 2:4]) == []
    # Three collinear points.
    x1 = c[:4, :2].copy()
    x1[2] = (x1[0] + x1[1]) / 2
    assert affcorr.homography_4pt(x1, c[:4, 2:4]) == []
    # det A <= 0.
    bad = c[:2].copy()
    bad[0, 4:] = [1.0, 0.0, 0.0, -1.0]
    assert affcorr.homography_2ac(bad) == []
    assert affcorr.homography_1ac_given_f(bad[:1], s.F) == []
    # The same AC twice.
    assert affcorr.homography_2ac(np.vstack([c[0], c[0]])) == []
    # F of rank 1.
    assert affcorr.homography_1ac_given_f(c[:1], np.outer(s.F[:, 0], s.F[0])) == []


def test_bad_inputs_raise_value_error_naming_the_argument():
    x = np.zeros((4, 2))
    with pytest.raises(ValueError, match="x1"):
        affcorr.homography_4pt(np.zeros((3, 2)), x)
    with pytest.raises(ValueError, match="x2"):
        affcorr.homography_4pt(x, np.zeros((4, 3)))
    with pytest.raises(ValueError, match="corrs"):
        affcorr.homography_2ac(np.zeros((3, 8)))
    with pytest.raises(ValueError, match="corrs"):
        affcorr.homography_1ac_given_f(np.zeros((1, 4)), np.eye(3))
    with pytest.raises(ValueError, match="F"):
        affcorr.homography_1ac_given_f(np.zeros((1, 8)), np.eye(2))
    with pytest.raises(ValueError, match="x1"):
        affcorr.homography_lsq(np.zeros((3, 2)), np.zeros((3, 2)))
    with pytest.raises(ValueError, match="x1 and x2"):
        affcorr.homography_lsq(np.zeros((5, 2)), np.zeros((6, 2)))
    with pytest.raises(ValueError, match="corrs"):
        affcorr.homography_ac_lsq(np.zeros((1, 8)))
    with pytest.raises(ValueError, match="x1"):
        affcorr.fundamental_7pt(np.zeros((8, 2)), np.zeros((7, 2)))
    with pytest.raises(ValueError, match="x2"):
        affcorr.fundamental_8pt(np.zeros((8, 2)), np.zeros((7, 2)))
    with pytest.raises(ValueError, match="x1 and x2"):
        affcorr.fundamental_8pt(np.zeros((9, 2)), np.zeros((8, 2)))
    with pytest.raises(ValueError, match="corrs"):
        affcorr.fundamental_3ac(np.zeros((2, 8)))
    with pytest.raises(ValueError, match="corrs"):
        affcorr.fundamental_ac_lsq(np.zeros((2, 8)))
    with pytest.raises(ValueError, match="corr"):
        affcorr.homography_1ac2pt(np.zeros((2, 8)), np.zeros((2, 2)), np.zeros((2, 2)))
    with pytest.raises(ValueError, match="x2"):
        affcorr.homography_1ac2pt(np.zeros((1, 8)), np.zeros((2, 2)), np.zeros((3, 2)))
    with pytest.raises(ValueError, match="x1"):
        affcorr.fundamental_1ac4pt(np.zeros((1, 8)), np.zeros((3, 2)), np.zeros((4, 2)))
    with pytest.raises(ValueError, match="corr"):
        affcorr.fundamental_1ac4pt(np.full((1, 8), np.nan), np.zeros((4, 2)), np.zeros((4, 2)))
    with pytest.raises(ValueError, match="x1"):
        affcorr.homography_4pt([["a", "b"]] * 4, x)
    # NaN / infinity.
    rng = np.random.default_rng(0)
    pts = rng.uniform(0, 500, size=(9, 2))
    acs = rng.uniform(0, 1, size=(3, 8))
    for bad in (np.nan, np.inf):
        p = pts.copy()
        p[1, 1] = bad
        with pytest.raises(ValueError, match="x1 contains NaN"):
            affcorr.homography_4pt(p[:4], pts[:4])
        with pytest.raises(ValueError, match="x2 contains NaN"):
            affcorr.fundamental_7pt(pts[:7], p[:7])
        with pytest.raises(ValueError, match="x1 contains NaN"):
            affcorr.fundamental_8pt(p, pts)
        with pytest.raises(ValueError, match="x2 contains NaN"):
            affcorr.homography_lsq(pts, p)
        a = acs.copy()
        a[2, 5] = bad
        with pytest.raises(ValueError, match="corrs contains NaN"):
            affcorr.fundamental_3ac(a)
        with pytest.raises(ValueError, match="corrs contains NaN"):
            affcorr.homography_2ac(a[1:])
        with pytest.raises(ValueError, match="F contains NaN"):
            affcorr.homography_1ac_given_f(acs[:1], np.full((3, 3), bad))


def test_dtype_and_memory_order_are_converted():
    rng = np.random.default_rng(30)
    s = Scene(rng)
    p = s.plane()
    c = s.acs(p, 4)
    h = s.homography(p)
    ref = affcorr.homography_4pt(c[:, :2], c[:, 2:4])
    # Fortran order, non-contiguous views, lists and float32.
    x1f = np.asfortranarray(c[:, :2])
    x2v = c[:, 2:4]  # a strided view
    assert not x2v.flags.c_contiguous
    out = affcorr.homography_4pt(x1f, x2v)
    assert rel_err(out[0], ref[0]) < 1e-15
    out = affcorr.homography_4pt(c[:, :2].tolist(), c[:, 2:4].tolist())
    assert rel_err(out[0], h) < TOL
    out32 = affcorr.homography_4pt(c[:, :2].astype(np.float32), c[:, 2:4].astype(np.float32))
    assert rel_err(out32[0], h) < 1e-3
    acs = s.multi_plane_acs(3)
    out = affcorr.fundamental_3ac(np.asfortranarray(acs))
    assert rel_err(out[0], s.F) < TOL
    out = affcorr.homography_1ac_given_f(c[:1].tolist(), np.asfortranarray(s.F))
    assert rel_err(out[0], h) < TOL
    ints = np.array([[0, 0], [100, 0], [100, 80], [10, 90]])
    assert len(affcorr.homography_4pt(ints, ints + 5)) == 1
