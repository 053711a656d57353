"""Export the trained shape network to ONNX with the contract of docs/design.md §6.

    python -m affcorr.train.export --workdir DIR --loss laff -o models/shape.onnx

Contract (``affcorr.contract = shape-v1`` in the metadata):
- inputs ``patch_a``, ``patch_b``: float32 (N, 1, 32, 32), grayscale in [0, 1], pixel (r, c)
  read bilinearly at ``x + (c - 15.5, r - 15.5)``; the graph normalises each patch itself;
- outputs ``angle_logits_a``, ``angle_logits_b`` (N, K_theta), ``scale_logits_a``,
  ``scale_logits_b`` (N, K_s), ``residual_shape`` (N, 3) = A'' (docs/design.md §2);
- metadata ``angle_bins`` (radians) and ``scale_bins`` (linear factors) as JSON lists, and
  ``decode`` = ``softmax-mean``: O = atan2(sum p sin c, sum p cos c), S = exp(sum p log s),
  then O_AB = O_B - O_A, S_AB = S_B / S_A, A = S_AB R(O_AB) A'(A'').
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import torch

from .shape import _load, checkpoint_architecture
from .shape_net import (
    ARCHITECTURES,
    DEFAULT_ARCHITECTURE,
    PATCH_SIZE,
    ShapeNet,
    angle_bin_centres,
    scale_bin_centres,
)

CONTRACT = "shape-v1"
OUTPUT_NAMES = [
    "angle_logits_a",
    "angle_logits_b",
    "scale_logits_a",
    "scale_logits_b",
    "residual_shape",
]


def metadata(extra: dict[str, str] | None = None) -> dict[str, str]:
    """The custom metadata every shape model carries."""
    meta = {
        "affcorr.contract": CONTRACT,
        "patch_size": str(PATCH_SIZE),
        "input": "grayscale float32 in [0, 1]; the model normalises each patch",
        "angle_bins": json.dumps([float(c) for c in angle_bin_centres()]),
        "scale_bins": json.dumps([float(c) for c in scale_bin_centres()]),
        "decode": "softmax-mean",
    }
    meta.update(extra or {})
    return meta


def export(net: ShapeNet, out: Path, extra_metadata: dict[str, str] | None = None) -> Path:
    """Write ``net`` to ``out`` (opset 16: GridSample) with dynamic N and the metadata."""
    import onnx

    net.eval()
    x = torch.rand(4, 1, PATCH_SIZE, PATCH_SIZE)
    out.parent.mkdir(parents=True, exist_ok=True)
    torch.onnx.export(
        net,
        (x, x.flip(-1)),
        str(out),
        opset_version=16,
        input_names=["patch_a", "patch_b"],
        output_names=OUTPUT_NAMES,
        dynamic_axes={name: {0: "n"} for name in ["patch_a", "patch_b", *OUTPUT_NAMES]},
    )
    model = onnx.load(str(out))
    for k, v in metadata(extra_metadata).items():
        entry = model.metadata_props.add()
        entry.key, entry.value = k, v
    model.producer_name = "affcorr"
    onnx.save(model, str(out))
    return out


def load_trained(workdir: Path, loss: str) -> ShapeNet:
    """E_os from ``workdir/os.pt`` and E_aff from ``workdir/aff_<loss>.pt`` in one module, in
    the architecture the checkpoints record."""
    arch = checkpoint_architecture(workdir / "os.pt")
    if arch is None:
        raise SystemExit(f"{workdir / 'os.pt'} is missing: train the 'os' stage first")
    net = ShapeNet(arch)
    if _load(workdir / "os.pt", {"os": net.os}, None) == 0:
        raise SystemExit(f"{workdir / 'os.pt'} is missing: train the 'os' stage first")
    if loss != "none" and _load(workdir / f"aff_{loss}.pt", {"aff": net.aff}, None) == 0:
        raise SystemExit(f"{workdir / f'aff_{loss}.pt'} is missing: train the 'aff' stage")
    return net.eval()


def main(argv=None) -> None:
    p = argparse.ArgumentParser(
        prog="python -m affcorr.train.export",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--workdir", type=Path, help="training directory (omit: untrained weights)")
    p.add_argument(
        "--loss",
        default="laff",
        choices=["laff", "direct", "both", "none"],
        help="which E_aff to ship; 'none' keeps A'' = 0 (similarity only)",
    )
    p.add_argument("-o", "--output", type=Path, required=True)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument(
        "--arch",
        choices=list(ARCHITECTURES),
        default=DEFAULT_ARCHITECTURE,
        help="architecture of the untrained network (without --workdir)",
    )
    args = p.parse_args(argv)
    if args.workdir is None:
        torch.manual_seed(args.seed)
        net, extra = ShapeNet(args.arch).eval(), {"trained": "no (random weights, for tests)"}
    else:
        net = load_trained(args.workdir, args.loss)
        extra = {"trained": f"E_aff loss {args.loss}"}
    extra["architecture"] = net.arch.name
    print(f"wrote {export(net, args.output, extra)}")


if __name__ == "__main__":
    main()
