"""Type stubs of the Rust extension ``affcorr._native``.

Conventions (DESIGN.md §2): float64 arrays (other dtypes and memory orders are converted);
ACs are ``(N, 8)`` rows ``[x1, y1, x2, y2, a11, a12, a21, a22]`` with ``A = dx2/dx1``;
``p2^T F p1 = 0``; motion ``X2 = R X1 + t``, ``E = [t]x R``; angles in radians.
Bad inputs raise ``ValueError`` naming the argument.
"""

import numpy as np
from numpy.typing import ArrayLike, NDArray

__version__: str

# --- geometry -------------------------------------------------------------------------------

def synthesize_affine(
    orientation: ArrayLike, scale: ArrayLike, residual_shape: ArrayLike
) -> NDArray[np.float64]:
    """A = scale · R(orientation) · A'(residual_shape) per row (paper eq. 7).

    orientation (N,) radians; scale (N,) > 0; residual_shape (N, 3) = (x0, x1, x2) with
    A' = B / sqrt(det B), B = [[1 + x0, 0], [x1, 1 + x2]], 1 + x0 > 0, 1 + x2 > 0.
    Returns (N, 2, 2).
    """

def decompose_affine(
    A: ArrayLike,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Inverse of synthesize_affine: A (N, 2, 2) with det A > 0 -> (orientation (N,), scale (N,),
    residual_shape (N, 3)). The residual shape is the canonical one with det B = 1."""

def affine_from_homography(H: ArrayLike, x1: ArrayLike) -> NDArray[np.float64]:
    """The affine maps A = dx2/dx1 (N, 2, 2) that H (3, 3) induces at the points x1 (N, 2)."""

def correspondences_from_homography(H: ArrayLike, x1: ArrayLike) -> NDArray[np.float64]:
    """The full ACs (N, 8) that H (3, 3) induces at the points x1 (N, 2): x2 = H(x1), A = dx2/dx1."""

def normalize_correspondences(corrs: ArrayLike, K1: ArrayLike, K2: ArrayLike) -> NDArray[np.float64]:
    """ACs (N, 8) in pixels to normalised coordinates: x1 -> K1^-1 x1, x2 -> K2^-1 x2,
    A -> K2[:2,:2]^-1 A K1[:2,:2]. K must be upper triangular with positive focal lengths."""

def laf_to_affine(laf1: ArrayLike, laf2: ArrayLike) -> NDArray[np.float64]:
    """kornia LAF pairs (B, N, 2, 3) or (N, 2, 3) to ACs (B, N, 8) or (N, 8):
    x1, x2 are the LAF centres and A = L2 L1^-1."""

def affine_to_laf(
    corrs: ArrayLike, radius: float = 1.0
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """ACs (N, 8) to kornia LAF pairs (1, N, 2, 3): L1 = radius·I at x1, L2 = radius·A at x2."""

def essential_from_pose(R: ArrayLike, t: ArrayLike) -> NDArray[np.float64]:
    """E = [t]x R (3, 3) for the motion X2 = R X1 + t."""

def fundamental_from_essential(E: ArrayLike, K1: ArrayLike, K2: ArrayLike) -> NDArray[np.float64]:
    """F = K2^-T E K1^-1."""

def decompose_essential(E: ArrayLike) -> list[tuple[NDArray[np.float64], NDArray[np.float64]]]:
    """The four (R, t) factorisations of E (unit t)."""

def pose_from_essential(
    E: ArrayLike, x1: ArrayLike, x2: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64], int]:
    """The (R, t) of E that puts the most normalised correspondences x1, x2 (N, 2) in front of
    both cameras, and that count."""
