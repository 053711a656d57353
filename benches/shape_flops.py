"""FLOPs per patch pair of the shape network (multiply-adds x 2), counted with forward hooks on
the torch module that the ONNX model is exported from, for each architecture (or the named ones).

    .venv/bin/python benches/shape_flops.py [ARCH ...]
"""

from __future__ import annotations

import sys
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "python"))
from affcorr.train.shape_net import ARCHITECTURES, ShapeNet  # noqa: E402


def count_macs(net: torch.nn.Module, n: int = 1) -> int:
    macs = 0

    def hook(module, inputs, output):
        nonlocal macs
        if isinstance(module, torch.nn.Conv2d):
            k = module.kernel_size[0] * module.kernel_size[1] * module.in_channels // module.groups
            macs += output.numel() * k
        elif isinstance(module, torch.nn.Linear):
            macs += output.numel() * module.in_features

    hooks = [
        m.register_forward_hook(hook)
        for m in net.modules()
        if isinstance(m, (torch.nn.Conv2d, torch.nn.Linear))
    ]
    with torch.no_grad():
        x = torch.rand(n, 1, 32, 32)
        net.eval()(x, x)
    for h in hooks:
        h.remove()
    return macs // n


if __name__ == "__main__":
    for name in sys.argv[1:] or ARCHITECTURES:
        net = ShapeNet(name)
        macs = count_macs(net, 2)
        params = sum(p.numel() for p in net.parameters())
        print(
            f"{name}: {params} parameters, {macs / 1e6:.2f} M multiply-adds per patch pair "
            f"({2 * macs / 1e6:.2f} MFLOP)"
        )
