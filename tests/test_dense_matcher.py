"""The dense-matcher path (dense-warp-v1, docs/design.md §6) with a test model whose warp is
graffiti's
ground-truth homography (affcorr.export.dense_test_model, written to the test's tmp dir).

- The contract checker accepts the model and rejects broken variants.
- The model's warp is H in DKM's normalised coordinates (x = W/2 (u + 1) - 0.5).
- affcorr.Pipeline(dense_model=...): the ACs' points lie on H within 0.5 px (measured 7e-5 px:
  float32), the homography estimated from them has a mean corner error < 0.5 px (measured
  < 1e-3 px), the sampling is seeded, only from confident cells and spread over the overlap.
"""

from __future__ import annotations

import affcorr
import numpy as np
import pytest
from affcorr.data import data_dir, graffiti
from affcorr.metrics import corner_error, transfer

onnx = pytest.importorskip("onnx")
ort = pytest.importorskip("onnxruntime")

from affcorr.export import ContractError, check_model  # noqa: E402
from affcorr.export.dense_test_model import (  # noqa: E402
    VARIANTS,
    dense_homography_model,
    normalised_homography,
)

GRAF = data_dir() / "graffiti"
A_PATH, B_PATH = GRAF / "graf1.png", GRAF / "graf3.png"
W, H = 800, 640


@pytest.fixture(scope="module")
def truth():
    return graffiti()[2]


@pytest.fixture(scope="module")
def model(tmp_path_factory, truth):
    return dense_homography_model(
        tmp_path_factory.mktemp("dense") / "gt.onnx", truth, (W, H), (W, H)
    )


@pytest.fixture(scope="module")
def pipe(model):
    # refine_affine=False: these tests check the matcher's own points.
    return affcorr.Pipeline(dense_model=model, max_matches=400, threads=2, refine_affine=False)


def test_the_contract_accepts_the_model_and_rejects_broken_variants(tmp_path, model, truth):
    info = check_model(model)
    assert info.contract == "dense-warp-v1"
    for variant in VARIANTS:
        if variant == "ok":
            continue
        path = dense_homography_model(
            tmp_path / f"{variant}.onnx", truth, (W, H), (W, H), variant=variant
        )
        with pytest.raises(ContractError):
            check_model(path)
    with pytest.raises(ValueError, match="variant"):
        dense_homography_model(tmp_path / "x.onnx", truth, (W, H), (W, H), variant="nope")


def test_the_warp_is_the_homography_in_dkm_coordinates(model, truth):
    s = ort.InferenceSession(str(model), providers=["CPUExecutionProvider"])
    hh, ww = 48, 60  # any input size: the coordinates are resolution-free
    img = np.zeros((1, 3, hh, ww), np.float32)
    warp, cert = s.run(["warp", "certainty"], {"image_a": img, "image_b": img})
    assert warp.shape == (1, hh, ww, 2) and cert.shape == (1, hh, ww)
    j, i = np.meshgrid(np.arange(ww), np.arange(hh))
    u, v = (2 * j + 1) / ww - 1, (2 * i + 1) / hh - 1  # DKM's linspace(-1 + 1/n, 1 - 1/n, n)
    xa = np.stack([(u + 1) * W / 2 - 0.5, (v + 1) * H / 2 - 0.5], -1).reshape(-1, 2)
    want = transfer(truth, xa)
    got = np.stack([(warp[0, ..., 0] + 1) * W / 2 - 0.5, (warp[0, ..., 1] + 1) * H / 2 - 0.5], -1)
    np.testing.assert_allclose(got.reshape(-1, 2), want, atol=1e-2)
    inside = (np.abs(warp[0]) <= 1).all(-1)
    assert np.all(cert[0][~inside] == 0) and cert[0][inside].max() == 1.0
    # H_n maps DKM's normalised A to normalised B.
    hn = normalised_homography(truth, (W, H), (W, H))
    p = hn @ np.array([u[5, 7], v[5, 7], 1.0])
    np.testing.assert_allclose(p[:2] / p[2], warp[0, 5, 7], atol=1e-5)


