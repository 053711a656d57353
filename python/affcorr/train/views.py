"""Patch pairs with exact ground truth, cut from synthetic views of real images.

Two kinds of pairs (docs/design.md §6, "Training"):

- :func:`similarity_pairs` for E_os: patch B is patch A's content rotated by ``phi`` and magnified
  by ``s`` about the same texture point (S3Esti's supervision), so O_B - O_A = phi and
  S_B / S_A = s exactly.
- :func:`plane_pairs` for E_aff and for evaluation: a textured plane seen by two random pinhole
  cameras (tilt up to ``max_tilt_deg``, scale ratio up to ``max_scale_ratio``, any roll). Every
  match has exact x1, x2, A = dx2/dx1 and the pair's F (p2^T F p1 = 0, X2 = R X1 + t).

Patches are 32x32, pixel (r, c) at ``x + (c - 15.5, r - 15.5)``, read with bilinear sampling from
a texture blurred to match the view's resolution (a camera integrates over its pixel; plain
bilinear sampling of a shrunk texture would alias). Intensities get a random photometric change
(gain, gamma, offset, noise) per patch.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F  # noqa: N812

from .._native import correspondences_from_homography

PATCH = 32
_OFFSETS = np.arange(PATCH, dtype=np.float64) - (PATCH - 1) / 2.0
# Blur levels of the texture pyramid: the downscale factor m each level is made for.
_LEVELS = 2.0 ** np.arange(0.0, 3.01, 0.25)


def _gaussian_blur(img: torch.Tensor, sigma: float) -> torch.Tensor:
    if sigma < 0.05:
        return img
    r = int(math.ceil(3 * sigma))
    x = torch.arange(-r, r + 1, dtype=img.dtype)
    k = torch.exp(-0.5 * (x / sigma) ** 2)
    k = k / k.sum()
    img = F.conv2d(F.pad(img, (r, r, 0, 0), mode="replicate"), k.view(1, 1, 1, -1))
    return F.conv2d(F.pad(img, (0, 0, r, r), mode="replicate"), k.view(1, 1, -1, 1))


class Texture:
    """A grayscale image with its anti-aliasing pyramid (same size, growing blur)."""

    def __init__(self, image: np.ndarray) -> None:
        base = torch.from_numpy(np.ascontiguousarray(image, dtype=np.float32))[None, None]
        self.h, self.w = image.shape
        # Shrinking by m needs a blur of about sigma = 0.5 sqrt(m^2 - 1) texture pixels.
        self.levels = [
            _gaussian_blur(base, 0.5 * math.sqrt(max(m * m - 1.0, 0.0))) for m in _LEVELS
        ]

    def sample(self, coords: np.ndarray, shrink: np.ndarray) -> np.ndarray:
        """Bilinear reads at texture ``coords`` (N, P, P, 2) (x, y); ``shrink`` (N,) is how many
        texture pixels one patch pixel spans. Returns (N, P, P) float32."""
        level = np.clip(np.searchsorted(_LEVELS, shrink, side="left"), 0, len(_LEVELS) - 1)
        out = np.empty(coords.shape[:3], dtype=np.float32)
        for lv in np.unique(level):
            idx = np.nonzero(level == lv)[0]
            g = torch.from_numpy(coords[idx]).float()
            # align_corners=True: -1 and 1 are the centres of the border pixels.
            g[..., 0] = g[..., 0] / (self.w - 1) * 2 - 1
            g[..., 1] = g[..., 1] / (self.h - 1) * 2 - 1
            g = g.reshape(1, -1, PATCH, 2)
            s = F.grid_sample(
                self.levels[lv], g, mode="bilinear", padding_mode="border", align_corners=True
            )
            out[idx] = s.reshape(len(idx), PATCH, PATCH).numpy()
        return out


def _photometric(rng: np.random.Generator, p: np.ndarray, strength: float) -> np.ndarray:
    n = p.shape[0]
    gain = np.exp(rng.uniform(-0.4, 0.4, n) * strength)[:, None, None]
    gamma = np.exp(rng.uniform(-0.4, 0.4, n) * strength)[:, None, None]
    offset = rng.uniform(-0.1, 0.1, n)[:, None, None] * strength
    noise = rng.uniform(0.0, 0.02, n)[:, None, None] * rng.standard_normal(p.shape)
    out = np.clip(p, 0.0, 1.0) ** gamma * gain + offset + noise
    return np.clip(out, 0.0, 1.0).astype(np.float32)


def _grid(centres: np.ndarray, maps: np.ndarray) -> np.ndarray:
    """Texture coordinates ``centre + M u`` over the patch offsets u: (N, P, P, 2)."""
    u = np.stack(np.meshgrid(_OFFSETS, _OFFSETS, indexing="xy"), -1)  # (P, P, 2): (x, y)
    return centres[:, None, None, :] + np.einsum("nij,rcj->nrci", maps, u)


def rotation(theta: np.ndarray) -> np.ndarray:
    """R(theta) = [[cos, -sin], [sin, cos]] per entry, (N, 2, 2) (docs/design.md §2)."""
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


@dataclass
class SimilarityPairs:
    """E_os supervision: ``patch_b`` is ``patch_a`` rotated by ``angle`` and magnified by
    ``scale`` (x2 = scale R(angle) x1 about the patch centres)."""

    patch_a: np.ndarray  # (N, 32, 32) float32 in [0, 1]
    patch_b: np.ndarray
    angle: np.ndarray  # (N,) radians in [-pi, pi)
    scale: np.ndarray  # (N,)


def similarity_pairs(
    rng: np.random.Generator,
    texture: Texture,
    n: int,
    *,
    max_log2_scale: float = 2.0,
    shear: float = 0.1,
    centre_jitter: float = 0.0,
) -> SimilarityPairs:
    """``n`` pairs from random texture points. Each patch reads the texture through
    ``m R(alpha) (I + small shear)``; the shear (up to ``shear``) makes E_os robust to mild
    affine distortion without changing the labels' meaning much. ``centre_jitter`` (patch B
    pixels, std) moves patch B's centre off the exact point, as keypoint noise does."""
    log_m_a = rng.uniform(-0.5, 1.0, n)  # texture pixels per patch pixel, log2
    rel = rng.uniform(-max_log2_scale, max_log2_scale, n)  # log2 S_B / S_A
    log_m_b = log_m_a - rel
    alpha = rng.uniform(-math.pi, math.pi, n)
    phi = rng.uniform(-math.pi, math.pi, n)
    # x2 = s R(phi) x1 and texture = c + M_i u_i  =>  M_B = M_A R(-phi) / s.
    eps = rng.uniform(-shear, shear, (n, 2, 2))
    m_a = (2.0**log_m_a)[:, None, None] * rotation(alpha) @ (np.eye(2) + eps)
    m_b = m_a @ rotation(-phi) / (2.0**rel)[:, None, None]
    span = PATCH * np.maximum(2.0**log_m_a, 2.0**log_m_b) * 1.3
    ok = span < min(texture.w, texture.h) - 4
    cx = span / 2 + 1 + rng.uniform(0, 1, n) * np.maximum(texture.w - span - 2, 0)
    cy = span / 2 + 1 + rng.uniform(0, 1, n) * np.maximum(texture.h - span - 2, 0)
    c = np.stack([cx, cy], -1)[ok]
    m_a, m_b = m_a[ok], m_b[ok]
    c_b = c
    if centre_jitter > 0:  # no draw otherwise: seeded datasets without jitter stay the same
        shift = centre_jitter * rng.standard_normal((n, 2))[ok]
        c_b = c + np.einsum("nij,nj->ni", m_b, shift)
    pa = texture.sample(_grid(c, m_a), np.linalg.svd(m_a, compute_uv=False)[:, 0])
    pb = texture.sample(_grid(c_b, m_b), np.linalg.svd(m_b, compute_uv=False)[:, 0])
    return SimilarityPairs(
        _photometric(rng, pa, 0.5),
        _photometric(rng, pb, 1.0),
        np.angle(np.exp(1j * phi[ok])),
        2.0 ** rel[ok],
    )


