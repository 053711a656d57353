"""The shape network's training pieces: exact ground truth of the synthetic views, the
covariance loss's shift, torch synthesis vs the Rust one, and the ONNX export contract."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

torch = pytest.importorskip("torch")

import affcorr  # noqa: E402
from affcorr.train import views  # noqa: E402
from affcorr.train.shape import shift_distribution  # noqa: E402
from affcorr.train.shape_net import (  # noqa: E402
    ANGLE_BINS,
    ARCHITECTURES,
    SCALE_BINS,
    ShapeNet,
    angle_bin_centres,
    decode_orientation,
    decode_scale,
    scale_bin_centres,
    similarity_to_frame_a,
    synthesize_torch,
)


def smooth_texture(seed=0, h=400, w=500):
    rng = np.random.default_rng(seed)
    img = torch.from_numpy(rng.random((1, 1, h // 8, w // 8)).astype(np.float32))
    img = torch.nn.functional.interpolate(img, size=(h, w), mode="bicubic", align_corners=False)
    return img[0, 0].clamp(0, 1).numpy()


@pytest.fixture(scope="module")
def texture():
    return views.Texture(smooth_texture())


def numeric_jacobian(H, x, h=1e-4):
    cols = []
    for d in (np.array([h, 0.0]), np.array([0.0, h])):
        cols.append((views._apply(H, x + d) - views._apply(H, x - d)) / (2 * h))
    return np.stack(cols, -1)


def test_plane_pairs_have_exact_ground_truth(texture):
    rng = np.random.default_rng(1)
    pp = None
    while pp is None:
        pp = views.plane_pairs(rng, texture, 50)
    c = pp.corrs
    assert pp.patch_a.shape == (len(c), 32, 32) and pp.patch_a.dtype == np.float32
    np.testing.assert_allclose(views._apply(pp.H, c[:, :2]), c[:, 2:4], atol=1e-8)
    np.testing.assert_allclose(numeric_jacobian(pp.H, c[:, :2]).reshape(-1, 4), c[:, 4:], atol=1e-6)
    # F and H come from the same cameras: every AC satisfies both epipolar constraints.
    assert affcorr.sampson_point(pp.F, c).max() < 1e-16
    assert affcorr.sampson_affine(pp.F, c).max() < 1e-16


def test_plane_pair_patches_show_the_same_surface(texture):
    """Patch B resampled by the ground-truth A around its centre matches patch A."""
    rng = np.random.default_rng(2)
    pp = None
    while pp is None:
        pp = views.plane_pairs(rng, texture, 40, max_tilt_deg=30)
    A = pp.corrs[:, 4:].reshape(-1, 2, 2)
    # Read patch B at A u for the patch offsets u of patch A (central 16x16 stays inside).
    u = np.arange(32) - 15.5
    uu = np.stack(np.meshgrid(u, u, indexing="xy"), -1)[8:24, 8:24]
    diffs = []
    for k in range(len(A)):
        q = uu @ A[k].T + 15.5
        b = torch.from_numpy(pp.patch_b[k])[None, None]
        g = torch.from_numpy(q / 31.0 * 2 - 1).float()[None]
        rb = torch.nn.functional.grid_sample(b, g, align_corners=True)[0, 0].numpy()
        a = pp.patch_a[k, 8:24, 8:24]
        za, zb = (a - a.mean()) / (a.std() + 1e-6), (rb - rb.mean()) / (rb.std() + 1e-6)
        diffs.append(np.mean(za * zb))
    assert np.median(diffs) > 0.9  # normalised cross-correlation


def _back_rotated_correlation(sp, sign=1.0):
    """Median correlation of patch A's centre with patch B rotated back by sign × the label."""
    ok = (sp.patch_a.std((1, 2)) > 0.02) & (sp.scale < 1.5)
    pb = torch.from_numpy(sp.patch_b[ok])[:, None]
    ang = sign * torch.from_numpy(sp.angle[ok]).float()
    s = torch.from_numpy(sp.scale[ok]).float()
    back = similarity_to_frame_a(pb, torch.cos(ang), torch.sin(ang), s)[:, 0, 10:22, 10:22]
    a = torch.from_numpy(sp.patch_a[ok])[:, 10:22, 10:22]
    za = (a - a.mean((1, 2), keepdim=True)) / a.std((1, 2), keepdim=True)
    zb = (back - back.mean((1, 2), keepdim=True)) / back.std((1, 2), keepdim=True)
    return float((za * zb).mean((1, 2)).median())


def test_similarity_pairs_labels(texture):
    sp = views.similarity_pairs(np.random.default_rng(3), texture, 64, shear=0.0)
    # Rotating patch B back by the label recovers patch A (content magnified by `scale`).
    assert _back_rotated_correlation(sp) > 0.8
    assert _back_rotated_correlation(sp, sign=-1.0) < 0.5


def test_similarity_pairs_centre_jitter_moves_patch_b_only(texture):
    exact = views.similarity_pairs(np.random.default_rng(3), texture, 64, shear=0.0)
    moved = views.similarity_pairs(
        np.random.default_rng(3), texture, 64, shear=0.0, centre_jitter=3.0
    )
    # Same labels (drawn before the jitter), content of B off-centre by ~3 px.
    np.testing.assert_array_equal(exact.angle, moved.angle)
    np.testing.assert_array_equal(exact.scale, moved.scale)
    assert _back_rotated_correlation(exact) > 0.8
    assert _back_rotated_correlation(moved) < _back_rotated_correlation(exact) - 0.1