def test_the_pipeline_with_the_ground_truth_as_matcher(pipe, truth):
    assert pipe.matcher == "dense"
    assert pipe.matcher_metadata["affcorr.contract"] == "dense-warp-v1"
    assert set(pipe.models) == {"dense", "shape"}
    res = pipe.match_pair(A_PATH, B_PATH)
    assert len(res) == 400 and res.certainty.shape == (400,)
    err = np.linalg.norm(transfer(truth, res.corrs[:, :2]) - res.corrs[:, 2:4], axis=1)
    assert err.max() < 0.5, err.max()
    a = res.corrs[:, 4:].reshape(-1, 2, 2)
    assert np.all(np.linalg.det(a) > 0)
    assert res.timings["matcher"] > 0 and res.timings["detection"] == 0
    # Only confident cells (certainty 0 outside B): every point of B inside the image.
    x2 = res.corrs[:, 2:4]
    assert np.all((x2 > -0.5) & (x2 < [W - 0.5, H - 0.5]))
    assert np.all(res.certainty > 0)
    # Spread over the overlap: most 200x160 blocks of A have matches.
    blocks = {(int(x // 200), int(y // 160)) for x, y in res.corrs[:, :2]}
    assert len(blocks) >= 12, sorted(blocks)

    Hest, info = pipe.homography(A_PATH, B_PATH, threshold=2.0)
    ce = corner_error(Hest, truth, W, H)
    assert ce < 0.5, ce
    assert info.num_inliers > 350


def test_sampling_is_seeded(model, pipe):
    again = pipe.match_pair(A_PATH, B_PATH)
    np.testing.assert_array_equal(again.corrs, pipe.match_pair(A_PATH, B_PATH).corrs)
    other = affcorr.Pipeline(
        dense_model=model, max_matches=400, threads=2, seed=5, refine_affine=False
    )
    assert other.seed == 5
    res = other.match_pair(A_PATH, B_PATH)
    assert not np.array_equal(res.corrs[:, :4], again.corrs[:, :4])


def test_arrays_and_relative_pose(pipe, truth):
    a, b, _ = graffiti()  # gray arrays: the dense model gets R = G = B
    res = pipe.match_pair(a, b)
    err = np.linalg.norm(transfer(truth, res.corrs[:, :2]) - res.corrs[:, 2:4], axis=1)
    assert err.max() < 0.5
    K = np.array([[800.0, 0, 399.5], [0, 800.0, 319.5], [0, 0, 1]])  # noqa: N806
    pose, info = pipe.relative_pose(A_PATH, B_PATH, K, K)
    assert np.allclose(pose.R @ pose.R.T, np.eye(3), atol=1e-9) and info.num_inliers > 0


def test_bad_dense_arguments_are_named(model, tmp_path):
    with pytest.raises(ValueError, match="dense_model"):
        affcorr.Pipeline("dense")
    with pytest.raises(ValueError, match="dense_model"):
        affcorr.Pipeline("xfeat", dense_model=model)
    with pytest.raises(ValueError, match="seed"):
        affcorr.Pipeline(dense_model=model, seed=-1)
    with pytest.raises(FileNotFoundError, match="missing.onnx"):
        affcorr.Pipeline(dense_model=tmp_path / "missing.onnx")
    broken = dense_homography_model(
        tmp_path / "broken.onnx", np.eye(3), (W, H), (W, H), variant="warp-channels"
    )
    with pytest.raises(RuntimeError, match="dense-warp-v1"):
        affcorr.Pipeline(dense_model=broken)


def test_colour_arrays_reach_the_dense_matcher(pipe):
    from PIL import Image

    a = np.asarray(Image.open(A_PATH).convert("RGB"))
    b = np.asarray(Image.open(B_PATH).convert("RGBA"))
    from_files = pipe.match_pair(A_PATH, B_PATH)
    from_arrays = pipe.match_pair(a, b)
    # The test model ignores the pixels: the same cells are drawn; the patches' gray (luma of
    # the same 8-bit samples) gives the same A up to float rounding.
    np.testing.assert_array_equal(from_arrays.corrs[:, :4], from_files.corrs[:, :4])
    np.testing.assert_allclose(from_arrays.corrs[:, 4:], from_files.corrs[:, 4:], atol=1e-4)
    with pytest.raises(ValueError, match="image_a"):
        pipe.match_pair(np.full((64, 80, 3), np.nan, np.float32), b)
