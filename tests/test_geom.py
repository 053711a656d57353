"""Python face of affcorr-geom: results against independent numpy math, and every bad input."""

from __future__ import annotations

import affcorr
import numpy as np
import pytest


def rot2(theta):
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


# --- synthesis / decomposition -------------------------------------------------------------


def test_synthesize_matches_the_definition(rng):
    n = 50
    theta = rng.uniform(-np.pi, np.pi, n)
    s = np.exp(rng.uniform(-2, 2, n))
    x = rng.uniform(-0.5, 0.5, (n, 3))
    B = np.zeros((n, 2, 2))
    B[:, 0, 0], B[:, 1, 0], B[:, 1, 1] = 1 + x[:, 0], x[:, 1], 1 + x[:, 2]
    Ap = B / np.sqrt(np.linalg.det(B))[:, None, None]
    expected = s[:, None, None] * rot2(theta) @ Ap
    np.testing.assert_allclose(
        affcorr.synthesize_affine(theta, s, x), expected, rtol=1e-13, atol=1e-13
    )


def test_decompose_inverts_synthesize(rng):
    A = rng.normal(size=(200, 2, 2))
    A = A[np.linalg.det(A) > 1e-3]
    theta, s, x = affcorr.decompose_affine(A)
    np.testing.assert_allclose(s, np.sqrt(np.linalg.det(A)), rtol=1e-13)
    assert np.all((theta > -np.pi) & (theta <= np.pi))
    # Canonical residual shape: det B = 1.
    np.testing.assert_allclose((1 + x[:, 0]) * (1 + x[:, 2]), 1.0, rtol=1e-12)
    np.testing.assert_allclose(affcorr.synthesize_affine(theta, s, x), A, rtol=1e-12, atol=1e-12)


def test_batch_errors_name_the_first_bad_row():
    A = np.tile(np.eye(2), (6000, 1, 1))
    A[4321] = [[1.0, 0.0], [0.0, -1.0]]
    A[5000] = 0.0
    with pytest.raises(ValueError, match=r"A\[4321\].*det A"):
        affcorr.decompose_affine(A)
    with pytest.raises(ValueError, match=r"scale\[1\]"):
        affcorr.synthesize_affine([0.0, 0.0], [1.0, -1.0], np.zeros((2, 3)))
    with pytest.raises(ValueError, match=r"orientation\[0\]"):
        affcorr.synthesize_affine([np.nan], [1.0], np.zeros((1, 3)))
    with pytest.raises(ValueError, match="residual_shape"):
        affcorr.synthesize_affine([0.0], [1.0], [[-1.5, 0.0, 0.0]])
    with pytest.raises(ValueError, match="scale: expected 2 rows, got 1"):
        affcorr.synthesize_affine([0.0, 0.0], [1.0], np.zeros((2, 3)))


@pytest.mark.parametrize(
    ("args", "name"),
    [
        (
            ([0.0], [1.0], np.zeros((1, 2))),
            "residual_shape must have shape \\(N, 3\\), got \\(1, 2\\)",
        ),
        (([[0.0]], [1.0], np.zeros((1, 3))), "orientation must have shape \\(N,\\)"),
        (([0.0], np.ones((1, 1, 1)), np.zeros((1, 3))), "scale must have shape"),
        ((["a"], [1.0], np.zeros((1, 3))), "orientation must be a numeric array"),
    ],
)
def test_synthesize_shape_errors(args, name):
    with pytest.raises(ValueError, match=name):
        affcorr.synthesize_affine(*args)


def test_inputs_of_any_dtype_and_order_are_converted():
    A = np.asfortranarray(np.array([[[2, 1], [0, 3]], [[1, 0], [0, 1]]], dtype=np.int32))
    theta, s, x = affcorr.decompose_affine(A)
    np.testing.assert_allclose(s, [np.sqrt(6.0), 1.0])
    A32 = np.array([[[2, 1], [0, 3]]], dtype=np.float32)
    np.testing.assert_allclose(affcorr.decompose_affine(A32)[1], [np.sqrt(6.0)], rtol=1e-7)
    big = np.zeros((3, 2, 2, 2))
    big[..., 0, 0] = big[..., 1, 1] = 1.0
    theta, s, _ = affcorr.decompose_affine(big[:, 1])  # non-contiguous view
    np.testing.assert_allclose(s, 1.0)
    out = affcorr.synthesize_affine(np.array([0.5]), [2], [[0, 0, 0]])
    assert out.dtype == np.float64 and out.flags.c_contiguous


