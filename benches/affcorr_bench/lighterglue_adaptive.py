"""Adaptive LighterGlue (issue 21): the layer loop over the pieces vs the full graph, per
depth/width confidence, and the variants (fused attention, fp16 weights, int8 dynamic
quantisation).

    .venv/bin/python -m affcorr_bench.lighterglue_adaptive [--top-k 1024 2048] [--repeats 3]

Pairs: graffiti 1→3 (800×640, its published H) and the viewpoint pairs of the evaluation
suite (affcorr_bench.eval.data.hpatches_pairs, longer side 640: graffiti again and three
held-out images under 5 random homographies each): 17 pairs. Features: the shipped XFeat
backbone, top-k per image. The loop is
:class:`affcorr.export.lightglue_pieces.AdaptiveGlueOnnx` (onnxruntime, 2 threads), the numpy
specification of the Rust loop (crates/affcorr-runner/src/lightglue.rs); the full graph is
python/affcorr/models/xfeat_lighterglue.onnx. *identical*: index pairs also found by the full
graph / the full graph's matches; *correct*: within 3 px of H. Times: the matcher alone, sums
over the pairs of per-pair medians, configurations alternated (so that all see the same load);
wall and CPU (process) time. ``--top-k`` with no values runs only the variants.
Writes benches/results/lighterglue_adaptive.md.
"""

from __future__ import annotations

import argparse
import os
import platform
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

from . import common

OUT = common.RESULTS / "lighterglue_adaptive.md"
# (label, depth_confidence, width_confidence); None: the full graph
CONFIGS = [
    ("full graph (every layer, width 0.95 in the graph)", None, None),
    ("pieces, depth off, width 0.95 (the full graph's rule)", -1.0, 0.95),
    ("pieces, depth 0.95, width 0.95 (**default**)", 0.95, 0.95),
    ("pieces, depth 0.9, width 0.95", 0.9, 0.95),
    ("pieces, depth 0.95, width 0.99 (LightGlue's)", 0.95, 0.99),
    ("pieces, depth 0.95, width 0.9", 0.95, 0.9),
    ("pieces, depth off, width off (every layer, every point)", -1.0, -1.0),
]


def pairs():
    from affcorr.data import graffiti

    from .eval.data import Pair, hpatches_pairs

    a, b, H = graffiti()
    u8 = lambda x: np.clip(np.rint(x * 255), 0, 255).astype(np.uint8)  # noqa: E731
    out = [Pair("graffiti-1-3", "viewpoint", u8(a), u8(b), H)]
    out += [p for p in hpatches_pairs(max_side=640) if p.kind == "viewpoint"]
    return out


def features(pipe, pair, k):
    from affcorr.export.xfeat_reference import normalize_keypoints_lighterglue

    fa = pipe.detect(pair.img1.astype(np.float32) / 255.0, k)
    fb = pipe.detect(pair.img2.astype(np.float32) / 255.0, k)
    args = (
        normalize_keypoints_lighterglue(fa.keypoints, fa.size_wh),
        fa.descriptors,
        normalize_keypoints_lighterglue(fb.keypoints, fb.size_wh),
        fb.descriptors,
    )
    return fa, fb, args


def evaluate(runners: dict, plist, k: int, repeats: int) -> dict:
    """{label: totals} for ``runners`` = {label: fn(fa, fb, args) -> (i, j, layers)}."""
    from affcorr.export.xfeat_reference import XFeatOnnx, correct_within

    pipe = XFeatOnnx()
    tot = {
        lab: {"matches": 0, "common": 0, "correct": 0, "layers": [], "s": 0.0, "cpu": 0.0}
        for lab in runners
    }
    full_total = 0
    for pair in plist:
        fa, fb, args = features(pipe, pair, k)
        times = {lab: [] for lab in runners}
        cpu = {lab: [] for lab in runners}
        res = {}
        for _ in range(repeats):  # alternated
            for lab, fn in runners.items():
                t0, c0 = time.perf_counter(), time.process_time()
                res[lab] = fn(fa, fb, args)
                times[lab].append(time.perf_counter() - t0)
                cpu[lab].append(time.process_time() - c0)
        i, j, _ = res[next(iter(runners))]
        full = set(zip(i.tolist(), j.tolist()))
        full_total += len(full)
        for lab, (i2, j2, layers) in res.items():
            got = set(zip(i2.tolist(), j2.tolist()))
            t = tot[lab]
            t["matches"] += len(got)
            t["common"] += len(got & full)
            t["correct"] += int(correct_within(fa.keypoints[i2], fb.keypoints[j2], pair.H).sum())
            t["layers"].append(layers)
            t["s"] += float(np.median(times[lab]))
            t["cpu"] += float(np.median(cpu[lab]))
    for t in tot.values():
        t["identical"] = t["common"] / max(1, full_total)
        t["layers"] = float(np.mean(t["layers"]))
    return tot


def config_runners(models: Path):
    from affcorr.export.lightglue_pieces import AdaptiveGlueOnnx
    from affcorr.export.xfeat_reference import XFeatOnnx

    pipe = XFeatOnnx(models)
    glue = AdaptiveGlueOnnx(models)
    runners = {}
    for label, dc, wc in CONFIGS:
        if dc is None:

            def fn(fa, fb, args):
                i, j, _ = pipe.lighterglue(fa, fb)
                return i, j, 6

        else:

            def fn(fa, fb, args, dc=dc, wc=wc):
                i, j, _ = glue.run(*args, depth_confidence=dc, width_confidence=wc)
                return i, j, glue.last_stop

        runners[label] = fn
    return runners


