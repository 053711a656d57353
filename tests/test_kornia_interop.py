"""kornia LAF interop, with the orientation sign checked on a rotated real image (docs/design.md
§2).

kornia builds its LAF rotation as [[cos, sin], [-sin, cos]], so its angle is the negative of our
orientation. Reading it the wrong way round would give A = R(-phi) instead of R(phi) here.
"""

from __future__ import annotations

from pathlib import Path

import affcorr
import numpy as np
import pytest

torch = pytest.importorskip("torch")
kornia = pytest.importorskip("kornia")
PIL = pytest.importorskip("PIL.Image")

DATA = Path(__file__).resolve().parents[1] / "data" / "graffiti"


def bilinear(img: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = x - x0, y - y0
    x0, y0 = np.clip(x0, 0, img.shape[1] - 2), np.clip(y0, 0, img.shape[0] - 2)
    return (
        img[y0, x0] * (1 - fx) * (1 - fy)
        + img[y0, x0 + 1] * fx * (1 - fy)
        + img[y0 + 1, x0] * (1 - fx) * fy
        + img[y0 + 1, x0 + 1] * fx * fy
    )


def rotated_pair(phi: float):
    """A real 320x320 crop and its rotation by phi about the centre: x2 = R(phi)(x1 - c) + c,
    in pixel coordinates (x right, y down). The ground-truth A is R(phi) everywhere."""
    img = np.asarray(PIL.open(DATA / "graf1.png").convert("L"), dtype=np.float64) / 255.0
    img1 = img[200:520, 250:570]
    c = np.array([159.5, 159.5])
    R = np.array([[np.cos(phi), -np.sin(phi)], [np.sin(phi), np.cos(phi)]])
    ys, xs = np.mgrid[0:320, 0:320].astype(np.float64)
    src = (np.stack([xs.ravel(), ys.ravel()], 1) - c) @ R + c  # R^T (x2 - c) + c
    img2 = bilinear(img1, src[:, 0], src[:, 1]).reshape(320, 320)
    return img1, img2, R, c


@pytest.mark.parametrize("phi_deg", [35.0, -60.0])
def test_laf_orientation_sign_on_a_rotated_image(phi_deg):
    phi = np.deg2rad(phi_deg)
    img1, img2, R, c = rotated_pair(phi)
    g = np.random.default_rng(0)
    x1 = c + g.uniform(-70, 70, size=(40, 2))
    x2 = (x1 - c) @ R.T + c

    orienter = kornia.feature.LAFOrienter(32)

    def oriented_lafs(img, pts):
        centers = torch.from_numpy(pts[None]).float()
        laf = kornia.feature.laf_from_center_scale_ori(
            centers, torch.full((1, len(pts), 1, 1), 12.0), torch.zeros(1, len(pts), 1)
        )
        with torch.no_grad():
            return orienter(laf, torch.from_numpy(img[None, None]).float()).double().numpy()

    laf1, laf2 = oriented_lafs(img1, x1), oriented_lafs(img2, x2)
    corrs = affcorr.laf_to_affine(laf1, laf2)
    assert corrs.shape == (1, 40, 8)
    np.testing.assert_allclose(corrs[0, :, :2], x1, atol=1e-4)
    np.testing.assert_allclose(corrs[0, :, 2:4], x2, atol=1e-4)

    theta, scale, _ = affcorr.decompose_affine(corrs[0, :, 4:].reshape(-1, 2, 2))
    err = np.angle(np.exp(1j * (theta - phi)))
    # Dominant-gradient orientation is noisy per patch; the median must match phi, not -phi.
    assert abs(np.median(err)) < np.deg2rad(5.0), np.rad2deg(err)
    np.testing.assert_allclose(np.median(scale), 1.0, atol=1e-6)

    # kornia's own angle has the opposite sign to ours.
    k1 = kornia.feature.get_laf_orientation(torch.from_numpy(laf1)).numpy().ravel()
    k2 = kornia.feature.get_laf_orientation(torch.from_numpy(laf2)).numpy().ravel()
    kornia_delta = np.deg2rad(k2 - k1)
    assert abs(np.median(np.angle(np.exp(1j * (kornia_delta + phi))))) < np.deg2rad(5.0)


def test_affine_to_laf_round_trips_through_kornia(scene, rng):
    corrs = scene.correspondences(scene.sample_pixels(rng, 25))
    laf1, laf2 = affcorr.affine_to_laf(corrs, radius=8.0)
    # kornia reads the centre and scale of our LAFs as we wrote them.
    t1 = torch.from_numpy(laf1)
    np.testing.assert_allclose(kornia.feature.get_laf_center(t1).numpy()[0], corrs[:, :2])
    np.testing.assert_allclose(kornia.feature.get_laf_scale(t1).numpy().ravel(), 8.0)
    np.testing.assert_allclose(affcorr.laf_to_affine(laf1, laf2)[0], corrs, atol=1e-12)
