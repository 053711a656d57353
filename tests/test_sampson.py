"""Sampson distances (docs/design.md §3) from Python: the Rust kernels against an independent numpy
implementation of the formulas, exact plane-induced ACs, gradients against finite differences,
and every bad-input path."""

from __future__ import annotations

import affcorr
import numpy as np
import pytest
from conftest import random_scene

# --- independent numpy implementation (matrix form, unlike the Rust kernels) ----------------


def _lines(F, corrs):
    F = np.broadcast_to(F, (len(corrs), 3, 3))
    ones = np.ones(len(corrs))
    p1 = np.c_[corrs[:, 0:2], ones]
    p2 = np.c_[corrs[:, 2:4], ones]
    l1 = np.einsum("nij,nj->ni", F, p1)  # F p1
    l2 = np.einsum("nji,nj->ni", F, p2)  # F^T p2
    return F, p1, p2, l1, l2


def np_sampson_point(F, corrs):
    _, _, p2, l1, l2 = _lines(F, corrs)
    e = np.einsum("ni,ni->n", p2, l1)
    return e**2 / (np.sum(l1[:, :2] ** 2, 1) + np.sum(l2[:, :2] ** 2, 1))


def np_sampson_affine(F, corrs):
    F, _, _, l1, l2 = _lines(F, corrs)
    A = corrs[:, 4:8].reshape(-1, 2, 2)
    At = np.swapaxes(A, 1, 2)
    r = np.einsum("nki,ni->nk", At, l1[:, :2]) + l2[:, :2]
    # Row k of each Jacobian block: d r_k / d(x1, y1) = (A^T F22)[k], d r_k / d(x2, y2) = F22^T[k],
    # d r_k / d(a1k, a2k) = l1[:2].
    F22 = F[:, :2, :2]
    j_x1 = At @ F22
    j_x2 = np.swapaxes(F22, 1, 2)
    g = np.sum(j_x1**2, 2) + np.sum(j_x2**2, 2) + np.sum(l1[:, :2] ** 2, 1)[:, None]
    return r**2 / g


# --- data -------------------------------------------------------------------------------------


def exact_acs(scene, rng, n):
    """Exact ACs from the Rust homography binding with the numpy scene's H, and its unit F."""
    return scene.F, affcorr.correspondences_from_homography(scene.H, scene.sample_pixels(rng, n))


def perturbed_acs(scene, rng, n):
    """Exact ACs with ~1 px noise on x2 and ~5% on A: residuals well away from zero, where the
    gradients do not vanish."""
    F, corrs = exact_acs(scene, rng, n)
    corrs = corrs.copy()
    corrs[:, 2:4] += rng.uniform(-1, 1, (n, 2))
    corrs[:, 4:8] += rng.uniform(-0.05, 0.05, (n, 4))
    return F, corrs


# --- values -----------------------------------------------------------------------------------


def test_exact_plane_correspondences_have_zero_distances(rng):
    transposed = []
    for _ in range(20):
        F, corrs = exact_acs(random_scene(rng), rng, 50)
        assert np.all(affcorr.sampson_point(F, corrs) < 1e-12)
        assert np.all(affcorr.sampson_point(F, corrs[:, :4]) < 1e-12)
        sd = affcorr.sampson_affine(F, corrs)
        assert sd.shape == (50, 2)
        assert np.all(sd < 1e-12)
        # The transposed A breaks the affine constraint (pins A = dx2/dx1, not its transpose).
        wrong = corrs.copy()
        wrong[:, 4:8] = corrs[:, [4, 6, 5, 7]]
        transposed.append(affcorr.sampson_affine(F, wrong).sum(1))
    # Scenes with little rotation have nearly symmetric A: compare over all of them.
    assert np.median(np.concatenate(transposed)) > 1e-3


