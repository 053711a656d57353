"""Writes the tiny ONNX models the shape-runner tests load (Rust and pytest).

Run from the repository root with the `onnx` package installed:

    .venv/bin/python tests/data/shape/make_fixtures.py

The output is deterministic, so re-running it leaves the committed files unchanged.

`echo.onnx` honours the shape-v1 contract (docs/design.md §6) with 8 angle bins and 5 scale bins;
its outputs are slices of the flattened patches, so a test controls every logit exactly:

    angle_logits_a = patch_a.flat[:, 0:8]     angle_logits_b = patch_b.flat[:, 0:8]
    scale_logits_a = patch_a.flat[:, 8:13]    scale_logits_b = patch_b.flat[:, 8:13]
    residual_shape = patch_a.flat[:, 16:19]

Every other file breaks the contract in one named way.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import onnx
from onnx import TensorProto, helper

HERE = Path(__file__).resolve().parent
ANGLES = [-math.pi + math.pi / 8 + k * math.pi / 4 for k in range(8)]
SCALES = [0.25, 0.5, 1.0, 2.0, 4.0]
SLICES = {
    "angle_logits_a": ("flat_a", 0, 8),
    "angle_logits_b": ("flat_b", 0, 8),
    "scale_logits_a": ("flat_a", 8, 13),
    "scale_logits_b": ("flat_b", 8, 13),
    "residual_shape": ("flat_a", 16, 19),
}


def metadata(**overrides: str | None) -> dict[str, str]:
    meta = {
        "affcorr.contract": "shape-v1",
        "patch_size": "32",
        "angle_bins": json.dumps(ANGLES),
        "scale_bins": json.dumps(SCALES),
        "decode": "softmax-mean",
        "trained": "no (test fixture: outputs are slices of the input patches)",
    }
    for k, v in overrides.items():
        k = k.replace("__", ".")
        if v is None:
            meta.pop(k, None)
        else:
            meta[k] = v
    return meta


def model(
    meta: dict[str, str],
    *,
    inputs=("patch_a", "patch_b"),
    channels: int = 1,
    rename: dict[str, str] | None = None,
    symbolic_widths: bool = False,
    residual_dtype: int = TensorProto.FLOAT,
) -> onnx.ModelProto:
    rename = rename or {}
    nodes = [
        helper.make_node("Flatten", [inputs[0]], ["flat_a"], axis=1),
        helper.make_node("Flatten", [inputs[1]], ["flat_b"], axis=1),
        helper.make_node(
            "Constant", [], ["axes"], value=helper.make_tensor("a", TensorProto.INT64, [1], [1])
        ),
    ]
    if symbolic_widths:
        nodes += [
            helper.make_node("Shape", [inputs[0]], ["shape_a"]),
            helper.make_node("Slice", ["shape_a", "axes", "two", "zero"], ["channels"]),
            helper.make_node(
                "Constant", [], ["two"], value=helper.make_tensor("t", TensorProto.INT64, [1], [2])
            ),
            helper.make_node(
                "Constant", [], ["zero"], value=helper.make_tensor("z", TensorProto.INT64, [1], [0])
            ),
        ]
        # Constants first (topological order).
        nodes = nodes[:3] + nodes[5:] + nodes[3:5]
    outputs = []
    for name, (src, start, end) in SLICES.items():
        out = rename.get(name, name)
        for tag, v in (("s", start), ("e", end)):
            const = f"{name}_{tag}" if tag == "s" or not symbolic_widths else f"{name}_{tag}_c"
            nodes.append(
                helper.make_node(
                    "Constant",
                    [],
                    [const],
                    value=helper.make_tensor(const, TensorProto.INT64, [1], [v]),
                )
            )
        if symbolic_widths:
            # end = c * channels (= c): data-dependent, so no shape inference knows the width.
            nodes.append(helper.make_node("Mul", [f"{name}_e_c", "channels"], [f"{name}_e"]))
        dtype = TensorProto.FLOAT
        sliced = out
        if name == "residual_shape" and residual_dtype != TensorProto.FLOAT:
            sliced = f"{name}_float"
            nodes.append(helper.make_node("Cast", [sliced], [out], to=residual_dtype))
            dtype = residual_dtype
        nodes.insert(
            len(nodes) if sliced == out else len(nodes) - 1,
            helper.make_node("Slice", [src, f"{name}_s", f"{name}_e", "axes"], [sliced]),
        )
        width = f"w_{name}" if symbolic_widths else end - start
        outputs.append(helper.make_tensor_value_info(out, dtype, ["n", width]))
    graph = helper.make_graph(
        nodes,
        "shape_fixture",
        [
            helper.make_tensor_value_info(i, TensorProto.FLOAT, ["n", channels, 32, 32])
            for i in inputs
        ],
        outputs,
    )
    m = helper.make_model(
        graph,
        opset_imports=[helper.make_opsetid("", 13)],
        producer_name="affcorr tests/data/shape/make_fixtures.py",
    )
    m.ir_version = 8
    for k, v in meta.items():
        m.metadata_props.add(key=k, value=v)
    onnx.checker.check_model(m)
    return m


FIXTURES = {
    # Valid.
    "echo.onnx": lambda: model(metadata()),
    "echo_symbolic.onnx": lambda: model(metadata(), symbolic_widths=True),
    # Metadata.
    "no_contract.onnx": lambda: model({}),
    "wrong_contract.onnx": lambda: model(metadata(affcorr__contract="dense-v1")),
    "bad_metadata.onnx": lambda: model(
        metadata(patch_size="64", decode="argmax", angle_bins="not json", scale_bins="[1.0, -2.0]")
    ),
    # Inputs and outputs.
    "wrong_input_name.onnx": lambda: model(metadata(), inputs=("patch", "patch_b")),
    "wrong_input_shape.onnx": lambda: model(metadata(), channels=3),
    "wrong_outputs.onnx": lambda: model(
        metadata(), rename={"residual_shape": "residual", "angle_logits_b": "angle_b"}
    ),
    "wrong_dtype.onnx": lambda: model(metadata(), residual_dtype=TensorProto.DOUBLE),
    # Logit widths that differ from the bin counts: declared, and only visible by running.
    "width_mismatch.onnx": lambda: model(metadata(angle_bins=json.dumps(ANGLES[:7]))),
    "width_mismatch_symbolic.onnx": lambda: model(
        metadata(scale_bins=json.dumps(SCALES + [8.0])), symbolic_widths=True
    ),
}


def main() -> None:
    for name, make in FIXTURES.items():
        (HERE / name).write_bytes(make().SerializeToString(deterministic=True))
        print(f"wrote {HERE / name}")


if __name__ == "__main__":
    main()