@dataclass
class PlanePairs:
    """Matches on a textured plane seen by two cameras, with exact ground truth."""

    patch_a: np.ndarray  # (N, 32, 32) float32
    patch_b: np.ndarray
    corrs: np.ndarray  # (N, 8) float64: x1, x2, A = dx2/dx1 (docs/design.md §2)
    F: np.ndarray  # (3, 3): p2^T F p1 = 0
    H: np.ndarray  # (3, 3): p2 ~ H p1


def _look_at(rng, target: np.ndarray, tilt: float, distance: float) -> tuple:
    """A camera at ``distance`` from ``target`` on the plane z = 0, its axis ``tilt`` away from
    the plane's normal, with a random azimuth and roll. Returns (R, C): X_cam = R (X - C)."""
    az = rng.uniform(0, 2 * math.pi)
    d = np.array([math.sin(tilt) * math.cos(az), math.sin(tilt) * math.sin(az), -math.cos(tilt)])
    centre = target - distance * d
    z = d
    x = np.cross([0.0, 0.0, 1.0] if abs(z[2]) < 0.9 else [1.0, 0.0, 0.0], z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    roll = rng.uniform(-math.pi, math.pi)
    base = np.stack([x, y, z])  # rows: camera axes in world coordinates
    cr, sr = math.cos(roll), math.sin(roll)
    return np.array([[cr, -sr, 0], [sr, cr, 0], [0, 0, 1.0]]) @ base, centre


def _intrinsics(rng) -> np.ndarray:
    f = rng.uniform(450, 900)
    return np.array(
        [
            [f * rng.uniform(0.95, 1.05), 0, rng.uniform(300, 340)],
            [0, f, rng.uniform(220, 260)],
            [0, 0, 1.0],
        ]
    )


def _texture_to_view(K: np.ndarray, R: np.ndarray, C: np.ndarray) -> np.ndarray:
    """Homography from texture pixels (the plane z = 0, one unit per pixel) to view pixels."""
    return K @ np.column_stack([R[:, 0], R[:, 1], -R @ C])


def _apply(H: np.ndarray, x: np.ndarray) -> np.ndarray:
    p = x @ H[:, :2].T + H[:, 2]
    return p[..., :2] / p[..., 2:3]


def _local_shrink(Hinv: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Largest singular value of d(texture)/d(view) at view points x: texture pixels per view
    pixel, which picks the anti-aliasing level."""
    p = x @ Hinv[:2, :2].T + Hinv[:2, 2]
    w = x @ Hinv[2, :2] + Hinv[2, 2]
    J = (Hinv[None, :2, :2] - (p / w[:, None])[:, :, None] * Hinv[None, 2:3, :2]) / w[:, None, None]
    return np.linalg.svd(J, compute_uv=False)[:, 0]


def _fundamental(K1, R1, C1, K2, R2, C2) -> np.ndarray:
    """F of two cameras X_cam = R (X - C): X2 = R X1 + t with R = R2 R1^T, t = R2 (C1 - C2),
    F = K2^-T [t]x R K1^-1 (p2^T F p1 = 0), Frobenius-normalised."""
    R = R2 @ R1.T
    t = R2 @ (C1 - C2)
    tx = np.array([[0, -t[2], t[1]], [t[2], 0, -t[0]], [-t[1], t[0], 0]])
    Fm = np.linalg.inv(K2).T @ tx @ R @ np.linalg.inv(K1)
    return Fm / np.linalg.norm(Fm)


def plane_pairs(
    rng: np.random.Generator,
    texture: Texture,
    n: int,
    *,
    max_tilt_deg: float = 60.0,
    max_scale_ratio: float = 4.0,
    centre_jitter: float = 0.0,
) -> PlanePairs | None:
    """Up to ``n`` matches of one random two-view plane scene (None if the draw is unusable).

    View 1 looks at the texture with a tilt up to 30 deg at 0.7-1.4 view pixels per texture
    pixel; view 2 with a tilt up to ``max_tilt_deg`` and a scale 1/``max_scale_ratio`` to
    ``max_scale_ratio`` times view 1's. ``centre_jitter`` (px, std) moves patch B's centre off
    the exact x2, as matcher noise does; the ground truth stays exact.
    """
    K1, K2 = _intrinsics(rng), _intrinsics(rng)
    target = np.array(
        [
            texture.w / 2 + rng.uniform(-0.2, 0.2) * texture.w,
            texture.h / 2 + rng.uniform(-0.2, 0.2) * texture.h,
            0.0,
        ]
    )
    s1 = 2.0 ** rng.uniform(-0.5, 0.5)
    s2 = s1 * max_scale_ratio ** rng.uniform(-1, 1)
    s2 = min(max(s2, 0.25), 2.0)
    tilt1 = math.radians(rng.uniform(0, 30))
    tilt2 = math.radians(rng.uniform(0, max_tilt_deg))
    R1, C1 = _look_at(rng, target, tilt1, K1[1, 1] / s1)
    R2, C2 = _look_at(rng, target, tilt2, K2[1, 1] / s2)
    G1, G2 = _texture_to_view(K1, R1, C1), _texture_to_view(K2, R2, C2)
    H = G2 @ np.linalg.inv(G1)
    H /= H[2, 2]
    Fm = _fundamental(K1, R1, C1, K2, R2, C2)

    # Texture points whose patches lie inside the texture in both views.
    m = 4 * n
    tex = np.stack([rng.uniform(0, texture.w, m), rng.uniform(0, texture.h, m)], -1)
    x1, x2 = _apply(G1, tex), _apply(G2, tex)
    depth1, depth2 = tex @ G1[2, :2] + G1[2, 2], tex @ G2[2, :2] + G2[2, 2]
    ok = (depth1 > 0) & (depth2 > 0)
    ok &= (np.abs(x1 - K1[:2, 2]).max(1) < 600) & (np.abs(x2 - K2[:2, 2]).max(1) < 600)
    x1, x2 = x1[ok], x2[ok]
    x2c = x2 + centre_jitter * rng.standard_normal(x2.shape)
    G1i, G2i = np.linalg.inv(G1), np.linalg.inv(G2)
    eye = np.broadcast_to(np.eye(2), (len(x1), 2, 2))
    g1 = _apply(G1i, _grid(x1, eye).reshape(-1, 2)).reshape(-1, PATCH, PATCH, 2)
    g2 = _apply(G2i, _grid(x2c, eye).reshape(-1, 2)).reshape(-1, PATCH, PATCH, 2)

    def inside(g):
        return (
            (g[..., 0] >= 0)
            & (g[..., 0] <= texture.w - 1)
            & (g[..., 1] >= 0)
            & (g[..., 1] <= texture.h - 1)
        ).all(axis=(1, 2))

    keep = np.nonzero(inside(g1) & inside(g2))[0][:n]
    if len(keep) == 0:
        return None
    x1, x2, x2c, g1, g2 = x1[keep], x2[keep], x2c[keep], g1[keep], g2[keep]
    pa = texture.sample(g1, _local_shrink(G1i, x1))
    pb = texture.sample(g2, _local_shrink(G2i, x2c))
    corrs = correspondences_from_homography(H, x1)  # x2 = H(x1), A = dx2/dx1 (docs/design.md §2)
    return PlanePairs(_photometric(rng, pa, 0.5), _photometric(rng, pb, 1.0), corrs, Fm, H)


def _view_rotation(K1, R1, C1, K2, R2, C2, x) -> float:
    """The rotation angle (rad) of the view-1 -> view-2 homography's Jacobian J at view-1
    point x: atan2(J21 - J12, J11 + J22), the angle of J's closest similarity."""
    H = _texture_to_view(K2, R2, C2) @ np.linalg.inv(_texture_to_view(K1, R1, C1))
    p = H @ np.array([x[0], x[1], 1.0])
    J = (H[:2, :2] - np.outer(p[:2] / p[2], H[2, :2])) / p[2]
    return math.atan2(J[1, 0] - J[0, 1], J[0, 0] + J[1, 1])


def render_plane_views(
    rng: np.random.Generator,
    image: np.ndarray,
    *,
    size=(640, 480),
    max_tilt_deg: float = 60.0,
    max_scale_ratio: float = 4.0,
    tilts_deg: tuple[float, float] | None = None,
    with_fundamental: bool = False,
    max_rotation_deg: float | None = None,
):
    """Two full views (H, W) float32 of ``image`` on a plane, as :func:`plane_pairs` draws them,
    and the ground-truth homography view 1 -> view 2. Outside the texture is black. For
    evaluating detectors and matchers on held-out textures. ``tilts_deg``: the two cameras'
    tilts from the plane's normal, instead of random ones (0-30 and 0-``max_tilt_deg``).
    ``with_fundamental``: also return the two cameras' F (p2^T F p1 = 0), as a 4th item.
    ``max_rotation_deg``: roll camera 2 so that view 2 is rotated w.r.t. view 1 (at view 1's
    centre) by a uniform angle within +-this (default: any roll, the views' rotation is
    arbitrary), for matchers that are not rotation invariant; drawn after the rest."""
    tex = Texture(image)
    w, h = size
    K1, K2 = _intrinsics(rng), _intrinsics(rng)
    target = np.array([tex.w / 2, tex.h / 2, 0.0])
    fit = min(w / tex.w, h / tex.h)  # view 1 sees most of the texture
    s1 = fit * 2.0 ** rng.uniform(0.0, 0.5)
    s2 = s1 * max_scale_ratio ** rng.uniform(-0.5, 0.5)
    # Drawn in this order so that seeded calls without tilts_deg give the same views as before.
    tilt1 = rng.uniform(0, 30) if tilts_deg is None else tilts_deg[0]
    R1, C1 = _look_at(rng, target, math.radians(tilt1), K1[1, 1] / s1)
    tilt2 = rng.uniform(0, max_tilt_deg) if tilts_deg is None else tilts_deg[1]
    R2, C2 = _look_at(rng, target, math.radians(tilt2), K2[1, 1] / s2)
    if max_rotation_deg is not None:
        want = math.radians(rng.uniform(-max_rotation_deg, max_rotation_deg))
        # Rolling camera 2 by a about its axis turns view 2 by a about the principal point.
        for _ in range(3):  # the view's rotation is nearly linear in the roll: converges fast
            a = want - _view_rotation(K1, R1, C1, K2, R2, C2, (w / 2, h / 2))
            ca, sa = math.cos(a), math.sin(a)
            R2 = np.array([[ca, -sa, 0], [sa, ca, 0], [0, 0, 1.0]]) @ R2
    views = []
    for K, R, C in ((K1, R1, C1), (K2, R2, C2)):
        G = _texture_to_view(K, R, C)
        xs, ys = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
        pts = np.stack([xs.ravel(), ys.ravel()], -1)
        Gi = np.linalg.inv(G)
        t = _apply(Gi, pts)
        shrink = float(np.median(_local_shrink(Gi, pts[::97])))
        lv = int(np.clip(np.searchsorted(_LEVELS, shrink), 0, len(_LEVELS) - 1))
        g = torch.from_numpy(t).float()
        g[:, 0] = g[:, 0] / (tex.w - 1) * 2 - 1
        g[:, 1] = g[:, 1] / (tex.h - 1) * 2 - 1
        img = F.grid_sample(
            tex.levels[lv],
            g.view(1, h, w, 2),
            mode="bilinear",
            padding_mode="zeros",
            align_corners=True,
        )[0, 0].numpy()
        views.append((img, G))
    H = views[1][1] @ np.linalg.inv(views[0][1])
    if with_fundamental:
        return views[0][0], views[1][0], H / H[2, 2], _fundamental(K1, R1, C1, K2, R2, C2)
    return views[0][0], views[1][0], H / H[2, 2]