def test_kernels_match_numpy(rng, scene):
    F, corrs = perturbed_acs(scene, rng, 300)
    expected_p = np_sampson_point(F, corrs)
    expected_a = np_sampson_affine(F, corrs)
    assert np.median(expected_p) > 1e-3 and np.median(expected_a) > 1e-5
    # Rounding: p2^T F p1 sums pixel-sized terms that cancel, so tiny distances carry an
    # absolute error of ~1e-13 px^2 whatever the order of the operations.
    tol = {"rtol": 1e-10, "atol": 1e-12}
    np.testing.assert_allclose(affcorr.sampson_point(F, corrs), expected_p, **tol)
    np.testing.assert_allclose(affcorr.sampson_point(F, corrs[:, :4]), expected_p, **tol)
    np.testing.assert_allclose(affcorr.sampson_affine(F, corrs), expected_a, **tol)


def test_per_row_f_mixes_image_pairs(rng):
    F1, c1 = perturbed_acs(random_scene(rng), rng, 4)
    F2, c2 = perturbed_acs(random_scene(rng), rng, 3)
    corrs = np.vstack([c1, c2])
    Fs = np.stack([F1] * 4 + [F2] * 3)
    np.testing.assert_array_equal(
        affcorr.sampson_point(Fs, corrs),
        np.r_[affcorr.sampson_point(F1, c1), affcorr.sampson_point(F2, c2)],
    )
    np.testing.assert_array_equal(
        affcorr.sampson_affine(Fs, corrs),
        np.vstack([affcorr.sampson_affine(F1, c1), affcorr.sampson_affine(F2, c2)]),
    )
    np.testing.assert_allclose(
        affcorr.sampson_affine(Fs, corrs), np_sampson_affine(Fs, corrs), rtol=1e-10, atol=1e-12
    )
    d, dc, dF = affcorr.sampson_affine_grad(Fs, corrs)
    d1, dc1, dF1 = affcorr.sampson_affine_grad(F1, c1)
    np.testing.assert_array_equal(d[:4], d1)
    np.testing.assert_array_equal(dc[:4], dc1)
    np.testing.assert_array_equal(dF[:4], dF1)


def test_large_batches_run_in_parallel_and_agree(rng, scene):
    # Above the rayon threshold (4096 rows).
    F, corrs = perturbed_acs(scene, rng, 200)
    big = np.tile(corrs, (30, 1))
    np.testing.assert_array_equal(
        affcorr.sampson_point(F, big), np.tile(affcorr.sampson_point(F, corrs), 30)
    )
    np.testing.assert_array_equal(
        affcorr.sampson_affine_grad(F, big)[1],
        np.tile(affcorr.sampson_affine_grad(F, corrs)[1], (30, 1, 1)),
    )


def test_scale_of_f_does_not_matter(rng, scene):
    F, corrs = perturbed_acs(scene, rng, 50)
    for lam in (-2.0, 1e-3, 1e4):
        np.testing.assert_allclose(
            affcorr.sampson_point(lam * F, corrs),
            affcorr.sampson_point(F, corrs),
            rtol=1e-10,
            atol=1e-12,
        )
        np.testing.assert_allclose(
            affcorr.sampson_affine(lam * F, corrs),
            affcorr.sampson_affine(F, corrs),
            rtol=1e-10,
            atol=1e-12,
        )


def test_degenerate_denominators_give_zero_or_inf_not_nan():
    corrs = np.array([[3.0, 4.0, 5.0, -1.0, 1.0, 0.2, -0.3, 0.9]])
    assert affcorr.sampson_point(np.zeros((3, 3)), corrs)[0] == 0.0
    F = np.zeros((3, 3))
    F[2, 2] = 1.0  # l1 = l2 = (0, 0, 1): D = 0 with residual 1
    assert affcorr.sampson_point(F, corrs)[0] == np.inf
    d, dc, dF = affcorr.sampson_point_grad(F, corrs)
    assert d[0] == np.inf and not dc.any() and not dF.any()
    F = np.zeros((3, 3))
    F[2, 0] = 1.0  # affine row 0: G = 0 with r = 1; row 1: r = G = 0
    np.testing.assert_array_equal(affcorr.sampson_affine(F, corrs), [[np.inf, 0.0]])


