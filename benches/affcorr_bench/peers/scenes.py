"""Synthetic two-view scenes for the peer benchmark (numpy only: it runs in every peer venv).

A scene is planes n^T X1 = d seen by two cameras with anisotropic intrinsics (fx != fy, K1 != K2)
and motion X2 = R X1 + t. Each correspondence is an exact AC (x1, x2 = H x1, A = dx2/dx1 of its
plane's homography, docs/design.md §2), then:

- Gaussian noise of SIGMA px on x2 and SIGMA_A on each entry of A (inliers);
- a fraction of the rows replaced by outliers: x2 uniform in image 2, A a random rotation-scale.

Homography scenes have one plane; relative-pose and fundamental scenes have PLANES planes, so F is
determined (a single plane leaves it ambiguous).
"""

from __future__ import annotations

import numpy as np

from ..common import intrinsics, random_rotation

W, H_IMG = 640, 480
SIGMA = 0.5
SIGMA_A = 0.02
PLANES = 8


def plane_homography(K1, K2, R, t, n, d) -> np.ndarray:
    return K2 @ (R + np.outer(t, n) / d) @ np.linalg.inv(K1)


def plane_acs(rng, K1, K2, R, t, n, d, count: int) -> np.ndarray:
    """`count` exact ACs (count, 8) of the plane, at pixels of image 1 whose 3-D point is in
    front of both cameras and projects inside image 2 (with a margin)."""
    Hm = plane_homography(K1, K2, R, t, n, d)
    K1i = np.linalg.inv(K1)
    out = []
    while sum(len(o) for o in out) < count:
        x1 = rng.uniform([0, 0], [W, H_IMG], (4 * count + 64, 2))
        rays = np.c_[x1, np.ones(len(x1))] @ K1i.T
        depth = d / (rays @ n)
        X1 = rays * depth[:, None]
        z2 = (X1 @ R.T + t)[:, 2]
        p = np.c_[x1, np.ones(len(x1))] @ Hm.T
        x2 = p[:, :2] / p[:, 2:]
        ok = (depth > 0) & (z2 > 0)
        ok &= (x2[:, 0] > -W / 2) & (x2[:, 0] < 1.5 * W) & (x2[:, 1] > -H_IMG / 2)
        ok &= x2[:, 1] < 1.5 * H_IMG
        x1, x2, w = x1[ok], x2[ok], p[ok, 2]
        A = (Hm[None, :2, :2] - x2[:, :, None] * Hm[None, 2:3, :2]) / w[:, None, None]
        out.append(np.c_[x1, x2, A.reshape(-1, 4)])
    return np.vstack(out)[:count]


def random_motion(rng):
    R = random_rotation(rng, 0.4)
    t = rng.normal(size=3)
    return R, t * rng.uniform(0.3, 1.0) / np.linalg.norm(t)


def make_scene(rng: np.random.Generator, problem: str, n: int, outlier_ratio: float) -> dict:
    """One scene: corrs (n, 8), truth (n,) bool, K1, K2, R, t, and H (homography scenes)."""
    K1, K2 = intrinsics(rng), intrinsics(rng)
    R, t = random_motion(rng)
    planes = 1 if problem == "homography" else PLANES
    rows = []
    for k in range(planes):
        normal = random_rotation(rng, 0.7) @ np.array([0, 0, 1.0])
        d = rng.uniform(3.0, 8.0)
        m = n // planes + (k < n % planes)
        rows.append(plane_acs(rng, K1, K2, R, t, normal, d, m))
        if k == 0:
            Hm = plane_homography(K1, K2, R, t, normal, d)
    exact = rng.permutation(np.vstack(rows))
    corrs = exact.copy()
    corrs[:, 2:4] += rng.normal(0, SIGMA, (n, 2))
    corrs[:, 4:8] += rng.normal(0, SIGMA_A, (n, 4))
    out = rng.permutation(n)[: int(round(outlier_ratio * n))]
    corrs[out, 2:4] = rng.uniform([0, 0], [W, H_IMG], (len(out), 2))
    th = rng.uniform(-np.pi, np.pi, len(out))
    s = rng.uniform(0.5, 2.0, len(out))
    c, si = np.cos(th) * s, np.sin(th) * s
    corrs[out, 4:8] = np.c_[c, -si, si, c]
    truth = np.ones(n, bool)
    truth[out] = False
    return dict(corrs=corrs, exact=exact, truth=truth, K1=K1, K2=K2, R=R, t=t, H=Hm / Hm[2, 2])


def save(path, scenes: list[dict]) -> None:
    arrays = {f"{i}/{k}": v for i, s in enumerate(scenes) for k, v in s.items()}
    np.savez(path, count=len(scenes), **arrays)


def load(path) -> list[dict]:
    z = np.load(path)
    out = []
    for i in range(int(z["count"])):
        prefix = f"{i}/"
        out.append({k[len(prefix) :]: z[k] for k in z.files if k.startswith(prefix)})
    return out