def test_shift_distribution():
    p = torch.zeros(2, 10, dtype=torch.float64)
    p[:, 2] = 1.0
    q = shift_distribution(p, torch.tensor([3.0, -3.0], dtype=torch.float64), circular=True)
    assert q[0, 5] == 1.0 and q[1, 9] == 1.0
    q = shift_distribution(p, torch.tensor([0.25, 1.5], dtype=torch.float64), circular=False)
    np.testing.assert_allclose(q[0, 2:4].numpy(), [0.75, 0.25])
    np.testing.assert_allclose(q[1, 3:5].numpy(), [0.5, 0.5])
    q = shift_distribution(p, torch.tensor([-2.5, 0.0], dtype=torch.float64), circular=False)
    np.testing.assert_allclose(q[0].sum().numpy(), 0.5)  # half the mass fell off the end


def test_decoders_on_one_hot_logits():
    c = angle_bin_centres()
    logits = torch.full((2, ANGLE_BINS), -50.0, dtype=torch.float64)
    logits[0, 3], logits[1, 60] = 50.0, 50.0
    np.testing.assert_allclose(decode_orientation(logits).numpy(), [c[3], c[60]], atol=1e-9)
    s = scale_bin_centres()
    logits = torch.full((1, SCALE_BINS), -50.0, dtype=torch.float64)
    logits[0, 20] = 50.0
    np.testing.assert_allclose(decode_scale(logits).numpy(), [s[20]], rtol=1e-9)


def test_synthesize_torch_matches_rust():
    rng = np.random.default_rng(4)
    o = rng.uniform(-math.pi, math.pi, 20)
    s = rng.uniform(0.3, 3, 20)
    r = np.column_stack(
        [rng.uniform(-0.5, 0.5, 20), rng.normal(0, 0.5, 20), rng.uniform(-0.5, 0.5, 20)]
    )
    got = synthesize_torch(torch.from_numpy(o), torch.from_numpy(s), torch.from_numpy(r))
    np.testing.assert_allclose(got.numpy(), affcorr.synthesize_affine(o, s, r), atol=1e-12)


@pytest.mark.parametrize("arch", list(ARCHITECTURES))
def test_onnx_export_contract_and_parity(tmp_path, arch):
    pytest.importorskip("onnx")
    ort = pytest.importorskip("onnxruntime")
    from affcorr.train.export import OUTPUT_NAMES, export

    torch.manual_seed(0)
    net = ShapeNet(arch).eval()
    path = export(net, tmp_path / "shape.onnx", {"architecture": arch})
    sess = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    assert [i.name for i in sess.get_inputs()] == ["patch_a", "patch_b"]
    assert [o.name for o in sess.get_outputs()] == OUTPUT_NAMES
    meta = sess.get_modelmeta().custom_metadata_map
    assert meta["affcorr.contract"] == "shape-v1" and meta["decode"] == "softmax-mean"
    assert meta["architecture"] == arch
    np.testing.assert_allclose(json.loads(meta["angle_bins"]), angle_bin_centres().numpy())
    np.testing.assert_allclose(json.loads(meta["scale_bins"]), scale_bin_centres().numpy())
    rng = np.random.default_rng(5)
    pa = rng.random((7, 1, 32, 32)).astype(np.float32)
    pb = rng.random((7, 1, 32, 32)).astype(np.float32)
    got = sess.run(None, {"patch_a": pa, "patch_b": pb})
    with torch.no_grad():
        want = net(torch.from_numpy(pa), torch.from_numpy(pb))
    for g, w in zip(got, want):
        np.testing.assert_allclose(g, w.numpy(), atol=2e-4)
    assert got[4].shape == (7, 3) and np.all(got[4][:, [0, 2]] > -1)


def test_checkpoints_record_their_architecture(tmp_path):
    from affcorr.train.export import load_trained
    from affcorr.train.shape import _load, _save, checkpoint_architecture

    torch.manual_seed(1)
    net = ShapeNet("fast")
    for key, m, file in (("os", net.os, "os.pt"), ("aff", net.aff, "aff_both.pt")):
        _save(tmp_path / file, {key: m}, torch.optim.SGD(m.parameters(), lr=0.1), 3)
    assert checkpoint_architecture(tmp_path / "os.pt") == "fast"
    assert checkpoint_architecture(tmp_path / "missing.pt") is None
    loaded = load_trained(tmp_path, "both")
    assert loaded.arch.name == "fast"
    x = torch.rand(3, 1, 32, 32)
    with torch.no_grad():
        for g, w in zip(loaded(x, x.flip(-1)), net.eval()(x, x.flip(-1))):
            torch.testing.assert_close(g, w)
    # Loading into another architecture names the one the file holds.
    with pytest.raises(SystemExit, match="holds a 'fast' network, not 'v1': pass --arch fast"):
        _load(tmp_path / "os.pt", {"os": ShapeNet("v1").os}, None)


def test_unknown_architecture_is_named():
    with pytest.raises(ValueError, match="architecture: unknown 'huge'; known: v1, fast"):
        ShapeNet("huge")
