"""Train the shape network, decoupled as in the paper (§3.4): E_os first, then E_aff.

    python -m affcorr.train.shape os  --workdir DIR [--minutes M]
    python -m affcorr.train.shape aff --workdir DIR [--loss laff|direct|both] [--minutes M]

Both stages are resumable: each saves ``DIR/<stage>.pt`` (weights, optimiser, step) every
``--save-every`` steps and at the end, and continues from it when run again. Validation metrics
go to ``DIR/<stage>.csv``. Datasets are generated on first use into ``DIR`` (see datasets.py).

Losses
- E_os, the probability covariance loss (S3Esti): for a pair with known rotation phi and scale
  s, the distribution predicted for patch B must equal patch A's shifted by phi (circularly)
  and by log2 s, and vice versa; each direction is a cross-entropy.
- E_aff (E_os frozen), with A = S R(O) A'(A''):
  ``laff``: L_aff = mean SD_A against the pair's F (affcorr.losses, the paper's weak
  supervision), under a Cauchy robustifier log(1 + SD_A / 1 px^2) so that pairs whose E_os
  prediction is off cannot dominate; ``direct``: ||A - A_gt||_F / sqrt(det A_gt);
  ``both``: their sum.
"""

from __future__ import annotations

import argparse
import csv
import math
import time
from pathlib import Path

import numpy as np
import torch

from .datasets import plane_dataset, similarity_dataset
from .shape_net import (
    ANGLE_BINS,
    ARCHITECTURES,
    DEFAULT_ARCHITECTURE,
    LOG2_SCALE_RANGE,
    SCALE_BINS,
    OrientationScaleNet,
    ResidualShapeNet,
    decode_orientation,
    decode_scale,
    normalise_patches,
    synthesize_torch,
)


def _patches(u8: np.ndarray, idx: np.ndarray) -> torch.Tensor:
    return torch.from_numpy(u8[idx]).float().div_(255.0).unsqueeze(1)


def shift_distribution(p: torch.Tensor, shift_bins: torch.Tensor, circular: bool) -> torch.Tensor:
    """q[k] = p[k - shift] with linear interpolation between bins (fractional shifts); mass
    shifted past the ends of a non-circular axis is dropped (q sums to less than one)."""
    k = p.shape[-1]
    src = torch.arange(k, dtype=p.dtype).unsqueeze(0) - shift_bins.unsqueeze(1)
    lo = torch.floor(src)
    w = src - lo
    lo = lo.long()
    hi = lo + 1
    if circular:
        q = (1 - w) * p.gather(1, lo % k) + w * p.gather(1, hi % k)
    else:

        def take(i):
            valid = (i >= 0) & (i < k)
            return torch.where(valid, p.gather(1, i.clamp(0, k - 1)), torch.zeros_like(p))

        q = (1 - w) * take(lo) + w * take(hi)
    return q


def covariance_loss(logits_a, logits_b, shift_bins, circular: bool) -> torch.Tensor:
    """Symmetric probability covariance loss: CE(shift(p_A), p_B) + CE(shift(p_B, -), p_A).

    On a non-circular axis (scale) the mass that a shift pushes past either end costs
    2 log K, the price of a wrong guess: otherwise piling all mass on an end bin would satisfy
    the covariance trivially (it did, in a first run).
    """
    pa, pb = torch.softmax(logits_a, 1), torch.softmax(logits_b, 1)
    la, lb = torch.log_softmax(logits_a, 1), torch.log_softmax(logits_b, 1)
    ta = shift_distribution(pa, shift_bins, circular)
    tb = shift_distribution(pb, -shift_bins, circular)
    loss = -(ta * lb).sum(1).mean() - (tb * la).sum(1).mean()
    if not circular:
        lost = (1 - ta.sum(1)).mean() + (1 - tb.sum(1)).mean()
        loss = loss + 2 * math.log(logits_a.shape[1]) * lost
    return loss


ANGLE_BIN_WIDTH = 2 * math.pi / ANGLE_BINS
LOG2_SCALE_BIN_WIDTH = 2 * LOG2_SCALE_RANGE / (SCALE_BINS - 1)


