"""Image pairs with a known relative pose for experiment 3 (affcorr_bench.eval.pose).

Every pair is a :class:`PosePair`: two uint8 gray images, pinhole intrinsics K1, K2 and the
motion ``X2 = R X1 + t`` (docs/design.md §2; ``t`` has unit norm, the scale is unobservable).

- ``chessboard``: Debian opencv-doc's calibration set (left01..14, right01..14 without 10). The
  board poses of the left views come from ``left_intrinsics.yml`` (its ``extrinsic_parameters``),
  so every pair of left views has a ground-truth motion (78 pairs); the left/right rig is
  calibrated with OpenCV on the pairs of ``stereo_calib.xml`` (13 pairs, one motion). The images
  are undistorted first (pose_calib, run once in benches/peers/.venv-peers). The views show
  a repetitive, low-texture board in a plain room: a hard case for any matcher.
- ``motorcycle``: scikit-image's rectified Middlebury 2014 pair (R = I, t along -x), with the
  calibration of its docstring rescaled to the bundled resolution.
- ``synthetic``: MegaDepth-like scenes rendered here: a back wall, an optional ground plane
  and 2-4 slanted facades, each textured with a crop of a held-out real image (the validation
  split of affcorr.train.sources, never seen by the shape network), seen by two cameras 5-30
  degrees apart with different focal lengths and a photometric change. Rendering is exact ray
  casting with a z-buffer and per-pixel anti-aliasing (affcorr.train.views.Texture's pyramid).
  Pairs are seeded by their index and cached as .npz (``cache_dir()/eval/pose``).
"""

from __future__ import annotations

import json
import math
import subprocess
from collections.abc import Callable
from dataclasses import dataclass, replace
from functools import lru_cache
from pathlib import Path

import numpy as np
from affcorr.train.sources import cache_dir, opencv_doc_data

from .. import common

PEERS_PYTHON = common.PEERS_PYTHON
SYNTH_VERSION = "synth-v1"
SIZE = (640, 480)  # synthetic views, W x H
MIN_COVISIBLE = 0.25  # fraction of view 1 seen unoccluded in view 2


@dataclass
class PosePair:
    """One image pair with its ground-truth relative pose; images load on demand."""

    dataset: str
    name: str
    K1: np.ndarray
    K2: np.ndarray
    R: np.ndarray
    t: np.ndarray  # unit norm
    load: Callable[[], tuple[np.ndarray, np.ndarray]]  # -> (img1, img2) uint8 (H, W)
    # Where the pose holds, when not everywhere: a convex polygon (k, 2) in each image.
    region: tuple[np.ndarray, np.ndarray] | None = None

    def keep(self, x1: np.ndarray, x2: np.ndarray) -> np.ndarray:
        """(N,) bool: the matches inside the region in both images (all without one)."""
        if self.region is None:
            return np.ones(len(x1), bool)
        return inside_convex(self.region[0], x1) & inside_convex(self.region[1], x2)


def inside_convex(poly: np.ndarray, x: np.ndarray) -> np.ndarray:
    """(N,) bool: points x (N, 2) inside the convex polygon ``poly`` (k, 2), either winding."""
    e = np.roll(poly, -1, axis=0) - poly  # edges
    r = x[:, None, :] - poly[None]  # (N, k, 2)
    cross = e[None, :, 0] * r[..., 1] - e[None, :, 1] * r[..., 0]
    return np.all(cross >= 0, axis=1) | np.all(cross <= 0, axis=1)


def pose_cache() -> Path:
    d = cache_dir() / "eval" / "pose"
    d.mkdir(parents=True, exist_ok=True)
    return d


def _unit(t: np.ndarray) -> np.ndarray:
    return np.asarray(t, float).reshape(3) / np.linalg.norm(t)


def _read_u8(path: Path) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(path).convert("L"), dtype=np.uint8)


# --- chessboard (opencv-doc) ------------------------------------------------------------------