# --- gradients --------------------------------------------------------------------------------


def _fd(fun, F, corrs, which, index, h):
    """Richardson-extrapolated central difference of fun(F, corrs) (N,) w.r.t. one entry of
    every row (F per row) at once."""

    def at(step):
        Fp = np.broadcast_to(F, (len(corrs), 3, 3)).copy()
        cp = corrs.copy()
        target = Fp if which == "F" else cp
        target[(slice(None),) + index] += step
        return fun(Fp, cp)

    def central(s):
        return (at(s) - at(-s)) / (2 * s)

    return (4 * central(h / 2) - central(h)) / 3


def _f_step(corrs, m, n):
    """F_mn multiplies x2_m x1_n (pixels): its step is 1e-4 over their typical product."""
    ones = np.ones(len(corrs))
    q1 = np.c_[np.abs(corrs[:, 0:2]), ones]
    q2 = np.c_[np.abs(corrs[:, 2:4]), ones]
    return 1e-4 / np.median(np.maximum(q2[:, m], 1) * np.maximum(q1[:, n], 1))


def _check(fd, an, floor):
    err = np.abs(fd - an) / (np.abs(an) + floor)
    assert err.max() < 1e-6, err.max()


@pytest.mark.parametrize("width", [4, 8])
def test_point_gradients_match_finite_differences(rng, scene, width):
    F, corrs = perturbed_acs(scene, rng, 40)
    corrs = corrs[:, :width]
    d, dc, dF = affcorr.sampson_point_grad(F, corrs)
    assert d.shape == (40,) and dc.shape == (40, width) and dF.shape == (40, 3, 3)
    np.testing.assert_array_equal(d, affcorr.sampson_point(F, corrs))
    if width == 8:
        assert not dc[:, 4:].any()
    for j in range(4):
        fd = _fd(np_sampson_point, F, corrs, "corrs", (j,), 1e-3)
        _check(fd, dc[:, j], 1e-3 * np.abs(dc[:, :4]).max(1))
    for m in range(3):
        for n in range(3):
            fd = _fd(np_sampson_point, F, corrs, "F", (m, n), _f_step(corrs, m, n))
            _check(fd, dF[:, m, n], 1e-3 * np.abs(dF).max((1, 2)))


def test_affine_gradients_match_finite_differences(rng, scene):
    F, corrs = perturbed_acs(scene, rng, 40)
    d, dc, dF = affcorr.sampson_affine_grad(F, corrs)
    assert d.shape == (40, 2) and dc.shape == (40, 2, 8) and dF.shape == (40, 2, 3, 3)
    np.testing.assert_array_equal(d, affcorr.sampson_affine(F, corrs))
    # Row k depends on column k of A only.
    assert not dc[:, 0, [5, 7]].any() and not dc[:, 1, [4, 6]].any()
    for k in range(2):

        def row(Fs, c, k=k):
            return np_sampson_affine(Fs, c)[:, k]

        for j in range(8):
            h = 1e-3 if j < 4 else 1e-5
            fd = _fd(row, F, corrs, "corrs", (j,), h)
            group = slice(0, 4) if j < 4 else slice(4, 8)
            _check(fd, dc[:, k, j], 1e-3 * np.abs(dc[:, k, group]).max(1))
        for m in range(3):
            for n in range(3):
                fd = _fd(row, F, corrs, "F", (m, n), _f_step(corrs, m, n))
                _check(fd, dF[:, k, m, n], 1e-3 * np.abs(dF[:, k]).max((1, 2)))


# --- inputs -----------------------------------------------------------------------------------


