"""Would batching the view cascade's synthetic views through ONNX Runtime pay? (issue 20)

    .venv/bin/python -m affcorr_bench.views_batch [--repeats 7] [--threads 2]

The cascade extracts XFeat features of each synthetic view on its own (the screened groups of
crates/affcorr-pipeline/src/views.rs: a 640×480 image tilted by 2 in 4 directions, by 4 in 8
directions, and by 4 zoomed by ½ in 8 directions). The exported backbone takes a batch
dimension, so a group could run as one call. This times the backbone, as the runner runs it
(ONNX Runtime, ``--threads`` intra-op threads, no spinning), on each group's views one call
per view, against one call on the whole group padded to its largest view (the views differ in
size: a batch needs one), and against one call on views of one size (the largest), the lower
bound of what padding could cost. Sizes are rounded down to multiples of 32, as XFeat's
preprocessing does. Writes benches/results/views_batch.md. Each cell is the fastest of
``--repeats`` runs.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from . import common

OUT = common.RESULTS / "views_batch.md"
SIZE = (640, 480)
# (label, zoom, tilt, directions): the cascade's screened tilt groups of one image
GROUPS = [
    ("tilt 2, 4 directions", 1.0, 2.0, 4),
    ("tilt 4, 8 directions", 1.0, 4.0, 8),
    ("tilt 4 zoomed by ½, 8 directions", 0.5, 4.0, 8),
]


def view_size(zoom: float, tilt: float, angle: float, size=SIZE) -> tuple[int, int]:
    """(W, H) of the view that holds the whole image under s · R(φ)ᵀ diag(1, 1/t) R(φ)
    (``AffineWarp::linear(0, s, t, φ).fitted``), rounded down to multiples of 32."""
    c, s = np.cos(angle), np.sin(angle)
    r = np.array([[c, -s], [s, c]])
    m = zoom * r.T @ np.diag([1.0, 1.0 / tilt]) @ r
    w, h = size[0] - 1, size[1] - 1
    corners = m @ np.array([[0, w, 0, w], [0, 0, h, h]], float)
    ext = corners.max(1) - corners.min(1) + 1
    return int(ext[0] // 32 * 32), int(ext[1] // 32 * 32)


def session(models: Path, threads: int):
    import onnxruntime as ort

    so = ort.SessionOptions()
    so.intra_op_num_threads = threads
    so.inter_op_num_threads = 1
    so.add_session_config_entry("session.intra_op.allow_spinning", "0")
    return ort.InferenceSession(
        str(models / "xfeat_backbone.onnx"), so, providers=["CPUExecutionProvider"]
    )


def fastest_ms(fn, repeats: int) -> float:
    fn()  # warm-up
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return 1e3 * best


def one_call_each_and_batched(s, views, batch: np.ndarray, repeats: int) -> tuple[float, float]:
    """ms of the backbone on ``views`` (each (1, 1, H, W), or one (n, 1, H, W) array) one call
    per view, and on ``batch`` in one call."""
    name = s.get_inputs()[0].name
    singles = [v[None] if v.ndim == 3 else v for v in views]
    one_by_one = fastest_ms(lambda: [s.run(None, {name: v}) for v in singles], repeats)
    batched = fastest_ms(lambda: s.run(None, {name: batch}), repeats)
    return one_by_one, batched


def main(argv=None) -> None:
    from affcorr.pipeline import bundled_models_dir

    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--repeats", type=int, default=7)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("-o", "--output", type=Path, default=OUT)
    args = p.parse_args(argv)
    s = session(bundled_models_dir(), args.threads)
    rng = np.random.default_rng(0)
    rows = []
    t_start, load0 = time.time(), common.load_average()
    for label, zoom, tilt, n in GROUPS:
        sizes = [view_size(zoom, tilt, np.pi * k / n) for k in range(n)]
        views = [rng.random((1, 1, h, w), dtype=np.float32) for w, h in sizes]
        wmax, hmax = max(w for w, _ in sizes), max(h for _, h in sizes)
        padded = np.zeros((n, 1, hmax, wmax), np.float32)
        for i, v in enumerate(views):
            padded[i, :, : v.shape[2], : v.shape[3]] = v
        same = rng.random((n, 1, hmax, wmax), dtype=np.float32)
        one_by_one, batched = one_call_each_and_batched(s, views, padded, args.repeats)
        same_single, same_batched = one_call_each_and_batched(s, same, same, args.repeats)
        pixels = sum(w * h for w, h in sizes)
        rows.append(
            [
                label,
                f"{min(sizes)[0]}×{min(sizes)[1]} … {wmax}×{hmax}",
                f"{pixels / (n * wmax * hmax):.2f}",
                f"{one_by_one:.1f}",
                f"{batched:.1f} ({batched / one_by_one:.2f})",
                f"{same_single:.1f}",
                f"{same_batched:.1f} ({same_batched / same_single:.2f})",
            ]
        )
    load1 = common.load_average()
    import onnxruntime

    lines = [
        "# Batching the view cascade's views through ONNX Runtime (issue 20)",
        "",
        f"Command: `{common.command(__spec__.name)}`",
        "",
        f"Date: {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; onnxruntime "
        f"{onnxruntime.__version__}, {args.threads} intra-op threads, no spinning (as the "
        f"runner); load average {load0[0]:.2f} before, {load1[0]:.2f} after, on 2 cores; "
        f"{time.time() - t_start:.0f} s. The XFeat backbone (python/affcorr/models/"
        "xfeat_backbone.onnx) on the views of one screened group of the cascade (a 640×480 "
        "image); ms, the fastest of "
        f"{args.repeats} runs. *fill*: the views' pixels over the padded batch's.",
        "",
        *common.md_table(
            [
                "group",
                "view sizes",
                "fill",
                "one call per view (ms)",
                "one padded batch (ms, ratio)",
                "views of one size, one call each (ms)",
                "the same as one batch (ms, ratio)",
            ],
            rows,
        ),
        "",
        "A batch pays only where each call is small enough for its fixed cost to matter, and "
        "the cascade's views differ in size: padded to the largest, a batch computes the "
        "padding too.",
    ]
    common.write_report(args.output, lines)


if __name__ == "__main__":
    main()
