"""Scenes of the evaluation suite: image pairs with exact ground-truth homographies.

- :func:`hpatches_pairs` (experiments 1 and 2): graffiti 1 -> 3 with its published H, and
  HPatches-style sequences made from held-out real images (affcorr.train.sources' "val" split,
  never seen in training): a reference and 5 targets each. *Viewpoint* targets are the reference
  under random homographies of growing strength (k = 1..5: corner shifts up to 6k % of the
  image, rotation up to 6k deg, scale 2^(+-0.12k)) with a mild photometric change; *illumination*
  targets keep the geometry (H = I) under growing photometric change (gain, gamma, a smooth
  shading field, noise).
- :func:`extreme_pairs` (experiment 4): a held-out image on a plane seen by two pinhole cameras,
  camera 1 facing it (tilt 0-10 deg), camera 2 at 50-80 deg tilt
  (affcorr.train.views.render_plane_views: anti-aliased rendering, exact H).

Everything is seeded: the same arguments give the same pixels. Images are uint8 gray.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: Held-out images per sequence kind (all six of affcorr.train.sources.OPENCV_VAL/SKIMAGE_VAL).
VIEWPOINT_IMAGES = ["building.jpg", "starry_night.jpg", "chelsea.png"]
ILLUMINATION_IMAGES = ["leuvenA.jpg", "gravel.png", "smarties.png"]
EXTREME_IMAGES = ["building.jpg", "leuvenA.jpg", "starry_night.jpg", "gravel.png"]
TARGETS = 5


@dataclass
class Pair:
    """Two images and the homography from image 1 to image 2 (p2 ~ H p1)."""

    id: str  # unique across the suite: names cache files
    kind: str  # "viewpoint", "illumination" or "extreme"
    img1: np.ndarray  # uint8 (H, W)
    img2: np.ndarray
    H: np.ndarray  # (3, 3)
    meta: dict = field(default_factory=dict)


def _u8(img: np.ndarray) -> np.ndarray:
    return np.clip(np.rint(np.asarray(img, np.float64) * 255.0), 0, 255).astype(np.uint8)


def _fit(img: np.ndarray, max_side: int) -> tuple[np.ndarray, float]:
    """``img`` (float in [0, 1]) downscaled (area filter) so its longer side is at most
    ``max_side``, and the scale factor."""
    import cv2

    s = min(1.0, max_side / max(img.shape))
    if s == 1.0:
        return img.astype(np.float32), 1.0
    w, h = round(img.shape[1] * s), round(img.shape[0] * s)
    return cv2.resize(img.astype(np.float32), (w, h), interpolation=cv2.INTER_AREA), s


def _held_out() -> dict[str, np.ndarray]:
    from affcorr.train.sources import textures

    return dict(textures("val"))


def graffiti_pair(max_side: int = 512) -> Pair:
    """graf1 -> graf3 with the published H, downscaled to ``max_side`` (H follows)."""
    from affcorr.data import graffiti

    g1, g3, H = graffiti()
    a, s = _fit(g1, max_side)
    b, _ = _fit(g3, max_side)
    S = np.diag([s, s, 1.0])
    Hs = S @ H @ np.linalg.inv(S)
    return Pair("graffiti-1-3", "viewpoint", _u8(a), _u8(b), Hs / Hs[2, 2], {"source": "graffiti"})


def random_homography(rng: np.random.Generator, w: int, h: int, k: int) -> np.ndarray:
    """A homography of strength ``k`` (1..5) that keeps the image roughly in view: the corners
    are rotated and scaled about the centre, then each is moved at random."""
    import cv2

    c = np.array([[0, 0], [w - 1, 0], [w - 1, h - 1], [0, h - 1]], np.float64)
    centre = c.mean(0)
    ang = np.radians(rng.uniform(-6, 6) * k)
    sc = 2.0 ** (rng.uniform(-0.12, 0.12) * k)
    R = sc * np.array([[np.cos(ang), -np.sin(ang)], [np.sin(ang), np.cos(ang)]])
    d = (c - centre) @ R.T + centre
    d += rng.uniform(-1, 1, (4, 2)) * 0.06 * k * np.array([w, h])
    H = cv2.getPerspectiveTransform(c.astype(np.float32), d.astype(np.float32))
    return H / H[2, 2]


def _photometric(rng: np.random.Generator, img: np.ndarray, k: float) -> np.ndarray:
    """Gain, gamma, a smooth multiplicative shading field and noise, growing with ``k``."""
    h, w = img.shape
    gain = np.exp(rng.uniform(-0.2, 0.2) * k)
    gamma = np.exp(rng.uniform(-0.25, 0.25) * k)
    ys, xs = np.mgrid[0:h, 0:w] / max(h, w)
    cx, cy = rng.uniform(0, w / max(h, w)), rng.uniform(0, h / max(h, w))
    blob = np.exp(-((xs - cx) ** 2 + (ys - cy) ** 2) / (2 * rng.uniform(0.15, 0.4) ** 2))
    grad = rng.uniform(-1, 1) * (xs - 0.5) + rng.uniform(-1, 1) * (ys - 0.5)
    shade = np.clip(1.0 + 0.12 * k * (grad + rng.uniform(-1, 1) * blob), 0.2, 3.0)
    noise = rng.normal(0.0, (1.0 + k) / 255.0, img.shape)
    return np.clip(np.clip(img, 0, 1) ** gamma * gain * shade + noise, 0.0, 1.0)


def hpatches_pairs(max_side: int = 512, seed: int = 0, images: int | None = None) -> list[Pair]:
    """graffiti 1 -> 3 plus ``images`` viewpoint and ``images`` illumination sequences of 5
    targets each (all listed images by default)."""
    import cv2

    tex = _held_out()
    pairs = [graffiti_pair(max_side)]
    for kind, names in (("viewpoint", VIEWPOINT_IMAGES), ("illumination", ILLUMINATION_IMAGES)):
        for name in names[:images]:
            if name not in tex:
                continue
            ref, _ = _fit(tex[name], max_side)
            h, w = ref.shape
            # One generator per sequence: adding images or targets never changes the others.
            rng = np.random.default_rng([seed, sum(map(ord, kind + name))])
            for k in range(1, TARGETS + 1):
                if kind == "viewpoint":
                    H = random_homography(rng, w, h, k)
                    tgt = cv2.warpPerspective(ref, H, (w, h), flags=cv2.INTER_LINEAR)
                    tgt = _photometric(rng, tgt, 0.3)
                else:
                    H = np.eye(3)
                    tgt = _photometric(rng, ref, k)
                stem = name.rsplit(".", 1)[0]
                pairs.append(Pair(f"{kind[0]}-{stem}-{k}", kind, _u8(ref), _u8(tgt), H, {"k": k}))
    return pairs


def unrelated_pairs(
    n: int, max_side: int = 640, seed: int = 5
) -> list[tuple[str, str, np.ndarray, np.ndarray]]:
    """``n`` pairs of different training and held-out textures (affcorr.train.sources), which
    do not overlap: ``(name0, name1, img0, img1)``, the images float in [0, 1] at most
    ``max_side`` a side, the pairs drawn with ``seed`` and sorted. Files named alike (pic1,
    pic3, ...) may show one scene: they are never paired."""
    from affcorr.train.sources import textures

    tex = dict(textures("train")) | dict(textures("val"))
    names = sorted(tex)
    rng = np.random.default_rng(seed)
    pairs: set[tuple[str, str]] = set()
    while len(pairs) < n:
        i, j = sorted(rng.choice(len(names), 2, replace=False))
        if names[i][:3] != names[j][:3]:
            pairs.add((names[i], names[j]))
    fitted: dict[str, np.ndarray] = {}

    def image(name: str) -> np.ndarray:
        if name not in fitted:
            fitted[name] = _fit(tex[name], max_side)[0]
        return fitted[name]

    return [(a, b, image(a), image(b)) for a, b in sorted(pairs)]


def extreme_pairs(
    tilts=(50, 60, 70, 80),
    seed: int = 0,
    images: int | None = None,
    size=(640, 480),
    every_held_out: bool = False,
    scale_ratio: float = 1.0,
) -> list[Pair]:
    """One pair per held-out image and tilt of camera 2 (camera 1: tilt 0-10 deg; the same
    distance to the plane, so only the viewpoint changes the scale). The images are
    EXTREME_IMAGES, or with ``every_held_out`` every held-out texture; a seed other than 0
    draws other cameras (and names the pairs ``...-s<seed>``). ``scale_ratio`` > 1: camera 2's
    distance differs too, by a zoom drawn log-uniformly within 1/sqrt(ratio)..sqrt(ratio) (and
    the pairs are named ``...-z<ratio>``); 1 gives the same pairs as before it existed."""
    from affcorr.train.views import render_plane_views

    tex = _held_out()
    names = sorted(tex) if every_held_out else EXTREME_IMAGES
    pairs = []
    for name in names[:images]:
        if name not in tex:
            continue
        for t in tilts:
            rng = np.random.default_rng([seed, int(t), sum(map(ord, name))])
            t1 = float(rng.uniform(0, 10))
            i1, i2, H = render_plane_views(
                rng, tex[name], size=size, max_scale_ratio=scale_ratio, tilts_deg=(t1, float(t))
            )
            stem = name.rsplit(".", 1)[0]
            pid = f"x-{stem}-{t}" + (f"-s{seed}" if seed else "")
            pid += f"-z{scale_ratio:g}" if scale_ratio != 1.0 else ""
            pairs.append(Pair(pid, "extreme", _u8(i1), _u8(i2), H, {"tilt": t, "tilt1": t1}))
    return pairs
