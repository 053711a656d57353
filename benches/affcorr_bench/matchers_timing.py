"""Milliseconds per VGA image for the exported XFeat models: onnxruntime (2 threads) vs torch.

    .venv/bin/python -m affcorr_bench.matchers_timing [--repeats 5] [--no-torch]

The image is a 640×480 crop of graffiti 1 (and the same crop of graffiti 3 for matching).
Stages: backbone (ORT vs torch ``XFeatModel``), XFeat*'s two scales (0.6, 1.3) through the
backbone, the refinement MLP, the numpy reference post-processing (Python; the Rust runner
replaces it), and LighterGlue at 1024 / 2048 keypoints per image (ORT vs upstream kornia
``LightGlue``). Writes benches/results/matchers_timing.md. Medians of ``--repeats`` runs.
"""

from __future__ import annotations

import argparse
import os
import time
import warnings
from pathlib import Path

import numpy as np
from affcorr.data import graffiti
from affcorr.export import xfeat_reference as R

from . import common

OUT = common.RESULTS / "matchers_timing.md"


def median_ms(fn, repeats: int) -> float:
    fn()  # warm-up
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1e3 * float(np.median(times))


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--no-torch", action="store_true")
    p.add_argument("--threads", type=int, default=2, help="ORT intra-op and torch threads")
    p.add_argument("--models", type=Path, default=None)
    p.add_argument("-o", "--output", type=Path, default=OUT)
    args = p.parse_args(argv)
    warnings.filterwarnings("ignore")
    a, b, _ = graffiti()
    a = np.ascontiguousarray(a[80:560, 80:720], np.float32)
    b = np.ascontiguousarray(b[80:560, 80:720], np.float32)
    pipe = R.XFeatOnnx(args.models, threads=args.threads)
    n = args.repeats
    rows: list[tuple[str, float, float | None]] = []

    torch = None
    if not args.no_torch:
        try:
            import torch
            from affcorr.export.xfeat import Refine, load_upstream

            torch.set_num_threads(args.threads)
            torch.set_grad_enabled(False)
            xf = load_upstream(lighterglue=True)
        except ImportError:
            torch = None

    def t(x):
        return torch.from_numpy(np.ascontiguousarray(x, np.float32))[None, None]

    # backbone
    ms_onnx = median_ms(lambda: pipe.backbone(a), n)
    ms_torch = median_ms(lambda: xf.net(t(a)), n) if torch else None
    rows.append(("backbone 640×480", ms_onnx, ms_torch))
    star_in = [net_in for _, net_in, _, _ in R.star_scale_inputs(a)]
    ms_onnx = median_ms(lambda: [pipe.backbone(x) for x in star_in], n)
    ms_torch = median_ms(lambda: [xf.net(t(x)) for x in star_in], n) if torch else None
    shapes = " + ".join(f"{x.shape[1]}×{x.shape[0]}" for x in star_in)
    rows.append((f"backbone, XFeat* scales ({shapes})", ms_onnx, ms_torch))

    # post-processing (numpy reference, Python)
    outs = pipe.backbone(a)
    rows.append(
        (
            "sparse detection, top 4096 (numpy reference)",
            median_ms(lambda: R.detect_and_compute(*outs), n),
            None,
        )
    )
    fa, fb = pipe.detect(a), pipe.detect(b)
    rows.append(
        (
            f"MNN matching {len(fa.keypoints)}×{len(fb.keypoints)} (numpy)",
            median_ms(lambda: R.match_mnn(fa.descriptors, fb.descriptors), n),
            None,
        )
    )
    k1, s1, d1 = pipe.dense(a)
    k2, _, d2 = pipe.dense(b)
    i, j = R.match_mnn(d1, d2)
    pair = np.concatenate([d1[i], d2[j]], axis=1).astype(np.float32)
    refine = pipe.session("refine")
    ms_onnx = median_ms(lambda: refine.run(None, {"pair_feats": pair}), n)
    ms_torch = None
    if torch:
        mlp = Refine(xf.net).eval()
        tp = torch.from_numpy(pair)
        ms_torch = median_ms(lambda: mlp(tp), n)
    rows.append((f"XFeat* refinement MLP, {len(pair)} matches", ms_onnx, ms_torch))

    # LighterGlue
    for k in (1024, 2048):
        fa, fb = pipe.detect(a, k), pipe.detect(b, k)
        ms_onnx = median_ms(lambda fa=fa, fb=fb: pipe.lighterglue(fa, fb), n)
        ms_torch = None
        if torch:
            data = {
                "keypoints0": torch.from_numpy(fa.keypoints)[None],
                "keypoints1": torch.from_numpy(fb.keypoints)[None],
                "descriptors0": torch.from_numpy(fa.descriptors)[None],
                "descriptors1": torch.from_numpy(fb.descriptors)[None],
                "image_size0": torch.tensor(fa.size_wh)[None],
                "image_size1": torch.tensor(fb.size_wh)[None],
            }
            ms_torch = median_ms(lambda data=data: xf.lighterglue(data), max(1, n // 2))
        label = f"LighterGlue {len(fa.keypoints)}×{len(fb.keypoints)} keypoints"
        rows.append((label, ms_onnx, ms_torch))
        print(rows[-1], flush=True)

    load = os.getloadavg()[0]
    cli = ["--repeats", n, "--threads", args.threads] + (["--no-torch"] if args.no_torch else [])
    lines = [
        "# XFeat matchers: time per VGA image (ms)",
        "",
        f"Command: `{common.command(__spec__.name, cli)}`. onnxruntime "
        + __import__("onnxruntime").__version__
        + f" with {args.threads} intra-op threads; torch = Debian's CPU torch "
        + (torch.__version__ if torch else "(not run)")
        + f" with {args.threads} threads (its generic BLAS is slow: docs/design.md §7). Medians of "
        + f"{n} runs (upstream LighterGlue: {max(1, n // 2)}).",
        "",
        f"**Load average {load:.1f} on {os.cpu_count()} cores when this finished** (a training "
        "job shared the machine), so absolute numbers are pessimistic (docs/design.md §7 measured "
        "28 ms for the ONNX backbone on an idle machine).",
        "",
        "| stage | ONNX (ms) | torch (ms) |",
        "|---|---|---|",
    ]
    for label, mo, mt in rows:
        lines.append(f"| {label} | {mo:.1f} | {'—' if mt is None else f'{mt:.1f}'} |")
    lines += [
        "",
        "The numpy rows are the Python reference (`affcorr.export.xfeat_reference`), which the "
        "Rust runner replaces; they are here for scale only.",
        "",
    ]
    common.write_report(args.output, lines)


if __name__ == "__main__":
    main()
