"""FLOPs per patch pair of the shape network (multiply-adds x 2), counted with forward hooks on
the torch module that the ONNX model is exported from, for each architecture (or the named ones).

    .venv/bin/python -m affcorr_bench.shape_flops [ARCH ...]
"""

from __future__ import annotations

import argparse


def count_macs(net, n: int = 1) -> int:
    """Multiply-adds per sample of the torch module ``net`` on (n, 1, 32, 32) patch pairs."""
    import torch

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


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("arch", nargs="*", help="architectures (default: all; needs torch)")
    args = ap.parse_args(argv)
    from affcorr.train.shape_net import ARCHITECTURES, ShapeNet

    for name in args.arch or ARCHITECTURES:
        net = ShapeNet(name)
        macs = count_macs(net, 2)
        params = sum(p.numel() for p in net.parameters())
        print(
            f"{name}: {params} parameters, {macs / 1e6:.2f} M multiply-adds per patch pair "
            f"({2 * macs / 1e6:.2f} MFLOP)"
        )


if __name__ == "__main__":
    main()
