"""The matcher ONNX contracts (docs/design.md §6) and a checker the runner's Python side can share.

Every matcher model carries the custom metadata key ``affcorr.contract``; the runner picks the
code path from it. The contracts (docs/matchers.md has the full text):

``features-backbone-v1``
    input ``image`` float32 (B, C, H, W), C = 1 grayscale in [0, 1] (C = 3: the graph takes the
    channel mean, as upstream XFeat does), H and W multiples of 32; outputs ``feats``
    (B, D, H/8, W/8) dense descriptors (not normalised), ``keypoints`` (B, 65, H/8, W/8)
    keypoint logits (64 cell positions + dustbin), ``heatmap`` (B, 1, H/8, W/8) reliability.
``features-refine-v1``
    input ``pair_feats`` float32 (N, 2D) = [raw descriptor in A, raw descriptor in B] of coarse
    matches; outputs ``logits`` (N, 64) over the 8×8 offset grid, ``offset`` (N, 2) = softmax(T·
    logits) expectation of (col − 4, row − 4) in coarse pixels, ``confidence`` (N,) = max of
    softmax(T·logits).
``matcher-lighterglue-v1``
    inputs ``keypoints0`` (1, M, 2), ``keypoints1`` (1, N, 2) normalised as
    (x − size/2) / (max(W, H)/2) with size = (W, H) of each original image, ``descriptors0``
    (1, M, D), ``descriptors1`` (1, N, D) L2-normalised sparse descriptors; outputs ``scores``
    (1, M, N) log assignment (without dustbins), ``matches0`` (1, M) int64 mutual best match in
    image 1 or −1, ``mscores0`` (1, M) its exp(score) (0 when not mutual); a match is kept when
    ``matches0 ≥ 0`` and ``mscores0 > min_conf``.
``matcher-lightglue-encode-v1``, ``matcher-lightglue-layer-v1``, ``matcher-lightglue-assign-v1``
    LightGlue in pieces for the adaptive layer loop (input projection + positional encoding; one
    transformer layer chosen by the input ``layer`` with its token-confidence and matchability
    heads; the assignment of a layer): :mod:`affcorr.export.lightglue_pieces` and
    docs/matchers.md.
``features-disk-v1``
    input ``image`` float32 (1, 3, H, W) RGB in [0, 1], H and W multiples of 16; outputs
    ``heatmap`` (1, 1, H, W) DISK's detection logits and ``descriptors`` (1, D, H, W) raw dense
    descriptors (:mod:`affcorr.export.lightglue_models`).
``features-aliked-v1``
    input ``image`` float32 (1, 3, H, W) RGB in [0, 1], H and W multiples of 32; outputs
    ``scores`` (1, 1, H, W) ALIKED's score map (sigmoid) and ``features`` (1, D, H, W) its
    L2-normalised feature map (:mod:`affcorr.export.aliked`).
``features-aliked-sddh-v1``
    inputs ``features`` (1, D, H, W) the cropped feature map and ``keypoints`` (N, 2) in
    [−1, 1] (x / (W − 1) · 2 − 1, y likewise); output ``descriptors`` (N, D), ALIKED's SDDH
    head (:mod:`affcorr.export.aliked`).
``dense-warp-v1``
    inputs ``image_a``, ``image_b`` float32 (1, 3, H, W) RGB in [0, 1]; outputs ``warp``
    (1, H', W', 2) position in B of each pixel of A in normalised [−1, 1] coordinates
    (align_corners=False convention unless ``affcorr.warp_align_corners`` says ``true``), and
    ``certainty`` (1, H', W') in [0, 1].

:func:`check_model` needs only onnxruntime (a runtime dependency); :func:`identity_warp_model`
and :func:`set_metadata` need ``onnx``. This module never imports torch.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

BACKBONE = "features-backbone-v1"
REFINE = "features-refine-v1"
LIGHTERGLUE = "matcher-lighterglue-v1"
GLUE_ENCODE = "matcher-lightglue-encode-v1"
GLUE_LAYER = "matcher-lightglue-layer-v1"
GLUE_ASSIGN = "matcher-lightglue-assign-v1"
DENSE_WARP = "dense-warp-v1"
DISK_BACKBONE = "features-disk-v1"
ALIKED_BACKBONE = "features-aliked-v1"
ALIKED_SDDH = "features-aliked-sddh-v1"

_GLUE_META = [
    "affcorr.descriptor_dim",
    "affcorr.embedding_dim",
    "affcorr.heads",
    "affcorr.head_dim",
    "affcorr.layers",
]

# name -> (inputs, outputs, required metadata keys besides affcorr.contract); each input/output is
# (name, rank, {axis: fixed size}).
CONTRACTS: dict[str, dict[str, Any]] = {
    BACKBONE: {
        "inputs": [("image", 4, {})],
        "outputs": [("feats", 4, {}), ("keypoints", 4, {1: 65}), ("heatmap", 4, {1: 1})],
        "metadata": [
            "affcorr.input",
            "affcorr.input_multiple",
            "affcorr.stride",
            "affcorr.descriptor_dim",
            "affcorr.detection.nms_size",
            "affcorr.detection.threshold",
            "affcorr.detection.top_k",
            "affcorr.sampling",
            "affcorr.semidense.scales",
            "affcorr.semidense.split",
        ],
    },
    REFINE: {
        "inputs": [("pair_feats", 2, {})],
        "outputs": [("logits", 2, {1: 64}), ("offset", 2, {1: 2}), ("confidence", 1, {})],
        "metadata": [
            "affcorr.descriptor_dim",
            "affcorr.refine.grid",
            "affcorr.refine.temperature",
            "affcorr.refine.confidence",
        ],
    },
    LIGHTERGLUE: {
        "inputs": [
            ("keypoints0", 3, {0: 1, 2: 2}),
            ("keypoints1", 3, {0: 1, 2: 2}),
            ("descriptors0", 3, {0: 1}),
            ("descriptors1", 3, {0: 1}),
        ],
        "outputs": [("scores", 3, {0: 1}), ("matches0", 2, {0: 1}), ("mscores0", 2, {0: 1})],
        "metadata": [
            "affcorr.descriptor_dim",
            "affcorr.keypoint_normalisation",
            "affcorr.min_conf",
        ],
    },
    GLUE_ENCODE: {
        "inputs": [("keypoints", 3, {0: 1, 2: 2}), ("descriptors", 3, {0: 1})],
        "outputs": [("desc", 3, {0: 1}), ("cos", 3, {0: 1}), ("sin", 3, {0: 1})],
        "metadata": [*_GLUE_META, "affcorr.keypoint_normalisation"],
    },
    GLUE_LAYER: {
        "inputs": [
            ("layer", 1, {0: 1}),
            ("desc0", 3, {0: 1}),
            ("desc1", 3, {0: 1}),
            ("cos0", 3, {0: 1}),
            ("sin0", 3, {0: 1}),
            ("cos1", 3, {0: 1}),
            ("sin1", 3, {0: 1}),
        ],
        "outputs": [
            ("desc0_out", 3, {0: 1}),
            ("desc1_out", 3, {0: 1}),
            ("token0", 2, {0: 1}),
            ("token1", 2, {0: 1}),
            ("match0", 2, {0: 1}),
            ("match1", 2, {0: 1}),
        ],
        "metadata": [
            *_GLUE_META,
            "affcorr.min_conf",
            "affcorr.glue.width_confidence",
            "affcorr.glue.depth_confidence",
            "affcorr.glue.confidence_thresholds",
        ],
    },
    GLUE_ASSIGN: {
        "inputs": [("layer", 1, {0: 1}), ("desc0", 3, {0: 1}), ("desc1", 3, {0: 1})],
        "outputs": [("matches0", 2, {0: 1}), ("mscores0", 2, {0: 1})],
        "metadata": _GLUE_META,
    },
    DISK_BACKBONE: {
        "inputs": [("image", 4, {0: 1, 1: 3})],
        "outputs": [("heatmap", 4, {0: 1, 1: 1}), ("descriptors", 4, {0: 1})],
        "metadata": [
            "affcorr.input_multiple",
            "affcorr.descriptor_dim",
            "affcorr.detection.nms_size",
            "affcorr.detection.threshold",
            "affcorr.detection.top_k",
        ],
    },
    ALIKED_BACKBONE: {
        "inputs": [("image", 4, {0: 1, 1: 3})],
        "outputs": [("scores", 4, {0: 1, 1: 1}), ("features", 4, {0: 1})],
        "metadata": [
            "affcorr.input_multiple",
            "affcorr.descriptor_dim",
            "affcorr.detection.nms_radius",
            "affcorr.detection.threshold",
            "affcorr.detection.temperature",
            "affcorr.detection.top_k",
        ],
    },
    ALIKED_SDDH: {
        "inputs": [("features", 4, {0: 1}), ("keypoints", 2, {1: 2})],
        "outputs": [("descriptors", 2, {})],
        "metadata": ["affcorr.descriptor_dim"],
    },
    DENSE_WARP: {
        "inputs": [("image_a", 4, {0: 1, 1: 3}), ("image_b", 4, {0: 1, 1: 3})],
        "outputs": [("warp", 4, {0: 1, 3: 2}), ("certainty", 3, {0: 1})],
        "metadata": [],
    },
}


class ContractError(ValueError):
    """A model does not follow the contract its metadata names."""


@dataclass
class ContractInfo:
    """What :func:`check_model` found: the contract and all ``affcorr.*`` metadata."""

    contract: str
    metadata: dict[str, str] = field(default_factory=dict)

    def get(self, key: str, default: Any = None) -> Any:
        """A metadata value parsed as JSON when it is JSON, else the raw string."""
        v = self.metadata.get(key)
        if v is None:
            return default
        try:
            return json.loads(v)
        except ValueError:
            return v


def _dims(value_info) -> list[int | str | None]:
    out: list[int | str | None] = []
    for d in value_info.type.tensor_type.shape.dim:
        if d.HasField("dim_value"):
            out.append(int(d.dim_value))
        elif d.HasField("dim_param"):
            out.append(d.dim_param)
        else:
            out.append(None)
    return out


def _describe(model) -> tuple[dict, dict, dict]:
    """(inputs, outputs, metadata) of a path (read with ``onnx`` when it is installed, else
    with onnxruntime, a runtime dependency), an ``onnxruntime.InferenceSession`` or an
    ``onnx.ModelProto``; inputs and outputs map names to dims."""
    if isinstance(model, (str, Path)):
        try:  # fast: no graph optimisation
            import onnx

            model = onnx.load(str(model), load_external_data=False)
        except ImportError:
            import onnxruntime as ort

            model = ort.InferenceSession(str(model), providers=["CPUExecutionProvider"])
    if hasattr(model, "get_modelmeta"):
        meta = dict(model.get_modelmeta().custom_metadata_map)
        ins = {v.name: list(v.shape) for v in model.get_inputs()}
        outs = {v.name: list(v.shape) for v in model.get_outputs()}
        return ins, outs, meta
    meta = {p.key: p.value for p in model.metadata_props}
    inits = {i.name for i in model.graph.initializer}
    ins = {v.name: _dims(v) for v in model.graph.input if v.name not in inits}
    outs = {v.name: _dims(v) for v in model.graph.output}
    return ins, outs, meta


def check_model(model) -> ContractInfo:
    """Checks a matcher model (a path, an ``onnxruntime.InferenceSession`` or an
    ``onnx.ModelProto``) against the contract its ``affcorr.contract`` metadata names:
    input/output names, ranks, fixed axes and required metadata keys. Raises
    :class:`ContractError` listing every problem found."""
    graph_in, graph_out, meta = _describe(model)
    name = meta.get("affcorr.contract")
    if name is None:
        raise ContractError("no 'affcorr.contract' metadata: not an affcorr matcher model")
    if name not in CONTRACTS:
        raise ContractError(f"unknown contract {name!r} (known: {sorted(CONTRACTS)})")
    spec = CONTRACTS[name]
    problems: list[str] = []
    for kind, table, wanted in (
        ("input", graph_in, spec["inputs"]),
        ("output", graph_out, spec["outputs"]),
    ):
        for vname, rank, fixed in wanted:
            if vname not in table:
                problems.append(f"{kind} {vname!r} missing (has {sorted(table)})")
                continue
            dims = table[vname]
            if len(dims) != rank:
                problems.append(f"{kind} {vname!r} has rank {len(dims)}, contract says {rank}")
                continue
            for axis, size in fixed.items():
                if isinstance(dims[axis], int) and dims[axis] != size:
                    problems.append(f"{kind} {vname!r} axis {axis} is {dims[axis]}, not {size}")
    for key in spec["metadata"]:
        if key not in meta:
            problems.append(f"metadata {key!r} missing")
    if problems:
        raise ContractError(f"{name}: " + "; ".join(problems))
    return ContractInfo(name, {k: v for k, v in meta.items() if k.startswith("affcorr.")})


def set_metadata(model, meta: dict[str, Any]) -> None:
    """Writes ``meta`` into ``model.metadata_props`` (values that are not strings as JSON),
    replacing existing keys."""
    keep = [(p.key, p.value) for p in model.metadata_props if p.key not in meta]
    del model.metadata_props[:]
    for k, v in keep:
        entry = model.metadata_props.add()
        entry.key, entry.value = k, v
    for k, v in meta.items():
        entry = model.metadata_props.add()
        entry.key, entry.value = k, v if isinstance(v, str) else json.dumps(v)


def identity_warp_model(path: Path | str, size: tuple[int, int] = (64, 80)) -> Path:
    """A tiny ``dense-warp-v1`` model built with ``onnx.helper`` (no torch): the identity warp
    at the input resolution (dynamic H, W) with certainty 1, for tests of the dense path.

    ``warp[0, i, j] = ((2j + 1)/W − 1, (2i + 1)/H − 1)`` (pixel centres, align_corners=False).
    ``size`` is only the nominal (H, W) recorded in the metadata."""
    import numpy as np
    import onnx
    from onnx import TensorProto, helper

    f32 = TensorProto.FLOAT
    i64 = TensorProto.INT64
    const = lambda name, arr, dt: helper.make_tensor(  # noqa: E731
        name, dt, list(np.shape(arr)), np.asarray(arr).ravel().tolist()
    )
    nodes = [
        helper.make_node("Shape", ["image_a"], ["shape"]),
        helper.make_node("Gather", ["shape", "i2"], ["h"], axis=0),
        helper.make_node("Gather", ["shape", "i3"], ["w"], axis=0),
        helper.make_node("Cast", ["h"], ["hf"], to=f32),
        helper.make_node("Cast", ["w"], ["wf"], to=f32),
        # x = (2 * arange(w) + 1) / w - 1
        helper.make_node("Range", ["zero_f", "wf", "one_f"], ["xr"]),
        helper.make_node("Range", ["zero_f", "hf", "one_f"], ["yr"]),
        helper.make_node("Mul", ["xr", "two_f"], ["x2"]),
        helper.make_node("Add", ["x2", "one_f"], ["x3"]),
        helper.make_node("Div", ["x3", "wf"], ["x4"]),
        helper.make_node("Sub", ["x4", "one_f"], ["xs"]),
        helper.make_node("Mul", ["yr", "two_f"], ["y2"]),
        helper.make_node("Add", ["y2", "one_f"], ["y3"]),
        helper.make_node("Div", ["y3", "hf"], ["y4"]),
        helper.make_node("Sub", ["y4", "one_f"], ["ys"]),
        # broadcast to (1, H, W, 1) each
        helper.make_node("Reshape", ["xs", "shape_x"], ["xb"]),  # (1, 1, W, 1)
        helper.make_node("Reshape", ["ys", "shape_y"], ["yb"]),  # (1, H, 1, 1)
        helper.make_node("Add", ["xb", "yb"], ["xy0"]),  # (1, H, W, 1) (value unused)
        helper.make_node("Mul", ["xy0", "zero_f"], ["zeros"]),
        helper.make_node("Add", ["zeros", "xb"], ["xg"]),
        helper.make_node("Add", ["zeros", "yb"], ["yg"]),
        helper.make_node("Concat", ["xg", "yg"], ["warp"], axis=3),
        helper.make_node("Squeeze", ["zeros", "i3_1d"], ["zeros3"]),
        helper.make_node("Add", ["zeros3", "one_f"], ["certainty"]),
    ]
    inits = [
        const("i2", 2, i64),
        const("i3", 3, i64),
        const("i3_1d", [3], i64),
        const("zero_f", 0.0, f32),
        const("one_f", 1.0, f32),
        const("two_f", 2.0, f32),
        const("shape_x", [1, 1, -1, 1], i64),
        const("shape_y", [1, -1, 1, 1], i64),
    ]
    img = lambda n: helper.make_tensor_value_info(n, f32, [1, 3, "height", "width"])  # noqa: E731
    graph = helper.make_graph(
        nodes,
        "identity_warp",
        [img("image_a"), img("image_b")],
        [
            helper.make_tensor_value_info("warp", f32, [1, "height", "width", 2]),
            helper.make_tensor_value_info("certainty", f32, [1, "height", "width"]),
        ],
        inits,
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.producer_name = "affcorr"
    model.ir_version = 8
    set_metadata(
        model,
        {
            "affcorr.contract": DENSE_WARP,
            "affcorr.input": "RGB float32 in [0, 1], (1, 3, H, W)",
            "affcorr.warp_align_corners": "false",
            "affcorr.nominal_size": list(size),
            "affcorr.source": "synthetic identity warp (affcorr.export.contracts)",
        },
    )
    onnx.checker.check_model(model)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    onnx.save(model, str(path))
    return path
