"""A ``dense-warp-v1`` test model for a fixed homography, built with ``onnx.helper`` (no torch).

The graph stands in for DKM/RoMa in tests of the dense path: for every cell of its output grid
(the input resolution, dynamic or fixed) it returns the position in image B that the homography
``H`` (p2 ~ H p1, in the *original* pixels of two images of sizes ``size_a`` and ``size_b``)
gives, in DKM's normalised coordinates, and a certainty that is 1 inside image B, falls off
linearly to 0 over ``falloff`` (normalised units) at its border, and is 0 outside and where the
point maps behind the homography's line at infinity.

Normalised coordinates (DKM, ``align_corners=False``; docs/matchers.md): pixel x of an image W
wide (centres at integers) is u = (2x + 1)/W - 1, so the network's cell (i, j) of an H' x W' grid
is at u = (2j + 1)/W' - 1 and the warp maps u to pixels of B by x = W_B/2 (u + 1) - 0.5. The graph
applies H_n = N_B H N_A^-1 with N = [[2/W, 0, 1/W - 1], [0, 2/H, 1/H - 1], [0, 0, 1]].

    python -m affcorr.export.dense_test_model OUT.onnx --size-a 800 640 --size-b 800 640 \\
        --homography h11 h12 h13 h21 h22 h23 h31 h32 h33

Without ``--homography`` it uses graffiti's H1to3p (``data/graffiti``) and the graffiti sizes.
The file is a few kB: tests write it to their temporary directory.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .contracts import DENSE_WARP, set_metadata

__all__ = [
    "VARIANTS",
    "dense_homography_model",
    "normalised_homography",
    "pixel_to_normalised",
]

#: Broken variants for the contract checkers' tests: every one is a valid ONNX graph.
VARIANTS: dict[str, str] = {
    "ok": "follows dense-warp-v1",
    "no-certainty": "the certainty output is called 'confidence'",
    "warp-channels": "warp has 3 channels (1, H, W, 3)",
    "gray-input": "image_a is declared (1, 1, H, W)",
    "wrong-contract": "metadata affcorr.contract names features-backbone-v1",
    "no-contract": "no affcorr.contract metadata",
}


def pixel_to_normalised(width: int, height: int) -> np.ndarray:
    """N: pixels (centres at integers) to DKM's normalised coordinates, 3x3."""
    return np.array(
        [[2.0 / width, 0.0, 1.0 / width - 1.0], [0.0, 2.0 / height, 1.0 / height - 1.0], [0, 0, 1]]
    )


def normalised_homography(
    H: np.ndarray,  # noqa: N803 (a homography is a capital)
    size_a: tuple[int, int],
    size_b: tuple[int, int],
) -> np.ndarray:
    """H_n = N_B H N_A^-1: the homography in normalised coordinates (sizes are (W, H))."""
    na = pixel_to_normalised(*size_a)
    nb = pixel_to_normalised(*size_b)
    return nb @ np.asarray(H, dtype=np.float64) @ np.linalg.inv(na)