def os_errors(net: OrientationScaleNet, data: dict, batch: int = 2048) -> dict[str, float]:
    """Median |angle error| (deg) and |log2 scale error| of O_B - O_A and S_B / S_A."""
    net.eval()
    da, ds = [], []
    with torch.no_grad():
        for i in range(0, len(data["angle"]), batch):
            idx = np.arange(i, min(i + batch, len(data["angle"])))
            aa, sa = net(_patches(data["patch_a"], idx))
            ab, sb = net(_patches(data["patch_b"], idx))
            o = decode_orientation(ab) - decode_orientation(aa)
            s = decode_scale(sb) / decode_scale(sa)
            d = o.double() - torch.from_numpy(data["angle"][idx])
            da.append(torch.atan2(torch.sin(d), torch.cos(d)).abs().numpy())
            ds.append((torch.log2(s.double()) - np.log2(data["scale"][idx])).abs().numpy())
    da, ds = np.degrees(np.concatenate(da)), np.concatenate(ds)
    return {
        "angle_med_deg": float(np.median(da)),
        "angle_within_10deg": float(np.mean(da < 10)),
        "log2_scale_med": float(np.median(ds)),
        "scale_within_quarter_octave": float(np.mean(ds < 0.25)),
    }


def checkpoint_architecture(path: Path) -> str | None:
    """The architecture a checkpoint was trained with (``None``: no checkpoint); checkpoints
    from before architectures were recorded are ``v1``."""
    if not path.exists():
        return None
    return torch.load(path, map_location="cpu").get("arch", "v1")


def _load(path: Path, modules: dict, optimiser) -> int:
    if not path.exists():
        return 0
    state = torch.load(path, map_location="cpu")
    for name, m in modules.items():
        want, have = state.get("arch", "v1"), m.arch.name
        if want != have:
            raise SystemExit(f"{path} holds a {want!r} network, not {have!r}: pass --arch {want}")
        m.load_state_dict(state[name])
    if optimiser is not None and "optimiser" in state:
        optimiser.load_state_dict(state["optimiser"])
    return int(state.get("step", 0))


def _save(path: Path, modules: dict, optimiser, step: int) -> None:
    state = {name: m.state_dict() for name, m in modules.items()}
    (arch,) = {m.arch.name for m in modules.values()}
    state.update(optimiser=optimiser.state_dict(), step=step, arch=arch)
    tmp = path.with_suffix(".tmp")
    torch.save(state, tmp)
    tmp.replace(path)


def _log(path: Path, row: dict) -> None:
    new = not path.exists()
    with path.open("a", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(row))
        if new:
            w.writeheader()
        w.writerow(row)
    print(
        " ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}" for k, v in row.items()),
        flush=True,
    )


def _lr(step: int, steps: int, base: float) -> float:
    warm = 200
    if step < warm:
        return base * (step + 1) / warm
    return 0.5 * base * (1 + math.cos(math.pi * min(step, steps) / steps))


def train_os(args) -> None:
    wd = Path(args.workdir)
    jit = 0.0 if args.centre_jitter is None else args.centre_jitter
    train = similarity_dataset(wd / "similarity_train.npz", "train", args.seed, centre_jitter=jit)
    val = similarity_dataset(wd / "similarity_val.npz", "val", args.seed, centre_jitter=jit)
    print(f"E_os: {len(train['angle'])} training pairs, {len(val['angle'])} validation pairs")
    torch.manual_seed(args.seed)
    net = OrientationScaleNet(args.arch)
    opt = torch.optim.AdamW(net.parameters(), lr=args.lr, weight_decay=1e-4)
    ckpt = wd / "os.pt"
    step = _load(ckpt, {"os": net}, opt)
    rng = np.random.default_rng([args.seed, step])
    t_end = time.time() + 60 * args.minutes
    # Curriculum: pairs with a large scale change share little content; --max-log2-scale
    # limits training to the easier ones.
    pool = np.nonzero(np.abs(np.log2(train["scale"])) <= args.max_log2_scale)[0]
    while step < args.steps and time.time() < t_end:
        net.train()
        idx = pool[rng.integers(0, len(pool), args.batch)]
        pa, pb = _patches(train["patch_a"], idx), _patches(train["patch_b"], idx)
        angle = torch.from_numpy(train["angle"][idx]).float()
        log2s = torch.from_numpy(np.log2(train["scale"][idx])).float()
        logits, scales = net(torch.cat([pa, pb]))
        b = len(idx)
        loss = covariance_loss(
            logits[:b], logits[b:], angle / ANGLE_BIN_WIDTH, True
        ) + args.scale_weight * covariance_loss(
            scales[:b], scales[b:], log2s / LOG2_SCALE_BIN_WIDTH, False
        )
        for g in opt.param_groups:
            g["lr"] = _lr(step, args.steps, args.lr)
        opt.zero_grad()
        loss.backward()
        opt.step()
        step += 1
        if step % args.save_every == 0 or step == args.steps:
            _save(ckpt, {"os": net}, opt, step)
            _log(wd / "os.csv", {"step": step, "loss": float(loss), **os_errors(net, val)})
    _save(ckpt, {"os": net}, opt, step)