def test_any_dtype_and_memory_order_is_converted(rng, scene):
    F, corrs = perturbed_acs(scene, rng, 20)
    expected = affcorr.sampson_affine(F, corrs)
    fortran = np.asfortranarray(corrs)
    assert not fortran.flags.c_contiguous
    np.testing.assert_array_equal(affcorr.sampson_affine(np.asfortranarray(F), fortran), expected)
    np.testing.assert_array_equal(affcorr.sampson_affine(F, corrs.tolist()), expected)
    c32 = corrs.astype(np.float32)
    np.testing.assert_array_equal(
        affcorr.sampson_affine(F, c32), affcorr.sampson_affine(F, c32.astype(np.float64))
    )
    ci = np.round(corrs).astype(np.int32)
    np.testing.assert_array_equal(
        affcorr.sampson_point(F, ci), affcorr.sampson_point(F, ci.astype(np.float64))
    )
    # A strided view (every other row) is copied, not misread.
    np.testing.assert_array_equal(
        affcorr.sampson_point(F, corrs[::2]), affcorr.sampson_point(F, corrs)[::2]
    )
    assert affcorr.sampson_point(F, np.zeros((0, 4))).shape == (0,)
    assert affcorr.sampson_affine_grad(F, np.zeros((0, 8)))[1].shape == (0, 2, 8)


@pytest.mark.parametrize(
    "fun",
    [
        affcorr.sampson_point,
        affcorr.sampson_affine,
        affcorr.sampson_point_grad,
        affcorr.sampson_affine_grad,
    ],
)
@pytest.mark.parametrize(
    ("F", "corrs", "match"),
    [
        (
            np.eye(3),
            np.zeros((3, 7)),
            r"corrs must have shape \(N, (4\) or \(N, )?8\), got \(3, 7\)",
        ),
        (np.eye(3), np.zeros((2, 3, 8)), r"corrs must have shape .* got \(2, 3, 8\)"),
        (np.eye(3), np.zeros(8), r"corrs must have shape .* got \(8\)"),
        (np.eye(3), [["a"] * 8], "corrs must be a numeric array"),
        (np.eye(3), [[0, 0, 0, 0, 1, 0, 0, np.nan]] * 2, None),  # point: A unused
        (
            np.eye(3),
            [[0, 0, 0, 0, 1, 0, 0, 1], [0, np.inf, 0, 0, 1, 0, 0, 1]],
            r"corrs\[1\] contains NaN or infinity",
        ),
        (np.eye(4), np.zeros((2, 8)), r"F must have shape \(3, 3\) or \(N, 3, 3\), got \(4, 4\)"),
        (np.zeros((2, 9)), np.zeros((2, 8)), r"F must have shape .* got \(2, 9\)"),
        (np.full((3, 3), np.nan), np.zeros((2, 8)), "F contains NaN or infinity"),
        (np.zeros((3, 3, 3)), np.zeros((2, 8)), "F: expected 2 rows, got 3"),
        (
            np.stack([np.eye(3), np.full((3, 3), np.inf)]),
            np.zeros((2, 8)),
            r"F\[1\] contains NaN or infinity",
        ),
    ],
)
def test_bad_inputs_raise_value_errors_naming_the_argument(fun, F, corrs, match):
    point = fun in (affcorr.sampson_point, affcorr.sampson_point_grad)
    if match is None:
        if point:
            fun(F, corrs)  # the point distance ignores the A columns
            return
        match = r"corrs\[0\] contains NaN"
    with pytest.raises(ValueError, match=match):
        fun(F, corrs)


@pytest.mark.parametrize("fun", [affcorr.sampson_affine, affcorr.sampson_affine_grad])
def test_affine_distance_needs_the_affine_columns(fun):
    with pytest.raises(ValueError, match=r"corrs must have shape \(N, 8\), got \(2, 4\)"):
        fun(np.eye(3), np.zeros((2, 4)))