def variant_runners(models: Path, work: Path):
    """The default loop (0.95, 0.95) over variants of the pieces: the shipped ones (fused
    attention, fp16-stored weights) and, with torch, fresh exports of the others."""
    from affcorr.export import lightglue_pieces as P
    from affcorr.export.xfeat_reference import XFeatOnnx

    pipe = XFeatOnnx(models)
    runners = {}

    def full(fa, fb, args):
        i, j, _ = pipe.lighterglue(fa, fb)
        return i, j, 6

    runners["full graph"] = full

    def add(label, glue):
        def fn(fa, fb, args):
            i, j, _ = glue.run(*args)
            return i, j, glue.last_stop

        runners[label] = fn

    add("fused attention, fp16-stored weights (**shipped**)", P.AdaptiveGlueOnnx(models))
    sizes = {"shipped layer graph": (models / P.PIECES["layer"]).stat().st_size}
    plain = models
    try:
        import torch  # noqa: F401
        from affcorr.export.xfeat import load_upstream_lighterglue

        lg = load_upstream_lighterglue().net
        for att in ("plain", "fused", "fused-self"):
            d = work / att
            d.mkdir()
            P.export_pieces(lg, d, attention=att)
        plain = work / "plain"
        add("MatMul/Softmax attention, float32 weights", P.AdaptiveGlueOnnx(plain))
        add("fused attention, float32 weights", P.AdaptiveGlueOnnx(work / "fused"))
        add("fused self attention only, float32 weights", P.AdaptiveGlueOnnx(work / "fused-self"))
        sizes["float32 layer graph"] = (plain / P.PIECES["layer"]).stat().st_size
    except ImportError:
        pass
    n = P.AdaptiveGlueOnnx(models).n_layers
    fixed = P.fixed_layer_models(plain / P.PIECES["layer"], work / "fixed", n)
    add(
        "one model per layer (weights folded), float32",
        P.AdaptiveGlueOnnx(plain, layer_models=fixed),
    )
    int8 = P.quantize_int8(fixed, work / "fixed")
    add(
        "one model per layer, int8 dynamic quantisation",
        P.AdaptiveGlueOnnx(plain, layer_models=int8),
    )
    sizes["int8 per-layer models (sum)"] = sum(p.stat().st_size for p in int8)
    return runners, sizes


def table(tot: dict, base: str) -> list[str]:
    rows = [
        "| configuration | matches | identical to full | correct (3 px) | layers run (mean) "
        "| wall s (sum) | vs full | CPU s (sum) | vs full |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    b, bc = tot[base]["s"], tot[base]["cpu"]
    for lab, t in tot.items():
        rows.append(
            f"| {lab} | {t['matches']} | {100 * t['identical']:.1f} % | {t['correct']} | "
            f"{t['layers']:.2f} | {t['s']:.2f} | {t['s'] / b:.2f}× | {t['cpu']:.2f} | "
            f"{t['cpu'] / bc:.2f}× |"
        )
    return rows


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--top-k", type=int, nargs="*", default=[1024, 2048])
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--variants-top-k", type=int, default=2048)
    p.add_argument("-o", "--output", type=Path, default=OUT)
    args = p.parse_args(argv)
    warnings.filterwarnings("ignore")
    from affcorr.export.xfeat_reference import models_dir

    models = models_dir()
    load0 = os.getloadavg()[0]
    plist = pairs()
    lines = [
        "# Adaptive LighterGlue: the layer loop vs the full graph (issue 21)",
        "",
        f"Command: `.venv/bin/python -m affcorr_bench.lighterglue_adaptive --top-k "
        f"{' '.join(map(str, args.top_k))} --repeats {args.repeats} "
        f"--variants-top-k {args.variants_top_k}` "
        "(benches/affcorr_bench/lighterglue_adaptive.py; its docstring has the protocol).",
        "",
        f"{len(plist)} pairs: graffiti 1→3 (800×640, and 640×512 as the evaluation suite has "
        "it) and 15 viewpoint pairs of the evaluation suite; "
        "the loop is the numpy/onnxruntime specification of the Rust one "
        "(`AdaptiveGlueOnnx`), 2 threads. *identical*: index pairs of the full graph found "
        "too (over all pairs); *correct*: within 3 px of H.",
        "",
    ]
    runners = config_runners(models)
    base = next(iter(runners))
    for k in args.top_k:
        tot = evaluate(runners, plist, k, args.repeats)
        lines += [f"## {k} keypoints per image", "", *table(tot, base), ""]
        print(
            k,
            {lab: (t["matches"], round(t["identical"], 3), t["correct"]) for lab, t in tot.items()},
        )
    with tempfile.TemporaryDirectory() as tmp:
        vr, sizes = variant_runners(models, Path(tmp))
        k = args.variants_top_k
        tot = evaluate(vr, plist, k, args.repeats)
        lines += [
            f"## Variants of the pieces ({k} keypoints, depth 0.95, width 0.95)",
            "",
            *table(tot, "full graph"),
            "",
            "File sizes: " + ", ".join(f"{n} {s / 1e6:.2f} MB" for n, s in sizes.items()) + ".",
            "",
        ]
    load1 = os.getloadavg()[0]
    lines += [
        f"Load average {load0:.1f} → {load1:.1f} on {os.cpu_count()} cores "
        f"({platform.machine()}); onnxruntime "
        f"{__import__('onnxruntime').__version__}. Times are sums of per-pair medians; with "
        "other jobs on the machine they are pessimistic, the ratios (same run, alternated) "
        "are what to read, and the CPU time (process time of the 2 onnxruntime threads, which "
        "do not spin) is less sensitive to the load than the wall time.",
        "",
    ]
    args.output.write_text("\n".join(lines))
    print(f"wrote {args.output}")


if __name__ == "__main__":
    main()