def _affine_prediction(os_net, aff_net, pa, pb):
    with torch.no_grad():
        na, nb = normalise_patches(pa), normalise_patches(pb)
        aa, sa = os_net.logits(na)
        ab, sb = os_net.logits(nb)
        o = decode_orientation(ab) - decode_orientation(aa)
        s = decode_scale(sb) / decode_scale(sa)
    residual = aff_net(na, nb, torch.cos(o), torch.sin(o), s)
    return synthesize_torch(o.double(), s.double(), residual.double()), o, s


def aff_errors(os_net, aff_net, data: dict, batch: int = 2048) -> dict[str, float]:
    """The paper's Table 2 metrics on ``data``: median ||A - A_gt||_F, mean cosine similarity
    of vec(A) and vec(A_gt), and the same for the similarity part alone (O, S)."""
    os_net.eval()
    aff_net.eval()
    fro, cos, fro_os, cos_os, sda = [], [], [], [], []
    from ..losses import affine_sampson

    with torch.no_grad():
        for i in range(0, len(data["corrs"]), batch):
            idx = np.arange(i, min(i + batch, len(data["corrs"])))
            pa, pb = _patches(data["patch_a"], idx), _patches(data["patch_b"], idx)
            A, o, s = _affine_prediction(os_net, aff_net, pa, pb)
            gt = torch.from_numpy(data["corrs"][idx, 4:]).view(-1, 2, 2)
            sim = synthesize_torch(o.double(), s.double(), torch.zeros(len(idx), 3).double())
            for pred, f_out, c_out in ((A, fro, cos), (sim, fro_os, cos_os)):
                d = (pred - gt).flatten(1)
                f_out.append(d.norm(dim=1).numpy())
                c_out.append(
                    torch.nn.functional.cosine_similarity(pred.flatten(1), gt.flatten(1)).numpy()
                )
            corrs = torch.from_numpy(data["corrs"][idx]).clone()
            corrs[:, 4:] = A.flatten(1)
            sda.append(affine_sampson(torch.from_numpy(data["F"][idx]), corrs).sum(1).numpy())
    cat = np.concatenate
    return {
        "fro_med": float(np.median(cat(fro))),
        "cos_mean": float(np.mean(cat(cos))),
        "fro_med_os_only": float(np.median(cat(fro_os))),
        "cos_mean_os_only": float(np.mean(cat(cos_os))),
        "sd_a_med": float(np.median(cat(sda))),
    }