def test_empty_batches_give_empty_outputs():
    assert affcorr.synthesize_affine([], [], np.zeros((0, 3))).shape == (0, 2, 2)
    assert [a.shape for a in affcorr.decompose_affine(np.zeros((0, 2, 2)))] == [(0,), (0,), (0, 3)]
    assert affcorr.correspondences_from_homography(np.eye(3), np.zeros((0, 2))).shape == (0, 8)


# --- homography ----------------------------------------------------------------------------


def test_homography_acs_match_independent_jacobians(scene, rng):
    x1 = scene.sample_pixels(rng, 100)
    np.testing.assert_allclose(
        affcorr.affine_from_homography(scene.H, x1), scene.jacobians(x1), rtol=1e-10, atol=1e-12
    )
    corrs = affcorr.correspondences_from_homography(scene.H, x1)
    np.testing.assert_allclose(corrs, scene.correspondences(x1), rtol=1e-10, atol=1e-10)


def test_homography_errors():
    with pytest.raises(ValueError, match="H must have shape \\(3, 3\\)"):
        affcorr.affine_from_homography(np.eye(2), np.zeros((1, 2)))
    with pytest.raises(ValueError, match="H contains NaN"):
        affcorr.affine_from_homography(np.full((3, 3), np.nan), np.zeros((1, 2)))
    with pytest.raises(ValueError, match=r"x1\[1\] maps to infinity"):
        H = np.array([[1.0, 0, 0], [0, 1, 0], [1, 0, -2]])
        affcorr.affine_from_homography(H, [[0.0, 0.0], [2.0, 5.0]])
    with pytest.raises(ValueError, match="x1 must have shape \\(N, 2\\)"):
        affcorr.correspondences_from_homography(np.eye(3), np.zeros((4, 3)))


# --- normalisation -------------------------------------------------------------------------


def test_normalisation_uses_both_intrinsics(scene, rng):
    corrs = scene.correspondences(scene.sample_pixels(rng, 30))
    out = affcorr.normalize_correspondences(corrs, scene.K1, scene.K2)
    K1i, K2i = np.linalg.inv(scene.K1), np.linalg.inv(scene.K2)
    x1 = np.c_[corrs[:, :2], np.ones(30)] @ K1i.T
    x2 = np.c_[corrs[:, 2:4], np.ones(30)] @ K2i.T
    np.testing.assert_allclose(out[:, :2], x1[:, :2], rtol=1e-12)
    np.testing.assert_allclose(out[:, 2:4], x2[:, :2], rtol=1e-12)
    A = corrs[:, 4:].reshape(-1, 2, 2)
    np.testing.assert_allclose(
        out[:, 4:].reshape(-1, 2, 2), K2i[:2, :2] @ A @ scene.K1[:2, :2], rtol=1e-12
    )
    # Normalised ACs are those of the normalised homography R + t n^T / d: the plane-induced
    # ground truth that pins the convention.
    Hn = scene.R + np.outer(scene.t, scene.n) / scene.d
    np.testing.assert_allclose(
        affcorr.correspondences_from_homography(Hn, out[:, :2]), out, rtol=1e-9, atol=1e-12
    )


@pytest.mark.parametrize(
    ("K", "match"),
    [
        (np.eye(2), "K2 must have shape \\(3, 3\\)"),
        (np.diag([0.0, 1.0, 1.0]), "K2 is not a valid intrinsic matrix: the focal lengths"),
        (
            np.array([[1.0, 0, 0], [0.5, 1, 0], [0, 0, 1]]),
            "K2 is not a valid intrinsic matrix: it must be upper",
        ),
        (np.diag([1.0, 1.0, 0.0]), "K2 is not a valid intrinsic matrix"),
        (np.full((3, 3), np.inf), "K2 is not a valid intrinsic matrix: it contains NaN"),
    ],
)
def test_bad_intrinsics(K, match):
    with pytest.raises(ValueError, match=match):
        affcorr.normalize_correspondences(np.zeros((1, 8)), np.eye(3), K)


