"""Accuracy measures against a ground-truth homography, shared by the CLI, the plots, the demo,
the benches and the tests (docs/design.md §2 conventions: p2 ~ H p1, A = dx2/dx1)."""

from __future__ import annotations

import numpy as np

from ._native import correspondences_from_homography


def transfer(H: np.ndarray, x1: np.ndarray) -> np.ndarray:
    """The points H(x1), (N, 2)."""
    return correspondences_from_homography(H, x1)[:, 2:4]


def correct_mask(corrs: np.ndarray, H: np.ndarray, threshold: float = 3.0) -> np.ndarray:
    """(N,) bool: the transfer error ||H(x1) - x2|| is below ``threshold`` px."""
    corrs = np.asarray(corrs, dtype=np.float64)
    if len(corrs) == 0:
        return np.zeros(0, dtype=bool)
    return np.linalg.norm(transfer(H, corrs[:, :2]) - corrs[:, 2:4], axis=1) < threshold


def corner_error(H: np.ndarray, H_gt: np.ndarray, width: int, height: int) -> float:
    """Mean distance (px) between image 1's corner pixels mapped by H and by H_gt; +inf when H
    is not finite (no model)."""
    if not np.all(np.isfinite(H)):
        return float("inf")
    c = np.array([[0, 0], [width - 1, 0], [width - 1, height - 1], [0, height - 1]], float)
    return float(np.linalg.norm(transfer(H, c) - transfer(H_gt, c), axis=1).mean())


def affine_errors(A: np.ndarray, A_gt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per AC: ||A - A_gt||_F and the cosine similarity of vec(A) and vec(A_gt) (the paper's
    Table 2 measures). A, A_gt: (N, 2, 2) or (N, 4)."""
    a = np.asarray(A, dtype=np.float64).reshape(-1, 4)
    g = np.asarray(A_gt, dtype=np.float64).reshape(-1, 4)
    cos = (a * g).sum(1) / (np.linalg.norm(a, axis=1) * np.linalg.norm(g, axis=1))
    return np.linalg.norm(a - g, axis=1), cos