def train_aff(args) -> None:
    from ..losses import affine_sampson

    wd = Path(args.workdir)
    jit = 0.5 if args.centre_jitter is None else args.centre_jitter
    train = plane_dataset(wd / "plane_train.npz", "train", args.seed, centre_jitter=jit)
    val = plane_dataset(wd / "plane_val.npz", "val", args.seed, centre_jitter=jit)
    print(
        f"E_aff ({args.loss}): {len(train['corrs'])} training pairs, "
        f"{len(val['corrs'])} validation pairs"
    )
    os_net = OrientationScaleNet(checkpoint_architecture(wd / "os.pt") or args.arch)
    if _load(wd / "os.pt", {"os": os_net}, None) == 0:
        raise SystemExit(f"no trained E_os in {wd}: run the 'os' stage first")
    os_net.eval()
    torch.manual_seed(args.seed)
    aff_net = ResidualShapeNet(os_net.arch)
    opt = torch.optim.AdamW(aff_net.parameters(), lr=args.lr, weight_decay=1e-4)
    ckpt = wd / f"aff_{args.loss}.pt"
    step = _load(ckpt, {"aff": aff_net}, opt)
    rng = np.random.default_rng([args.seed, step, 1])
    t_end = time.time() + 60 * args.minutes
    n = len(train["corrs"])
    while step < args.steps and time.time() < t_end:
        aff_net.train()
        idx = rng.integers(0, n, args.batch)
        pa, pb = _patches(train["patch_a"], idx), _patches(train["patch_b"], idx)
        A, _, _ = _affine_prediction(os_net, aff_net, pa, pb)
        gt_corrs = torch.from_numpy(train["corrs"][idx])
        loss = torch.zeros((), dtype=torch.float64)
        if args.loss in ("laff", "both"):
            corrs = torch.cat([gt_corrs[:, :4], A.flatten(1)], 1)
            sd = affine_sampson(torch.from_numpy(train["F"][idx]), corrs).sum(1)
            loss = loss + torch.log1p(sd).mean()
        if args.loss in ("direct", "both"):
            gt = gt_corrs[:, 4:].view(-1, 2, 2)
            norm = torch.sqrt(torch.det(gt)).clamp_min(1e-6)
            loss = loss + ((A - gt).flatten(1).norm(dim=1) / norm).mean()
        for g in opt.param_groups:
            g["lr"] = _lr(step, args.steps, args.lr)
        opt.zero_grad()
        loss.backward()
        opt.step()
        step += 1
        if step % args.save_every == 0 or step == args.steps:
            _save(ckpt, {"aff": aff_net}, opt, step)
            _log(
                wd / f"aff_{args.loss}.csv",
                {"step": step, "loss": float(loss), **aff_errors(os_net, aff_net, val)},
            )
    _save(ckpt, {"aff": aff_net}, opt, step)


def main(argv=None) -> None:
    p = argparse.ArgumentParser(
        prog="python -m affcorr.train.shape",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("stage", choices=["os", "aff"])
    p.add_argument("--workdir", required=True, help="datasets, checkpoints and logs (not git)")
    p.add_argument("--loss", choices=["laff", "direct", "both"], default="laff")
    p.add_argument(
        "--steps", type=int, default=None, help="total optimiser steps (the LR schedule's length)"
    )
    p.add_argument("--minutes", type=float, default=1e9, help="stop after this wall time")
    p.add_argument("--batch", type=int, default=256)
    p.add_argument("--lr", type=float, default=2e-3)
    p.add_argument(
        "--max-log2-scale",
        type=float,
        default=2.0,
        help="E_os: train only on pairs with |log2 S_B/S_A| up to this",
    )
    p.add_argument(
        "--scale-weight",
        type=float,
        default=2.0,
        help="E_os: weight of the scale term against the angle term",
    )
    p.add_argument(
        "--centre-jitter",
        type=float,
        default=None,
        help="std (px) of the offset of patch B's centre from the true point, as keypoint noise "
        "has (default: 0 for os, 0.5 for aff); datasets are cached per workdir, so use a new "
        "workdir for a new value",
    )
    p.add_argument(
        "--arch",
        choices=list(ARCHITECTURES),
        default=DEFAULT_ARCHITECTURE,
        help="layer plan (shape_net.ARCHITECTURES); the aff stage takes E_os's",
    )
    p.add_argument("--save-every", type=int, default=500)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args(argv)
    if args.steps is None:
        args.steps = 5000 if args.stage == "os" else 3000
    torch.set_num_threads(args.threads)
    Path(args.workdir).mkdir(parents=True, exist_ok=True)
    (train_os if args.stage == "os" else train_aff)(args)


if __name__ == "__main__":
    main()