def dense_homography_model(
    path: str | Path,
    H: np.ndarray,  # noqa: N803
    size_a: tuple[int, int],
    size_b: tuple[int, int],
    *,
    falloff: float = 0.02,
    input_size: tuple[int, int] | None = None,
    metadata: dict[str, Any] | None = None,
    variant: str = "ok",
) -> Path:
    """Writes the model to ``path`` and returns it.

    Args:
        H: (3, 3) homography p2 ~ H p1 between the original images.
        size_a, size_b: (W, H) of the original images A and B.
        falloff: width (normalised units) of the certainty's linear fall to 0 at B's border;
            0 gives a step (1 inside, 0 outside).
        input_size: (H, W) to fix the inputs' spatial axes; ``None``: dynamic.
        metadata: extra or replaced metadata.
        variant: a key of :data:`VARIANTS` (``"ok"``, or a way to break the contract).
    """
    import onnx
    from onnx import TensorProto, helper

    if variant not in VARIANTS:
        raise ValueError(f"variant must be one of {sorted(VARIANTS)}, got {variant!r}")
    f32, i64 = TensorProto.FLOAT, TensorProto.INT64
    hn = normalised_homography(H, size_a, size_b)

    def const(name: str, value: Any, dtype: int) -> onnx.TensorProto:
        arr = np.asarray(value)
        return helper.make_tensor(name, dtype, list(arr.shape), arr.ravel().tolist())

    def node(op: str, ins: list[str], out: str, **kw: Any) -> onnx.NodeProto:
        return helper.make_node(op, ins, [out], **kw)

    nodes = [
        node("Shape", ["image_a"], "shape"),
        node("Gather", ["shape", "i2"], "h", axis=0),
        node("Gather", ["shape", "i3"], "w", axis=0),
        node("Cast", ["h"], "hf", to=f32),
        node("Cast", ["w"], "wf", to=f32),
    ]
    # u = (2k + 1)/n - 1 along each axis: the cell centres of the grid.
    for axis, n in (("x", "wf"), ("y", "hf")):
        nodes += [
            node("Range", ["zero", n, "one"], f"{axis}r"),
            node("Mul", [f"{axis}r", "two"], f"{axis}2"),
            node("Add", [f"{axis}2", "one"], f"{axis}3"),
            node("Div", [f"{axis}3", n], f"{axis}4"),
            node("Sub", [f"{axis}4", "one"], f"{axis}s"),
        ]
    # The contract's 2-channel warp; the "warp-channels" variant appends a third channel.
    warp2 = "warp2" if variant == "warp-channels" else "warp"
    nodes += [
        node("Reshape", ["xs", "row"], "xb"),  # (1, W)
        node("Reshape", ["ys", "col"], "yb"),  # (H, 1)
        node("Mul", ["xb", "zero"], "x0"),
        node("Mul", ["yb", "zero"], "y0"),
        node("Add", ["x0", "y0"], "zeros"),  # (H, W)
        node("Add", ["zeros", "xb"], "ug"),
        node("Add", ["zeros", "yb"], "vg"),
        node("Add", ["zeros", "one"], "ones"),
        node("Unsqueeze", ["ug", "last"], "u1"),
        node("Unsqueeze", ["vg", "last"], "v1"),
        node("Unsqueeze", ["ones", "last"], "o1"),
        node("Concat", ["u1", "v1", "o1"], "grid", axis=2),  # (H, W, 3)
        node("MatMul", ["grid", "hn_t"], "proj"),  # rows times H_n^T
        node("Slice", ["proj", "s0", "s2", "last"], "num"),
        node("Slice", ["proj", "s2", "s3", "last"], "den"),
        node("Div", ["num", "den"], "warp3"),
        node("Unsqueeze", ["warp3", "first"], warp2),  # (1, H, W, 2)
        node("Abs", [warp2], "absw"),
        node("ReduceMax", ["absw"], "m", axes=[3], keepdims=0),  # (1, H, W)
        node("Squeeze", ["den", "last"], "den2"),
        node("Unsqueeze", ["den2", "first"], "den3"),
        node("Greater", ["den3", "zero"], "front_b"),
        node("Cast", ["front_b"], "front", to=f32),
    ]
    if falloff > 0:
        nodes += [
            node("Sub", ["one", "m"], "inside"),
            node("Div", ["inside", "falloff"], "ramp"),
            node("Clip", ["ramp", "zero", "one"], "cin"),
        ]
    else:
        nodes += [
            node("LessOrEqual", ["m", "one"], "cin_b"),
            node("Cast", ["cin_b"], "cin", to=f32),
        ]
    cert_name = "confidence" if variant == "no-certainty" else "certainty"
    nodes.append(node("Mul", ["cin", "front"], cert_name))
    warp_channels = 2
    if variant == "warp-channels":
        nodes += [
            node("Slice", [warp2, "s0", "s1", "last"], "w_extra"),
            node("Concat", [warp2, "w_extra"], "warp", axis=3),
        ]
        warp_channels = 3
    inits = [
        const("i2", 2, i64),
        const("i3", 3, i64),
        const("zero", np.float32(0.0), f32),
        const("one", np.float32(1.0), f32),
        const("two", np.float32(2.0), f32),
        const("falloff", np.float32(max(falloff, 1e-12)), f32),
        const("row", [1, -1], i64),
        const("col", [-1, 1], i64),
        const("last", [-1], i64),
        const("first", [0], i64),
        const("s0", [0], i64),
        const("s1", [1], i64),
        const("s2", [2], i64),
        const("s3", [3], i64),
        const("hn_t", hn.T.astype(np.float32), f32),
    ]
    if falloff <= 0:
        inits = [t for t in inits if t.name != "falloff"]
    hh, ww = input_size if input_size is not None else ("height", "width")
    channels_a = 1 if variant == "gray-input" else 3
    graph = helper.make_graph(
        nodes,
        "dense_homography",
        [
            helper.make_tensor_value_info("image_a", f32, [1, channels_a, hh, ww]),
            helper.make_tensor_value_info("image_b", f32, [1, 3, hh, ww]),
        ],
        [
            helper.make_tensor_value_info("warp", f32, [1, hh, ww, warp_channels]),
            helper.make_tensor_value_info(cert_name, f32, [1, hh, ww]),
        ],
        inits,
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.producer_name = "affcorr"
    model.ir_version = 8
    meta: dict[str, Any] = {
        "affcorr.contract": DENSE_WARP,
        "affcorr.input": "RGB float32 in [0, 1], (1, 3, H, W)",
        "affcorr.warp_align_corners": "false",
        "affcorr.source": (
            "synthetic fixed-homography warp (affcorr.export.dense_test_model), "
            f"size_a {list(size_a)}, size_b {list(size_b)}"
        ),
        "affcorr.homography": np.asarray(H, dtype=np.float64).ravel().tolist(),
    }
    if variant == "wrong-contract":
        meta["affcorr.contract"] = "features-backbone-v1"
    if variant == "no-contract":
        del meta["affcorr.contract"]
    meta.update(metadata or {})
    set_metadata(model, meta)
    onnx.checker.check_model(model)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    onnx.save(model, str(path))
    return path


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("output", type=Path)
    p.add_argument("--homography", type=float, nargs=9, metavar="H", help="row-major H")
    p.add_argument("--size-a", type=int, nargs=2, metavar=("W", "H"), default=None)
    p.add_argument("--size-b", type=int, nargs=2, metavar=("W", "H"), default=None)
    p.add_argument("--falloff", type=float, default=0.02)
    p.add_argument("--input-size", type=int, nargs=2, metavar=("H", "W"), default=None)
    p.add_argument("--variant", choices=sorted(VARIANTS), default="ok")
    p.add_argument(
        "--meta", action="append", default=[], metavar="KEY=VALUE", help="extra metadata"
    )
    args = p.parse_args(argv)
    if args.homography is None:
        from ..data import data_dir, read_opencv_matrix

        H = read_opencv_matrix(data_dir() / "graffiti" / "H1to3p.xml")  # noqa: N806
        size_a = size_b = (800, 640)
    else:
        H = np.array(args.homography).reshape(3, 3)  # noqa: N806
        if args.size_a is None or args.size_b is None:
            p.error("--size-a and --size-b are needed with --homography")
        size_a, size_b = tuple(args.size_a), tuple(args.size_b)
    size_a = tuple(args.size_a or size_a)
    size_b = tuple(args.size_b or size_b)
    out = dense_homography_model(
        args.output,
        H,
        size_a,
        size_b,
        falloff=args.falloff,
        input_size=tuple(args.input_size) if args.input_size else None,
        metadata=dict(m.split("=", 1) for m in args.meta),
        variant=args.variant,
    )
    print(out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