def chessboard_calibration() -> tuple[Path, dict]:
    """The undistorted images and calib.json of pose_calib (made on first use, in .venv-peers)."""
    out = pose_cache() / "chessboard"
    if not (out / "calib.json").exists():
        if not PEERS_PYTHON.exists():
            raise FileNotFoundError(f"{PEERS_PYTHON} missing: run benches/eval/pose_setup.sh")
        module = "affcorr_bench.eval.pose_calib"
        cmd = common.module_cmd(PEERS_PYTHON, module, opencv_doc_data(), out)
        subprocess.run(cmd, check=True, env=common.child_env())
    return out, json.loads((out / "calib.json").read_text())


# The board's printed area in squares around its 9 x 6 inner corners, with a small margin.
_BOARD_OUTLINE = np.array([[-1.5, -1.5], [9.5, -1.5], [9.5, 6.5], [-1.5, 6.5]])


def chessboard_pairs() -> list[PosePair]:
    """78 pairs of left views (board poses) + 13 left/right stereo pairs (calibrated rig).

    The camera of the left views stands still while the board moves: the board poses give the
    motion of the board's points only (the room's points do not move), so in those pairs only
    the matches on the board (inside its outline in both images) are used; the scene is then a
    single plane. The stereo pairs use all matches (the rig is rigid)."""
    d, c = chessboard_calibration()
    K_l, K_r = np.array(c["K_left"]), np.array(c["K_right"])
    poses = {k: (np.array(v["R"]), np.array(v["t"])) for k, v in c["board_from_yml"].items()}
    outline = np.c_[_BOARD_OUTLINE * c["square_size_m"], np.zeros(4)]

    def board_polygon(name):
        R, t = poses[name]
        p = (outline @ R.T + t) @ K_l.T
        return p[:, :2] / p[:, 2:]

    def loader(a: str, b: str):
        return lambda: (_read_u8(d / f"{a}.png"), _read_u8(d / f"{b}.png"))

    out = []
    lefts = c["lefts"]
    for i, a in enumerate(lefts):
        for b in lefts[i + 1 :]:
            (Ra, ta), (Rb, tb) = poses[a], poses[b]
            R = Rb @ Ra.T  # X_a = Ra X + ta, X_b = Rb X + tb => X_b = R X_a + tb - R ta
            t = tb - R @ ta
            region = (board_polygon(a), board_polygon(b))
            out.append(
                PosePair("chessboard", f"{a}-{b}", K_l, K_l, R, _unit(t), loader(a, b), region)
            )
    Rs, ts = np.array(c["stereo"]["R"]), np.array(c["stereo"]["t"])
    for a, b in zip(lefts, c["rights"]):
        out.append(PosePair("chessboard-stereo", f"{a}-{b}", K_l, K_r, Rs, _unit(ts), loader(a, b)))
    return out


# --- motorcycle (scikit-image) ----------------------------------------------------------------

# The calibration in skimage.data.stereo_motorcycle's docstring, valid for the bundled
# (4x down-sampled) images: focal length, principal point (x, y), the right camera's principal
# point offset dx, baseline 193.001 mm.
_MOTO_F, _MOTO_CX, _MOTO_CY, _MOTO_DX = 994.978, 311.193, 254.877, 31.086


def motorcycle_pair() -> PosePair:
    from skimage import data

    left, right, _ = data.stereo_motorcycle()

    def K_of(cx):
        return np.array([[_MOTO_F, 0, cx], [0, _MOTO_F, _MOTO_CY], [0, 0, 1.0]])

    def gray(img):
        g = img[..., :3].astype(np.float64) @ np.array([0.299, 0.587, 0.114])
        return np.clip(np.rint(g), 0, 255).astype(np.uint8)

    # Rectified: same orientation, camera 2 (right) a baseline to the right: X2 = X1 - (B, 0, 0).
    return PosePair(
        "motorcycle",
        "motorcycle",
        K_of(_MOTO_CX),
        K_of(_MOTO_CX + _MOTO_DX),
        np.eye(3),
        np.array([-1.0, 0, 0]),
        lambda: (gray(left), gray(right)),
    )


# --- synthetic multi-plane scenes -------------------------------------------------------------


@lru_cache(maxsize=1)
def _textures():
    from affcorr.train.sources import textures
    from affcorr.train.views import Texture

    return [(name, Texture(img)) for name, img in textures("val")]


