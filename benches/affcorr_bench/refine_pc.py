"""XFeat* with the original vs the PC-loss fine-tuned refinement MLP (affcorr.train.refine_pc):
mean matching accuracy on held-out pairs, through the shipped code path.

    .venv/bin/python -m affcorr_bench.refine_pc [--weights ~/.cache/affcorr/refine-pc/best.pt]

Both refine models are exported with ``affcorr.export.xfeat.export_refine`` into temporary model
directories (next to a copy of the shipped backbone) and run by
``affcorr.Pipeline("xfeat-star", models_dir=...)`` (the Rust runner). Pairs: rendered plane
views of the *validation* textures (``textures("val")``, never trained on; ±15 deg rotation as
in training, XFeat is not rotation invariant) and graffiti 1→3 with its ground-truth H.
MMA@t = matches with |H x1 - x2| <= t px / all matches, pooled over a set's pairs.

Writes benches/results/refine_pc.md and .csv.
"""

from __future__ import annotations

import argparse
import datetime
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from . import common

THRESHOLDS = (1, 2, 3, 5)


def held_out_pairs(pairs_per_texture: int, seed: int):
    from affcorr.data import graffiti
    from affcorr.train.refine_pc import MAX_ROTATION_DEG
    from affcorr.train.sources import textures
    from affcorr.train.views import render_plane_views

    val = []
    for ti, (_, image) in enumerate(textures("val")):
        for k in range(pairs_per_texture):
            rng = np.random.default_rng([seed, ti, k])
            a, b, H = render_plane_views(rng, image, max_rotation_deg=MAX_ROTATION_DEG)
            val.append((a, b, H))
    a, b, H = graffiti()
    return {"val textures (rendered)": val, "graffiti 1→3": [(a, b, H)]}


def errors(pipe, pairs) -> np.ndarray:
    out = []
    for a, b, H in pairs:
        c = pipe.match_pair(a, b).corrs
        p = np.c_[c[:, :2], np.ones(len(c))] @ H.T
        out.append(np.linalg.norm(p[:, :2] / p[:, 2:] - c[:, 2:4], axis=1))
    return np.concatenate(out) if out else np.zeros(0)


def model_dirs(tmp: Path, weights: Path, label: str) -> dict:
    import torch
    from affcorr.export.xfeat import FILES, export_refine, load_refine_weights, load_upstream
    from affcorr.pipeline import bundled_models_dir

    torch.set_grad_enabled(False)
    dirs = {}
    for name, w in (("original", None), (label, weights)):
        d = tmp / ("orig" if w is None else "tuned")
        d.mkdir()
        shutil.copy(bundled_models_dir() / FILES["backbone"], d / FILES["backbone"])
        xf = load_upstream()
        note = load_refine_weights(xf, w) if w is not None else ""
        export_refine(xf, d / FILES["refine"], note)
        dirs[name] = d
    return dirs


def main(argv=None) -> None:
    from affcorr.train.refine_pc import default_workdir

    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--weights", type=Path, default=default_workdir() / "best.pt")
    p.add_argument("--pairs-per-texture", type=int, default=4)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--out", type=Path, default=common.RESULTS / "refine_pc")
    p.add_argument("--label", default="fine-tuned (CE + 0.01 L_pc)", help="the tuned model's row")
    args = p.parse_args(argv)
    import affcorr
    import torch

    torch.set_num_threads(args.threads)
    sets = held_out_pairs(args.pairs_per_texture, args.seed)
    rows = []
    t0 = time.time()
    with tempfile.TemporaryDirectory() as tmp:
        for label, d in model_dirs(Path(tmp), args.weights, args.label).items():
            pipe = affcorr.Pipeline("xfeat-star", models_dir=d, threads=args.threads)
            for name, pairs in sets.items():
                e = errors(pipe, pairs)
                row = {"set": name, "refine model": label, "pairs": len(pairs), "matches": len(e)}
                for t in THRESHOLDS:
                    row[f"MMA@{t}px"] = float((e <= t).mean()) if len(e) else 0.0
                rows.append(row)
                print(row, flush=True)
    blob = torch.load(str(args.weights), map_location="cpu")
    cmd = common.command(__spec__.name, argv)
    write(args.out, rows, cmd, blob.get("note", ""), time.time() - t0)


def write(out: Path, rows: list, cmd: str, note: str, seconds: float) -> None:
    keys = list(rows[0])
    common.write_csv(rows, out.with_suffix(".csv"))
    fmt = lambda v: f"{v:.3f}" if isinstance(v, float) else str(v)  # noqa: E731
    lines = [
        "# XFeat* refinement: original vs PC-loss fine-tuned (paper §3.3 stage 1)",
        "",
        f"- Command: `{cmd}` ({seconds:.0f} s)",
        f"- Date: {datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC",
        f"- Fine-tuned weights: {note}",
        "- Path: ONNX refine model exported by `affcorr.export.xfeat.export_refine`, run by "
        '`affcorr.Pipeline("xfeat-star", models_dir=...)` with the shipped backbone.',
        "- MMA@t: fraction of all matches with |H x1 − x2| ≤ t px (pooled over the set).",
        "",
        "| " + " | ".join(keys) + " |",
        "|" + "---|" * len(keys),
    ]
    lines += ["| " + " | ".join(fmt(r[k]) for k in keys) + " |" for r in rows]
    out.with_suffix(".md").write_text("\n".join(lines) + "\n")
    print(f"wrote {out.with_suffix('.md')}")


if __name__ == "__main__":
    main()