def test_normalisation_rejects_bad_rows():
    with pytest.raises(ValueError, match="corrs must have shape \\(N, 8\\), got \\(2, 4\\)"):
        affcorr.normalize_correspondences(np.zeros((2, 4)), np.eye(3), np.eye(3))
    bad = np.zeros((3, 8))
    bad[2, 5] = np.nan
    with pytest.raises(ValueError, match=r"corrs\[2\] contains NaN"):
        affcorr.normalize_correspondences(bad, np.eye(3), np.eye(3))


# --- LAFs ----------------------------------------------------------------------------------


def test_lafs_round_trip_and_frames_compose(rng):
    corrs = np.c_[rng.uniform(0, 100, (10, 4)), rng.normal(size=(10, 4))]
    l1, l2 = affcorr.affine_to_laf(corrs, radius=5.0)
    assert l1.shape == l2.shape == (1, 10, 2, 3)
    np.testing.assert_allclose(affcorr.laf_to_affine(l1, l2)[0], corrs, atol=1e-12)
    np.testing.assert_allclose(affcorr.laf_to_affine(l1[0], l2[0]), corrs, atol=1e-12)
    with pytest.raises(ValueError, match="laf2 must have the shape of laf1"):
        affcorr.laf_to_affine(l1, l2[:, :5])
    with pytest.raises(ValueError, match="laf1 must have shape \\(B, N, 2, 3\\) or \\(N, 2, 3\\)"):
        affcorr.laf_to_affine(np.zeros((3, 2, 2)), np.zeros((3, 2, 2)))
    with pytest.raises(ValueError, match="radius"):
        affcorr.affine_to_laf(corrs, radius=0.0)
    singular = l1.copy()
    singular[0, 3, :, :2] = 0.0
    with pytest.raises(ValueError, match=r"laf1\[3\]"):
        affcorr.laf_to_affine(singular, l2)


# --- epipolar ------------------------------------------------------------------------------


def test_epipolar_utilities_recover_the_pose(scene, rng):
    E = affcorr.essential_from_pose(scene.R, scene.t)
    np.testing.assert_allclose(E, scene.E, atol=1e-14)
    F = affcorr.fundamental_from_essential(E, scene.K1, scene.K2)
    np.testing.assert_allclose(F / np.linalg.norm(F), scene.F, atol=1e-12)
    cands = affcorr.decompose_essential(E)
    assert len(cands) == 4
    t_unit = scene.t / np.linalg.norm(scene.t)
    assert (
        sum(
            np.allclose(R, scene.R, atol=1e-10) and np.allclose(t, t_unit, atol=1e-10)
            for R, t in cands
        )
        == 1
    )
    corrs = affcorr.normalize_correspondences(
        scene.correspondences(scene.sample_pixels(rng, 20)), scene.K1, scene.K2
    )
    R, t, n_front = affcorr.pose_from_essential(E, corrs[:, :2], corrs[:, 2:4])
    assert n_front == 20
    np.testing.assert_allclose(R, scene.R, atol=1e-10)
    np.testing.assert_allclose(t, t_unit, atol=1e-10)


def test_epipolar_errors():
    with pytest.raises(ValueError, match="R must be a rotation matrix"):
        affcorr.essential_from_pose(np.diag([1.0, 1.0, -1.0]), [0, 0, 1])
    with pytest.raises(ValueError, match="t must have shape \\(3,\\) or \\(3, 1\\)"):
        affcorr.essential_from_pose(np.eye(3), [0, 1])
    with pytest.raises(ValueError, match="E is degenerate: it is zero"):
        affcorr.decompose_essential(np.zeros((3, 3)))
    with pytest.raises(ValueError, match="x2: expected 3 rows, got 2"):
        affcorr.pose_from_essential(np.eye(3), np.zeros((3, 2)), np.zeros((2, 2)))