@dataclass
class _Plane:
    origin: np.ndarray  # world point of texture pixel (x0, y0)
    u: np.ndarray  # world direction of texture +x
    v: np.ndarray  # world direction of texture +y
    m: float  # world units per texture pixel
    tex: int
    crop: tuple[float, float, float, float]  # x0, y0, width, height in texture pixels
    # Texture-poor surfaces (rooms): at least this pyramid level (a blur of up to ~4 texture
    # pixels, affcorr.train.views._LEVELS), and values grey + contrast * (value - 0.5).
    min_level: int = 0
    contrast: float = 1.0
    grey: float = 0.5


def _rot(axis: str, a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    if axis == "x":
        return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    if axis == "y":
        return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def _crop(rng, tex, aspect: float, frac: float):
    """A crop of ``frac`` of the texture's width (or height) with width/height ``aspect``."""
    w = min(tex.w * frac, tex.h * frac * aspect)
    h = w / aspect
    return (rng.uniform(0, max(tex.w - w, 0.0)), rng.uniform(0, max(tex.h - h, 0.0)), w, h)


def _plane(rng, centre, u, v, width: float, height: float, frac: float, **look) -> _Plane:
    """A width x height rectangle centred at ``centre`` along u (texture +x) and v (texture +y),
    textured with a crop of ``frac`` of a random texture; ``look``: _Plane's min_level,
    contrast, grey."""
    texs = _textures()
    k = int(rng.integers(len(texs)))
    crop = _crop(rng, texs[k][1], width / height, frac)
    u, v = np.asarray(u, float), np.asarray(v, float)
    origin = np.asarray(centre, float) - u * width / 2 - v * height / 2
    return _Plane(origin, u, v, width / crop[2], k, crop, **look)


def _scene(rng, f1: float) -> list[_Plane]:
    D = rng.uniform(5.0, 8.0)
    half_w = D * (SIZE[0] / 2) / f1  # half the view's width at depth D
    planes = []

    def add(centre, Rp, width, height, frac):
        planes.append(_plane(rng, centre, Rp[:, 0], Rp[:, 1], width, height, frac))

    # back wall, facing camera 1 (normal -z), tilted a little
    depth = D + rng.uniform(1.0, 3.0)
    Rw = _rot("y", rng.uniform(-0.35, 0.35)) @ _rot("x", rng.uniform(-0.2, 0.2))
    wall_w = 2.6 * half_w * depth / D
    add(np.array([0, 0, depth]), Rw, wall_w, wall_w * 0.8, 1.0)
    # ground plane y = +h (y is down), seen at a grazing angle
    if rng.uniform() < 0.7:
        h = rng.uniform(0.15, 0.3) * D
        Rg = _rot("x", -math.pi / 2)  # texture x -> world x, texture y -> world -z... (u, v)
        add(np.array([0, h, D * 0.7]), Rg, 2.0 * half_w, D * 1.2, 1.0)
    # facades
    for _ in range(int(rng.integers(2, 5))):
        c = np.array(
            [
                rng.uniform(-0.5, 0.5) * half_w,
                rng.uniform(-0.4, 0.3) * half_w,
                D + rng.uniform(-2.0, 0.5),
            ]
        )
        Rf = _rot("y", rng.uniform(-1.0, 1.0)) @ _rot("x", rng.uniform(-0.35, 0.35))
        width = rng.uniform(0.35, 0.8) * half_w
        add(c, Rf, width, width * rng.uniform(0.6, 1.4), rng.uniform(0.4, 0.9))
    return planes


def _intrinsics(rng, f: float) -> np.ndarray:
    return np.array(
        [
            [f, 0, SIZE[0] / 2 - 0.5 + rng.uniform(-10, 10)],
            [0, f * rng.uniform(0.98, 1.02), SIZE[1] / 2 - 0.5 + rng.uniform(-10, 10)],
            [0, 0, 1.0],
        ]
    )


def _render(planes: list[_Plane], K: np.ndarray, Rc: np.ndarray, C: np.ndarray):
    """Ray-cast view (H, W) float32 in [0, 1] and its depth (inf where no plane is hit) of a
    camera X_cam = Rc (X - C)."""
    import torch
    import torch.nn.functional as F  # noqa: N812
    from affcorr.train.views import _LEVELS

    w, h = SIZE
    # float32 is plenty here (texture coordinates to ~1e-4 px) and twice as fast
    xs, ys = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    rays = np.stack([xs, ys, np.ones_like(xs)], -1) @ np.linalg.inv(K).T.astype(np.float32)
    d = rays @ Rc.astype(np.float32)  # world directions (Rc^T r), camera z = 1
    depth = np.full((h, w), np.inf)
    img = np.zeros((h, w), np.float32)
    texs = _textures()
    for p in planes:
        n = np.cross(p.u, p.v).astype(np.float32)
        den = d @ n
        with np.errstate(divide="ignore", invalid="ignore"):
            lam = np.float32((p.origin - C) @ n) / den  # = camera depth z: rays have z = 1
        # texture coordinates of X = C + lam d: (X - origin) . u / m
        o = (C - p.origin).astype(np.float32)
        a = (lam * (d @ p.u.astype(np.float32)) + o @ p.u) / np.float32(p.m)
        b = (lam * (d @ p.v.astype(np.float32)) + o @ p.v) / np.float32(p.m)
        x0, y0, cw, ch = p.crop
        hit = (lam > 1e-6) & (a >= 0) & (a <= cw) & (b >= 0) & (b <= ch) & (lam < depth)
        if not hit.any():
            continue
        # texture pixels per view pixel, from the texture coordinates of the next pixel
        shrink = np.hypot(np.gradient(a, axis=1), np.gradient(b, axis=1))
        shrink = np.maximum(shrink, np.hypot(np.gradient(a, axis=0), np.gradient(b, axis=0)))
        tex = texs[p.tex][1]
        tx, ty = a[hit] + x0, b[hit] + y0
        level = np.clip(np.searchsorted(_LEVELS, shrink[hit]), p.min_level, len(_LEVELS) - 1)
        vals = np.empty(len(tx), np.float32)
        for lv in np.unique(level):
            k = level == lv
            g = torch.from_numpy(
                np.stack([tx[k] / (tex.w - 1) * 2 - 1, ty[k] / (tex.h - 1) * 2 - 1], -1)
            ).float()
            s = F.grid_sample(
                tex.levels[lv],
                g.view(1, 1, -1, 2),
                mode="bilinear",
                padding_mode="border",
                align_corners=True,
            )
            vals[k] = s.reshape(-1).numpy()
        if p.contrast != 1.0:
            vals = np.float32(p.grey) + np.float32(p.contrast) * (vals - np.float32(0.5))
        img[hit] = vals
        depth[hit] = lam[hit]
    return img, depth


def _project(K, Rc, C, X):
    Xc = (X - C) @ Rc.T
    p = Xc @ K.T
    return p[:, :2] / p[:, 2:3], Xc[:, 2]


def _covisible(planes, K1, K2, R2, C2, depth1, depth2) -> float:
    """Fraction of view 1's pixels (on an 8-px grid) seen unoccluded in view 2."""
    ys, xs = np.mgrid[4 : SIZE[1] : 8, 4 : SIZE[0] : 8]
    z = depth1[ys, xs].ravel()
    ok = np.isfinite(z)
    rays = np.stack([xs.ravel(), ys.ravel(), np.ones(xs.size)], -1) @ np.linalg.inv(K1).T
    X = rays[ok] * z[ok, None]
    x2, z2 = _project(K2, R2, C2, X)
    c = np.rint(x2).astype(int)
    inside = (z2 > 0) & (c[:, 0] >= 0) & (c[:, 0] < SIZE[0]) & (c[:, 1] >= 0) & (c[:, 1] < SIZE[1])
    vis = np.zeros(len(X), bool)
    ci = c[inside]
    vis[inside] = np.abs(depth2[ci[:, 1], ci[:, 0]] - z2[inside]) < 0.01 * z2[inside]
    return float(vis.sum() / xs.size)


def _u8(img: np.ndarray) -> np.ndarray:
    return np.clip(np.rint(img * 255.0), 0, 255).astype(np.uint8)


def _views(rng, planes, K1, K2, R2, C2, with_depth: bool) -> dict | None:
    """Both views of ``planes`` (camera 1 = world, camera 2 X_cam = R2 (X - C2)) with the pair's
    photometric change and noise, as render_pair returns them; None when less than
    MIN_COVISIBLE of view 1 is seen in view 2."""
    img1, depth1 = _render(planes, K1, np.eye(3), np.zeros(3))
    img2, depth2 = _render(planes, K2, R2, C2)
    cov = _covisible(planes, K1, K2, R2, C2, depth1, depth2)
    if cov < MIN_COVISIBLE:
        return None
    gain, gamma = np.exp(rng.uniform(-0.3, 0.3)), np.exp(rng.uniform(-0.3, 0.3))
    img2 = np.clip(np.clip(img2, 0, 1) ** gamma * gain, 0, 1)
    img1 = img1 + rng.normal(0, 1.5 / 255, img1.shape)
    img2 = img2 + rng.normal(0, 1.5 / 255, img2.shape)
    t = -R2 @ C2  # X2 = R2 (X1 - C2) with camera 1 = world
    out = dict(img1=_u8(img1), img2=_u8(img2), K1=K1, K2=K2, R=R2, t=_unit(t))
    out["covisible"] = np.float64(cov)
    out["baseline"] = np.float64(np.linalg.norm(t))  # scene units
    if with_depth:
        out.update(depth1=depth1, depth2=depth2)
    return out


def _look_at(forward) -> np.ndarray:
    """World-to-camera rotation of an upright camera (y down) looking along ``forward``."""
    z = np.asarray(forward, float) / np.linalg.norm(forward)
    x = np.cross([0.0, 1.0, 0.0], z)
    x /= np.linalg.norm(x)
    return np.stack([x, np.cross(z, x), z])


def render_pair(index: int, seed: int = 0, *, with_depth: bool = False) -> dict:
    """Synthetic pair ``index``: img1, img2 (uint8), K1, K2, R, t (unit), covisible (and the
    views' depth maps depth1, depth2 with ``with_depth``: inf where no plane is hit)."""
    for attempt in range(50):
        rng = np.random.default_rng([seed, index, attempt])
        f1 = rng.uniform(420.0, 620.0)
        K1 = _intrinsics(rng, f1)
        K2 = _intrinsics(rng, f1 * 2.0 ** rng.uniform(-0.35, 0.35))
        planes = _scene(rng, f1)
        angle = math.radians(rng.uniform(5.0, 30.0))
        direction = np.array(
            [rng.choice([-1.0, 1.0]), rng.uniform(-0.3, 0.3), rng.uniform(-0.5, 0.5)]
        )
        direction /= np.linalg.norm(direction)
        target = np.array([0, 0, 6.5]) + rng.normal(0, 0.3, 3)
        C2 = direction * np.linalg.norm(target) * math.tan(angle)
        R2 = _rot("z", rng.uniform(-0.2, 0.2)) @ _look_at(target - C2)
        out = _views(rng, planes, K1, K2, R2, C2, with_depth)
        if out is not None:
            return out
    raise RuntimeError(f"synthetic pair {index}: no usable draw in 50 attempts")


def _cached_pairs(
    folder: str, dataset: str, count: int, render: Callable[[int], dict]
) -> list[PosePair]:
    """The first ``count`` pairs that ``render(i)`` draws, rendered once into the pose cache's
    ``folder`` and then read from it; images load on demand."""
    d = pose_cache() / folder
    d.mkdir(parents=True, exist_ok=True)
    out = []
    for i in range(count):
        path = d / f"{i:04d}.npz"
        if not path.exists():
            np.savez_compressed(path, **render(i))
        z = np.load(path)

        def load(path=path):
            zz = np.load(path)
            return zz["img1"], zz["img2"]

        out.append(PosePair(dataset, f"{i:04d}", z["K1"], z["K2"], z["R"], z["t"], load))
    return out


def synthetic_pairs(count: int, seed: int = 0) -> list[PosePair]:
    """The first ``count`` synthetic pairs (rendered once, then read from the cache)."""
    return _cached_pairs(
        f"{SYNTH_VERSION}-seed{seed}", "synthetic", count, lambda i: render_pair(i, seed)
    )


# --- rendered low-texture rooms ---------------------------------------------------------------

ROOM_VERSION = "rooms-v1"
ROOM_ROLL = (0.0, 10.0)  # |roll| of camera 2 about its optical axis (deg), upright set
ROOM_ROLL_ROTATED = (60.0, 180.0)  # rotated set
_ROOM_TAG, _ROLL_TAG = 0x524F4F4D, 0x524F4C4C  # random streams of their own ("ROOM", "ROLL")


def _room(rng) -> tuple[list[_Plane], np.ndarray, tuple[np.ndarray, np.ndarray]]:
    """A texture-poor room around camera 1, in room coordinates (x right, y down, z forward,
    metres; camera 1 at the origin). Returns its planes, camera 1's world-to-camera rotation
    and the room's box (min corner, max corner).

    Floor, ceiling and 4 walls (closed: an open side would show a black void, an edge no room
    has) carry blurred crops of the textures at 10-30 % contrast around
    a grey (both varying per room and per surface); 2-5 fully textured rectangles stand on or
    near the walls: posters, furniture fronts (0.25-0.6 m off the wall), doors."""
    from affcorr.train.views import _LEVELS

    left, right = rng.uniform(1.2, 3.5, 2)  # walls' distances from camera 1
    front, back = rng.uniform(2.5, 6.0), rng.uniform(0.6, 3.0)
    height, eye = rng.uniform(2.4, 3.2), rng.uniform(1.2, 1.7)
    floor, ceil = eye, eye - height  # y of the floor and the ceiling
    contrast, wall_grey = rng.uniform(0.1, 0.3), rng.uniform(0.45, 0.7)
    e = 0.05  # surfaces overlap at the edges (no cracks; the overlap is behind a neighbour)

    def poor(centre, u, v, w, h, grey):
        look = dict(
            min_level=int(rng.integers(4, len(_LEVELS))),
            contrast=float(np.clip(contrast * rng.uniform(0.7, 1.3), 0.1, 0.3)),
            grey=float(np.clip(grey + rng.uniform(-0.08, 0.08), 0.2, 0.85)),
        )
        return _plane(rng, centre, u, v, w + 2 * e, h + 2 * e, rng.uniform(0.4, 1.0), **look)

    X, Y, Z = np.eye(3)
    mid_x, mid_y, mid_z = (right - left) / 2, (floor + ceil) / 2, (front - back) / 2
    wx, wz = left + right, front + back
    planes = [
        poor([mid_x, mid_y, front], X, Y, wx, height, wall_grey),
        poor([-left, mid_y, mid_z], -Z, Y, wz, height, wall_grey),
        poor([right, mid_y, mid_z], Z, Y, wz, height, wall_grey),
        poor([mid_x, floor, mid_z], X, Z, wx, wz, rng.uniform(0.25, 0.5)),
        poor([mid_x, ceil, mid_z], X, -Z, wx, wz, rng.uniform(0.65, 0.85)),
        poor([mid_x, mid_y, -back], -X, Y, wx, height, wall_grey),
    ]
    # objects on the front and side walls: (a point of the wall, along, inward normal, range)
    walls = [
        (front * Z, X, -Z, (-left, right)),
        (-left * X, Z, X, (0.5, front)),
        (right * X, Z, -X, (0.5, front)),
    ]
    for _ in range(int(rng.integers(2, 6))):
        base, along, inward, (lo, hi) = walls[int(rng.integers(len(walls)))]
        kind = rng.choice(["poster", "poster", "furniture", "door"])
        if kind == "poster":
            w = rng.uniform(0.4, 1.2)
            h = min(w * rng.uniform(0.6, 1.5), height - 0.6)
            y, off = max(floor - rng.uniform(1.1, 1.8), ceil + h / 2 + 0.1), 0.02
        elif kind == "furniture":
            w, h = rng.uniform(0.6, 1.6), rng.uniform(0.5, 1.1)
            y, off = floor - h / 2 - 0.01, rng.uniform(0.25, 0.6)
        else:
            w, h = rng.uniform(0.8, 0.95), min(rng.uniform(1.95, 2.1), height - 0.1)
            y, off = floor - h / 2 - 0.01, 0.02
        a = rng.uniform(lo + w / 2 + 0.05, max(hi - w / 2 - 0.05, lo + w / 2 + 0.1))
        centre = base + a * along + off * inward
        centre[1] = y
        planes.append(_plane(rng, centre, along, Y, w, h, rng.uniform(0.3, 0.9)))
    # camera 1 looks at a wall (front, left or right) or at one of the front corners
    view = rng.choice(["front", "left", "right", "corner", "corner"])
    yaw = {"front": 0.0, "left": -math.pi / 2, "right": math.pi / 2}.get(view)
    if yaw is None:
        yaw = math.atan2(right, front) if rng.uniform() < 0.5 else math.atan2(-left, front)
    yaw += rng.uniform(-0.3, 0.3)
    pitch = rng.uniform(-0.25, 0.25)  # > 0: down
    R1 = _look_at(
        [math.cos(pitch) * math.sin(yaw), math.sin(pitch), math.cos(pitch) * math.cos(yaw)]
    )
    box = (np.array([-left, ceil, -back]), np.array([right, floor, front]))
    return planes, R1, box


def room_pair(
    index: int, seed: int = 0, roll: tuple[float, float] = ROOM_ROLL, *, with_depth: bool = False
) -> dict:
    """Room pair ``index``: the keys of render_pair (metres) and ``roll``, camera 2's rotation
    about its optical axis in degrees, |roll| in ``roll`` with a random sign.

    Camera 1 stands in a texture-poor room (_room) looking at a wall or a corner; camera 2 is
    0.3-1.5 m away (inside the room), turned by up to 30 deg of yaw and 20 deg of pitch, then
    rolled. The room and the motion do not depend on ``roll`` (a stream of their own), so the
    upright and the rolled sets show the same rooms where the same draw is covisible in both."""
    for attempt in range(50):
        rng = np.random.default_rng([seed, index, attempt, _ROOM_TAG])
        roll_rng = np.random.default_rng([seed, index, attempt, _ROLL_TAG])
        f1 = rng.uniform(420.0, 620.0)
        K1 = _intrinsics(rng, f1)
        K2 = _intrinsics(rng, f1 * 2.0 ** rng.uniform(-0.35, 0.35))
        planes, R1, (lo, hi) = _room(rng)
        direction = rng.normal(size=3) * [1.0, 0.5, 1.0]
        C2 = direction / np.linalg.norm(direction) * rng.uniform(0.3, 1.5)  # camera 1's frame
        yaw, pitch = np.radians(rng.uniform(-30.0, 30.0)), np.radians(rng.uniform(-20.0, 20.0))
        r = roll_rng.uniform(*roll) * roll_rng.choice([-1.0, 1.0])
        C2_room = R1.T @ C2
        if np.any(C2_room < lo + 0.25) or np.any(C2_room > hi - 0.25):
            continue  # camera 2 outside the room, or too close to a surface
        R2 = _rot("z", math.radians(r)) @ _rot("x", pitch) @ _rot("y", yaw)
        # the room in camera 1's frame (camera 1 = world, as _views wants it)
        moved = [replace(p, origin=R1 @ p.origin, u=R1 @ p.u, v=R1 @ p.v) for p in planes]
        out = _views(rng, moved, K1, K2, R2, C2, with_depth)
        if out is not None:
            out["roll"] = np.float64(r)
            return out
    raise RuntimeError(f"room pair {index}: no usable draw in 50 attempts")


def room_pairs(count: int, seed: int = 0, roll: tuple[float, float] = ROOM_ROLL) -> list[PosePair]:
    """The first ``count`` room pairs with |roll| in ``roll`` (degrees): ROOM_ROLL upright,
    ROOM_ROLL_ROTATED rolled (rendered once, then read from the cache)."""
    lo, hi = roll
    return _cached_pairs(
        f"{ROOM_VERSION}-seed{seed}-roll{lo:g}-{hi:g}",
        "rooms" if hi <= 45 else "rooms-rolled",
        count,
        lambda i: room_pair(i, seed, roll),
    )


DATASETS = {
    "chessboard": chessboard_pairs,
    "motorcycle": lambda: [motorcycle_pair()],
}


def main(argv=None) -> None:
    """Pre-renders the synthetic pairs: ``python -m affcorr_bench.eval.pose_data COUNT [SEED]``."""
    import argparse

    ap = argparse.ArgumentParser(description=main.__doc__)
    ap.add_argument("count", type=int, help="synthetic pairs to render")
    ap.add_argument("seed", type=int, nargs="?", default=0)
    args = ap.parse_args(argv)
    synthetic_pairs(args.count, args.seed)


if __name__ == "__main__":
    main()
