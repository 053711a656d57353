"""The rendered low-texture rooms of affcorr_bench.eval.pose_data (room_pair): a pair agrees with
its ground truth (view 1's depths moved by (R, t) land on view 2's own depths and textures, and
back; the true fundamental matrix vanishes on them), the rolled set is rolled and the upright
one is not, the draws are deterministic, and the rooms are texture-poor next to the
multi-plane scenes rendered with the same textures. The textures are blurred noise (no data
needed)."""

from __future__ import annotations

import numpy as np
import pytest
from affcorr_bench.common import skew
from affcorr_bench.eval import pose_data

W, H = pose_data.SIZE


@pytest.fixture
def noise_textures(monkeypatch):
    pytest.importorskip("torch")
    import torch
    from affcorr.train.views import Texture, _gaussian_blur

    rng = np.random.default_rng(0)
    out = []
    for i, sigma in enumerate((2.0, 4.0)):
        noise = torch.from_numpy(rng.random((1, 1, 400, 400)).astype(np.float32))
        tex = _gaussian_blur(noise, sigma)[0, 0].numpy()
        out.append((f"noise{i}", Texture((tex - tex.min()) / (tex.max() - tex.min()))))
    monkeypatch.setattr(pose_data, "_textures", lambda: out)


def _lift(d, K, depth, R, t, step=7):
    """Pixels of a grid with their depth, moved by X' = R X + t: (pixels (N, 3), X' (N, 3))."""
    ys, xs = np.mgrid[10 : H - 10 : step, 10 : W - 10 : step]
    z = depth[ys, xs].ravel()
    ok = np.isfinite(z)
    p = np.c_[xs.ravel(), ys.ravel(), np.ones(xs.size)][ok]
    return p, (z[ok, None] * p @ np.linalg.inv(K).T) @ R.T + t


def _seen(X, K, depth):
    """Rounded pixels of X (N, 3) in a view, and whether the view's depth there is X's."""
    p = X @ K.T
    c = np.rint(p[:, :2] / p[:, 2:]).astype(int)
    vis = (X[:, 2] > 0) & (c[:, 0] >= 0) & (c[:, 0] < W) & (c[:, 1] >= 0) & (c[:, 1] < H)
    vis[vis] &= np.abs(depth[c[vis, 1], c[vis, 0]] - X[vis, 2]) < 0.01 * X[vis, 2]
    return c, vis


@pytest.mark.parametrize("roll", [pose_data.ROOM_ROLL, pose_data.ROOM_ROLL_ROTATED])
def test_room_pair_agrees_with_its_ground_truth(noise_textures, roll):
    d = pose_data.room_pair(1, seed=5, roll=roll, with_depth=True)
    assert d["img1"].shape == (H, W) and d["img1"].dtype == np.uint8
    R, t = d["R"], d["t"] * d["baseline"]  # metres
    assert np.allclose(R @ R.T, np.eye(3)) and np.linalg.det(R) == pytest.approx(1.0)
    assert 0.3 - 1e-9 <= d["baseline"] <= 1.5 + 1e-9
    assert d["covisible"] >= pose_data.MIN_COVISIBLE
    assert np.isfinite(d["depth1"]).all() and np.isfinite(d["depth2"]).all()  # a closed room
    # the roll about camera 2's optical axis: the angle of camera 1's down axis in image 2
    r = np.degrees(np.arctan2(-R[0, 1], R[1, 1]))
    assert r == pytest.approx(float(d["roll"]), abs=1e-6)
    assert roll[0] <= abs(r) <= roll[1]
    # view 1's pixels lifted with their depth and moved land on view 2's own depths ...
    p1, X2 = _lift(d, d["K1"], d["depth1"], R, t)
    c2, vis = _seen(X2, d["K2"], d["depth2"])
    assert vis.sum() > 0.2 * len(p1)
    # ... and back: view 2's depths at those pixels, moved back, fall on p1 (within rounding)
    q = np.c_[c2[vis], np.ones(vis.sum())]
    X1 = (d["depth2"][c2[vis, 1], c2[vis, 0], None] * q @ np.linalg.inv(d["K2"]).T - t) @ R
    back = X1 @ d["K1"].T
    assert np.median(np.linalg.norm(back[:, :2] / back[:, 2:] - p1[vis, :2], axis=1)) < 1.0
    # the true fundamental matrix vanishes on the exact projections
    F = np.linalg.inv(d["K2"]).T @ skew(d["t"]) @ R @ np.linalg.inv(d["K1"])
    p2 = X2[vis] @ d["K2"].T
    p2 /= p2[:, 2:]
    res = np.abs(np.einsum("ni,ij,nj->n", p2, F, p1[vis]))
    scale = np.linalg.norm(p2, axis=1) * np.linalg.norm(F) * np.linalg.norm(p1[vis], axis=1)
    assert np.max(res / scale) < 1e-6
    # the same texture points show at both ends (low contrast, so a loose threshold)
    a = d["img1"][p1[vis, 1].astype(int), p1[vis, 0].astype(int)].astype(float)
    b = d["img2"][c2[vis, 1], c2[vis, 0]].astype(float)
    assert np.corrcoef(a, b)[0, 1] > 0.8


def test_rooms_are_deterministic_share_the_room_and_are_texture_poor(noise_textures):
    up = pose_data.room_pair(0, seed=2)
    again = pose_data.room_pair(0, seed=2)
    rolled = pose_data.room_pair(0, seed=2, roll=pose_data.ROOM_ROLL_ROTATED)
    assert np.array_equal(up["img1"], again["img1"]) and np.array_equal(up["R"], again["R"])
    assert abs(rolled["roll"]) >= 60 and abs(up["roll"]) <= 10
    # the room, camera 1 and camera 2's centre do not depend on the roll (where the first
    # covisible draw is the same one, as here): C2 = -R^T t
    assert np.array_equal(up["img1"], rolled["img1"])
    assert np.allclose(up["R"].T @ up["t"], rolled["R"].T @ rolled["t"])

    def median_gradient(img):  # on 4 x 4 block means: the pixel noise averaged out
        b = img.astype(float).reshape(H // 4, 4, W // 4, 4).mean(axis=(1, 3))
        return float(np.median(np.hypot(*np.gradient(b))))

    rooms = [median_gradient(pose_data.room_pair(i, seed=2)["img1"]) for i in range(2)]
    scenes = [median_gradient(pose_data.render_pair(i, seed=2)["img1"]) for i in range(2)]
    assert max(rooms) < 0.3 * min(scenes), (rooms, scenes)


def test_matchers_scenes_selects_sets_by_name_and_rejects_unknown_ones(capsys):
    from affcorr_bench import matchers_scenes as ms

    assert ms.selected(["rooms"]) == (ms.ROOMS, ms.ROOMS_ROLLED)
    assert ms.selected(None) == ms.SET_NAMES
    assert set(ms.CASCADE_SETS) <= set(ms.SET_NAMES)
    with pytest.raises(SystemExit):
        ms.main(["--sets", "no such set", "--no-torch"])
    assert "no set matches" in capsys.readouterr().err
